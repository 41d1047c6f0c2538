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


@pytest.fixture(scope="session")
def coma_test():
    from facelib.data import load_dataset
    return load_dataset("coma", "test")


@pytest.fixture(scope="session")
def denoiser():
    """The shipped denoiser of the CoMA-like data."""
    from facelib import tasks
    return tasks.load_denoiser("denoiser_coma")


@pytest.fixture(scope="session")
def merged_denoiser():
    """The shipped denoiser of the merged 18-action data of text control."""
    from facelib import tasks
    return tasks.load_denoiser("denoiser_coma+bu")


@pytest.fixture(scope="session")
def text_head():
    from facelib import tasks
    return tasks.load_text_head()


@pytest.fixture(scope="session")
def description_table():
    """E of every training description of the merged data (labels, 2, K, D)."""
    from facelib import data, text
    return text.description_embeddings(data.load_dataset("coma+bu", "train"), text.get_encoder())


@pytest.fixture(scope="module")
def small_classifier():
    """A tiny noisy classifier (3 classes) and a 100-step diffusion."""
    import torch

    from facelib.diffusion import GaussianDiffusion, linear_betas
    from facelib.models.noisy_classifier import NoisyClassifier, NoisyClassifierConfig
    torch.manual_seed(0)
    clf = NoisyClassifier(NoisyClassifierConfig(num_classes=3, width=32, depth=1, heads=2, ff=32, dropout=0.0)).eval()
    return clf, GaussianDiffusion(linear_betas(100))


@pytest.fixture(scope="session")
def face_obj(tmp_path_factory):
    """An OBJ of the neutral face of identity seed 31 (template topology), as `python -m facelib neutral` writes it."""
    from facelib import meshio
    from facelib.face import Face, sample_identity
    path = tmp_path_factory.mktemp("mesh") / "face.obj"
    meshio.write_obj(path, Face(sample_identity(31)).neutral)
    return path
