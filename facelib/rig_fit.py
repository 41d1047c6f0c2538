"""From landmarks back to a face mesh by fitting the synthetic world's AU rig (a
stand-in for the FLAME fitting that the paper compares against in footnote 1 of App. B:
470 s per sequence there).

Before the learned landmark-guided deformation of the mesh-deformation chapter, this is
how the chapters show generated landmark sequences as faces: choose the known face whose
neutral landmarks fit the sequence's neutral end best, then solve for the AU intensities
of every frame by projected Gauss-Newton on the landmark error, and evaluate the rig.
It only works for faces of our synthetic world (the rig must be known), which is exactly
the limitation that the deformation network of the mesh-deformation chapter removes.
"""

from __future__ import annotations

import numpy as np

from . import data
from .face.aus import NUM_AUS
from .face.expressions import MAX_INTENSITY

_LIMIT = MAX_INTENSITY  # the range of the data generator (expressions.apex_intensities)


def known_faces(datasets=("coma", "bu")):
    """Faces of the training subjects of ``datasets`` (the anatomies the denoisers were
    trained on)."""
    faces = []
    for name in datasets:
        train = data.load_dataset(name, "train")
        faces += [train.face(int(s)) for s in np.unique(train.subjects)]
    return faces


def closest_face(landmarks, faces):
    """The face whose neutral landmarks are closest (RMSE) to the first or the last
    frame of a sequence (F, 68, 3): one end of an N2E or E2N sequence is neutral."""
    neutral = np.stack([f.landmarks(np.zeros(NUM_AUS)) for f in faces])
    ends = np.asarray(landmarks)[[0, -1]]
    rmse = np.sqrt(((neutral[:, None] - ends[None]) ** 2).sum(-1).mean(-1)).min(1)
    return faces[int(np.argmin(rmse))]


def fit_aus(face, landmarks, iterations=10, damping=1e-3, step=1e-3):
    """AU intensities (F, NUM_AUS) whose landmarks best match ``landmarks`` (F, 68, 3)
    on ``face``: projected Gauss-Newton with a finite-difference Jacobian, intensities
    kept in the rig's range.
    """
    target = np.asarray(landmarks, dtype=np.float64)
    w = np.zeros((len(target), NUM_AUS))
    probes = step * np.eye(NUM_AUS)
    for _ in range(iterations):
        # (1 + A, F, 68, 3)
        evals = face.landmarks(np.concatenate([w[None], w[None] + probes[:, None]]))
        residual = (evals[0] - target).reshape(len(target), -1)
        jac = (
            ((evals[1:] - evals[0]) / step)
            .reshape(NUM_AUS, len(target), -1)
            .transpose(1, 2, 0)
        )
        lhs = jac.transpose(0, 2, 1) @ jac + damping * np.eye(NUM_AUS)
        delta = np.linalg.solve(lhs, -(jac.transpose(0, 2, 1) @ residual[..., None]))[
            ..., 0
        ]
        w = np.clip(w + delta, -_LIMIT, _LIMIT)
    return w


def landmarks_to_meshes(landmarks, faces=None):
    """Meshes (F, V, 3) in mm for a landmark sequence (F, 68, 3), and the landmark RMSE
    (mm) of the fit."""
    faces = faces or known_faces()
    face = closest_face(landmarks, faces)
    w = fit_aus(face, landmarks)
    rmse = float(np.sqrt(((face.landmarks(w) - landmarks) ** 2).sum(-1).mean()))
    return face.expression(w).astype(np.float32), rmse
