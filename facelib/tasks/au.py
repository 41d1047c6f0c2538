"""AU-curve control (not in the paper; the fine-control chapter): the unconditional DDPM
steered so that the action units of its sequence follow requested intensity curves, e.g.
"raise AU12 from 0 to 0.8 between frames 10 and 30 while the jaw stays closed".

A request is one curve per constrained AU, written ``NAME:value@frame,value@frame,...``
(frames from 0; linear between the keys, held before the first and after the last) or
``NAME:value`` (constant).  NAME is one of the world's AUs (``face.aus.AU_NAMES``) or an
alias of several (``AU12``: both lip corners).  The AUs a request does not name stay
free.  The guidance climbs log N(c | R(x, t), tau^2) on the constrained (frame, AU)
pairs (:class:`facelib.guidance.AUCurveScore`) with Alg. 1's Adagrad steps.
"""

from __future__ import annotations

import numpy as np
import torch

from .. import data, rig_fit
from ..config import (
    AU_ACTIVE,
    AU_MEASURABLE_FIT_ERROR,
    NUM_FRAMES,
)
from ..face.aus import AU_NAMES
from ..guidance import (
    AUCurveScore,
    MeanShiftGuidance,
    OptimisationGuidance,
    ReconstructionGuidance,
    chain,
)
from ..inpainting import KnownFrames, keep_known, neutral_faces
from .fill import known_noise
from .loading import guided_chain, load_au_regressor, task_settings
from .settings import AUControl

AU_ALIASES = {"AU12": ("AU12L", "AU12R")}  # a symmetric smile: both lip corner pullers
# The baseline that separates what the AU guidance adds from what animating a given face
# costs: the same chain on the same face (frame 0 known, reconstruction guidance to it)
# with the AU score's weight zero.  Not plain sampling: Alg. 1's Adagrad steps still
# climb lambda log p_theta, a pull towards the denoiser's mean mu_theta.
AU_GUIDANCE_OFF = {"au_weight": 0.0}


def au_names_of(name):
    """The world's AUs that a name in a request stands for (one AU, or the AUs of an
    alias)."""
    if name in AU_ALIASES:
        return AU_ALIASES[name]
    if name not in AU_NAMES:
        raise ValueError(
            f"unknown AU {name!r}; allowed: {', '.join(AU_NAMES + tuple(AU_ALIASES))}"
        )
    return (name,)


def data_ranges(dataset="coma"):
    """{AU name: (lowest, highest) intensity} of the training split of ``dataset``: what
    a request may ask."""
    w = data.load_dataset(dataset, "train").au_weights
    return {
        name: (float(w[..., k].min()), float(w[..., k].max()))
        for k, name in enumerate(AU_NAMES)
    }


def parse_curve(spec, num_frames=NUM_FRAMES, ranges=None):
    """One request ``NAME:value@frame,...`` or ``NAME:value`` -> (the AU names it
    constrains, the curve (F,)). ``ranges`` ({AU: (low, high)}, e.g.
    :func:`data_ranges`) bounds the values; a clear error for an unknown AU, a frame
    outside 0..F-1, a repeated frame, a value outside the range or a malformed spec.
    """
    if not isinstance(spec, str) or spec.count(":") != 1:
        raise ValueError(
            "an AU curve is NAME:value@frame,value@frame,... or NAME:value, got"
            f" {spec!r}"
        )
    name, keys = (part.strip() for part in spec.split(":"))
    names = au_names_of(name)
    try:
        pairs = [key.split("@") for key in keys.split(",")]
        if len(pairs) == 1 and len(pairs[0]) == 1:
            pairs = [[pairs[0][0], "0"]]
        values, frames = (
            np.array([float(p[0]) for p in pairs]),
            np.array([int(p[1]) for p in pairs]),
        )
        if any(len(p) != 2 for p in pairs):
            raise ValueError
    except (ValueError, IndexError):
        raise ValueError(
            f"AU curve {spec!r}: write each key as value@frame (e.g. AU12:0@0,0.8@20)"
            " or one constant value (e.g. AU26:0)"
        ) from None
    if not np.isfinite(values).all():
        raise ValueError(f"AU curve {spec!r}: the values must be finite intensities")
    if (
        frames.min() < 0
        or frames.max() >= num_frames
        or len(set(frames.tolist())) != len(frames)
    ):
        raise ValueError(
            f"AU curve {spec!r}: key frames must be distinct, in 0..{num_frames - 1}"
        )
    for n in names if ranges else ():
        low, high = ranges[n]
        if values.min() < low - 1e-9 or values.max() > high + 1e-9:
            raise ValueError(
                f"AU curve {spec!r}: {n}'s intensity must stay in the data's range "
                f"[{low:.2f}, {high:.2f}]"
            )
    order = np.argsort(frames)
    return names, np.interp(np.arange(num_frames), frames[order], values[order])


