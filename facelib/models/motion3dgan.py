"""Motion3DGAN-style baseline (papers/motion3dgan-s2d-otberdout2022, §3.2, Eq. 2-7): a
label-conditioned WGAN-GP that generates the SRVF of a landmark motion on the unit
hypersphere.

* Each training motion is turned into its unit-norm SRVF q (facelib/srvf.py, Eq. 2); E2N
  motions are first reversed in time, so every motion starts near the neutral face, as
  in that paper.
* The GAN works in the tangent space at p, the *renormalised* mean SRVF (Eq. 6): the
  generator G(z, c) outputs a tangent vector (projected orthogonal to p), q_fake =
  exp_p(G); the critic D(log_p(q), c) is trained with the Wasserstein loss and gradient
  penalty (Eq. 4-5, lambda = 10); the generator adds alpha_2 L_r, the L1 distance
  between log_p(q_fake) and log_p(q) of a random real motion of the same class (Eq. 7;
  the pairing is not specified in the paper).
* Decoding (Eq. 3, 10): alpha(0) = the neutral landmarks of a training face, eps = the
  class's mean arc length; a motion is reversed back to E2N with the class's E2N
  frequency.

Architecture (not given in the paper, which points to MotionGAN): 1-D convolutions over
time, small enough to ship (our choice).  Adam lr 1e-4, alpha_1 = 1, alpha_2 = 10
(paper); n_critic = 5, betas (0.5, 0.9) (WGAN-GP defaults).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from .. import srvf


@dataclass(frozen=True)
class Motion3DGANConfig:
    num_classes: int
    num_frames: int = 40
    num_landmarks: int = 68
    noise_dim: int = 128  # paper: 128-d noise
    channels: int = 64  # our choice: a few minutes of CPU training


class Generator(nn.Module):
    """G(z, c): noise + one-hot label -> tangent vector (B, F-1, 204), in units of
    ``tangent_scale``."""

    def __init__(self, c):
        super().__init__()
        self.c = c
        self.seed_frames = (c.num_frames - 1 + 3) // 4
        self.fc = nn.Linear(c.noise_dim + c.num_classes, c.channels * self.seed_frames)
        self.body = nn.Sequential(
            nn.LeakyReLU(0.2),
            nn.Upsample(scale_factor=2),
            nn.Conv1d(c.channels, c.channels, 5, padding=2),
            nn.LeakyReLU(0.2),
            nn.Upsample(size=c.num_frames - 1),
            nn.Conv1d(c.channels, c.channels, 5, padding=2),
            nn.LeakyReLU(0.2),
            nn.Conv1d(c.channels, c.num_landmarks * 3, 5, padding=2),
        )

    def forward(self, z, onehot):
        h = self.fc(torch.cat([z, onehot], 1)).reshape(
            len(z), self.c.channels, self.seed_frames
        )
        return self.body(h).transpose(1, 2)


class Critic(nn.Module):
    """D(log_p(q), c): tangent vector (B, F-1, 204) + one-hot label -> a score (B,)."""

    def __init__(self, c):
        super().__init__()
        self.body = nn.Sequential(
            nn.Conv1d(
                c.num_landmarks * 3 + c.num_classes, c.channels, 5, stride=2, padding=2
            ),
            nn.LeakyReLU(0.2),
            nn.Conv1d(c.channels, c.channels, 5, stride=2, padding=2),
            nn.LeakyReLU(0.2),
            nn.Conv1d(c.channels, c.channels, 5, stride=2, padding=2),
            nn.LeakyReLU(0.2),
            nn.AdaptiveAvgPool1d(1),
            nn.Flatten(),
            nn.Linear(c.channels, 1),
        )

    def forward(self, u, onehot):
        h = torch.cat(
            [u.transpose(1, 2), onehot[:, :, None].expand(-1, -1, u.shape[1])], 1
        )
        return self.body(h)[:, 0]


class Motion3DGAN(nn.Module):
    """The generator with everything needed to decode: p, the tangent scale, per-class
    arc lengths and E2N frequencies, and the neutral faces of the training subjects."""

    def __init__(self, config, num_neutrals=1):
        super().__init__()
        c = self.config = config
        self.generator = Generator(c)
        d = c.num_landmarks * 3
        # p, on the sphere
        self.register_buffer("reference", torch.zeros(c.num_frames - 1, d))
        self.register_buffer("tangent_scale", torch.ones(()))
        # mm, mean per class
        self.register_buffer("arc_length", torch.ones(c.num_classes))
        self.register_buffer("e2n_fraction", torch.zeros(c.num_classes))
        self.register_buffer("neutrals", torch.zeros(num_neutrals, c.num_landmarks, 3))

    def tangent(self, z, onehot):
        """G's tangent vector at p (B, F-1, 204), projected orthogonal to p."""
        s = self.generator(z, onehot) * self.tangent_scale
        return s - srvf.inner(s, self.reference)[:, None, None] * self.reference

    @torch.no_grad()
    def sample(self, labels, seed=0):
        """Landmark sequences (n, F, 68, 3) in mm, a tensor where the model is, for
        class indices ``labels`` (n,). The draws are made on the CPU, so that a seed
        gives the same sequences on every device.
        """
        gen = torch.Generator().manual_seed(seed)
        n, c, device = len(labels), self.config, self.reference.device
        labels = torch.as_tensor(np.asarray(labels), dtype=torch.long, device=device)
        z = torch.randn(n, c.noise_dim, generator=gen).to(self.reference)
        onehot = nn.functional.one_hot(labels, c.num_classes).to(self.reference.dtype)
        q = srvf.exp_map(self.tangent(z, onehot), self.reference)
        start = self.neutrals[
            torch.randint(0, len(self.neutrals), (n,), generator=gen).to(device)
        ].flatten(1)
        motion = srvf.from_srvf(q, start, self.arc_length[labels]).reshape(
            n, c.num_frames, c.num_landmarks, 3
        )
        reverse = torch.rand(n, generator=gen).to(device) < self.e2n_fraction[labels]
        motion[reverse] = motion[reverse].flip(1)
        return motion

    def generate(self, labels, seed=0):
        """Landmark sequences (n, F, 68, 3) float32 in mm (numpy) for class indices
        ``labels`` (n,)."""
        return self.sample(labels, seed).cpu().numpy().astype(np.float32)


