"""The coverage protocol against a reference population (issue 58): the gap of a percentile with an interval
over people, the label mix against real resamples of the same size, the second reader."""
import numpy as np
import pytest

from facelib import config, data, evaluation, metrics


def clustered(rng, people, per_person, spread=3.0, noise=0.3):
    """Values of ``people`` people, ``per_person`` each: a person's offset (std ``spread``) plus noise."""
    offsets = rng.normal(0, spread, people)
    ids = np.repeat(np.arange(people), per_person)
    return offsets[ids] + rng.normal(0, noise, len(ids)), ids


def test_the_population_gap_is_zero_for_the_same_population_and_resamples_people_not_rows():
    """Generated values drawn like the reference (each from a new person) give an interval around 0; shifted
    by 5 they give a gap near 5 whose interval excludes 0.  The reference's sequences of one person move
    together: resampled by person, the interval is several times wider than if every row were its own
    person (what a row bootstrap of a 20-person reference would claim)."""
    rng = np.random.default_rng(0)
    reference, people = clustered(rng, 20, 24)
    generated, _ = clustered(rng, 300, 1)
    gap, (low, high) = metrics.population_gap(generated, reference, people, np.median, num_resamples=500)
    assert low <= 0 <= high and abs(gap) < 2
    gap, (low, high) = metrics.population_gap(generated + 5, reference, people, np.median, num_resamples=500)
    assert low > 0 and abs(gap - 5) < 2
    _, (row_low, row_high) = metrics.population_gap(generated, reference, np.arange(len(reference)), np.median,
                                                    num_resamples=500)
    assert (high - low) > 1.5 * (row_high - row_low)
    same = metrics.population_gap(generated, reference, people, np.median, num_resamples=500)
    assert same == metrics.population_gap(generated, reference, people, np.median, num_resamples=500)
    with pytest.raises(ValueError, match="2 or more people"):
        metrics.population_gap(generated, reference, np.zeros(len(reference)), np.median)
    with pytest.raises(ValueError, match="a person id each"):
        metrics.population_gap(generated, reference, people[:-1], np.median)


def test_the_label_mix_gap_passes_real_resamples_and_flags_a_label_made_too_often():
    rng = np.random.default_rng(1)
    people = np.repeat(np.arange(40), 12)
    reference = np.tile(np.arange(12), 40)
    fair = metrics.label_mix_gap(rng.choice(reference, 300), reference, people, 12)
    assert fair["tv"] < fair["tv_real"] and fair["max_ratio"] < fair["max_ratio_real"]
    skewed = np.where(rng.random(300) < 0.3, 11, rng.choice(reference, 300))  # a third more label 11
    gap = metrics.label_mix_gap(skewed, reference, people, 12)
    assert gap["tv"] > gap["tv_real"] and gap["max_ratio"] > 3 > gap["max_ratio_real"]
    assert np.isclose(gap["reference_mix"], 1 / 12).all()
    with pytest.raises(ValueError, match="every class must occur"):
        metrics.label_mix_gap(skewed, reference % 11, people, 12)


def test_the_reference_population_is_new_people_and_the_retakes_are_the_training_people():
    people = data.load_dataset("coma_people", "test")
    coma, retakes = data.load_dataset("coma", "all"), data.load_dataset("coma_retakes", "all")
    assert len(people) == 1200 and len(np.unique(people.subjects)) == 50
    assert config.REFERENCE_POPULATIONS["coma"] == "coma_people"
    assert len(data.load_dataset("coma_people", "train")) == 0
    # the same faces as coma's, new takes (5 and 6), the same people held out
    assert np.array_equal(coma.identity_coeffs, retakes.identity_coeffs)
    takes = {name: data.build(name)["takes"] for name in ("coma", "coma_retakes")}
    assert set(np.unique(takes["coma_retakes"])) == {5, 6} and takes["coma"].max() == 4
    assert set(data.load_dataset("coma_retakes", "test").subjects) == set(data.load_dataset("coma", "test").subjects)
    assert not set(config.EVALUATION_DATASETS) & set(data.MODEL_DATASETS)


def test_the_second_reader_is_a_temporal_cnn_that_reads_the_data_as_the_ic_does():
    """ic_coma_I_cnn: another architecture, trained on the same split; it recognises the reference
    population's labels about as well as the IC (both within 10 points of each other, both well above
    chance), and refuses an unknown reader by name."""
    people = data.load_dataset("coma_people", "test")
    accuracy = {}
    for reader in ("lstm", "cnn"):
        ev = evaluation.load_evaluator("coma", "I", reader=reader)
        accuracy[reader] = (ev.features(people.landmarks).argmax(1) == people.targets("I")).mean()
    assert type(evaluation.load_evaluator("coma", "I", reader="cnn").model).__name__ == "TemporalCNNClassifier"
    assert min(accuracy.values()) > 0.7 and abs(accuracy["lstm"] - accuracy["cnn"]) < 0.1, accuracy
    with pytest.raises(ValueError, match="unknown reader 'gru'; allowed: lstm, cnn"):
        evaluation.load_evaluator("coma", "I", reader="gru")
