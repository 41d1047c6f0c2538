"""Time unconditional sampling with the shipped denoiser, and one training step; print a
table.

Usage: python benchmarks/sampling.py [--n 64] [--checkpoint denoiser_coma] [--steps 2000
500 ...]
                                     [--lengths 25 30 ...] [--save NAME]
Respacing (the default): n sequences of 40 frames at the paper's T = 2000 and respaced,
each row from the same seed, with the distance of every sample to its closest training
sequence (RMSE, mm; whole sequence and motion only, mean with a 95 % bootstrap interval
over the sequences), the mean frame-to-frame speed of a landmark and the roughness (mm),
then the time of one training step. With ``--lengths``: the sequence-length comparison
of chapter 03, section 9 (paper, appendix A): n sequences per length from the
fixed-length model (``--checkpoint``) and the variable-length one (``--variable``),
resampled to 40 frames, with the same distances. ``--save NAME`` writes the table to
results/NAME.json (facelib.results: provenance, checkpoint hashes), which chapter 03
shows as the full-scale version of its live tables.
"""

import argparse
import os
import time

import numpy as np
import torch

from facelib import data, results, tasks
from facelib.metrics import (
    bootstrap_interval,
    landmark_statistics,
    nearest_neighbour_rmse,
    resample_frames,
    temporal_roughness,
)
from facelib.training import DenoiserTraining


def motion(x):
    """A sequence minus its own mean shape: the expression without the anatomy."""
    return x - x.mean(axis=1, keepdims=True)


def distances(x, train):
    """Mean RMSE (mm) to the closest training sequence, whole and motion only, with 95 %
    intervals."""
    nn = nearest_neighbour_rmse(x, train.landmarks)
    nn_motion = nearest_neighbour_rmse(motion(x), motion(train.landmarks))
    return [
        float(nn.mean()),
        list(bootstrap_interval(np.mean, nn)),
        float(nn_motion.mean()),
        list(bootstrap_interval(np.mean, nn_motion)),
    ]


def respacing(args, denoiser, train):
    columns = [
        "reverse steps",
        "time (s)",
        "nearest training RMSE, mean (mm)",
        "95 % interval",
        "motion only, mean (mm)",
        "95 % interval",
        "frame-to-frame speed (mm)",
        "roughness (mm)",
    ]
    rows = []
    print(
        f"{'steps':>6}{'seconds':>10}{'ms/step':>9}{'NN RMSE mm':>12}{'motion mm':>11}{'speed':>8}{'roughness':>11}"
    )
    for steps in args.steps:
        t0 = time.perf_counter()
        x = tasks.unconditional(
            args.n, seed=args.seed, steps=steps, denoiser=denoiser, progress=False
        )
        dt = time.perf_counter() - t0
        nn, nn_ci, nm, nm_ci = distances(x, train)
        speed = landmark_statistics(x)["frame-to-frame speed"]
        rows.append([steps, dt, nn, nn_ci, nm, nm_ci, speed, temporal_roughness(x)])
        print(
            f"{steps:>6}{dt:>10.1f}{1e3 * dt / steps:>9.1f}{nn:>12.2f}{nm:>11.2f}{speed:>8.3f}"
            f"{temporal_roughness(x):>11.3f}",
            flush=True,
        )
    for name, x, exclude in (
        ("another take (training)", train.landmarks, True),
        ("test split", data.load_dataset(train.name, "test").landmarks, False),
    ):
        nn = nearest_neighbour_rmse(x, train.landmarks, exclude_self=exclude)
        nm = nearest_neighbour_rmse(
            motion(x), motion(train.landmarks), exclude_self=exclude
        )
        rows.append(
            [
                name,
                "",
                float(nn.mean()),
                list(bootstrap_interval(np.mean, nn)),
                float(nm.mean()),
                list(bootstrap_interval(np.mean, nm)),
                landmark_statistics(x)["frame-to-frame speed"],
                temporal_roughness(x),
            ]
        )
        print(
            f"{name:>24}{nn.mean():>12.2f}{nm.mean():>11.2f}{rows[-1][6]:>8.3f}{rows[-1][7]:>11.3f}"
        )
    return (
        columns,
        rows,
        "Unconditional sampling: respacing (chapter 03, section 8)",
        [args.checkpoint],
    )


