"""Does the unconditional DDPM cover its data?  The coverage protocol (issue 43) on the
shipped denoiser.

Usage: python benchmarks/coverage.py [--dataset coma] [--n N] [--steps 100 500 2000]
[--save NAME]

For the training split, the test split (the reference: what an ideal generator that
reproduced held-out data would score) and ``--n`` unconditional samples (default: as
many as the test split holds, so that recall and coverage, which grow with n, compare
like with like) at each of ``--steps`` respaced reverse steps, it prints and stores
(facelib.evaluation.Evaluator.coverage, against the training split, in the type-I IC's
feature space):

* the label mix's total variation to the training split's, and the 95th percentile of
  the same statistic over random real test subsets of the same size (a generated set
  above it skews its labels beyond chance);
* per region (mouth opening, mouth-corner excursion, brow raise, eye closure) the 90th
  percentile of each sequence's largest motion (mm) and the Kolmogorov-Smirnov p-value
  against the test split;
* precision, recall, density and coverage (k = 5) with 95 % bootstrap intervals, and FID
  with its interval.

    python benchmarks/coverage.py --steps 100 500 2000 --save coverage_unconditional   # about 6 min, one thread
"""

import argparse
import time

import numpy as np

from facelib import data, evaluation, metrics, results, tasks

REGIONS = metrics.AMPLITUDE_REGIONS
COLUMNS = (
    ["rows", "steps", "n", "label TV", "real subsets' TV p95"]
    + [f"{r} p90 (mm)" for r in REGIONS]
    + [f"{r} KS p vs test" for r in REGIONS]
    + [
        c
        for name in ("precision", "recall", "density", "coverage")
        for c in (name, "95 % interval")
    ]
    + ["FID", "FID 95 % interval", "seconds"]
)


def table_row(name, steps, measured, scores, seconds):
    amp = measured["amplitudes"]
    return (
        [
            name,
            steps,
            measured["n"],
            measured["label_tv"],
            measured["label_tv_real_p95"],
        ]
        + [amp[r]["p90"] for r in REGIONS]
        + [amp[r]["ks_p_vs_test"] for r in REGIONS]
        + [
            v
            for name in ("precision", "recall", "density", "coverage")
            for v in (measured[name], list(measured[name + "_ci"]))
        ]
        + [scores["fid"], list(scores["fid_ci"]), seconds]
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", default="coma", choices=["coma", "bu"])
    parser.add_argument(
        "--n",
        type=int,
        default=None,
        help="samples per row (default: the test split's size)",
    )
    parser.add_argument(
        "--steps",
        type=int,
        nargs="+",
        default=[tasks.Unconditional().steps],
        help="respaced reverse steps, one row each (default: the command line's)",
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    t_start = time.perf_counter()
    ev = evaluation.load_evaluator(args.dataset, "I")
    train = data.load_dataset(args.dataset, "train")
    denoiser = tasks.load_denoiser(f"denoiser_{args.dataset}")
    test = data.load_dataset(args.dataset, "test")
    args.n = args.n or len(test)
    rows, p90 = [], {
        r: float(np.percentile(a, 90))
        for r, a in metrics.amplitudes(train.landmarks).items()
    }
    print(f"training split, p90 amplitudes (mm): {p90}", flush=True)
    for steps in args.steps:
        t0 = time.perf_counter()
        x = tasks.unconditional(
            args.n, steps=steps, seed=0, denoiser=denoiser, progress=False
        )
        seconds = time.perf_counter() - t0
        measured = ev.coverage(x)
        if not rows:
            rows.append(
                table_row(
                    "test split",
                    "",
                    measured["test"],
                    ev.score(
                        test.landmarks,
                        test.targets("I"),
                        intervals=True,
                        num_resamples=200,
                    ),
                    0.0,
                )
            )
            print(rows[-1], flush=True)
        scores = ev.score(x, np.zeros(len(x), int), intervals=True, num_resamples=200)
        rows.append(
            table_row(
                "DDPM, unconditional", steps, measured["generated"], scores, seconds
            )
        )
        print(rows[-1], flush=True)
    if args.save:
        path = results.save_result(
            args.save,
            f"Coverage of unconditional samples ({args.dataset}; against the training"
            " split)",
            COLUMNS,
            rows,
            results.Run(
                allow_dirty=args.allow_dirty,
                settings=(tasks.Unconditional(),),
                checkpoints=[f"denoiser_{args.dataset}", f"ic_{args.dataset}_I"],
                seeds=[0],
                n=args.n,
                steps=args.steps,
                wall_time_s=time.perf_counter() - t_start,
            ),
            notes=(
                "training split p90 amplitudes (mm):"
                f" {', '.join(f'{r} {v:.1f}' for r, v in p90.items())}; amplitudes:"
                " metrics.amplitudes; label mix read by the type-I IC;"
                " precision/recall/density/coverage: k = 5 in the IC's feature space"
                " (logits), bootstrap intervals over the rows (rough: a resample"
                " repeats rows); FID against the training split"
            ),
        )
        print(f"saved {path}")


if __name__ == "__main__":
    main()
