"""Text descriptions of the 18 actions for text control (paper §5.2, Table 2; the
text-control chapter).

* Raw text (the paper's "raw text" task): the label written as words, "high smile".
* Paraphrases: other ways to say the same thing, grounded in what the synthetic world's
  recipe of each label does (facelib/face/expressions.py: e.g. "lips_back" stretches and
  tightens the lips). The "train" paraphrases (the raw text first) may be used to train
  the text head; the "held_out" ones never are, and measure whether text control follows
  meaning, not spelling.
* Enriched text (the paper's "enriched text" task, type-S evaluation): the order of the
  expression in words, "from the neutral face to X" (N2E) and "from X to the neutral
  face" (E2N), with training and held-out sentence templates.
* Written blind (not in the paper; the vocabulary of text control): two more sets of
  phrasings and templates, each written by a writer (a language model given a fresh
  context) who saw only the labels and the action units they move
  (:func:`writers_spec`), never the texts above nor each other's.
  - "vocabulary": the train descriptions and the first writer's.  No network is trained
    on them: the contrastive score of text control can match a text against them
    (``vocabulary=True``), so that the text side knows the meaning of more ways to say a
    label.
  - "blind_held_out": the second writer's, a second evaluation set, blind to every
    training text.
  A written phrasing that is already a held-out one (for the vocabulary) or a known one
  (for the blind held-out set) is dropped, so that held-out stays held out
  (:func:`dropped` lists them).
"""

from __future__ import annotations

from dataclasses import replace

from .face.aus import AU_DESCRIPTIONS
from .face.expressions import ALL_LABELS, KIND_NAMES, RECIPES, check_label

SPLITS = ("train", "held_out", "vocabulary", "blind_held_out")

# label: (train phrasings, held-out phrasings); the raw text is added in front of train
PARAPHRASES = {
    "bareteeth": (
        ("baring the teeth", "showing the teeth"),
        ("teeth bared", "lips pulled apart to show the teeth"),
    ),
    "cheeks_in": (
        ("sucking the cheeks in", "hollow cheeks"),
        ("cheeks sucked inwards", "drawing in the cheeks"),
    ),
    "eyebrow": (
        ("raising the eyebrows", "moving the eyebrows"),
        ("brows lifted", "the eyebrows go up"),
    ),
    "high_smile": (("a big smile", "smiling widely"), ("a broad grin", "beaming")),
    "lips_back": (
        ("pulling the lips back", "tight stretched lips"),
        ("lips drawn back tightly", "stretching the lips sideways"),
    ),
    "lips_up": (
        ("raising the upper lip", "lips pushed up"),
        ("upper lip lifted", "curling the upper lip up"),
    ),
    "mouth_down": (
        ("mouth corners pulled down", "a frowning mouth"),
        ("the corners of the mouth turn down", "a downturned mouth"),
    ),
    "mouth_extreme": (
        ("mouth stretched wide open", "opening the mouth as wide as possible"),
        ("jaw dropped wide with stretched lips", "an extremely open mouth"),
    ),
    "mouth_middle": (
        ("puckering the lips", "lips pushed to the middle"),
        ("pursed lips", "lips drawn together into a pout"),
    ),
    "mouth_open": (
        ("opening the mouth", "the jaw drops open"),
        ("an open mouth", "parting the lips and lowering the jaw"),
    ),
    "mouth_side": (
        ("moving the mouth to one side", "mouth pulled sideways"),
        ("a lopsided mouth", "shifting the lips to the side"),
    ),
    "mouth_up": (
        ("pushing the chin and lower lip up", "raising the mouth"),
        ("lower lip pushed upwards", "chin raised, lips pressed"),
    ),
    "anger": (("angry", "an angry face"), ("furious", "glaring in rage")),
    "disgust": (
        ("disgusted", "a look of disgust"),
        ("revolted", "wrinkling the nose in disgust"),
    ),
    "fear": (("afraid", "a fearful face"), ("terrified", "scared")),
    "happy": (("happiness", "a happy face"), ("joyful", "delighted")),
    "sad": (("sadness", "a sad face"), ("unhappy", "sorrowful")),
    "surprise": (("surprised", "a surprised face"), ("astonished", "amazed")),
}

