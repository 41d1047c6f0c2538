"""AU-curve control (not in the paper; the fine-control chapter): the unconditional DDPM steered so that the
action units of its sequence follow requested intensity curves, e.g. "raise AU12 from 0 to 0.8 between
frames 10 and 30 while the jaw stays closed".

A request is one curve per constrained AU, written ``NAME:value@frame,value@frame,...`` (frames from 0;
linear between the keys, held before the first and after the last) or ``NAME:value`` (constant).  NAME is
one of the world's AUs (``face.aus.AU_NAMES``) or an alias of several (``AU12``: both lip corners).  The
AUs a request does not name stay free.  The guidance climbs log N(c | R(x, t), tau^2) on the constrained
(frame, AU) pairs (:class:`facelib.guidance.AUCurveScore`) with Alg. 1's Adagrad steps.
"""
from __future__ import annotations

import numpy as np

from .. import data
from ..config import AU_CURVE_LR, AUControl
from ..face.aus import AU_NAMES
from ..guidance import AUCurveScore, MeanShiftGuidance, OptimisationGuidance
from .label import step_scaled_lr
from .loading import guided_chain, load_au_regressor, task_settings

AU_ALIASES = {"AU12": ("AU12L", "AU12R")}  # a symmetric smile: both lip corner pullers
AU_CURVE_REFERENCE_STEPS = 50  # AU_CURVE_LR is chosen for chains of this length


def au_names_of(name):
    """The world's AUs that a name in a request stands for (one AU, or the AUs of an alias)."""
    if name in AU_ALIASES:
        return AU_ALIASES[name]
    if name not in AU_NAMES:
        raise ValueError(f"unknown AU {name!r}; allowed: {', '.join(AU_NAMES + tuple(AU_ALIASES))}")
    return (name,)


def data_ranges(dataset="coma"):
    """{AU name: (lowest, highest) intensity} of the training split of ``dataset``: what a request may ask."""
    w = data.load_dataset(dataset, "train").au_weights
    return {name: (float(w[..., k].min()), float(w[..., k].max())) for k, name in enumerate(AU_NAMES)}


def parse_curve(spec, num_frames=40, ranges=None):
    """One request ``NAME:value@frame,...`` or ``NAME:value`` -> (the AU names it constrains, the curve (F,)).
    ``ranges`` ({AU: (low, high)}, e.g. :func:`data_ranges`) bounds the values; a clear error for an unknown
    AU, a frame outside 0..F-1, a repeated frame, a value outside the range or a malformed spec."""
    if not isinstance(spec, str) or spec.count(":") != 1:
        raise ValueError(f"an AU curve is NAME:value@frame,value@frame,... or NAME:value, got {spec!r}")
    name, keys = (part.strip() for part in spec.split(":"))
    names = au_names_of(name)
    try:
        pairs = [key.split("@") for key in keys.split(",")]
        if len(pairs) == 1 and len(pairs[0]) == 1:
            pairs = [[pairs[0][0], "0"]]
        values, frames = (np.array([float(p[0]) for p in pairs]), np.array([int(p[1]) for p in pairs]))
        if any(len(p) != 2 for p in pairs):
            raise ValueError
    except (ValueError, IndexError):
        raise ValueError(f"AU curve {spec!r}: write each key as value@frame (e.g. AU12:0@0,0.8@20) or one "
                         f"constant value (e.g. AU26:0)") from None
    if frames.min() < 0 or frames.max() >= num_frames or len(set(frames.tolist())) != len(frames):
        raise ValueError(f"AU curve {spec!r}: key frames must be distinct, in 0..{num_frames - 1}")
    for n in names if ranges else ():
        low, high = ranges[n]
        if values.min() < low - 1e-9 or values.max() > high + 1e-9:
            raise ValueError(f"AU curve {spec!r}: {n}'s intensity must stay in the data's range "
                             f"[{low:.2f}, {high:.2f}]")
    order = np.argsort(frames)
    return names, np.interp(np.arange(num_frames), frames[order], values[order])


def requested_curves(specs, num_frames=40, ranges=None):
    """Curves (F, A) and the mask (F, A) of the AUs they constrain, for a list of :func:`parse_curve` specs
    (an AU named twice is an error)."""
    if isinstance(specs, str) or not specs:
        raise ValueError(f"give a list of AU curves (e.g. ['AU12:0@0,0.8@20', 'AU26:0']), got {specs!r}")
    curves, mask = np.zeros((num_frames, len(AU_NAMES))), np.zeros((num_frames, len(AU_NAMES)), dtype=bool)
    for spec in specs:
        names, curve = parse_curve(spec, num_frames, ranges)
        for n in names:
            k = AU_NAMES.index(n)
            if mask[0, k]:
                raise ValueError(f"{n} is constrained twice in {specs!r}")
            curves[:, k], mask[:, k] = curve, True
    return curves, mask


