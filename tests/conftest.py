import os

import numpy as np
import pytest

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


@pytest.fixture(scope="session")
def coma_train():
    from facelib.data import load_dataset
    return load_dataset("coma", "train")


@pytest.fixture
def rng():
    return np.random.default_rng(0)
