"""Fine control (the fine-control chapter, not in the paper): AU-intensity curves and landmark keyframes.

Usage:
    python benchmarks/fine_control.py --experiment au [--n 32] [--steps 50] [--save NAME]
    python benchmarks/fine_control.py --experiment keyframes [--n 32] [--steps 100] [--save NAME]

``au``: ``--n`` random requests of one AU within the data's range (tasks.random_requests), and ``--n`` of an AU
pair that no training sequence activates together (tasks.never_together), each generated once by AU-curve
control on the neutral face of a held-out test subject; that subject's rig is fitted back to every result
(tasks.fitted_curves) and the mean absolute error (intensity units) to the requested curve is taken over the
constrained frames and AUs.  The row "AU guidance off" runs the same chain on the same faces with the AU
score's weight zero (tasks.AU_GUIDANCE_OFF; Alg. 1's Adagrad steps still pull towards the denoiser's mean): the
part of the FID that animating a given face costs, without the AU guidance.  Only AUs the fit recovers within FLOOR on real test sequences are requested
(tasks.fit_floor).  Beside it the FID of
the results (the type-I IC of coma) and the unconditional samples' FID on the same number of sequences.

``keyframes``: ``--n`` random keys (tasks.random_keys: the displacement of a mobile landmark at a frame of a
real test sequence, from its subject's neutral face), met by each method (replace, reconstruction, both);
the constraint error (mm), the share of requests within 0.5 mm whose keyed landmark moves into and out of
the keyed frame no faster than the 95th percentile of that landmark's frame-to-frame motion in the test
data, and the FID against the unconstrained samples'.  Every mean with its 95 % bootstrap interval.

    python benchmarks/fine_control.py --experiment au --save fine_control_au
    python benchmarks/fine_control.py --experiment keyframes --save fine_control_keyframes
"""
import argparse
import time

import numpy as np

from facelib import config, data, evaluation, metrics, results, tasks

AU_GUIDANCE_OFF_ROW = "AU guidance off"  # tasks.AU_GUIDANCE_OFF: the same chain and face, the AU score's weight 0
FLOOR = config.AU_MEASURABLE_FIT_ERROR  # AUs whose rig fit on real sequences errs by more cannot be scored at 0.1
COLUMNS = {
    "au": ["requests", "method", "n", "MAE (intensity)", "MAE 95 % interval", "share with MAE <= 0.1 (%)", "FID",
           "FID 95 % interval", "s per sequence"],
    "keyframes": ["method", "n", "constraint error (mm)", "error 95 % interval", "met (%)", "FID",
                  "FID 95 % interval", "s per sequence"],
}


def fid_with_interval(evaluator, x):
    """FID of sequences against the training split (the IC's logits), with its 95 % bootstrap interval."""
    f = evaluator.features(x)
    statistic = lambda g: metrics.frechet_distance(g, evaluator.reference_features)  # noqa: E731
    return statistic(f), [float(v) for v in metrics.bootstrap_interval(statistic, f, num_resamples=200)]


def au_rows(args, evaluator):
    floor = tasks.fit_floor("coma")
    measurable = tasks.measurable_aus(floor, max_error=FLOOR)
    pairs = [p for p in tasks.never_together("coma") if set(p) <= set(measurable)]
    requests = {"one AU": tasks.random_requests(args.n, seed=1, aus=measurable),
                "an AU pair never active together": tasks.random_requests(args.n, seed=2, pairs=pairs)}
    test = data.load_dataset("coma", "test")  # the faces animated: held-out subjects, each its own rig
    subjects = np.unique(test.subjects)[np.arange(args.n) % len(np.unique(test.subjects))]
    neutral = np.stack([test.neutral_landmarks(int(s)) for s in subjects])
    faces = [test.face(int(s)) for s in subjects]
    rows = []
    t0 = time.perf_counter()
    plain = tasks.unconditional(args.n, steps=args.steps, seed=3, progress=False)
    fid, fid_ci = fid_with_interval(evaluator, plain)
    rows.append(["(none)", "unconditional", args.n, "", "", "", fid, fid_ci, (time.perf_counter() - t0) / args.n])
    runs = [(f"adagrad, lr {lr:g}" if lr else "adagrad", dict(lr=lr)) for lr in args.lr]
    runs += [("mean_shift", dict(method="mean_shift")), (AU_GUIDANCE_OFF_ROW, tasks.AU_GUIDANCE_OFF)]
    for name, request in requests.items():
        for label, setting in runs:
            t0 = time.perf_counter()
            x = tasks.au_control(request, args.n, neutral, steps=args.steps, seed=3, progress=False, **setting)
            seconds = (time.perf_counter() - t0) / args.n
            errors = tasks.curve_errors(tasks.fitted_curves(x, faces), request)
            fid, fid_ci = fid_with_interval(evaluator, x)
            rows.append([name, label, args.n, float(errors.mean()),
                         [float(v) for v in metrics.bootstrap_interval(np.mean, errors)],
                         float(100 * (errors <= 0.1).mean()), fid, fid_ci, seconds])
            print(rows[-1], flush=True)
    args.notes = (f"requests on the AUs the rig fit recovers within {FLOOR} on real test sequences "
                  f"({', '.join(measurable)}; fit floor per AU: "
                  + ", ".join(f"{a} {e:.3f}" for a, e in floor.items()) + "); each animates the neutral face of a "
                  "held-out test subject, its curves fitted with that subject's rig")
    return rows, ["denoiser_coma", "au_regressor_coma", "ic_coma_I"]


