"""The paper's published numbers (Zou et al. 2023, §5-6, Tables 1-5), as printed, for
the chapters' tables "The paper and this book".  Accuracies in %, FIDs on the paper's
own IC features and errors in mm on real scans: not comparable in size with ours, so the
chapters compare orderings, not values.
"""

TABLE_1 = {  # label control, §5.1 (A2M, MoGAN, ACTOR: the paper's baselines)
    "ground truth": {
        "Acc (CoMA)": 83.78,
        "FID (CoMA)": 2.77,
        "Acc (BU-4DFE)": 99.51,
        "FID (BU-4DFE)": 6.02,
    },
    "A2M": {
        "Acc (CoMA)": 52.36,
        "FID (CoMA)": 29.44,
        "Acc (BU-4DFE)": 80.83,
        "FID (BU-4DFE)": 19.64,
    },
    "MoGAN": {
        "Acc (CoMA)": 80.76,
        "FID (CoMA)": 7.72,
        "Acc (BU-4DFE)": 99.26,
        "FID (BU-4DFE)": 13.29,
    },
    "ACTOR": {
        "Acc (CoMA)": 81.40,
        "FID (CoMA)": 7.11,
        "Acc (BU-4DFE)": 99.13,
        "FID (BU-4DFE)": 14.56,
    },
    "ours": {
        "Acc (CoMA)": 84.97,
        "FID (CoMA)": 6.79,
        "Acc (BU-4DFE)": 99.89,
        "FID (BU-4DFE)": 12.37,
    },
}
TABLE_2 = {  # text control, §5.2: raw text task (rtt) and enriched text task (ent)
    "ground truth": {
        "Acc (rtt)": 86.02,
        "FID (rtt)": 3.67,
        "Acc (ent)": 74.40,
        "FID (ent)": 4.56,
    },
    "MotionCLIP": {
        "Acc (rtt)": 80.67,
        "FID (rtt)": 42.19,
        "Acc (ent)": 58.33,
        "FID (ent)": 38.83,
    },
    "ours (Alg. 2)": {
        "Acc (rtt)": 82.01,
        "FID (rtt)": 9.46,
        "Acc (ent)": 64.38,
        "FID (ent)": 11.34,
    },
}
# expression filling, §5.3; the ground truth is printed once, "in all cases" (the
# caption)
TABLE_3 = {
    "ground truth": {
        "Acc (FFE)": 83.78,
        "FID (FFE)": 2.77,
        "Acc (FFM)": 83.78,
        "FID (FFM)": 2.77,
        "Acc (FFB)": 83.78,
        "FID (FFB)": 2.77,
    },
    "mean imputation": {
        "Acc (FFE)": 60.15,
        "FID (FFE)": 25.67,
        "Acc (FFM)": 56.25,
        "FID (FFM)": 17.68,
        "Acc (FFB)": 53.90,
        "FID (FFB)": 27.32,
    },
    "ours (Alg. 3)": {
        "Acc (FFE)": 67.18,
        "FID (FFE)": 5.51,
        "Acc (FFM)": 85.93,
        "FID (FFM)": 5.06,
        "Acc (FFB)": 70.31,
        "FID (FFB)": 5.22,
    },
}
TABLE_4 = {  # geometry-adaptive generation, §5.4 (type-S IC)
    "ground truth": {"Acc": 71.01, "FID": 5.57},
    "geometry-adaptive (Alg. 4)": {"Acc": 70.43, "FID": 9.26},
}
TABLE_5 = {  # landmark-guided mesh deformation, §6: mean (std) per-vertex error, mm
    "Linear": {"expression split": (0.67, 0.76), "identity split": (0.73, 0.77)},
    "CoMA": {"expression split": (0.58, 0.63), "identity split": (0.63, 0.67)},
    "S2D": {"expression split": (0.52, 0.59), "identity split": (0.55, 0.62)},
    "ours (w/o attention)": {
        "expression split": (0.54, 0.59),
        "identity split": (0.57, 0.64),
    },
    "ours": {"expression split": (0.45, 0.51), "identity split": (0.50, 0.58)},
}


def column(table, name):
    """One column of a paper table: {method: value}."""
    missing = [m for m, row in table.items() if name not in row]
    if missing:
        raise ValueError(
            f"no column {name!r} for {missing}; the columns are"
            f" {sorted(next(iter(table.values())))}"
        )
    return {m: row[name] for m, row in table.items()}
