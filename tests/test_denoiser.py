import json

import numpy as np
import pytest
import torch

from facelib import data, tasks
from facelib.__main__ import main
from facelib.checkpoints import load_checkpoint, save_checkpoint
from facelib.models.denoiser import Denoiser, DenoiserConfig
from facelib.training import Draws, swap_anatomy, training_anatomies

SMALL = DenoiserConfig(width=32, depth=2, heads=2, ff=64)
PLAIN = DenoiserConfig(width=32, depth=2, heads=2, ff=64, gaussian_skip=False)  # output layer not zeroed


def test_any_length_and_shape():
    m = Denoiser(SMALL).eval()
    for f in (2, 20, 40, 57, 80):
        x = torch.randn(3, f, 68, 3)
        assert m(x, torch.tensor([1.0, 500.0, 2000.0])).shape == x.shape


def test_padded_frames_do_not_change_the_valid_ones():
    torch.manual_seed(0)
    m = Denoiser(PLAIN).eval()
    x = torch.randn(1, 40, 68, 3)
    padded = torch.cat([x, torch.randn(1, 5, 68, 3) * 10], dim=1)
    mask = torch.tensor([[True] * 40 + [False] * 5])
    t = torch.tensor([300.0])
    with torch.no_grad():
        torch.testing.assert_close(m(padded, t, mask)[:, :40], m(x, t), atol=1e-5, rtol=1e-4)


def test_attention_is_bidirectional():
    torch.manual_seed(0)
    m = Denoiser(PLAIN).eval()
    x = torch.randn(1, 40, 68, 3)
    y = x.clone()
    y[:, 30] += 1.0  # a change in the future...
    t = torch.tensor([100.0])
    with torch.no_grad():
        assert (m(x, t)[:, 5] - m(y, t)[:, 5]).abs().max() > 1e-4  # ...is seen by an earlier frame


def test_normalizer_is_invertible(coma_train):
    norm = data.LandmarkNormalizer.fit(coma_train)
    z = norm.normalize(coma_train.landmarks[:10])
    assert abs(float(norm.normalize(coma_train.landmarks).std()) - 1) < 0.05
    np.testing.assert_allclose(norm.denormalize(z), coma_train.landmarks[:10], atol=1e-4)
    zt = norm.normalize(torch.as_tensor(coma_train.landmarks[:10]))
    np.testing.assert_allclose(norm.denormalize(zt).numpy(), coma_train.landmarks[:10], atol=1e-4)
    again = data.LandmarkNormalizer.from_dict(json.loads(json.dumps(norm.to_dict())))
    np.testing.assert_allclose(again.normalize(coma_train.landmarks[:2]), norm.normalize(coma_train.landmarks[:2]))


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


def test_shipped_denoisers_load_and_sample_deterministically():
    for name in ("denoiser_coma", "denoiser_coma_var"):
        d = tasks.load_denoiser(name)
        assert d.meta["training"]["num_diffusion_steps"] == 2000 and d.meta["training"]["schedule"] == "linear"
    d = tasks.load_denoiser()
    a = tasks.unconditional(2, num_frames=24, seed=4, steps=5, denoiser=d, progress=False)
    b = tasks.unconditional(2, num_frames=24, seed=4, steps=5, denoiser=d, progress=False)
    assert a.shape == (2, 24, 68, 3) and a.dtype == np.float32
    np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="n must be a positive integer"):
        tasks.unconditional(0, denoiser=d)
    with pytest.raises(ValueError, match="num_frames must be in"):
        tasks.unconditional(2, num_frames=1, denoiser=d)


def test_cli_sample_writes_npz(tmp_path):
    out = tmp_path / "out.npz"
    assert main(["sample", "unconditional", "--n", "2", "--length", "30", "--steps", "4",
                 "--out", str(out)]) == 0
    z = np.load(out)
    assert z["landmarks"].shape == (2, 30, 68, 3) and z["landmarks"].dtype == np.float32
    cfg = json.loads(str(z["config"]))
    assert cfg["steps"] == 4 and cfg["checkpoint"] == "denoiser_coma"


