"""A noisy AU-intensity regressor R(x_t, t): the action-unit curves a noisy sequence is
heading for.

Not in the paper (the fine-control chapter).  AUBlendNet controls single meshes by
action units; here a BiT reads x_t = q_sample(x_0, t) and returns, for every frame, the
intensities (F, NUM_AUS) of the action units that made x_0 (the synthetic world knows
them: ``FaceDataset.au_weights``).  Guidance climbs log N(c | R(x, t), tau^2) for
requested curves c (guidance.AUCurveScore), as Alg. 1 climbs log p_phi(y | x, t).

Like the guidance classifier it reads *motion* (the frames minus their mean frame), so
that it does not need to know the face; the intensity of a frame is read relative to the
rest of the sequence. Unlike it, every frame token has an output (no classification
token).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from torch import nn

from ..face.aus import NUM_AUS
from .bit import BiT, check_sequence_input
from .noisy_classifier import motion_input


@dataclass(frozen=True)
class AURegressorConfig:
    """Sizes of the AU regressor (our choice: the guidance classifier's)."""

    num_aus: int = NUM_AUS
    num_landmarks: int = 68
    width: int = 128
    depth: int = 3
    heads: int = 4
    ff: int = 256
    dropout: float = 0.1


class AURegressor(BiT):
    """R(x_t, t): (B, F, 68, 3) normalised landmarks, (B,) steps -> (B, F, num_aus) AU
    intensities."""

    def __init__(self, config=AURegressorConfig()):
        c = config
        super().__init__(c.num_landmarks, c.width, c.depth, c.heads, c.ff, c.dropout)
        self.config = config
        self.head = nn.Linear(c.width, c.num_aus)

    def forward(self, xt, t, mask=None):
        """Per-frame AU intensities (B, F, num_aus) of x_t (B, F, 68, 3)
        at steps t (B,); ``mask`` (B, F) bool marks the valid frames (the outputs of
        padding frames are meaningless)."""
        check_sequence_input(xt, t, mask, self.config.num_landmarks)
        return self.head(self.encode(motion_input(xt, mask), t, mask))

    def config_dict(self):
        return asdict(self.config)
