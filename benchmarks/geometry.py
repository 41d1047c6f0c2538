"""Table 4 (geometry-adaptive generation, §5.4) on the test split of "coma", pass by
pass, with 95 % intervals.

Usage: python benchmarks/geometry.py [--per-class 3] [--steps 100] [--passes 5]
[--reconstruction-scale 2]
                                     [--save NAME]

For each type-S class (label x N2E/E2N, 24 on "coma") the first ``--per-class`` test
sequences (default: all of them); each is regenerated from its own neutral frame, label
and order by Alg. 4 as printed (``--passes`` harmonising passes, each re-noised to T)
and by Alg. 4 with reconstruction guidance (zeta = ``--reconstruction-scale``).  It
prints, for the ground truth and for every pass of both methods, the type-S IC accuracy,
FID and diversity with their 95 % bootstrap intervals over the sequences, and the median
step from the given frame to its generated neighbour (mm/frame); the last pass is what
Alg. 4 returns.

``--save NAME`` stores the table in results/NAME.json with its provenance
(facelib.results); chapter 08 shows ``results/geometry_table4.json``, written by

    python benchmarks/geometry.py --per-class 3 --save geometry_table4

(72 sequences x 5 passes x 100 steps x 2 methods: 11 min with one torch thread,
2026-12-03; most of it bootstraps the FID intervals).
"""

import argparse
import os
import time

import numpy as np
import torch

from facelib import config, data, evaluation, experiments, metrics, results, tasks

COLUMNS = [
    "method",
    "pass",
    "Acc (%)",
    "Acc 95 % interval",
    "FID",
    "FID 95 % interval",
    "diversity",
    "diversity 95 % interval",
    "step from the given frame, median (mm/frame)",
    "seconds",
]


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--per-class",
        type=int,
        default=None,
        help="test sequences per type-S class (default: all)",
    )
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--passes", type=int, default=config.HARMONISING_PASSES)
    parser.add_argument(
        "--reconstruction-scale", type=float, default=config.RECONSTRUCTION_SCALE
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
    rows_sel, labels, neutral, known = experiments.table4_inputs(
        test, ev.class_names, args.per_class
    )
    truth, targets = test.landmarks[rows_sel], test.targets("S")[rows_sel]
    print(
        f"cores: {os.cpu_count()}, torch threads: {torch.get_num_threads()}, n ="
        f" {len(rows_sel)}, steps {args.steps} per pass, {args.passes} passes, zeta ="
        f" {args.reconstruction_scale:g}"
    )
    print(
        f"{'method':<36}{'pass':>5}{'Acc %':>8} {'interval':>14}{'FID':>8}"
        f" {'interval':>16}{'div.':>7}{'seam':>7}{'seconds':>9}"
    )
    table = []

    def row(name, p, out, seconds):
        s = ev.score(out, targets, intervals=True)
        s["accuracy_ci"] = tuple(
            np.clip(s["accuracy_ci"], 0, 100)
        )  # the shifted interval may leave [0, 100]
        seam = float(np.median(metrics.seam_steps(out, known)))
        table.append(
            [
                name,
                p,
                s["accuracy"],
                list(s["accuracy_ci"]),
                s["fid"],
                list(s["fid_ci"]),
                s["diversity"],
                list(s["diversity_ci"]),
                seam,
                seconds,
            ]
        )
        acc_ci, fid_ci = "[{:.1f}, {:.1f}]".format(
            *s["accuracy_ci"]
        ), "[{:.2f}, {:.2f}]".format(*s["fid_ci"])
        print(
            f"{name:<36}{p:>5}{s['accuracy']:>8.1f} {acc_ci:>14}{s['fid']:>8.2f}"
            f" {fid_ci:>16}{s['diversity']:>7.2f}{seam:>7.2f}{seconds:>9.1f}",
            flush=True,
        )

    row("ground truth (test sequences)", 0, truth, 0.0)
    for name, scale in (
        ("Alg. 4", 0.0),
        ("Alg. 4 + reconstruction guidance", args.reconstruction_scale),
    ):
        t0 = time.perf_counter()
        out = tasks.geometry_passes(
            neutral,
            labels,
            n=len(rows_sel),
            steps=args.steps,
            passes=args.passes,
            reconstruction_scale=scale,
            denoiser=denoiser,
            guide=guide,
            seed=0,
            progress=False,
        )
        seconds = time.perf_counter() - t0
        for p in range(len(out)):
            row(name, p + 1, out[p], seconds / len(out))
    if args.save:
        path = results.save_result(
            args.save,
            title=(
                "Table 4, geometry-adaptive generation on the coma test split (IC type"
                " S), pass by pass"
            ),
            columns=COLUMNS,
            rows=table,
            run=results.Run(
                allow_dirty=args.allow_dirty,
                settings=(tasks.GeometryAdaptive(),),
                checkpoints=["denoiser_coma", "guide_coma_S", "ic_coma_S"],
                seeds=[0],
                n=len(rows_sel),
                steps=[args.steps],
                wall_time_s=time.perf_counter() - t_start,
            ),
            notes=(
                f"{args.per_class or 'all'} test sequences per type-S class, each from"
                f" its own neutral frame; {args.passes} passes of Alg. 4 (re-noised to"
                " T), the last is what Alg. 4 returns; reconstruction guidance zeta ="
                f" {args.reconstruction_scale:g}; sampler seed 0; intervals: 95 %"
                " bootstrap over the sequences (Evaluator.score(intervals=True));"
                " seconds: wall time per pass"
            ),
        )
        print("stored", path)


if __name__ == "__main__":
    main()
