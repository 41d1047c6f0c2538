"""The command line: python -m facelib data|train|sample TASK|neutral|animate."""
import dataclasses
import functools
import json
import re

import numpy as np
import pytest
import torch
import trimesh

from facelib import __main__ as cli, cli_sample, config, data, meshio as io, tasks, training
from facelib.__main__ import RECIPE_OPTIONS, build_parser, main, train_settings
from facelib.face import template as tpl


T = tpl.get_template()


def sample(out, *args):
    """Run ``python -m facelib sample ARGS --out OUT``; its arrays and the config it records."""
    assert main(["sample", *args, "--out", str(out)]) == 0
    with np.load(out) as f:
        arrays = {k: f[k] for k in f.files}
    return arrays, json.loads(str(arrays["config"]))


def test_cli_fill_and_geometry(tmp_path, coma_test, capsys):
    seq = tmp_path / "seq.npz"
    np.savez(seq, landmarks=coma_test.landmarks[0])
    out = tmp_path / "filled.npz"
    assert main(["sample", "fill", "--input", str(seq), "--known", "0:10,30:40", "--steps", "5",
                 "--out", str(out)]) == 0
    with np.load(out) as f:
        filled, known = f["landmarks"], f["known"]
    assert filled.shape == (1, 40, 68, 3) and known.sum() == 20
    assert np.array_equal(filled[0, :10], coma_test.landmarks[0, :10])
    neutral = tmp_path / "neutral.npz"
    np.savez(neutral, neutral=coma_test.subject_neutrals()[0])
    out = tmp_path / "geo.npz"
    assert main(["sample", "geometry", "--neutral", str(neutral), "--label", "mouth_open", "--n", "2",
                 "--passes", "1", "--steps", "5", "--out", str(out)]) == 0
    with np.load(out) as f:
        assert f["landmarks"].shape == (2, 40, 68, 3) and list(f["labels"]) == ["mouth_open N2E"] * 2
    with pytest.raises(SystemExit):
        main(["sample", "fill", "--input", str(seq), "--known", "0:40", "--out", str(out)])
    assert "no unknown frame" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["sample", "geometry", "--neutral", str(seq), "--label", "mouth_open", "--out", str(out)])
    assert "(68, 3)" in capsys.readouterr().err


def test_cli_label_task_writes_npz(tmp_path):
    out = tmp_path / "smile.npz"
    npz, _ = sample(out, "label", "--label", "high_smile", "--n", "2", "--steps", "5")
    assert npz["landmarks"].shape == (2, 40, 68, 3) and npz["landmarks"].dtype == np.float32
    assert list(npz["labels"]) == ["high_smile", "high_smile"]
    assert '"guidance_weight": 0.01' in str(npz["config"])
    assert f'"lr": {tasks.adagrad_lr("coma", 5)}' in str(npz["config"])
    with pytest.raises(SystemExit):
        main(["sample", "label", "--label", "grin", "--n", "2", "--steps", "5", "--out", str(out)])


def test_cli_long_runs_labels_on_their_data_and_texts_on_the_text_heads(tmp_path, coma_test, capsys):
    neutral = tmp_path / "neutral.npz"
    np.savez(neutral, neutral=coma_test.neutral_landmarks(int(coma_test.subjects[0])))
    out, common = tmp_path / "long.npz", ("--neutral", str(neutral), "--n", "1", "--steps", "2")
    npz, used = sample(out, "long", "--schedule", "mouth_open:1s, neutral:0.5s", *common, "--fps", "15")
    assert npz["landmarks"].shape == (1, 23, 68, 3) and used["checkpoint"] == "denoiser_coma"
    assert set(used["checkpoints"]) == {"denoiser_coma", "guide_coma_I", "guide_coma_S"}
    spec = "mouth_open:1s, 'a broad grin, then neutral':1.5s"
    npz, used = sample(out, "long", "--schedule", spec, *common)
    assert npz["landmarks"].shape == (1, 75, 68, 3) and used["schedule"] == spec
    assert set(used["checkpoints"]) == {"denoiser_coma+bu", "guide_coma+bu_text"}
    assert used["text_lr"] == pytest.approx(tasks.text_lr(2))
    assert used["text_guidance_weight"] == config.TEXT_GUIDANCE_WEIGHT
    assert [s["text"] for s in json.loads(str(npz["schedule"]))] == [False, True]
    npz, used = sample(out, "long", "--seconds", "2", "--join", "learned", *common)
    assert used["checkpoint"] == "denoiser_coma_join" and npz["landmarks"].shape == (1, 60, 68, 3)
    with pytest.raises(SystemExit):
        main(["sample", "long", "--schedule", spec, "--join", "learned", *common, "--out", str(tmp_path / "j.npz")])
    assert "denoiser_coma+bu_join of the 'coma+bu' data, and none is shipped" in capsys.readouterr().err
    assert not (tmp_path / "j.npz").exists()


