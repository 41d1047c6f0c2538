"""Quality against the number of steps, from 1 to 2000 (issue 46): the DDPM chain, DDIM,
the progressively distilled students and the rectified flow (Euler, Heun) of coma, on
the same network, data and training steps.

Usage: python benchmarks/few_steps.py [--n 128] [--guided-n 96] [--rows ...] [--steps
...] [--save few_steps]

Each row, unconditional (n sequences in batches of 64, seeds 0, 1, ...): seconds per
sequence on one thread and the peak resident memory of sampling above the loaded models
(each row in a fresh process, as benchmarks/fast_sampling.py), FID against the training
split, diversity, and the mean frame-to-frame speed over the test split's (the "static
pose" of few-step DDIM), each with a 95 % bootstrap interval.  Label control (guided n
sequences, the 12 labels in equal numbers) with the book's default guidance for the
sampler (Alg. 1 under DDPM, the mean shift otherwise; the flow's classifier reads its
noise levels, tasks.guided_chain): IC accuracy and FID with intervals; left blank at
2000 steps (the label chapters' stored tables) and for Heun (no guided Heun sampler).
The first row is the physical floor: one forward pass of the network.

DDPM and DDIM run on trailing steps (T/K, 2T/K, ..., T: the students' and the flow's
grid; Lin et al. 2024); the rows "DDIM, uniform" show the book's uniform spacing.
--rows runs some row groups; with --save their rows replace those of the stored table.
"""

import argparse
import gc
import multiprocessing
import os
import time

import numpy as np
import torch

from facelib import config, data, evaluation, metrics, results, tasks
from facelib.flow import RectifiedFlow

BATCH = 64
STEPS = [1, 2, 4, 8, 16, 50, 200, 2000]
GROUPS = {
    "floor": [("network, one forward pass", "floor", 1)],
    "ddpm": [("DDPM", "ddpm", k) for k in STEPS],
    "ddim": [("DDIM", "ddim", k) for k in STEPS],
    "uniform": [("DDIM, uniform", "ddim-uniform", k) for k in (4, 16, 50)],
    "student": None,  # the shipped students, found at run time
    "flow": [("flow, Euler", "flow", k) for k in STEPS[:-1]],
    "heun": [("flow, Heun", "heun", k) for k in (2, 4, 8, 16)],
}
COLUMNS = [
    "sampler",
    "steps",
    "network calls",
    "s per sequence",
    "peak memory (MiB)",
    "FID",
    "95 % interval",
    "diversity",
    "95 % interval",
    "speed / data's",
    "95 % interval",
    "guided Acc (%)",
    "95 % interval",
    "guided FID",
    "95 % interval",
]


def chain_settings(kind, steps):
    """The task settings of a row kind: sampler and spacing."""
    if kind == "ddim-uniform":
        return dict(steps=steps, sampler="ddim", spacing="uniform")
    return dict(steps=steps, sampler=kind, spacing="trailing")


def denoiser_of(kind, steps):
    return tasks.load_denoiser(
        tasks.denoiser_name("coma", chain_settings(kind, steps)["sampler"], steps)
        if kind not in ("floor", "heun")
        else "denoiser_coma" if kind == "floor" else "denoiser_coma_flow"
    )


def network_calls(kind, steps):
    return 2 * steps - 1 if kind == "heun" else steps


def _memory_kib(field):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith(field + ":"))