# split: ((N2E template, E2N template), ...); {x} is a phrasing of the label
ENRICHED_TEMPLATES = {
    "train": (
        ("from the neutral face to {x}", "from {x} to the neutral face"),
        ("a neutral face turning into {x}", "{x} relaxing into a neutral face"),
    ),
    "held_out": (
        (
            "starting neutral and ending with {x}",
            "starting with {x} and ending neutral",
        ),
    ),
}

# sha256 of writers_spec(WRITERS_RECIPES), the spec as the writers saw it: the written
# texts below describe this world.  They wrote for version 1 of the world; version 2
# (issue 25) raised only the apex ranges of two recipes, with the same action units,
# which the texts do not name (WRITERS_RECIPES keeps the ranges they saw).
WRITERS_SPEC_SHA256 = "d2c174fb531e0929f1f5e716b899ab8c2484fe4183a3577bbb069abff277bc28"
WRITERS_RECIPES = {
    **RECIPES,
    "high_smile": replace(
        RECIPES["high_smile"],
        aus=(
            ("AU6", 0.6, 1.0),
            ("AU12L", 0.8, 1.0),
            ("AU12R", 0.8, 1.0),
            ("AU25", 0.3, 0.7),
            ("AU26", 0.0, 0.2),
        ),
    ),
    "mouth_open": replace(
        RECIPES["mouth_open"], aus=(("AU25", 0.6, 1.0), ("AU26", 0.5, 0.8))
    ),
}

