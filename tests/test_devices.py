"""Device-correct by construction (issue 42): every network of facelib/models moves with ``module.to(device)``.

There is no GPU here, so three checks stand in for one:

* structural: every tensor a module holds is a parameter or a registered buffer (a tensor kept as a plain
  attribute, or inside a list/tuple/dict attribute, stays on the CPU when the module moves; so does a
  module kept in a plain list);
* a simulated device move: the parameters and buffers become *fake* tensors on another device (torch's
  FakeTensor: shapes, dtypes and devices, no data) and each network runs on fake inputs there, so that a tensor
  left on the CPU (a cached CPU index, ``torch.arange(n)`` without ``device=``) raises the device mismatch a
  GPU would;
* a float64 pass (``model.double()``, float64 inputs) of the same calls, generation included: a tensor that did
  not follow the module's dtype raises a dtype mismatch.

The networks are built in their smallest configurations; a test fails if a network class of facelib/models
is built by none of them, or a shipped checkpoint kind is not covered; every shipped checkpoint must still load
strictly (the buffers added for devices are not persistent).
"""
import copy
import dataclasses
import importlib
import inspect
import json
import pkgutil
import unittest.mock

import numpy as np
import pytest
import torch
from torch import nn

import facelib.models
from facelib import checkpoints, config, deformation
from facelib.diffusion import TimeMapped
from facelib.face import template as tpl
from facelib.models import (actor, au_regressor, classifier, coma, deformer, denoiser, linear_deformer, lstm_filler,
                            motion3dgan, motionclip, noisy_classifier)

B, F, L = 2, 6, 68  # batch, frames, landmarks
SMALL = dict(width=16, depth=1, heads=2, ff=32)


# ------------------------------------------------------------------------ the networks and one call of each
def _sequence_call(model, make):
    xt, t = make(torch.randn(B, F, L, 3)), make(torch.tensor([3.0, 7.0]))
    mask = make(torch.tensor([[True] * F, [True] * (F - 2) + [False] * 2]))
    return model(xt, t, mask)  # a label-conditional denoiser: every sequence gets the "no label" token


def _mesh_call(model, make):
    v = len(tpl.get_template().vertices)
    return model(make(torch.randn(B, v, 3)), make(torch.randn(B, 3, L, 3)))


def _actor_call(model, make):
    delta, labels = make(torch.randn(B, F, L, 3)), make(torch.tensor([0, 2]))
    mu, logvar = model.encode(delta, labels)
    return model.decode(mu + logvar.exp(), labels, F)


def _gan_call(model, make):
    onehot = make(torch.eye(3)[[0, 2]])
    return model.tangent(make(torch.randn(B, model.config.noise_dim)), onehot)


def _critic_call(model, make):
    return model(make(torch.randn(B, 7, L * 3)), make(torch.eye(3)[[0, 2]]))


def _filler_call(model, make):
    known = make(torch.tensor([[True, False, True, True, False, True]] * B))
    return model(make(torch.randn(B, F, L, 3)), known)


def _gan_config():
    return motion3dgan.Motion3DGANConfig(num_classes=3, num_frames=8, noise_dim=4, channels=4)


