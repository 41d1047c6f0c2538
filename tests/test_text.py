"""Text (Alg. 2): the offline encoder (real embeddings, caching, clear errors) and the descriptions."""
import hashlib

import numpy as np
import pytest

from facelib import descriptions, text


@pytest.fixture(scope="module")
def encoder(tmp_path_factory):
    return text.TextEncoder(cache_dir=tmp_path_factory.mktemp("text_cache"))


def test_embeddings_are_unit_vectors_of_a_real_sentence_model(encoder):
    e = encoder.encode(["high smile", "a broad smile", "the eyebrows are raised", "high smile"])
    assert e.shape == (4, text.EMBEDDING_DIM) and e.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(e, axis=1), 1.0, atol=1e-5)
    assert np.array_equal(e[0], e[3])  # deterministic
    sim = e @ e.T
    assert sim[0, 1] > sim[0, 2] + 0.1  # meaning, not spelling: a paraphrase is closer than another expression
    assert text.cosine_similarity(e[0], e[1]) == pytest.approx(sim[0, 1], abs=1e-5)
    assert encoder.encode("high smile").shape == (text.EMBEDDING_DIM,)


def test_embeddings_are_cached_on_disk_and_reused_without_the_model(encoder):
    first = encoder.encode(["from the neutral face to bareteeth"])
    again = text.TextEncoder(cache_dir=encoder.cache_dir)
    assert np.array_equal(again.encode(["from the neutral face to bareteeth"]), first)
    assert again._model is None  # read from the cache: the model was never loaded
    path = again._path("from the neutral face to bareteeth")
    path.write_bytes(b"damaged")
    fresh = text.TextEncoder(cache_dir=encoder.cache_dir)
    np.testing.assert_allclose(fresh.encode("from the neutral face to bareteeth"), first[0], atol=1e-6)


def test_an_embedding_does_not_depend_on_what_is_embedded_with_it():
    # in a batch the shorter texts are padded, which changes their last bits: each text is embedded alone
    long_text = "from the neutral face to a very wide open mouth with stretched lips"
    alone = text.TextEncoder(cache_dir=None).encode(["high smile"])[0]
    batched = text.TextEncoder(cache_dir=None).encode(["high smile", long_text, "sad"])[0]
    assert np.array_equal(alone, batched)


def test_bad_text_is_refused_with_a_clear_error(encoder):
    for bad, msg in [("", "empty"), ("   ", "empty"), (3, "must be a string"), (None, "must be a string"),
                     ("smile " * 300, "at most 256")]:
        with pytest.raises(ValueError, match=msg):
            encoder.encode(bad)
    with pytest.raises(ValueError, match="no text"):
        encoder.encode([])


def test_descriptions_cover_every_label_and_keep_held_out_phrasings_apart():
    from facelib import descriptions
    from facelib.face.expressions import ALL_LABELS
    assert descriptions.raw_text("high_smile") == "high smile"
    every_train, every_held = set(), set()
    for label in ALL_LABELS:
        train, held = descriptions.phrasings(label, "train"), descriptions.phrasings(label, "held_out")
        assert train[0] == descriptions.raw_text(label) and len(train) >= 3 and len(held) >= 2
        every_train |= set(train)
        every_held |= set(held)
        for kind in ("N2E", "E2N"):
            assert all("neutral" in s for s in descriptions.enriched_texts(label, kind, "train"))
            assert set(descriptions.enriched_texts(label, kind, "train")).isdisjoint(
                descriptions.enriched_texts(label, kind, "held_out"))
    assert every_train.isdisjoint(every_held) and len(every_train) == 3 * len(ALL_LABELS)
    assert descriptions.enriched_texts("mouth_open", "N2E")[0] == "from the neutral face to mouth open"
    assert descriptions.enriched_texts("mouth_open", "E2N")[0] == "from mouth open to the neutral face"
    for call, msg in [(lambda: descriptions.phrasings("smile"), "allowed"),
                      (lambda: descriptions.phrasings("happy", "test"), "blind_held_out"),
                      (lambda: descriptions.enriched_texts("happy", "X2Y"), "N2E")]:
        with pytest.raises(ValueError, match=msg):
            call()


