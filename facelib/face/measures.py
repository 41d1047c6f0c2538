"""Measurements that check the synthetic world has the properties the paper's methods
need."""

from __future__ import annotations

import re

import numpy as np

from .aus import AU_NAMES, Face, au_vector
from .identity import sample_identity


def identity_dependence(au, num_pairs=50, intensity=1.0, seed=0):
    """Relative difference of one AU's landmark displacement on random identity pairs.

    For each pair (a, b) of random identities, with d = L(w) - L(0) the landmark
    displacement of the AU at ``intensity``: ||d_a - d_b|| / (0.5 (||d_a|| + ||d_b||)).
    Returns (num_pairs,). Zero would mean that the AU moves every face the same way (a
    generic, "universal" rig).
    """
    if au not in AU_NAMES:
        raise ValueError(f"unknown action unit {au!r}; allowed: {', '.join(AU_NAMES)}")
    rng = np.random.default_rng(seed)
    w = au_vector(**{au: intensity})
    out = np.empty(num_pairs)
    for k in range(num_pairs):
        d = []
        for _ in range(2):
            face = Face(sample_identity(rng))
            d.append(face.landmarks(w) - face.landmarks(np.zeros_like(w)))
        out[k] = np.linalg.norm(d[0] - d[1]) / (
            0.5 * (np.linalg.norm(d[0]) + np.linalg.norm(d[1]))
        )
    return out


def identity_and_expression_spread(dataset):
    """(identity std, expression std) in mm of a dataset's landmarks.

    identity std: RMS over landmark coordinates of the std over subjects of the neutral
    landmarks L.  expression std: RMS of L_f - L over all frames of all sequences (the
    motion the expressions add to each subject's own neutral face).
    """
    subjects = np.unique(dataset.subjects)
    neutral = {s: dataset.neutral_landmarks(int(s)) for s in subjects}
    identity = np.sqrt(np.stack(list(neutral.values())).var(axis=0).mean())
    motion = []
    for i in range(len(dataset)):
        f = dataset.lengths[i]
        motion.append(
            (dataset.landmarks[i, :f] - neutral[dataset.subjects[i]]).reshape(-1)
        )
    expression = np.sqrt(np.mean(np.concatenate(motion) ** 2))
    return float(identity), float(expression)


# Published measurements of real faces that world 2 is calibrated to (chapter 01's
# table): measure -> (value, unit, what was measured, citation key in references.bib).
PUBLISHED = {
    "smile_corner_mm": (
        9.28,
        "mm",
        "mouth-corner excursion in a maximal smile (3D motion capture, 12 adults)",
        "jorge2012facial",
    ),
    "smile_widening_pct": (
        27.0,
        "%",
        "widening of the mouth in a spontaneous smile (video)",
        "tarantili2005smile",
    ),
    "smile_angle_deg": (
        47.0,
        "deg",
        "direction of the corners' travel above the horizontal (video)",
        "tarantili2005smile",
    ),
    "mouth_opening_mm": (
        48.8,
        "mm",
        "maximal mouth opening (140 adults)",
        "zawawi2003mouth",
    ),
    "brow_raise_mm": (
        10.57,
        "mm",
        "eyebrow lift (3D motion capture, 12 adults)",
        "jorge2012facial",
    ),
    "eye_closure_mm": (
        9.09,
        "mm",
        "eyelid travel in eye closure (3D motion capture, 12 adults)",
        "jorge2012facial",
    ),
}
# The poses that play each measure in the world (AU intensities; 1 = a strong, typical
# apex).
MEASURE_POSES = {
    "smile": {"AU6": 1.0, "AU12L": 1.0, "AU12R": 1.0},
    # expressions.MAX_INTENSITY: the maximal opening
    "mouth_opening": {"AU25": 1.0, "AU26": 1.5},
    "brow_raise": {"AU1": 1.0, "AU2": 1.0},
    "eye_closure": {"AU45": 1.0},
}
_CORNERS, _INNER_LIPS, _BROWS, _UPPER_LIDS = (
    (48, 54),
    (62, 66),
    tuple(range(17, 27)),
    (37, 38, 43, 44),
)