def test_cli_text_task_writes_npz(tmp_path, capsys):
    out = tmp_path / "text.npz"
    npz, used = sample(out, "text", "--text", "disgust high smile", "--n", "2", "--steps", "5")
    assert npz["landmarks"].shape == (2, 40, 68, 3) and list(npz["texts"]) == ["disgust high smile"] * 2
    assert used["dataset"] == "coma+bu" and used["guide"] == "guide_coma+bu_text"
    assert used["lr"] == pytest.approx(tasks.text_lr(5))
    assert used["guidance_weight"] == config.TEXT_GUIDANCE_WEIGHT and used["head_input"] == "x_t"
    assert used["particles"] == 1 and used["max_time"] is None
    sad = ("text", "--text", "from sad to the neutral face")
    assert sample(out, *sad, "--n", "1", "--steps", "3", "--head-input", "x0_hat")[1]["head_input"] == "x0_hat"
    _, used = sample(out, *sad, "--n", "1", "--steps", "3", "--score", "contrastive")
    assert used["score"] == "contrastive" and used["guidance_weight"] == config.CONTRASTIVE_GUIDANCE_WEIGHT
    assert used["lr"] == pytest.approx(tasks.text_lr(3, score="contrastive"))
    npz, used = sample(out, *sad, "--n", "2", "--steps", "10", "--score", "contrastive", "--particles", "3",
                       "--max-time", "1400")
    assert used["particles"] == 3 and used["select_time"] == config.SELECT_TIME and used["max_time"] == 1400
    assert npz["landmarks"].shape == (2, 40, 68, 3)
    assert used["vocabulary"] is False
    assert sample(out, "text", "--text", "beaming", "--n", "1", "--steps", "3", "--score", "contrastive",
                  "--vocabulary")[1]["vocabulary"] is True
    with pytest.raises(SystemExit):
        main(["sample", "text", "--text", "beaming", "--n", "1", "--steps", "3", "--vocabulary",
              "--out", str(out)])
    assert "vocabulary is matched by the contrastive score" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["sample", "label", "--label", "happy", "--particles", "2", "--out", str(out)])
    assert "unrecognized arguments: --particles" in capsys.readouterr().err  # an option of text only
    npz, used = sample(out, "decoder", *sad[1:], "--n", "2", "--steps", "20", "--start", "400")
    assert used["task"] == "decoder" and used["start"] == 400 and used["guide"] == "motionclip_coma+bu"
    assert npz["landmarks"].shape == (2, 40, 68, 3)
    for extra in (["--lr", "0.1"], ["--head-input", "x0_hat"], ["--score", "contrastive"], ["--particles", "2"],
                  ["--vocabulary"]):  # options of Alg. 2, which the decoder route does not run
        with pytest.raises(SystemExit):
            main(["sample", "decoder", "--text", "sad", "--n", "1", "--steps", "5", *extra, "--out", str(out)])
        assert "unrecognized arguments" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["sample", "text", "--n", "2", "--out", str(out)])


def test_cli_sample_writes_npz(tmp_path):
    z, cfg = sample(tmp_path / "out.npz", "unconditional", "--n", "2", "--length", "30", "--steps", "4")
    assert z["landmarks"].shape == (2, 30, 68, 3) and z["landmarks"].dtype == np.float32
    assert cfg["steps"] == 4 and cfg["checkpoint"] == "denoiser_coma"
    z, cfg = sample(tmp_path / "ddim.npz", "unconditional", "--n", "2", "--steps", "4", "--sampler", "ddim",
                    "--eta", "0")
    assert cfg["sampler"] == "ddim" and cfg["eta"] == 0.0 and np.all(np.isfinite(z["landmarks"]))


