"""How far ``python -m facelib animate`` moves a face: apex displacements on unseen
identities, beside the data's.

Usage: python benchmarks/animate_magnitudes.py [--faces 4] [--seeds 4] [--steps N]
[--save NAME]

For each label of ``REGIONS`` it animates the neutral faces of ``--faces`` identities
that no dataset holds (identity seeds 4242, 4243, ...), each with ``--seeds`` sampling
seeds of its own (pipeline.animate: Alg. 4 with the book's settings, then the deformer),
and measures the largest displacement over the frames of the region's landmark vertices
from the neutral mesh (the mean over the region's landmarks, mm).  The data's row is the
same measure on every coma sequence of that label, on the world's noise-free landmarks
(the animations are noise-free meshes too). Mean and 95 % bootstrap interval over the
animations (over the sequences for the data), the smallest animation and the data's 10th
percentile (how far a weak animation or a weak real sequence goes), and every
animation's value (column "animations (mm)", in the order face by face, seed by seed)
and every data sequence's ("data sequences (mm)"); and how many animations the type-S IC
(chapter 04) reads as the label requested (either order).

    python benchmarks/animate_magnitudes.py --save animate_magnitudes

(3 labels x 4 faces x 4 seeds: about 30 minutes with one torch thread.)
"""

import argparse
import time

import numpy as np

from facelib import data, evaluation, metrics, pipeline, results, tasks
from facelib.face import Face, sample_identity
from facelib.face.template import get_template

COLUMNS = [
    "label",
    "measure",
    "animate: mean (mm)",
    "animate 95 % interval",
    "data: mean (mm)",
    "data 95 % interval",
    "animations",
    "data sequences",
    "animate: smallest (mm)",
    "data: 10th percentile (mm)",
    "animations (mm)",
    "data sequences (mm)",
    "IC reads the label (%)",
]
REGIONS = {  # label -> (measure, iBUG-68 landmarks)
    "high_smile": ("mouth corners", [48, 54]),
    "mouth_open": ("lower lip", [57]),
    "eyebrow": ("brows", list(range(17, 27))),
}
FIRST_FACE = (
    4242  # identity seeds from here on: no dataset's (theirs come from their own seeds)
)


def apex_displacement(frames, rest, landmarks):
    """Largest displacement over frames of the mean over ``landmarks`` of |frame - rest|
    (mm): ``frames`` (..., F, 68, 3) landmarks, ``rest`` (..., 68, 3) the neutral
    ones."""
    d = np.linalg.norm(
        frames[..., landmarks, :] - rest[..., None, landmarks, :], axis=-1
    )
    return d.mean(-1).max(-1)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--faces", type=int, default=4, help="unseen identities (default 4)"
    )
    parser.add_argument(
        "--seeds", type=int, default=4, help="sampling seeds per face (default 4)"
    )
    parser.add_argument(
        "--steps",
        type=int,
        default=None,
        help="reverse steps (default: the book's, config)",
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    t_start = time.perf_counter()
    index = get_template().landmark_index
    coma = data.load_dataset("coma", "all")
    neutrals = coma.sequence_neutrals()
    exact = np.stack(
        [
            coma.face(int(coma.subjects[i])).landmarks(
                coma.au_weights[i].astype(np.float64)
            )
            for i in range(len(coma))
        ]
    )  # noise-free landmarks of every sequence
    overrides = {} if args.steps is None else {"steps": args.steps}
    ic = evaluation.load_evaluator("coma", "S")
    rows = []
    for label, (measure, region) in REGIONS.items():
        moved, read = [], []
        for k in range(args.faces):
            neutral = Face(sample_identity(FIRST_FACE + k)).neutral.astype(np.float32)
            for s in range(args.seeds):
                meshes, landmarks, _ = pipeline.animate(
                    neutral, label, seed=k * args.seeds + s, **overrides
                )
                moved.append(
                    apex_displacement(meshes[:, index], neutral[index], region)
                )
                read.append(
                    ic.class_names[int(ic.features(landmarks[None]).argmax())].split()[
                        0
                    ]
                    == label
                )
        mine = coma.labels == coma.label_names.index(label)
        real = apex_displacement(exact[mine], neutrals[mine], region)
        rows.append(
            [
                label,
                measure,
                float(np.mean(moved)),
                list(metrics.bootstrap_interval(np.mean, np.array(moved))),
                float(real.mean()),
                list(metrics.bootstrap_interval(np.mean, real)),
                len(moved),
                int(mine.sum()),
                float(np.min(moved)),
                float(np.percentile(real, 10)),
                [round(float(m), 2) for m in moved],
                [round(float(r), 2) for r in real],
                100.0 * float(np.mean(read)),
            ]
        )
        print(rows[-1], flush=True)
    if args.save:
        results.save_result(
            args.save,
            "How far `animate` moves unseen faces at the apex",
            COLUMNS,
            rows,
            results.Run(
                allow_dirty=args.allow_dirty,
                checkpoints=[
                    "denoiser_coma",
                    "guide_coma_S",
                    "deform_ours_identity",
                    "ic_coma_S",
                ],
                seeds=list(range(args.faces * args.seeds)),
                n=args.faces * args.seeds,
                steps=[args.steps or tasks.GeometryAdaptive().steps],
                wall_time_s=time.perf_counter() - t_start,
            ),
            notes=(
                f"identity seeds {FIRST_FACE}..{FIRST_FACE + args.faces - 1},"
                f" {args.seeds} sampling seeds each"
            ),
        )


if __name__ == "__main__":
    main()
