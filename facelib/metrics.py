"""Evaluation metrics (paper §5): classification accuracy and the confusion matrix."""
from __future__ import annotations

import numpy as np


def accuracy(predicted, true):
    """Fraction of sequences whose predicted class equals the true class."""
    predicted, true = np.asarray(predicted), np.asarray(true)
    if predicted.shape != true.shape:
        raise ValueError(f"predicted {predicted.shape} and true {true.shape} must have the same shape")
    return float((predicted == true).mean())


def confusion_matrix(predicted, true, num_classes):
    """Counts C[i, j] of sequences of true class i predicted as class j."""
    c = np.zeros((num_classes, num_classes), dtype=np.int64)
    np.add.at(c, (np.asarray(true), np.asarray(predicted)), 1)
    return c
