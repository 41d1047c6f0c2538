"""Sequences of any length (issue 47, the chapter "Any length"): how smooth the joins
between windows are, whether each segment shows its label, and what a long stream
costs.

Usage: python benchmarks/long_sequences.py [--experiment joins|length] [--n 8]
[--joins fill replace handshake concat] [--stream schedule|free|text] [--feather 4]
[--text-lr 0.2] [--minutes 1 10] [--save NAME]

--experiment joins (default; --type-i-opening adds a row whose segments open with the
type-I classifier; --joins some rows, merged into the stored table): n streams, the
held-out test faces in turn (their neutral landmarks), follow one schedule: the 12 coma
labels in a shuffled order (numpy seed 0), each "LABEL:2s, neutral:1s" (36 s, 36
windows, n x 35 joins).  For each join method (config.JOIN_METHODS) and for the test
split: the frame-to-frame speed (mean over landmarks, metrics.frame_speeds) and jerk
(third difference, metrics.frame_jerks) at the joins against those inside windows (more
than 3 frames from a join), as 95th percentiles, the ratio of their medians and a
two-sample Kolmogorov-Smirnov test; the IC accuracy of each label segment (the 40 frames
its first window generated) against the test split's, with 95 % bootstrap intervals;
frames made per second (one thread).

--stream free: the same streams without a schedule (free motion of the same length):
most of the schedule's joins fall where a segment begins, and the face moves
differently there with or without a join; a free stream's joins are only joins.
--feather: rows of fill with feathered replacement (tasks.Long.feather).
--learned-alone: a row of join "learned" (the join denoiser) without reconstruction
guidance.

--stream text: a schedule of texts in quotes on the text head's data (coma+bu, 18
labels, its held-out faces): each label's raw text ("high smile"), "TEXT:2s,
neutral:1s", in a shuffled order (54 s); the IC accuracy of each text segment is read
by the coma+bu type-I IC (compare text control of single sequences,
results/text_table2_raw.json); join fill only, unless --joins says;
--type-i-opening adds a row whose segments open with the text said in order ("from the
neutral face to ...", tasks.Long.text_opening), --text-lr rows of other Adagrad rates
(default: text control's).

--experiment length: one stream of the first test face follows "LABEL:2s, neutral:1s"
over the shuffled labels, repeated for the longest of --minutes; at the end of each of
--minutes: frames made per second so far, the peak resident memory above the loaded
models (Linux /proc/self/status; the frames are consumed as they are made, as `sample
long` writes them), and the identity drift: the distance (mean over landmarks, mm) of
the middle frame of each rest in that minute from the given face, and of the rest's
end (the anchor, 0 by construction).

--save NAME stores the table in results/NAME.json:

    python benchmarks/long_sequences.py --type-i-opening --feather 4 --learned-alone \
        --save long_sequences
    python benchmarks/long_sequences.py --stream free --feather 4 --learned-alone \
        --save long_sequences_free
    python benchmarks/long_sequences.py --stream text --type-i-opening --text-lr 0.2 0.4 \
        --save long_sequences_text
    python benchmarks/long_sequences.py --experiment length --save long_sequences_length
"""

import argparse
import time

import numpy as np
import torch
from scipy import stats

from facelib import config, data, evaluation, metrics, results, tasks
from facelib.descriptions import raw_text
from facelib.tasks import long

JOIN_COLUMNS = [
    "join",
    "joins",
    "speed p95 at joins (mm/frame)",
    "speed p95 inside windows",
    "KS p, speed",
    "speed median, joins / inside",
    "jerk p95 at joins (mm/frame^3)",
    "jerk p95 inside windows",
    "KS p, jerk",
    "segment Acc (%)",
    "95 % interval",
    "frames per second",
]
LENGTH_COLUMNS = [
    "minutes",
    "frames",
    "frames per second",
    "peak memory (MiB)",
    "rest middle to the face (mm)",
    "rest end to the face (mm)",
]


def label_schedule(labels, seconds=2, rest=1, seed=0, texts=False):
    """Every label once in a shuffled order, each followed by a rest (``texts``: each
    label's raw text in quotes)."""
    order = np.random.default_rng(seed).permutation(sorted(labels))
    said = [f'"{raw_text(y)}"' if texts else y for y in order]
    return ", ".join(f"{y}:{seconds}s, neutral:{rest}s" for y in said)


