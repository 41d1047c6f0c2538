"""Label control under DDIM, classifier-free label control, and editing by DDIM inversion (issue 27)."""
import numpy as np
import pytest
import torch

from facelib import config, tasks
from facelib.guidance import ClassifierFree
from facelib.models.denoiser import Denoiser, DenoiserConfig


@pytest.fixture(scope="module")
def tiny_cfg(denoiser, coma_test):
    """A label-conditional denoiser (untrained, tiny) in the shipped denoiser's space, with CoMA's labels."""
    torch.manual_seed(0)
    model = Denoiser(DenoiserConfig(width=32, depth=1, heads=2, ff=64, num_classes=len(coma_test.label_names)))
    torch.nn.init.normal_(model.out.weight, std=0.05)  # the output starts at zero: let the label through
    meta = {"class_names": list(coma_test.label_names), "name": "tiny_cfg", "sha256": "0" * 64}
    return tasks.TrainedDenoiser(model.eval(), denoiser.normalizer, denoiser.diffusion, meta)


def test_label_control_runs_under_ddim_and_is_deterministic_at_eta_0(denoiser):
    kwargs = dict(steps=6, seed=2, sampler="ddim", denoiser=denoiser, progress=False)
    a = tasks.label_control("mouth_open", 2, **kwargs)
    assert a.shape == (2, 40, 68, 3) and np.all(np.isfinite(a))
    np.testing.assert_array_equal(a, tasks.label_control("mouth_open", 2, **kwargs))
    assert np.abs(a - tasks.label_control("mouth_open", 2, **{**kwargs, "sampler": "ddpm"})).max() > 0.1
    # the mean shift too, and the guidance moves the deterministic chain
    shifted = tasks.label_control("mouth_open", 2, method="mean_shift", scale=5.0, **kwargs)
    unguided = tasks.label_control("mouth_open", 2, method="mean_shift", scale=0.0, **kwargs)
    assert np.abs(shifted - unguided).max() > 1e-3


def test_classifier_free_label_control_samples_the_conditional_denoiser(tiny_cfg, denoiser):
    kwargs = dict(steps=4, seed=1, guidance="cfg", denoiser=tiny_cfg, progress=False)
    a = tasks.label_control(["high_smile", "eyebrow"], 2, **kwargs)
    assert a.shape == (2, 40, 68, 3) and np.all(np.isfinite(a))
    b = tasks.label_control(["high_smile", "eyebrow"], 2, scale=0.0, **kwargs)
    c = tasks.label_control(["mouth_open", "bareteeth"], 2, scale=0.0, **kwargs)
    np.testing.assert_array_equal(b, c)  # w = 0: the unconditional model, whatever the label
    assert np.abs(a - b).max() > 1e-4
    assert tasks.LabelControl(guidance="cfg").guidance_scale == config.CFG_SCALE
    assert tasks.LabelControl().guidance_scale == config.MEAN_SHIFT_SCALE
    # classifier guidance: Alg. 1 under DDPM, the mean shift under DDIM, unless chosen; --paper is Alg. 1
    assert tasks.LabelControl().guidance_method == "adagrad"
    assert tasks.LabelControl(sampler="ddim").guidance_method == "mean_shift"
    assert tasks.LabelControl(sampler="ddim", method="adagrad").guidance_method == "adagrad"
    assert tasks.LabelControl(sampler="ddim").paper().guidance_method == "adagrad"
    assert tasks.Edit().guidance_method == "mean_shift"
    assert tasks.Edit().guidance_scale == config.EDIT_MEAN_SHIFT_SCALE
    assert tasks.Edit(guidance="cfg").guidance_scale == config.CFG_SCALE and tasks.Edit(scale=3.0).guidance_scale == 3
    with pytest.raises(ValueError, match="needs a label-conditional denoiser.*denoiser_coma is unconditional"):
        tasks.label_control("high_smile", 2, steps=2, guidance="cfg", denoiser=denoiser, progress=False)
    with pytest.raises(ValueError, match="unknown label 'smile'.*allowed: bareteeth"):
        tasks.label_control("smile", 2, **kwargs)
    with pytest.raises(ValueError, match="scale must be a non-negative number"):
        tasks.label_control("high_smile", 2, scale=-1.0, **kwargs)
    with pytest.raises(ValueError, match="guidance must be one of"):
        tasks.LabelControl(guidance="free")


def test_ddim_inversion_regenerates_a_test_sequence_and_refining_it_divides_the_error(denoiser, coma_test):
    x = coma_test.landmarks[:2]
    chain = denoiser.diffusion_with(50, eta=0.0)

    def rmse(refine):  # mm per landmark, over the sequence
        back = denoiser.to_mm(chain.run(denoiser.model, tasks.invert(denoiser, x, tasks.Edit(steps=50, refine=refine)),
                                        progress=False))
        return np.sqrt(((back - x) ** 2).sum(-1).mean((1, 2))).max()
    plain, refined = rmse(0), rmse(2)
    assert plain < 2.0 and refined < plain / 5, (plain, refined)
    with pytest.raises(ValueError, match="refine must be a number of fixed-point iterations >= 0"):
        tasks.Edit(refine=-1)