def smooth_in_time(motion, sigma):
    """Gaussian smoothing (sigma in frames, edges replicated) of motions (n, F, d) along
    F."""
    if sigma <= 0:
        return motion
    r = max(1, int(3 * sigma))
    kernel = torch.exp(
        -0.5
        * (torch.arange(-r, r + 1, dtype=motion.dtype, device=motion.device) / sigma)
        ** 2
    )
    x = nn.functional.pad(motion.transpose(1, 2), (r, r), mode="replicate")
    n, d, f = x.shape
    out = nn.functional.conv1d(
        x.reshape(n * d, 1, f), (kernel / kernel.sum())[None, None]
    )
    return out.reshape(n, d, -1).transpose(1, 2)


def prepare(train, smoothing=0.0):
    """Unit SRVFs (n, F-1, 204) of the training motions (E2N reversed), arc lengths (n,)
    in mm.

    The SRVF differentiates the motion, so capture noise dominates it: on the CoMA-like
    data the arc length of the raw landmark paths is about 3 times that of the same
    paths smoothed with sigma = 1 frame.  A generator of smooth SRVFs decoded with the
    noisy arc lengths would exaggerate every expression; hence ``smoothing`` (the
    Motion3DGAN paper works on cleaner data).
    """
    motion = torch.as_tensor(train.landmarks).flatten(2).double()
    e2n = torch.as_tensor(train.kinds == train.kind_names.index("E2N"))
    motion = torch.where(e2n[:, None, None], motion.flip(1), motion)
    return srvf.to_srvf(smooth_in_time(motion, smoothing))


def config_dict(model):
    return asdict(model.config) | {"num_neutrals": len(model.neutrals)}


def build(config):
    """Rebuild a Motion3DGAN from a checkpoint config (see :func:`config_dict`)."""
    c = dict(config)
    num_neutrals = c.pop("num_neutrals")
    return Motion3DGAN(Motion3DGANConfig(**c), num_neutrals)
