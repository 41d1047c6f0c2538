"""Label control (Alg. 1): time and score guided sequences, sweep its settings, or run
Table 1.

Usage: python benchmarks/label_control.py [--experiment steps|sweep|table1|per_label]
[--dataset coma [bu]]
                                          [--n 64] [--steps 2000 200 100] [--lr 0.03]
                                          [--save NAME]
steps (default): n sequences cycling through the dataset's labels, for each number of
reverse
    steps (2000 = the paper's T; fewer = respaced): wall time, time per step, IC
    accuracy and FID (against the training split, from n sequences: compare rows with
    each other, not with tables computed from another n), each with a 95 % bootstrap
    interval.
sweep: chapter 05's full sweep at one step count (default 200), n sequences per setting
(the
    labels in equal numbers, seed 11): the Adagrad rate on every dataset given, and on
    "coma" the weight lambda, the mean-shift scale and no guidance.
table1: chapter 05's Table 1 on the whole test split (or its first --n sequences): GT,
the two
    baselines, the unguided DDPM, mean shift (--mean-shift-scale) and Alg. 1, with
    intervals.
per_label: the command line's label control (tasks.LabelControl: its steps, guidance
and rate), n
    sequences per label, against the test split's sequences of that label, both read by
    the IC: accuracy per label with 95 % intervals (does guidance reach every label, the
    rare and subtle ones too?); and, where the dataset has a reference population
    (issue 58), each reader's accuracy minus the population's on its sequences of the
    label, with an interval that resamples the people.
--save NAME writes the table to results/NAME.json (facelib.results: provenance,
  checkpoint hashes).
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
    experiments,
    metrics,
    results,
    tasks,
)

SWEEP_LR = {
    "coma": [0.001, 0.003, 0.01, 0.03, 0.05, 0.1],
    "bu": [0.01, 0.03, 0.05, 0.1],
}  # at 200 steps
SWEEP_WEIGHTS = [0.0, 0.01, 1.0]
SWEEP_SCALES = [1.0, 3.0, 10.0, 30.0]
SCORE_COLUMNS = [
    "Acc (%)",
    "95 % interval",
    "FID",
    "95 % interval",
    "diversity",
    "95 % interval",
    "multimodality",
]


def scored(ev, x, targets):
    s = ev.score(x, targets, intervals=True)
    return [
        s["accuracy"],
        list(s["accuracy_ci"]),
        s["fid"],
        list(s["fid_ci"]),
        s["diversity"],
        list(s["diversity_ci"]),
        s["multimodality"],
    ]


def steps_experiment(args, name, ev, guide, denoiser):
    labels = [ev.class_names[i % len(ev.class_names)] for i in range(args.n)]
    targets = np.array([ev.class_index(y) for y in labels])
    test = data.load_dataset(name, "test")
    pick = np.random.default_rng(0).choice(
        len(test), min(args.n, len(test)), replace=False
    )
    rows = [
        [
            name,
            "GT (random test sequences)",
            "",
            "",
            *scored(ev, test.landmarks[pick], test.targets("I")[pick]),
        ]
    ]
    print(
        f"{'GT':>6}{'':>19}{rows[0][4]:>8.1f}{rows[0][6]:>8.2f}   ({len(pick)} random"
        " test sequences)"
    )
    for steps in args.steps:
        t0 = time.perf_counter()
        lr = tasks.adagrad_lr(name, steps) if args.lr is None else args.lr
        x = tasks.label_control(
            labels,
            args.n,
            dataset=name,
            steps=steps,
            seed=0,
            guide=guide,
            denoiser=denoiser,
            lr=lr,
            progress=False,
        )
        dt = time.perf_counter() - t0
        rows.append([name, steps, round(dt, 1), f"{lr:.4g}", *scored(ev, x, targets)])
        print(
            f"{steps:>6}{dt:>10.1f}{1e3 * dt / steps:>9.1f}{rows[-1][4]:>8.1f}{rows[-1][6]:>8.2f}{lr:>9.4f}",
            flush=True,
        )
    return ["dataset", "reverse steps", "time (s)", "Adagrad lr"] + SCORE_COLUMNS, rows


def sweep_experiment(args, name, ev, guide, denoiser):
    steps = args.steps[0]
    per_label = args.n // len(ev.class_names)
    labels = [y for y in ev.class_names for _ in range(per_label)]
    targets = np.array([ev.class_index(y) for y in labels])
    settings = [
        (
            "Adagrad lr at 200 steps",
            lr,
            dict(lr=tasks.step_scaled_lr(lr, config.LR_REFERENCE_STEPS, steps)),
        )
        for lr in SWEEP_LR.get(name, [])
    ]
    if name == "coma":
        settings += [("lambda", w, dict(guidance_weight=w)) for w in SWEEP_WEIGHTS]
        settings += [
            ("mean-shift scale", s, dict(method="mean_shift", scale=s))
            for s in SWEEP_SCALES
        ]
    rows = []
    for setting, value, kwargs in settings:
        x = tasks.label_control(
            labels,
            len(labels),
            dataset=name,
            steps=steps,
            seed=11,
            guide=guide,
            denoiser=denoiser,
            progress=False,
            **kwargs,
        )
        rows.append([name, setting, f"{value:g}", *scored(ev, x, targets)])
        print(
            f"{name:>6} {setting:>24}"
            f" {value:>8g}{rows[-1][3]:>8.1f}{rows[-1][5]:>8.2f}",
            flush=True,
        )
    x = tasks.unconditional(
        len(labels), steps=steps, seed=11, denoiser=denoiser, progress=False
    )
    rows.append([name, "no guidance", "", *scored(ev, x, targets)])
    return ["dataset", "setting", "value"] + SCORE_COLUMNS, rows


def table1_experiment(args, name, ev, guide, denoiser):
    steps = args.steps[0]
    test = data.load_dataset(name, "test")
    n = min(args.n or len(test), len(test))
    targets = test.targets("I")[:n]
    generators = experiments.table1_generators(
        name, range(n), steps, guide, denoiser, args.mean_shift_scale
    )
    rows = []
    for row, generate in generators.items():
        t0 = time.perf_counter()
        x = generate()
        dt = time.perf_counter() - t0
        rows.append([name, row, n, *scored(ev, x, targets), round(dt, 1)])
        print(
            f"{name:>6} {row:>34}{rows[-1][3]:>8.1f}{rows[-1][5]:>8.2f}{dt:>8.1f}",
            flush=True,
        )
    return ["dataset", "model", "n"] + SCORE_COLUMNS + ["time (s)"], rows


def per_label_experiment(args, name, ev, guide, denoiser):
    settings = tasks.LabelControl(dataset=name)
    test = data.load_dataset(name, "test")
    test_targets = test.targets("I")
    # issue 58: both readers, against the reference population's sequences of the label
    population = config.REFERENCE_POPULATIONS.get(name)
    people = None if population is None else data.load_dataset(population, "test")
    readers = {
        r: evaluation.load_evaluator(name, "I", reader=r)
        for r in evaluation.ARCHITECTURES
    }
    rows = []
    for k, label in enumerate(ev.class_names):
        t0 = time.perf_counter()
        x = tasks.label_control(
            label,
            args.n,
            settings,
            denoiser=denoiser,
            guide=guide,
            progress=False,
            seed=k,
        )
        dt = time.perf_counter() - t0
        cells = []
        for seqs in (x, test.landmarks[test_targets == k]):
            hits = 100.0 * (ev.features(seqs).argmax(1) == k)
            low, high = metrics.bootstrap_interval(np.mean, hits, seed=0)
            cells += [
                float(hits.mean()),
                [max(float(low), 0.0), min(float(high), 100.0)],
                len(seqs),
            ]
        if people is not None:
            theirs = people.targets("I") == k
            for reader in readers.values():
                mine = 100.0 * (reader.features(x).argmax(1) == k)
                ref = 100.0 * (reader.features(people.landmarks[theirs]).argmax(1) == k)
                gap, interval = metrics.population_gap(
                    mine, ref, people.subjects[theirs], np.mean, seed=0
                )
                cells += [float(mine.mean()), float(ref.mean()), float(gap),
                          list(interval)]
        rows.append([name, label, *cells, round(dt, 1)])
        print(
            f"{label:>14}{cells[0]:>8.1f} [{cells[1][0]:5.1f}, {cells[1][1]:5.1f}] "
            f" test{cells[3]:>8.1f} ({cells[5]} seqs)"
            + "".join(
                f"  {r} {cells[6 + 4 * i + 2]:+6.1f} [{cells[6 + 4 * i + 3][0]:+6.1f},"
                f" {cells[6 + 4 * i + 3][1]:+6.1f}]"
                for i, r in enumerate(readers) if people is not None
            )
            + f"{dt:>8.1f} s",
            flush=True,
        )
    by_reference = [
        c
        for r in readers
        for c in (
            f"Acc (%) ({r})",
            f"people's Acc (%) ({r})",
            f"gap (points) ({r})",
            "gap 95 % interval",
        )
    ]
    return [
        "dataset",
        "label",
        "Acc (%)",
        "95 % interval",
        "n",
        "test Acc (%)",
        "test 95 % interval",
        "test n",
        *(by_reference if people is not None else []),
        "time (s)",
    ], rows


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--experiment",
        choices=["steps", "sweep", "table1", "per_label"],
        default="steps",
    )
    parser.add_argument("--dataset", nargs="+", default=["coma"])
    parser.add_argument(
        "--n",
        type=int,
        default=None,
        help=(
            "sequences per row (steps: 64; sweep: 48; table1: the whole test split;"
            " per_label: 32)"
        ),
    )
    parser.add_argument(
        "--steps",
        type=int,
        nargs="+",
        default=None,
        help=(
            "reverse steps (steps: 2000 500 200 100; sweep and table1: one value, 200; "
            "per_label: the command line's, tasks.LabelControl)"
        ),
    )
    parser.add_argument(
        "--lr",
        type=float,
        default=None,
        help="steps: one Adagrad rate for every row (default: tasks.adagrad_lr)",
    )
    parser.add_argument(
        "--mean-shift-scale",
        type=float,
        default=10.0,
        help="table1: the mean-shift row's scale",
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    if args.experiment == "per_label" and args.steps is not None:
        parser.error(
            "--experiment per_label runs the command line's steps"
            " (tasks.LabelControl); drop --steps"
        )
    if args.steps is None:
        args.steps = {
            "steps": [2000, 500, 200, 100],
            "per_label": [tasks.LabelControl().steps],
        }.get(args.experiment, [200])
    elif args.experiment != "steps" and len(args.steps) != 1:
        parser.error(
            f"--experiment {args.experiment} takes one --steps value, got {args.steps}"
        )
    if args.n is None and args.experiment != "table1":
        args.n = {"steps": 64, "per_label": 32}.get(args.experiment, 48)
    if args.n is not None and args.n < 2:
        parser.error(
            "--n must be at least 2 (intervals are bootstrapped over the sequences),"
            f" got {args.n}"
        )
    experiment = {
        "steps": steps_experiment,
        "sweep": sweep_experiment,
        "table1": table1_experiment,
        "per_label": per_label_experiment,
    }[args.experiment]
    print(
        f"cores: {os.cpu_count()}, torch threads: {torch.get_num_threads()},"
        f" experiment: {args.experiment}, n = {args.n}, steps {args.steps}; Adagrad lr"
        f" {config.ADAGRAD_LR} at {config.LR_REFERENCE_STEPS} steps, x"
        f" sqrt({config.LR_REFERENCE_STEPS} / steps), lambda {config.GUIDANCE_WEIGHT}"
    )
    t0, rows, checkpoints = time.perf_counter(), [], []
    for name in args.dataset:
        ev = evaluation.load_evaluator(name, "I")
        guide, denoiser = tasks.load_guide(name), tasks.load_denoiser(
            f"denoiser_{name}"
        )
        columns, new = experiment(args, name, ev, guide, denoiser)
        rows += new
        checkpoints += [f"denoiser_{name}", f"ic_{name}_I", f"guide_{name}_I"]
        if args.experiment == "per_label" and name in config.REFERENCE_POPULATIONS:
            checkpoints += [f"ic_{name}_I_cnn"]
        if args.experiment == "table1":
            checkpoints += [f"{b}_{name}" for b in baselines.LABEL_BASELINES]
    if args.save:
        titles = {
            "steps": "Label control (Alg. 1) at several numbers of reverse steps",
            "sweep": (
                f"Label control: the settings of Alg. 1 and mean shift, {args.steps[0]}"
                " steps"
            ),
            "table1": (
                f"Table 1 (label control), {args.steps[0]} reverse steps for the DDPM"
                " rows"
            ),
            "per_label": (
                "Label control per label at the command line's settings"
                f" ({args.steps[0]} steps)"
            ),
        }
        path = results.save_result(
            args.save,
            title=titles[args.experiment],
            columns=columns,
            rows=rows,
            run=results.Run(
                allow_dirty=args.allow_dirty,
                checkpoints=checkpoints,
                seeds=[0, 11],
                n=args.n
                or max(len(data.load_dataset(d, "test")) for d in args.dataset),
                steps=args.steps,
                wall_time_s=time.perf_counter() - t0,
                settings=(
                    (tasks.LabelControl(),) if args.experiment == "per_label" else ()
                ),
            ),
            notes=(
                "intervals: 95 % bootstrap over the sequences (Evaluator.score); "
                "table1: the rows of each dataset use n = its whole test split "
                "(column n)"
            ),
        )
        print(f"saved {path}")


if __name__ == "__main__":
    main()