def keyframe_rows(args, evaluator):
    requests = tasks.random_keys(args.n, seed=4)
    real = data.load_dataset("coma", "test").landmarks
    p95 = {l: tasks.real_speed_p95(real, l) for l in {key["landmark"] for keys, _ in requests for key in keys}}
    t0 = time.perf_counter()
    plain = tasks.unconditional(args.n, steps=args.steps, seed=5, progress=False)
    fid, fid_ci = fid_with_interval(evaluator, plain)
    rows = [["unconstrained", args.n, "", "", "", fid, fid_ci, (time.perf_counter() - t0) / args.n]]
    runs = [(m, None) for m in config.KEYFRAME_METHODS] + [("both", z) for z in args.scale]
    for method, zeta in runs:
        t0 = time.perf_counter()
        extra = {} if zeta is None else {"reconstruction_scale": zeta}
        x = np.concatenate([tasks.keyframes(keys, 1, neutral, steps=args.steps, method=method, seed=5 + k,
                                            progress=False, **extra) for k, (keys, neutral) in enumerate(requests)])
        seconds = (time.perf_counter() - t0) / args.n
        errors = np.array([tasks.key_errors(x[k:k + 1], keys, neutral).max() for k, (keys, neutral)
                           in enumerate(requests)])
        smooth = np.array([(tasks.key_speeds(x[k:k + 1], keys)[0] <= [p95[key["landmark"]] for key in keys]).all()
                           for k, (keys, _) in enumerate(requests)])
        fid, fid_ci = fid_with_interval(evaluator, x)
        interval = [float(v) for v in metrics.bootstrap_interval(np.mean, errors)]
        met = float(100 * ((errors <= 0.5) & smooth).mean())
        name = method if zeta is None else f"{method}, zeta {zeta:g}"
        rows.append([name, args.n, float(errors.mean()), interval, met, fid, fid_ci, seconds])
        print(rows[-1], flush=True)
    return rows, ["denoiser_coma", "ic_coma_I"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiment", choices=list(COLUMNS), required=True)
    parser.add_argument("--n", type=int, default=32, help="requests per row (default 32)")
    parser.add_argument("--steps", type=int, default=None, help="reverse steps (default: the task's, config)")
    parser.add_argument("--lr", type=float, nargs="+", default=[None],
                        help="au: Adagrad rates to compare (default: the book's, config.AU_CURVE_LR, step-scaled)")
    parser.add_argument("--scale", type=float, nargs="*", default=[],
                        help="keyframes: more reconstruction scales zeta to try with 'both' (default: none)")
    parser.add_argument("--save", metavar="NAME", help="store the table in results/NAME.json")
    args = parser.parse_args()
    default = {"au": config.AUControl(), "keyframes": config.Keyframes()}[args.experiment]
    args.steps = args.steps or default.steps
    t_start = time.perf_counter()
    evaluator = evaluation.load_evaluator("coma", "I")
    rows, checkpoints = (au_rows if args.experiment == "au" else keyframe_rows)(args, evaluator)
    if args.save:
        title = {"au": "AU-curve control: requested against fitted curves",
                 "keyframes": "Landmark keyframes: constraint error, smoothness, realism"}[args.experiment]
        results.save_result(args.save, title, COLUMNS[args.experiment], rows,
                            results.Run(checkpoints=checkpoints, seeds=[1, 2, 3, 4, 5], n=args.n, steps=[args.steps],
                                        wall_time_s=time.perf_counter() - t_start),
                            notes="FID against the training split with the type-I IC of coma; intervals by "
                                  "bootstrap over the requests; " + getattr(args, "notes", ""))


if __name__ == "__main__":
    main()
