"""Neural networks of the book (one module per network)."""
from .classifier import LSTMClassifier, train_classifier

__all__ = ["LSTMClassifier", "train_classifier"]
