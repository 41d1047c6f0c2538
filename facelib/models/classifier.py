"""The independent classifier (IC) of the paper's evaluation (§5): one LSTM layer + a
linear layer.

The IC reads a landmark sequence (B, F, 68, 3) in mm and predicts its label.  By default
it looks at *motion*: each sequence minus its own mean shape over the frames.  Our
choice, and a measured one (the face-world chapter): with only 9 training subjects, an
LSTM on raw coordinates memorises the anatomy of those subjects and fails on new ones;
removing the sequence's mean shape keeps everything about the expression (including N2E
vs E2N order) and drops the anatomy. ``inputs="absolute"`` gives the raw-coordinate
variant for comparison.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

INPUTS = ("motion", "absolute")


ARCHITECTURES = ("lstm", "cnn")


class SequenceClassifier(nn.Module):
    """A classifier of landmark sequences (B, F, 68, 3) in mm: inputs standardised from
    the training data (``fit_normalization``), ``features`` of a subclass, a linear
    layer to the class logits."""

    def __init__(self, num_landmarks, inputs):
        super().__init__()
        if inputs not in INPUTS:
            raise ValueError(f"inputs must be one of {INPUTS}, got {inputs!r}")
        self.inputs, self.num_landmarks = inputs, num_landmarks
        # Input standardisation, set from the training data by ``fit_normalization``.
        self.register_buffer("offset", torch.zeros(num_landmarks * 3))
        self.register_buffer("scale", torch.ones(()))

    def _prepare(self, x):
        if x.ndim != 4 or x.shape[-2:] != (self.num_landmarks, 3):
            raise ValueError(
                "expected landmark sequences "
                f"(B, F, {self.num_landmarks}, 3), got {tuple(x.shape)}"
            )
        x = x.flatten(2)
        if self.inputs == "motion":
            x = x - x.mean(dim=1, keepdim=True)
        return (x - self.offset) / self.scale

    @torch.no_grad()
    def fit_normalization(self, x):
        """Set the input offset and scale from training sequences (B, F, 68, 3)."""
        self.offset.zero_()
        self.scale.fill_(1.0)
        z = self._prepare(
            torch.as_tensor(x, dtype=self.offset.dtype, device=self.offset.device)
        )
        self.offset.copy_(z.mean(dim=(0, 1)))
        self.scale.fill_(float((z - self.offset).std()))

    def forward(self, x):
        """Class logits (B, num_classes): the output of the linear layer."""
        return self.linear(self.features(x))

    @torch.no_grad()
    def predict(self, x, batch_size=256):
        """Predicted classes (n,) (numpy) for sequences given as a numpy array or tensor
        (n, F, 68, 3)."""
        self.eval()
        x = torch.as_tensor(
            x if isinstance(x, torch.Tensor) else np.asarray(x),
            dtype=self.offset.dtype,
            device=self.offset.device,
        )
        predicted = [
            self.forward(x[i : i + batch_size]).argmax(1)
            for i in range(0, len(x), batch_size)
        ]
        return torch.cat(predicted).cpu().numpy()


class LSTMClassifier(SequenceClassifier):
    """One LSTM layer over frames + a linear layer on its last hidden state (paper §5,
    as in [62])."""

    def __init__(self, num_classes, hidden=128, num_landmarks=68, inputs="motion"):
        super().__init__(num_landmarks, inputs)
        self.lstm = nn.LSTM(num_landmarks * 3, hidden, batch_first=True)
        self.linear = nn.Linear(hidden, num_classes)

    def features(self, x):
        """Last hidden state of the LSTM (B, hidden)."""
        _, (h, _) = self.lstm(self._prepare(x))
        return h[-1]


class TemporalCNNClassifier(SequenceClassifier):
    """A second reader of another architecture (issue 58): three 1-D convolutions over
    frames (kernel 5, dilations 1, 2, 4: about 25 frames seen at once), then the mean
    and the maximum over frames and a linear layer.  It reads the whole motion at once
    where the LSTM reads it in order, so a skew in the label mix that one misses the
    other may see."""

    def __init__(self, num_classes, channels=128, num_landmarks=68, inputs="motion"):
        super().__init__(num_landmarks, inputs)
        layers, width = [], num_landmarks * 3
        for dilation in (1, 2, 4):
            layers += [
                nn.Conv1d(width, channels, 5, padding=2 * dilation, dilation=dilation),
                nn.GELU(),
            ]
            width = channels
        self.convolutions = nn.Sequential(*layers)
        self.linear = nn.Linear(2 * channels, num_classes)

    def features(self, x):
        """The mean and maximum over frames of the last convolution (B, 2 channels)."""
        h = self.convolutions(self._prepare(x).transpose(1, 2))
        return torch.cat([h.mean(dim=2), h.amax(dim=2)], dim=1)


def classifier_from_config(config):
    """The classifier a checkpoint's config describes: "architecture" "cnn" (its
    "channels"), else the IC's LSTM (checkpoints from before the second reader record
    no architecture)."""
    config = dict(config)
    architecture = config.pop("architecture", "lstm")
    if architecture not in ARCHITECTURES:
        raise ValueError(
            f"unknown classifier architecture {architecture!r}; allowed:"
            f" {', '.join(ARCHITECTURES)}"
        )
    return (TemporalCNNClassifier if architecture == "cnn" else LSTMClassifier)(
        **config
    )
