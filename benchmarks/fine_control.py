"""Fine control (the fine-control chapter, not in the paper): AU-intensity curves and
landmark keyframes.

Usage:
    python benchmarks/fine_control.py --experiment au [--n 32] [--steps 50] [--save
    NAME] python benchmarks/fine_control.py --experiment floor [--save NAME]
    python benchmarks/fine_control.py --experiment keyframes [--n 32] [--steps 100]
    [--save NAME]

``au``: ``--n`` random requests of one AU within the data's range
(experiments.random_requests), and ``--n`` of an AU pair that no training sequence
activates together (tasks.never_together), each generated once by AU-curve control on
the neutral face of a held-out test subject; that subject's rig is fitted back to every
result (tasks.fitted_curves) and the mean absolute error (intensity units) to the
requested curve is taken over the constrained frames and AUs; beside it the change of
that error from "AU guidance off" (paired: the same requests, faces and seeds) and the
error of the curves the AU regressor R reads on the results (tasks.regressor_curves,
what the guidance climbs).  The row "AU guidance off" runs the same chain on the same
faces with the AU score's weight zero (tasks.AU_GUIDANCE_OFF; Alg. 1's Adagrad steps
still pull towards the denoiser's mean): the part of the FID that animating a given face
costs, without the AU guidance.  Only AUs the fit recovers within FLOOR on real test
sequences are requested (experiments.fit_floor, tasks.measurable_aus).  Beside it the
FID of the results (the type-I IC of coma) and the unconditional samples' FID on the
same number of sequences.

``floor``: the rig fit's error per AU on real test sequences with their own faces
(experiments.fit_floor), and the AUs the ``au`` experiment requests
(tasks.measurable_aus).

``keyframes``: ``--n`` random keys (experiments.random_keys: the displacement of a
mobile landmark at a frame of a real test sequence, from its subject's neutral face),
met by each method (replace, reconstruction, both) with replacement as Alg. 3 prints it
(feather 0), by 'both' at more reconstruction scales (``--scale``) and with feathered
replacement (``--feather``, inpainting.KnownFrames); the constraint error (mm), the share
of requests within config.KEYFRAME_TOLERANCE whose keyed landmark moves, at every frame
pair within config.KEYFRAME_SPEED_RADIUS frames of the key, no faster than the 95th
percentile of that landmark's frame-to-frame motion in the test data, and the FID
against the unconstrained samples'.  Every mean with its 95 % bootstrap interval; the
first row measures the real sequences the keys were read from alike.  ``--keys-seed``
draws other keys (6: those config.KEYFRAME_FEATHER was chosen on).

    python benchmarks/fine_control.py --experiment au --save fine_control_au
    python benchmarks/fine_control.py --experiment floor --save fine_control_floor
    python benchmarks/fine_control.py --experiment keyframes --n 64 --scale 4 8 16
    --feather 2 4 6 --save fine_control_keyframes
    python benchmarks/fine_control.py --experiment keyframes --keys-seed 6 --n 64
    --feather 1 2 3 4 6 --save fine_control_keyframes_choice
"""

import argparse
import time

import numpy as np

from facelib import config, data, evaluation, experiments, metrics, results, tasks

# tasks.AU_GUIDANCE_OFF: the same chain and face, the AU score's weight 0
AU_GUIDANCE_OFF_ROW = "AU guidance off"
FLOOR = (
    config.AU_MEASURABLE_FIT_ERROR
)  # AUs whose rig fit on real sequences errs by more cannot be scored at 0.1
MEASURED = {
    "au": (tasks.AUControl(),),
    "floor": (),
    "keyframes": (tasks.Keyframes(),),
}  # the defaults measured
# test sequences the rig fit's error is measured on (experiments.fit_floor's default)
FLOOR_SEQUENCES = 30
COLUMNS = {
    "au": [
        "requests",
        "method",
        "n",
        "MAE (intensity)",
        "MAE 95 % interval",
        "MAE change vs AU guidance off",
        "change 95 % interval",
        "MAE read by R",
        "R 95 % interval",
        "share with MAE <= 0.1 (%)",
        "FID",
        "FID 95 % interval",
        "s per sequence",
        "AUs requested",
    ],
    "floor": [
        "AU",
        "rig fit error (intensity)",
        "highest intensity in the data",
        "requested",
    ],
    "keyframes": [
        "method",
        "n",
        "constraint error (mm)",
        "error 95 % interval",
        "met (%)",
        "met 95 % interval",
        "FID",
        "FID 95 % interval",
        "s per sequence",
    ],
}
SEEDS = {
    "au": [1, 2, 3],
    "floor": [],
    "keyframes": [4, 5],
}  # what each experiment draws with (see its notes)