def test_written_blind_sets_keep_held_out_phrasings_held_out():
    # appendix A1 section 6: the vocabulary (train + the first blind writer's phrasings and templates)
    # holds no held-out phrasing, the blind held-out set no vocabulary phrasing; what was dropped is listed
    from facelib import descriptions
    from facelib.face.expressions import ALL_LABELS
    key = lambda p: " ".join(p.lower().split())  # noqa: E731
    held = {key(p) for y in ALL_LABELS for p in descriptions.phrasings(y, "held_out")}
    vocabulary = {key(p) for y in ALL_LABELS for p in descriptions.phrasings(y, "vocabulary")}
    blind = {key(p) for y in ALL_LABELS for p in descriptions.phrasings(y, "blind_held_out")}
    assert vocabulary.isdisjoint(held) and blind.isdisjoint(vocabulary)
    for y in ALL_LABELS:
        train, voc = descriptions.phrasings(y), descriptions.phrasings(y, "vocabulary")
        assert voc[:len(train)] == train and len(voc) >= len(train) + 5
        assert len(descriptions.phrasings(y, "blind_held_out")) >= 2
        written = set(descriptions.WRITTEN_VOCABULARY[y])
        assert written - set(voc) == set(descriptions.dropped("vocabulary")[y]) <= held | set(train)
        assert set(descriptions.dropped("blind_held_out")[y]) == set(descriptions.WRITTEN_BLIND_HELD_OUT[y]) - set(
            descriptions.phrasings(y, "blind_held_out"))
        for kind in ("N2E", "E2N"):
            enriched = descriptions.enriched_texts(y, kind, "vocabulary")
            assert set(descriptions.enriched_texts(y, kind)) <= set(enriched)
            assert len(enriched) == len(voc) * len(descriptions.TEMPLATES["vocabulary"])
    assert "furious" in descriptions.dropped("vocabulary")["anger"]  # written by both: stays held out
    first = descriptions.WRITTEN_BLIND_HELD_OUT_TEMPLATES[0][1].format(x=descriptions.phrasings("sad", "blind_held_out")[0])
    assert descriptions.enriched_texts("sad", "E2N", "blind_held_out")[0] == first
    spec = descriptions.writers_spec(descriptions.WRITERS_RECIPES)
    # the spec the writers saw: if the world's recipes change, the written texts describe another world
    assert hashlib.sha256(spec.encode()).hexdigest() == descriptions.WRITERS_SPEC_SHA256
    for y, seen in descriptions.WRITERS_RECIPES.items():  # since then only apex ranges changed, same AUs
        now = descriptions.RECIPES[y]
        assert [a[0] for a in seen.aus] == [a[0] for a in now.aus] and seen.variants == now.variants
    changed = [y for y in ALL_LABELS if descriptions.WRITERS_RECIPES[y] != descriptions.RECIPES[y]]
    assert changed == ["high_smile", "mouth_open"] and descriptions.writers_spec() != spec
    assert all(f"`{y}`" in spec for y in ALL_LABELS) and "AU9 nose wrinkler" in spec
    assert not any(p in spec for y in ALL_LABELS for p in descriptions.phrasings(y, "held_out"))
    with pytest.raises(ValueError, match="only the written splits"):
        descriptions.dropped("train")


def test_held_out_paraphrases_are_closer_to_their_label_than_to_others(encoder):
    # the premise of the held-out evaluation of chapter 06: the encoder maps a paraphrase nearer
    # its own label's training phrasings than most other labels' (measured, not assumed)
    from facelib import descriptions
    from facelib.face.expressions import ALL_LABELS
    train = {y: encoder.encode(list(descriptions.phrasings(y))).mean(0) for y in ALL_LABELS}
    centroids = np.stack([train[y] / np.linalg.norm(train[y]) for y in ALL_LABELS])
    hits = [int(np.argmax(centroids @ encoder.encode(p)) == i) for i, y in enumerate(ALL_LABELS)
            for p in descriptions.phrasings(y, "held_out")]
    assert np.mean(hits) > 0.6, np.mean(hits)


def test_descriptions_put_the_raw_text_first_and_keep_held_out_apart():
    train = descriptions.descriptions("high_smile", "N2E")
    assert train[0] == "high smile" and "from the neutral face to high smile" in train
    assert "from high smile to the neutral face" in descriptions.descriptions("high_smile", "E2N")
    held_out = descriptions.descriptions("high_smile", "N2E", "held_out")
    assert not set(held_out) & set(train)
    assert all(not set(descriptions.descriptions(y, k, "held_out")) & set(descriptions.descriptions(y, k))
               for y in descriptions.ALL_LABELS for k in ("N2E", "E2N"))