MODELS = {  # name: (build, call(model, make) with ``make`` putting a CPU tensor where the model is)
    "denoiser": (lambda: denoiser.Denoiser(denoiser.DenoiserConfig(**SMALL, num_diffusion_steps=10)), _sequence_call),
    "denoiser_cfg": (lambda: denoiser.Denoiser(denoiser.DenoiserConfig(**SMALL, num_diffusion_steps=10, num_classes=3)),
                     _sequence_call),
    "guide": (lambda: noisy_classifier.NoisyClassifier(noisy_classifier.NoisyClassifierConfig(3, **SMALL)),
              _sequence_call),
    "text_head": (lambda: noisy_classifier.NoisyTextHead(noisy_classifier.TextHeadConfig(embedding_dim=8, **SMALL)),
                  _sequence_call),
    "au_regressor": (lambda: au_regressor.AURegressor(au_regressor.AURegressorConfig(**SMALL)), _sequence_call),
    "evaluator": (lambda: classifier.LSTMClassifier(3, hidden=8), lambda m, make: m(make(torch.randn(B, F, L, 3)))),
    "evaluator_cnn": (lambda: classifier.TemporalCNNClassifier(3, channels=8),
                      lambda m, make: m(make(torch.randn(B, F, L, 3)))),
    "deformer_ours": (lambda: deformer.Deformer(deformer.DeformerConfig(channels=(4,) * 5)), _mesh_call),
    "deformer_no_attention": (lambda: deformer.Deformer(deformer.DeformerConfig(channels=(4,) * 5, attention=False)),
                              _mesh_call),
    "deformer_s2d": (lambda: deformer.Deformer(deformer.DeformerConfig(channels=(4,) * 5, identity=False)),
                     _mesh_call),
    "deformer_coma": (lambda: coma.ComaDeformer(coma.ComaDeformerConfig(channels=(4,) * tpl.NUM_LEVELS, order=3,
                                                                         latent=4)), _mesh_call),
    "deformer_linear": (lambda: linear_deformer.LinearDeformer(linear_deformer.LinearDeformerConfig(hidden=4,
                                                                                                    latent=4)),
                        _mesh_call),
    "actor": (lambda: actor.ActorCVAE(actor.ActorConfig(3, **SMALL, num_neutrals=2)), _actor_call),
    "motion3dgan": (lambda: motion3dgan.Motion3DGAN(_gan_config(), num_neutrals=2), _gan_call),
    "motion3dgan_critic": (lambda: motion3dgan.Critic(_gan_config()), _critic_call),
    "motionclip": (lambda: motionclip.TextToMotion(motionclip.MotionClipConfig(embedding_dim=8, **SMALL)),
                   lambda m, make: m.decode(make(torch.randn(B, 8)), F)),
    "lstm_filler": (lambda: lstm_filler.LSTMFiller(lstm_filler.LSTMFillerConfig(hidden=8)), _filler_call),
}

# The shipped checkpoint kinds (data/checkpoints) and the entries of MODELS that build them.
KINDS = {"denoiser": ("denoiser", "denoiser_cfg"), "guide": ("guide",), "text_head": ("text_head",),
         "au_regressor": ("au_regressor",), "evaluator": ("evaluator", "evaluator_cnn"),
         "deformer": ("deformer_ours", "deformer_no_attention", "deformer_s2d", "deformer_coma", "deformer_linear"),
         "actor": ("actor",), "motion3dgan": ("motion3dgan", "motion3dgan_critic"), "motionclip": ("motionclip",),
         "lstm_filler": ("lstm_filler",)}


@pytest.fixture(scope="module")
def models():
    torch.manual_seed(0)
    return {name: build() for name, (build, _) in MODELS.items()}


# --------------------------------------------------------------------------------------- structural check
def _stray(value, where, depth=0):
    """(where, what, object) of every tensor or module inside a plain attribute value (containers searched)."""
    if isinstance(value, torch.Tensor):
        yield where, f"tensor {tuple(value.shape)} {value.dtype}", value
    elif isinstance(value, nn.Module):
        yield where, f"module {type(value).__name__} outside _modules", value
    elif depth < 4 and isinstance(value, dict):
        for k, v in value.items():
            yield from _stray(v, f"{where}[{k!r}]", depth + 1)
    elif depth < 4 and isinstance(value, (list, tuple, set, frozenset)):
        for i, v in enumerate(value):
            yield from _stray(v, f"{where}[{i}]", depth + 1)
    elif depth < 4 and dataclasses.is_dataclass(value) and not isinstance(value, type):
        for field in dataclasses.fields(value):
            yield from _stray(getattr(value, field.name), f"{where}.{field.name}", depth + 1)


def stray_tensors(model):
    """'module.path.attribute: what' of every tensor (or module) a module holds outside its parameters,
    buffers and submodules: ``model.to(device)`` would leave it where it is.  A module's own aliases of its
    parameters (nn.LSTM's ``_flat_weights``, which LSTM re-syncs on every move) are not strays."""
    found = []
    for path, module in model.named_modules():
        own = {id(t) for t in (*module._parameters.values(), *module._buffers.values()) if t is not None}
        for name, value in vars(module).items():
            if name in ("_parameters", "_buffers", "_modules"):
                continue
            found += [f"{path or '<root>'}.{where}: {what}" for where, what, obj in _stray(value, name)
                      if id(obj) not in own]
    return found