WRITTEN_VOCABULARY = {  # label: phrasings, as the first blind writer wrote them
    "bareteeth": (
        "all the teeth showing",
        "a toothy grimace",
        "a teeth-showing face",
        "front teeth exposed",
        "lips drawn apart over the teeth",
        "upper lip raised, lips stretched wide",
        "teeth on display",
        "a tense grimace with visible teeth",
    ),
    "cheeks_in": (
        "sucked-in cheeks",
        "hollow cheeks",
        "a fish face",
        "cheeks drawn inward",
        "a gaunt hollow-cheeked look",
        "cheeks pulled in between the teeth",
        "sucking in the cheeks",
        "cheeks pinched inward by suction",
    ),
    "eyebrow": (
        "raised brows",
        "both brows lifted",
        "brows up, mouth still",
        "a raised-brow look",
        "arched brows with a still mouth",
        "brows lifted high on the forehead",
        "only the brows moving",
        "a quick brow lift",
    ),
    "high_smile": (
        "a big toothy grin",
        "the broadest possible smile",
        "mouth corners pulled way up",
        "an exaggerated open-lipped smile",
        "grinning hard with lips apart",
        "a wide beaming grin",
        "a maximal grin",
        "cheeks pushed up by a huge grin",
    ),
    "lips_back": (
        "lips pressed thin and stretched",
        "a tight flat-lipped stretch",
        "closed lips drawn taut sideways",
        "lips pulled taut toward the ears",
        "a thin straight-line mouth",
        "pressed lips pulled wide",
        "a tense closed-mouth stretch",
        "lips flattened against the teeth",
    ),
    "lips_up": (
        "top lip curled toward the nose",
        "upper lip lifted in a pout",
        "lips pushed up toward the nostrils",
        "a raised, pursed upper lip",
        "a snout-like lip lift",
        "a pouty upward lip curl",
        "lips bunched up under the nose",
        "upper lip hitched upward, lips pursed",
    ),
    "mouth_down": (
        "mouth corners turned down",
        "an upside-down smile",
        "corners of the lips pulled down",
        "a downturned mouth",
        "lip corners dragged toward the chin",
        "a horseshoe-shaped mouth",
        "an exaggerated mouth-corner droop",
        "an inverted u mouth",
    ),
    "mouth_extreme": (
        "the widest possible open mouth",
        "jaw dropped all the way",
        "a huge gaping mouth",
        "maximal jaw opening",
        "an enormous yawn-like gape",
        "mouth stretched open to the limit",
        "lips stretched around a fully dropped jaw",
        "jaw hanging as low as it goes",
    ),
    "mouth_middle": (
        "puckered lips",
        "a kissy face",
        "pursed lips pushed forward",
        "whistling lips",
        "lips gathered tight at the center",
        "lips ready to blow a kiss",
        "a small round pucker",
        "lips pouted straight out",
    ),
    "mouth_open": (
        "lips parted, jaw lowered",
        "a slack open mouth",
        "jaw dropped halfway",
        "an open-mouthed face",
        "a relaxed open jaw",
        "saying ah",
        "lips apart and jaw loosely down",
        "a moderately opened mouth",
    ),
    "mouth_side": (
        "jaw shifted to one side",
        "lower face skewed to the side",
        "lips pushed toward one cheek",
        "jaw slid sideways",
        "a lopsided mouth",
        "mouth moved off-center",
        "a sideways mouth twist",
        "one lip corner pulled, jaw shifted over",
    ),
    "mouth_up": (
        "lower lip pushed up",
        "chin raised, lips pressed",
        "a bulging chin pout",
        "lower lip pressed against the upper",
        "a puckered dimpled chin",
        "a pressed-lip pout",
        "chin muscle bunched up",
        "a stubborn closed-mouth pout",
    ),
    "anger": (
        "angry",
        "furious",
        "a glaring face",
        "rage",
        "an irate scowl",
        "lowered brows and tightly pressed lips",
        "a fierce glare with tight lips",
        "enraged",
    ),
    "disgust": (
        "disgusted",
        "grossed out",
        "revulsion",
        "wrinkled nose and raised upper lip",
        "a repulsed face",
        "an expression of distaste",
        "a yuck face",
        "loathing",
    ),
    "fear": (
        "scared",
        "afraid",
        "terrified",
        "a frightened face",
        "panic",
        "wide eyes, raised brows, stretched lips",
        "dread",
        "eyes wide, lips pulled tense",
    ),
    "happy": (
        "joyful",
        "cheerful",
        "delighted",
        "a glad face",
        "pleased",
        "a warm contented smile",
        "happiness",
        "cheeks lifted in a gentle smile",
    ),
    "sad": (
        "sorrowful",
        "a gloomy face",
        "grief",
        "downcast",
        "tilted brows and drooping mouth corners",
        "on the verge of tears",
        "a mournful look",
        "heartbroken",
    ),
    "surprise": (
        "astonished",
        "amazed",
        "shocked",
        "a startled face",
        "brows up, eyes wide, jaw dropped",
        "a stunned open-mouthed look",
        "caught off guard",
        "a jaw-dropping wow",
    ),
}
WRITTEN_VOCABULARY_TEMPLATES = (  # (N2E, E2N), as the first blind writer wrote them
    ("neutral first, then {x}", "{x} first, then neutral"),
    (
        "a neutral face that gradually shifts into {x}",
        "a face that begins with {x} and settles back to neutral",
    ),
    ("{x}, building up from a resting face", "{x}, fading back to a resting face"),
    ("begin relaxed, end with {x}", "begin with {x}, end relaxed"),
)

