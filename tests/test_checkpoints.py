"""Checkpoints: weights + JSON config, sha256 and architecture checked."""
import json
import re

import pytest
import torch

from facelib import config
from facelib.checkpoints import load_checkpoint, save_checkpoint, world_fingerprint
from facelib.models.denoiser import Denoiser, DenoiserConfig


SMALL = DenoiserConfig(width=32, depth=2, heads=2, ff=64)


def test_checkpoint_roundtrip_and_errors(tmp_path):
    m = Denoiser(SMALL)
    stem = tmp_path / "tiny"
    save_checkpoint(stem, m, "denoiser", SMALL.__dict__, note="test")
    build = lambda c: Denoiser(DenoiserConfig(**c))  # noqa: E731
    loaded, meta = load_checkpoint(stem, "denoiser", build)
    assert meta["note"] == "test"
    for k, v in m.state_dict().items():
        torch.testing.assert_close(loaded.state_dict()[k], v)
    with pytest.raises(ValueError, match="is a 'denoiser' checkpoint, expected 'classifier'"):
        load_checkpoint(stem, "classifier", build)
    with pytest.raises(ValueError, match="does not fit a denoiser"):
        load_checkpoint(stem, "denoiser", lambda c: Denoiser(DenoiserConfig(**{**c, "depth": 3})))
    with pytest.raises(ValueError, match="does not fit a denoiser"):
        load_checkpoint(stem, "denoiser", lambda c: Denoiser(DenoiserConfig(**{**c, "width": 48})))
    raw = bytearray(stem.with_suffix(".pt").read_bytes())
    raw[-20] ^= 0xFF
    stem.with_suffix(".pt").write_bytes(bytes(raw))
    with pytest.raises(ValueError, match="corrupted or does not match its metadata"):
        load_checkpoint(stem, "denoiser", build)
    with pytest.raises(FileNotFoundError, match="not found"):
        load_checkpoint(tmp_path / "missing", "denoiser", build)


def _with_world(stem, world):
    js = stem.with_suffix(".json")
    meta = json.loads(js.read_text())
    meta["world"] = world
    js.write_text(json.dumps(meta))


def test_a_checkpoint_of_another_world_is_refused_naming_both_worlds_and_the_retrain_command(tmp_path):
    stem = tmp_path / "tiny"
    save_checkpoint(stem, Denoiser(SMALL), "denoiser", SMALL.__dict__)
    build = lambda c: Denoiser(DenoiserConfig(**c))  # noqa: E731
    here = world_fingerprint()
    assert json.loads(stem.with_suffix(".json").read_text())["world"] == here
    other = 1  # the book runs on world 2; world 1's checkpoints were retrained (issue 25)
    _with_world(stem, {"version": other, "fingerprint": "0123456789ab"})
    with pytest.raises(ValueError, match=rf"trained on world {other}, but this process builds world {config.WORLD}"):
        load_checkpoint(stem, "denoiser", build)
    _with_world(stem, {"version": config.WORLD, "fingerprint": "0123456789ab"})  # same version, other datasets
    with pytest.raises(ValueError, match="datasets as they were .fingerprint 0123456789ab.; they have changed"):
        load_checkpoint(stem, "denoiser", build)
    _with_world(stem, here)
    load_checkpoint(stem, "denoiser", build)


def test_a_checkpoint_from_before_the_world_was_recorded_is_world_1_and_refused(tmp_path):
    assert config.WORLD == 2 and config.CHECKPOINT_DIR.name == "world2"
    stem = tmp_path / "old"
    save_checkpoint(stem, Denoiser(SMALL), "denoiser", SMALL.__dict__)
    meta = json.loads(stem.with_suffix(".json").read_text())
    del meta["world"]  # world 1's checkpoints predate the record
    stem.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"trained on world 1, .*train all --missing --only old"):
        load_checkpoint(stem, "denoiser", lambda c: Denoiser(DenoiserConfig(**c)))


def test_an_installed_package_without_the_data_folder_says_where_to_point_it(monkeypatch, tmp_path):
    from facelib import checkpoints, config
    monkeypatch.setattr(config, "DATA_DIR", tmp_path / "absent")
    with pytest.raises(FileNotFoundError, match="set FACELIB_DATA_DIR to the data/ folder of a clone"):
        checkpoints.load_checkpoint("denoiser_coma", "denoiser", lambda c: None)


def _fingerprints_file(monkeypatch, tmp_path, change):
    """Point the process at a copy of data/synthetic/fingerprints.json that ``change``
    (a function of its entries) edited."""
    entries = json.loads((config.SYNTHETIC_DIR / "fingerprints.json").read_text())
    change(entries)
    (tmp_path / "fingerprints.json").write_text(json.dumps(entries, indent=2, sort_keys=True) + "\n")
    monkeypatch.setattr(config, "SYNTHETIC_DIR", tmp_path)


def _add_a_dataset(entries):
    entries["speech-F40"] = {**entries["coma-F40"], "num_sequences": 1, "metadata_sha256": "0" * 64}


def _change_coma(entries):
    entries["coma-F40"]["num_sequences"] += 1


def _shipped_metadata():
    return {js.stem: json.loads(js.read_text()) for js in sorted(config.CHECKPOINT_DIR.glob("*.json"))}


