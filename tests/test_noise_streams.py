"""One random stream per chain: the noise a task's first reverse step adds is independent of the x it starts from.

A task that draws x_T (or re-noised data) from a generator seeded with ``seed`` and then runs the chain from a
fresh generator seeded alike makes its first step add x_T's own values where fresh noise belongs (issue 42).
The probe records, for the first chain run of a call, x at its first step and the noise z that step's p_sample
draws (the next values of the generator the chain runs on), and correlates them over every coordinate.

    pytest tests/test_noise_streams.py -s     prints the correlation of every task
"""
import contextlib

import numpy as np
import pytest
import torch

from facelib import inpainting, tasks
from facelib.diffusion import GaussianDiffusion
from facelib.face.aus import AU_NAMES
from facelib.models.au_regressor import AURegressor, AURegressorConfig
from facelib.tasks.fill import known_noise


@contextlib.contextmanager
def first_steps():
    """Inside the block, every chain run appends (x at its first step, the noise its first step draws)."""
    pairs, run = [], GaussianDiffusion.run

    def probed(self, model, x, seed=0, steps=None, *args, **kwargs):
        generator = seed if isinstance(seed, torch.Generator) else torch.Generator().manual_seed(seed)
        z = torch.randn(x.shape, generator=torch.Generator().set_state(generator.get_state()))
        pairs.append((x.detach().cpu().flatten(), z.flatten()))
        return run(self, model, x, generator, steps, *args, **kwargs)

    GaussianDiffusion.run = probed
    try:
        yield pairs
    finally:
        GaussianDiffusion.run = run


def correlation(call, seeds=range(3)):
    """corr(x_first, z_first) pooled over the first chain run of ``call(seed)`` for each seed."""
    xs, zs = [], []
    for seed in seeds:
        with first_steps() as pairs:
            call(seed)
        xs.append(pairs[0][0])
        zs.append(pairs[0][1])
    return float(np.corrcoef(torch.cat(xs).numpy(), torch.cat(zs).numpy())[0, 1])


@pytest.fixture(scope="module")
def regressor(denoiser):
    torch.manual_seed(0)
    return tasks.TrainedGuide(AURegressor(AURegressorConfig(width=32, depth=1, heads=2, ff=64)).eval(), "coma", "au",
                              AU_NAMES, denoiser.normalizer, {"training": {"num_diffusion_steps": 2000}})


def task_calls(test, denoiser, regressor):
    """{task: call(seed)} with tiny chains (4 steps, 2 sequences)."""
    x, neutral = test.landmarks[:2], test.sequence_neutrals()[:2]
    keys = [{"frame": 25, "landmark": 54, "displacement": [0, 8, 0]}]
    small = dict(steps=4, denoiser=denoiser, progress=False)
    return {
        "unconditional": lambda s: tasks.unconditional(2, seed=s, **small),
        "label": lambda s: tasks.label_control("high_smile", 2, seed=s, **small),
        "fill": lambda s: tasks.fill(x, inpainting.fill_masks("FFM", 2, 40, seed=0), seed=s, **small),
        "geometry": lambda s: tasks.geometry_adaptive(neutral[0], "mouth_open", 2, seed=s, **small),
        "geometry, pass 2": lambda s: tasks.geometry_passes(neutral[0], "mouth_open", 1, passes=2, renoise_step=3,
                                                           seed=s, **small),
        "keyframes (both)": lambda s: tasks.keyframes(keys, 2, neutral[0], seed=s, **small),
        "keyframes (reconstruction)": lambda s: tasks.keyframes(keys, 2, neutral[0], method="reconstruction",
                                                                seed=s, **small),
        "au (a given face)": lambda s: tasks.au_control(["AU26:1.0"], 2, neutral[0], seed=s, regressor=regressor,
                                                        **small),
        "au": lambda s: tasks.au_control(["AU26:1.0"], 2, seed=s, regressor=regressor, **small),
        "edit": lambda s: tasks.edit(x, "high_smile", keep="0:1", seed=s, **small),
    }


TASKS = ["unconditional", "label", "fill", "geometry", "geometry, pass 2", "keyframes (both)",
         "keyframes (reconstruction)", "au (a given face)", "au", "edit"]


@pytest.mark.parametrize("task", TASKS)
def test_the_first_step_adds_noise_independent_of_where_the_chain_starts(task, coma_test, denoiser, regressor):
    call = task_calls(coma_test, denoiser, regressor)[task]
    if task == "geometry, pass 2":  # the second pass's chain starts from re-noised data: probe that run
        def second_run(seed):
            with first_steps() as pairs:
                call(seed)
            return pairs[1]
        xs, zs = zip(*(second_run(s) for s in range(3)))
        r = float(np.corrcoef(torch.cat(xs).numpy(), torch.cat(zs).numpy())[0, 1])
    else:
        r = correlation(call)
    print(f"{task:<28} corr(x_first, z_first) = {r:+.3f}")
    assert abs(r) < 0.05, f"{task}: the first reverse step's noise correlates with the chain's start (r = {r:.3f})"


def test_text_tasks_keep_one_stream(merged_denoiser, text_head):
    small = dict(steps=4, denoiser=merged_denoiser, progress=False)
    for name, call in {"text": lambda s: tasks.text_control("high smile", 2, seed=s, head=text_head, **small),
                       "decoder": lambda s: tasks.decoder_then_diffusion("high smile", 2, seed=s, **small)}.items():
        r = correlation(call)
        print(f"{name:<28} corr(x_first, z_first) = {r:+.3f}")
        assert abs(r) < 0.05, f"{name}: r = {r:.3f}"


def test_a_conditioned_chain_is_one_run_from_a_caller_made_start_with_the_continued_generator(coma_test, denoiser):
    x, known = coma_test.landmarks[:2], inpainting.fill_masks("FFE", 2, 40, seed=1)
    filled = tasks.fill(x, known, steps=5, seed=7, reconstruction_scale=0.0, denoiser=denoiser, progress=False)
    chain = denoiser.diffusion_with(5, "posterior")
    given, mask = inpainting.check_fill_input(x, known)
    hook = inpainting.KnownFrames(chain, denoiser.to_model(given), torch.as_tensor(mask), known_noise(7))
    generator = torch.Generator().manual_seed(7)
    x_T = hook.start(generator)
    by_hand = chain.run(denoiser.model, x_T, generator, chain.schedule(), hook, progress=False)
    assert np.array_equal(filled, inpainting.keep_known(denoiser.to_mm(by_hand), x, known))
