"""Expression filling (Alg. 3) and geometry-adaptive generation (Alg. 4): masks, the known-frame
step, the baselines, the seam metric, the tasks and the CLI."""
import numpy as np
import pytest
import torch

from facelib import baselines, data, inpainting, metrics, tasks
from facelib.__main__ import main
from facelib.diffusion import GaussianDiffusion, linear_betas
from facelib.models.lstm_filler import masked_l1
from facelib.training.recipes import random_masks


@pytest.fixture(scope="module")
def coma_test():
    return data.load_dataset("coma", "test")


@pytest.fixture(scope="module")
def denoiser():
    return tasks.load_denoiser("denoiser_coma")


def test_parse_known_and_mask_errors():
    m = inpainting.parse_known("0:10,30:40", 40)
    assert m.sum() == 20 and m[:10].all() and m[30:].all() and not m[10:30].any()
    assert inpainting.parse_known("5", 8).tolist() == [False] * 5 + [True] + [False] * 2
    for spec, msg in [("0:50", "outside 0:40"), ("a:b", "cannot read"), ("", "ranges like"), ("0:40", "no unknown")]:
        with pytest.raises(ValueError, match=msg):
            inpainting.parse_known(spec, 40)
    with pytest.raises(ValueError, match="no known frame"):
        inpainting.check_known_mask(np.zeros(40, bool))
    with pytest.raises(ValueError, match="has 30 frames but the sequence has 40"):
        inpainting.check_known_mask(np.ones(30, bool), 40)
    with pytest.raises(ValueError, match="boolean"):
        inpainting.check_known_mask(np.full(40, 0.5))


@pytest.mark.parametrize("setting", inpainting.FILL_SETTINGS)
def test_fill_masks_follow_section_5_3(setting):
    m = inpainting.fill_masks(setting, 500, 40, seed=1)
    n_known = m.sum(1)
    if setting == "FFM":  # l ~ U[5, 15] at each end
        assert m[:, 0].all() and m[:, -1].all() and not m[:, 19:21].any()
        assert n_known.min() == 10 and n_known.max() == 30 and (n_known % 2 == 0).all()
    else:  # l ~ U[10, 30]; FFB fills the beginning (the end is known), FFE fills the end
        assert (m[:, -1] if setting == "FFB" else m[:, 0]).all()
        assert n_known.min() == 10 and n_known.max() == 30
    with pytest.raises(ValueError, match="allowed: FFB, FFE, FFM"):
        inpainting.fill_masks("FFX", 2)


@pytest.mark.parametrize("t", [2, 10, 700])
@pytest.mark.parametrize("respaced", [False, True])
def test_known_frames_at_step_t_minus_1_have_the_exact_marginal_of_q(t, respaced):
    # Alg. 3 line 12 (with the errata's abar): after the reverse step t, the known frames are
    # x_{t-1} ~ N(sqrt(abar_{t-1}) x_0, (1 - abar_{t-1}) I).  At small t the traps are visible: abar_t
    # instead of abar_{t-1} doubles the variance at t = 2; alpha instead of abar, or the std used as
    # a variance, are off by orders of magnitude.
    diffusion = GaussianDiffusion(linear_betas(2000))
    if respaced:
        diffusion = diffusion.respace(100)
        t = min(t, 100)
    n = 20000
    x0 = torch.full((n, 2, 68, 3), 0.7, dtype=torch.float64)
    known = torch.tensor([[True, False]]).expand(n, 2)
    hook = inpainting.KnownFrames(diffusion, x0, known, torch.Generator().manual_seed(0))
    x_hat = torch.full_like(x0, 123.0)
    x = hook(x_hat, None, t, None)
    assert (x[:, 1] == 123.0).all()  # unknown frames: the model's sample, untouched
    k = x[:, 0].flatten()
    abar = diffusion.alphas_bar[t - 1]
    var, mean = k.var().item(), k.mean().item()
    assert abs(var / (1 - abar) - 1) < 0.02, (var, 1 - abar)
    assert abs(mean - np.sqrt(abar) * 0.7) < 4 * np.sqrt((1 - abar) / k.numel()) + 1e-12
    assert torch.equal(hook(x_hat, None, 1, None)[:, 0], x0[:, 0])  # at t = 1, x_0|S_K is the data itself