def test_a_checkpoint_records_the_fingerprints_of_the_datasets_it_read(tmp_path):
    from facelib.checkpoints import dataset_fingerprints, datasets_read
    digests = dataset_fingerprints()
    assert {"coma-F40", "bu-F40"} <= set(digests) and all(len(d) == 12 for d in digests.values())
    assert datasets_read({"kind": "denoiser", "training": {"dataset": "coma+bu"}}) == ["bu-F40", "coma-F40"]
    assert datasets_read({"kind": "guide", "training": {"dataset": "bu"}}) == ["bu-F40"]
    assert datasets_read({"kind": "deformer", "training": {}}) == datasets_read(
        {"kind": "denoiser", "training": {"dataset": config.DEFORMATION_DATASET}})
    stem = tmp_path / "tiny"
    save_checkpoint(stem, Denoiser(SMALL), "denoiser", SMALL.__dict__, training={"dataset": "bu"})
    world = json.loads(stem.with_suffix(".json").read_text())["world"]
    assert world == {**world_fingerprint(), "datasets": {"bu-F40": digests["bu-F40"]}}
    for name, meta in _shipped_metadata().items():  # the shipped ones record what they read
        if meta["world"]["fingerprint"] is not None:
            assert meta["world"]["datasets"] == {k: digests[k] for k in datasets_read(meta)}, name


def test_a_new_dataset_leaves_every_shipped_checkpoint_loadable(monkeypatch, tmp_path):
    from facelib.checkpoints import check_world
    _fingerprints_file(monkeypatch, tmp_path, _add_a_dataset)
    shipped = _shipped_metadata()
    assert len(shipped) > 40
    for name, meta in shipped.items():
        check_world(meta, f"{name}.pt")
    assert "speech-F40" in world_fingerprint()["datasets"]


def test_a_changed_dataset_refuses_only_the_checkpoints_that_read_it(monkeypatch, tmp_path):
    from facelib import checkpoints
    from facelib.checkpoints import check_world
    shipped = _shipped_metadata()
    _fingerprints_file(monkeypatch, tmp_path, _change_coma)
    for name in ("denoiser_bu", "guide_bu_I", "ic_bu_S", "actor_bu"):
        check_world(shipped[name], f"{name}.pt")
    before = shipped["denoiser_coma"]["world"]["datasets"]["coma-F40"]
    after = checkpoints.dataset_fingerprints()["coma-F40"]
    assert after != before
    for name in ("denoiser_coma", "denoiser_coma+bu", "deform_ours_expression", "student_denoiser_coma_1"):
        with pytest.raises(ValueError, match=rf"checkpoint {re.escape(name)}\.pt was trained on world 2's datasets"
                                             rf" as they were; they have changed since: coma-F40 \(fingerprint"
                                             rf" {before}, now {after}\); retrain it .*--only {re.escape(name)}`"):
            check_world(shipped[name], f"{name}.pt")
    _fingerprints_file(monkeypatch, tmp_path, lambda entries: entries.pop("bu-F40"))
    with pytest.raises(ValueError, match=r"bu-F40 \(fingerprint \w{12}, now no entry in fingerprints.json\)"):
        check_world(shipped["denoiser_bu"], "denoiser_bu.pt")


def test_a_checkpoint_is_hashed_once_until_its_file_changes_and_a_corrupted_one_is_still_refused(
        tmp_path, monkeypatch):
    import os
    import time
    from facelib import checkpoints
    stem = tmp_path / "tiny"
    pt = stem.with_suffix(".pt")
    build = lambda c: Denoiser(DenoiserConfig(**c))  # noqa: E731
    hashed = []
    real = checkpoints._sha256
    monkeypatch.setattr(checkpoints, "_sha256", lambda path: hashed.append(path) or real(path))

    def save(seed, mtime_ns):
        torch.manual_seed(seed)
        save_checkpoint(stem, Denoiser(SMALL), "denoiser", SMALL.__dict__)
        os.utime(pt, ns=(mtime_ns, mtime_ns))  # written a while ago (a fresh file is hashed every time)
        hashed.clear()

    old = time.time_ns() - 60 * 10**9
    save(0, old)
    first = load_checkpoint(stem, "denoiser", build)[0].state_dict()
    load_checkpoint(stem, "denoiser", build)
    assert len(hashed) == 1
    save(1, old + 10**9)  # rewritten: new bytes, new mtime
    second = load_checkpoint(stem, "denoiser", build)[0].state_dict()
    load_checkpoint(stem, "denoiser", build)
    assert len(hashed) == 1 and any(not torch.equal(first[k], second[k]) for k in first)
    raw = bytearray(pt.read_bytes())
    raw[-20] ^= 0xFF
    pt.write_bytes(bytes(raw))  # same size, new mtime
    with pytest.raises(ValueError, match="corrupted or does not match its metadata"):
        load_checkpoint(stem, "denoiser", build)
    os.utime(pt, ns=(old + 2 * 10**9, old + 2 * 10**9))
    with pytest.raises(ValueError, match="corrupted or does not match its metadata"):
        load_checkpoint(stem, "denoiser", build)
