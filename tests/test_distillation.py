"""Progressive distillation (Salimans & Ho 2022): nested chains, the student's target,
a round that trains, saves and becomes the next round's teacher."""
import json

import numpy as np
import pytest
import torch

from facelib import config, tasks, training
from facelib.diffusion import halving_steps
from facelib.models.denoiser import Denoiser, DenoiserConfig


def test_every_other_step_of_a_chain_is_the_chain_of_half_the_steps():
    for k in (1, 2, 4, 64, 128, 1000):
        full, half = halving_steps(2 * k), halving_steps(k)
        np.testing.assert_array_equal(full[::2], half)
        assert full[0] == 0 and full[-1] == 2000 and np.all(np.diff(full) > 0)
    with pytest.raises(ValueError, match="at most 2000 steps"):
        halving_steps(4000)


@pytest.mark.parametrize("prediction", ["eps", "x0", "v", "u"])
def test_the_clean_estimate_agrees_with_the_noise_estimate(prediction):
    torch.manual_seed(0)
    schedule = "flow" if prediction == "u" else "linear"
    model = Denoiser(DenoiserConfig(width=32, depth=1, heads=2, ff=32, schedule=schedule,
                                    prediction=prediction)).eval()
    torch.nn.init.normal_(model.out.weight, std=0.05)
    x, t = torch.randn(3, 5, 68, 3), torch.tensor([20.0, 700.0, 1500.0])
    with torch.no_grad():
        abar = model._abar(t, x)
        from_eps = (x - (1 - abar).sqrt() * model(x, t)) / abar.sqrt()
        torch.testing.assert_close(model.x0(x, t), from_eps, atol=1e-3, rtol=1e-3)


@pytest.fixture(scope="module")
def round_of_8():
    settings = training.DistillationTraining(teacher_steps=8, batch_size=4).with_steps(2)
    return training.DistillationRecipe(settings)


def test_the_students_target_is_the_clean_sequence_one_ddim_step_takes_to_the_teachers_two(round_of_8):
    r = round_of_8
    g = torch.Generator().manual_seed(0)
    x = torch.randn(3, 40, 68, 3, generator=g)
    t, t_mid, t_end = (torch.full((3,), s) for s in (750, 625, 500))  # not on the grid: any steps
    with torch.no_grad():
        teacher = r.teacher.model
        x_end = r._ddim(teacher, r._ddim(teacher, x, t, t_mid), t_mid, t_end)
        a, a_end = (r.alphas_bar[s].float().reshape(-1, 1, 1, 1) for s in (t, t_end))
        ratio = ((1 - a_end) / (1 - a)).sqrt()
        target = (x_end - ratio * x) / (a_end.sqrt() - ratio * a.sqrt())
        # one DDIM step with x0 = target: eps = (x - sqrt(a) x0) / sqrt(1 - a)
        eps = (x - a.sqrt() * target) / (1 - a).sqrt()
        landed = a_end.sqrt() * target + (1 - a_end).sqrt() * eps
    torch.testing.assert_close(landed, x_end, atol=1e-4, rtol=1e-4)


def test_a_round_trains_saves_and_teaches_the_next(round_of_8, tmp_path):
    r = round_of_8
    assert r.checkpoint_name() == "student_denoiser_coma_4"
    assert r.grid.tolist() == [0, 250, 500, 750, 1000, 1250, 1500, 1750, 2000]
    model, history = training.fit(r, progress=False)
    assert model.config.prediction == "v" and np.isfinite(history["loss"]).all()
    training.train_and_save(r, name=str(tmp_path / "s4"), progress=False)
    meta = json.loads((tmp_path / "s4.json").read_text())["training"]
    assert meta["sampler_steps"] == [500, 1000, 1500, 2000]
    assert meta["distilled_from"] == "denoiser_coma" and meta["distillation"]["teacher_steps"] == 8
    student = tasks.load_denoiser(str(tmp_path / "s4"))
    assert student.model.config.prediction == "v"
    nxt = training.DistillationRecipe(training.DistillationTraining(
        teacher=str(tmp_path / "s4"), teacher_steps=4, batch_size=4).with_steps(1))
    assert nxt.checkpoint_name() == "student_denoiser_coma_2"
    assert nxt.data.settings.anatomy_swap == r.data.settings.anatomy_swap


def test_bad_distillation_settings_are_refused():
    with pytest.raises(ValueError, match="teacher_steps must be even"):
        training.DistillationTraining(teacher_steps=7)
    with pytest.raises(ValueError, match=r"weighting must be one of \('landing', 'truncated_snr', 'snr'\), got 'x'"):
        training.DistillationTraining(weighting="x")
    with pytest.raises(ValueError, match="not a rectified flow"):
        training.DistillationRecipe(training.DistillationTraining(teacher="denoiser_coma_flow"))
    with pytest.raises(ValueError, match="denoiser_coma is unconditional, it has no classifier-free guidance"):
        training.DistillationRecipe(training.DistillationTraining(guidance_scale=2.0))