def test_edit_changes_the_expression_and_refuses_bad_input(denoiser, coma_test):
    x = coma_test.landmarks[:2]
    kwargs = dict(steps=6, denoiser=denoiser, progress=False, keep=None)
    edited = tasks.edit(x, "mouth_open", **kwargs)
    assert edited.shape == x.shape and edited.dtype == np.float32
    guide = tasks.load_guide("coma")  # the guide reads the new label more in the edited sequences than before

    def log_p(seqs):
        with torch.no_grad():
            return guide.model.log_prob(denoiser.to_model(seqs), torch.full((2,), 10.0),
                                        torch.as_tensor(guide.class_indices(["mouth_open"] * 2)))
    gain = log_p(edited) - log_p(x)  # the default: the mean shift at EDIT_MEAN_SHIFT_SCALE (DDIM's guidance)
    assert (gain > 0).all() and gain.mean() > 1.0, (log_p(x), log_p(edited))
    np.testing.assert_array_equal(edited, tasks.edit(x, "mouth_open", **kwargs))
    assert tasks.edit(x[0], "mouth_open", **kwargs).shape == (1, 40, 68, 3)
    with pytest.raises(ValueError, match=r"must be \(F, 68, 3\) or \(n, F, 68, 3\)"):
        tasks.edit(x[:, :, :60], "mouth_open", **kwargs)
    bad = x.copy()
    bad[0, 3, 5, 1] = np.nan
    with pytest.raises(ValueError, match="NaN or infinite"):
        tasks.edit(bad, "mouth_open", **kwargs)
    with pytest.raises(ValueError, match="sampler must be 'ddim' with eta 0"):
        tasks.edit(x, "mouth_open", sampler="ddpm", **kwargs)
    with pytest.raises(ValueError, match="sampler must be 'ddim' with eta 0"):
        tasks.edit(x, "mouth_open", eta=0.5, **kwargs)
    with pytest.raises(ValueError, match="eta must be a number in"):
        tasks.edit(x, "mouth_open", eta=2.0, **kwargs)
    with pytest.raises(ValueError, match="num_frames 30 differs from the sequences' 40 frames"):
        tasks.edit(x, "mouth_open", num_frames=30, **kwargs)
    with pytest.raises(ValueError, match="label must be a label name or a list of n=2"):
        tasks.edit(x, ["mouth_open"], **kwargs)
    with pytest.raises(ValueError, match="no --paper version"):
        tasks.Edit().paper()
    kwargs.pop("keep")
    with pytest.raises(ValueError, match="outside 0:40"):
        tasks.edit(x, "mouth_open", keep="38:41", **kwargs)
    with pytest.raises(ValueError, match="keep holds every frame of a sequence"):
        tasks.edit(x, "mouth_open", keep="0:40", **kwargs)
    with pytest.raises(ValueError, match=r"keep must be frame ranges like '0:1' or a boolean mask of shape \(40,\)"):
        tasks.edit(x, "mouth_open", keep=np.ones(39, dtype=bool), **kwargs)


def test_edit_keeps_the_frames_asked_for_and_regenerates_the_others(denoiser, coma_test):
    x = coma_test.landmarks[:2]
    kwargs = dict(steps=6, denoiser=denoiser, progress=False)
    kept = tasks.edit(x, "mouth_open", **kwargs)  # the default keeps the neutral frame (tasks.Edit.keep)
    np.testing.assert_array_equal(kept[:, 0], x[:, 0].astype(np.float32))
    assert np.abs(kept[:, 1:] - x[:, 1:]).max() > 0.5
    # the kept frame follows its own inversion path, which is the chain's own path: with no guidance pull,
    # keeping it changes the other frames by almost nothing (taking path[t] instead of path[t-1]: 0.13 mm)
    still = dict(method="mean_shift", scale=0.0, steps=50, refine=4, denoiser=denoiser, progress=False)
    gap = np.abs(tasks.edit(x, "mouth_open", keep="0:1", **still) - tasks.edit(x, "mouth_open", keep=None, **still))
    assert gap[:, 1:].max() < 0.01, gap.max()


def test_edit_with_classifier_free_guidance_inverts_with_the_free_model(tiny_cfg, coma_test):
    x = coma_test.landmarks[:1]
    kwargs = dict(steps=4, guidance="cfg", denoiser=tiny_cfg, progress=False)
    chain = tiny_cfg.diffusion_with(4, eta=0.0)
    free = tasks.invert(tiny_cfg, x, tasks.Edit(steps=4))  # inverted by the free estimate (no label)
    guided = ClassifierFree(tiny_cfg.model, tiny_cfg.class_indices(["eyebrow"]), 3.0)
    np.testing.assert_allclose(tasks.edit(x, "eyebrow", scale=3.0, keep=None, **kwargs),
                               tiny_cfg.to_mm(chain.run(guided, free, progress=False)), atol=1e-4)
    inverted_guided = tasks.invert(tiny_cfg, x, tasks.Edit(steps=4), model=guided)
    assert (inverted_guided - free).abs().max() > 1e-3  # so the line above tells the two apart
