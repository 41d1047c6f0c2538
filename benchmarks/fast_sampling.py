"""Fewer steps and guidance without a classifier (issue 27): DDIM against respaced DDPM,
classifier-free against classifier guidance, and editing by DDIM inversion, on coma.

Usage: python benchmarks/fast_sampling.py [--experiment steps|guidance|edit] [--tasks
...] [--n N] [--save NAME] steps (default): unconditional sampling and label control (Alg. 1, and the mean shift of scale
    --mean-shift-scale) with the ancestral DDPM step and with DDIM (eta = 0) on chains
      of 10, 20, 50, 100, 200
    and 2000 steps: seconds per sequence, IC accuracy, FID and diversity with 95 %
    bootstrap intervals (n = 48 sequences, the labels in equal numbers).  --tasks runs
    some of the three; with --save, their rows replace those of the stored table and the
    other rows stay.
guidance: classifier guidance (Alg. 1, and the mean shift at several scales s: the
unconditional denoiser and
    guide_coma_I) against classifier-free guidance (denoiser_coma_cfg) at several
    weights w, each with DDPM and DDIM on 50 and 200 steps: accuracy, FID, diversity,
    seconds per sequence and the peak memory of sampling (each row in a fresh process:
    its peak resident memory above what loading the models took).
edit: DDIM inversion of the first n = 32 test sequences at 100 steps (refine 0, 1, 2:
the reconstruction error in
    mm), then editing each towards another label (the IC's reading of the new label, the
    neutral frame's drift in mm, the correlation of the motion's timing with the
    original's), by Alg. 1, the mean shift and classifier-free guidance, each
    regenerating every frame or keeping the neutral one (then the drift is that of the
    frame next to it).  --edit-runs runs some parts, --edit-scales several mean-shift
    scales.
--save NAME writes the table to results/NAME.json (facelib.results: provenance,
  checkpoint hashes).
"""

import argparse
import gc
import multiprocessing
import os
import time

import numpy as np
import torch

from facelib import config, data, evaluation, results, tasks

STEPS = [10, 20, 50, 100, 200, 2000]
CFG_SCALES = [1.0, 1.5, 2.5, 4.0]
MEAN_SHIFT_SCALES = [1.0, 3.0, 10.0, 30.0]
EDIT_RUNS = ("inversion", "alg1", "mean_shift", "cfg")
SCORE_COLUMNS = [
    "Acc (%)",
    "95 % interval",
    "FID",
    "95 % interval",
    "diversity",
    "95 % interval",
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
    ]


def balanced_labels(ev, n):
    """n labels cycling through the IC's classes, and their class indices."""
    labels = [ev.class_names[i % len(ev.class_names)] for i in range(n)]
    return labels, np.array([ev.class_index(y) for y in labels])


def steps_tasks(mean_shift_scale):
    """{--tasks name: (row name, label control's settings changed; None: unconditional
    sampling)}."""
    return {
        "unconditional": ("unconditional", None),
        "alg1": ("label control (Alg. 1)", {"method": "adagrad"}),
        "mean_shift": (
            f"label control (mean shift, s = {mean_shift_scale:g})",
            {"method": "mean_shift", "scale": mean_shift_scale},
        ),
    }


def steps_experiment(args, ev):
    labels, targets = balanced_labels(ev, args.n)
    denoiser, guide = tasks.load_denoiser("denoiser_coma"), tasks.load_guide("coma")
    rows = []
    for task, changed in (
        steps_tasks(args.mean_shift_scale)[name] for name in args.tasks
    ):
        for sampler in ("ddpm", "ddim"):
            for steps in args.steps:
                common = dict(
                    steps=steps,
                    seed=0,
                    sampler=sampler,
                    denoiser=denoiser,
                    progress=False,
                )
                t0 = time.perf_counter()
                if changed is None:
                    x = tasks.unconditional(args.n, **common)
                else:
                    x = tasks.label_control(
                        labels, args.n, guide=guide, **common, **changed
                    )
                dt = time.perf_counter() - t0
                scores = scored(
                    ev, x, ev.features(x).argmax(1) if changed is None else targets
                )
                if changed is None:  # no target: no accuracy
                    scores[:2] = ["", ""]
                rows.append([task, sampler, steps, round(dt / args.n, 3), *scores])
                print(
                    f"{task:>24} {sampler:>5} {steps:>5} {rows[-1][3]:>8.3f} s/seq  Acc"
                    f" {rows[-1][4]}  FID {rows[-1][6]:6.2f}",
                    flush=True,
                )
    return ["task", "sampler", "steps", "s per sequence"] + SCORE_COLUMNS, rows