def fid_with_interval(evaluator, x):
    """FID of sequences against the training split (the IC's logits), with its 95 %
    bootstrap interval."""
    f = evaluator.features(x)
    statistic = lambda g: metrics.frechet_distance(
        g, evaluator.reference_features
    )  # noqa: E731
    return statistic(f), [
        float(v) for v in metrics.bootstrap_interval(statistic, f, num_resamples=200)
    ]


def au_rows(args, evaluator):
    floor = experiments.fit_floor("coma", n=FLOOR_SEQUENCES)
    measurable = tasks.measurable_aus(floor, max_error=FLOOR)
    pairs = [p for p in tasks.never_together("coma") if set(p) <= set(measurable)]
    requests = {
        "one AU": experiments.random_requests(args.n, seed=1, aus=measurable),
        "an AU pair never active together": experiments.random_requests(
            args.n, seed=2, pairs=pairs
        ),
    }
    test = data.load_dataset(
        "coma", "test"
    )  # the faces animated: held-out subjects, each its own rig
    subjects = np.unique(test.subjects)[
        np.arange(args.n) % len(np.unique(test.subjects))
    ]
    neutral = np.stack([test.neutral_landmarks(int(s)) for s in subjects])
    faces = [test.face(int(s)) for s in subjects]
    t0 = time.perf_counter()
    plain = tasks.unconditional(args.n, steps=args.steps, seed=3, progress=False)
    fid, fid_ci = fid_with_interval(evaluator, plain)
    rows = [
        [
            "(none)",
            "unconditional",
            args.n,
            "",
            "",
            "",
            "",
            "",
            "",
            "",
            fid,
            fid_ci,
            (time.perf_counter() - t0) / args.n,
            [],
        ]
    ]
    runs = {f"adagrad, lr {lr:g}" if lr else "adagrad": dict(lr=lr) for lr in args.lr}
    runs |= {"mean_shift": dict(method="mean_shift")}
    interval = lambda statistic, *x: [
        float(v) for v in metrics.bootstrap_interval(statistic, *x)
    ]  # noqa: E731

    def generate(request, setting):
        t0 = time.perf_counter()
        x = tasks.au_control(
            request,
            args.n,
            neutral,
            steps=args.steps,
            seed=3,
            progress=False,
            **setting,
        )
        return x, (time.perf_counter() - t0) / args.n, *fid_with_interval(evaluator, x)

    # AU guidance off never reads the request (its score is 0): one chain serves both
    # kinds of request
    unread = generate(requests["one AU"], tasks.AU_GUIDANCE_OFF)
    for name, request in requests.items():
        measured = {}
        for label, generated in [
            *((label, generate(request, s)) for label, s in runs.items()),
            (AU_GUIDANCE_OFF_ROW, unread),
        ]:
            x, seconds, fid, fid_ci = generated
            errors = tasks.curve_errors(tasks.fitted_curves(x, faces), request)
            read = tasks.curve_errors(tasks.regressor_curves(x), request)
            measured[label] = (errors, read, fid, fid_ci, seconds)
        off = measured[AU_GUIDANCE_OFF_ROW][0]
        for label in [
            *runs,
            AU_GUIDANCE_OFF_ROW,
        ]:  # the stored order: the guided rows, then the twin
            errors, read, fid, fid_ci, seconds = measured[label]
            change = (
                ["", ""]
                if label == AU_GUIDANCE_OFF_ROW
                else [
                    float((errors - off).mean()),
                    interval(lambda a, b: (a - b).mean(), errors, off),
                ]
            )
            rows.append(
                [
                    name,
                    label,
                    args.n,
                    float(errors.mean()),
                    interval(np.mean, errors),
                    *change,
                    float(read.mean()),
                    interval(np.mean, read),
                    float(100 * (errors <= 0.1).mean()),
                    fid,
                    fid_ci,
                    seconds,
                    tasks.requested_aus(request),
                ]
            )
            print(rows[-1], flush=True)
    args.notes = (
        f"requests on the AUs the rig fit recovers within {FLOOR} on real test"
        f" sequences ({', '.join(measurable)}; fit floor per AU: "
        + ", ".join(f"{a} {e:.3f}" for a, e in floor.items())
        + "); each animates the neutral face of a held-out test subject, its curves"
        " fitted with that subject's rig; requests drawn with seeds 1 (one AU) and 2"
        " (pairs), sampled with seed 3; the row AU guidance off is one chain for both"
        " kinds of request (it never reads the request)"
    )
    return rows, ["denoiser_coma", "au_regressor_coma", "ic_coma_I"]