def _memory_kib(field):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith(field + ":"))


def join_statistics(x, windows, radius=3):
    """Speeds and jerks (flat arrays) at the joins and inside windows of streams x (n,
    frames, 68, 3) at the native frame rate."""
    speed, jerk = metrics.frame_speeds(x), metrics.frame_jerks(x)
    joins = long.join_frames(windows)
    # the pair (e - 1, e) is speed index e - 1; the jerk centred on it starts at e - 2
    near = np.zeros(speed.shape[1], dtype=bool)
    for e in joins:
        near[max(e - 1 - radius, 0) : e + radius] = True
    near_jerk = np.zeros(jerk.shape[1], dtype=bool)
    for e in joins:
        near_jerk[max(e - 2 - radius, 0) : e - 1 + radius] = True
    return {
        "speed_joins": speed[:, joins - 1].ravel(),
        "speed_inside": speed[:, ~near].ravel(),
        "jerk_joins": jerk[:, joins - 2].ravel(),
        "jerk_inside": jerk[:, ~near_jerk].ravel(),
    }


def segment_windows(x, schedule, windows, num_frames, label_of=None):
    """The 40 frames (n, F, 68, 3) of each label (or text) segment that its first
    window made, and their labels (``label_of``: {text: label})."""
    starts = np.cumsum([0] + [s.frames for s in schedule])[:-1]
    first = dict()
    position = 0
    for w in windows:
        first.setdefault(position, w)
        position += w.keep
    out, labels = [], []
    for s, segment in zip(starts, schedule):
        if not segment.text and segment.what in (
            config.SCHEDULE_NEUTRAL,
            config.SCHEDULE_FREE,
        ):
            continue
        begin = s - first[s].known
        out.append(x[:, begin : begin + num_frames])
        label = label_of[segment.what] if segment.text else segment.what
        labels += [label] * len(x)
    return (np.concatenate(out) if out else None), labels


