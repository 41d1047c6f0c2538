"""Label control (Alg. 1): the noisy classifier, optimisation and mean-shift guidance, the task."""
import numpy as np
import pytest
import torch

from facelib import config, evaluation, tasks
from facelib.diffusion import GaussianDiffusion, linear_betas
from facelib.guidance import ClassifierScore, MeanShiftGuidance, OptimisationGuidance, log_p_theta
from facelib.models.noisy_classifier import NoisyClassifier, NoisyClassifierConfig


@pytest.fixture(scope="module")
def small():
    torch.manual_seed(0)
    clf = NoisyClassifier(NoisyClassifierConfig(num_classes=3, width=32, depth=1, heads=2, ff=32, dropout=0.0)).eval()
    diffusion = GaussianDiffusion(linear_betas(100))
    return clf, diffusion


def test_log_p_theta_is_the_gaussian_log_density_up_to_a_constant():
    mean, var = torch.randn(2, 5, 68, 3), torch.full((2, 1, 1, 1), 0.3)
    out = {"mean": mean, "variance": var}
    x1, x2 = torch.randn(2, 5, 68, 3), torch.randn(2, 5, 68, 3)
    normal = torch.distributions.Normal(mean, var.sqrt())
    exact = lambda x: normal.log_prob(x).flatten(1).sum(1)  # noqa: E731
    assert torch.allclose(log_p_theta(x1, out) - log_p_theta(x2, out), exact(x1) - exact(x2), rtol=1e-4, atol=1e-3)


def test_noisy_classifier_reads_motion_and_ignores_padding(small):
    clf, _ = small
    x, t = torch.randn(2, 12, 68, 3), torch.tensor([5.0, 50.0])
    shifted = x + torch.randn(2, 1, 68, 3)  # another anatomy: the same motion
    assert torch.allclose(clf(x, t), clf(shifted, t), atol=1e-5)
    mask = torch.ones(2, 12, dtype=torch.bool)
    mask[:, 9:] = False
    padded = x.clone()
    padded[:, 9:] = 100.0
    assert torch.allclose(clf(x[:, :9], t), clf(padded, t, mask), atol=1e-5)
    assert clf(x, t).shape == (2, 3)


def test_one_guided_step_increases_the_class_log_probability(small):
    # Alg. 1 line 10 with lambda = 0: pure ascent of log p_phi(y | x, t-1) from x_hat_{t-1}.
    clf, diffusion = small
    labels = torch.tensor([0, 1, 2, 1])
    score = ClassifierScore(clf, labels)
    xt = torch.randn(4, 10, 68, 3)
    out = {"mean": xt * 0.9, "variance": torch.full((4, 1, 1, 1), 0.01)}
    x_hat = out["mean"] + 0.1 * torch.randn_like(xt)
    t = 50
    t_prev = diffusion.model_time(t - 1, 4)
    before = score(x_hat, t_prev)
    guided = OptimisationGuidance(score, diffusion, guidance_weight=0.0, lr=1e-3)(x_hat, xt, t, out)
    assert (score(guided, t_prev) > before).all()
    # with lambda > 0 the full objective of Alg. 1 increases, and x stays near the model's mean
    guide = OptimisationGuidance(score, diffusion, guidance_weight=0.01, lr=1e-3)
    guided = guide(x_hat, xt, t, out)
    assert (guide.objective(guided, out, t_prev) > guide.objective(x_hat, out, t_prev)).all()
    assert (guided - x_hat).abs().max() <= 3 * 1e-3 + 1e-6  # 3 Adagrad steps of at most lr each


def test_mean_shift_guidance_moves_along_the_gradient(small):
    clf, diffusion = small
    score = ClassifierScore(clf, torch.tensor([2, 2]))
    xt = torch.randn(2, 8, 68, 3)
    out = {"mean": xt, "variance": torch.full((2, 1, 1, 1), 0.02)}
    x_hat = xt + 0.1
    assert torch.equal(MeanShiftGuidance(score, diffusion, scale=0.0)(x_hat, xt, 10, out), x_hat)
    shifted = MeanShiftGuidance(score, diffusion, scale=1.0)(x_hat, xt, 10, out)
    t = diffusion.model_time(10, 2)
    step = 1e-2 * (shifted - x_hat) / (shifted - x_hat).norm()
    assert (score(xt + step, t) > score(xt, t)).all()


