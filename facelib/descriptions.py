"""Text descriptions of the 18 actions for text control (paper §5.2, Table 2; chapter 06).

* Raw text (the paper's "raw text" task): the label written as words, "high smile".
* Paraphrases: other ways to say the same thing, grounded in what the synthetic world's recipe of
  each label does (facelib/face/expressions.py: e.g. "lips_back" stretches and tightens the lips).
  The "train" paraphrases (the raw text first) may be used to train the text head; the
  "held_out" ones never are, and measure whether text control follows meaning, not spelling.
* Enriched text (the paper's "enriched text" task, type-S evaluation): the order of the
  expression in words, "from the neutral face to X" (N2E) and "from X to the neutral face" (E2N),
  with training and held-out sentence templates.
"""
from __future__ import annotations

from .face.expressions import ALL_LABELS, KIND_NAMES, check_label

SPLITS = ("train", "held_out")

PARAPHRASES = {  # label: (train phrasings, held-out phrasings); the raw text is added in front of train
    "bareteeth": (("baring the teeth", "showing the teeth"), ("teeth bared", "lips pulled apart to show the teeth")),
    "cheeks_in": (("sucking the cheeks in", "hollow cheeks"), ("cheeks sucked inwards", "drawing in the cheeks")),
    "eyebrow": (("raising the eyebrows", "moving the eyebrows"), ("brows lifted", "the eyebrows go up")),
    "high_smile": (("a big smile", "smiling widely"), ("a broad grin", "beaming")),
    "lips_back": (("pulling the lips back", "tight stretched lips"), ("lips drawn back tightly",
                                                                         "stretching the lips sideways")),
    "lips_up": (("raising the upper lip", "lips pushed up"), ("upper lip lifted", "curling the upper lip up")),
    "mouth_down": (("mouth corners pulled down", "a frowning mouth"), ("the corners of the mouth turn down",
                                                                        "a downturned mouth")),
    "mouth_extreme": (("mouth stretched wide open", "opening the mouth as wide as possible"),
                      ("jaw dropped wide with stretched lips", "an extremely open mouth")),
    "mouth_middle": (("puckering the lips", "lips pushed to the middle"), ("pursed lips",
                                                                          "lips drawn together into a pout")),
    "mouth_open": (("opening the mouth", "the jaw drops open"), ("an open mouth",
                                                                 "parting the lips and lowering the jaw")),
    "mouth_side": (("moving the mouth to one side", "mouth pulled sideways"), ("a lopsided mouth",
                                                                               "shifting the lips to the side")),
    "mouth_up": (("pushing the chin and lower lip up", "raising the mouth"), ("lower lip pushed upwards",
                                                                              "chin raised, lips pressed")),
    "anger": (("angry", "an angry face"), ("furious", "glaring in rage")),
    "disgust": (("disgusted", "a look of disgust"), ("revolted", "wrinkling the nose in disgust")),
    "fear": (("afraid", "a fearful face"), ("terrified", "scared")),
    "happy": (("happiness", "a happy face"), ("joyful", "delighted")),
    "sad": (("sadness", "a sad face"), ("unhappy", "sorrowful")),
    "surprise": (("surprised", "a surprised face"), ("astonished", "amazed")),
}

ENRICHED_TEMPLATES = {  # split: ((N2E template, E2N template), ...); {x} is a phrasing of the label
    "train": (("from the neutral face to {x}", "from {x} to the neutral face"),
              ("a neutral face turning into {x}", "{x} relaxing into a neutral face")),
    "held_out": (("starting neutral and ending with {x}", "starting with {x} and ending neutral"),),
}


def _check_split(split):
    if split not in SPLITS:
        raise ValueError(f"unknown description split {split!r}; allowed: {', '.join(SPLITS)}")


def raw_text(label):
    """The label as words (the paper's raw text): "high_smile" -> "high smile"."""
    return check_label(label).replace("_", " ")


def phrasings(label, split="train"):
    """Ways to describe a label: the raw text and its training paraphrases, or the held-out ones."""
    _check_split(split)
    train, held_out = PARAPHRASES[check_label(label)]
    return (raw_text(label),) + train if split == "train" else held_out


def enriched_texts(label, kind, split="train"):
    """Sentences that also say the order (N2E / E2N), from the split's templates and phrasings."""
    _check_split(split)
    if kind not in KIND_NAMES:
        raise ValueError(f"kind must be one of {KIND_NAMES}, got {kind!r}")
    column = KIND_NAMES.index(kind)
    return tuple(t[column].format(x=x) for t in ENRICHED_TEMPLATES[split] for x in phrasings(label, split))


def descriptions(label, kind, split="train"):
    """Every description of a sequence of ``label`` performed in order ``kind`` (N2E / E2N): its
    phrasings (the raw-text task) and its enriched sentences (the enriched-text task)."""
    return phrasings(label, split) + enriched_texts(label, kind, split)


assert set(PARAPHRASES) == set(ALL_LABELS), "every label needs its paraphrases"