def joins_experiment(args):
    settings = tasks.Long()
    texts = args.stream == "text"
    dataset = settings.text_dataset if texts else settings.dataset
    test = data.load_dataset(dataset, "test")
    subjects = np.unique(test.subjects)  # the held-out faces, in turn
    faces = np.stack(
        [
            test.neutral_landmarks(int(subjects[i % len(subjects)]))
            for i in range(args.n)
        ]
    )
    labels = test.class_names("I")
    guides = (
        dict(text_head=tasks.load_text_head(dataset))
        if texts
        else dict(guide=tasks.load_guide(dataset, "I"))
    )
    schedule = long.parse_schedule(label_schedule(labels, texts=texts), labels)
    label_of = {raw_text(y): y for y in labels}
    if args.stream == "free":  # as long, with no segment beginning anywhere
        schedule = long.free_schedule(sum(s.frames for s in schedule) / long.NATIVE_FPS)
    evaluator = evaluation.load_evaluator(dataset, "I")
    rows = []
    real = {
        "speed": metrics.frame_speeds(test.landmarks).ravel(),
        "jerk": metrics.frame_jerks(test.landmarks).ravel(),
    }
    truth = (
        evaluator.ground_truth(intervals=True, seed=0)
        if args.stream != "free"
        else {"accuracy": None, "accuracy_ci": None}  # no segment to read
    )
    rows.append(
        [
            "test split (real)",
            None,
            None,
            float(np.percentile(real["speed"], 95)),
            None,
            None,
            None,
            float(np.percentile(real["jerk"], 95)),
            None,
            truth["accuracy"],
            truth["accuracy_ci"] and list(truth["accuracy_ci"]),
            None,
        ]
    )
    print(rows[-1])
    runs = [(join, {}) for join in args.joins]
    if args.type_i_opening and texts:  # the opening said in order, as type S does
        runs.append(("fill, texts said in order (N2E)", dict(text_opening="N2E")))
    elif args.type_i_opening:  # a segment's first window guided as its others would be
        runs.append(("fill, segments open with type I", dict(opening=None)))
    runs += [(f"fill, feather {f:g}", dict(feather=f)) for f in args.feather]
    runs += [(f"fill, text lr {r:g}", dict(text_lr=r)) for r in args.text_lr]
    if args.learned_alone:  # the join denoiser without reconstruction guidance
        runs.append(
            ("learned, no reconstruction guidance", dict(reconstruction_scale=0))
        )
    for name, changed in runs:
        join = name.split(",")[0]
        t0 = time.perf_counter()
        x = long.long_sequence(
            faces,
            schedule,
            len(faces),
            join=join,
            fps=long.NATIVE_FPS,
            progress=False,
            **guides,
            **changed,
        )
        seconds = time.perf_counter() - t0
        plan = long.plan_windows(
            schedule, settings.num_frames, settings.transition, join
        )
        s = join_statistics(x, plan)
        clips, targets = segment_windows(
            x, schedule, plan, settings.num_frames, label_of
        )
        score = (
            evaluator.score(
                clips, evaluator_targets(evaluator, targets), intervals=True, seed=0
            )
            if targets
            else {"accuracy": None, "accuracy_ci": None}
        )
        rows.append(
            [
                name,
                len(s["speed_joins"]),
                float(np.percentile(s["speed_joins"], 95)),
                float(np.percentile(s["speed_inside"], 95)),
                float(stats.ks_2samp(s["speed_joins"], s["speed_inside"]).pvalue),
                float(np.median(s["speed_joins"]) / np.median(s["speed_inside"])),
                float(np.percentile(s["jerk_joins"], 95)),
                float(np.percentile(s["jerk_inside"], 95)),
                float(stats.ks_2samp(s["jerk_joins"], s["jerk_inside"]).pvalue),
                score["accuracy"],
                score["accuracy_ci"] and list(score["accuracy_ci"]),
                x.shape[0] * x.shape[1] / seconds,
            ]
        )
        print(rows[-1], f"{seconds:.0f} s", flush=True)
    checkpoints = (
        [f"denoiser_{dataset}", f"guide_{dataset}_text", f"ic_{dataset}_I"]
        if texts
        else [f"denoiser_{dataset}", f"guide_{dataset}_I", f"guide_{dataset}_S"]
        + [f"ic_{dataset}_I"]
    )
    if "learned" in args.joins or args.learned_alone:
        checkpoints.append(f"denoiser_{dataset}_join")
    return rows, checkpoints, settings, len(faces)


def evaluator_targets(evaluator, labels):
    return np.array([evaluator.class_index(y) for y in labels])


