"""Measurements that check the synthetic world has the properties the paper's methods need."""
from __future__ import annotations

import numpy as np

from .aus import AU_NAMES, Face, au_vector
from .identity import sample_identity


def identity_dependence(au, num_pairs=50, intensity=1.0, seed=0):
    """Relative difference of one AU's landmark displacement on random identity pairs.

    For each pair (a, b) of random identities, with d = L(w) - L(0) the landmark displacement of
    the AU at ``intensity``: ||d_a - d_b|| / (0.5 (||d_a|| + ||d_b||)).  Returns (num_pairs,).
    Zero would mean that the AU moves every face the same way (a generic, "universal" rig).
    """
    if au not in AU_NAMES:
        raise ValueError(f"unknown action unit {au!r}; allowed: {', '.join(AU_NAMES)}")
    rng = np.random.default_rng(seed)
    w = au_vector(**{au: intensity})
    out = np.empty(num_pairs)
    for k in range(num_pairs):
        d = []
        for _ in range(2):
            face = Face(sample_identity(rng))
            d.append(face.landmarks(w) - face.landmarks(np.zeros_like(w)))
        out[k] = np.linalg.norm(d[0] - d[1]) / (0.5 * (np.linalg.norm(d[0]) + np.linalg.norm(d[1])))
    return out


def identity_and_expression_spread(dataset):
    """(identity std, expression std) in mm of a dataset's landmarks.

    identity std: RMS over landmark coordinates of the std over subjects of the neutral
    landmarks L.  expression std: RMS of L_f - L over all frames of all sequences (the motion
    the expressions add to each subject's own neutral face).
    """
    subjects = np.unique(dataset.subjects)
    neutral = {s: dataset.neutral_landmarks(int(s)) for s in subjects}
    identity = np.sqrt(np.stack(list(neutral.values())).var(axis=0).mean())
    motion = []
    for i in range(len(dataset)):
        f = dataset.lengths[i]
        motion.append((dataset.landmarks[i, :f] - neutral[dataset.subjects[i]]).reshape(-1))
    expression = np.sqrt(np.mean(np.concatenate(motion) ** 2))
    return float(identity), float(expression)
