"""Checkpoints: weights + JSON config, sha256 and architecture checked."""
import pytest
import torch

from facelib.checkpoints import load_checkpoint, save_checkpoint
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