def lengths(args, denoiser, train):
    variable = tasks.load_denoiser(args.variable)
    columns = [
        "frames",
        "fixed F = 40",
        "95 % interval",
        "fixed, motion only",
        "95 % interval",
        f"variable {args.variable}",
        "95 % interval",
        "variable, motion only",
        "95 % interval",
    ]
    rows = []
    steps = args.steps[0]
    print(
        f"{args.n} sequences per length, {steps} steps; mean RMSE (mm) to the closest"
        " training sequence"
    )
    print(f"{'frames':>6}{'fixed':>8}{'motion':>8}{'variable':>10}{'motion':>8}")
    for f in args.lengths:
        row = [f]
        for model in (denoiser, variable):
            x = tasks.unconditional(
                args.n,
                num_frames=f,
                seed=args.seed,
                steps=steps,
                denoiser=model,
                progress=False,
            )
            row += distances(resample_frames(x, 40), train)
        rows.append(row)
        print(
            f"{f:>6}{row[1]:>8.2f}{row[3]:>8.2f}{row[5]:>10.2f}{row[7]:>8.2f}",
            flush=True,
        )
    title = (
        f"Unconditional sampling at other lengths, {steps} steps (chapter 03,"
        " section 9)"
    )
    return columns, rows, title, [args.checkpoint, args.variable]


def training_step(denoiser, train):
    cfg = DenoiserTraining()
    model = denoiser.model.train()
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr)
    x0 = torch.as_tensor(
        denoiser.normalizer.normalize(train.landmarks[: cfg.batch_size])
    )
    times = []
    for _ in range(6):
        t0 = time.perf_counter()
        loss = denoiser.diffusion.training_loss(model, x0)
        opt.zero_grad()
        loss.backward()
        opt.step()
        times.append(time.perf_counter() - t0)
    per_step = np.median(times[1:])
    print(
        f"training step (batch {cfg.batch_size}, 40 frames): {per_step:.3f} s; the"
        f" shipped recipe of {cfg.steps} steps: {cfg.steps * per_step / 60:.1f} min"
        " (target <= 30 min)"
    )


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--n", type=int, default=64)
    parser.add_argument("--checkpoint", default="denoiser_coma")
    parser.add_argument(
        "--variable",
        default="denoiser_coma_var",
        help="the variable-length model (--lengths)",
    )
    parser.add_argument(
        "--steps",
        type=int,
        nargs="+",
        default=None,
        help=(
            "reverse steps per row (default 2000 500 200 100 50 20; with --lengths one"
            " value, 500)"
        ),
    )
    parser.add_argument(
        "--lengths",
        type=int,
        nargs="+",
        default=None,
        help=(
            "compare sequence lengths instead of step counts (e.g. 25 30 35 40 45"
            " 50 60)"
        ),
    )
    parser.add_argument("--seed", type=int, default=0)
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    if args.n < 2:
        parser.error(
            "--n must be at least 2 (intervals are bootstrapped over the sequences),"
            f" got {args.n}"
        )
    if args.steps is None:
        args.steps = [500] if args.lengths else [2000, 500, 200, 100, 50, 20]
    elif args.lengths and len(args.steps) != 1:
        parser.error(f"with --lengths give one --steps value, got {args.steps}")
    denoiser = tasks.load_denoiser(args.checkpoint)
    train = data.load_dataset(denoiser.meta["training"]["dataset"], "train")
    print(
        f"cores: {os.cpu_count()}, torch threads: {torch.get_num_threads()},"
        f" checkpoint: {args.checkpoint}, n = {args.n}, seed {args.seed}"
    )
    t0 = time.perf_counter()
    columns, rows, title, checkpoints = (lengths if args.lengths else respacing)(
        args, denoiser, train
    )
    wall = time.perf_counter() - t0
    if args.save:
        path = results.save_result(
            args.save,
            title=title,
            columns=columns,
            rows=rows,
            run=results.Run(
                allow_dirty=args.allow_dirty,
                checkpoints=checkpoints,
                seeds=[args.seed],
                n=args.n,
                steps=args.steps,
                wall_time_s=wall,
            ),
            notes=(
                "mean RMSE (mm) to the closest training sequence over n sequences; "
                "intervals: 95 % bootstrap over the sequences"
            ),
        )
        print(f"saved {path}")
    if not args.lengths:
        training_step(denoiser, train)


if __name__ == "__main__":
    main()
