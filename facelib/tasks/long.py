"""Sequences of any length (not in the paper; the chapter "Any length"): a model of 40
frames, composed.

A schedule ("high_smile:3s, neutral:1s, mouth_open:2s") is cut into windows of the
model's length.  Every window after the first shares its first ``transition`` frames
with the end of the stream so far, and those frames are conditioned on as the known
frames of expression filling (Alg. 3, with the book's reconstruction guidance: join
"fill"), so the window continues the motion it starts from; only its new frames are
kept.  Memory stays that of one window, whatever the length, and each window's frames
can be written as soon as they are made (:func:`stream`).

The face is the one given: its neutral landmarks are the first frame, and the last
frame of every window of a ``neutral`` segment, so the identity is re-anchored at every
rest.  The first window of a label's segment is guided by Alg. 1 with the type-S
classifier as an N2E sequence (the face sets out from where the stream is, as Alg. 4
from its neutral face); the segment's other windows continue it unguided, as ``free``
windows are.  A schedule with a text in quotes runs on the text head's data
(``settings.text_dataset``): each segment's first window is guided by Alg. 2 with its
text, a label's by its raw text ("high smile").

Join "learned" (not in the paper; CondMDI, Cohan et al. 2024) is fill run by a join
denoiser, which also reads the known frames as input (inpainting.KnownInput), trained
to continue them (denoiser_<dataset>_join).

The other joins, to compare: "replace" (Alg. 3 as printed, no reconstruction guidance),
"handshake" (PriorMDM's DoubleTake, its first take: every window at once in one batch,
the frames two windows share replaced by their mean after every step; memory grows with
the length) and "concat" (independent windows end to end, each from the given face: the
naive baseline).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
import torch

from .. import data
from ..config import (
    CHECKPOINT_DIR,
    JOIN_METHODS,
    LONG_MAX_SECONDS,
    NATIVE_FPS,
    NUM_LANDMARKS,
    SCHEDULE_FREE,
    SCHEDULE_NEUTRAL,
)
from ..descriptions import in_order, raw_text
from ..guidance import (
    ClassifierScore,
    CosineScore,
    OptimisationGuidance,
    ReconstructionGuidance,
    chain,
)
from ..face import Face, sample_identity
from ..face.aus import NUM_AUS
from ..inpainting import KnownFrames, KnownInput, keep_known, neutral_faces
from ..metrics import resample_frames
from ..text import check_text, get_encoder
from .fill import known_noise
from .loading import (
    check_n,
    denoiser_name,
    guided_chain,
    load_denoiser,
    load_guide,
    load_text_head,
)
from .settings import Long
from ..checks import with_overrides


@dataclass(frozen=True)
class Segment:
    """A part of a schedule: ``what`` the face does (a label of the dataset,
    ``neutral``, ``free`` or, with ``text``, a description) for ``frames`` frames at
    :data:`NATIVE_FPS`."""

    what: str
    frames: int
    text: bool = False


@dataclass(frozen=True)
class Window:
    """One window of a long sequence: its first ``known`` frames are the end of the
    stream so far, the next ``keep`` frames are new and kept; at the window frames
    ``anchors`` the face is the given neutral face."""

    what: str
    known: int
    keep: int
    anchors: tuple
    opens: bool = False  # the first window of its segment
    text: bool = False  # ``what`` is a description


# WHAT:SECONDS, WHAT a word or a text in double or single quotes, then a comma or end
_ITEM = re.compile(
    r"""\s*(?:"(?P<double>[^"]*)"|'(?P<single>[^']*)'|(?P<word>[^:,"']+?))"""
    r"""\s*:\s*(?P<seconds>[0-9]*\.?[0-9]+)\s*s?\s*(?P<comma>,|$)"""
)


