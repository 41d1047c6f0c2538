"""The coverage protocol against a reference population (issue 58): does a denoiser
reproduce what new people do, judged over several seeds?

Usage: python benchmarks/population.py [--checkpoint denoiser_coma] [--seeds 0 1 2 3 4]
[--n 64] [--steps 500] [--calibrate 20] [--loss] [--save NAME]

Draws ``--n`` unconditional sequences for each of ``--seeds`` at ``--steps`` (default:
the command line's), pools them and prints (evaluation.population_gap) against the
reference population coma_people (50 new people, config.REFERENCE_POPULATIONS):

* per region (mouth opening, corner excursion, brow raise, eye closure) the median and
  the 90th percentile of each sequence's largest motion, generated minus reference (mm)
  with a 95 % interval (generated resampled by sample, the reference by person);
* the label mix as read by the IC (LSTM) and by the second reader (a temporal CNN):
  total variation to the reference's mix and the largest share over its reference
  share, each beside the 95th percentile of real sets of the same size;
* ``--calibrate K``: the same interval test on K real stand-ins (n x seeds sequences
  of 25 random reference people against the other 25): the share whose interval holds 0
  says how well the test is calibrated (a real set should pass);
* ``--loss``: the held-out denoising loss (evaluation.denoising_loss) at t = 50, 200,
  600, 1200 on the training split, on new takes of the training people (coma_retakes
  train), on the test split and on the reference population, each as a ratio to the
  training split's.

    python benchmarks/population.py --calibrate 20 --loss --save coverage_population   # about 6 min, one thread
"""

import argparse
import time

import numpy as np
import torch

from facelib import config, data, evaluation, metrics, results, tasks

REGIONS = metrics.AMPLITUDE_REGIONS