@pytest.mark.parametrize("kwargs, message", [
    ({"guidance_weight": -0.1}, "non-negative"), ({"lr": 0.0}, "positive"), ({"num_steps": 0}, "positive integer")])
def test_guidance_rejects_bad_settings(small, kwargs, message):
    clf, diffusion = small
    with pytest.raises(ValueError, match=message):
        OptimisationGuidance(ClassifierScore(clf, [0]), diffusion, **kwargs)


def test_label_control_errors():
    with pytest.raises(ValueError, match="allowed: bareteeth"):
        tasks.label_control("happyy", 2, steps=2, progress=False)
    with pytest.raises(ValueError, match="positive integer"):
        tasks.label_control("high_smile", 0, steps=2, progress=False)
    with pytest.raises(ValueError, match="non-negative"):
        tasks.label_control("high_smile", 2, steps=2, guidance_weight=-1.0, progress=False)
    with pytest.raises(ValueError, match="method"):
        tasks.label_control("high_smile", 2, steps=2, method="magic", progress=False)
    # a classifier of another dataset: its labels and its normalisation do not match
    with pytest.raises(ValueError, match="normalise landmarks differently"):
        tasks.label_control("happy", 2, steps=2, guide=tasks.load_guide("bu"), denoiser=tasks.load_denoiser("denoiser_coma"),
                            progress=False)
    with pytest.raises(ValueError, match="has classes"):
        tasks.load_guide("coma", name="guide_bu_I")


def test_default_adagrad_rate_is_the_sweep_pick_at_200_steps_and_scales_with_sqrt_steps():
    for dataset, lr in config.ADAGRAD_LR.items():
        assert tasks.adagrad_lr(dataset, config.LR_REFERENCE_STEPS) == pytest.approx(lr)
        assert tasks.adagrad_lr(dataset, None) == pytest.approx(lr * np.sqrt(config.LR_REFERENCE_STEPS / 2000))
        assert tasks.adagrad_lr(dataset, 50) == pytest.approx(2 * lr)
    with pytest.raises(ValueError, match="no default Adagrad learning rate for dataset 'coma\\+bu'.*pass lr="):
        tasks.adagrad_lr("coma+bu", 200)
    # label_control's default is that rate: passing it explicitly gives the same samples
    kwargs = dict(steps=5, seed=1, progress=False)
    assert np.array_equal(tasks.label_control("mouth_open", 2, **kwargs),
                          tasks.label_control("mouth_open", 2, lr=tasks.adagrad_lr("coma", 5), **kwargs))


def test_label_control_is_deterministic_and_beats_unguided_sampling():
    labels = list(evaluation.load_evaluator("coma").class_names)  # one sequence per label
    kwargs = dict(steps=50, seed=3, progress=False)
    guided = tasks.label_control(labels, len(labels), **kwargs)
    again = tasks.label_control(labels, len(labels), **kwargs)
    assert guided.shape == (12, 40, 68, 3) and guided.dtype == np.float32
    assert np.array_equal(guided, again)
    unguided = tasks.unconditional(len(labels), steps=50, seed=3, progress=False)
    ev = evaluation.load_evaluator("coma")
    targets = np.arange(len(labels))
    acc_guided = (ev.features(guided).argmax(1) == targets).mean()
    acc_unguided = (ev.features(unguided).argmax(1) == targets).mean()
    assert acc_guided > acc_unguided + 0.25


def test_cli_label_task_writes_npz(tmp_path):
    from facelib.__main__ import main
    out = tmp_path / "smile.npz"
    assert main(["sample", "label", "--label", "high_smile", "--n", "2", "--steps", "5",
                 "--out", str(out)]) == 0
    npz = np.load(out)
    assert npz["landmarks"].shape == (2, 40, 68, 3) and npz["landmarks"].dtype == np.float32
    assert list(npz["labels"]) == ["high_smile", "high_smile"]
    assert '"guidance_weight": 0.01' in str(npz["config"])
    assert f'"lr": {tasks.adagrad_lr("coma", 5)}' in str(npz["config"])
    with pytest.raises(SystemExit):
        main(["sample", "label", "--label", "grin", "--n", "2", "--steps", "5", "--out", str(out)])