def test_cli_train_writes_a_loadable_checkpoint(tmp_path, capsys):
    stem = tmp_path / "smoke"
    assert main(["train", "denoiser", "--steps", "3", "--out", str(stem)]) == 0
    d = tasks.load_denoiser(stem)
    assert d.meta["training"]["steps"] == 3 and len(d.meta["history"]["loss"]) >= 1
    assert "wrote" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["train", "classifier"])


def test_gaussian_estimate_is_the_optimal_noise_estimate_for_gaussian_frames():
    """With the transformer output at zero, eps_theta is E[eps | x_t] for frames ~ N(0, Sigma)."""
    torch.manual_seed(0)
    m = Denoiser(SMALL).eval()
    a = torch.randn(204, 6) * torch.tensor([3.0, 2.0, 1.0, 0.5, 0.2, 0.1])
    frames = (torch.randn(20_000, 6) @ a.T).reshape(-1, 68, 3)
    m.fit_prior(frames)
    x0 = frames[:4000].reshape(200, 20, 68, 3)
    for t in (50, 400, 1500):
        eps = torch.randn_like(x0)
        abar = float(m.alphas_bar[t])
        xt = abar ** 0.5 * x0 + (1 - abar) ** 0.5 * eps
        with torch.no_grad():
            mse = ((m(xt, torch.full((200,), float(t))) - eps) ** 2).mean().item()
        lam = m.prior_variances.double()
        optimum = 1 - ((1 - abar) / (abar * lam + 1 - abar)).mean().item()  # per-dimension posterior variance
        assert mse == pytest.approx(optimum, abs=0.01)
        assert mse < ((xt * (1 - abar) ** 0.5 - eps) ** 2).mean().item()  # beats the isotropic estimate


@pytest.mark.parametrize("shape, t_shape, message", [
    ((2, 40, 204), (2,), "x_t must have shape"),
    ((2, 40, 60, 3), (2,), "x_t must have shape"),
    ((2, 40, 68, 3), (3,), "t must have shape"),
])
def test_denoiser_rejects_bad_shapes(shape, t_shape, message):
    with pytest.raises(ValueError, match=message):
        Denoiser(SMALL)(torch.zeros(shape), torch.zeros(t_shape))


def test_anatomy_augmentation_keeps_the_motion_and_swaps_the_neutral_face(coma_train):
    pool = torch.as_tensor(training_anatomies(("coma", "bu")))
    assert pool.shape == (9 + 81, 68, 3)
    x = torch.as_tensor(coma_train.landmarks[:6])
    own = torch.as_tensor(np.stack([coma_train.neutral_landmarks(int(s)) for s in coma_train.subjects[:6]]))
    draws = Draws(torch.Generator().manual_seed(0), len(x))
    assert torch.equal(swap_anatomy(x, own, pool, 0.0, draws), x)
    swapped = swap_anatomy(x, own, pool, 1.0, draws)
    shift = swapped - x
    assert torch.allclose(shift, shift[:, :1].expand_as(shift), atol=1e-4)  # the same offset in every frame
    new_neutral = own + shift[:, 0]
    dist = (new_neutral[:, None] - pool[None]).norm(dim=-1).mean(-1).min(1).values
    assert (dist < 1e-4).all()  # the new neutral face is one of the pool's


def test_rig_fit_recovers_a_known_face(coma_train):
    from facelib import rig_fit
    seq = coma_train.landmarks[3]
    face = coma_train.face(int(coma_train.subjects[3]))
    meshes, rmse = rig_fit.landmarks_to_meshes(seq, [face])
    assert meshes.shape == (40, coma_train.meshes(3).shape[1], 3)
    assert rmse < 0.6  # about the capture noise of the landmarks
    assert np.linalg.norm(meshes - coma_train.meshes(3), axis=-1).mean() < 0.3