def test_cli_train_writes_a_loadable_checkpoint(tmp_path, capsys):
    stem = tmp_path / "smoke"
    assert main(["train", "denoiser", "--steps", "3", "--out", str(stem)]) == 0
    d = tasks.load_denoiser(stem)
    assert d.meta["training"]["steps"] == 3 and len(d.meta["history"]["loss"]) >= 1
    assert "wrote" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["train", "classifier"])


def test_cli_train_reaches_every_setting_with_set(tmp_path, capsys):
    stem = tmp_path / "v"
    assert main(["train", "denoiser", "--steps", "2", "--out", str(stem), "--set", "prediction=v", "--set",
                 "min_snr_gamma=5", "--set", "mirror=0.5", "--set", "ema_decay=none", "--set",
                 "anatomy_pool=('coma',)"]) == 0
    training_record = tasks.load_denoiser(stem).meta["training"]
    assert (training_record["prediction"], training_record["min_snr_gamma"], training_record["mirror"],
            training_record["ema_decay"], training_record["anatomy_pool"]) == ("v", 5, 0.5, None, ["coma"])
    for bad, message in ((["--set", "predicton=v"], "NAME a setting of denoiser .*prediction"),
                         (["--set", "mirror=often"], "mirror: must be float, got 'often'"),
                         (["--set", "prediction=score"], "unknown prediction target 'score'; allowed: eps, x0, v, u"),
                         (["--set", "steps=4"], "repeats a setting"),
                         (["--set", "conditional=maybe"], "true or false")):
        with pytest.raises(SystemExit):
            main(["train", "denoiser", "--steps", "2", "--out", str(stem), *bad])
        assert re.search(message, capsys.readouterr().err)


def test_cli_data_prints_a_summary(capsys):
    assert main(["data", "--name", "coma"]) == 0
    out = capsys.readouterr().out
    assert "dataset 'coma': 689 sequences, 12 subjects" in out and "mouth_open" in out
    assert "fingerprint matches" in out


def test_cli_rejects_bad_arguments(capsys):
    with pytest.raises(SystemExit):
        main(["data", "--name", "cmoa"])
    assert "invalid choice: 'cmoa'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["data", "--frames", "1"])
    assert "num_frames must be in [2, 400]" in capsys.readouterr().err


def test_animate_writes_obj_frames_a_gif_and_the_landmarks(tmp_path, face_obj):
    out = tmp_path / "anim"
    assert cli.main(["animate", "--mesh", str(face_obj), "--label", "mouth_open", "--steps", "2",
                     "--out", str(out)]) == 0
    objs = sorted(out.glob("frame_*.obj"))
    assert len(objs) == 40 and (out / "animation.gif").stat().st_size > 1000
    first, last = (trimesh.load(p, process=False, maintain_order=True) for p in (objs[0], objs[-1]))
    np.testing.assert_array_equal(first.faces, T.faces)
    neutral = io.read_neutral_mesh(face_obj)
    assert np.abs(first.vertices - neutral).max() < 0.5  # N2E: frame 1 is (nearly) the neutral face
    assert np.abs(last.vertices - neutral).max() > 1.0  # and the face moves
    with np.load(out / "landmarks.npz") as f:
        assert f["landmarks"].shape == (1, 40, 68, 3)
        assert json.loads(str(f["config"]))["label"] == "mouth_open"


def test_animate_a_schedule_writes_real_time_frames_and_a_gif(tmp_path, face_obj):
    out = tmp_path / "anim"
    assert cli.main(["animate", "--mesh", str(face_obj), "--schedule", "mouth_open:1s, neutral:1s", "--fps", "20",
                     "--steps", "2", "--out", str(out)]) == 0
    objs = sorted(out.glob("frame_*.obj"))
    assert len(objs) == 40  # 2 s at 20 fps
    neutral = io.read_neutral_mesh(face_obj)
    first, last = (trimesh.load(p, process=False, maintain_order=True).vertices for p in (objs[0], objs[-1]))
    assert np.abs(first - neutral).max() < 0.5 and np.abs(last - neutral).max() < 0.5  # the rest ends on the face
    with np.load(out / "landmarks.npz") as f:
        assert f["landmarks"].shape == (1, 40, 68, 3)
        used = json.loads(str(f["config"]))
    assert used["schedule"] == "mouth_open:1s, neutral:1s" and used["fps"] == 20
    from PIL import Image
    with Image.open(out / "animation.gif") as gif:  # every 2nd frame, at 10 fps: real time
        assert gif.n_frames == 20 and gif.info["duration"] == 100


