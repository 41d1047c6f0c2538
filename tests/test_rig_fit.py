"""Fitting the face world's rig to landmarks."""
import numpy as np


def test_rig_fit_recovers_a_known_face(coma_train):
    from facelib import rig_fit
    seq = coma_train.landmarks[3]
    face = coma_train.face(int(coma_train.subjects[3]))
    meshes, rmse = rig_fit.landmarks_to_meshes(seq, [face])
    assert meshes.shape == (40, coma_train.meshes(3).shape[1], 3)
    assert rmse < 0.6  # about the capture noise of the landmarks
    assert np.linalg.norm(meshes - coma_train.meshes(3), axis=-1).mean() < 0.3
