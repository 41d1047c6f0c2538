"""The "CoMA" baseline of Table 5 (paper §6, after Ranjan et al. [73]; the
mesh-deformation chapter).

CoMA's mesh autoencoder uses Chebyshev spectral convolutions (order K = 6) with mesh
pooling.  As in §6 its decoder, which originally decodes the latent code of the input
mesh, consumes the concatenation of that code with Delta L_f.  A Chebyshev layer on a
mesh with scaled Laplacian L~ = 2 L / lambda_max - I, with the symmetric normalised
Laplacian L = I - D^-1/2 A D^-1/2 and lambda_max taken as 2 (so L~ = -D^-1/2 A D^-1/2),
is

    y = sum_{k<K} T_k(L~) x Theta_k,
    T_0 x = x,  T_1 x = L~ x,  T_k x = 2 L~ T_{k-1} x - T_{k-2} x,

a polynomial filter of the graph: vertex v sees its (K-1)-ring, weighted by the graph,
not by position in a spiral.  Pooling and unpooling are the template's levels
(models/spiral.py). Same interface as the Deformer: (neutral (B, V, 3), Delta L (B, F,
68, 3)) -> Delta M (B, F, V, 3), mm.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache

import numpy as np
import torch
from torch import nn

from ..face import template as tpl
from . import spiral


@lru_cache(maxsize=None)
def scaled_laplacian(level):
    """L~ = -D^-1/2 A D^-1/2 of a resolution level of the template, as a sparse (V, V)
    tensor."""
    lv = tpl.get_template().levels[level]
    ring = spiral.neighbours(lv.faces, len(lv.vertex_index))
    rows = np.concatenate([[v] * len(r) for v, r in enumerate(ring)])
    cols = np.concatenate([sorted(r) for r in ring])
    degree = np.array([len(r) for r in ring], dtype=np.float64)
    values = -1.0 / np.sqrt(degree[rows] * degree[cols])
    return torch.sparse_coo_tensor(
        np.stack([rows, cols]),
        values.astype(np.float32),
        (len(ring), len(ring)),
        check_invariants=True,
    ).coalesce()


class ChebConv(nn.Module):
    """One Chebyshev convolution of order K on a template level: (B, V, C_in) -> (B, V,
    C_out)."""

    def __init__(self, in_channels, out_channels, level, order=6):
        super().__init__()
        self.level, self.order = level, order
        self.layer = nn.Linear(order * in_channels, out_channels)
        # a buffer, not the cached tensor, so that it moves with the layer (not in the
        # state_dict: the template's)
        self.register_buffer("laplacian", scaled_laplacian(level), persistent=False)

    def forward(self, x):
        b, v, c = x.shape
        lap = self.laplacian
        # vertex-major: one sparse product per term
        terms = [x.transpose(0, 1).reshape(v, b * c)]
        for k in range(1, self.order):
            nxt = torch.sparse.mm(lap, terms[-1])
            terms.append(nxt if k == 1 else 2 * nxt - terms[-2])
        h = torch.stack(terms, -1).reshape(v, b, c * self.order).transpose(0, 1)
        return self.layer(h)


@dataclass(frozen=True)
class ComaDeformerConfig:
    channels: tuple = (16, 16, 16, 32)  # CoMA's encoder filters
    order: int = 6  # CoMA's K
    latent: int = 8  # CoMA's latent size
    num_landmarks: int = 68
    scale: float = 10.0  # mm per network unit, as the Deformer

    def __post_init__(self):
        object.__setattr__(self, "channels", tuple(self.channels))  # JSON gives a list


class ComaDeformer(nn.Module):
    """Encoder: Chebyshev layer + pooling per level, a linear layer to the code of M.
    Decoder: a linear layer from [code, Delta L_f] to the coarsest level, then Chebyshev
    layers with unpooling up to the full mesh, and a last Chebyshev layer to 3
    channels."""

    def __init__(self, config=ComaDeformerConfig()):
        super().__init__()
        c = self.config = config
        if len(c.channels) != tpl.NUM_LEVELS:
            raise ValueError(
                f"give one channel count per template level ({tpl.NUM_LEVELS}), got"
                f" {c.channels}"
            )
        levels = tpl.get_template().levels
        self.num_coarse = len(levels[-1].vertex_index)
        ins = (3,) + tuple(c.channels[:-1])
        self.encoder = nn.ModuleList(
            ChebConv(i, o, k, c.order) for k, (i, o) in enumerate(zip(ins, c.channels))
        )
        self.to_code = nn.Linear(self.num_coarse * c.channels[-1], c.latent)
        self.from_z = nn.Linear(
            c.latent + 3 * c.num_landmarks, self.num_coarse * c.channels[-1]
        )
        outs = tuple(reversed(c.channels[:-1]))
        # no weights
        self.pools = nn.ModuleList(spiral.Pool(k) for k in range(len(self.encoder) - 1))
        self.decoder = nn.ModuleList(
            ChebConv(i, o, k, c.order)
            for k, i, o in zip(
                range(tpl.NUM_LEVELS - 1, 0, -1), reversed(c.channels), outs
            )
        )
        self.last = ChebConv(c.channels[0], 3, 0, c.order)
        self.register_buffer(
            "template",
            torch.tensor(tpl.get_template().vertices, dtype=torch.float32),
            persistent=False,
        )

    def encode(self, neutral):
        h = (neutral - self.template) / self.config.scale
        for k, layer in enumerate(self.encoder):
            h = torch.nn.functional.elu(layer(h))
            if k < len(self.encoder) - 1:
                h = self.pools[k](h)
        return self.to_code(h.flatten(1))

    def forward(self, neutral, delta):
        b, f = delta.shape[:2]
        code = self.encode(neutral)[:, None].expand(-1, f, -1)
        h = self.from_z(
            torch.cat([code, delta.flatten(2) / self.config.scale], -1)
        ).reshape(b * f, self.num_coarse, -1)
        for layer in self.decoder:
            h = spiral.unpool(torch.nn.functional.elu(layer(h)), layer.level - 1)
        return self.last(h).reshape(b, f, -1, 3) * self.config.scale


def config_dict(model):
    return asdict(model.config)


def build(config):
    return ComaDeformer(ComaDeformerConfig(**config))
