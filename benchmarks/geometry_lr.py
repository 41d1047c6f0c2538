"""The Adagrad rate of Alg. 4's type-S guidance (config.GEOMETRY_LR): accuracy, FID and
how far the faces move.

Usage: python benchmarks/geometry_lr.py [--per-class 2] [--lr 0.01 0.03 0.1] [--save
NAME]

Alg. 4 with the book's settings (tasks.GeometryAdaptive: one pass, reconstruction
guidance) regenerates ``--per-class`` coma test sequences of every type-S class from
their own neutral frames, at each rate.  The type-S IC scores them (accuracy and FID
with 95 % bootstrap intervals); "motion" is the mean over sequences of the largest
landmark displacement from the given neutral frame (mm), beside the same for the test
sequences themselves.  The rule: the smallest rate whose accuracy interval overlaps the
best rate's and whose motion stays within 1.5 times the data's.

    python benchmarks/geometry_lr.py --save geometry_lr

(48 sequences x 3 rates: about 10 minutes with one torch thread.)
"""

import argparse
import time

import numpy as np

from facelib import data, evaluation, experiments, results, tasks

COLUMNS = [
    "rate",
    "Acc (%)",
    "Acc 95 % interval",
    "FID",
    "FID 95 % interval",
    "motion (mm)",
    "seconds",
]


def motion(x, neutral):
    """Mean over sequences of the largest landmark displacement from the neutral
    landmarks (mm)."""
    return float(np.linalg.norm(x - neutral[:, None], axis=-1).max(axis=(1, 2)).mean())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--per-class",
        type=int,
        default=2,
        help="test sequences per type-S class (default 2)",
    )
    parser.add_argument(
        "--lr",
        type=float,
        nargs="+",
        default=[0.01, 0.03, 0.1],
        help="rates to compare",
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    t_start = time.perf_counter()
    ev = evaluation.load_evaluator("coma", "S")
    denoiser, guide = tasks.load_denoiser("denoiser_coma"), tasks.load_guide(
        "coma", "S"
    )
    test = data.load_dataset("coma", "test")
    rows_sel, labels, neutral, _ = experiments.table4_inputs(
        test, ev.class_names, args.per_class
    )
    targets = test.targets("S")[rows_sel]

    def row(name, x, seconds):
        s = ev.score(x, targets, intervals=True)
        return [
            name,
            s["accuracy"],
            [float(v) for v in np.clip(s["accuracy_ci"], 0, 100)],
            s["fid"],
            list(s["fid_ci"]),
            motion(x, neutral),
            seconds,
        ]

    table = [row("test sequences", test.landmarks[rows_sel], 0.0)]
    print(table[-1], flush=True)
    for lr in args.lr:
        t0 = time.perf_counter()
        x = tasks.geometry_adaptive(
            neutral,
            labels,
            n=len(rows_sel),
            denoiser=denoiser,
            guide=guide,
            lr=lr,
            progress=False,
        )
        table.append(row(lr, x, time.perf_counter() - t0))
        print(table[-1], flush=True)
    if args.save:
        results.save_result(
            args.save,
            "Alg. 4's Adagrad rate (coma test split, IC type S)",
            COLUMNS,
            table,
            results.Run(
                allow_dirty=args.allow_dirty,
                checkpoints=["denoiser_coma", "guide_coma_S", "ic_coma_S"],
                seeds=[0],
                n=len(rows_sel),
                steps=[tasks.GeometryAdaptive().steps],
                wall_time_s=time.perf_counter() - t_start,
            ),
            notes=(
                f"{args.per_class} test sequences per type-S class; the book's Alg. 4"
                " settings"
            ),
        )


if __name__ == "__main__":
    main()