def au_control(curves, n=16, settings=AUControl(), denoiser=None, regressor=None, progress=True, **overrides):
    """n sequences (n, F, 68, 3) float32 in mm whose AU curves follow a request (a list of specs, the same for
    every sequence, or a list of n such lists).  ``settings``: :class:`facelib.config.AUControl`."""
    settings, shape = task_settings(settings, overrides, n)
    regressor = regressor or load_au_regressor(settings.dataset)
    ranges = data_ranges(settings.dataset)
    per_sequence = curves if curves and not isinstance(curves[0], str) else [curves] * n
    if len(per_sequence) != n:
        raise ValueError(f"give one request for all sequences or one per sequence (n={n}), got {len(per_sequence)}")
    target, mask = map(np.stack, zip(*(requested_curves(c, settings.num_frames, ranges) for c in per_sequence)))
    denoiser, diffusion = guided_chain(regressor, denoiser, settings)
    score = AUCurveScore(regressor.model, target, mask, settings.tolerance)
    if settings.method == "adagrad":
        lr = settings.lr if settings.lr is not None else step_scaled_lr(
            AU_CURVE_LR, AU_CURVE_REFERENCE_STEPS, settings.steps, regressor.meta["training"]["num_diffusion_steps"])
        hook = OptimisationGuidance(score, diffusion, settings.guidance_weight, lr)
    else:
        hook = MeanShiftGuidance(score, diffusion, settings.scale)
    x = diffusion.sample(denoiser.model, shape, seed=settings.seed, guide=hook, progress=progress)
    return denoiser.to_mm(x)


def fitted_curves(sequences, faces=None):
    """The AU curves (n, F, A) that the world's rig needs to reproduce each sequence (n, F, 68, 3) in mm: the
    known face closest to its neutral end (:func:`facelib.rig_fit.closest_face`), then Gauss-Newton per frame
    (:func:`facelib.rig_fit.fit_aus`).  How AU-curve control is scored: the curves the result shows, read by
    the rig that made the data, against the curves requested."""
    from .. import rig_fit

    faces = faces or rig_fit.known_faces()
    return np.stack([rig_fit.fit_aus(rig_fit.closest_face(s, faces), s) for s in np.asarray(sequences)])


def curve_errors(fitted, requests, num_frames=40):
    """Mean absolute error (intensity units) per sequence between fitted curves (n, F, A) and the requests
    (one list of specs per sequence), over the constrained frames and AUs only."""
    out = []
    for w, request in zip(fitted, requests):
        curves, mask = requested_curves(request, num_frames)
        out.append(float(np.abs(w - curves)[mask].mean()))
    return np.array(out)


def never_together(dataset="coma", active=0.2):
    """The pairs of AUs (names) that no training sequence of ``dataset`` activates together (both above
    ``active`` at some frame of the same sequence), among the AUs the data activate at all."""
    w = data.load_dataset(dataset, "train").au_weights
    on = (np.abs(w) > active).any(1)  # (n, A): the AUs each sequence activates
    used = np.flatnonzero(on.any(0))
    return [(AU_NAMES[a], AU_NAMES[b]) for i, a in enumerate(used) for b in used[i + 1:]
            if not (on[:, a] & on[:, b]).any()]


def random_requests(n, seed=0, dataset="coma", aus=None, pairs=None, low=0.3):
    """n random requests within the data's range: one AU (of ``aus``; default, every AU the data push to at
    least 0.5) or one pair of ``pairs``, each a curve from 0 at frame 0 up to a peak in [low, the data's
    highest, at most 1] at a frame in 10..25, then to a value between 0 and the peak at frame 39."""
    rng = np.random.default_rng(seed)
    ranges = data_ranges(dataset)
    aus = aus or [a for a in AU_NAMES if ranges[a][1] >= 0.5 and a != "AU45"]
    requests = []
    for _ in range(n):
        chosen = pairs[rng.integers(len(pairs))] if pairs else (aus[rng.integers(len(aus))],)
        request = []
        for a in chosen:
            peak = rng.uniform(low, min(1.0, ranges[a][1]))
            request.append(f"{a}:0@0,{peak:.2f}@{rng.integers(10, 26)},{rng.uniform(0, peak):.2f}@39")
        requests.append(request)
    return requests