@pytest.mark.parametrize("name", MODELS)
def test_every_tensor_of_a_network_is_a_parameter_or_a_buffer(models, name):
    stray = stray_tensors(models[name])
    assert not stray, f"{name}: tensors that module.to(device) would not move: " + "; ".join(stray)


def test_the_check_finds_a_plain_tensor_attribute():
    class Leaky(nn.Module):
        def __init__(self):
            super().__init__()
            self.inner = nn.Linear(2, 2)
            self.inner.index = torch.arange(3)
            self.cached = {"rows": [torch.zeros(2)], "layers": (nn.Linear(1, 1),)}
            self.register_buffer("kept", torch.zeros(2), persistent=False)

    assert sorted(stray_tensors(Leaky())) == ["<root>.cached['layers'][0]: module Linear outside _modules",
                                              "<root>.cached['rows'][0]: tensor (2,) torch.float32",
                                              "inner.index: tensor (3,) torch.int64"]
    assert stray_tensors(nn.LSTM(2, 3, num_layers=2)) == []  # its _flat_weights alias its parameters


def test_every_network_class_and_shipped_checkpoint_kind_is_covered(models):
    built = [m for model in models.values() for m in model.modules()]
    classes = {cls for info in pkgutil.iter_modules(facelib.models.__path__)
               for _, cls in inspect.getmembers(importlib.import_module(f"facelib.models.{info.name}"), inspect.isclass)
               if issubclass(cls, nn.Module) and cls.__module__.startswith("facelib.models")}
    missing = sorted(c.__qualname__ for c in classes if not any(isinstance(m, c) for m in built))
    assert not missing, f"networks of facelib/models built by no entry of MODELS: {missing}"
    shipped = {json.loads(p.read_text())["kind"] for p in config.CHECKPOINT_DIR.glob("*.json")}
    assert shipped <= set(KINDS), f"shipped checkpoint kinds not covered: {sorted(shipped - set(KINDS))}"
    assert {n for names in KINDS.values() for n in names} == set(MODELS) and set(SHIPPED_BUILDERS) == set(KINDS)


# ---------------------------------------------------------------------------- a simulated device move
FAKE_DEVICE = torch.device("meta")  # a CPU build cannot fake CUDA's views; any device other than the CPU will do


def _moved_call(model, call):
    """``call(model, make)`` with the parameters and buffers of ``model`` (and the inputs ``make`` gives) as fake
    tensors on another device (torch's FakeTensor: shapes, dtypes and devices, no data): a real CPU tensor meeting
    them raises FakeTensorDeviceMismatchError, as it would on a GPU."""
    fake_tensor = pytest.importorskip("torch._subclasses.fake_tensor")
    mode = fake_tensor.FakeTensorMode(allow_non_fake_inputs=True)

    def make(t):
        return fake_tensor.FakeTensor(mode, t.detach().to("meta"), FAKE_DEVICE)

    class Call(nn.Module):
        def __init__(self):
            super().__init__()
            self.model = model

        def forward(self):
            return call(self.model, make)

    def sparse_mm(a, b):  # torch has no sparse kernels on the meta device: check the devices, give the shape
        if a.device != b.device:
            raise RuntimeError(f"Expected all tensors to be on the same device, but found at least two devices, "
                               f"{a.device} and {b.device}!")
        return b.new_empty((a.shape[0], b.shape[1]))

    wrapper = Call()
    state = {**dict(wrapper.named_parameters()), **dict(wrapper.named_buffers())}
    with mode, unittest.mock.patch.object(torch.sparse, "mm", sparse_mm):
        state = {k: make(v) for k, v in state.items()}
        return torch.func.functional_call(wrapper, state, ())


@pytest.mark.parametrize("name", MODELS)
def test_a_simulated_device_move_keeps_every_tensor_on_the_device(models, name):
    out = _moved_call(models[name], MODELS[name][1])
    assert out.device == FAKE_DEVICE


