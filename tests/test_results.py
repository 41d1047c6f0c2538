"""Stored results (results/*.json): sound, fresh (checkpoint hashes match the shipped ones), and
written atomically; bootstrap intervals behave like intervals."""
import json
import re

import numpy as np
import pytest

from facelib import metrics, results, tasks


@pytest.fixture
def tmp_results(tmp_path, monkeypatch):
    monkeypatch.setattr(results, "RESULTS_DIR", tmp_path)
    monkeypatch.setattr(results, "uncommitted_code", lambda: [])  # a clean tree (the refusal has its own test)
    return tmp_path


def _save(name="demo", **overrides):
    kwargs = dict(title="a demo", columns=["method", "Acc (%)", "95 % interval"],
                  rows=[["ours", 80.0, [75.0, 85.0]]],
                  run=results.Run(checkpoints=["ic_coma_I"], seeds=[0], n=8, steps=[20], wall_time_s=1.0,
                                  command="python -m facelib experiment demo"))
    kwargs.update(overrides)
    return results.save_result(name, **kwargs)


@pytest.mark.parametrize("name", results.stored_results())
def test_every_stored_result_is_sound_and_fresh(name):
    record = json.loads(results.result_path(name).read_text())
    assert results.problems(record, f"results/{name}.json") == []


def test_save_then_load_keeps_the_table_and_its_provenance(tmp_results):
    path = _save()
    record = results.load_result("demo")
    assert path == tmp_results / "demo.json"
    assert record["rows"] == [["ours", 80.0, [75.0, 85.0]]]
    assert record["checkpoints"]["ic_coma_I"] == results.checkpoint_sha256("ic_coma_I")
    assert record["cores"] >= 1 and record["commit"] and record["command"].startswith("python -m facelib")
    assert "re-run" in results.markdown_table(record) and "[75.00, 85.00]" in results.markdown_table(record)


def test_merged_rows_replace_the_stored_rows_of_the_same_key_and_keep_the_others(tmp_results):
    assert results.merged_rows("demo", [["new", 1.0, [0.0, 2.0]]]) == ([["new", 1.0, [0.0, 2.0]]], [None])
    results.save_result("demo", "t", ["m", "steps", "x"], [["a", 10, 1.0], ["a", 50, 2.0], ["b", 10, 3.0]],
                        results.Run(checkpoints=[], seeds=[0], n=1, steps=[], wall_time_s=0.0, command="first"))
    merged, provenance = results.merged_rows("demo", [["a", 50, 9.0], ["c", 10, 4.0]], key_length=2)
    assert merged == [["a", 10, 1.0], ["a", 50, 9.0], ["b", 10, 3.0], ["c", 10, 4.0]]
    assert [p and p["command"] for p in provenance] == ["first", None, "first", None]
    results.save_result("demo", "t", ["m", "steps", "x"], merged, results.Run(checkpoints=[], seeds=[0], n=1,
                        steps=[], wall_time_s=0.0, command="second"), row_provenance=provenance)
    record = results.load_result("demo")
    assert [p["command"] for p in record["row_provenance"]] == ["first", "second", "first", "second"]
    _, provenance = results.merged_rows("demo", [["b", 10, 5.0]], key_length=2)  # kept rows keep their own run
    assert [p and p["command"] for p in provenance] == ["first", "second", None, "second"]


def test_a_result_is_not_stored_from_uncommitted_code_unless_allowed(tmp_results, monkeypatch):
    monkeypatch.setattr(results, "uncommitted_code", lambda: [" M facelib/tasks/fill.py"])
    with pytest.raises(ValueError, match=r"demo\.json not written: facelib, benchmarks have uncommitted changes "
                                         r"\( M facelib/tasks/fill\.py\).*--allow-dirty"):
        _save()
    assert not (tmp_results / "demo.json").exists()
    monkeypatch.setattr(results, "facelib_commit", lambda: "abc+dirty")
    run = results.Run(checkpoints=[], seeds=[0], n=1, steps=[], wall_time_s=0.0, allow_dirty=True)
    assert results.load_result(_save(run=run).stem)["commit"] == "abc+dirty (stored with --allow-dirty)"


def test_a_result_is_stale_when_its_world_or_the_defaults_it_measured_change(tmp_results):
    run = results.Run(checkpoints=[], seeds=[0], n=1, steps=[], wall_time_s=0.0, settings=(tasks.Fill(),),
                      command="python benchmarks/fill_defaults.py --save demo")
    path = _save(run=run)
    record = json.loads(path.read_text())
    assert record["settings"]["Fill"]["steps"] == tasks.Fill().steps and results.problems(record) == []
    record["settings"]["Fill"]["steps"] = 7
    record["world"] = {"version": 1, "fingerprint": None}
    found = results.problems(record, "demo.json")
    assert any("stale, tasks.Fill.steps was 7, is 100 now; re-run: python benchmarks/fill_defaults.py" in f
               for f in found), found
    assert any("stale, made on the datasets of world" in f for f in found), found