def test_animate_a_mesh_of_another_topology_units_and_pose(tmp_path):
    """A decimated face in cm, randomly rotated: registered, animated, written on its own vertices and triangles."""
    from facelib.face import scans
    scan = scans.make_scan(4547, remeshing="decimated", units="cm")
    path = tmp_path / "mine.obj"
    trimesh.Trimesh(scan.vertices, scan.faces, process=False).export(path)
    out = tmp_path / "anim"
    assert cli.main(["animate", "--mesh", str(path), "--label", "mouth_open", "--steps", "2", "--keep-template",
                     "--out", str(out)]) == 0
    objs = sorted(out.glob("frame_*.obj"))
    first, last = (trimesh.load(p, process=False, maintain_order=True) for p in (objs[0], objs[-1]))
    source = trimesh.load(path, process=False, maintain_order=True)
    np.testing.assert_array_equal(first.faces, source.faces)
    np.testing.assert_allclose(first.vertices, source.vertices, atol=1e-6)  # frame 0 is the input file
    assert np.abs(last.vertices - source.vertices).max() * 10 > 1.0  # in cm: the face moves by millimetres
    assert len(list((out / "template").glob("frame_*.obj"))) == 40
    assert json.loads((out / "registration.json").read_text())["units"] == "cm"


@pytest.mark.parametrize("args, message", [
    (["--label", "wink"], "unknown label"),
    (["--label", "mouth_open", "--mesh", "SPHERE"], "has 162 vertices; allowed: 300 to 200,000"),
    (["--label", "mouth_open", "--steps", "0"], "steps must be a positive integer, got 0"),
    (["--label", "mouth_open", "--fast"], "give --fast or --steps, not both"),
    ([], "give --label or --schedule"),
    (["--label", "mouth_open", "--schedule", "high_smile:2s"], "give --label or --schedule"),
    (["--label", "mouth_open", "--fps", "20"], "--fps is the frame rate of a --schedule"),
    (["--schedule", "high_smile:2s", "--order", "E2N"], "--fast and --order apply to a --label"),
    (["--schedule", "high_smile:2s", "--fps", "5"], "fps must be an integer in 10..60"),
    (["--schedule", "high_smile:2s", "--fps", "0"], "fps must be an integer in 10..60"),
    (["--schedule", "high_smile:50s, neutral:11s"], "takes at most 60 s"),
    (["--schedule", "wink:2s"], "unknown"),
    (["--schedule", "high_smile:2s; neutral:1s"], "schedule"),
])
def test_animate_refuses_bad_input_and_writes_nothing(tmp_path, face_obj, capsys, args, message):
    sphere = tmp_path / "sphere.obj"
    trimesh.creation.icosphere(2).export(sphere)
    argv = ["animate", "--mesh", str(face_obj), "--steps", "2", "--out", str(tmp_path / "out")] + args
    argv = [str(sphere) if a == "SPHERE" else a for a in argv]
    with pytest.raises(SystemExit) as e:
        cli.main(argv)
    assert e.value.code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_sampling_on_an_absent_gpu_is_a_clear_error(tmp_path, capsys):
    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    with pytest.raises(SystemExit):
        main(["sample", "unconditional", "--n", "1", "--steps", "2", "--device", "cuda",
              "--out", str(tmp_path / "x.npz")])
    assert "no CUDA device" in capsys.readouterr().err and not (tmp_path / "x.npz").exists()


