"""Time expression filling (Alg. 3) for 64 sequences and score the completions; print a table.

Usage: python benchmarks/filling.py [--setting FFM] [--n 64] [--steps 2000 200 100] [--resample 4]
The n inputs are test sequences of "coma" (cycled) with the §5.3 masks of ``--setting``.  For each
number of reverse steps (2000 = the paper's T; fewer = respaced) it prints the wall time, the time
per step, the IC accuracy and FID of the completed sequences, the error on the missing frames and
the median step across the seams; then, at the smallest step count, the same with RePaint
resampling (``--resample``) and with reconstruction guidance, and the three baselines.  FID is computed from n sequences: compare rows
with each other, not with tables computed from another n.
"""
import argparse
import os
import time

import numpy as np
import torch

from facelib import baselines, data, evaluation, inpainting, metrics, tasks


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--setting", default="FFM", choices=inpainting.FILL_SETTINGS)
    parser.add_argument("--n", type=int, default=64)
    parser.add_argument("--steps", type=int, nargs="+", default=[2000, 200, 100])
    parser.add_argument("--resample", type=int, default=4)
    args = parser.parse_args()
    ev = evaluation.load_evaluator("coma", "I")
    denoiser, filler = tasks.load_denoiser("denoiser_coma"), baselines.load_filler("coma")
    test = data.load_dataset("coma", "test")
    idx = np.resize(np.arange(len(test)), args.n)
    truth, targets = test.landmarks[idx], test.targets("I")[idx]
    known = inpainting.fill_masks(args.setting, args.n, truth.shape[1], seed=0)
    given = np.where(known[..., None, None], truth, np.nan)
    print(f"cores: {os.cpu_count()}, torch threads: {torch.get_num_threads()}, setting {args.setting}, n = {args.n}")
    print(f"{'method':<34}{'seconds':>9}{'ms/step':>9}{'Acc %':>8}{'FID':>8}{'L2 mm':>8}{'seam mm/f':>11}")

    def row(name, fn, steps=None):
        t0 = time.perf_counter()
        out = fn()
        dt = time.perf_counter() - t0
        s = ev.score(out, targets)
        per_step = f"{1e3 * dt / steps:>9.1f}" if steps else f"{'':>9}"
        print(f"{name:<34}{dt:>9.1f}{per_step}{s['accuracy']:>8.1f}{s['fid']:>8.2f}"
              f"{metrics.missing_frame_error(out, truth, known):>8.2f}{np.median(metrics.seam_steps(out, known)):>11.2f}",
              flush=True)

    row("ground truth", lambda: truth)
    for steps in args.steps:
        row(f"Alg. 3, {steps} steps", lambda: tasks.fill(given, known, steps=steps, denoiser=denoiser, progress=False), steps)
    low = min(args.steps)
    row(f"Alg. 3 + RePaint r={args.resample}, {low} steps",
        lambda: tasks.fill(given, known, steps=low, resample=args.resample, denoiser=denoiser, progress=False),
        low * args.resample)
    row(f"Alg. 3 + reconstruction, {low} steps",
        lambda: tasks.fill(given, known, steps=low, reconstruction_scale=tasks.RECONSTRUCTION_SCALE, denoiser=denoiser,
                           progress=False), low)
    row("mean imputation", lambda: inpainting.mean_imputation(given, known))
    row("linear interpolation", lambda: inpainting.linear_interpolation(given, known))
    row("BiLSTM filler", lambda: baselines.lstm_fill(given, known, filler))


if __name__ == "__main__":
    main()
