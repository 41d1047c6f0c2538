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

--experiment tasks: each guided task with its book defaults, then at 50 and 4 steps of
DDIM, with the 4-step student and with the flow's Euler steps (4, 16): label control
(the mean shift; IC accuracy, FID; also classifier-free guidance with DDIM at 50 steps
and its distilled students of 4 and 1 steps, --samplers picks rows), filling FFM (Alg. 3 with reconstruction guidance; IC
accuracy of the completed test sequences, error on the missing frames), geometry-
adaptive generation (Alg. 4; type-S IC accuracy, distance of the known frame from the
given face), keyframes (share met within 0.5 mm and smoothly, mean key error), each
with a 95 % bootstrap interval (--task-n sequences per row; --save few_steps_tasks).
"""

import argparse
import gc
import multiprocessing
import time

import numpy as np
import torch

from facelib import data, evaluation, metrics, results, tasks
from facelib.flow import RectifiedFlow

BATCH = 64
STEPS = [1, 2, 4, 8, 16, 50, 200, 2000]
GROUPS = {
    "floor": [("network, one forward pass", "floor", 1)],
    "ddpm": [("DDPM", "ddpm", k) for k in STEPS],
    # DDIM at 2000 steps: chapter 11's stored table (results/fast_sampling_steps.json)
    "ddim": [("DDIM", "ddim", k) for k in STEPS[:-1]],
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


# the guided tasks' samplers: (row name, settings changed; {}: the task's defaults)
TASK_SAMPLERS = [
    ("the book's default", {}),
    ("DDIM, 50 steps", dict(sampler="ddim", steps=50, spacing="trailing")),
    ("DDIM, 4 steps", dict(sampler="ddim", steps=4, spacing="trailing")),
    ("student, 4 steps", dict(sampler="student", steps=4)),
    ("flow, Euler 4 steps", dict(sampler="flow", steps=4)),
    ("flow, Euler 16 steps", dict(sampler="flow", steps=16)),
]
# label control only: classifier-free guidance, the teacher chain and its students (w
# distilled in, Meng et al. 2023)
CFG_SAMPLERS = [
    (
        "classifier-free, DDIM 50 steps",
        dict(guidance="cfg", sampler="ddim", steps=50, spacing="trailing"),
    ),
    *(
        (
            f"classifier-free student, {k} step{'s' * (k > 1)}",
            dict(guidance="cfg", sampler="student", steps=k),
        )
        for k in (4, 1)
    ),
]
TASK_COLUMNS = [
    "task",
    "sampler",
    "measure",
    "value",
    "95 % interval",
    "second measure",
    "second value",
    "95 % interval",
    "s per sequence",
]


def mean_interval(values, scale=1.0):
    v = scale * np.asarray(values, dtype=np.float64)
    return [float(v.mean()), list(metrics.bootstrap_interval(np.mean, v))]


def label_task(n, sampler, ev, test):
    labels = [ev.class_names[i % len(ev.class_names)] for i in range(n)]
    x = tasks.label_control(labels, n, seed=0, progress=False, **sampler)
    s = ev.score(x, np.array([ev.class_index(y) for y in labels]), intervals=True)
    return ["IC Acc (%)", s["accuracy"], list(s["accuracy_ci"])], [
        "FID",
        s["fid"],
        list(s["fid_ci"]),
    ]


def filling_task(n, sampler, ev, test):
    from facelib import inpainting

    pick = np.linspace(0, len(test.landmarks) - 1, n).round().astype(int)
    truth, targets = test.landmarks[pick], test.labels[pick]
    known = inpainting.fill_masks("FFM", n, truth.shape[1], seed=0)
    x = tasks.fill(truth, known, progress=False, seed=0, **sampler)
    s = ev.score(x, targets, intervals=True)
    missing = [
        metrics.missing_frame_error(a[None], b[None], k[None])
        for a, b, k in zip(x, truth, known)
    ]
    return ["IC Acc (%)", s["accuracy"], list(s["accuracy_ci"])], [
        "missing-frame error (mm)",
        *mean_interval(missing),
    ]


def geometry_task(n, sampler, ev_s, test):
    from facelib import experiments

    per_class = max(2, n // len(ev_s.class_names))  # pairs: diversity needs them
    rows, labels, neutral, known = experiments.table4_inputs(
        test, ev_s.class_names, per_class
    )
    x = tasks.geometry_adaptive(
        neutral, labels, len(rows), progress=False, seed=0, **sampler
    )
    s = ev_s.score(x, test.targets("S")[rows], intervals=True)
    # how far the face moves from its given neutral frame (which is kept exactly)
    motion = np.linalg.norm(x - neutral[:, None], axis=-1).max(axis=(1, 2))
    return ["type-S IC Acc (%)", s["accuracy"], list(s["accuracy_ci"])], [
        "largest motion from the face (mm)",
        *mean_interval(motion),
    ]


def keyframe_task(n, sampler, ev, test):
    from facelib import experiments

    requests = experiments.random_keys(n, seed=4)
    x = np.concatenate(
        [
            tasks.keyframes(keys, 1, neutral, seed=5 + k, progress=False, **sampler)
            for k, (keys, neutral) in enumerate(requests)
        ]
    )
    report = tasks.keyframe_report(x, requests, test.landmarks)
    met = mean_interval(report["met"], 100)
    met[1] = [float(np.clip(v, 0, 100)) for v in met[1]]
    # the keys themselves are met exactly (replacement): a pop shows in the speed
    return ["met smoothly (%)", *met], [
        "largest speed near the key / data's p95",
        *mean_interval(report["speed_ratio"]),
    ]


GUIDED_TASKS = {
    "label": label_task,
    "filling": filling_task,
    "geometry": geometry_task,
    "keyframes": keyframe_task,
}


def task_rows(args, ev):
    test = data.load_dataset("coma", "test")
    ev_s = evaluation.load_evaluator("coma", "S")
    rows = []
    for task in args.tasks:
        for name, sampler in TASK_SAMPLERS + (CFG_SAMPLERS if task == "label" else []):
            if args.samplers and name not in args.samplers:
                continue
            t0 = time.perf_counter()
            first, second = GUIDED_TASKS[task](
                args.task_n, sampler, ev_s if task == "geometry" else ev, test
            )
            seconds = (time.perf_counter() - t0) / args.task_n
            rows.append([task, name, *first, *second, seconds])
            print(" | ".join(map(str, rows[-1])), flush=True)
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--experiment", choices=["steps", "tasks"], default="steps")
    parser.add_argument("--n", type=int, default=128, help="unconditional sequences")
    parser.add_argument(
        "--guided-n", type=int, default=96, help="label-controlled sequences"
    )
    parser.add_argument(
        "--rows",
        nargs="+",
        choices=list(GROUPS),
        default=list(GROUPS),
        help="steps: the row groups to run (default: all)",
    )
    parser.add_argument(
        "--steps",
        type=int,
        nargs="+",
        default=None,
        help="steps: only the rows of these step counts (default: all)",
    )
    parser.add_argument(
        "--tasks",
        nargs="+",
        choices=list(GUIDED_TASKS),
        default=list(GUIDED_TASKS),
        help="tasks: the guided tasks to run (default: all)",
    )
    parser.add_argument(
        "--task-n", type=int, default=48, help="tasks: sequences per row"
    )
    parser.add_argument(
        "--samplers",
        nargs="+",
        default=None,
        help="tasks: only the rows of these samplers (default: all)",
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)
    if args.n < BATCH or args.n % BATCH or min(args.guided_n, args.task_n) < 24:
        parser.error(
            f"--n must be a multiple of {BATCH}, --guided-n and --task-n at least 24"
            f" (two of each label), got {args.n}, {args.guided_n}, {args.task_n}"
        )
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    ev = evaluation.load_evaluator("coma", "I")
    steps_run = args.experiment == "steps"
    rows = run_rows(args, ev) if steps_run else task_rows(args, ev)
    if not args.save:
        return
    provenance = None
    everything = set(args.rows if steps_run else args.tasks) == set(
        GROUPS if steps_run else GUIDED_TASKS
    )
    if not everything or (steps_run and args.steps) or args.samplers:
        rows, provenance = results.merged_rows(args.save, rows, key_length=2)
    students = [f"student_denoiser_coma_{k}" for k in tasks.shipped_students("coma")]
    if not steps_run:
        students += ["denoiser_coma_cfg"] + [
            f"student_denoiser_coma_cfg_{k}"
            for k in tasks.shipped_students("coma", "cfg")
        ]
    path = results.save_result(
        args.save,
        title=(
            "Quality against the number of steps: DDPM, DDIM, students, flow"
            if steps_run
            else "The guided tasks at few steps: students, flow, DDIM"
        ),
        columns=COLUMNS if steps_run else TASK_COLUMNS,
        rows=rows,
        run=results.Run(
            allow_dirty=args.allow_dirty,
            checkpoints=[
                "denoiser_coma",
                "denoiser_coma_flow",
                "guide_coma_I",
                "ic_coma_I",
                *students,
                *([] if steps_run else ["guide_coma_S", "ic_coma_S"]),
            ],
            seeds=list(range(args.n // BATCH)) if steps_run else [0],
            n=args.n if steps_run else args.task_n,
            steps=STEPS if steps_run else [4, 16, 50],
            wall_time_s=time.perf_counter() - t0,
            settings=[tasks.LabelControl(), tasks.Fill(), tasks.GeometryAdaptive()]
            + [tasks.Keyframes()],
        ),
        notes=(
            f"unconditional: n = {args.n} in batches of {BATCH}, one thread, each row"
            f" in a fresh process; guided: n = {args.guided_n}, the labels in equal"
            " numbers, tasks.LabelControl's defaults for the sampler; intervals: 95 %"
            " bootstrap over the sequences; FID against the training split; speed: the"
            " mean frame-to-frame speed over the test split's; DDPM and DDIM on"
            " trailing steps unless 'uniform'"
            if steps_run
            else (
                f"n = {args.task_n} per row; each task's settings are its book defaults"
                " (config) with the sampler changed; intervals: 95 % bootstrap over"
                " the sequences; filling: n test sequences evenly spread, FFM masks"
                " (seed 0); geometry: Table 4's inputs; keyframes: random real keys"
                " (seed 4)"
            )
        ),
        row_provenance=provenance,
    )
    print(f"saved {path}")


if __name__ == "__main__":
    main()
