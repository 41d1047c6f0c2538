"""Landmark keyframes (the fine-control chapter): the constraints, their file, the task."""
import json

import numpy as np
import pytest

from facelib import experiments, tasks

NEUTRAL = np.random.default_rng(0).normal(0, 30, (68, 3))


def test_keys_become_targets_and_a_mask_with_the_neutral_face_as_frame_zero():
    keys = [{"frame": 25, "landmark": 54, "displacement": [0, 8, 0]},
            {"frame": 10, "landmark": 8, "position": [1.0, 2.0, 3.0]}]
    given, mask = tasks.check_keys(keys, 40, NEUTRAL)
    assert mask.sum() == 68 + 2 and mask[0].all() and mask[25, 54] and mask[10, 8]
    assert np.allclose(given[25, 54], NEUTRAL[54] + [0, 8, 0]) and np.allclose(given[10, 8], [1, 2, 3])
    assert np.allclose(given[0], NEUTRAL)


@pytest.mark.parametrize("keys, message", [
    ([], "non-empty list"),
    ([{"frame": 3, "landmark": 54}], "one of 'position' or 'displacement'"),
    ([{"frame": 3, "landmark": 54, "position": [0, 0, 0], "displacement": [0, 0, 0]}], "one of"),
    ([{"frame": 40, "landmark": 54, "position": [0, 0, 0]}], r"integer in 0..39"),
    ([{"frame": 3, "landmark": 68, "position": [0, 0, 0]}], r"iBUG-68 index in 0..67"),
    ([{"frame": 3, "landmark": 5, "position": [0, 0]}], "3 finite numbers"),
    ([{"frame": 3, "landmark": 5, "position": [0, 0, np.nan]}], "3 finite numbers"),
    ([{"frame": 3, "landmark": 5, "position": [0, 0, 0]}] * 2, "constrained twice"),
])
def test_bad_keys_are_refused_naming_what_is_allowed(keys, message):
    with pytest.raises(ValueError, match=message):
        tasks.check_keys(keys, 40, NEUTRAL)


def test_a_displacement_needs_a_face_and_a_constraints_file_must_be_valid(tmp_path):
    with pytest.raises(ValueError, match="displacement is taken from the neutral face"):
        tasks.check_keys([{"frame": 3, "landmark": 5, "displacement": [0, 1, 0]}], 40)
    bad = tmp_path / "bad.json"
    bad.write_text("{keys: [")
    with pytest.raises(ValueError, match="not valid JSON"):
        tasks.read_constraints(bad)
    bad.write_text(json.dumps({"keyz": []}))
    with pytest.raises(ValueError, match="'keys'"):
        tasks.read_constraints(bad)
    good = tmp_path / "keys.json"
    good.write_text(json.dumps({"neutral": NEUTRAL.tolist(), "keys": [{"frame": 3, "landmark": 5,
                                                                       "displacement": [0, 1, 0]}]}))
    keys, neutral = tasks.read_constraints(good)
    assert np.allclose(neutral, NEUTRAL) and keys[0]["landmark"] == 5


@pytest.mark.parametrize("method", ["replace", "reconstruction", "both"])
def test_keyframes_meet_their_keys(method, denoiser, coma_test):
    neutral = coma_test.neutral_landmarks(int(coma_test.subjects[0]))
    keys = [{"frame": 20, "landmark": 57, "displacement": [0.0, -10.0, 0.0]}]  # the lower lip 10 mm down
    x = tasks.keyframes(keys, 2, neutral, steps=10, method=method, denoiser=denoiser, progress=False)
    assert x.shape == (2, 40, 68, 3) and np.isfinite(x).all()
    errors = tasks.key_errors(x, keys, neutral)
    plain = tasks.unconditional(2, steps=10, denoiser=denoiser, progress=False)
    assert errors.mean() < tasks.key_errors(plain, keys, neutral).mean()
    if method != "reconstruction":  # replacement: the keyed coordinates and the face are given exactly
        assert errors.max() < 1e-3 and np.abs(x[:, 0] - neutral).max() < 1e-3


def test_random_keys_are_real_displacements_and_key_speeds_read_the_keyed_frame():
    (keys, neutral), = experiments.random_keys(1, seed=3)
    tasks.check_keys(keys, 40, neutral)  # valid against their own face
    x = np.zeros((1, 40, 68, 3))
    x[0, keys[0]["frame"]:, keys[0]["landmark"]] += 4.0  # the keyed landmark jumps at the keyed frame
    assert tasks.key_speeds(x, keys)[0, 0] == pytest.approx(4.0 * np.sqrt(3))
    x[0, keys[0]["frame"]:, keys[0]["landmark"] + 1] += 40.0  # another landmark's jump does not count
    assert tasks.key_speeds(x, keys)[0, 0] == pytest.approx(4.0 * np.sqrt(3))
    walk = np.zeros((2, 40, 68, 3))
    walk[:, :, 5, 0] = np.arange(40) * 0.5  # 0.5 mm per frame
    assert tasks.real_speed_p95(walk, 5) == pytest.approx(0.5)


def test_key_speeds_see_a_jump_moved_off_the_key_within_the_radius():
    keys = [{"frame": 20, "landmark": 54, "displacement": [0.0, 10.0, 0.0]}]
    x = np.zeros((1, 40, 68, 3))
    x[0, 18:, 54, 1] = 3.0  # the landmark jumps between frames 17 and 18, two before the key
    assert tasks.key_speeds(x, keys, radius=1)[0, 0] == 0.0  # into and out of the key: still
    assert tasks.key_speeds(x, keys)[0, 0] == pytest.approx(3.0)  # config.KEYFRAME_SPEED_RADIUS = 3
    x[0, 24:, 54, 1] = 8.0  # a jump four frames after it: outside the radius
    assert tasks.key_speeds(x, keys)[0, 0] == pytest.approx(3.0)
    assert tasks.key_speeds(x, keys, radius=4)[0, 0] == pytest.approx(5.0)


def test_a_keyframe_report_meets_a_key_only_when_close_and_without_a_jump():
    real = np.zeros((2, 40, 68, 3))
    real[:, :, 54, 1] = np.arange(40) * 0.5  # real corners move 0.5 mm per frame: p95 = 0.5
    keys = [{"frame": 20, "landmark": 54, "displacement": [0.0, 10.0, 0.0]}]
    x = np.zeros((3, 40, 68, 3))
    x[:, :, 54, 1] = np.arange(40) * 0.5  # smooth, 10 mm at frame 20
    x[1, 20, 54, 1] = 12.0  # off by 2 mm (and a jump)
    x[2, 20:, 54, 1] += 0.3  # on the key (10.3 mm: within 0.5) but 0.8 mm into the keyed frame
    report = tasks.keyframe_report(x, [(keys, np.zeros((68, 3)))] * 3, real)
    assert report["error"] == pytest.approx([0.0, 2.0, 0.3]) and report["met"].tolist() == [True, False, False]
    assert report["speed_ratio"] == pytest.approx([1.0, 5.0, 1.6])
    with pytest.raises(ValueError, match="one sequence per request"):
        tasks.keyframe_report(x[:2], [(keys, None)] * 3, real)