WRITTEN_BLIND_HELD_OUT = {  # label: phrasings, as the second blind writer wrote them
    "bareteeth": (
        "show all your teeth",
        "pull the lips back to bare teeth",
        "teeth bared, lips stretched apart",
        "flash both rows of teeth",
    ),
    "cheeks_in": (
        "suck in your cheeks",
        "hollow cheeks",
        "fish face",
        "cheeks drawn in between the teeth",
    ),
    "eyebrow": (
        "raise your eyebrows",
        "lift both brows high",
        "move only the eyebrows",
        "brows up, mouth stays still",
    ),
    "high_smile": (
        "big toothy grin",
        "grin from ear to ear",
        "huge smile with lips open",
        "smile as wide as you can",
    ),
    "lips_back": (
        "thin lips pressed and pulled back",
        "lips stretched tight and flat",
        "press lips closed, stretch them wide",
        "tight-lipped sideways stretch",
    ),
    "lips_up": (
        "curl the lips up toward the nose",
        "pout with the upper lip lifted",
        "lips pushed up and out",
        "upper lip raised, no nose wrinkle",
    ),
    "mouth_down": (
        "pull the mouth corners down",
        "upside-down smile",
        "mouth corners down, brows relaxed",
        "exaggerated frown with the lips",
    ),
    "mouth_extreme": (
        "open your mouth as wide as possible",
        "jaw dropped all the way down",
        "maximum mouth stretch",
        "mouth stretched open to the limit",
    ),
    "mouth_open": (
        "open your mouth",
        "lips apart, jaw relaxed down",
        "drop the jaw halfway",
        "mouth comfortably open",
    ),
    "mouth_middle": (
        "pucker up",
        "kiss face",
        "purse the lips forward",
        "lips pushed out in a tight pout",
    ),
    "mouth_side": (
        "shift the mouth to one side",
        "jaw slid sideways",
        "lopsided mouth pulled toward one cheek",
        "push the lips over to the side",
    ),
    "mouth_up": (
        "push the chin up",
        "lower lip pressed up, chin wrinkled",
        "bunch up the chin",
        "press the lower lip into the upper",
    ),
    "anger": (
        "angry",
        "furious",
        "glaring with lowered brows",
        "scowl with lips pressed tight",
    ),
    "disgust": (
        "disgusted",
        "grossed out",
        "wrinkle your nose in distaste",
        "yuck face",
    ),
    "fear": (
        "scared",
        "terrified",
        "frightened look",
        "eyes wide with dread, lips stretched",
    ),
    "happy": ("happy", "cheerful", "joyful face", "warm smile with crinkled eyes"),
    "sad": (
        "sad",
        "sorrowful",
        "unhappy and downcast",
        "inner brows up, mouth turned down",
    ),
    "surprise": (
        "surprised",
        "astonished",
        "caught off guard",
        "brows shoot up, eyes wide, jaw drops",
    ),
}
# (N2E, E2N), as the second blind writer wrote them
WRITTEN_BLIND_HELD_OUT_TEMPLATES = (
    (
        "start from a neutral face, then {x}",
        "start with {x}, then relax back to neutral",
    ),
    (
        "begin relaxed and move into this: {x}",
        "begin with this: {x}, and return to a relaxed face",
    ),
)


def _check_split(split):
    if split not in SPLITS:
        raise ValueError(
            f"unknown description split {split!r}; allowed: {', '.join(SPLITS)}"
        )


def raw_text(label):
    """The label as words (the paper's raw text): "high_smile" -> "high smile"."""
    return check_label(label).replace("_", " ")


def _key(text):
    return " ".join(text.lower().split())


def _kept(written, taken):
    """The written phrasings of every label that are not already in ``taken`` (a set of
    _key)."""
    return {
        label: tuple(p for p in written[label] if _key(p) not in taken)
        for label in ALL_LABELS
    }


def _phrasing_table():
    """Every split's phrasings of every label: {split: {label: phrasings}}."""
    train = {y: (raw_text(y),) + PARAPHRASES[y][0] for y in ALL_LABELS}
    held_out = {y: PARAPHRASES[y][1] for y in ALL_LABELS}
    added = _kept(
        WRITTEN_VOCABULARY,
        {_key(p) for table in (train, held_out) for v in table.values() for p in v},
    )
    vocabulary = {y: train[y] + added[y] for y in ALL_LABELS}
    blind = _kept(
        WRITTEN_BLIND_HELD_OUT, {_key(p) for v in vocabulary.values() for p in v}
    )
    return {
        "train": train,
        "held_out": held_out,
        "vocabulary": vocabulary,
        "blind_held_out": blind,
    }


_PHRASINGS = _phrasing_table()
TEMPLATES = {
    **ENRICHED_TEMPLATES,
    "vocabulary": ENRICHED_TEMPLATES["train"] + WRITTEN_VOCABULARY_TEMPLATES,
    # every split's (N2E, E2N) templates
    "blind_held_out": WRITTEN_BLIND_HELD_OUT_TEMPLATES,
}


