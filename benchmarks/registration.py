"""Registration on truth: the template fitted to re-triangulated, re-posed, re-scaled
faces whose truth is known.

Usage: python benchmarks/registration.py [--faces 6] [--save NAME]

For each case (facelib/face/scans.py: subdivided, decimated to about 2k vertices in cm,
remeshed to about 20k in m, with 0.3 mm noise, with 3 holes, with two eyeballs as extra
components, and a face outside the identity model), the faces of ``--faces`` identities
that no dataset holds are registered (facelib/registration.py, the book's settings) and
measured against their truth:

* landmark error (mm): the fitted template's 68 landmarks against the true ones, pooled
  over the faces: median, 95th percentile, the median per region, and the median after
  the rigid and the identity-model stages;
* apex error (mm): the true motion of each template vertex for high_smile, mouth_open
  and eyebrow (at the middle of each recipe's ranges) is carried to the scan's vertices
  by FittedTemplate.transfer and compared with the true motion of those vertices (the
  face's vertices; extra components excluded): mean over vertices, then mean and 95 %
  bootstrap interval over faces and labels;
* seconds per registration (mean) and the rigid residual (trimmed RMS, mm) that decides
  whether a mesh is a face.

Meshes that are not faces (a sphere, a cube, a hand, a plane) are rows with their rigid
residual and whether they were refused.

    python benchmarks/registration.py --save registration_truth

(7 cases x 6 faces: about 15 minutes on one core beside other jobs.)
"""

import argparse
import time

import numpy as np

from facelib import config, metrics, registration, results
from facelib.face import scans
from facelib.face.template import LANDMARK_REGIONS, get_template

CASES = {  # name -> scans.make_scan arguments
    "subdivided (mm)": dict(remeshing="subdivided"),
    "decimated (cm)": dict(remeshing="decimated", units="cm"),
    "remeshed (m)": dict(remeshing="remeshed", units="m"),
    "noise 0.3 mm": dict(noise_mm=0.3),
    "3 holes": dict(holes=3),
    "eyeballs": dict(extra=True),
    "outside the model": dict(out_of_model=True),
}
# identity seeds from here on (scans.make_scan draws from [seed, 45]): no dataset's
FIRST_FACE = 4545
COLUMNS = [
    "case",
    "vertices",
    "units",
    "landmarks: median (mm)",
    "landmarks: p95 (mm)",
    *[f"{r}: median (mm)" for r in LANDMARK_REGIONS],
    "after rigid: median (mm)",
    "after identity model: median (mm)",
    "apex error: mean (mm)",
    "apex 95 % interval",
    "apex error: p95 (mm)",
    "seconds",
    "rigid residual (mm)",
    "refused",
]


def landmark_errors(landmarks, truth, units):
    return np.linalg.norm(landmarks - truth, axis=-1) * config.UNITS_MM[units]


def apex_errors(reg, scan):
    """Per label: mean over the scan's face vertices of |transferred motion - true
    motion| (mm)."""
    r, _ = reg.pose
    mm = config.UNITS_MM[scan.units]
    out = []
    for label, motion in scan.template_motion.items():
        frames = np.stack([reg.neutral, reg.neutral + (motion * mm) @ r.T])
        moved = (reg.transfer(frames)[1] - scan.vertices) * mm
        err = np.linalg.norm(moved - scan.truth_motion[label] * mm, axis=1)[
            scan.face_vertex
        ]
        out.append(err)
    return out


def face_row(case, kwargs, faces, settings):
    lm, by_stage, apex, apex_all, seconds, residual, counts = (
        [],
        {"rigid": [], "identity model": []},
        [],
        [],
        [],
        [],
        [],
    )
    index = get_template().landmark_index
    for k in range(faces):
        scan = scans.make_scan(FIRST_FACE + k, **kwargs)
        mesh = registration.check_mesh(scan.vertices, scan.faces)
        assert mesh.units == scan.units, (mesh.units, scan.units)
        t0 = time.perf_counter()
        reg = registration.register(mesh, settings)
        seconds.append(time.perf_counter() - t0)
        lm.append(landmark_errors(reg.landmarks, scan.truth_landmarks, scan.units))
        for stage in by_stage:
            by_stage[stage].append(
                landmark_errors(
                    reg.stages[stage][index] / config.UNITS_MM[scan.units],
                    scan.truth_landmarks,
                    scan.units,
                )
            )
        errors = apex_errors(reg, scan)
        apex += [float(e.mean()) for e in errors]
        apex_all.append(np.concatenate(errors))
        residual.append(reg.residual_mm["rigid (trimmed RMS)"])
        counts.append(len(scan.vertices))
    lm = np.stack(lm)  # (faces, 68)
    apex = np.array(apex)
    row = [
        case,
        int(np.median(counts)),
        kwargs.get("units", "mm"),
        float(np.median(lm)),
        float(np.percentile(lm, 95)),
        *[float(np.median(lm[:, list(r)])) for r in LANDMARK_REGIONS.values()],
        *[float(np.median(np.stack(v))) for v in by_stage.values()],
        float(apex.mean()),
        list(metrics.bootstrap_interval(np.mean, apex)),
        float(np.percentile(np.concatenate(apex_all), 95)),
        float(np.mean(seconds)),
        float(np.mean(residual)),
        False,
    ]
    return row


def refusal_row(name, vertices, faces, settings):
    mesh = registration.check_mesh(vertices, faces, units="mm")
    t0 = time.perf_counter()
    try:
        refused, residual = (
            False,
            registration.register(mesh, settings).residual_mm["rigid (trimmed RMS)"],
        )
    except registration.NotAFaceError as e:
        refused, residual = True, e.residual_mm
    return [
        f"not a face: {name}",
        len(vertices),
        "mm",
        *[None] * (len(COLUMNS) - 6),
        time.perf_counter() - t0,
        residual,
        refused,
    ]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--faces", type=int, default=6, help="unseen identities per case (default 6)"
    )
    results.add_save_options(parser)
    args = parser.parse_args()
    results.check_save_args(args)  # before any compute
    t_start = time.perf_counter()
    settings = registration.Registration()
    rows = []
    for case, kwargs in CASES.items():
        rows.append(face_row(case, kwargs, args.faces, settings))
        print(rows[-1], flush=True)
    for name, (v, f) in scans.not_faces().items():
        rows.append(refusal_row(name, v, f, settings))
        print(rows[-1], flush=True)
    if args.save:
        results.save_result(
            args.save,
            "Registration of unseen faces against their truth",
            COLUMNS,
            rows,
            results.Run(
                allow_dirty=args.allow_dirty,
                checkpoints=[],
                seeds=list(range(FIRST_FACE, FIRST_FACE + args.faces)),
                n=args.faces,
                steps=[],
                wall_time_s=time.perf_counter() - t_start,
                settings=[settings],
            ),
            notes=(
                f"identity seeds {FIRST_FACE}..{FIRST_FACE + args.faces - 1}"
                " (scans.make_scan); apex labels high_smile, mouth_open, eyebrow"
            ),
        )


if __name__ == "__main__":
    main()
