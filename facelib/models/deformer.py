"""Landmark-guided mesh deformation (paper §3.3, Eq. 11, Fig. 1; the mesh-deformation
chapter).

Given a neutral mesh M (V, 3) of the template topology and one frame's landmark
displacement Delta L_f = L_f - L (68, 3), predict the per-vertex displacement Delta M_f;
M_f = M + Delta M_f.

* Encoder: five spiral layers on M (models/spiral.py), pooling to the next resolution
  level of the template after each of the first three, giving mesh features F_e (80
  vertices x d).
* Cross-attention (Eq. 11): softmax(FC(Delta L_f) F_e^T / sqrt(d)) F_e, one query per
  frame: which parts of *this* face matter for *this* motion.  A linear layer maps it to
  z_id (204 values).
* z = lambda_theta z_id + Delta L_f, lambda_theta learnable.  Its initial value is not
  in the paper; we start at 1, since at 0 the encoder receives no gradient (dz/dz_id =
  lambda_theta) and the network stays S2D (the mesh-deformation chapter, exercise 1).
* Decoder (S2D's): a linear layer to 80 x d, then five spiral layers with unpooling
  between levels, giving Delta M_f (V, 3).

``attention=False`` gives "ours without attention" (F_e averaged over vertices instead
of attended); ``identity=False`` gives S2D (decoder only, z = Delta L_f).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from ..face import template as tpl
from . import spiral


@dataclass(frozen=True)
class DeformerConfig:
    # our choice: the five encoder spiral layers (decoder mirrors them)
    channels: tuple = (16, 32, 32, 64, 64)
    spiral_length: int = 9  # SpiralNet++'s default on meshes of this density
    num_landmarks: int = 68
    attention: bool = True
    identity: bool = True
    scale: float = 10.0  # mm per network unit (our choice: displacements are a few mm)
    # lambda_theta at initialisation (not in the paper; at 0 the encoder gets no
    # gradient)
    identity_init: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "channels", tuple(self.channels))  # JSON gives a list


def _levels_of_layers():
    """Resolution level of each of the five encoder layers: 0, 1, 2, 3, 3."""
    return (0, 1, 2, 3, 3)


class Deformer(nn.Module):
    """(neutral (B, V, 3) mm, Delta L (B, F, 68, 3) mm) -> Delta M (B, F, V, 3) mm."""

    def __init__(self, config=DeformerConfig()):
        super().__init__()
        c = self.config = config
        if len(c.channels) != 5:
            raise ValueError(
                "the encoder has five spiral layers: give five channel counts, got"
                f" {c.channels}"
            )
        levels = _levels_of_layers()
        d = c.channels[-1]
        self.num_coarse = len(tpl.get_template().levels[3].vertex_index)
        if c.identity:  # S2D (identity=False) has no encoder: it reads Delta L only
            ins = (3,) + tuple(c.channels[:-1])
            self.encoder = nn.ModuleList(
                spiral.SpiralConv(i, o, spiral.template_spirals(lv, c.spiral_length))
                for i, o, lv in zip(ins, c.channels, levels)
            )
            # no weights: no state_dict entry
            self.pools = nn.ModuleList(spiral.Pool(lv) for lv in levels[:3])
            if c.attention:
                self.query = nn.Linear(c.num_landmarks * 3, d)
            self.to_z_id = nn.Linear(d, c.num_landmarks * 3)
            # lambda_theta
            self.identity_weight = nn.Parameter(torch.tensor(float(c.identity_init)))
        self.from_z = nn.Linear(c.num_landmarks * 3, self.num_coarse * d)
        outs = tuple(reversed(c.channels[:-1])) + (3,)
        self.decoder = nn.ModuleList(
            spiral.SpiralConv(i, o, spiral.template_spirals(lv, c.spiral_length))
            for i, o, lv in zip(reversed(c.channels), outs, reversed(levels))
        )
        self.register_buffer(
            "template",
            torch.tensor(tpl.get_template().vertices, dtype=torch.float32),
            persistent=False,
        )

    def encode(self, neutral):
        """Mesh features F_e (B, 80, d) of neutral meshes (B, V, 3) in mm."""
        h = (neutral - self.template) / self.config.scale
        for k, layer in enumerate(self.encoder):
            h = torch.nn.functional.elu(layer(h))
            if k < 3:
                h = self.pools[k](h)
        return h

    def attend(self, features, delta):
        """Eq. 11: softmax(FC(Delta L) F_e^T / sqrt(d)) F_e, (B, F, d),
        and the weights (B, F, 80)."""
        q = self.query(delta.flatten(2))  # (B, F, d)
        weights = torch.softmax(
            q @ features.transpose(1, 2) / features.shape[-1] ** 0.5, dim=-1
        )
        return weights @ features, weights

    def latent(self, neutral, delta):
        """z = lambda_theta z_id + Delta L (B, F, 204), in network units."""
        delta = delta / self.config.scale
        if not self.config.identity:
            return delta.flatten(2)
        features = self.encode(neutral)
        if self.config.attention:
            attended, _ = self.attend(features, delta)
        else:
            attended = features.mean(1, keepdim=True).expand(-1, delta.shape[1], -1)
        return self.identity_weight * self.to_z_id(attended) + delta.flatten(2)

    def forward(self, neutral, delta):
        b, f = delta.shape[:2]
        h = self.from_z(self.latent(neutral, delta)).reshape(b * f, self.num_coarse, -1)
        levels = tuple(reversed(_levels_of_layers()))
        for k, layer in enumerate(self.decoder):
            h = layer(h)
            if k < len(self.decoder) - 1:
                h = torch.nn.functional.elu(h)
            if levels[k] != levels[min(k + 1, 4)]:
                h = spiral.unpool(h, levels[k + 1])
        return h.reshape(b, f, -1, 3) * self.config.scale


def landmark_weights(vertices, landmark_index, epsilon=1.0):
    """S2D's per-vertex loss weights (their Eq. 1):
    w_i = 1 / max(min_j ||p_i - Z_j||, epsilon), divided by the largest weight.
    Min-max rescaling ("re-scaled to [0, 1]") would give the farthest vertex weight 0,
    i.e. no supervision; dividing by the maximum keeps every vertex in the loss."""
    v = np.asarray(vertices, dtype=np.float64)
    d = np.linalg.norm(v[:, None] - v[np.asarray(landmark_index)][None], axis=-1).min(1)
    w = 1.0 / np.maximum(d, epsilon)
    return (w / w.max()).astype(np.float32)


def deformation_loss(predicted, target, weights, displacement_weight=0.1):
    """S2D's weighted L1 on the deformed vertices plus 0.1 x the plain L1 of the
    displacement (predicted, target: Delta M (B, F, V, 3); weights (V,))."""
    l1 = (predicted - target).abs().sum(-1)  # (B, F, V)
    return (l1 * weights).mean() + displacement_weight * l1.mean()


def config_dict(model):
    return asdict(model.config)


def build(config):
    return Deformer(DeformerConfig(**config))