def length_experiment(args):
    test = data.load_dataset("coma", "test")
    face = test.neutral_landmarks(int(np.unique(test.subjects)[0]))
    guide = tasks.load_guide("coma", "I")
    settings = tasks.Long()
    one = label_schedule(guide.class_names)
    cycle = long.parse_schedule(one, guide.class_names)
    cycle_seconds = sum(s.frames for s in cycle) / long.NATIVE_FPS
    repeats = int(np.ceil(max(args.minutes) * 60 / cycle_seconds))
    schedule = long.parse_schedule(", ".join([one] * repeats), guide.class_names)
    windows = long.plan_windows(schedule, settings.num_frames, settings.transition)
    # the middle and the end of every rest (stream frames)
    rests, start = [], 0
    for s in schedule:
        if s.what == config.SCHEDULE_NEUTRAL:
            rests.append((start + s.frames // 2, start + s.frames - 1))
        start += s.frames
    denoiser = tasks.load_denoiser("denoiser_coma")
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    loaded = _memory_kib("VmRSS")
    frame, t0, rows = 0, time.perf_counter(), []
    wanted = sorted(int(m * 60 * long.NATIVE_FPS) for m in args.minutes)
    middle, end = [], []
    for chunk, window in zip(
        long.stream(face, schedule, 1, settings, denoiser, guide, progress=False),
        windows,
    ):
        for m, e in rests:
            for f, store in ((m, middle), (e, end)):
                if frame <= f < frame + len(chunk[0]):
                    d = np.linalg.norm(chunk[0, f - frame] - face, axis=-1).mean()
                    store.append((f, float(d)))
        frame += len(chunk[0])
        if wanted and frame >= wanted[0]:
            limit = wanted.pop(0)
            seconds = time.perf_counter() - t0
            last_minute = (limit - 60 * long.NATIVE_FPS, limit)

            def in_minute(values):
                return [d for f, d in values if last_minute[0] <= f < last_minute[1]]

            rows.append(
                [
                    limit / 60 / long.NATIVE_FPS,
                    frame,
                    frame / seconds,
                    (_memory_kib("VmHWM") - loaded) / 1024,
                    float(np.mean(in_minute(middle))),
                    float(np.max(in_minute(end))),
                ]
            )
            print(rows[-1], flush=True)
            if not wanted:
                break
    return rows, ["denoiser_coma", "guide_coma_I", "guide_coma_S"], settings, 1


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--experiment", choices=["joins", "length"], default="joins")
    p.add_argument("--n", type=int, default=8)
    p.add_argument(
        "--joins",
        nargs="*",
        default=None,
        choices=config.JOIN_METHODS,
        help="joins: the rows (default: every join; fill only for --stream text)",
    )
    p.add_argument(
        "--type-i-opening",
        action="store_true",
        help="joins: also a row whose segments open with the type-I classifier",
    )
    p.add_argument(
        "--stream",
        choices=["schedule", "free", "text"],
        default="schedule",
        help=(
            "joins: streams that follow the labels' schedule, free streams of the"
            " same length (`sample long --seconds`: no segment begins at a join), or"
            " a schedule of texts in quotes (coma+bu)"
        ),
    )
    p.add_argument(
        "--feather",
        type=float,
        nargs="*",
        default=[],
        help="joins: also rows of fill with these feathers (frames; tasks.Long)",
    )
    p.add_argument(
        "--learned-alone",
        action="store_true",
        help="joins: also a row of the join denoiser without reconstruction guidance",
    )
    p.add_argument(
        "--text-lr",
        type=float,
        nargs="*",
        default=[],
        help="--stream text: also rows of these Adagrad rates (tasks.Long.text_lr)",
    )
    p.add_argument("--minutes", type=float, nargs="+", default=[1, 10])
    p.add_argument("--save", default=None)
    p.add_argument("--allow-dirty", action="store_true")
    args = p.parse_args()
    if args.experiment == "length" and (
        args.feather or args.type_i_opening or args.stream != "schedule"
    ):
        p.error("--feather, --type-i-opening and --stream are options of the joins")
    if args.text_lr and args.stream != "text":
        p.error("--text-lr is an option of --stream text")
    if args.stream == "text" and (
        args.learned_alone or "learned" in (args.joins or ())
    ):
        p.error("no join denoiser is shipped for the text head's data (coma+bu)")
    if args.experiment == "length" and (
        args.text_lr or args.learned_alone or args.joins
    ):
        p.error("--text-lr, --learned-alone and --joins are options of the joins")
    if args.stream == "free" and args.type_i_opening:
        p.error("a free stream has no segment to open: drop --type-i-opening")
    if args.joins is None:
        args.joins = ["fill"] if args.stream == "text" else list(config.JOIN_METHODS)
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    if args.experiment == "joins":
        rows, checkpoints, settings, n = joins_experiment(args)
        columns, title = (
            JOIN_COLUMNS,
            "Joins of long sequences"
            + {
                "schedule": "",
                "free": ", free streams",
                "text": ", a schedule of texts",
            }[args.stream],
        )
    else:
        rows, checkpoints, settings, n = length_experiment(args)
        columns, title = LENGTH_COLUMNS, "A long stream over time"
    if args.save:
        provenance = None
        if (
            args.experiment == "joins"
            and set(args.joins) != set(config.JOIN_METHODS)
            and args.stream != "text"
        ):
            rows, provenance = results.merged_rows(args.save, rows)
        run = results.Run(
            checkpoints=checkpoints,
            seeds=[settings.seed],
            n=n,
            steps=[settings.steps],
            wall_time_s=time.perf_counter() - t0,
            allow_dirty=args.allow_dirty,
            settings=(settings,),
        )
        print(
            results.save_result(
                args.save, title, columns, rows, run, row_provenance=provenance
            )
        )


if __name__ == "__main__":
    main()