def test_a_stale_result_names_the_file_and_the_checkpoint(tmp_results):
    path = _save()
    record = json.loads(path.read_text())
    record["checkpoints"]["ic_coma_I"] = "0" * 64
    path.write_text(json.dumps(record))
    with pytest.raises(ValueError, match=r"demo\.json: stale, checkpoint 'ic_coma_I'"):
        results.load_result("demo")


def test_a_result_of_another_schema_or_with_missing_fields_is_refused(tmp_results):
    path = _save()
    record = json.loads(path.read_text())
    record["schema"] = 99
    del record["seeds"]
    path.write_text(json.dumps(record))
    with pytest.raises(ValueError, match="missing field 'seeds'"):
        results.load_result("demo")
    record["seeds"] = [0]
    path.write_text(json.dumps(record))
    with pytest.raises(ValueError, match="schema 99"):
        results.load_result("demo")


def test_an_interrupted_write_leaves_the_previous_result(tmp_results, monkeypatch):
    _save(rows=[["ours", 80.0, [75.0, 85.0]]])
    before = (tmp_results / "demo.json").read_text()

    def crash(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(results.os, "replace", crash)
    with pytest.raises(KeyboardInterrupt):
        _save(rows=[["ours", 10.0, [5.0, 15.0]]])
    assert (tmp_results / "demo.json").read_text() == before
    assert [p.name for p in tmp_results.iterdir()] == ["demo.json"]


def test_bad_names_rows_and_checkpoints_are_refused(tmp_results):
    with pytest.raises(ValueError, match="letters, digits and underscores"):
        _save(name="../x")
    with pytest.raises(ValueError, match="every row needs 3 entries"):
        _save(rows=[["ours", 1.0]])
    with pytest.raises(FileNotFoundError, match="no_such_model"):
        _save(run=results.Run(checkpoints=["no_such_model"], seeds=[0], n=8, steps=[20], wall_time_s=1.0))
    with pytest.raises(FileNotFoundError, match="--save missing"):
        results.load_result("missing")
    assert not list(tmp_results.iterdir())


def test_bootstrap_interval_covers_the_mean_and_narrows_with_n():
    rng = np.random.default_rng(0)
    small, large = rng.normal(size=20), rng.normal(size=2000)
    lo_s, hi_s = metrics.bootstrap_interval(np.mean, small)
    lo_l, hi_l = metrics.bootstrap_interval(np.mean, large)
    assert lo_s <= small.mean() <= hi_s and lo_l <= large.mean() <= hi_l
    assert (hi_l - lo_l) < 0.2 * (hi_s - lo_s)
    assert metrics.bootstrap_interval(np.mean, small, seed=3) == metrics.bootstrap_interval(np.mean, small, seed=3)
    with pytest.raises(ValueError, match="same number of rows"):
        metrics.bootstrap_interval(lambda a, b: 0.0, small, large)


def test_bootstrap_interval_of_a_biased_statistic_contains_the_statistic():
    """FID grows when a resample repeats sequences; the bias-corrected interval still covers the FID."""
    rng = np.random.default_rng(1)
    a, reference = rng.normal(size=(40, 4)), rng.normal(size=(400, 4))
    fid = metrics.frechet_distance(a, reference)
    low, high = metrics.bootstrap_interval(lambda x: metrics.frechet_distance(x, reference), a)
    assert low <= fid <= high


def test_the_command_line_lists_stored_results_and_flags_a_stale_one(tmp_results, capsys):
    from facelib.__main__ import main
    _save("fresh_one")
    assert main(["results"]) == 0
    out = capsys.readouterr().out
    assert "fresh_one" in out and "ok" in out and "python -m facelib experiment demo" in out
    path = _save("stale_one")
    record = json.loads(path.read_text())
    record["checkpoints"]["ic_coma_I"] = "0" * 64
    path.write_text(json.dumps(record))
    assert main(["results"]) == 1
    out = capsys.readouterr().out
    assert "stale_one" in out and "STALE" in out and "ic_coma_I" in out


def test_markdown_table_merges_interval_columns_and_keeps_small_settings(tmp_results):
    _save(columns=["method", "lr", "Acc (%)", "95 % interval", "FID", "FID 95 % interval"],
          rows=[["ours", 0.0003, 80.0, [75.0, 85.0], 2.5, [1.0, 4.0]], ["GT", "", 85.0, [80.0, 90.0], 1.0, [0.5, 2.0]]])
    table = results.markdown_table(results.load_result("demo"))
    assert "| method | lr | Acc (%) [95 % interval] | FID [95 % interval] |" in table
    assert "| ours | 0.0003 | 80.00 [75.00, 85.00] | 2.50 [1.00, 4.00] |" in table
    chosen = results.markdown_table(results.load_result("demo"), columns=["FID", "FID 95 % interval", "method"])
    assert "| FID [95 % interval] | method |" in chosen and "| 2.50 [1.00, 4.00] | ours |" in chosen
    with pytest.raises(ValueError, match="demo has no column 'MM'"):
        results.markdown_table(results.load_result("demo"), columns=["method", "MM"])
    with pytest.raises(ValueError, match="interval column '95 % interval' must follow its value column 'Acc"):
        results.markdown_table(results.load_result("demo"), columns=["method", "95 % interval"])


def test_intervals_overlap_and_rows_as_dicts(tmp_results):
    assert metrics.intervals_overlap((1.0, 3.0), (2.0, 5.0)) and metrics.intervals_overlap((1.0, 2.0), (2.0, 3.0))
    assert not metrics.intervals_overlap((1.0, 2.0), (2.5, 3.0))
    assert [metrics.interval_order(a, (2.0, 3.0)) for a in ((0.5, 1.5), (2.5, 4.0), (3.5, 4.0))] == [
        "lower", "overlaps", "higher"]
    _save()
    assert results.row_dicts(results.load_result("demo")) == [
        {"method": "ours", "Acc (%)": 80.0, "95 % interval": [75.0, 85.0]}]


def test_a_stored_number_is_found_by_its_row_key_and_column_with_its_interval(tmp_results):
    _save(columns=["method", "steps", "Acc (%)", "95 % interval"],
          rows=[["ours", 50, 80.0, [75.0, 85.0]], ["ours", 200, 82.0, [77.0, 86.0]]])
    record = results.load_result("demo")
    assert results.stored_value(record, ("ours", 200), "Acc (%)") == 82.0
    assert results.stored_value(record, ("ours", 50), "Acc (%)", interval=True) == [75.0, 85.0]
    assert results.stored_cell(record, ("ours", 50), "Acc (%)") == "80 [75, 85]"
    with pytest.raises(KeyError, match=r"no row starts with \('ours', 100\).*\('ours', 50\)"):
        results.stored_row(record, ("ours", 100))
    with pytest.raises(KeyError, match="no column 'FID'"):
        results.stored_value(record, ("ours", 50), "FID")
    with pytest.raises(ValueError, match="the column after 'steps' holds no 95 % interval"):
        results.stored_value(record, ("ours", 50), "steps", interval=True)
    with pytest.raises(TypeError, match="a row key is a tuple"):
        results.stored_row(record, "ours")


def test_a_stored_tables_header_names_its_file_relative_to_the_project(monkeypatch):
    record = results.load_result(results.stored_results()[0])
    assert f"*Stored result* `results/{record['name']}.json`" in results.markdown_table(record)
    monkeypatch.setattr(results, "RESULTS_DIR", results.config.PROJECT_ROOT / "results" / "older")
    assert f"`results/older/{record['name']}.json`" in results.markdown_table(record)


def test_stored_numbers_keep_six_significant_digits_so_small_settings_survive():
    from facelib.results import _plain
    assert _plain({"kl_weight": 1e-05, "acc": np.float64(85.20710059), "rows": [0.000123456789]}) == \
        {"kl_weight": 1e-05, "acc": 85.2071, "rows": [0.000123457]}


def _fingerprints_file(monkeypatch, tmp_path, change):
    """Point the process at a copy of data/synthetic/fingerprints.json that ``change`` (a function of its
    entries) edited."""
    from facelib import config
    entries = json.loads((config.SYNTHETIC_DIR / "fingerprints.json").read_text())
    change(entries)
    (tmp_path / "synthetic").mkdir(parents=True)
    (tmp_path / "synthetic" / "fingerprints.json").write_text(json.dumps(entries, indent=2) + "\n")
    monkeypatch.setattr(config, "SYNTHETIC_DIR", tmp_path / "synthetic")


def test_a_new_dataset_leaves_every_stored_result_as_it_was(monkeypatch, tmp_path):
    records = {name: json.loads(results.result_path(name).read_text()) for name in results.stored_results()}
    before = {name: results.problems(record, f"{name}.json") for name, record in records.items()}
    _fingerprints_file(monkeypatch, tmp_path, lambda e: e.update({"speech-F40": {"num_sequences": 1}}))
    assert {name: results.problems(record, f"{name}.json") for name, record in records.items()} == before
    assert sum("datasets" in record.get("world", {}) for record in records.values()) > 20


def test_a_result_is_stale_when_a_dataset_it_recorded_changes_and_not_when_one_is_added(tmp_results,
                                                                                         monkeypatch):
    record = json.loads(_save().read_text())
    assert set(record["world"]["datasets"]) >= {"coma-F40", "bu-F40"} and results.problems(record) == []
    _fingerprints_file(monkeypatch, tmp_results, lambda e: e.update({"speech-F40": {"num_sequences": 1}}))
    assert results.problems(record) == []
    monkeypatch.undo()
    monkeypatch.setattr(results, "RESULTS_DIR", tmp_results)
    _fingerprints_file(monkeypatch, tmp_results / "changed", lambda e: e["bu-F40"].update(num_sequences=1))
    found = results.problems(record, "demo.json")
    assert len(found) == 1 and re.match(r"demo\.json: stale, made on world 2's dataset bu-F40 at fingerprint \w{12},"
                                        r" which is \w{12} now; re-run: python -m facelib experiment demo", found[0]), found