def test_mean_imputation_and_interpolation():
    f = np.arange(10, dtype=np.float64)
    x = np.broadcast_to(f[:, None, None] * np.array([1.0, -2.0, 0.5]), (10, 68, 3))[None].copy()
    known = np.zeros(10, bool)
    known[[0, 1, 8, 9]] = True
    lin = inpainting.linear_interpolation(x, known)
    np.testing.assert_allclose(lin, x, atol=1e-5)  # a linear motion is filled exactly
    mean = inpainting.mean_imputation(x, known)
    np.testing.assert_allclose(mean[0, 4], x[0, [0, 1, 8, 9]].mean(0), atol=1e-5)
    x_nan = x.copy()
    x_nan[0, ~known] = np.nan  # unknown frames may be missing values
    assert np.isfinite(inpainting.linear_interpolation(x_nan, known)).all()
    assert np.isfinite(inpainting.mean_imputation(x_nan, known)).all()
    head = np.zeros(10, bool)
    head[6:] = True  # FFB: frames before the first known one hold it
    np.testing.assert_allclose(inpainting.linear_interpolation(x, head)[0, :6], np.broadcast_to(x[0, 6], (6, 68, 3)), atol=1e-5)
    bad = x.copy()
    bad[0, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="known frames contain NaN"):
        inpainting.mean_imputation(bad, known)
    with pytest.raises(ValueError, match=r"\(n, frames, 68, 3\)"):
        inpainting.mean_imputation(np.zeros((2, 10, 67, 3)), known)


def test_seam_step_is_the_motion_across_the_seam():
    f = np.arange(12, dtype=np.float64)
    x = np.zeros((1, 12, 68, 3))
    x[0, :, :, 0] = f[:, None]  # every landmark moves 1 mm per frame
    known = np.zeros(12, bool)
    known[:4] = True
    assert np.allclose(metrics.seam_steps(x, known), 1.0)
    assert np.allclose(metrics.frame_speeds(x), 1.0) and metrics.frame_speeds(x).shape == (1, 11)
    y = x.copy()
    y[0, 4:, :, 0] += 2.0  # the generated part starts 2 mm off: one 3 mm step at the seam
    assert np.allclose(metrics.seam_steps(y, known), 3.0)
    both = np.zeros(12, bool)
    both[[0, 1, 10, 11]] = True  # two seams
    assert len(metrics.seam_steps(x, both)) == 2
    assert metrics.missing_frame_error(y, x, known) == pytest.approx(2.0)


def test_masked_l1_is_berson_eq_1_and_training_masks_mix_layouts():
    pred, target = torch.zeros(1, 4, 68, 3), torch.ones(1, 4, 68, 3)
    target[:, 2:] = 3.0
    known = torch.tensor([[True, True, False, False]])
    assert masked_l1(pred, target, known, alpha_gt=10.0).item() == pytest.approx(10 * 1.0 + 3.0)
    masks = random_masks(400, 40, torch.Generator().manual_seed(0))
    assert masks.shape == (400, 40) and masks.any(1).all() and (~masks).any(1).all()
    assert len({tuple(m.tolist()) for m in masks}) > 100


def test_fill_keeps_known_frames_exactly_and_is_deterministic(coma_test, denoiser):
    x = coma_test.landmarks[:3].copy()
    known = inpainting.fill_masks("FFM", 3, 40, seed=0)
    x[~known] = np.nan  # the unknown frames are not read
    a = tasks.fill(x, known, steps=10, seed=3, denoiser=denoiser, progress=False)
    b = tasks.fill(x, known, steps=10, seed=3, denoiser=denoiser, progress=False)
    assert a.shape == (3, 40, 68, 3) and a.dtype == np.float32 and np.isfinite(a).all()
    assert np.array_equal(a[known], coma_test.landmarks[:3][known])
    assert np.array_equal(a, b)
    c = tasks.fill(x, known, steps=10, seed=4, denoiser=denoiser, progress=False)
    assert not np.allclose(a[~known], c[~known])  # another seed, another completion
    with pytest.raises(ValueError, match="no unknown frame"):
        tasks.fill(x, np.ones((3, 40), bool), denoiser=denoiser)
    with pytest.raises(ValueError, match="has 30 frames but the sequence has 40"):
        tasks.fill(x, np.ones(30, bool), denoiser=denoiser)