def test_cli_classifier_free_label_control_and_edit(tmp_path, coma_test, capsys):
    stem = tmp_path / "cfg"
    assert main(["train", "denoiser", "--conditional", "--steps", "3", "--out", str(stem)]) == 0
    assert tasks.load_denoiser(stem).meta["class_names"] == list(coma_test.label_names)
    z, cfg = sample(tmp_path / "cfg.npz", "label", "--label", "eyebrow", "--guidance", "cfg", "--scale", "2",
                    "--checkpoint", str(stem), "--n", "2", "--steps", "3", "--sampler", "ddim")
    assert z["landmarks"].shape == (2, 40, 68, 3) and cfg["guidance"] == "cfg" and cfg["scale"] == 2.0
    assert cfg["guide"] is None and cfg["checkpoint"] == str(stem) and "lr" in cfg and cfg["lr"] is None
    out = tmp_path / "refused.npz"
    with pytest.raises(SystemExit):  # CFG with the unconditional denoiser
        main(["sample", "label", "--label", "eyebrow", "--guidance", "cfg", "--checkpoint", "denoiser_coma",
              "--n", "2", "--steps", "3", "--out", str(out)])
    assert "needs a label-conditional denoiser" in capsys.readouterr().err and not out.exists()
    seq = tmp_path / "seq.npz"
    np.savez(seq, landmarks=coma_test.landmarks[:2])
    edited = tmp_path / "edited.npz"
    assert main(["edit", "--input", str(seq), "--label", "mouth_open", "--steps", "4", "--out", str(edited)]) == 0
    with np.load(edited) as f:
        assert f["landmarks"].shape == (2, 40, 68, 3) and list(f["labels"]) == ["mouth_open"] * 2
        assert json.loads(str(f["config"]))["sampler"] == "ddim"
    np.savez(seq, landmarks=coma_test.landmarks[:1, :30])  # the recorded length is the input's
    assert main(["edit", "--input", str(seq), "--label", "mouth_open", "--steps", "4", "--out", str(edited)]) == 0
    with np.load(edited) as f:
        assert f["landmarks"].shape == (1, 30, 68, 3) and json.loads(str(f["config"]))["num_frames"] == 30
    bad = coma_test.landmarks[:1].copy()
    bad[0, 0, 0, 0] = np.nan
    np.savez(seq, landmarks=bad)
    for args, message in [([], "NaN or infinite"), (["--scale", "-1"], "scale must be a non-negative number"),
                          (["--keep", "0:40"], "keep holds every frame"),
                          (["--guidance", "cfg", "--dataset", "bu"], "train denoiser --conditional --dataset bu")]:
        if args:
            np.savez(seq, landmarks=coma_test.landmarks[:1])
        with pytest.raises(SystemExit):
            main(["edit", "--input", str(seq), "--label", "mouth_open", "--steps", "4", "--out", str(out), *args])
        assert message in capsys.readouterr().err and not out.exists()


def test_cli_keyframes_and_au_curves(tmp_path, coma_test, capsys, monkeypatch):
    neutral = coma_test.subject_neutrals()[0]
    keys = tmp_path / "keys.json"
    keys.write_text(json.dumps({"neutral": neutral.tolist(),
                                "keys": [{"frame": 20, "landmark": 57, "displacement": [0, -10, 0]}]}))
    arrays, used = sample(tmp_path / "keys.npz", "keyframes", "--constraints", str(keys), "--n", "2", "--steps", "4")
    assert arrays["landmarks"].shape == (2, 40, 68, 3) and used["method"] == "both"
    assert np.allclose(arrays["landmarks"][:, 20, 57], neutral[57] + [0, -10, 0], atol=1e-3)
    out = tmp_path / "bad.npz"
    keys.write_text(json.dumps({"keys": [{"frame": 40, "landmark": 57, "position": [0, 0, 0]}]}))
    with pytest.raises(SystemExit):
        main(["sample", "keyframes", "--constraints", str(keys), "--out", str(out)])
    assert "integer in 0..39" in capsys.readouterr().err and not out.exists()  # nothing written on failure
    absent = functools.partial(tasks.loading.load_au_regressor, name="au_regressor_coma_absent")
    monkeypatch.setattr(tasks.au, "load_au_regressor", absent)  # a missing regressor: named, with its command
    with pytest.raises(SystemExit):
        main(["sample", "au", "--curve", "AU12:0@0,0.8@20", "--out", str(out)])
    assert "au_regressor_coma_absent not found" in capsys.readouterr().err and not out.exists()


