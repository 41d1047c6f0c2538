"""Conditioning the reverse process on known frames (paper §3.2, App. C Alg. 3 and 4).

Expression filling is inpainting in time: the frames S_K of x_0 are known, the frames
S_U are not.  Because q(x_t | x_0) is isotropic (Eq. 3), the known frames can be noised
to *any* step on their own, so the sampler is left as it is and, after every reverse
step, the known frames of x_{t-1} are overwritten by a fresh draw from q(x_{t-1} | x_0):

    x_{t-1}|S_U = x_hat_{t-1}|S_U,
    x_{t-1}|S_K = sqrt(abar_{t-1}) x_0|S_K + sqrt(1 - abar_{t-1}) eps

(Alg. 3 lines 10-12; the paper prints alpha where abar is meant, see the errata).  Two
traps of public RePaint implementations are pinned by tests: the noise level is that of
step t-1, not t, and sqrt(1 - abar) is a standard deviation, not a variance.

Also here: the known/unknown masks (parsing "0:10,30:40", validation, the FFB / FFE /
FFM settings of §5.3) and the two non-learned filling baselines (mean imputation,
interpolation).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np
import torch

from .config import NUM_LANDMARKS
from .diffusion import GaussianDiffusion

# §5.3: filling from the beginning, the end, the middle
FILL_SETTINGS = ("FFB", "FFE", "FFM")
# no landmark of a face in mm lies 10 m from the origin: a larger coordinate is another
LANDMARK_LIMIT_MM = 1e4
# unit or a corrupt file (and beyond 3.4e38 it would not even fit the float32 the
# samplers return)


def landmark_array(values, what):
    """``values`` as a float64 array: a clear error naming ``what`` for text, objects,
    booleans, complex numbers, ragged lists or anything else that is not an array of
    real numbers."""
    try:
        raw = np.asarray(values)
    except (ValueError, TypeError) as e:  # ragged lists
        raise ValueError(
            f"{what} must be an array of numbers (landmarks in mm), got"
            f" {type(values).__name__}: {e}"
        ) from None
    if raw.dtype.kind not in "iuf":
        raise ValueError(
            f"{what} must be an array of real numbers (landmarks in mm), got "
            f"{type(values).__name__} of dtype {raw.dtype}"
        )
    return raw.astype(np.float64)


def check_finite_landmarks(x, what):
    """A clear error when landmark coordinates ``x`` (mm) hold NaN, infinities or values
    beyond :data:`LANDMARK_LIMIT_MM`."""
    if not np.isfinite(x).all():
        raise ValueError(f"{what} contain NaN or infinite values")
    if x.size and np.abs(x).max() > LANDMARK_LIMIT_MM:
        raise ValueError(
            f"{what} reach {np.abs(x).max():.3g} mm: landmark coordinates must be in"
            f" mm, within +-{LANDMARK_LIMIT_MM:g}"
        )


def neutral_faces(values, n=None, what="the neutral face"):
    """A face's neutral landmarks in mm as a checked (68, 3) array, or with ``n`` as (n,
    68, 3) (a single face repeated n times); a clear error for another shape, text, NaN,
    infinities or values beyond :data:`LANDMARK_LIMIT_MM`.  The one check of every task
    given a face (AU control, geometry, keyframes).
    """
    x = landmark_array(values, what)
    wanted = (NUM_LANDMARKS, 3) if n is None else (n, NUM_LANDMARKS, 3)
    if n is not None and x.shape == (NUM_LANDMARKS, 3):
        x = np.broadcast_to(x, wanted)
    if x.shape != wanted:
        allowed = "(68, 3)" + ("" if n is None else f" or (n={n}, 68, 3)")
        raise ValueError(
            f"{what} must be finite landmarks of shape {allowed} in mm, got"
            f" {np.shape(values)}"
        )
    check_finite_landmarks(x, f"{what}'s landmarks")
    return x


def check_known_mask(mask, num_frames=None):
    """Validate a known-frame mask (F,) or (B, F) of booleans (True = known); returns a
    bool array.

    At least one frame must be known and at least one unknown in every sequence."""
    m = np.asarray(mask)
    if m.dtype != bool:
        if not np.isin(m, (0, 1)).all():
            raise ValueError(
                "the known-frame mask must be boolean (True = known frame) or 0/1"
            )
        m = m.astype(bool)
    if m.ndim not in (1, 2) or m.shape[-1] == 0:
        raise ValueError(
            "the known-frame mask must have shape (frames,) or (batch, frames), got"
            f" {m.shape}"
        )
    if num_frames is not None and m.shape[-1] != num_frames:
        raise ValueError(
            f"the known-frame mask has {m.shape[-1]} frames but the sequence has"
            f" {num_frames}"
        )
    rows = m.reshape(-1, m.shape[-1])
    if not rows.any(axis=1).all():
        raise ValueError(
            "the known-frame mask has no known frame: give at least one frame to fill"
            " from"
        )
    if rows.all(axis=1).any():
        raise ValueError(
            "the known-frame mask has no unknown frame: there is nothing to fill"
        )
    return m


def parse_known(spec, num_frames):
    """Parse known frames like "0:10,30:40" (:func:`parse_ranges`) into a checked
    known-frame mask (F,)."""
    return check_known_mask(parse_ranges(spec, num_frames))


def parse_ranges(spec, num_frames):
    """Parse frame ranges like "0:10,30:40" (Python slices, 0-based, end excluded) into
    a mask (F,)."""
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError(
            f"frames must be given as ranges like '0:10,30:40', got {spec!r}"
        )
    mask = np.zeros(num_frames, dtype=bool)
    for part in spec.split(","):
        try:
            start, stop = (
                (int(v) for v in part.split(":"))
                if ":" in part
                else (int(part), int(part) + 1)
            )
        except ValueError:
            raise ValueError(
                f"cannot read the frame range {part.strip()!r}; write start:stop, e.g."
                " '0:10,30:40'"
            ) from None
        if not 0 <= start < stop <= num_frames:
            raise ValueError(
                f"frame range {part.strip()!r} is outside 0:{num_frames} (start < stop"
                " required)"
            )
        mask[start:stop] = True
    return mask


def fill_masks(setting, n, num_frames=40, seed=0):
    """Known-frame masks (n, F) of the §5.3 experiments, with a random length per
    sequence: FFB (filling from the beginning: the last l frames known, l ~ U{10..30}),
    FFE (the first l known), FFM (l ~ U{5..15} known at each end, the middle
    missing)."""
    if setting not in FILL_SETTINGS:
        raise ValueError(
            f"unknown filling setting {setting!r}; allowed: {', '.join(FILL_SETTINGS)}"
        )
    rng = np.random.default_rng(seed)
    low, high = (5, 15) if setting == "FFM" else (10, 30)
    lengths = rng.integers(low, high + 1, size=n)
    f = np.arange(num_frames)[None, :]
    l = lengths[:, None]
    mask = {
        "FFB": f >= num_frames - l,
        "FFE": f < l,
        "FFM": (f < l) | (f >= num_frames - l),
    }[setting]
    return check_known_mask(mask, num_frames)


class KnownInput(torch.nn.Module):
    """A join denoiser (DenoiserConfig.known_input) with its known frames bound: x0 (B,
    F, 68, 3) in the model's space, ``known`` (B, F) bool.  A model like the denoiser,
    eps_theta(x_t, t | x_0 m, m), so that every sampler and hook runs it (the chapter
    "Any length"; CondMDI, Cohan et al. 2024)."""

    def __init__(self, denoiser, x0, known):
        super().__init__()
        if not getattr(denoiser.config, "known_input", False):
            raise ValueError(
                "this denoiser does not read known frames: use a join denoiser"
                " (denoiser_<dataset>_join, training.DenoiserTraining.known_frames)"
            )
        known = torch.as_tensor(known)
        if known.dtype != torch.bool or tuple(known.shape) != tuple(x0.shape[:2]):
            raise ValueError(
                f"known must be a (B, F) bool mask of frames, {tuple(x0.shape[:2])},"
                f" got {known.dtype} {tuple(known.shape)}"
            )
        self.denoiser, self.config = denoiser, denoiser.config
        self.register_buffer("x0", torch.as_tensor(x0), persistent=False)
        self.register_buffer("known", known, persistent=False)

    def forward(self, xt, t, mask=None):
        return self.denoiser(xt, t, mask, known=(self.x0, self.known))

    def eps_and_x0(self, xt, t, mask=None):
        return self.denoiser.eps_and_x0(xt, t, mask, known=(self.x0, self.known))


@dataclass
class KnownFrames:
    """Sampler hook of Alg. 3 (lines 10-12): keep x_hat on the unknown frames, re-draw
    the known frames from q(x_{t-1} | x_0).  ``inner`` is applied first: the guidance of
    Alg. 4 line 12.

    x0: (B, F, 68, 3) in the model's normalised space (values on unknown frames are
    ignored); known: (B, F) bool, or (B, F, 68) bool to know single landmarks of a frame
    (keyframes: inpainting on coordinates instead of frames).  Deterministic through
    ``generator``.

    ``feather`` (frames; 0: Alg. 3 as printed, not in the paper): replacement draws the
    known coordinates of x_{t-1} around sqrt(abar_{t-1}) x_0, where the model's own
    estimate would put them around sqrt(abar_{t-1}) x0_hat; the unknown ones next to
    them follow the model, and the gap leaves a jump at the mask's edge.  With
    feather = sigma > 0 every unknown coordinate is also shifted by that gap of the
    known coordinates of its landmark nearby:

        d_t(g) = sqrt(abar_{t-1}) (x_0 - x0_hat)(g)         on the known coordinates g
        x_{t-1}(f) += sum_g w(f - g) d_t(g) / max(1, sum_g w(f - g)),
        w(k) = exp(-k^2 / (2 sigma^2)),

    d_t the difference of the means of q(x_{t-1} | x_0) and q(x_{t-1} | x0_hat), with
    x0_hat the model's (``out["x0"]``): a noise-free shift at every step, a weighted
    average where the known coordinates nearby weigh 1 or more together (next to a
    block of known frames), w(k) of a single key's gap at k frames from it.  A given
    neutral face (all landmarks of its frame known) shifts the frames after it the same
    way.  Spreading the whole difference between the replaced and the model's x_{t-1}
    instead also spreads the replacement's fresh noise (chapter 12, exercise 6).
    """

    diffusion: GaussianDiffusion
    x0: torch.Tensor
    known: torch.Tensor
    generator: torch.Generator
    inner: Optional[Callable] = None
    feather: float = 0.0

    def noised(self, t):
        """x_t ~ q(x_t | x_0) on every frame (Eq. 3, with the correct sqrt(abar_t));
        x_0 itself at t = 0."""
        if t == 0:
            return self.x0
        return self.diffusion.q_sample(
            self.x0, torch.full((len(self.x0),), t), generator=self.generator
        )

    def start(self, generator):
        """x_T: N(0, I) on the unknown frames, q(x_T | x_0) on the known ones (Alg. 3
        lines 1-2)."""
        noise = torch.randn(self.x0.shape, generator=generator).to(self.x0.device)
        return self.merge(noise, self.noised(self.diffusion.num_steps))

    def sample(self, model, seed, steps=None, callback=None, progress=True):
        """x_0 of the chain conditioned on the known frames: x_T from :meth:`start`,
        then ``steps`` (None: the whole chain) with this hook.  One random stream
        (``seed``: an int or a torch.Generator) makes x_T and then every step's noise,
        so that no step re-draws the values x_T was made of."""
        generator = (
            seed
            if isinstance(seed, torch.Generator)
            else torch.Generator().manual_seed(seed)
        )
        return self.diffusion.run(
            model, self.start(generator), generator, steps, self, callback, progress
        )

    def merge(self, unknown, known):
        return torch.where(known_coordinates(self.known), known, unknown)

    def __call__(self, x_hat, xt, t, out):
        if self.inner is not None:
            x_hat = self.inner(x_hat, xt, t, out)
        if self.feather > 0:
            x_hat = x_hat + self.feathered_shift(out["x0"], t)
        return self.merge(x_hat, self.known_step(t, out))

    def known_step(self, t, out):
        """The known coordinates of x_{t-1}.  The ancestral chain draws them afresh
        from q(x_{t-1} | x_0) (Alg. 3 line 11, as printed).  A DDIM chain (any eta; the
        students' and the flow's too) takes its own step with x0_hat replaced by the
        known x_0:

            x_{t-1} = sqrt(abar_{t-1}) x_0 + sqrt(1 - abar_{t-1} - sigma_t^2) eps_hat
                      + sigma_t z

        (eps_hat: ``out["eps"]``), so that at eta = 0 the chain stays deterministic and
        the known frames keep the noise the model reads in them and in their
        neighbours, continuous in eta
        (a fresh draw at every step of a deterministic chain gives the known frames
        noise the unknown ones never see: keyframes on 16 Euler steps of the flow were
        met smoothly far less often; benchmarks/few_steps.py --experiment tasks)."""
        if self.diffusion.eta is None or t == 1:
            return self.noised(t - 1)
        # the chain's own DDIM mean, with x0_hat = x_0 (xt only gives the shape)
        x = self.diffusion.mean_variance_from_eps(self.x0, t, out["eps"], self.x0)
        x, sigma = x["mean"], float(self.diffusion.sigmas[t])
        if sigma > 0:
            z = torch.randn(self.x0.shape, generator=self.generator, dtype=x.dtype)
            x = x + sigma * z.to(x.device)
        return x

    def feathered_shift(self, x0_hat, t):
        """The shift of every coordinate by its known neighbours' gaps
        sqrt(abar_{t-1}) (x_0 - x0_hat) (``feather``, class docstring)."""
        return self.spread(
            float(self.diffusion.sqrt_alphas_bar[t - 1]) * (self.x0 - x0_hat)
        )

    def spread(self, step):
        """``step`` (B, F, 68, 3) of the known coordinates spread to every coordinate of
        their landmark: sum_g w(f - g) step(g) / max(1, sum_g w(f - g)) over the known
        g, w a Gaussian of sigma = ``feather`` frames (the known coordinates' own values
        are overwritten by the merge)."""
        mask = known_coordinates(self.known)
        known = mask.to(step.dtype)
        frames = torch.arange(step.shape[1], device=step.device, dtype=step.dtype)
        weights = torch.exp(
            -0.5 * ((frames[:, None] - frames[None]) / self.feather) ** 2
        )
        total = torch.einsum("fg,bgld->bfld", weights, known)
        # nothing of the unknown coordinates (x0 may hold anything there) enters
        on_known = torch.where(mask, step, torch.zeros((), dtype=step.dtype))
        shifts = torch.einsum("fg,bgld->bfld", weights, on_known)
        return shifts / total.clamp_min(1.0)


def known_coordinates(known):
    """A known mask (B, F) of frames or (B, F, 68) of landmarks as a (B, F, 68 or 1, 1)
    mask of coordinates."""
    return known[:, :, None, None] if known.ndim == 2 else known[..., None]


def mean_imputation(sequences, known):
    """Baseline: every missing frame is the mean of the sequence's known frames.

    Our reading of the paper's undefined "mean imputation" (§5.3): the per-sequence mean
    over time, the classic imputation of a missing value by the mean of the observed
    ones; it keeps the subject's anatomy (a dataset mean would not) and carries no
    motion."""
    x, m = check_fill_input(sequences, known)
    # unknown frames are zero
    mean = x.sum(1, keepdims=True) / m.sum(1)[:, None, None, None]
    return keep_known(mean, x, m)


def linear_interpolation(sequences, known):
    """Baseline: missing frames linearly interpolated between the nearest known frames;
    before the first (after the last) known frame, that frame is held constant."""
    x, m = check_fill_input(sequences, known)
    out = np.zeros_like(x)
    frames = np.arange(x.shape[1])
    for i in range(len(x)):
        k = frames[m[i]]
        flat = x[i, k].reshape(len(k), -1)
        out[i] = np.stack(
            [np.interp(frames, k, flat[:, j]) for j in range(flat.shape[1])], 1
        ).reshape(x.shape[1:])
    return out.astype(np.float32)


def keep_known(filled, given, known):
    """``filled`` (n, F, 68, 3) with its known frames replaced by the given ones,
    float32: every filler returns the known frames exactly as given."""
    return np.where(known[..., None, None], given, filled).astype(np.float32)


def check_fill_input(sequences, known):
    """(x, mask) as (n, F, 68, 3) float64 and (n, F) bool.  The unknown frames may hold
    anything (even NaN): they are set to zero here, so that nothing of them can reach a
    filler.
    """
    x = landmark_array(sequences, "the landmark sequences")
    if x.ndim == 3:
        x = x[None]
    if x.ndim != 4 or x.shape[2:] != (68, 3) or 0 in x.shape:
        raise ValueError(
            "expected landmark sequences (n, frames, 68, 3) or (frames, 68, 3), got"
            f" {np.shape(sequences)}"
        )
    m = check_known_mask(known, x.shape[1])
    m = np.broadcast_to(m, x.shape[:2]).copy() if m.ndim == 1 else m
    if m.shape != x.shape[:2]:
        raise ValueError(
            f"mask {m.shape} does not match {len(x)} sequences of {x.shape[1]} frames"
        )
    check_finite_landmarks(x[m], "the known frames")
    return np.where(m[..., None, None], x, 0.0), m