def requested_curves(specs, num_frames=NUM_FRAMES, ranges=None):
    """Curves (F, A) and the mask (F, A) of the AUs they constrain, for a list of
    :func:`parse_curve` specs (an AU named twice is an error)."""
    if not isinstance(specs, (list, tuple)) or not specs:
        raise ValueError(
            "give a list of AU curves (e.g. ['AU12:0@0,0.8@20', 'AU26:0']), got"
            f" {specs!r}"
        )
    curves, mask = np.zeros((num_frames, len(AU_NAMES))), np.zeros(
        (num_frames, len(AU_NAMES)), dtype=bool
    )
    for spec in specs:
        names, curve = parse_curve(spec, num_frames, ranges)
        for n in names:
            k = AU_NAMES.index(n)
            if mask[0, k]:
                raise ValueError(f"{n} is constrained twice in {specs!r}")
            curves[:, k], mask[:, k] = curve, True
    return curves, mask


def au_control(
    curves,
    n=16,
    neutral=None,
    settings=AUControl(),
    denoiser=None,
    regressor=None,
    progress=True,
    **overrides,
):
    """n sequences (n, F, 68, 3) float32 in mm whose AU curves follow a request (a list
    of specs, the same for every sequence, or a list of n such lists).  ``neutral``: the
    neutral landmarks (68, 3) (or (n, 68, 3)) of the face to animate, which is then
    frame 0 (re-drawn from q as Alg. 3's known frames, with reconstruction guidance
    joining the other frames to it, as geometry-adaptive generation does); None: the
    model draws the face too.  ``settings``: :class:`facelib.AUControl`."""
    settings, shape = task_settings(settings, overrides, n)
    regressor = regressor or load_au_regressor(settings.dataset)
    ranges = data_ranges(settings.dataset)
    if not isinstance(curves, (list, tuple)) or not curves:
        raise ValueError(
            "curves must be a list of AU curves (e.g. ['AU12:0@0,0.8@20', 'AU26:0'])"
            f" or a list of n such lists, got {curves!r}"
        )
    per_sequence = curves if not isinstance(curves[0], str) else [curves] * n
    if len(per_sequence) != n:
        raise ValueError(
            f"give one request for all sequences or one per sequence (n={n}), got"
            f" {len(per_sequence)}"
        )
    target, mask = map(
        np.stack,
        zip(*(requested_curves(c, settings.num_frames, ranges) for c in per_sequence)),
    )
    denoiser, diffusion, regressor = guided_chain(regressor, denoiser, settings)
    reader = (
        dict(denoiser=denoiser.model, diffusion=diffusion)
        if settings.read == "x0_hat"
        else {}
    )
    score = (
        AUCurveScore(
            regressor.model,
            target,
            mask,
            settings.tolerance,
            settings.au_weight,
            **reader,
        )
        if settings.au_weight
        else no_au_score
    )
    if settings.method == "adagrad":
        lr = settings.resolved(regressor.meta["training"]["num_diffusion_steps"]).lr
        hook = OptimisationGuidance(score, diffusion, settings.guidance_weight, lr)
    else:
        hook = MeanShiftGuidance(score, diffusion, settings.scale)
    if neutral is None:
        x = diffusion.sample(
            denoiser.model, shape, seed=settings.seed, guide=hook, progress=progress
        )
        return denoiser.to_mm(x)
    given, known = neutral_frame(neutral, shape)
    x0, known_t = denoiser.to_model(given), torch.as_tensor(known).to(denoiser.device)
    if settings.reconstruction_scale:
        hook = chain(
            hook,
            ReconstructionGuidance(
                denoiser.model, diffusion, x0, known_t, settings.reconstruction_scale
            ),
        )
    hook = KnownFrames(diffusion, x0, known_t, known_noise(settings.seed), inner=hook)
    out = hook.sample(denoiser.model, settings.seed, progress=progress)
    return keep_known(denoiser.to_mm(out), given, known)


def no_au_score(x, t):
    """The AU score at weight zero (:data:`AU_GUIDANCE_OFF`): 0 for every sequence, R
    not even read."""
    return 0.0 * x.flatten(1).sum(1)