def test_a_student_samples_on_its_own_steps_and_refuses_others(tmp_path):
    r = training.DistillationRecipe(training.DistillationTraining(teacher_steps=8, batch_size=4).with_steps(1))
    training.train_and_save(r, name=str(tmp_path / "s"), progress=False)
    student = tasks.load_denoiser(str(tmp_path / "s"))
    chain = student.diffusion_with()
    assert chain.timesteps.tolist() == [0, 500, 1000, 1500, 2000] and chain.eta == 0.0
    x = tasks.unconditional(2, steps=4, sampler="student", denoiser=student, progress=False)
    assert x.shape == (2, 40, 68, 3) and np.isfinite(x).all()
    for bad in ({"steps": 3}, {"steps": 4, "eta": 1.0}):
        with pytest.raises(ValueError, match="distilled student of 4 deterministic steps"):
            student.diffusion_with(**bad)


def test_the_landing_error_is_the_x0_error_times_the_steps_conditioning():
    """The student's landing misses the teacher's by (sqrt(abar'') - (sigma''/sigma)
    sqrt(abar)) times its x_0 error: the factor that makes the x_0 target ill-conditioned
    near T (about 3e-4 on the linear schedule), which the "landing" loss never divides by."""
    from facelib.diffusion import GaussianDiffusion, linear_betas
    from facelib.diffusion import ddim_step
    ab = torch.as_tensor(GaussianDiffusion(linear_betas(2000)).alphas_bar)
    g = torch.Generator().manual_seed(1)
    xt, x_end, x0_hat = (torch.randn(2, 5, 68, 3, generator=g, dtype=torch.float64) for _ in range(3))
    for t, t_end in ((750, 500), (2000, 1984)):
        a, a_end = ab[t], ab[t_end]
        ratio = ((1 - a_end) / (1 - a)).sqrt()
        factor = a_end.sqrt() - ratio * a.sqrt()
        target = (x_end - ratio * xt) / factor
        landed = ddim_step(xt, x0_hat, a, a_end)
        torch.testing.assert_close(x_end - landed, factor * (target - x0_hat))
    assert abs(factor) < 1e-3  # near T


def test_a_student_of_the_conditional_denoiser_samples_with_the_guidance_weight_distilled_in(tmp_path):
    """Meng et al. 2023 with one w: the first round's teacher is CFG-guided, the student
    samples guided in one call a step, and its own students keep its w."""
    r = training.DistillationRecipe(training.DistillationTraining(
        teacher="denoiser_coma_cfg", teacher_steps=8, batch_size=4).with_steps(1))
    assert r.guidance_scale == config.CFG_SCALE
    x, t = torch.randn(2, 40, 68, 3), torch.full((2,), 900.0)
    y = torch.tensor([0, 5])
    with torch.no_grad():
        free, cond = r.teacher.model.x0(x, t), r.teacher.model.x0(x, t, labels=y)
        torch.testing.assert_close(r.teacher_x0(x, t, y), free + 2.5 * (cond - free))
    training.train_and_save(r, name=str(tmp_path / "c4"), progress=False)
    student = tasks.load_denoiser(str(tmp_path / "c4"))
    assert student.meta["training"]["cfg_scale"] == 2.5 and student.model.config.num_classes
    out = tasks.label_control("high_smile", 2, steps=4, sampler="student", guidance="cfg",
                              denoiser=student, progress=False)
    assert out.shape == (2, 40, 68, 3) and np.isfinite(out).all()
    with pytest.raises(ValueError, match="samples with w = 2.5 distilled in, not scale = 4"):
        tasks.label_control("high_smile", 2, steps=4, sampler="student", guidance="cfg",
                            scale=4.0, denoiser=student, progress=False)
    nxt = training.DistillationRecipe(training.DistillationTraining(
        teacher=str(tmp_path / "c4"), teacher_steps=4, batch_size=4).with_steps(1))
    assert nxt.guidance_scale == 2.5 and nxt.checkpoint_name() == "student_denoiser_coma_cfg_2"
    with torch.no_grad():  # a guided student's estimate is used as it is
        torch.testing.assert_close(nxt.teacher_x0(x, t, y), student.model.x0(x, t, labels=y))
    with pytest.raises(ValueError, match="keep it"):
        training.DistillationRecipe(training.DistillationTraining(
            teacher=str(tmp_path / "c4"), teacher_steps=4, guidance_scale=1.0))
