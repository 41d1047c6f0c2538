"""Label control (Alg. 1) as a task."""
import numpy as np
import pytest

from facelib import config, evaluation, experiments, tasks


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


def test_table1_has_the_papers_rows_for_the_requested_test_sequences(coma_test, denoiser):
    rows = experiments.table1_generators("coma", [3, 5], 2, tasks.load_guide("coma"), denoiser, 10.0)
    assert list(rows) == ["Ground truth (test split)", "Motion3DGAN-style (MoGAN)", "ACTOR-style CVAE",
                          "DDPM, unguided", "DDPM + mean shift (scale 10)", "DDPM + Alg. 1 (ours)"]
    assert np.array_equal(rows["Ground truth (test split)"](), coma_test.landmarks[[3, 5]])
    assert rows["ACTOR-style CVAE"]().shape == rows["DDPM + Alg. 1 (ours)"]().shape == (2, 40, 68, 3)