def _sample_in_child(kind, steps, n):
    """One row's unconditional sequences in a fresh one-thread process: (sequences in
    mm, seconds per sequence, peak resident memory of sampling above the loaded model in
    MiB; reset after loading: Linux /proc/self/clear_refs)."""
    torch.set_num_threads(1)
    denoiser = denoiser_of(kind, steps)
    shape = (BATCH, 40, 68, 3)
    gc.collect()
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    loaded = _memory_kib("VmRSS")
    out, t0 = [], time.perf_counter()
    for seed in range(n // BATCH):
        if kind == "floor":
            with torch.no_grad():
                x = torch.randn(shape, generator=torch.Generator().manual_seed(seed))
                denoiser.model(x, torch.full((BATCH,), 1000.0))
            continue
        if kind == "heun":
            x = RectifiedFlow(denoiser.diffusion.num_steps).sample(
                denoiser.model,
                shape,
                steps,
                "heun",
                generator=torch.Generator().manual_seed(seed),
            )
            out.append(denoiser.to_mm(x))
            continue
        out.append(
            tasks.unconditional(
                BATCH,
                seed=seed,
                denoiser=denoiser,
                progress=False,
                **chain_settings(kind, steps),
            )
        )
    seconds = (time.perf_counter() - t0) / n
    peak = (_memory_kib("VmHWM") - loaded) / 1024
    return (np.concatenate(out) if out else None), seconds, peak


def speed_ratio(x, data_speed):
    """Mean frame-to-frame speed of x over the data's, with its 95 % bootstrap interval
    over the sequences."""
    per_sequence = metrics.frame_speeds(x).mean(1)

    def ratio(s):
        return s.mean() / data_speed

    return ratio(per_sequence), list(metrics.bootstrap_interval(ratio, per_sequence))


def guided_scores(ev, kind, steps, n, guide):
    if kind in ("floor", "heun") or steps == 2000:
        return [""] * 4
    labels = [ev.class_names[i % len(ev.class_names)] for i in range(n)]
    x = tasks.label_control(
        labels,
        n,
        seed=0,
        denoiser=denoiser_of(kind, steps),
        guide=guide,
        progress=False,
        **chain_settings(kind, steps),
    )
    s = ev.score(x, np.array([ev.class_index(y) for y in labels]), intervals=True)
    return [s["accuracy"], list(s["accuracy_ci"]), s["fid"], list(s["fid_ci"])]


def run_rows(args, ev):
    guide = tasks.load_guide("coma")
    data_speed = metrics.frame_speeds(
        data.load_dataset("coma", "test").landmarks
    ).mean()
    context = multiprocessing.get_context("spawn")
    rows = []
    for group in args.rows:
        specs = GROUPS[group] or [
            ("student", "student", k) for k in tasks.shipped_students("coma")
        ]
        for name, kind, steps in specs:
            if args.steps and steps not in args.steps:
                continue
            with context.Pool(1) as pool:
                x, seconds, peak = pool.apply(_sample_in_child, (kind, steps, args.n))
            row = [name, steps, network_calls(kind, steps), seconds, round(peak, 1)]
            if x is None:  # the floor: no sequences
                row += [""] * 10
            else:
                s = ev.score(x, ev.features(x).argmax(1), intervals=True)
                row += [s["fid"], list(s["fid_ci"]), s["diversity"]]
                row += [list(s["diversity_ci"]), *speed_ratio(x, data_speed)]
                row += guided_scores(ev, kind, steps, args.guided_n, guide)
            rows.append(row)
            print(" | ".join(map(str, row)), flush=True)
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=128, help="unconditional sequences")
    parser.add_argument(
        "--guided-n", type=int, default=96, help="label-controlled sequences"
    )
    parser.add_argument(
        "--rows",
        nargs="+",
        choices=list(GROUPS),
        default=list(GROUPS),
        help="the row groups to run (default: all)",
    )
    parser.add_argument(
        "--steps",
        type=int,
        nargs="+",
        default=None,
        help="only the rows of these step counts (default: all)",
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)
    if args.n < BATCH or args.n % BATCH or args.guided_n < 24:
        parser.error(
            f"--n must be a multiple of {BATCH} and --guided-n at least 24 (two of"
            f" each label), got {args.n} and {args.guided_n}"
        )
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    ev = evaluation.load_evaluator("coma", "I")
    rows = run_rows(args, ev)
    if args.save:
        provenance = None
        if set(args.rows) != set(GROUPS):
            rows, provenance = results.merged_rows(args.save, rows, key_length=2)
        students = [
            f"student_denoiser_coma_{k}" for k in tasks.shipped_students("coma")
        ]
        path = results.save_result(
            args.save,
            title="Quality against the number of steps: DDPM, DDIM, students, flow",
            columns=COLUMNS,
            rows=rows,
            run=results.Run(
                allow_dirty=args.allow_dirty,
                checkpoints=[
                    "denoiser_coma",
                    "denoiser_coma_flow",
                    "guide_coma_I",
                    "ic_coma_I",
                    *students,
                ],
                seeds=list(range(args.n // BATCH)),
                n=args.n,
                steps=STEPS,
                wall_time_s=time.perf_counter() - t0,
                settings=[config.LabelControl()],
            ),
            notes=(
                f"unconditional: n = {args.n} in batches of {BATCH}, one thread, each"
                f" row in a fresh process; guided: n = {args.guided_n}, the labels in"
                " equal numbers, config.LabelControl's defaults for the sampler;"
                " intervals: 95 % bootstrap over the sequences; FID against the"
                " training split; speed: the mean frame-to-frame speed over the test"
                " split's; DDPM and DDIM on trailing steps unless 'uniform'"
            ),
            row_provenance=provenance,
        )
        print(f"saved {path}")


if __name__ == "__main__":
    main()
