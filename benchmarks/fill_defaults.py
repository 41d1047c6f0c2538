"""The default of ``python -m facelib sample fill`` (tasks.Fill): seams, accuracy and
FID of candidate settings.

Usage: python benchmarks/fill_defaults.py [--n 64] [--known 0:10,30:40] [--only TEXT]
[--save NAME]

``--n`` coma test sequences (a random subset, numpy seed 0) are filled with the frames
``--known`` given, by Alg. 3 as printed and by the book's additions: reconstruction
guidance (zeta), RePaint's resampling (r), fewer respaced steps, and the posterior
variance beta~_t instead of the paper's beta_t for the sampler. For each it prints the
fraction of sequences whose seams (every boundary between a known and a generated frame)
all move no faster than the 95th percentile of the training set's frame-to-frame speed,
the median speed inside the generated span (the data's own includes capture noise), the
type-I IC accuracy and FID with 95 % bootstrap intervals, and the seconds.  The real
sequences are the first row.

``--save NAME`` stores the table in results/NAME.json; tasks.Fill cites
``results/fill_defaults.json``:

    python benchmarks/fill_defaults.py --save fill_defaults

(64 sequences, 7 rows: about 4 minutes with one torch thread.)
"""

import argparse
import time

import numpy as np
import torch

from facelib import data, evaluation, inpainting, metrics, results, tasks

COLUMNS = [
    "method",
    "steps",
    "variance",
    "zeta",
    "r",
    "seams within p95 (%)",
    "generated speed, median (mm/frame)",
    "Acc (%)",
    "Acc 95 % interval",
    "FID",
    "FID 95 % interval",
    "seconds",
]
CANDIDATES = {  # name: the settings' fields
    "Alg. 3 as printed (respaced)": dict(
        steps=200, variance="beta", reconstruction_scale=0.0
    ),
    "+ reconstruction guidance": dict(
        steps=200, variance="beta", reconstruction_scale=2.0
    ),
    "+ reconstruction guidance, posterior variance": dict(
        steps=100, variance="posterior", reconstruction_scale=2.0
    ),
    "  the same, RePaint r = 2": dict(
        steps=100, variance="posterior", reconstruction_scale=2.0, resample=2
    ),
    "  the same, zeta = 4": dict(
        steps=100, variance="posterior", reconstruction_scale=4.0
    ),
    "  the same, zeta = 4, 50 steps": dict(
        steps=50, variance="posterior", reconstruction_scale=4.0
    ),
}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--n", type=int, default=64, help="coma test sequences (default 64)"
    )
    parser.add_argument(
        "--known", default="0:10,30:40", help="the known frames (default 0:10,30:40)"
    )
    parser.add_argument(
        "--only", metavar="TEXT", help="only the candidates whose name contains TEXT"
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    if args.only and args.save:
        parser.error(
            "--only measures some candidates: it cannot --save the whole table"
        )
    t_start = time.perf_counter()
    test = data.load_dataset("coma", "test")
    p95 = float(
        np.percentile(
            metrics.frame_speeds(data.load_dataset("coma", "train").landmarks), 95
        )
    )
    pick = np.random.default_rng(0).choice(len(test), args.n, replace=False)
    truth, targets = test.landmarks[pick], test.targets("I")[pick]
    known = inpainting.parse_known(args.known, truth.shape[1])
    generated = ~known
    ev = evaluation.load_evaluator("coma", "I")
    denoiser = tasks.load_denoiser("denoiser_coma")
    print(
        f"{args.n} coma test sequences, known {args.known}; real 95th percentile speed"
        f" {p95:.3f} mm/frame; {torch.get_num_threads()} torch thread(s)",
        flush=True,
    )

    def row(name, x, settings, seconds):
        seams = metrics.seam_steps(x, known).reshape(len(x), -1)
        s = ev.score(x, targets, intervals=True, num_resamples=200)
        speed = float(
            np.median(metrics.frame_speeds(x)[:, generated[1:] & generated[:-1]])
        )
        r = [
            name,
            settings.get("steps", "-"),
            settings.get("variance", "-"),
            settings.get("reconstruction_scale", "-"),
            settings.get("resample", 1) if settings else "-",
            100 * float((seams <= p95).all(1).mean()),
            speed,
            s["accuracy"],
            s["accuracy_ci"],
            s["fid"],
            s["fid_ci"],
            seconds,
        ]
        print(
            " | ".join(f"{v:.3g}" if isinstance(v, float) else str(v) for v in r),
            flush=True,
        )
        return r

    rows = [row("real sequences", truth, {}, 0.0)]
    for name, settings in CANDIDATES.items():
        if args.only and args.only not in name:
            continue
        t0 = time.perf_counter()
        x = tasks.fill(
            truth,
            known,
            tasks.Fill().paper(),
            denoiser=denoiser,
            progress=False,
            **settings,
        )
        rows.append(row(name, x, settings, time.perf_counter() - t0))
    if args.save:
        path = results.save_result(
            args.save,
            "The fill default: seams, accuracy and FID of candidate settings (coma test"
            " split)",
            COLUMNS,
            rows,
            results.Run(
                allow_dirty=args.allow_dirty,
                checkpoints=["denoiser_coma", "ic_coma_I"],
                seeds=[0],
                n=args.n,
                steps=sorted({s["steps"] for s in CANDIDATES.values()}),
                wall_time_s=time.perf_counter() - t_start,
            ),
            notes=(
                f"known frames {args.known}; seams within p95: every known/generated"
                f" boundary moves at most the 95th percentile ({p95:.3f} mm/frame) of"
                " the training set's frame-to-frame speed; sampler seed 0; intervals:"
                " 95 % bootstrap over the sequences (Evaluator.score(intervals=True))"
            ),
        )
        print(f"saved {path}")


if __name__ == "__main__":
    main()