def floor_rows(args, evaluator):
    """What the scoring of AU-curve control can resolve: the rig fit's error per AU on
    real test sequences with their own faces (experiments.fit_floor), and which AUs the
    requests of the au experiment may therefore use.
    """
    floor, ranges = experiments.fit_floor("coma", n=FLOOR_SEQUENCES), tasks.data_ranges(
        "coma"
    )
    measurable = tasks.measurable_aus(floor, max_error=FLOOR)
    rows = [
        [a, e, ranges[a][1], "yes" if a in measurable else "no"]
        for a, e in floor.items()
    ]
    args.n = FLOOR_SEQUENCES
    args.notes = (
        f"the rig fit of {FLOOR_SEQUENCES} real test sequences of coma with their own"
        " faces, mean absolute error where the AU is above 0.1 (AUs active in fewer"
        f" than 20 entries left out); requested: error <= {FLOOR}, pushed by the data"
        " to at least 0.5, not the blink AU45"
    )
    return rows, []


def keyframe_row_name(method, extra):
    """'both, zeta 4', 'both, feather 2': the method and what a row changes."""
    names = {"reconstruction_scale": "zeta", "feather": "feather"}
    return ", ".join(
        [method] + [f"{names[k]} {v:g}" for k, v in extra.items() if v != 0.0]
    )


def keyframe_row(name, x, requests, real, evaluator, seconds):
    """One row of the keyframes table for sequences x, one per request."""
    report = tasks.keyframe_report(x, requests, real)
    errors, met = report["error"], report["met"].astype(float)
    fid, fid_ci = fid_with_interval(evaluator, x)
    return [
        name,
        len(x),
        float(errors.mean()),
        [float(v) for v in metrics.bootstrap_interval(np.mean, errors)],
        float(100 * met.mean()),
        [
            float(np.clip(v, 0, 100))
            for v in metrics.bootstrap_interval(lambda h: 100 * h.mean(), met)
        ],
        fid,
        fid_ci,
        seconds,
    ]


