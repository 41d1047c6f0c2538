"""The inputs the book's tables and benchmarks measure the tasks on (not the sampling
API: facelib.tasks is): the rows of Table 1, the inputs of Table 4, random AU-curve
requests and keyframes that real motion can meet, and the rig fit's floor on real
sequences.  Used by benchmarks/ and the chapters; each draws from a seed.
"""

from __future__ import annotations

import numpy as np

from . import data
from .baselines import LABEL_BASELINES, generate, load_baseline
from .config import AU_REQUEST_PEAK, AU_REQUEST_PEAK_FRAMES, NUM_FRAMES
from .face.aus import AU_NAMES
from .tasks import data_ranges, fitted_curves, label_control, unconditional


def table1_generators(
    dataset, indices, steps, guide, denoiser, mean_shift_scale, seed=0
):
    """The rows of Table 1 (§5.1) for the test sequences ``indices`` of ``dataset``:
    {row: callable() -> sequences (n, F, 68, 3) in mm}, each asked for the labels of
    those sequences: the sequences themselves (the ground truth), the two trained
    baselines, the unguided DDPM, classic mean-shift guidance at ``mean_shift_scale``
    and Alg. 1 (with ``steps`` reverse steps, ``guide`` and ``denoiser``).  Score them
    with :func:`facelib.evaluation.compare`."""
    test = data.load_dataset(dataset, "test")
    indices = np.asarray(indices)
    labels, n = [test.label_of(int(i)) for i in indices], len(indices)
    models = {b: load_baseline(b, dataset) for b in LABEL_BASELINES}
    common = dict(
        dataset=dataset, steps=steps, seed=seed, denoiser=denoiser, progress=False
    )
    return {
        "Ground truth (test split)": lambda: test.landmarks[indices],
        "Motion3DGAN-style (MoGAN)": lambda: generate(
            models["motion3dgan"], labels, seed=seed
        ),
        "ACTOR-style CVAE": lambda: generate(models["actor"], labels, seed=seed),
        "DDPM, unguided": lambda: unconditional(n, **common),
        f"DDPM + mean shift (scale {mean_shift_scale:g})": lambda: label_control(
            labels,
            n,
            guide=guide,
            method="mean_shift",
            scale=mean_shift_scale,
            **common,
        ),
        "DDPM + Alg. 1 (ours)": lambda: label_control(labels, n, guide=guide, **common),
    }


def table4_inputs(test, class_names, per_class=None):
    """The inputs of Table 4 (§5.4) from a test split: its rows (``per_class`` per
    type-S class of ``class_names``; None: all), their type-S labels, neutral landmarks
    (n, 68, 3) and known-frame masks (n, F) (frame 1 for N2E, frame F for E2N)."""
    targets = test.targets("S")
    rows = np.concatenate(
        [np.flatnonzero(targets == c)[:per_class] for c in range(len(class_names))]
    )
    labels = [class_names[c] for c in targets[rows]]
    known = np.zeros((len(rows), test.landmarks.shape[1]), bool)
    known[
        np.arange(len(rows)), [0 if lab.endswith("N2E") else -1 for lab in labels]
    ] = True
    return rows, labels, test.sequence_neutrals()[rows], known


def random_requests(
    n,
    seed=0,
    dataset="coma",
    aus=None,
    pairs=None,
    low=AU_REQUEST_PEAK[0],
    high=AU_REQUEST_PEAK[1],
    peak_frames=AU_REQUEST_PEAK_FRAMES,
    num_frames=NUM_FRAMES,
):
    """n random requests within the data's range: one AU (of ``aus``; default, every AU
    the data push to at least 0.5) or one pair of ``pairs``, each a curve from 0 at
    frame 0 up to a peak in [low, min(high, the data's highest)] at a frame in
    ``peak_frames`` (first, last), then to a value between 0 and the peak at the last
    frame."""
    rng = np.random.default_rng(seed)
    ranges = data_ranges(dataset)
    aus = aus or [a for a in AU_NAMES if ranges[a][1] >= 0.5 and a != "AU45"]
    first, last = peak_frames
    if not 0 < first <= last < num_frames - 1:
        raise ValueError(
            "peak_frames must be (first, last) with 0 < first <= last <"
            f" {num_frames - 1}, got {peak_frames!r}"
        )
    requests = []
    for _ in range(n):
        chosen = (
            pairs[rng.integers(len(pairs))] if pairs else (aus[rng.integers(len(aus))],)
        )
        request = []
        for a in chosen:
            peak = rng.uniform(low, min(high, ranges[a][1]))
            at, end = rng.integers(first, last + 1), rng.uniform(0, peak)
            request.append(f"{a}:0@0,{peak:.2f}@{at},{end:.2f}@{num_frames - 1}")
        requests.append(request)
    return requests


def fit_floor(dataset="coma", n=30, active=0.1):
    """{AU: mean absolute error of the rig fit on real test sequences of ``dataset``
    with their own faces, over the entries where the AU is active (above ``active``)}:
    what the measurement of AU-curve control cannot resolve (capture noise, AUs the
    landmarks barely see); AUs active in fewer than 20 entries are left out.
    """
    test = data.load_dataset(dataset, "test")
    idx = np.linspace(0, len(test) - 1, n).round().astype(int)
    w = test.au_weights[idx]
    fit = fitted_curves(
        test.landmarks[idx], [test.face(int(test.subjects[i])) for i in idx]
    )
    on = np.abs(w) > active
    return {
        a: float(np.abs(fit - w)[..., k][on[..., k]].mean())
        for k, a in enumerate(AU_NAMES)
        if on[..., k].sum() >= 20
    }


# chin, brows, mouth corners, lower lip: what expressions move most
MOBILE_LANDMARKS = (8, 19, 24, 48, 54, 57)


def random_keys(
    n,
    seed=0,
    dataset="coma",
    landmarks=MOBILE_LANDMARKS,
    frames=(10, 35),
    sources=False,
):
    """n random requests [(keys, neutral (68, 3))] that real motion can meet: for a
    random test sequence of ``dataset`` (an N2E one), its subject's neutral face and one
    key, the displacement of one of ``landmarks`` at a frame in ``frames`` (first, last;
    our choice: after the onset, before the last frames) of that sequence.  With
    ``sources``: (requests, the test sequences' indices), the real motion that meets
    each."""
    test = data.load_dataset(dataset, "test")
    if not 0 < frames[0] <= frames[1] < test.landmarks.shape[1]:
        raise ValueError(
            "frames must be (first, last) with 0 < first <= last <"
            f" {test.landmarks.shape[1]}, got {frames!r}"
        )
    n2e = np.flatnonzero(test.kinds == 0)
    rng = np.random.default_rng(seed)
    requests = []
    chosen = rng.choice(n2e, n, replace=len(n2e) < n)
    for i in chosen:
        neutral = test.neutral_landmarks(int(test.subjects[i]))
        frame, landmark = int(rng.integers(frames[0], frames[1] + 1)), int(
            rng.choice(landmarks)
        )
        shift = (
            test.landmarks[i, frame, landmark].astype(np.float64) - neutral[landmark]
        )
        requests.append(
            (
                [
                    {
                        "frame": frame,
                        "landmark": landmark,
                        "displacement": shift.round(2).tolist(),
                    }
                ],
                neutral,
            )
        )
    return (requests, chosen) if sources else requests