def _items(spec):
    """(what, is a text, seconds, the item as written) of each item of a schedule."""
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError(
            "the schedule must be a text like 'high_smile:3s, neutral:1s', got"
            f" {spec!r}"
        )
    items, position = [], 0
    while position < len(spec):
        match = _ITEM.match(spec, position)
        if match is None or (match.group("comma") and not spec[match.end() :].strip()):
            rest = spec[position:].split(",")[0].strip() if match is None else ""
            raise ValueError(
                f"cannot read the schedule item {rest!r}"
                + (" (after the last comma)" if match is not None else "")
                + ": write WHAT:SECONDS, e.g."
                " 'high_smile:3s' or '\"a broad grin\":2s' (a text in quotes)"
            )
        quoted = match.group("double")
        quoted = match.group("single") if quoted is None else quoted
        what = match.group("word") if quoted is None else check_text(quoted)
        written = match.group(0).strip().rstrip(",").strip()
        items.append((what, quoted is not None, float(match.group("seconds")), written))
        position = match.end()
    return items


def has_text(spec):
    """Whether a schedule (a string or a list of :class:`Segment`) holds a text."""
    if isinstance(spec, str):
        return any(text for _, text, _, _ in _items(spec))
    return any(s.text for s in spec)


def parse_schedule(spec, labels, transition=Long.transition):
    """The segments of a schedule "label:3s, neutral:1s, 'a broad grin':2s, ...": each
    item a label of ``labels``, ``neutral`` (the given face at rest), ``free``
    (unguided motion) or a description in quotes (text control), and a duration in
    seconds ("3s", "1.5s" or "3").  A clear error for an empty or malformed schedule,
    an unknown label, an empty text, a segment shorter than ``transition`` frames (at
    :data:`NATIVE_FPS`) and a total over :data:`LONG_MAX_SECONDS`."""
    allowed = sorted(labels) + [SCHEDULE_NEUTRAL, SCHEDULE_FREE]
    segments = []
    for what, text, seconds, written in _items(spec):
        if text and what in allowed:
            raise ValueError(
                f"{written!r}: {what!r} is a name of the schedule, not a text; write"
                f" it unquoted ({what}:{seconds:g}s), or a description in quotes"
            )
        if not text and what not in allowed:
            raise ValueError(
                f"unknown expression {what!r} in the schedule; allowed: "
                + ", ".join(allowed)
                + ", or a description in quotes"
            )
        frames = int(round(seconds * NATIVE_FPS))
        if frames < transition:
            raise ValueError(
                f"the segment {written!r} lasts {frames} frames, shorter than a"
                f" transition ({transition} frames, {transition / NATIVE_FPS:.2f} s)"
            )
        segments.append(Segment(what, frames, text))
    total = sum(s.frames for s in segments) / NATIVE_FPS
    if total > LONG_MAX_SECONDS:
        raise ValueError(
            f"the schedule lasts {total:g} s; at most {LONG_MAX_SECONDS} s are allowed"
        )
    return segments


def schedule_dataset(settings, schedule):
    """The data a schedule (a string or Segments) runs on: ``settings.dataset``, or
    ``settings.text_dataset`` when it holds a text."""
    return settings.text_dataset if has_text(schedule) else settings.dataset


def read_schedule(spec, settings=Long()):
    """:func:`parse_schedule` with the labels of the data the schedule runs on:
    ``settings.dataset``'s, or ``settings.text_dataset``'s when it holds a text (each
    text checked by the encoder)."""
    dataset = schedule_dataset(settings, spec)
    labels = data.load_dataset(dataset, "train").class_names("I")
    segments = parse_schedule(spec, labels, settings.transition)
    texts = [s.what for s in segments if s.text]
    if texts:  # a text the encoder cannot read is refused before anything runs
        get_encoder().encode(texts)
    return segments


def free_schedule(seconds, transition=Long.transition):
    """The schedule of ``seconds`` of unguided motion (``sample long --seconds``)."""
    if (
        isinstance(seconds, bool)
        or not isinstance(seconds, (int, float))
        or not 0 < seconds <= LONG_MAX_SECONDS
    ):
        raise ValueError(
            f"seconds must be a number in (0, {LONG_MAX_SECONDS}], got {seconds!r}"
        )
    return parse_schedule(f"{SCHEDULE_FREE}:{seconds}s", (), transition)


