"""AU-curve control (the fine-control chapter): requests, the score, the task."""
import numpy as np
import pytest
import torch

from facelib import experiments, guidance, tasks
from facelib.face.aus import AU_NAMES
from facelib.models.au_regressor import AURegressor, AURegressorConfig

RANGES = {name: (0.0, 1.5) for name in AU_NAMES}


def test_a_curve_is_linear_between_its_keys_and_held_outside_them():
    names, curve = tasks.parse_curve("AU12:0@10,0.8@30", 40, RANGES)
    assert names == ("AU12L", "AU12R")  # the alias: both lip corners
    assert curve[:11].tolist() == [0.0] * 11 and curve[30:].tolist() == [0.8] * 10
    assert curve[20] == pytest.approx(0.4)
    assert tasks.parse_curve("AU26:0", 40, RANGES)[1].tolist() == [0.0] * 40  # a constant
    curves, mask = tasks.requested_curves(["AU12:0@10,0.8@30", "AU26:0.2"], 40, RANGES)
    assert mask.sum(1).tolist() == [3] * 40 and curves[:, AU_NAMES.index("AU26")].tolist() == [0.2] * 40


@pytest.mark.parametrize("spec, message", [
    ("AU99:0.5", "unknown AU 'AU99'; allowed: AU1, .*AU12"),
    ("AU26:0.5@40", r"key frames must be distinct, in 0..39"),
    ("AU26:0.5@3,0.2@3", "distinct"),
    ("AU26:2.0", r"AU26's intensity must stay in the data's range \[0.00, 1.50\]"),
    ("AU26", "NAME:value@frame"),
    ("AU26:high@3", "value@frame"),
])
def test_bad_curves_are_refused_with_what_is_allowed(spec, message):
    with pytest.raises(ValueError, match=message):
        tasks.parse_curve(spec, 40, RANGES)
    with pytest.raises(ValueError, match="constrained twice"):
        tasks.requested_curves(["AU12:0.5", "AU12R:0.2"], 40, RANGES)


