"""Checkpoints: weights + JSON config, sha256 and architecture checked."""
import json

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