def phrasings(label, split="train"):
    """Ways to describe a label in a split: "train" (the raw text first, then its
    paraphrases), "held_out", "vocabulary" (train's, then the first blind writer's) or
    "blind_held_out".
    """
    _check_split(split)
    return _PHRASINGS[split][check_label(label)]


def dropped(split):
    """{label: the written phrasings that ``split`` leaves out}: for the vocabulary,
    those that are held-out phrasings (of any label; one that repeats a train phrasing
    is in it anyway), for the blind held-out set, those that the vocabulary holds."""
    if split not in ("vocabulary", "blind_held_out"):
        raise ValueError(
            "only the written splits drop phrasings: vocabulary or blind_held_out, got"
            f" {split!r}"
        )
    written = WRITTEN_VOCABULARY if split == "vocabulary" else WRITTEN_BLIND_HELD_OUT
    kept = {_key(p) for v in _PHRASINGS[split].values() for p in v}
    return {y: tuple(p for p in written[y] if _key(p) not in kept) for y in ALL_LABELS}


def enriched_texts(label, kind, split="train"):
    """Sentences that also say the order (N2E / E2N), from the split's templates and
    phrasings."""
    _check_split(split)
    if kind not in KIND_NAMES:
        raise ValueError(f"kind must be one of {KIND_NAMES}, got {kind!r}")
    column = KIND_NAMES.index(kind)
    return tuple(
        t[column].format(x=x) for t in TEMPLATES[split] for x in phrasings(label, split)
    )


def in_order(text, kind):
    """Any description said in an order (N2E / E2N) by the first train template: "a
    broad grin" -> "from the neutral face to a broad grin" (N2E)."""
    if kind not in KIND_NAMES:
        raise ValueError(f"kind must be one of {KIND_NAMES}, got {kind!r}")
    return ENRICHED_TEMPLATES["train"][0][KIND_NAMES.index(kind)].format(x=text)


def descriptions(label, kind, split="train"):
    """Every description of a sequence of ``label`` performed in order ``kind`` (N2E /
    E2N): its phrasings (the raw-text task) and its enriched sentences (the
    enriched-text task).
    """
    return phrasings(label, split) + enriched_texts(label, kind, split)


def writers_spec(recipes=None):
    """What the blind writers of the "vocabulary" and "blind_held_out" texts were shown:
    each label, its raw text and the action units the synthetic world moves for it
    (markdown), from ``recipes`` (default: the world's, face.RECIPES; WRITERS_RECIPES:
    as the writers saw them)."""
    recipes = RECIPES if recipes is None else recipes
    lines = [
        "# The 18 facial actions of the synthetic face world",
        "",
        (
            "Each label is one facial action performed by a subject. The first 12 are"
            " CoMA-style instructions (a person is asked to make a face), the last 6"
            " are the basic emotions of BU-4DFE. For each: the label's raw text (the"
            " label name written as words) and the action units (FACS) the synthetic"
            " world moves, with their apex intensity ranges (1 = a strong typical"
            " apex)."
        ),
        "",
    ]

    def aus(ranges):
        return ", ".join(
            f"{n} {AU_DESCRIPTIONS[n]} ({lo:g}-{hi:g})" for n, lo, hi in ranges
        )

    for label in ALL_LABELS:
        lines.append(
            f'- `{label}` (raw text: "{raw_text(label)}"): {aus(recipes[label].aus)}'
        )
        lines += [
            f"  - variant, for {int(p * 100)} % of subjects: {aus(v)}"
            for p, v in recipes[label].variants
        ]
    lines += [
        "",
        (
            "Sequences are either N2E (from the neutral face to the expression's apex)"
            " or E2N (from the apex back to the neutral face)."
        ),
    ]
    return "\n".join(lines)


assert (
    set(PARAPHRASES)
    == set(ALL_LABELS)
    == set(WRITTEN_VOCABULARY)
    == set(WRITTEN_BLIND_HELD_OUT)
), "every label needs its phrasings"