def test_the_simulated_device_move_catches_cpu_tensors_made_in_forward():
    class Gather(nn.Module):
        def forward(self, x):
            return torch.index_select(x, 0, torch.tensor([0, 2]))

    class Arange(nn.Module):
        def forward(self, x):
            return x + torch.arange(2)

    class CachedSparse(nn.Module):
        def forward(self, x):
            return torch.sparse.mm(torch.eye(3).to_sparse(), x)

    for module in (Gather(), Arange(), CachedSparse()):
        with pytest.raises(Exception, match="same device"):
            _moved_call(module, lambda m, make: m(make(torch.randn(3, 2))))


@pytest.mark.parametrize("name", MODELS)
def test_a_float64_network_runs_in_float64(models, name):
    model = copy.deepcopy(models[name]).double()

    def make(t):
        return t.double() if t.is_floating_point() else t

    out = MODELS[name][1](model, make)
    assert out.dtype == torch.float64


def test_generation_of_a_moved_baseline_follows_its_parameters(models):
    for name, generate in [("actor", lambda m: m.generate([0, 2], num_frames=F)),
                           ("motion3dgan", lambda m: m.generate([0, 2])),
                           ("motionclip", lambda m: m.generate(np.ones((B, 8), np.float32), num_frames=F))]:
        reference = generate(models[name])
        moved = generate(copy.deepcopy(models[name]).double())
        assert moved.dtype == np.float32 and moved.shape == reference.shape
        np.testing.assert_allclose(moved, reference, atol=1e-4, err_msg=name)


# ------------------------------------------------------------------------------------ shipped checkpoints
SHIPPED_BUILDERS = {  # kind: build(config, metadata), as facelib's loaders build them
    "denoiser": lambda c, meta: denoiser.Denoiser(denoiser.DenoiserConfig(**c)),
    "guide": lambda c, meta: noisy_classifier.NoisyClassifier(noisy_classifier.NoisyClassifierConfig(**c)),
    "text_head": lambda c, meta: noisy_classifier.NoisyTextHead(noisy_classifier.TextHeadConfig(**c)),
    "au_regressor": lambda c, meta: au_regressor.AURegressor(au_regressor.AURegressorConfig(**c)),
    "evaluator": lambda c, meta: classifier.classifier_from_config(c),
    "deformer": lambda c, meta: deformation.METHODS[meta["method"]][0].build(c),
    "actor": lambda c, meta: actor.build(c),
    "motion3dgan": lambda c, meta: motion3dgan.build(c),
    "motionclip": lambda c, meta: motionclip.build(c),
    "lstm_filler": lambda c, meta: lstm_filler.LSTMFiller(lstm_filler.LSTMFillerConfig(**c)),
}


def test_every_shipped_checkpoint_loads_strictly_and_its_buffers_stay_out_of_the_state_dict():
    """The buffers registered for devices are non-persistent: every shipped checkpoint still loads with
    strict=True (the loader's own check, and load_state_dict's) and its state_dict has exactly the file's keys."""
    names = sorted(p.stem for p in config.CHECKPOINT_DIR.glob("*.json"))
    assert names
    for name in names:
        meta = json.loads((config.CHECKPOINT_DIR / f"{name}.json").read_text())
        model, _ = checkpoints.load_checkpoint(name, meta["kind"], lambda c: SHIPPED_BUILDERS[meta["kind"]](c, meta))
        state = torch.load(config.CHECKPOINT_DIR / f"{name}.pt", map_location="cpu", weights_only=True)
        model.load_state_dict(state, strict=True)
        assert list(model.state_dict()) == list(state), name


def test_time_mapped_networks_hold_their_time_labels_in_a_buffer(models):
    wrapped = TimeMapped(models["denoiser"], [0, 4, 9])
    assert stray_tensors(wrapped) == [] and "timesteps" in dict(wrapped.named_buffers())
    out = _moved_call(wrapped, lambda m, make: m(make(torch.randn(B, F, L, 3)), make(torch.tensor([1, 2]))))
    assert out.device == FAKE_DEVICE