def plan_windows(segments, num_frames, transition, join="fill"):
    """The windows (:class:`Window`) that make the segments' frames: the first starts
    at the given face (anchored at frame 0); each later one knows the ``transition``
    frames before it; a window of a ``neutral`` segment ends at the given face.  Join
    "concat": the same frames, each window on its own from the given face."""
    windows = []
    for segment in segments:
        left = segment.frames
        while left:
            known = transition if windows and join != "concat" else 0
            keep = min(num_frames - known, left)
            anchors = {0} if not windows or join == "concat" else set()
            if segment.what == SCHEDULE_NEUTRAL:
                anchors.add(known + keep - 1)
            opens = left == segment.frames
            windows.append(
                Window(
                    segment.what,
                    known,
                    keep,
                    tuple(sorted(anchors)),
                    opens,
                    segment.text,
                )
            )
            left -= keep
    return windows


def join_frames(windows):
    """The stream frames at which a window's new frames begin after the frames it knows
    (every window but the first): the frame pair (f - 1, f) is a join."""
    starts = np.cumsum([0] + [w.keep for w in windows])
    return starts[1:-1]


def _segment_guidance(window, n, diffusion, guides, settings):
    """The guidance of a window's n rows (None for ``neutral`` and ``free``, and for a
    segment's later windows unless ``settings.guide_continuation``): Alg. 1 for a
    label, Alg. 2 for a text (:func:`_text_guidance`)."""
    if window.what in (SCHEDULE_NEUTRAL, SCHEDULE_FREE) and not window.text:
        return None
    if not window.opens and not settings.guide_continuation:
        return None
    if "text" in guides:
        return _text_guidance(window, n, diffusion, guides, settings)
    return _label_guidance(window, n, diffusion, guides, settings)


def _label_guidance(window, n, diffusion, guides, settings):
    """Alg. 1 towards the window's label for n rows: a segment's first window by the
    type-S classifier as ``settings.opening`` (the face sets out from where the stream
    is, as an N2E sequence from its neutral face), its other windows by the type-I
    classifier."""
    if window.opens and settings.opening is not None:
        guide, lr = guides["S"], settings.opening_lr
        label = f"{window.what} {settings.opening}"
    else:
        guide, label = guides["I"], window.what
        lr = settings.resolved(guide.meta["training"]["num_diffusion_steps"]).lr
    score = ClassifierScore(guide.model, guide.class_indices([label] * n))
    return OptimisationGuidance(score, diffusion, settings.guidance_weight, lr)


def _guiding_text(window, settings):
    """What Alg. 2 reads for a window: its text (a label's raw text), said in the order
    ``settings.text_opening`` in a segment's first window (None: as written)."""
    text = window.what if window.text else raw_text(window.what)
    if window.opens and settings.text_opening is not None:
        text = in_order(text, settings.text_opening)
    return text


def _text_guidance(window, n, diffusion, guides, settings):
    """Alg. 2 (the cosine of Eq. 10 on x_t) towards the window's text for n rows, with
    text control's lambda and rate unless ``settings`` gives them."""
    head = guides["text"]
    embedding = guides["embeddings"][_guiding_text(window, settings)]
    score = CosineScore(head.model, embedding.expand(n, -1))
    resolved = settings.resolved(head.meta["training"]["num_diffusion_steps"])
    return OptimisationGuidance(
        score, diffusion, resolved.text_guidance_weight, resolved.text_lr
    )


def _known(window, n, num_frames, face, tail):
    """The window's given frames (n, F, 68, 3) in mm and their mask (n, F): the stream's
    last frames, then the anchors."""
    given = np.zeros((n, num_frames, NUM_LANDMARKS, 3))
    mask = np.zeros((n, num_frames), dtype=bool)
    if window.known:
        given[:, : window.known], mask[:, : window.known] = tail, True
    for a in window.anchors:
        given[:, a], mask[:, a] = face, True
    return given, mask


def _reconstruction(settings, model, diffusion, x0, known):
    """Reconstruction guidance towards the known frames (None at scale 0)."""
    if not settings.reconstruction_scale:
        return None
    return ReconstructionGuidance(
        model, diffusion, x0, known, settings.reconstruction_scale
    )


