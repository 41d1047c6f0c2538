"""Every shipped checkpoint (data/checkpoints) as the recipe that trains it
(``training.train_all`` retrains them).

``SHIPPED[name] = (model, settings)``: the model's recipe (training.RECIPES) with these
settings changed from its defaults (facelib/training/settings.py).
tests/test_training.py checks that every shipped checkpoint is here and that its
recorded settings are these, so ``python -m facelib train all`` rebuilds exactly what is
shipped.
"""

from __future__ import annotations

from ..checkpoints import checkpoint_name
from ..deformation import METHODS as DEFORMER_METHODS, SPLITS as DEFORMER_SPLITS

SHIPPED = {
    "denoiser_coma": ("denoiser", {}),
    # issue 58: not yet retrained with the temporal prior (frames independent)
    "denoiser_bu": ("denoiser", {"dataset": "bu", "temporal_prior": False}),
    "denoiser_coma+bu": ("denoiser", {"dataset": "coma+bu", "temporal_prior": False}),
    # mixed lengths: one Gaussian per frame (temporal_prior needs one length)
    "denoiser_coma_var": (
        "denoiser",
        {"num_frames": (35, 45), "temporal_prior": False},
    ),
    "guide_coma_I": ("guide", {}),
    "guide_coma_S": ("guide", {"classifier_type": "S"}),
    "guide_bu_I": ("guide", {"dataset": "bu"}),
    "guide_coma+bu_text": ("text_head", {}),
    **{
        checkpoint_name("ic", d, c): ("evaluator", {"dataset": d, "classifier_type": c})
        for d in ("coma", "bu", "coma+bu")
        for c in ("I", "S")
    },
    # issue 58: the second reader of the coverage protocol
    "ic_coma_I_cnn": ("evaluator", {"architecture": "cnn"}),
    "actor_coma": ("actor", {}),
    "actor_bu": ("actor", {"dataset": "bu"}),
    "motion3dgan_coma": ("motion3dgan", {}),
    "motion3dgan_bu": ("motion3dgan", {"dataset": "bu"}),
    "motionclip_coma+bu": ("motionclip", {}),
    "lstm_filler_coma": ("lstm_filler", {}),
    **{
        checkpoint_name("deform", m, s): ("deformer", {"method": m, "split": s})
        for m in DEFORMER_METHODS
        for s in DEFORMER_SPLITS
    },
    # Issue 25: Table 5 over three training seeds for ours, ours without attention and
    # S2D (seed 0 is above).
    **{
        checkpoint_name("deform", m, s, k): (
            "deformer",
            {"method": m, "split": s, "seed": k},
        )
        for m in ("ours", "no_attention", "s2d")
        for s in DEFORMER_SPLITS
        for k in (1, 2)
    },
    # Issue 27: the label-conditional denoiser of classifier-free guidance
    # (tasks.label_control(guidance="cfg")).
    "denoiser_coma_cfg": ("denoiser", {"conditional": True, "temporal_prior": False}),
    # Issue 28: the noisy AU-intensity regressor of AU-curve control (the fine-control
    # chapter).
    "au_regressor_coma": ("au_regressor", {}),
    # Issue 46: the rectified flow on the same network, data, steps and batch as
    # denoiser_coma (sampler "flow")
    "denoiser_coma_flow": (
        "denoiser",
        {"schedule": "flow", "prediction": "u", "temporal_prior": False},
    ),
    # Issue 47: the join denoiser of long sequences (join "learned"), fine-tuned from
    # denoiser_coma with known first frames as input (CondMDI, Cohan et al. 2024)
    "denoiser_coma_join": (
        "denoiser",
        {
            "known_frames": 0.75,
            # issue 58: the shipped join was fine-tuned from the previous, per-frame
            # denoiser_coma (it records no temporal_prior); retraining it from today's
            # gives it the temporal Gaussian
            "start_from": "denoiser_coma",
            "steps": 12_000,
            "lr": 5e-4,
            "warmup": 200,
        },
    ),
    # Issue 46: progressive distillation of denoiser_coma's DDIM chain, 256 -> 128 ->
    # ... -> 1 steps, each round's student the next round's teacher (sampler "student");
    # issue 58: the shipped students were distilled from the previous, per-frame
    # denoiser_coma
    **{
        f"student_denoiser_coma_{k}": (
            "student",
            {
                "teacher": (
                    "denoiser_coma" if k == 128 else f"student_denoiser_coma_{2 * k}"
                ),
                "teacher_steps": 2 * k,
            },
        )
        for k in (128, 64, 32, 16, 8, 4, 2, 1)
    },
    # Issue 46: the same chain for the label-conditional denoiser, its first teacher
    # guided with w = CFG_SCALE, which every student keeps (Meng et al. 2023)
    **{
        f"student_denoiser_coma_cfg_{k}": (
            "student",
            {
                "teacher": (
                    "denoiser_coma_cfg"
                    if k == 128
                    else f"student_denoiser_coma_cfg_{2 * k}"
                ),
                "teacher_steps": 2 * k,
            },
        )
        for k in (128, 64, 32, 16, 8, 4, 2, 1)
    },
}
