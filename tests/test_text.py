"""The offline text encoder of text control (Alg. 2): real embeddings, caching, clear errors."""
import numpy as np
import pytest

from facelib import text


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


def test_bad_text_is_refused_with_a_clear_error(encoder):
    for bad, msg in [("", "empty"), ("   ", "empty"), (3, "must be a string"), (None, "must be a string"),
                     ("smile " * 300, "at most 256")]:
        with pytest.raises(ValueError, match=msg):
            encoder.encode(bad)
    with pytest.raises(ValueError, match="no text"):
        encoder.encode([])
