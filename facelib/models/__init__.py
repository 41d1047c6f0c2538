"""Neural networks of the book (one module per network)."""

from .bit import BiT
from .classifier import LSTMClassifier
from .denoiser import Denoiser, DenoiserConfig
from .noisy_classifier import NoisyClassifier, NoisyClassifierConfig

__all__ = [
    "BiT",
    "LSTMClassifier",
    "Denoiser",
    "DenoiserConfig",
    "NoisyClassifier",
    "NoisyClassifierConfig",
]