@pytest.mark.parametrize("task", list(cli_sample.TASKS))
def test_every_setting_of_a_task_is_an_option_with_its_help_and_default(task, capsys):
    """The command line is generated from the settings dataclasses: each field (but those set from the input) is
    an option whose help states its default; 'none' is offered only where the field allows None."""
    with pytest.raises(SystemExit):
        main(["sample", task, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    settings = cli_sample.TASKS[task].settings
    for f in dataclasses.fields(settings):
        if (task, f.name) in cli_sample.INTERNAL:
            continue
        option = "--" + f.name.replace("_", "-")
        assert option in text, f"sample {task}: no option for {f.name}"
        value = getattr(settings, f.name)
        assert f"default {'none' if value is None else value}" in text.split(option, 1)[1], (task, f.name)
        help = tasks.settings.option_text(type(settings), f.name, "help")
        assert ("'none'" not in help) or "None" in str(f.type), f"sample {task} --{f.name}: 'none' is not allowed"


def test_every_recipe_is_trainable_from_the_command_line(tmp_path):
    assert set(cli.TRAINABLE) == set(training.RECIPES)
    assert main(["train", "au_regressor", "--steps", "2", "--out", str(tmp_path / "r")]) == 0
    assert tasks.load_au_regressor(name=str(tmp_path / "r")).model is not None


def test_an_output_records_every_checkpoint_it_used_by_checksum(tmp_path):
    _, used = sample(tmp_path / "x.npz", "label", "--label", "high_smile", "--n", "1", "--steps", "2")
    assert set(used["checkpoints"]) == {"denoiser_coma", "guide_coma_I"}
    assert used["checkpoints"]["denoiser_coma"] == tasks.load_denoiser("denoiser_coma").meta["sha256"]
    assert used["checkpoints"]["guide_coma_I"] == tasks.load_guide("coma").meta["sha256"]


def test_sample_edit_is_the_old_edit_and_keeps_the_neutral_frame_by_default(tmp_path, coma_test):
    seq = tmp_path / "seq.npz"
    np.savez(seq, landmarks=coma_test.landmarks[:1])
    a, used = sample(tmp_path / "a.npz", "edit", "--input", str(seq), "--label", "mouth_open", "--steps", "3")
    assert main(["edit", "--input", str(seq), "--label", "mouth_open", "--steps", "3",
                 "--out", str(tmp_path / "b.npz")]) == 0
    with np.load(tmp_path / "b.npz") as f:
        np.testing.assert_array_equal(a["landmarks"], f["landmarks"])
    assert used["keep"] == "0:1"
    np.testing.assert_array_equal(a["landmarks"][0, 0], coma_test.landmarks[0, 0].astype(np.float32))
    b, used = sample(tmp_path / "c.npz", "edit", "--input", str(seq), "--label", "mouth_open", "--steps", "3",
                     "--keep", "none")
    assert used["keep"] is None and np.abs(b["landmarks"][0, 0] - coma_test.landmarks[0, 0]).max() > 1e-3


def _alternatives(settings, name, choices):
    """Valid values of one field other than its default: the other choices, the other flag, a changed number,
    None where the field allows it."""
    value = getattr(settings, name)
    if choices is not None:
        candidates = [c for c in choices if c != value]
    elif isinstance(value, bool):
        candidates = [not value]
    elif isinstance(value, int):
        candidates = [value + 1, max(value - 1, 0)]
    elif isinstance(value, float):
        candidates = [value * 2 + 0.25, value / 2]
    elif value is None:
        candidates = [3, 0.5, "0:2", "N2E"]
    elif name.endswith("dataset"):
        candidates = [d for d in data.MODEL_DATASETS if d != value]
    else:  # a text without choices (Edit's keep)
        candidates = [None, "0:2"]
    out = []
    for c in candidates:
        try:
            out.append(dataclasses.replace(settings, **{name: c}))
        except (ValueError, TypeError):
            continue
    return out


def _options(task, settings, names):
    """argv of `sample TASK` that gives ``names`` of ``settings`` as options, with placeholders for the inputs."""
    spec = cli_sample.TASKS[task]
    argv = ["sample", task, "--out", "x.npz"]
    for flags, kwargs in spec.inputs:
        if kwargs.get("required"):
            argv += [flags[0], "placeholder"]
    for name in names:
        value = getattr(settings, name)
        flag = "--" + name.replace("_", "-")
        if isinstance(value, bool):
            argv.append(flag if value else "--no-" + name.replace("_", "-"))
        else:
            argv += [flag, "none" if value is None else str(value)]
    return argv


@pytest.mark.parametrize("task", list(cli_sample.TASKS))
def test_every_settings_field_round_trips_through_its_option(task):
    """Settings -> options -> settings, for every field of every task: each field alone at each other valid value
    (and all at their defaults, and --paper's), the command line's settings equal the dataclass's, resolved once
    (Sampling.resolved) as the task resolves them."""
    parser = cli.build_parser()
    spec = cli_sample.TASKS[task]
    names = [f.name for f in dataclasses.fields(spec.settings) if (task, f.name) not in cli_sample.INTERNAL]
    cases = [(spec.settings, names, [])]
    if spec.in_paper:
        cases.append((spec.settings.paper(), [], ["--paper"]))
    for name in names:
        choices = tasks.settings.option_text(type(spec.settings), name, "choices")
        cases += [(s, [name], []) for s in _alternatives(spec.settings, name, choices)]
    if task == "text":  # the vocabulary is matched by the contrastive score only
        cases.append((dataclasses.replace(spec.settings, score="contrastive", vocabulary=True),
                      ["score", "vocabulary"], []))
    changed = set()
    for settings, given, extra in cases:
        args = parser.parse_args(_options(task, settings, given) + extra)
        changed.update(given if settings != spec.settings else ())
        try:
            expected = settings.resolved()
        except ValueError as e:  # a combination without a default (label control on coma+bu: no rate)
            with pytest.raises(ValueError, match=re.escape(str(e))):
                cli_sample.settings_of(args)
            continue
        assert cli_sample.settings_of(args) == expected, (task, given, extra)
    # every field but those fixed by another (Edit's sampler and eta) was changed at least once
    fixed = {"sampler", "eta"} if task == "edit" else {"eta"}
    assert set(names) - changed <= fixed, set(names) - changed



def _train_args(*argv):
    return build_parser().parse_args(["train", *argv])


# a valid value other than every recipe's default, per option of `train`
TRAIN_VALUES = {"dataset": "bu", "classifier_type": "S", "method": "s2d", "split": "expression",
                "steps": 7, "batch_size": 3, "seed": 5, "conditional": True}


@pytest.mark.parametrize("name", RECIPE_OPTIONS)
def test_every_train_option_sets_its_field_in_every_recipe_that_has_it(name):
    """`train MODEL --option VALUE` is the recipe's settings with that one field changed (the options are made
    from the recipes' fields by options.add_option), for every recipe that has the field; a recipe without it
    refuses the option by name."""
    train = build_parser()._subparsers._group_actions[0].choices["train"]
    flag = next(a for a in train._actions if a.dest == name).option_strings[0]
    value = TRAIN_VALUES[name]
    argv = [flag] if isinstance(value, bool) else [flag, str(value)]
    having = [m for m, cls in training.SETTINGS.items() if name in {f.name for f in dataclasses.fields(cls)}]
    for model in having:
        default = training.settings_for(model)
        if name == "steps" and default.epochs is not None:
            with pytest.raises(ValueError, match="set epochs, not steps"):
                train_settings(_train_args(model, *argv))
            continue
        chosen = train_settings(_train_args(model, *argv))
        # steps keeps the warm-up at most a tenth of the run (Optimisation.with_steps)
        assert chosen == (default.with_steps(value) if name == "steps" else
                          dataclasses.replace(default, **{name: value}))
    for model in set(training.SETTINGS) - set(having):
        with pytest.raises(ValueError, match=f"{model} has no setting {name}"):
            train_settings(_train_args(model, *argv))
    with pytest.raises(ValueError, match="train all trains the shipped checkpoints"):
        train_settings(_train_args("all", *argv))


def test_a_recipe_setting_with_choices_refuses_another_value_by_name():
    """--set reaches the fields that have an option too; their choices are checked by the settings themselves."""
    for model, assignment, allowed in (("guide", "dataset=coma2", "coma', 'bu', 'coma+bu', 'coma+crowd'"),
                                       ("deformer", "method=ours2", "ours', 'no_attention'"),
                                       ("deformer", "split=people", "identity', 'expression'"),
                                       ("evaluator", "classifier_type=X", "I', 'S'")):
        with pytest.raises(ValueError, match=re.escape(allowed)):
            train_settings(_train_args(model, "--set", assignment))
    with pytest.raises(ValueError, match="--only and --missing pick checkpoints of train all"):
        train_settings(_train_args("guide", "--missing"))
