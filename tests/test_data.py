"""The synthetic datasets: shapes, splits, caches and fingerprints, the merged set of text control, the
landmark normaliser."""
import json
import re
import warnings

import numpy as np
import pytest
import torch

from facelib import config, data
from facelib.face import get_template


def test_shapes_counts_and_dtypes():
    for name, n, subjects, labels in (("coma", 689, 12, 12), ("bu", 1212, 101, 6)):
        ds = data.load_dataset(name, "all")
        assert len(ds) == n and ds.landmarks.shape == (n, 40, 68, 3) and ds.landmarks.dtype == np.float32
        assert ds.labels.dtype == np.int64 and set(np.unique(ds.labels)) == set(range(labels))
        assert len(np.unique(ds.subjects)) == subjects and set(np.unique(ds.kinds)) == {0, 1}
        assert np.all(np.isfinite(ds.landmarks))
        assert ds.au_weights.shape == (n, 40, len(ds.au_names))


def test_splits_hold_out_whole_subjects():
    for name in ("coma", "bu"):
        train, test = data.load_dataset(name, "train"), data.load_dataset(name, "test")
        assert not set(train.subjects) & set(test.subjects)
        assert len(train) + len(test) == len(data.load_dataset(name, "all"))
        assert set(np.unique(test.labels)) == set(range(len(test.label_names)))


def test_generation_is_deterministic():
    spec = config.DATASETS["coma"]
    a, b = data.generate(spec), data.generate(spec)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def test_the_cache_key_reads_the_config_the_generator_reads_and_nothing_else(monkeypatch):
    """A dataset's cache key hashes the generator's code and the config values it reads (DATASETS, WORLD, ...),
    not the whole of config.py: a guidance constant leaves every cache valid, a world setting does not."""
    spec, key = config.DATASETS["coma"], data.generator_fingerprint(config.DATASETS["coma"], 40)
    assert "config.py" not in data._SOURCE_FILES
    monkeypatch.setattr(config, "GUIDANCE_WEIGHT", config.GUIDANCE_WEIGHT + 1)
    assert data.generator_fingerprint(spec, 40) == key
    monkeypatch.setattr(config, "WORLDS", (*config.WORLDS, 99))
    assert data.generator_fingerprint(spec, 40) != key


def test_committed_fingerprints_match():
    expected = json.loads(data.FINGERPRINT_FILE.read_text())
    for name in config.DATASETS:
        actual = data.fingerprint(data.build(name))
        assert data.fingerprints_match(actual, expected[f"{name}-F40"]), (name, actual, expected[f"{name}-F40"])