def _memory_kib(field):
    """A field of /proc/self/status in KiB (VmRSS: resident now; VmHWM: the peak since
    the last reset)."""
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith(field + ":"))


def _sample_in_child(kind, labels, steps, sampler, scale, threads):
    """One guided run in a fresh process (CPU): (sequences, seconds, the peak resident
    memory of sampling above the memory the loaded models hold, MiB).  The peak is reset
    after loading (Linux: /proc/self/clear_refs).
    """
    torch.set_num_threads(threads)
    if kind in ("adagrad", "mean_shift"):
        models = dict(
            denoiser=tasks.load_denoiser("denoiser_coma"),
            guide=tasks.load_guide("coma"),
            method=kind,
            scale=scale,
        )
    else:
        models = dict(
            denoiser=tasks.load_denoiser("denoiser_coma_cfg"),
            guidance="cfg",
            scale=scale,
        )
    gc.collect()
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # resets VmHWM to the present VmRSS
    loaded = _memory_kib("VmRSS")
    t0 = time.perf_counter()
    x = tasks.label_control(
        labels,
        len(labels),
        steps=steps,
        seed=0,
        sampler=sampler,
        progress=False,
        **models,
    )
    seconds = time.perf_counter() - t0
    return x, seconds, (_memory_kib("VmHWM") - loaded) / 1024


def guidance_experiment(args, ev):
    labels, targets = balanced_labels(ev, args.n)
    runs = [("classifier guidance (Alg. 1)", "adagrad", None)]
    runs += [
        (f"classifier guidance (mean shift, s = {s:g})", "mean_shift", s)
        for s in MEAN_SHIFT_SCALES
    ]
    runs += [(f"classifier-free, w = {w:g}", "cfg", w) for w in CFG_SCALES]
    rows = []
    context = multiprocessing.get_context("spawn")
    for steps in (50, 200):
        for sampler in ("ddpm", "ddim"):
            for name, kind, scale in runs:
                with context.Pool(1) as pool:
                    x, seconds, peak = pool.apply(
                        _sample_in_child,
                        (kind, labels, steps, sampler, scale, torch.get_num_threads()),
                    )
                rows.append(
                    [
                        name,
                        sampler,
                        steps,
                        round(seconds / args.n, 3),
                        round(peak, 1),
                        *scored(ev, x, targets),
                    ]
                )
                print(
                    f"{name:>30} {sampler:>5} {steps:>4} {rows[-1][3]:>7.3f} s/seq"
                    f" {peak:7.1f} MiB  Acc {rows[-1][5]:5.1f}  FID {rows[-1][7]:6.2f}",
                    flush=True,
                )
    return [
        "guidance",
        "sampler",
        "steps",
        "s per sequence",
        "peak memory (MiB)",
    ] + SCORE_COLUMNS, rows


def neutral_frames(x, kinds):
    """The neutral frame of each sequence: the first for N2E, the last for E2N."""
    return x[np.arange(len(x)), data.neutral_frame_indices(kinds, x.shape[1])]


def next_to_neutral(x, kinds):
    """The frame next to the neutral one: the second for N2E, the last but one for
    E2N."""
    i = data.neutral_frame_indices(kinds, x.shape[1])
    return x[np.arange(len(x)), np.where(i == 0, 1, i - 1)]


def rms_mm(a, b):
    """Root mean square over the landmarks of the distance between landmark sets (...,
    68, 3), in mm."""
    return np.sqrt((np.linalg.norm(a - b, axis=-1) ** 2).mean(-1))


def timing_correlation(a, b, kinds):
    """Pearson r between the motion profiles (mean landmark distance from the neutral
    frame, per frame) of each pair of sequences."""

    def profile(x):
        return np.linalg.norm(x - neutral_frames(x, kinds)[:, None], axis=-1).mean(-1)

    pa, pb = profile(a), profile(b)
    return np.array([np.corrcoef(u, v)[0, 1] for u, v in zip(pa, pb)])


