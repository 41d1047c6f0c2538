"""Guidance of the unconditional DDPM's reverse process (paper §3.2, App. C): what is
climbed (``scores``) and how a sampler step climbs it (``hooks``); or no classifier at
all (``classifier_free``).  See the modules' docstrings."""

from .classifier_free import ClassifierFree
from .hooks import (
    BestOfK,
    MeanShiftGuidance,
    OptimisationGuidance,
    ReconstructionGuidance,
    best_particles,
    chain,
    gradient_at,
    log_p_theta,
    steps_of,
)
from .scores import (
    AUCurveScore,
    ClassifierScore,
    ContrastiveScore,
    CosineScore,
    DenoisedCosineScore,
    match_log_weights,
    nearest_wording,
    vocabulary_log_weights,
)

__all__ = [
    "ClassifierFree",
    "BestOfK",
    "MeanShiftGuidance",
    "OptimisationGuidance",
    "ReconstructionGuidance",
    "best_particles",
    "chain",
    "gradient_at",
    "log_p_theta",
    "steps_of",
    "AUCurveScore",
    "ClassifierScore",
    "ContrastiveScore",
    "CosineScore",
    "DenoisedCosineScore",
    "match_log_weights",
    "nearest_wording",
    "vocabulary_log_weights",
]