def test_the_score_is_the_gaussian_log_likelihood_of_the_constrained_entries_only():
    class Fixed(torch.nn.Module):  # a "regressor" that reads its answer off x
        def forward(self, x, t):
            return x[:, :, :2, 0].repeat(1, 1, len(AU_NAMES) // 2)

    curves = torch.zeros(1, 40, len(AU_NAMES))
    mask = torch.zeros(1, 40, len(AU_NAMES), dtype=torch.bool)
    mask[0, 5, 0] = True
    x = torch.zeros(2, 40, 68, 3)
    x[:, 5, 0, 0], x[:, 6, 0, 0] = 0.3, 5.0  # frame 6 is unconstrained: it does not count
    score = guidance.AUCurveScore(Fixed(), curves, mask, tolerance=0.1)
    assert torch.allclose(score(x, torch.zeros(2)), torch.full((2,), -0.3 ** 2 / (2 * 0.01)))
    with pytest.raises(ValueError, match="one shape"):
        guidance.AUCurveScore(Fixed(), curves, mask[0], tolerance=0.1)


def test_au_control_samples_and_guidance_moves_the_regressor_towards_the_request(denoiser):
    torch.manual_seed(0)
    regressor = tasks.TrainedGuide(AURegressor(AURegressorConfig(width=32, depth=1, heads=2, ff=64)).eval(),
                                   "coma", "au", AU_NAMES, denoiser.normalizer,
                                   {"training": {"num_diffusion_steps": 2000}})
    request = ["AU26:1.0"]
    kwargs = dict(steps=4, seed=2, denoiser=denoiser, regressor=regressor, progress=False)
    guided = tasks.au_control(request, 3, **kwargs)
    assert guided.shape == (3, 40, 68, 3) and np.isfinite(guided).all()
    assert np.array_equal(guided, tasks.au_control(request, 3, **kwargs))  # same seed, same sequences
    plain = tasks.unconditional(3, steps=4, seed=2, denoiser=denoiser, progress=False)
    curves, mask = tasks.requested_curves(request, 40)
    score = guidance.AUCurveScore(regressor.model, curves[None], mask[None], tolerance=0.1)
    with torch.no_grad():
        guided_score, plain_score = (score(denoiser.to_model(x).float(), torch.zeros(3)).mean()
                                     for x in (guided, plain))
    assert guided_score > plain_score  # the request is likelier under R after guidance
    with pytest.raises(ValueError, match="one request for all sequences or one per sequence"):
        tasks.au_control([request, request], 3, **kwargs)
    with pytest.raises(ValueError, match="method"):
        tasks.au_control(request, 3, method="magic", **kwargs)
    assert np.isfinite(tasks.au_control(request, 3, read="x_t", **kwargs)).all()  # R reads x_t itself
    face = guided[0, 0] + 1.0
    on_face = tasks.au_control(request, 3, face, **kwargs)  # a given face: frame 0, exactly
    assert np.array_equal(on_face[:, 0], np.broadcast_to(face, (3, 68, 3)).astype(np.float32))
    with pytest.raises(ValueError, match=r"neutral face must be finite landmarks of shape \(68, 3\)"):
        tasks.au_control(request, 3, face[:60], **kwargs)


def test_the_regressor_recipe_trains_and_its_checkpoint_loads_as_a_guide(tmp_path):
    from facelib import training
    recipe = training.recipe("au_regressor", fast=True)
    assert recipe.checkpoint_name() == "au_regressor_coma"
    stem = str(tmp_path / "au_regressor_coma")
    training.train_and_save(recipe, name=stem, progress=False)
    reg = tasks.load_au_regressor("coma", name=stem)
    assert reg.class_names == AU_NAMES and reg.classifier_type == "au"
    out = reg.model(torch.zeros(2, 40, 68, 3), torch.zeros(2))
    assert out.shape == (2, 40, len(AU_NAMES)) and torch.isfinite(out).all()
    with pytest.raises(ValueError, match="trained on 'coma', not 'bu'"):
        tasks.load_au_regressor("bu", name=stem)


def test_random_requests_stay_in_the_data_and_fitted_requests_score_zero():
    requests = experiments.random_requests(6, seed=1)
    ranges = tasks.data_ranges("coma")
    for request in requests:  # each parses against the data's ranges
        curves, mask = tasks.requested_curves(request, 40, ranges)
        assert mask.any() and curves[0][mask[0]].max() == 0.0
    exact = np.stack([tasks.requested_curves(r, 40)[0] for r in requests])
    assert np.allclose(tasks.curve_errors(exact, requests), 0.0)
    assert tasks.curve_errors(exact + 0.1, requests) == pytest.approx([0.1] * 6)
    pairs = tasks.never_together("coma")
    assert pairs and all(a in AU_NAMES and b in AU_NAMES for a, b in pairs)


def test_active_aus_reads_signed_aus_by_their_size_and_never_together_uses_it():
    w = np.zeros((2, 40, len(AU_NAMES)))
    w[0, 5, AU_NAMES.index("AD30")] = -0.5  # the jaw sideways, to the other side: active
    w[1, 5, AU_NAMES.index("AU2")] = 0.2  # at the threshold: not active
    on = tasks.au.active_aus(w)
    assert on[0, AU_NAMES.index("AD30")] and on.sum() == 1
    assert tasks.au.active_aus(w, active=0.1).sum() == 2
    with pytest.raises(ValueError, match="au_weights must be AU curves"):
        tasks.au.active_aus(w[0])
    with pytest.raises(ValueError, match="active must be an intensity >= 0"):
        tasks.au.active_aus(w, active=-1)


def test_random_requests_peak_where_their_settings_say_and_name_their_aus():
    requests = experiments.random_requests(20, seed=0, aus=["AU2", "AU26"], low=0.4, high=0.6, peak_frames=(12, 14))
    for (spec,) in requests:
        keys = [k.split("@") for k in spec.split(":")[1].split(",")]
        assert 0.4 <= float(keys[1][0]) <= 0.6 and 12 <= int(keys[1][1]) <= 14 and keys[2][1] == "39"
    assert tasks.au.requested_aus(requests) == ["AU2", "AU26"]
    assert tasks.au.requested_aus([["AU12:0", "AU1:0.5"]]) == ["AU1", "AU12L", "AU12R"]
    with pytest.raises(ValueError, match="peak_frames must be"):
        experiments.random_requests(1, peak_frames=(0, 39))


def test_au_guidance_off_is_the_same_chain_and_face_with_the_au_score_weighted_zero(denoiser):
    torch.manual_seed(0)
    regressor = tasks.TrainedGuide(AURegressor(AURegressorConfig(width=32, depth=1, heads=2, ff=64)).eval(),
                                   "coma", "au", AU_NAMES, denoiser.normalizer,
                                   {"training": {"num_diffusion_steps": 2000}})
    kwargs = dict(steps=4, seed=2, denoiser=denoiser, regressor=regressor, progress=False)
    face = tasks.unconditional(1, steps=4, seed=1, denoiser=denoiser, progress=False)[0, 0]
    assert tasks.AU_GUIDANCE_OFF == {"au_weight": 0.0}  # one named setting, used by the benchmark and the chapter
    off = tasks.au_control(["AU26:1.0"], 2, face, **kwargs, **tasks.AU_GUIDANCE_OFF)
    other = tasks.au_control(["AU12:0.5"], 2, face, **kwargs, **tasks.AU_GUIDANCE_OFF)
    assert np.array_equal(off, other)  # the request counts for nothing
    assert np.array_equal(off[:, 0], np.broadcast_to(face, (2, 68, 3)))  # the same face at frame 0
    on = tasks.au_control(["AU26:1.0"], 2, face, **kwargs)
    assert not np.allclose(off, on)  # with its weight, the AU score moves the sequences
    half = tasks.au_control(["AU26:1.0"], 2, face, au_weight=0.5, **kwargs)
    assert not np.allclose(half, on) and not np.allclose(half, off)
    with pytest.raises(ValueError, match="the AU score's weight must be a non-negative number"):
        tasks.au_control(["AU26:1.0"], 2, face, au_weight=-1.0, **kwargs)


def test_regressor_curves_are_what_r_reads_on_clean_sequences(denoiser):
    torch.manual_seed(0)
    regressor = tasks.TrainedGuide(AURegressor(AURegressorConfig(width=32, depth=1, heads=2, ff=64)).eval(),
                                   "coma", "au", AU_NAMES, denoiser.normalizer,
                                   {"training": {"num_diffusion_steps": 2000}})
    x = tasks.unconditional(2, steps=4, seed=1, denoiser=denoiser, progress=False)
    read = tasks.regressor_curves(x, regressor)
    with torch.no_grad():
        expected = regressor.model(denoiser.to_model(x).float(), torch.zeros(2)).numpy()
    assert read.shape == (2, 40, len(AU_NAMES)) and np.allclose(read, expected, atol=1e-6)