def join_denoiser_name(settings, schedule):
    """The join denoiser that join "learned" runs for a schedule (a string or
    Segments): denoiser_<dataset>_join of the data the schedule runs on; a clear error
    where none is shipped (a schedule with a text runs on the text head's data)."""
    dataset = schedule_dataset(settings, schedule)
    name = denoiser_name(dataset, settings.sampler, settings.steps, "join")
    if not (CHECKPOINT_DIR / f"{name}.pt").exists():
        raise ValueError(
            f"join 'learned' runs the join denoiser {name} of the {dataset!r} data, and"
            " none is shipped (only denoiser_coma_join; a schedule with a text runs on"
            f" {settings.text_dataset!r}): use join fill, or train one (`python -m"
            f" facelib train denoiser --dataset {dataset} --set known_frames=0.75`)"
        )
    return name


def _join_denoiser(settings, denoiser, schedule):
    """The denoiser of join "learned": the given one, which must read known frames, or
    :func:`join_denoiser_name`'s (the given one for the other joins)."""
    if settings.join != "learned":
        return denoiser
    if denoiser is None:
        denoiser = load_denoiser(join_denoiser_name(settings, schedule))
    if not getattr(denoiser.model.config, "known_input", False):
        raise ValueError(
            "join 'learned' needs a join denoiser, which reads the known frames"
            " (denoiser_<dataset>_join); this one does not"
        )
    return denoiser


def _models(settings, denoiser, guide, order_guide, text_head, schedule):
    """The denoiser, its chain and the guides of a long sequence: {"I": labels, "S":
    labels and their order}, or for a schedule with a text {"text": the text head,
    "embeddings": {text: E(text) (1, D)} of every text it reads}."""
    if has_text(schedule):
        if guide is not None or order_guide is not None:
            raise ValueError(
                "a schedule with a text is guided by the text head (text_head), not by"
                " label classifiers (guide, order_guide)"
            )
        head = text_head or load_text_head(settings.text_dataset)
        if head.classifier_type != "text":
            raise ValueError(
                "a schedule with a text needs a text head (load_text_head), not a label"
                " classifier"
            )
        bad = [
            s.what
            for s in schedule
            if not s.text
            and s.what not in (SCHEDULE_NEUTRAL, SCHEDULE_FREE)
            and s.what not in head.class_names
        ]
        if bad:
            raise ValueError(
                f"unknown label {bad[0]!r} for the text head's data"
                f" {head.dataset!r}; allowed: {', '.join(head.class_names)}"
            )
        denoiser, diffusion, head = guided_chain(head, denoiser, settings)
        texts = sorted(
            {
                _guiding_text(Window(s.what, 0, 1, (), opens, s.text), settings)
                for s in schedule
                if s.text or s.what not in (SCHEDULE_NEUTRAL, SCHEDULE_FREE)
                for opens in (True, False)
            }
        )
        encoded = torch.as_tensor(get_encoder().encode(texts)).to(denoiser.device)
        embeddings = {t: e[None] for t, e in zip(texts, encoded)}
        return denoiser, diffusion, {"text": head, "embeddings": embeddings}
    if text_head is not None:
        raise ValueError("a text head guides a schedule with a text; this one has none")
    guides = {
        "I": guide or load_guide(settings.dataset, "I"),
        "S": order_guide or load_guide(settings.dataset, "S"),
    }
    for kind, g in guides.items():
        if g.classifier_type != kind:
            raise ValueError(
                f"the type-{kind} guide of a long sequence is of type"
                f" {g.classifier_type!r}"
            )
        denoiser, diffusion, guides[kind] = guided_chain(g, denoiser, settings)
    return denoiser, diffusion, guides


def drawn_face(seed):
    """The neutral landmarks (68, 3) in mm of a new identity of the world drawn with
    ``seed`` (the face `python -m facelib neutral --seed SEED` writes): where a stream
    given no face starts and rests, as the other tasks draw their faces."""
    return Face(sample_identity(seed)).landmarks(np.zeros(NUM_AUS))


def _check(neutral, schedule, n, settings, overrides):
    if not isinstance(settings, Long):
        raise TypeError(
            f"settings must be facelib.Long, got {type(settings).__name__}"
        )
    settings = with_overrides(settings, overrides)
    check_n(n)
    if neutral is None:
        neutral = drawn_face(settings.seed)
    face = neutral_faces(neutral, n, "the neutral face")
    if isinstance(schedule, str):
        raise ValueError(
            "give the schedule parsed (tasks.long.parse_schedule) with the dataset's"
            " labels"
        )
    if not schedule or not all(isinstance(s, Segment) for s in schedule):
        raise ValueError("the schedule must be a non-empty list of Segment")
    return settings, face


