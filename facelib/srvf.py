"""Square-root velocity fields (SRVF) on the unit hypersphere: the representation of
Motion3DGAN (papers/motion3dgan-s2d-otberdout2022, Eq. 2, 3, 6), the GAN baseline of the
label-control chapter.

A landmark motion alpha: [0, 1] -> R^204 (F frames, dt = 1 / (F - 1)) becomes

    q(t) = alpha'(t) / sqrt(||alpha'(t)||)                                  (Eq. 2)

(q = 0 where the motion stops), with the L2 inner product <a, b> = sum_k a_k . b_k dt.
Then ||q||^2 = integral ||alpha'|| dt is the arc length of the motion: scaling q to norm
1 puts every motion on the unit hypersphere C and forgets its amplitude, which the
inverse

    alpha(t) = alpha(0) + eps * integral_0^t ||q(s)|| q(s) ds                (Eq. 3, 10)

restores with eps = the arc length (Eq. 10 of that paper sets eps by hand).  On C, a
reference point p gives a tangent space where the GAN works, through

    log_p(q) = d / sin(d) (q - cos(d) p),                                     (Eq. 6)
    exp_p(s) = cos(||s||) p + sin(||s||) s / ||s||,

d = arccos <q, p>.  exp_p maps into C only for s orthogonal to p (we project), and the
"mean SRVF" used as p is *not* on C unless renormalised (the mean of unit vectors is
shorter than 1).
"""

from __future__ import annotations

import torch

_TINY = 1e-8


def _dt(q):
    return 1.0 / q.shape[-2]  # F - 1 velocity samples on [0, 1]


def inner(a, b):
    """<a, b> = sum_k a_k . b_k dt over (..., F-1, D) fields -> (...)."""
    return (a * b).sum(dim=(-2, -1)) * _dt(a)


def norm(a):
    return inner(a, a).clamp_min(0).sqrt()


def to_srvf(motion):
    """(q, arc length) of motions (..., F, D): q (..., F-1, D) on the unit sphere
    (Eq. 2 normalised)."""
    velocity = torch.diff(motion, dim=-2) * (motion.shape[-2] - 1)
    speed = velocity.norm(dim=-1, keepdim=True)
    q = velocity / speed.clamp_min(_TINY).sqrt() * (speed > _TINY)
    length = norm(q) ** 2
    return q / norm(q).clamp_min(_TINY)[..., None, None], length


def from_srvf(q, start, length):
    """Inverse (Eq. 3 with eps = ``length``): motion (..., F, D) from q (..., F-1, D),
    alpha(0) = ``start`` (..., D) and the arc length (...)."""
    q = q / norm(q).clamp_min(_TINY)[..., None, None]
    steps = (
        q.norm(dim=-1, keepdim=True)
        * q
        * _dt(q)
        * torch.as_tensor(length)[..., None, None]
    )
    return torch.cat(
        [start[..., None, :], start[..., None, :] + torch.cumsum(steps, dim=-2)], dim=-2
    )


def log_map(q, p):
    """log_p(q): the tangent vector at p pointing to q, of length d_C(q, p) (Eq. 6)."""
    cos = inner(q, p).clamp(-1 + 1e-7, 1 - 1e-7)
    d = torch.arccos(cos)
    return (d / torch.sin(d))[..., None, None] * (q - cos[..., None, None] * p)


def exp_map(s, p):
    """exp_p(s) for a tangent vector s at p (Eq. 6); s is first projected to be
    orthogonal to p."""
    s = s - inner(s, p)[..., None, None] * p
    n = norm(s)[..., None, None]
    return torch.cos(n) * p + torch.sin(n) * s / n.clamp_min(_TINY)


def reference_point(qs):
    """The renormalised mean of SRVFs (n, F-1, D): a point of the sphere (the plain mean
    is not)."""
    mean = qs.mean(0)
    return mean / norm(mean)