def calibration(n, repeats, num_resamples, seed=0):
    """Share of ``repeats`` real stand-ins (n sequences of 25 random reference people,
    tested against the other 25) whose interval holds 0, per region and percentile."""
    reference = data.load_dataset(config.REFERENCE_POPULATIONS["coma"], "test")
    amplitudes = metrics.amplitudes(reference.landmarks)
    people = np.unique(reference.subjects)
    rng = np.random.default_rng(seed)
    passed = {(r, q): 0 for r in REGIONS for q in evaluation.POPULATION_PERCENTILES}
    for k in range(repeats):
        half = np.isin(reference.subjects, rng.permutation(people)[: len(people) // 2])
        rows = rng.choice(np.flatnonzero(half), n)
        for (region, q) in passed:
            _, (low, high) = metrics.population_gap(
                amplitudes[region][rows],
                amplitudes[region][~half],
                reference.subjects[~half],
                lambda v, q=q: np.percentile(v, q),
                num_resamples=num_resamples,
                seed=k,
            )
            passed[region, q] += low <= 0 <= high
    return {key: v / repeats for key, v in passed.items()}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", default="denoiser_coma")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--n", type=int, default=64, help="sequences per seed")
    parser.add_argument(
        "--steps",
        type=int,
        default=tasks.Unconditional().steps,
        help="respaced reverse steps (default: the command line's)",
    )
    parser.add_argument("--calibrate", type=int, default=0, metavar="K")
    parser.add_argument("--loss", action="store_true")
    parser.add_argument("--resamples", type=int, default=2000)
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    torch.set_num_threads(1)
    t_start = time.perf_counter()
    denoiser = tasks.load_denoiser(args.checkpoint)
    x = np.concatenate(
        [
            tasks.unconditional(
                args.n, steps=args.steps, seed=s, denoiser=denoiser, progress=False
            )
            for s in args.seeds
        ]
    )
    sampled = time.perf_counter() - t_start
    per_seed = [
        [seed]
        + [
            float(np.percentile(values[k * args.n : (k + 1) * args.n], q))
            for values in metrics.amplitudes(x).values()
            for q in evaluation.POPULATION_PERCENTILES
        ]
        for k, seed in enumerate(args.seeds)
    ]
    print(f"{len(x)} samples ({len(args.seeds)} seeds x {args.n}) in {sampled:.0f} s")
    gap = evaluation.population_gap(x, num_resamples=args.resamples)
    rows = []  # measure, value, 95 % interval, real sets' p95, calibration
    passed = calibration(len(x), args.calibrate, args.resamples // 4) if args.calibrate else {}
    for region in REGIONS:
        for q in evaluation.POPULATION_PERCENTILES:
            value, ci = gap["amplitudes"][region][f"p{q}"]
            share = passed.get((region, q), "")
            rows.append([f"{region} p{q} (mm)", value, list(ci), "", share])
    for reader, mix in gap["label_mix"].items():
        rows.append([f"label mix TV ({reader})", mix["tv"], "", mix["tv_real"], ""])
        rows.append(
            [
                f"largest label share / reference ({reader})",
                mix["max_ratio"],
                "",
                mix["max_ratio_real"],
                "",
            ]
        )
        shares = mix["mix"] / mix["reference_mix"]
        print(
            f"{reader}: "
            + ", ".join(f"{c} {v:.2f}" for c, v in zip(mix["class_names"], shares))
        )
    if args.loss:
        splits = {
            "training split": ("coma", "train"),
            "new takes": (config.NEW_TAKES["coma"], "train"),
            "test split": ("coma", "test"),
            "new people": (config.REFERENCE_POPULATIONS["coma"], "test"),
        }
        losses = {
            name: evaluation.denoising_loss(denoiser, data.load_dataset(*split).landmarks)
            for name, split in splits.items()
        }
        for t, base in losses["training split"].items():
            rows.append([f"loss at t = {t}, training split", base, "", "", ""])
            for name in list(splits)[1:]:
                ratio = losses[name][t] / base
                rows.append([f"loss at t = {t}, {name} / training split", ratio, "", "", ""])
    for row in rows:
        interval = "" if row[2] == "" else "[%.3f, %.3f]" % tuple(row[2])
        print(f"{row[0]:<48} {row[1]:8.4g}  {interval:<18} {row[3]!s:<8} {row[4]}")
    if args.save:
        run = results.Run(
            allow_dirty=args.allow_dirty,
            settings=(tasks.Unconditional(),),
            checkpoints=[args.checkpoint, "ic_coma_I", "ic_coma_I_cnn"],
            seeds=args.seeds,
            n=args.n,
            steps=[args.steps],
            wall_time_s=time.perf_counter() - t_start,
        )
        path = results.save_result(
            args.save,
            f"Coverage of unconditional samples against a reference population"
            f" ({args.checkpoint}, {len(args.seeds)} seeds x {args.n})",
            ["measure", "generated - reference", "95 % interval", "real sets' p95", "calibration"],
            rows,
            run,
            notes=(
                "amplitudes: generated minus reference (coma_people, 50 people), interval"
                " by metrics.population_gap; calibration: the share of real stand-ins"
                " (25 people against the other 25) whose interval holds 0. Label mix"
                " rows: the value and the 95th percentile of real sets of the same size"
                " (metrics.label_mix_gap). Loss rows (evaluation.denoising_loss): the"
                " training split's loss at t, then each other set's as a ratio to it"
            ),
        )
        print(f"saved {path}")
        path = results.save_result(
            args.save + "_seeds",
            f"Each seed's amplitude percentiles ({args.checkpoint}, {args.n} samples a"
            " seed) and the reference population's",
            ["seed"]
            + [f"{r} p{q} (mm)" for r in REGIONS for q in evaluation.POPULATION_PERCENTILES],
            per_seed + [["reference"] + reference_percentiles()],
            run,
            notes="one row per seed of the pooled samples; the last row: coma_people",
        )
        print(f"saved {path}")


def reference_percentiles():
    """The reference population's amplitude percentiles, region by region (mm)."""
    reference = data.load_dataset(config.REFERENCE_POPULATIONS["coma"], "test")
    return [
        float(np.percentile(values, q))
        for values in metrics.amplitudes(reference.landmarks).values()
        for q in evaluation.POPULATION_PERCENTILES
    ]


if __name__ == "__main__":
    main()