def stream(
    neutral,
    schedule,
    n=1,
    settings=Long(),
    denoiser=None,
    guide=None,
    progress=True,
    order_guide=None,
    text_head=None,
    **overrides,
):
    """Generate n long sequences of the face ``neutral`` (68, 3) in mm (or one face
    per sequence, (n, 68, 3); None: :func:`drawn_face` of the seed), following
    ``schedule`` (a list of :class:`Segment`, :func:`parse_schedule`), window by
    window: yields the new frames of each window,
    (n, k, 68, 3) float32 in mm at :data:`NATIVE_FPS`, as soon as they are made.
    Joins "fill", "replace", "concat" and "learned" (``settings.join``); memory is that
    of one window.  A schedule of labels is guided by ``guide`` (type I) and
    ``order_guide`` (type S), one with a text by ``text_head`` (None: the shipped
    ones)."""
    settings, face = _check(neutral, schedule, n, settings, overrides)
    if settings.join == "handshake":
        raise ValueError(
            "the handshake generates every window at once: use long_sequence, not"
            " stream"
        )
    denoiser = _join_denoiser(settings, denoiser, schedule)
    denoiser, diffusion, guides = _models(
        settings, denoiser, guide, order_guide, text_head, schedule
    )
    num_frames = settings.num_frames
    windows = plan_windows(schedule, num_frames, settings.transition, settings.join)
    generator, noise = torch.Generator().manual_seed(settings.seed), known_noise(
        settings.seed
    )
    tail = None  # the stream's last frames, which the next window knows
    for window in windows:
        given, mask = _known(window, n, num_frames, face, tail)
        x0 = denoiser.to_model(given)
        known = torch.as_tensor(mask).to(denoiser.device)
        model = denoiser.model
        if settings.join == "learned":
            model = KnownInput(model, x0, known)
        reconstruction = None
        if settings.join in ("fill", "learned"):
            reconstruction = _reconstruction(settings, model, diffusion, x0, known)
        inner = chain(
            _segment_guidance(window, n, diffusion, guides, settings), reconstruction
        )
        hook = KnownFrames(
            diffusion, x0, known, noise, inner=inner, feather=settings.feather
        )
        x = hook.sample(model, generator, progress=progress)
        out = keep_known(denoiser.to_mm(x.detach()), given, mask)
        new = out[:, window.known : window.known + window.keep]
        previous = new if tail is None else np.concatenate([tail, new], axis=1)
        tail = previous[:, -settings.transition :]
        yield new


@dataclass
class Handshake:
    """The sampler hook of DoubleTake's first take over a batch of windows (n streams x
    W windows, stream-major): ``inner`` (the rows' guidance and anchors), then the
    frames two consecutive windows share set to their mean, where neither copy is
    anchored (``known`` (n W, F) bool); where one is, both take its value, so that an
    anchor inside a shared block holds at every step, not half of it."""

    inner: object
    windows: list
    n: int
    transition: int
    known: torch.Tensor

    def __call__(self, x_hat, xt, t, out):
        x = self.inner(x_hat, xt, t, out)
        w, o = len(self.windows), self.transition
        x = x.view(self.n, w, *x.shape[1:]).clone()
        known = self.known.view(self.n, w, -1).to(x.dtype)
        for k in range(1, w):
            end = self.windows[k - 1].known + self.windows[k - 1].keep
            before, after = known[:, k - 1, end - o : end], known[:, k, :o]
            # the earlier copy's weight: 1/2, or 1 (0) where only it (the other) is
            # anchored
            weight = (0.5 * (1 + before - after))[:, :, None, None]
            shared = weight * x[:, k - 1, end - o : end] + (1 - weight) * x[:, k, :o]
            x[:, k - 1, end - o : end], x[:, k, :o] = shared, shared
        return x.view(-1, *x.shape[2:])


class _Rows:
    """A guidance hook applied to the chosen rows (B,) of the batch only: ``guide`` is
    made for as many rows as are chosen."""

    def __init__(self, guide, rows):
        self.guide, self.rows = guide, rows

    def __call__(self, x_hat, xt, t, out):
        r = self.rows.to(x_hat.device)
        part = {
            k: v[r] if torch.is_tensor(v) and v.ndim and len(v) == len(r) else v
            for k, v in out.items()
        }
        x = x_hat.clone()
        x[r] = self.guide(x_hat[r], xt[r], t, part)
        return x