def edit_experiment(args, ev):
    """Two tables in one: the inversion's reconstruction error, and the edits' measures
    (columns left blank where a measure does not apply)."""
    test = data.load_dataset("coma", "test")
    pick = np.arange(min(args.n, len(test)))
    x, kinds, own = test.landmarks[pick], test.kinds[pick], test.labels[pick]
    names = ev.class_names
    others = [[j for j in range(len(names)) if j != y] for y in own]
    new = np.array(
        [o[i % len(o)] for i, o in enumerate(others)]
    )  # another label for each, all used
    models = dict(
        denoiser=tasks.load_denoiser("denoiser_coma"), guide=tasks.load_guide("coma")
    )
    cfg_models = dict(denoiser=tasks.load_denoiser("denoiser_coma_cfg"), guidance="cfg")
    blank = [""] * 7  # the edit columns
    rows = []
    for refine in ((0, 1, 2) if "inversion" in args.edit_runs else ()):
        den = models["denoiser"]
        chain = den.diffusion_with(100, eta=0.0)
        back = den.to_mm(
            chain.run(
                den.model,
                tasks.invert(den, x, tasks.Edit(refine=refine)),
                progress=False,
            )
        )
        rmse = np.sqrt(((back - x) ** 2).sum(-1).mean((1, 2)))
        rows.append(
            [
                "inversion, then regeneration",
                f"refine {refine}",
                *np.percentile(rmse, [50, 90, 100]),
                *blank,
            ]
        )
        print(
            f"inversion refine {refine}: RMSE median {rows[-1][2]:.4f} mm, p90"
            f" {rows[-1][3]:.4f}, max {rows[-1][4]:.4f}",
            flush=True,
        )
    if (
        "inversion" in args.edit_runs
    ):  # what unrelated sequences share: the timing r with another of the same kind
        partner = np.array(
            [
                next(j for j in np.roll(pick, -1 - i) if kinds[j] == kinds[i])
                for i in pick
            ]
        )
        r_unrelated = float(
            np.median(timing_correlation(x, test.landmarks[partner], kinds))
        )
        rows.append(
            [
                "two different test sequences of the same order",
                "",
                *[""] * 8,
                r_unrelated,
                "",
            ]
        )
    keep = np.zeros(x.shape[:2], dtype=bool)  # the neutral frame of each sequence
    keep[np.arange(len(x)), data.neutral_frame_indices(kinds, x.shape[1])] = True
    runs = {
        "alg1": [("classifier guidance (Alg. 1)", dict(models, method="adagrad"))],
        "mean_shift": [
            (f"mean shift (scale {s:g})", dict(models, method="mean_shift", scale=s))
            for s in args.edit_scales or [args.mean_shift_scale]
        ],
        "cfg": [(f"classifier-free (w = {config.CFG_SCALE:g})", cfg_models)],
    }
    runs = [
        run for part in EDIT_RUNS[1:] if part in args.edit_runs for run in runs[part]
    ]
    for name, kwargs in runs:
        for kept in (False, True):
            t0 = time.perf_counter()
            edited = tasks.edit(
                x,
                [names[j] for j in new],
                keep=keep if kept else None,
                progress=False,
                **kwargs,
            )
            dt = time.perf_counter() - t0
            drift = rms_mm(neutral_frames(edited, kinds), neutral_frames(x, kinds))
            # the seam at the kept frame: how far the first regenerated frame moves from
            # it, against the original
            seam = rms_mm(
                next_to_neutral(edited, kinds), neutral_frames(edited, kinds)
            ) - rms_mm(next_to_neutral(x, kinds), neutral_frames(x, kinds))
            s = ev.score(edited, new, intervals=True)
            r = timing_correlation(x, edited, kinds)
            rows.append(
                [
                    f"edit, {name}",
                    "neutral frame kept" if kept else "every frame regenerated",
                    "",
                    "",
                    "",
                    float(np.median(drift)),
                    float(np.max(drift)),
                    float(np.median(seam)),
                    s["accuracy"],
                    list(s["accuracy_ci"]),
                    float(np.median(r)),
                    round(dt / len(x), 3),
                ]
            )
            print(
                f"{rows[-1][0]}, {rows[-1][1]}: neutral drift median {rows[-1][5]:.3f}"
                f" mm, seam {rows[-1][7]:+.3f} mm; IC reads the new label"
                f" {s['accuracy']:.1f} %; timing r {rows[-1][10]:.3f}",
                flush=True,
            )
    return [
        "run",
        "setting",
        "RMSE median (mm)",
        "RMSE 90th percentile (mm)",
        "RMSE max (mm)",
        "neutral drift median (mm)",
        "neutral drift max (mm)",
        "seam change median (mm)",
        "new label read (%)",
        "95 % interval",
        "timing r (median)",
        "s per sequence",
    ], rows


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--experiment", choices=["steps", "guidance", "edit"], default="steps"
    )
    parser.add_argument(
        "--n",
        type=int,
        default=None,
        help="sequences per row (steps, guidance: 48; edit: 32)",
    )
    parser.add_argument(
        "--steps",
        type=int,
        nargs="+",
        default=STEPS,
        help=f"steps: the chains' lengths (default {' '.join(map(str, STEPS))})",
    )
    parser.add_argument(
        "--tasks",
        nargs="+",
        choices=list(steps_tasks(0)),
        default=list(steps_tasks(0)),
        help="steps: the tasks to run (default: all)",
    )
    parser.add_argument(
        "--mean-shift-scale",
        type=float,
        default=config.MEAN_SHIFT_SCALE,
        help=(
            "steps, edit: the mean-shift rows' scale s (default:"
            " config.MEAN_SHIFT_SCALE)"
        ),
    )
    parser.add_argument(
        "--edit-runs",
        nargs="+",
        choices=EDIT_RUNS,
        default=list(EDIT_RUNS),
        help=(
            "edit: the parts to run (default: all); with --save, their rows replace"
            " those of the stored table and the other rows stay"
        ),
    )
    parser.add_argument(
        "--edit-scales",
        type=float,
        nargs="+",
        default=None,
        help="edit: the mean shift's scales (default: --mean-shift-scale)",
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    args.n = args.n or (32 if args.experiment == "edit" else 48)
    if args.n < 24:  # two per class: multimodality and the intervals need them
        parser.error(
            "--n must be at least 24 (two sequences of each of the 12 labels), got"
            f" {args.n}"
        )
    experiment = {
        "steps": steps_experiment,
        "guidance": guidance_experiment,
        "edit": edit_experiment,
    }[args.experiment]
    print(
        f"cores: {os.cpu_count()}, torch threads: {torch.get_num_threads()},"
        f" experiment: {args.experiment}, n = {args.n}",
        flush=True,
    )
    t0 = time.perf_counter()
    ev = evaluation.load_evaluator("coma", "I")
    if args.experiment != "steps":
        tasks.load_denoiser(
            "denoiser_coma_cfg"
        )  # fail now, not after the classifier rows
    columns, rows = experiment(args, ev)
    if args.save:
        checkpoints = ["denoiser_coma", "guide_coma_I", "ic_coma_I"]
        checkpoints += [] if args.experiment == "steps" else ["denoiser_coma_cfg"]
        titles = {
            "steps": (
                "DDIM against respaced DDPM: quality against the number of steps (coma)"
            ),
            "guidance": (
                "Classifier guidance (Alg. 1) against classifier-free guidance (coma)"
            ),
            "edit": "DDIM inversion and editing of test sequences (coma)",
        }
        steps = {"steps": args.steps, "guidance": [50, 200], "edit": [100]}[
            args.experiment
        ]
        provenance = None
        if args.experiment == "steps" and set(args.tasks) != set(steps_tasks(0)):
            rows, provenance = results.merged_rows(
                args.save, rows, key_length=3
            )  # the other tasks' rows stay
        if args.experiment == "edit" and set(args.edit_runs) != set(EDIT_RUNS):
            rows, provenance = results.merged_rows(args.save, rows, key_length=2)
        path = results.save_result(
            args.save,
            title=titles[args.experiment],
            columns=columns,
            rows=rows,
            run=results.Run(
                allow_dirty=args.allow_dirty,
                checkpoints=checkpoints,
                seeds=[0],
                n=args.n,
                steps=steps,
                wall_time_s=time.perf_counter() - t0,
            ),
            notes=(
                f"intervals: 95 % bootstrap over the sequences (Evaluator.score); FID"
                f" against the training split from n sequences; DDIM at eta = 0; label"
                f" control with the book's defaults (tasks.LabelControl); steps with"
                f" --tasks, edit with --edit-runs: the other rows are those of earlier"
                f" runs (the commit, date and wall time above are the last run's;"
                f" row_provenance names each row's run)"
            ),
            row_provenance=provenance,
        )
        print(f"saved {path}")


if __name__ == "__main__":
    main()