def face_measures(face):
    """The measures of ``PUBLISHED`` on one :class:`Face` (a dict of floats, same keys
    and units).

    Corner excursion: mean 3D displacement of the two corner landmarks.  Widening and
    angle: in the frontal (x, y) plane, as a video sees them.  Mouth opening: the
    distance between the inner-lip midpoints.  Brow raise: the mean upward motion of the
    10 brow landmarks.  Eye closure: the mean downward motion of the 4 upper-lid
    landmarks."""
    rest = face.landmarks(np.zeros(len(AU_NAMES)))
    pose = {k: face.landmarks(au_vector(**v)) for k, v in MEASURE_POSES.items()}
    smile = pose["smile"] - rest
    corners = list(_CORNERS)
    width = lambda lm: abs(lm[_CORNERS[1], 0] - lm[_CORNERS[0], 0])  # noqa: E731
    outward = np.abs(smile[corners, 0])
    return {
        "smile_corner_mm": float(np.linalg.norm(smile[corners], axis=1).mean()),
        "smile_widening_pct": float(
            100 * (width(pose["smile"]) - width(rest)) / width(rest)
        ),
        "smile_angle_deg": float(
            np.degrees(np.arctan2(smile[corners, 1], outward)).mean()
        ),
        "mouth_opening_mm": float(
            np.linalg.norm(np.subtract(*pose["mouth_opening"][list(_INNER_LIPS)]))
        ),
        "brow_raise_mm": float((pose["brow_raise"] - rest)[list(_BROWS), 1].mean()),
        "eye_closure_mm": float(
            -(pose["eye_closure"] - rest)[list(_UPPER_LIDS), 1].mean()
        ),
    }


def world_measures(world, num_identities=40, seed=0):
    """``face_measures`` on ``num_identities`` random identities of a world (1 or 2):
    {measure: (median, 10th percentile, 90th percentile)}."""
    rng = np.random.default_rng(seed)
    rows = [
        face_measures(Face(sample_identity(rng), world=world))
        for _ in range(num_identities)
    ]
    return {
        k: tuple(float(np.percentile([r[k] for r in rows], q)) for q in (50, 10, 90))
        for k in PUBLISHED
    }


def calibration_rows(worlds=(2,), num_identities=40):
    """Chapter 01's table: [measure, published value, source, then per world its median
    [10th, 90th percentile] and the ratio median / published] for every measure of
    ``PUBLISHED``."""
    ours = {w: world_measures(w, num_identities) for w in worlds}
    rows = []
    for key, (value, unit, what, source) in PUBLISHED.items():
        row = [f"{what} ({unit})", value, source]
        for w in worlds:
            median, low, high = ours[w][key]
            row += [median, [low, high], median / value]
        rows.append(row)
    return rows


def source_label(key):
    """'Jorge et al. 2012' for the references.bib key 'jorge2012facial' (every source of
    ``PUBLISHED`` has several authors)."""
    match = re.fullmatch(r"([a-z]+)(\d{4})[a-z]*", key)
    if match is None:
        raise ValueError(
            "a citation key is a name, a year and a word, like 'jorge2012facial', got"
            f" {key!r}"
        )
    return f"{match.group(1).title()} et al. {match.group(2)}"


def calibration_table(worlds=(2,), num_identities=40):
    """:func:`calibration_rows` as table cells, (columns, rows, {world: the ratios
    median / published}): measure | published | source | per world "median [10th, 90th
    percentile] (x ratio)".
    """
    columns = ["measure", "published", "source"] + [f"world {w}" for w in worlds]
    rows, ratios = [], {w: [] for w in worlds}
    for what, value, source, *ours in calibration_rows(worlds, num_identities):
        row = [what, f"{value:g}", source_label(source)]
        for w, (median, (low, high), ratio) in zip(
            worlds, zip(ours[::3], ours[1::3], ours[2::3])
        ):
            row.append(f"{median:.1f} [{low:.1f}, {high:.1f}] (x{ratio:.2f})")
            ratios[w].append(ratio)
        rows.append(row)
    return columns, rows, {w: np.array(r) for w, r in ratios.items()}
