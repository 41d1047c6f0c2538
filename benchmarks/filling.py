"""Table 3 (expression filling, §5.3) on the test split of "coma": every method, with 95
% intervals.

Usage: python benchmarks/filling.py [--settings FFB FFE FFM] [--n N] [--steps 200]
[--resample 4]
                                    [--reconstruction-scale 2] [--save NAME]

The n inputs are test sequences of "coma" (default: all of them; fewer: a random subset,
seed 0; more: cycled, for timing) with the §5.3 masks of each setting
(``inpainting.fill_masks``, seed 0). For each setting it prints, per method, the wall
time, the IC (type I) accuracy and FID of the completed sequences with their 95 %
bootstrap intervals over the sequences, the error on the missing frames and the median
step across the seams.  Methods: mean imputation, linear interpolation, the BiLSTM
filler, Alg. 3 at every step count of ``--steps`` (2000 = the paper's T; fewer =
respaced), and, at the smallest step count, Alg. 3 with RePaint resampling and with
reconstruction guidance.  FID is computed from n sequences: compare rows with each
other, not with tables computed from another n.

``--save NAME`` stores the table in results/NAME.json with its provenance
(facelib.results); chapter 07 shows ``results/filling_table3.json``, written by

    python benchmarks/filling.py --save filling_table3

(all 169 test sequences, 200 steps, r = 4: 17 min with one torch thread, 2026-12-03).
"""

import argparse
import os
import time

import numpy as np
import torch

from facelib import (
    baselines,
    config,
    data,
    evaluation,
    inpainting,
    metrics,
    results,
    tasks,
)

ALG3 = (
    tasks.Fill().paper()
)  # Alg. 3 as printed; its rows add RePaint or reconstruction guidance explicitly

COLUMNS = [
    "setting",
    "method",
    "steps",
    "Acc (%)",
    "Acc 95 % interval",
    "FID",
    "FID 95 % interval",
    "L2 on missing frames (mm)",
    "seam step, median (mm/frame)",
    "seconds",
]


def pick_sequences(num_test, n):
    """Indices of the n test sequences: all of them (n None), a random subset (seed 0),
    or cycled."""
    if n is None or n == num_test:
        return np.arange(num_test)
    if n < num_test:
        return np.sort(np.random.default_rng(0).choice(num_test, n, replace=False))
    return np.resize(np.arange(num_test), n)


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--settings",
        nargs="+",
        default=list(inpainting.FILL_SETTINGS),
        choices=inpainting.FILL_SETTINGS,
    )
    parser.add_argument(
        "--n", type=int, default=None, help="test sequences per row (default: all)"
    )
    parser.add_argument("--steps", type=int, nargs="+", default=[200])
    parser.add_argument("--resample", type=int, default=4)
    parser.add_argument(
        "--reconstruction-scale", type=float, default=config.RECONSTRUCTION_SCALE
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    t_start = time.perf_counter()
    ev = evaluation.load_evaluator("coma", "I")
    denoiser, filler = tasks.load_denoiser("denoiser_coma"), baselines.load_filler(
        "coma"
    )
    test = data.load_dataset("coma", "test")
    idx = pick_sequences(len(test), args.n)
    n = len(idx)
    truth, targets = test.landmarks[idx], test.targets("I")[idx]
    print(
        f"cores: {os.cpu_count()}, torch threads: {torch.get_num_threads()}, n = {n},"
        f" steps {args.steps}, r = {args.resample}, zeta ="
        f" {args.reconstruction_scale:g}"
    )
    print(
        f"{'setting':<8}{'method':<40}{'seconds':>9}{'Acc %':>8}"
        f" {'interval':>14}{'FID':>8} {'interval':>16}{'L2 mm':>8}{'seam mm/f':>11}"
    )
    rows = []

    def row(setting, name, steps, fn, known):
        t0 = time.perf_counter()
        out = fn()
        dt = time.perf_counter() - t0
        s = ev.score(out, targets, intervals=True)
        s["accuracy_ci"] = tuple(
            np.clip(s["accuracy_ci"], 0, 100)
        )  # the shifted interval may leave [0, 100]
        l2 = metrics.missing_frame_error(out, truth, known) if (~known).any() else 0.0
        seam = (
            float(np.median(metrics.seam_steps(out, known))) if (~known).any() else 0.0
        )
        rows.append(
            [
                setting,
                name,
                steps or "-",
                s["accuracy"],
                list(s["accuracy_ci"]),
                s["fid"],
                list(s["fid_ci"]),
                l2,
                seam,
                dt,
            ]
        )
        acc_ci = "[{:.1f}, {:.1f}]".format(*s["accuracy_ci"])
        fid_ci = "[{:.2f}, {:.2f}]".format(*s["fid_ci"])
        print(
            f"{setting:<8}{name:<40}{dt:>9.1f}{s['accuracy']:>8.1f}"
            f" {acc_ci:>14}{s['fid']:>8.2f} {fid_ci:>16}{l2:>8.2f}{seam:>11.2f}",
            flush=True,
        )

    row("-", "ground truth", 0, lambda: truth, np.ones(truth.shape[:2], bool))
    low = min(args.steps)
    for setting in args.settings:
        known = inpainting.fill_masks(setting, n, truth.shape[1], seed=0)
        given = np.where(known[..., None, None], truth, np.nan)
        fill = lambda steps, **kw: tasks.fill(
            given, known, ALG3, steps=steps, denoiser=denoiser, progress=False, **kw
        )  # noqa: E731
        row(
            setting,
            "mean imputation",
            0,
            lambda: inpainting.mean_imputation(given, known),
            known,
        )
        row(
            setting,
            "linear interpolation",
            0,
            lambda: inpainting.linear_interpolation(given, known),
            known,
        )
        row(
            setting,
            "BiLSTM filler (Berson et al.)",
            0,
            lambda: baselines.lstm_fill(given, known, filler),
            known,
        )
        for steps in args.steps:
            row(setting, "ours: Alg. 3", steps, lambda: fill(steps), known)
        row(
            setting,
            f"ours + RePaint (r = {args.resample})",
            low,
            lambda: fill(low, resample=args.resample),
            known,
        )
        row(
            setting,
            f"ours + reconstruction guidance (zeta = {args.reconstruction_scale:g})",
            low,
            lambda: fill(low, reconstruction_scale=args.reconstruction_scale),
            known,
        )
    if args.save:
        path = results.save_result(
            args.save,
            title="Table 3, expression filling on the coma test split (IC type I)",
            columns=COLUMNS,
            rows=rows,
            run=results.Run(
                allow_dirty=args.allow_dirty,
                checkpoints=["denoiser_coma", "lstm_filler_coma", "ic_coma_I"],
                seeds=[0],
                n=n,
                steps=sorted(set(args.steps)),
                wall_time_s=time.perf_counter() - t_start,
            ),
            notes=(
                "masks: inpainting.fill_masks(setting, n, 40, seed=0); sampler seed 0;"
                f" RePaint r = {args.resample} and reconstruction guidance (zeta ="
                f" {args.reconstruction_scale:g}) at {low} steps; intervals: 95 %"
                " bootstrap over the sequences (Evaluator.score(intervals=True));"
                " seconds: wall time of the row"
            ),
        )
        print("stored", path)


if __name__ == "__main__":
    main()