def _handshake(face, schedule, n, settings, denoiser, guides, progress):
    """DoubleTake's first take: (n, frames, 68, 3) float32 in mm at NATIVE_FPS;
    ``guides`` the (guide, order_guide, text_head) given."""
    denoiser, diffusion, guides = _models(settings, denoiser, *guides, schedule)
    num_frames, o = settings.num_frames, settings.transition
    windows = plan_windows(schedule, num_frames, o)
    # in a batch every window is generated at once: the shared frames are not known,
    # only the anchors
    rows = len(windows) * n
    made = [
        _known(Window(w.what, 0, w.keep, w.anchors), n, num_frames, face, None)
        for w in windows
    ]
    # stream-major: window k of stream i is row i * W + k
    given = np.stack([g for g, _ in made], axis=1).reshape(rows, num_frames, -1, 3)
    mask = np.stack([m for _, m in made], axis=1).reshape(rows, num_frames)
    x0, known = denoiser.to_model(given), torch.as_tensor(mask).to(denoiser.device)
    hooks = []
    for what, opens, text in sorted({(w.what, w.opens, w.text) for w in windows}):
        chosen = torch.tensor(
            [(w.what, w.opens, w.text) == (what, opens, text) for w in windows] * n
        )
        guidance = _segment_guidance(
            Window(what, 0, 1, (), opens, text),
            int(chosen.sum()),
            diffusion,
            guides,
            settings,
        )
        if guidance is not None:
            hooks.append(_Rows(guidance, chosen))
    reconstruction = _reconstruction(settings, denoiser.model, diffusion, x0, known)
    anchors = KnownFrames(
        diffusion,
        x0,
        known,
        known_noise(settings.seed),
        inner=chain(*hooks, reconstruction),
    )
    hook = Handshake(anchors, windows, n, o, known)
    generator = torch.Generator().manual_seed(settings.seed)
    start = anchors.start(generator)
    x = diffusion.run(denoiser.model, start, generator, None, hook, progress=progress)
    out = keep_known(denoiser.to_mm(x.detach()), given, mask).reshape(
        n, len(windows), num_frames, NUM_LANDMARKS, 3
    )
    return np.concatenate(
        [out[:, k, w.known : w.known + w.keep] for k, w in enumerate(windows)], axis=1
    )


def long_sequence(
    neutral,
    schedule,
    n=1,
    settings=Long(),
    denoiser=None,
    guide=None,
    progress=True,
    order_guide=None,
    text_head=None,
    **overrides,
):
    """n long sequences (n, frames, 68, 3) float32 in mm at ``settings.fps`` of the face
    ``neutral`` (None: :func:`drawn_face` of the seed) following ``schedule``
    (:func:`stream`, or the handshake), resampled in time from :data:`NATIVE_FPS`."""
    settings, face = _check(neutral, schedule, n, settings, overrides)
    if settings.join == "handshake":
        x = _handshake(
            face,
            schedule,
            n,
            settings,
            denoiser,
            (guide, order_guide, text_head),
            progress,
        )
    else:
        made = stream(
            face,
            schedule,
            n,
            settings,
            denoiser,
            guide,
            progress,
            order_guide,
            text_head,
        )
        x = np.concatenate(list(made), axis=1)
    return resample_fps(x, settings.fps)


def resample_fps(sequences, fps, native=NATIVE_FPS):
    """Sequences (n, F, ...) at ``native`` frames per second, linearly resampled to
    ``fps`` over the same duration."""
    x = np.asarray(sequences)
    if fps == native:
        return x.astype(np.float32)
    frames = int(round((x.shape[1] - 1) * fps / native)) + 1
    return resample_frames(x, frames)


__all__ = [
    "JOIN_METHODS",
    "Segment",
    "Window",
    "free_schedule",
    "has_text",
    "join_denoiser_name",
    "join_frames",
    "long_sequence",
    "parse_schedule",
    "plan_windows",
    "read_schedule",
    "resample_fps",
    "schedule_dataset",
    "stream",
]