def neutral_frame(neutral, shape):
    """The given frames (n, F, 68, 3) and the known mask (n, F) of a face's neutral
    landmarks (68, 3) or (n, 68, 3) put at frame 0 (a clear error for another shape or a
    non-finite value).
    """
    x = neutral_faces(neutral, shape[0])
    given, known = np.zeros(shape), np.zeros(shape[:2], dtype=bool)
    given[:, 0], known[:, 0] = x, True
    return given, known


def fitted_curves(sequences, faces=None):
    """The AU curves (n, F, A) that the world's rig needs to reproduce each sequence (n,
    F, 68, 3) in mm (:func:`facelib.rig_fit.fit_aus`, Gauss-Newton per frame).  How
    AU-curve control is scored: the curves the result shows, read by the rig that made
    the data, against the curves requested.  ``faces``: one :class:`~facelib.face.Face`
    per sequence (the face it animates: exact), or None for the known face nearest each
    sequence's neutral end (:func:`facelib.rig_fit.closest_face`; on a face that is not
    among them the fit also absorbs the difference of anatomy, several tenths of
    intensity on unseen test faces).
    """
    x = np.asarray(sequences)
    if faces is None:
        known = rig_fit.known_faces()
        faces = [rig_fit.closest_face(s, known) for s in x]
    if len(faces) != len(x):
        raise ValueError(f"give one face per sequence ({len(x)}), got {len(faces)}")
    return np.stack([rig_fit.fit_aus(face, s) for face, s in zip(faces, x)])


@torch.no_grad()
def regressor_curves(sequences, regressor=None, dataset="coma"):
    """The AU curves (n, F, A) that the AU regressor R reads on sequences (n, F, 68, 3)
    in mm taken as clean (t = 0): what AU-curve guidance climbs towards, as opposed to
    :func:`fitted_curves`, what the rig shows.
    """
    regressor = regressor or load_au_regressor(dataset)
    x = torch.as_tensor(
        regressor.normalizer.normalize(np.asarray(sequences)), dtype=torch.float32
    )
    return regressor.model(x, torch.zeros(len(x))).numpy()


def measurable_aus(floor, dataset="coma", max_error=AU_MEASURABLE_FIT_ERROR):
    """The AUs that requests may use when the result is scored by the rig fit: those
    whose fit error on real sequences (``floor``, :func:`facelib.experiments.fit_floor`)
    is at most ``max_error``, that the data push to at least 0.5, and not the blink AU45
    (a blink is over in a few frames)."""
    ranges = data_ranges(dataset)
    return [
        a
        for a, e in floor.items()
        if e <= max_error and ranges[a][1] >= 0.5 and a != "AU45"
    ]


def curve_errors(fitted, requests, num_frames=NUM_FRAMES):
    """Mean absolute error (intensity units) per sequence between fitted curves (n, F,
    A) and the requests (one list of specs per sequence), over the constrained frames
    and AUs only."""
    out = []
    for w, request in zip(fitted, requests):
        curves, mask = requested_curves(request, num_frames)
        out.append(float(np.abs(w - curves)[mask].mean()))
    return np.array(out)


def active_aus(au_weights, active=AU_ACTIVE):
    """The AUs each sequence activates, (n, A) bool, for AU curves ``au_weights`` (n, F,
    A): |intensity| above ``active`` at some frame (the absolute value: the AD AUs, e.g.
    AD30's jaw sideways, are signed).
    """
    w = np.asarray(au_weights)
    if w.ndim != 3 or w.shape[-1] != len(AU_NAMES):
        raise ValueError(
            f"au_weights must be AU curves (n, F, {len(AU_NAMES)}), got shape {w.shape}"
        )
    if (
        isinstance(active, bool)
        or not isinstance(active, (int, float))
        or not 0 <= active < np.inf
    ):
        raise ValueError(f"active must be an intensity >= 0, got {active!r}")
    return (np.abs(w) > active).any(1)


def never_together(dataset="coma", active=AU_ACTIVE):
    """The pairs of AUs (names) that no training sequence of ``dataset`` activates
    together (both above ``active`` at some frame of the same sequence,
    :func:`active_aus`), among the AUs the data activate at all.
    """
    on = active_aus(data.load_dataset(dataset, "train").au_weights, active)  # (n, A)
    used = np.flatnonzero(on.any(0))
    return [
        (AU_NAMES[a], AU_NAMES[b])
        for i, a in enumerate(used)
        for b in used[i + 1 :]
        if not (on[:, a] & on[:, b]).any()
    ]


def requested_aus(requests):
    """The AUs (names, in the order of ``face.aus.AU_NAMES``) that a list of requests
    constrains."""
    used = set()
    for request in requests:
        for spec in request:
            used.update(au_names_of(spec.split(":")[0].strip()))
    return [a for a in AU_NAMES if a in used]