def test_corrupted_cache_is_detected_and_rebuilt(tmp_path):
    a = data.build("coma", 20, cache_dir=tmp_path)
    path = data.cache_path("coma", 20, cache_dir=tmp_path)
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    path.write_bytes(bytes(raw))
    with pytest.warns(RuntimeWarning, match="corrupted"):
        b = data.build("coma", 20, cache_dir=tmp_path)
    np.testing.assert_array_equal(a["landmarks"], b["landmarks"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        data.build("coma", 20, cache_dir=tmp_path)  # the rebuilt cache is valid again
    path.with_suffix(".sha256").unlink()
    with pytest.warns(RuntimeWarning, match="corrupted or incomplete"):
        data.build("coma", 20, cache_dir=tmp_path)


def test_meshes_and_landmarks_agree(coma_train):
    i = 5
    meshes = coma_train.meshes(i)
    assert meshes.shape == (40, len(get_template().vertices), 3)
    diff = meshes[:, get_template().landmark_index] - coma_train.landmarks[i]
    assert np.abs(diff).max() < 6 * data.TIMING.noise_mm  # only the capture noise separates them
    assert abs(diff.std() - data.TIMING.noise_mm) < 0.05
    s = int(coma_train.subjects[i])
    np.testing.assert_allclose(coma_train.neutral_mesh(s)[get_template().landmark_index],
                               coma_train.neutral_landmarks(s), atol=1e-4)


def test_n2e_starts_and_e2n_ends_near_neutral(coma_train):
    neutral = np.stack([coma_train.neutral_landmarks(int(s)) for s in coma_train.subjects])
    first = np.abs(coma_train.landmarks[:, 0] - neutral).mean(axis=(1, 2))
    last = np.abs(coma_train.landmarks[:, -1] - neutral).mean(axis=(1, 2))
    n2e, e2n = coma_train.kinds == 0, coma_train.kinds == 1
    assert np.median(first[n2e]) < 0.5 * np.median(last[n2e])
    assert np.median(last[e2n]) < 0.5 * np.median(first[e2n])


def test_other_and_variable_lengths():
    ds = data.load_dataset("coma", "test", num_frames=60)
    assert ds.landmarks.shape[1:] == (60, 68, 3)
    var = data.load_dataset("coma", "test", num_frames=(35, 45))
    assert var.lengths.min() >= 35 and var.lengths.max() <= 45 and len(np.unique(var.lengths)) > 3
    for i in range(5):
        assert np.all(var.landmarks[i, var.lengths[i]:] == 0) and np.all(var.landmarks[i, :var.lengths[i]] != 0)


def test_expression_split(coma_train):
    train, test = data.expression_split(coma_train, ["mouth_open", "eyebrow"])
    names = {coma_train.label_names[k] for k in np.unique(test.labels)}
    assert names == {"mouth_open", "eyebrow"} and len(train) + len(test) == len(coma_train)
    assert not names & {coma_train.label_names[k] for k in np.unique(train.labels)}
    with pytest.raises(ValueError, match="unknown label 'happy' for dataset 'coma'; allowed: bareteeth"):
        data.expression_split(coma_train, ["happy"])


@pytest.mark.parametrize("kwargs, message", [
    (dict(name="cmoa"), "unknown dataset 'cmoa'; allowed: coma, bu"),
    (dict(name="coma", split="val"), "unknown split 'val'; allowed: train, test, all"),
    (dict(name="coma", num_frames=1), r"num_frames must be in \[2, 400\]"),
    (dict(name="coma", num_frames=40.0), "num_frames must be an integer"),
    (dict(name="coma", num_frames=(45, 35)), "low > high"),
])
def test_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        data.load_dataset(**kwargs)


def test_bad_indices(coma_train):
    with pytest.raises(ValueError, match="sequence index"):
        coma_train.meshes(len(coma_train))
    with pytest.raises(ValueError, match="subject must be in"):
        coma_train.neutral_mesh(99)


def test_composed_performances_show_the_action_units_of_both_labels():
    from facelib import rig_fit
    from facelib.face.aus import AU_NAMES
    bu = data.load_dataset("bu", "test")
    both, subjects = data.composed_performances(bu, ("disgust", "happy"))
    assert both.shape == (len(np.unique(bu.subjects)), bu.num_frames, 68, 3) and both.dtype == np.float32
    assert np.array_equal(subjects, np.unique(bu.subjects))
    again, _ = data.composed_performances(bu, ("disgust", "happy"))
    assert np.array_equal(both, again)
    alone = {label: data.composed_performances(bu, label)[0] for label in ("disgust", "happy")}
    nose, smile = AU_NAMES.index("AU9"), AU_NAMES.index("AU12L")  # disgust wrinkles the nose, happy smiles

    def apex_aus(x):  # AU intensities fitted to the last frame (N2E ends at the apex) of three subjects
        return np.array([rig_fit.fit_aus(bu.face(int(s)), x[i, -1:])[0] for i, s in enumerate(subjects[:3])])
    w_both, w_disgust, w_happy = apex_aus(both), apex_aus(alone["disgust"]), apex_aus(alone["happy"])
    assert (w_both[:, nose] > w_happy[:, nose] + 0.3).all() and (w_both[:, smile] > w_disgust[:, smile] + 0.3).all()
    neutral = np.stack([bu.neutral_landmarks(int(s)) for s in subjects])
    e2n, _ = data.composed_performances(bu, ("disgust", "happy"), kind="E2N")
    for start, end in ((both[:, 0], both[:, -1]), (e2n[:, -1], e2n[:, 0])):  # neutral end, expressive end
        assert np.abs(start - neutral).max() < 0.2 * np.abs(end - neutral).max()
    for labels, message in (((), "one or two"), (("disgust", "happy", "sad"), "one or two"),
                            (("bareteeth",), "unknown label 'bareteeth'")):
        with pytest.raises(ValueError, match=message):
            data.composed_performances(bu, labels)
    with pytest.raises(ValueError, match="kind must be one of"):
        data.composed_performances(bu, "happy", kind="apex")


def test_more_people_of_the_same_labels_merge_into_one_label_set_and_keep_the_test_split():
    coma, crowd = data.load_dataset("coma", "train"), data.load_dataset("coma_crowd", "train")
    merged = data.load_dataset("coma+crowd", "train")
    assert merged.label_names == coma.label_names and len(merged) == len(coma) + len(crowd)
    np.testing.assert_array_equal(merged.labels, np.concatenate([coma.labels, crowd.labels]))
    assert len(np.unique(merged.subjects)) == len(np.unique(coma.subjects)) + 36
    np.testing.assert_array_equal(data.load_dataset("coma+crowd", "test").landmarks,
                                  data.load_dataset("coma", "test").landmarks)


def test_merged_dataset_keeps_every_sequence_face_label_and_split():
    for split in ("train", "test"):
        merged = data.load_dataset("coma+bu", split)
        coma, bu = data.load_dataset("coma", split), data.load_dataset("bu", split)
        assert len(merged) == len(coma) + len(bu) and merged.label_names == coma.label_names + bu.label_names
        assert len(merged.label_names) == 18
        np.testing.assert_array_equal(merged.landmarks[len(coma):], bu.landmarks)
        assert [merged.label_of(len(coma) + i) for i in (0, 7)] == [bu.label_of(0), bu.label_of(7)]
        # a BU subject keeps its own face: subject ids are offset by CoMA's 12 subjects
        i = len(coma) + 5
        np.testing.assert_array_equal(merged.neutral_landmarks(int(merged.subjects[i])),
                                      bu.neutral_landmarks(int(bu.subjects[5])))
    train, test = data.load_dataset("coma+bu", "train"), data.load_dataset("coma+bu", "test")
    assert not set(train.subjects) & set(test.subjects)  # held-out subjects stay held out
    assert set(test.subjects) == set(test.extra["test_subjects"])
    with pytest.raises(ValueError, match="not generated but merged"):
        data.build("coma+bu")
    with pytest.raises(ValueError, match=re.escape("unknown dataset 'coma+bu4d'; allowed: " + ", ".join(data.DATASET_NAMES))):
        data.load_dataset("coma+bu4d")


def test_normalizer_is_invertible(coma_train):
    norm = data.LandmarkNormalizer.fit(coma_train)
    z = norm.normalize(coma_train.landmarks[:10])
    assert abs(float(norm.normalize(coma_train.landmarks).std()) - 1) < 0.05
    np.testing.assert_allclose(norm.denormalize(z), coma_train.landmarks[:10], atol=1e-4)
    zt = norm.normalize(torch.as_tensor(coma_train.landmarks[:10]))
    np.testing.assert_allclose(norm.denormalize(zt).numpy(), coma_train.landmarks[:10], atol=1e-4)
    again = data.LandmarkNormalizer.from_dict(json.loads(json.dumps(norm.to_dict())))
    np.testing.assert_allclose(again.normalize(coma_train.landmarks[:2]), norm.normalize(coma_train.landmarks[:2]))


def test_the_neutral_frame_is_the_first_of_n2e_and_the_last_of_e2n():
    kinds = [data.KIND_NAMES.index("N2E"), data.KIND_NAMES.index("E2N")]
    assert data.neutral_frame_indices(kinds, 40).tolist() == [0, 39]
    with pytest.raises(ValueError, match=r"kinds must index \('N2E', 'E2N'\)"):
        data.neutral_frame_indices([0, 2], 40)
