"""Table 5 in full: every deformer over its training seeds, the closed-form regression,
paired differences.

Usage: python benchmarks/deformation_table5.py [--frames 4] [--save NAME]

For each split of §6 (deformation.split_datasets) every shipped deformer predicts
``--frames`` evenly spaced frames of every test sequence; the error is Table 5's mean
per-vertex Euclidean error (mm).  The methods with several training seeds
(training.SHIPPED: ``deform_<method>_<split>[_seed<k>]``) give mean +- std over the
seeds.  Reference rows: no motion, and the closed-form ridge regression Delta M ~ A
Delta L + b (deformation.fit_linear_regression) fitted on the training pairs, once on
the captured landmarks the networks see and once on the world's noise-free landmarks
(scored on noise-free test landmarks).  For every network, the difference to ours (seed
0) paired over the test faces with a 95 % bootstrap interval, and for ours the
   attention's mean entropy over its seeds against uniform weights, log(coarse
   vertices).

    python benchmarks/deformation_table5.py --save deformation_table5

(both splits, every shipped deformer: 22 networks in world 2, about 20 minutes with one
torch thread.)
"""

import argparse
import time

import numpy as np

from facelib import deformation, results, training

COLUMNS = [
    "split",
    "method",
    "mean (mm)",
    "std over seeds (mm)",
    "seeds",
    "per-seed means (mm)",
    "95 % interval (seed 0)",
    "minus ours, paired (mm)",
    "paired 95 % interval",
    "attention entropy (nats)",
]


def checkpoints_of(method, split):
    """The shipped checkpoints of a method and split: seed 0 first."""
    base = deformation.deformer_checkpoint(method, split)
    return [base] + sorted(n for n in training.SHIPPED if n.startswith(base + "_seed"))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--frames", type=int, default=4, help="frames per test sequence (default 4)"
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    t_start = time.perf_counter()
    rows, used, tested = [], [], 0
    for split in deformation.SPLITS:
        train, test = deformation.split_datasets(split)
        pairs = deformation.make_pairs(test, args.frames)
        tested += len(test)
        exact = deformation.make_pairs(test, args.frames, noise_free=True)
        errors = {"no motion": np.linalg.norm(pairs.delta_mesh, axis=-1)}
        for name, tr, te in (
            ("regression, captured landmarks", False, pairs),
            ("regression, noise-free landmarks", True, exact),
        ):
            coef = deformation.fit_linear_regression(
                deformation.make_pairs(train, args.frames, seed=0, noise_free=tr)
            )
            errors[name] = deformation.linear_regression_errors(coef, te)
        seeds = {}
        for method in deformation.METHODS:
            names = checkpoints_of(method, split)
            used += names
            per_seed = [
                np.linalg.norm(
                    deformation.predict(
                        deformation.load_deformer(method, split, n), pairs
                    )
                    - pairs.delta_mesh,
                    axis=-1,
                )
                for n in names
            ]
            errors[method], seeds[method] = per_seed[0], per_seed
        ours = errors["ours"]
        for name, e in errors.items():
            runs = seeds.get(name, [e])
            mean, std = deformation.over_seeds([r.mean() for r in runs])
            diff, ci = deformation.paired_difference(e, ours, pairs.subjects)
            entropy = (
                float(
                    np.mean(
                        [
                            deformation.attention_entropy(
                                deformation.load_deformer("ours", split, n), pairs
                            ).mean()
                            for n in checkpoints_of("ours", split)
                        ]
                    )
                )
                if name == "ours"
                else None
            )
            rows.append(
                [
                    split,
                    deformation.METHOD_NAMES.get(name, f"({name})"),
                    mean,
                    std,
                    len(runs),
                    [float(r.mean()) for r in runs],
                    list(deformation.error_summary(e, pairs)["ci"]),
                    diff,
                    list(ci),
                    entropy,
                ]
            )
            print(rows[-1][:5], rows[-1][7:], flush=True)
    if args.save:
        seeds = sorted({training.SHIPPED[n][1].get("seed", 0) for n in used})
        coarse = deformation.load_deformer("ours", "identity").num_coarse
        results.save_result(
            args.save,
            "Table 5: per-vertex error over training seeds, with the closed-form "
            "regression",
            COLUMNS,
            rows,
            results.Run(
                allow_dirty=args.allow_dirty,
                checkpoints=sorted(set(used)),
                seeds=seeds,
                n=tested,
                steps=[],
                wall_time_s=time.perf_counter() - t_start,
            ),
            notes=(
                f"n: test sequences of both splits; {args.frames} evenly spaced frames"
                f" each; uniform attention over {coarse} coarse vertices: entropy log"
                f" {coarse} = {np.log(coarse):.3f} nats"
            ),
        )


if __name__ == "__main__":
    main()
