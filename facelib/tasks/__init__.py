"""The paper's sampling tasks (§3.2, App. C), one module each, all on one unconditional
DDPM: it is never retrained, only its reverse process is guided (classifier-free label
control, not in the paper, samples a label-conditional denoiser instead).

* ``unconditional``: §3.1
* ``label``: label control, Alg. 1
* ``text``: text control, Alg. 2
* ``decoder``: a text decoder's sequence refined by the DDPM
* ``fill``: expression filling, Alg. 3
* ``geometry``: geometry-adaptive generation, Alg. 4
* ``edit``: a given sequence inverted by DDIM and regenerated under label control (not
  in the paper)
* ``au``: AU-curve control: action units that follow requested intensity curves (not in
  the paper)
* ``keyframes``: chosen landmarks at chosen frames, a natural sequence around them (not
  in the paper)
* ``long``: sequences of any length from a schedule of labels, windows joined by
  expression filling (not in the paper)
* ``loading``: the trained denoiser and guidance networks they sample with
* ``settings``: each task's settings (``tasks.LabelControl()``, ...)

Every task is called as ``task(what, n, settings, models..., progress, **overrides)``:
``settings`` is the task's frozen dataclass in facelib/tasks/settings.py (the book's
recommended values; ``.paper()`` the paper's printed algorithm, ``.fast()`` a few
steps) and ``overrides`` change single fields, e.g. ``tasks.label_control("high_smile",
16, steps=100)``.
"""

from .au import (
    AU_GUIDANCE_OFF,
    active_aus,
    au_control,
    curve_errors,
    data_ranges,
    fitted_curves,
    measurable_aus,
    never_together,
    parse_curve,
    regressor_curves,
    requested_aus,
    requested_curves,
)
from . import long
from .decoder import decoder_then_diffusion
from .edit import check_sequences, edit, invert, keep_on_path
from .fill import fill
from .keyframes import (
    check_keys,
    key_errors,
    key_speeds,
    keyframe_report,
    keyframes,
    read_constraints,
    real_speed_p95,
)
from .geometry import geometry_adaptive, geometry_passes, order_sensitive_label
from .label import (
    check_labels,
    label_control,
    label_sampler,
    load_conditional_denoiser,
)
from .loading import (
    TrainedDenoiser,
    TrainedGuide,
    check_same_space,
    load_au_regressor,
    denoiser_name,
    load_denoiser,
    shipped_students,
    load_guide,
    load_text_head,
)
from .text import text_control, text_score
from .unconditional import unconditional
from .settings import (
    adagrad_lr,
    step_scaled_lr,
    text_guidance_weight,
    text_lr,
    AUControl,
    DecoderThenDiffusion,
    Edit,
    Fill,
    GeometryAdaptive,
    Keyframes,
    LabelControl,
    Long,
    Sampling,
    TextControl,
    Unconditional,
)

__all__ = [
    "AUControl",
    "DecoderThenDiffusion",
    "Edit",
    "Fill",
    "GeometryAdaptive",
    "Keyframes",
    "LabelControl",
    "Long",
    "Sampling",
    "TextControl",
    "Unconditional",
    "long",
    "check_keys",
    "key_errors",
    "key_speeds",
    "keyframe_report",
    "keyframes",
    "read_constraints",
    "real_speed_p95",
    "AU_GUIDANCE_OFF",
    "au_control",
    "curve_errors",
    "data_ranges",
    "fitted_curves",
    "measurable_aus",
    "never_together",
    "parse_curve",
    "requested_curves",
    "regressor_curves",
    "load_au_regressor",
    "active_aus",
    "requested_aus",
    "decoder_then_diffusion",
    "check_sequences",
    "edit",
    "invert",
    "keep_on_path",
    "check_labels",
    "label_sampler",
    "load_conditional_denoiser",
    "fill",
    "geometry_adaptive",
    "geometry_passes",
    "order_sensitive_label",
    "adagrad_lr",
    "label_control",
    "step_scaled_lr",
    "TrainedDenoiser",
    "TrainedGuide",
    "check_same_space",
    "denoiser_name",
    "load_denoiser",
    "shipped_students",
    "load_guide",
    "load_text_head",
    "text_control",
    "text_guidance_weight",
    "text_lr",
    "text_score",
    "unconditional",
]