def test_geometry_adaptive_keeps_the_neutral_frame_and_checks_input(coma_test, denoiser):
    guide = tasks.load_guide("coma", "S")
    neutral = coma_test.subject_neutrals()[0]
    out = tasks.geometry_passes(neutral, "mouth_open", n=2, steps=8, passes=2, denoiser=denoiser, guide=guide,
                                progress=False)
    assert out.shape == (2, 2, 40, 68, 3)
    assert np.array_equal(out[:, :, 0], np.broadcast_to(neutral, (2, 2, 68, 3)).astype(np.float32))
    e2n = tasks.geometry_adaptive(neutral, "mouth_open E2N", n=1, steps=8, passes=1, denoiser=denoiser, guide=guide,
                                  progress=False)
    assert np.array_equal(e2n[0, -1], neutral.astype(np.float32))  # E2N: S_K = {F}
    for bad, msg in [(dict(neutral_landmarks=neutral[:67]), r"\(68, 3\)"),
                     (dict(neutral_landmarks=np.full((68, 3), np.nan)), "NaN"),
                     (dict(label="smile"), "allowed: bareteeth N2E"),
                     (dict(order="sideways"), "order must be one of"),
                     (dict(passes=0), "passes must be a positive integer"),
                     (dict(renoise_step=9), "renoise_step must be in 1..8")]:
        kwargs = dict(neutral_landmarks=neutral, label="mouth_open", steps=8, passes=1, denoiser=denoiser,
                      guide=guide, progress=False) | bad
        with pytest.raises(ValueError, match=msg):
            tasks.geometry_adaptive(**kwargs)


def test_lstm_filler_keeps_known_frames(coma_test):
    known = inpainting.fill_masks("FFE", 4, 40, seed=0)
    out = baselines.lstm_fill(coma_test.landmarks[:4], known)
    assert out.shape == (4, 40, 68, 3) and np.isfinite(out).all()
    assert np.array_equal(out[known], coma_test.landmarks[:4][known])
    # it does better than holding the last known frame on the missing ones
    hold = inpainting.linear_interpolation(coma_test.landmarks[:4], known)
    assert metrics.missing_frame_error(out, coma_test.landmarks[:4], known) < 2 * metrics.missing_frame_error(
        hold, coma_test.landmarks[:4], known)


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


def test_reconstruction_guidance_pulls_the_estimate_towards_the_known_frame(denoiser, coma_test):
    from facelib.guidance import ReconstructionGuidance, chain
    diffusion = denoiser.diffusion_with(50)
    x0 = torch.as_tensor(denoiser.normalizer.normalize(np.repeat(coma_test.subject_neutrals()[:2, None], 40, 1)))
    known = torch.zeros(2, 40, dtype=torch.bool)
    known[:, 0] = True
    xt = diffusion.q_sample(torch.as_tensor(denoiser.normalizer.normalize(coma_test.landmarks[5:7])), torch.tensor([20, 20]),
                            generator=torch.Generator().manual_seed(0))  # a sequence of other faces, noised

    def known_error(x, t):
        with torch.no_grad():
            eps = denoiser.model(x, diffusion.model_time(t, 2))
            return ((diffusion.predict_x0(x, t, eps) - x0)[:, 0] ** 2).sum((1, 2))

    hook = ReconstructionGuidance(denoiser.model, diffusion, x0, known, scale=0.05)
    moved = hook(xt, xt, 20, None)  # x_hat = x_t: the step alone
    assert (known_error(moved, 20) < known_error(xt, 20)).all()
    assert torch.equal(chain(None, hook)(xt, xt, 20, None), moved)
    with pytest.raises(ValueError, match="non-negative"):
        ReconstructionGuidance(denoiser.model, diffusion, x0, known, scale=-1.0)


def test_resampling_is_checked_and_one_means_plain_alg_3(coma_test, denoiser):
    x, known = coma_test.landmarks[:2], inpainting.fill_masks("FFE", 2, 40, seed=1)
    plain = tasks.fill(x, known, steps=6, seed=0, denoiser=denoiser, progress=False)
    assert np.array_equal(plain, tasks.fill(x, known, steps=6, resample=1, seed=0, denoiser=denoiser, progress=False))
    assert not np.array_equal(plain, tasks.fill(x, known, steps=6, resample=2, seed=0, denoiser=denoiser, progress=False))
    with pytest.raises(ValueError, match="resample must be a positive integer"):
        tasks.fill(x, known, steps=6, resample=0, denoiser=denoiser)


def test_geometry_adaptive_takes_one_label_per_sequence(coma_test, denoiser):
    neutral = coma_test.subject_neutrals()[:2]
    out = tasks.geometry_adaptive(neutral, ["mouth_open", "eyebrow E2N"], n=2, steps=5, passes=1, denoiser=denoiser,
                                  progress=False)
    assert np.array_equal(out[0, 0], neutral[0].astype(np.float32))  # N2E: first frame given
    assert np.array_equal(out[1, -1], neutral[1].astype(np.float32))  # E2N: last frame given
    with pytest.raises(ValueError, match="list of n=3"):
        tasks.geometry_adaptive(neutral[0], ["mouth_open"] * 2, n=3, steps=5, denoiser=denoiser)
