"""Neural networks of the book (one module per network)."""
from .classifier import LSTMClassifier, train_classifier
from .denoiser import Denoiser, DenoiserConfig

__all__ = ["LSTMClassifier", "train_classifier", "Denoiser", "DenoiserConfig"]
