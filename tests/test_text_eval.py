"""Measurements of text control: when a curve settles, whether a composition mixes, the small balanced sets
of the text-control chapter and its prompts."""
import numpy as np
import pytest

from facelib import data, descriptions, text_eval


class FixedIC:
    """An evaluator whose logits are the sequences' first number per class (sequences (n, C) here)."""
    class_names = ("a", "b", "c")

    def features(self, x):
        return np.asarray(x, dtype=float)

    def class_index(self, name):
        return self.class_names.index(name)


def logits(p, n=4):
    return np.log(np.tile(np.asarray(p), (n, 1)))


def test_a_composition_mixes_only_when_both_terms_hold_a_real_share_above_the_other_terms_alone():
    ic = FixedIC()
    mixed = text_eval.composition_row(ic, "a", "b", logits([0.45, 0.45, 0.1]), logits([0.9, 0.05, 0.05]),
                                      logits([0.05, 0.9, 0.05]))
    assert np.allclose(mixed[:4], [0.45, 0.45, 0.05, 0.05]) and mixed[4]
    one_term = text_eval.composition_row(ic, "a", "b", logits([0.92, 0.04, 0.04]), logits([0.9, 0.05, 0.05]),
                                         logits([0.05, 0.9, 0.05]))
    assert not one_term[4]
    with pytest.raises(ValueError, match="unknown|not in"):
        text_eval.composition_row(ic, "a", "z", *(logits([1 / 3] * 3),) * 3)


def test_settled_from_is_the_earliest_t_after_which_the_curve_stays_up():
    curve = [(0, 100), (10, 95), (20, 91), (30, 60), (40, 95)]
    assert text_eval.settled_from(curve) == 20
    assert text_eval.settled_from([(0, 50)]) == 0


def test_the_balanced_subset_has_two_sequences_per_label_and_alternating_orders():
    test = data.load_dataset("coma", "test")
    sub = text_eval.balanced_subset(test, 6)
    assert len(sub) == 12 and all(np.bincount(sub.labels)[np.unique(sub.labels)] == 2)
    kinds = [sub.kinds[sub.labels == k] for k in np.unique(sub.labels)]
    assert all(len(set(k)) == 1 for k in kinds) and [k[0] for k in kinds] == [0, 1] * 3
    with pytest.raises(ValueError, match="num_labels must be in 1..12"):
        text_eval.balanced_subset(test, 13)


def test_prompts_describe_each_sequence_in_its_label_and_order():
    sub = text_eval.balanced_subset(data.load_dataset("coma", "test"), 2)
    prompts = text_eval.prompts_for(sub)
    for i in range(len(sub)):
        label, kind = sub.label_of(i), sub.kind_names[sub.kinds[i]]
        assert prompts["raw"][i] == descriptions.raw_text(label)
        assert prompts["raw, held-out phrasing"][i] in descriptions.phrasings(label, "held_out")
        assert prompts["enriched"][i] == descriptions.enriched_texts(label, kind)[0]
        assert prompts["enriched, held-out phrasing"][i] in descriptions.enriched_texts(label, kind, "held_out")
        assert all(isinstance(texts[i], str) for texts in prompts.values())


def test_the_order_is_read_right_when_the_own_orders_sentence_is_nearer():
    import torch
    orders = torch.tensor([[[1.0, 0.0], [0.0, 1.0]], [[0.6, 0.8], [0.8, 0.6]]])  # (2 orders, 2 labels, D)
    outputs = torch.tensor([[1.0, 0.0], [0.8, 0.6], [1.0, 0.0]])
    right = text_eval.order_read(outputs, orders, labels=[0, 1, 0], kinds=[0, 1, 1])
    assert right.tolist() == [True, True, False]