def keyframe_rows(args, evaluator):
    requests, sources = experiments.random_keys(
        args.n, seed=args.keys_seed, sources=True
    )
    real = data.load_dataset("coma", "test").landmarks
    # a reference: the real motion each key was read from, measured the same way
    rows = [
        keyframe_row(
            "real (the keys' own sequences)",
            real[sources],
            requests,
            real,
            evaluator,
            None,
        )
    ]
    t0 = time.perf_counter()
    plain = tasks.unconditional(args.n, steps=args.steps, seed=5, progress=False)
    fid, fid_ci = fid_with_interval(evaluator, plain)
    seconds = (time.perf_counter() - t0) / args.n
    rows.append(["unconstrained", args.n, "", "", "", "", fid, fid_ci, seconds])
    # Alg. 3's replacement as printed (feather 0), then feathered (the default)
    runs = [(m, {"feather": 0.0}) for m in config.KEYFRAME_METHODS]
    runs += [("both", {"reconstruction_scale": z, "feather": 0.0}) for z in args.scale]
    runs += [("both", {"feather": f}) for f in args.feather]
    for method, extra in runs:
        t0 = time.perf_counter()
        x = np.concatenate(
            [
                tasks.keyframes(
                    keys,
                    1,
                    neutral,
                    steps=args.steps,
                    method=method,
                    seed=5 + k,
                    progress=False,
                    **extra,
                )
                for k, (keys, neutral) in enumerate(requests)
            ]
        )
        seconds = (time.perf_counter() - t0) / args.n
        name = keyframe_row_name(method, extra)
        rows.append(keyframe_row(name, x, requests, real, evaluator, seconds))
        print(rows[-1], flush=True)
    args.notes = (
        f"keys drawn with seed {args.keys_seed}, request k sampled with seed 5 + k,"
        " the unconstrained samples with seed 5; met: key error <="
        f" {config.KEYFRAME_TOLERANCE} mm (config.KEYFRAME_TOLERANCE) and no speed of"
        f" the keyed landmark within {config.KEYFRAME_SPEED_RADIUS} frames of the key"
        " (config.KEYFRAME_SPEED_RADIUS) above the real 95th percentile"
    )
    return rows, ["denoiser_coma", "ic_coma_I"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiment", choices=list(COLUMNS), required=True)
    parser.add_argument(
        "--n", type=int, default=32, help="requests per row (default 32)"
    )
    parser.add_argument(
        "--steps",
        type=int,
        default=None,
        help="reverse steps (default: the task's, config)",
    )
    parser.add_argument(
        "--lr",
        type=float,
        nargs="+",
        default=[None],
        help=(
            "au: Adagrad rates to compare (default: the book's, config.AU_CURVE_LR,"
            " step-scaled)"
        ),
    )
    parser.add_argument(
        "--scale",
        type=float,
        nargs="*",
        default=[],
        help=(
            "keyframes: more reconstruction scales zeta to try with 'both' (default:"
            " none)"
        ),
    )
    parser.add_argument(
        "--keys-seed",
        type=int,
        default=4,
        help=(
            "keyframes: the seed of the random keys (experiments.random_keys; 6: the"
            " keys config.KEYFRAME_FEATHER was chosen on)"
        ),
    )
    parser.add_argument(
        "--feather",
        type=float,
        nargs="*",
        default=[],
        help=(
            "keyframes: feathers (frames) to try with 'both' at the default zeta (the"
            " other rows replace as Alg. 3 prints it, feather 0)"
        ),
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    default = (
        tasks.Keyframes() if args.experiment == "keyframes" else tasks.AUControl()
    )
    args.steps = args.steps or default.steps
    steps = (
        [] if args.experiment == "floor" else [args.steps]
    )  # the floor samples nothing: the rig fit of real data
    t_start = time.perf_counter()
    evaluator = (
        None if args.experiment == "floor" else evaluation.load_evaluator("coma", "I")
    )
    experiment = {"au": au_rows, "floor": floor_rows, "keyframes": keyframe_rows}[
        args.experiment
    ]
    rows, checkpoints = experiment(args, evaluator)
    if args.save:
        title = {
            "au": "AU-curve control: requested against fitted curves",
            "floor": (
                "What the rig fit resolves: its error per AU on real test sequences"
            ),
            "keyframes": "Landmark keyframes: constraint error, smoothness, realism",
        }[args.experiment]
        results.save_result(
            args.save,
            title,
            COLUMNS[args.experiment],
            rows,
            results.Run(
                allow_dirty=args.allow_dirty,
                settings=MEASURED[args.experiment],
                checkpoints=checkpoints,
                seeds=SEEDS[args.experiment],
                n=args.n,
                steps=steps,
                wall_time_s=time.perf_counter() - t_start,
            ),
            notes="; ".join(
                (
                    []
                    if evaluator is None
                    else [
                        "FID against the training split with the type-I IC of coma",
                        "intervals by bootstrap over the requests",
                    ]
                )
                + [args.notes]
            ),
        )


if __name__ == "__main__":
    main()
