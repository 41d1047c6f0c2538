"""``python -m facelib sample TASK``: one subcommand per task, dispatched through one
registry (:data:`TASKS`).

Every option of a task is generated from a field of the task's settings dataclass
(facelib/tasks/settings.py, whose defaults are the book's best measured settings;
``--paper`` the paper's), with its help (:data:`FIELD_HELP`) and its default, so that
the command line reaches every setting; only the fields in :data:`INTERNAL` (set from
the input) have no option. A task's own inputs (``--label``, ``--input``, ...) are
listed in its registry entry. Each output ``.npz`` records the settings used and the
sha256 of every checkpoint loaded to make it.
"""

from __future__ import annotations

import argparse
import json
import zipfile
import zlib
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Callable

import numpy as np

from . import checkpoints, config, data, inpainting, tasks
from .face.sequences import MAX_FRAMES, MIN_FRAMES
from .training.loop import device_for

# one text per field name: a field means the same in every task's settings
FIELD_HELP = {
    "steps": "reverse steps, respaced from T = 2000 ('none': all T)",
    "num_frames": "frames per sequence",
    "seed": "the random seed (one random stream per chain)",
    "dataset": "the data the networks were trained on",
    "variance": (
        "the DDPM sampler's sigma_t^2: beta_t (the paper's) or the posterior beta~_t"
        " ('none': the denoiser's own; DDIM's is eta^2 beta~_t)"
    ),
    "spacing": (
        "where a chain of K steps puts them: uniform (1, ..., T; the book's) or"
        " trailing (T/K, ..., T; Lin et al. 2024)"
    ),
    "sampler": (
        "the reverse step: DDPM's ancestral step (Eq. 5), DDIM's, a distilled"
        " student's (--steps: one it was distilled for) or the rectified flow's"
        " Euler step (chapter 14)"
    ),
    "eta": "DDIM's noise, in [0, 1] (0: deterministic)",
    "join": (
        "how windows join: fill (the shared frames known, with reconstruction"
        " guidance), replace (Alg. 3 as printed), handshake (DoubleTake: all windows"
        " at once, shared frames averaged), concat (independent windows), learned"
        " (fill by a join denoiser, which reads the known frames)"
    ),
    "transition": "frames each window shares with the one before (at the native rate)",
    "fps": "frames per second written",
    "opening": (
        "a label segment's first window is guided by the type-S classifier as this"
        " order ('none': by the type-I classifier, as the segment's other windows)"
    ),
    "opening_lr": "Adagrad learning rate of a segment's first window",
    "text_dataset": (
        "the data of a schedule with a text: its denoiser and text head (labels read"
        " as their raw text)"
    ),
    "text_opening": (
        "a text segment's first window guided by its text said in this order ('from"
        " the neutral face to ...'; 'none': as written)"
    ),
    "text_guidance_weight": (
        "lambda of Alg. 2 for a schedule's texts ('none': text control's)"
    ),
    "text_lr": (
        "Adagrad learning rate of a schedule's texts ('none': text control's for the"
        " steps)"
    ),
    "feather": (
        "shift the frames next to the known ones by the known ones' gap to the model's"
        " estimate, a Gaussian's sigma in frames (0: Alg. 3 as printed)"
    ),
    "guide_continuation": (
        "guide a segment's later windows by the type-I classifier too (default: they"
        " continue unguided)"
    ),
    "guidance": (
        "classifier: a noisy classifier steers the unconditional denoiser (the"
        " paper's); cfg: classifier-free guidance of the label-conditional denoiser"
        " denoiser_<dataset>_cfg"
    ),
    "classifier_type": (
        "the guidance classifier's type: I = label (Alg. 1), S = label x N2E/E2N"
    ),
    "method": (
        "classifier guidance by adagrad (Alg. 1's steps) or mean_shift ('none': adagrad"
        " with the ddpm sampler, mean_shift with ddim)"
    ),
    "guidance_weight": "lambda of Alg. 1-2, the weight of log p_theta",
    "lr": (
        "Adagrad learning rate of the guidance ('none': the book's choice for the"
        " dataset and the steps)"
    ),
    "scale": (
        "the mean shift's gradient scale s, or CFG's weight w >= 0 ('none': the book's"
        " choice)"
    ),
    "refine": "fixed-point iterations per inversion step (0: the plain DDIM inversion)",
    "keep": (
        "frames kept as given, as 0-based ranges ('0:1': the neutral frame of an N2E"
        " sequence; 'none': every frame is regenerated)"
    ),
    "score": (
        "what Alg. 2 climbs: the cosine of Eq. 10 or the text head's log-probability of"
        " the text among the training descriptions"
    ),
    "head_input": "what the head reads: x_t (Alg. 2) or the denoiser's estimate x0_hat",
    "vocabulary": (
        "with --score contrastive: match the text against every description known, also"
        " those no network has seen"
    ),
    "particles": (
        "best-of-K: K guided chains per sequence, the head keeps one at the time label"
        " --select-time"
    ),
    "select_time": "the time label where best-of-K picks",
    "max_time": (
        "leave the steps above this time label unguided ('none': guide every step)"
    ),
    "start": "the step of the paper's chain the decoder's sequence is re-noised to",
    "reconstruction_scale": "reconstruction guidance zeta (0: none)",
    "resample": "RePaint's resampling r (1: none)",
    "order": (
        "neutral face first (N2E) or last (E2N) ('none': N2E unless the label says)"
    ),
    "passes": "harmonising passes of Alg. 4",
    "renoise_step": (
        "the step a pass after the first re-noises to ('none': T, as Alg. 4)"
    ),
    "tolerance": "tau of log N(curve | R(x, t), tau^2), in intensity units",
    "read": "what the AU regressor reads: x0_hat, the denoiser's estimate, or x_t",
    "au_weight": "the weight of the AU score (0: AU guidance off)",
}
TASK_HELP = {
    (
        "keyframes",
        "method",
    ): "replace (Alg. 3 on coordinates), reconstruction (guidance) or both",
    ("text", "guidance_weight"): (
        "lambda of Alg. 2, the weight of log p_theta ('none': the book's choice "
        "for the score)"
    ),
    ("geometry", "lr"): "Adagrad learning rate of the guidance",
    ("au", "method"): "adagrad (Alg. 1's steps) or mean_shift",
    ("au", "scale"): "the mean shift's gradient scale s",
    ("au", "lr"): "Adagrad learning rate ('none': the book's choice for the steps)",
}
CHOICES = {
    "variance": ("beta", "posterior"),
    "sampler": config.SAMPLERS,
    "spacing": config.SPACINGS,
    "dataset": data.DATASET_NAMES,
    "guidance": config.LABEL_GUIDANCE,
    "classifier_type": data.CLASSIFIER_TYPES,
    "method": config.GUIDANCE_METHODS,
    "score": config.TEXT_SCORES,
    "head_input": config.HEAD_INPUTS,
    "read": config.HEAD_INPUTS,
    "order": data.KIND_NAMES,
    "join": config.JOIN_METHODS,
    "opening": data.KIND_NAMES,
    "text_opening": data.KIND_NAMES,
}
TASK_CHOICES = {("keyframes", "method"): config.KEYFRAME_METHODS}
INPUT_LENGTH = ("fill", "edit")  # tasks whose sequences have the input's length
# fields without an option: the input's length; a long sequence's windows have the
# model's
INTERNAL = {(task, "num_frames") for task in (*INPUT_LENGTH, "long")}
ALIASES = {"num_frames": ("--length",)}
KEYFRAMES = (
    "keyframes --constraints keys.json --out out.npz: sequences that meet landmark"
    ' keyframes. keys.json: {"neutral": [[x, y, z], ... 68 rows] (optional, mm; frame 0'
    ' is then that face), "keys": [{"frame": 25, "landmark": 54, "displacement": [0, 8,'
    ' 0]}, {"frame": 10, "landmark": 8, "position": [x, y, z]}]}: frames from 0,'
    " iBUG-68 landmark indices, positions in mm, displacements in mm from the neutral"
    " face"
)
LONG = (
    "long --schedule 'high_smile:3s, neutral:1s, \"a broad grin\":2s' --neutral"
    " face.npz --out long.npz: one sequence of any length, made window by window"
    " (each the model's length,"
    " overlapping the one before by --transition frames, joined by --join) at"
    f" {config.NATIVE_FPS} frames per second and written at --fps"
    f" ({config.LONG_FPS_RANGE[0]}..{config.LONG_FPS_RANGE[1]}); at most"
    f" {config.LONG_MAX_SECONDS} s"
)
EDIT = (
    "edit --input seq.npz --label X --out edited.npz: each sequence is inverted by DDIM"
    " (eta = 0) to the x_T the chain regenerates it from, then regenerated from there"
    " with label guidance towards X: its identity and timing are kept, its expression"
    " changes; the neutral frame is kept unless --keep says otherwise (not in the"
    " paper)"
)


def read_npz_array(path, keys, what):
    """The first of ``keys`` found in an .npz, as float64 (a clear error naming the file
    and the keys otherwise, and for a file that is not an .npz, is cut short, or holds
    something else than real numbers).
    """
    try:
        with np.load(path) as f:
            if not hasattr(f, "keys"):  # a .npy file: one array, no keys
                raise ValueError("not an .npz archive")
            for key in keys:
                if key in f:
                    return inpainting.landmark_array(f[key], repr(key))
            found = list(f.keys())
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        raise ValueError(f"cannot read {what} from {path}: {e}") from None
    raise ValueError(
        f"{path} has no {' or '.join(repr(k) for k in keys)} array ({what}); it has"
        f" {found}"
    )


def _sequences(args, what):
    x = read_npz_array(args.input, ["landmarks"], what)
    if x.ndim not in (3, 4) or x.shape[-2:] != (68, 3) or 0 in x.shape:
        raise ValueError(
            f"{args.input}: 'landmarks' must be (F, 68, 3) or (n, F, 68, 3) in mm, got"
            f" {x.shape}"
        )
    if not MIN_FRAMES <= x.shape[-3] <= MAX_FRAMES:
        raise ValueError(
            f"{args.input}: 'landmarks' has {x.shape[-3]} frames; a sequence has"
            f" {MIN_FRAMES} to {MAX_FRAMES}"
        )
    return x


def _neutral(path):
    return read_npz_array(path, ["neutral", "landmarks"], "the neutral landmarks")


def _unconditional(args, s, den):
    return tasks.unconditional(args.n, s, den), {}


def _label(args, s, den):
    return tasks.label_control(args.label, args.n, s, den), {
        "labels": [args.label] * args.n
    }


def _text(args, s, den):
    return tasks.text_control(args.text, args.n, s, den), {
        "texts": [args.text] * args.n
    }


def _decoder(args, s, den):
    return tasks.decoder_then_diffusion(args.text, args.n, s, den), {
        "texts": [args.text] * args.n
    }


def _fill(args, s, den):
    given = _sequences(args, "the sequence to fill")
    known = inpainting.parse_known(args.known, given.shape[-3])
    return tasks.fill(given, known, s, den), {"known": known}


def _geometry(args, s, den):
    labels = [tasks.order_sensitive_label(args.label, s.order)] * args.n
    return tasks.geometry_adaptive(_neutral(args.neutral), labels, args.n, s, den), {
        "labels": labels
    }


def _edit(args, s, den):
    given = tasks.check_sequences(_sequences(args, "the sequences to edit"))
    edited = tasks.edit(given, args.label, replace(s, num_frames=given.shape[1]), den)
    return edited, {"labels": [args.label] * len(edited)}


def _au(args, s, den):
    neutral = None if args.neutral is None else _neutral(args.neutral)
    return tasks.au_control(args.curve, args.n, neutral, s, den), {"curves": args.curve}


def _keyframes(args, s, den):
    keys, neutral = tasks.read_constraints(args.constraints)
    return tasks.keyframes(keys, args.n, neutral, s, den), {}


def _long_dataset(args, s):
    """A schedule with a text runs on the text head's data."""
    return tasks.long.schedule_dataset(s, args.schedule or [])


def _long(args, s, den):
    if (args.schedule is None) == (args.seconds is None):
        raise ValueError("give either --schedule or --seconds (not both)")
    face = None if args.neutral is None else _neutral(args.neutral)
    schedule = (
        tasks.long.read_schedule(args.schedule, s)
        if args.schedule is not None
        else tasks.long.free_schedule(args.seconds, s.transition)
    )
    x = tasks.long.long_sequence(face, schedule, args.n, s, den)
    return x, {
        "schedule": json.dumps([asdict(segment) for segment in schedule]),
        "native_fps": tasks.long.NATIVE_FPS,
    }


LABEL = (
    ("--label",),
    dict(required=True, help="an expression label of the dataset, e.g. high_smile"),
)
TEXT = (
    ("--text",),
    dict(
        required=True,
        help=(
            'what to show, e.g. "disgust high smile" or "from the neutral face '
            'to bareteeth"'
        ),
    ),
)


@dataclass(frozen=True)
class Task:
    """A sampling task of the command line: what it does, its settings
    (tasks/settings.py), how it runs, its own inputs."""

    description: str
    settings: object
    # (args, settings, denoiser) -> (landmarks (n, F, 68, 3) in mm, extra arrays to
    # store)
    run: Callable
    inputs: tuple = ()  # ((flags...), argparse keywords) of the task's own inputs
    in_paper: bool = True  # --paper: the paper's printed algorithm
    takes_n: bool = True
    default_n: int = 16  # --n's default
    usage: str | None = None
    # (args, settings) -> the data of the denoiser, when the inputs decide it (None:
    # settings.dataset)
    dataset: Callable | None = None


TASKS = {
    "unconditional": Task(
        "the unconditional DDPM (§3.1)", tasks.Unconditional(), _unconditional
    ),
    "label": Task("label control (Alg. 1)", tasks.LabelControl(), _label, (LABEL,)),
    "text": Task("text control (Alg. 2)", tasks.TextControl(), _text, (TEXT,)),
    "decoder": Task(
        "a text decoder's sequence refined by the DDPM (not in the paper)",
        tasks.DecoderThenDiffusion(),
        _decoder,
        (TEXT,),
    ),
    "fill": Task(
        "expression filling (Alg. 3)",
        tasks.Fill(),
        _fill,
        (
            (
                ("--input",),
                dict(
                    required=True,
                    help=(
                        ".npz whose 'landmarks' (F, 68, 3) or (n, F, 68, 3) holds the "
                        "sequence(s) to complete"
                    ),
                ),
            ),
            (
                ("--known",),
                dict(
                    required=True,
                    help="known frames as 0-based ranges, e.g. 0:10,30:40",
                ),
            ),
        ),
        takes_n=False,
    ),
    "geometry": Task(
        "geometry-adaptive generation of a given face (Alg. 4)",
        tasks.GeometryAdaptive(),
        _geometry,
        (
            (
                ("--label",),
                dict(
                    required=True,
                    help="an expression label, e.g. mouth_open, or 'mouth_open E2N'",
                ),
            ),
            (
                ("--neutral",),
                dict(
                    required=True,
                    help=(
                        ".npz with the neutral landmarks (68, 3) in mm (key 'neutral'"
                        " or 'landmarks')"
                    ),
                ),
            ),
        ),
    ),
    "edit": Task(
        "change the expression of a given sequence: DDIM inversion, then label control"
        " (not in the paper)",
        tasks.Edit(),
        _edit,
        (
            LABEL,
            (
                ("--input",),
                dict(
                    required=True,
                    help=(
                        ".npz whose 'landmarks' (F, 68, 3) or (n, F, 68, 3) in mm holds"
                        " the sequence(s) to edit"
                    ),
                ),
            ),
        ),
        in_paper=False,
        takes_n=False,
        usage=EDIT,
    ),
    "au": Task(
        "AU-curve control: action units that follow requested intensity curves (not in"
        " the paper)",
        tasks.AUControl(),
        _au,
        (
            (
                ("--curve",),
                dict(
                    action="append",
                    required=True,
                    help=(
                        "an AU curve NAME:value@frame,... (frames from 0, linear"
                        " between keys) or NAME:value (constant), e.g."
                        " AU12:0@0,0.8@20,0@39 --curve AU26:0; NAME is an AU of the"
                        " world (AU1 ... AU45) or AU12 (both lip corners); repeat it"
                    ),
                ),
            ),
            (
                ("--neutral",),
                dict(
                    default=None,
                    help=(
                        ".npz with the neutral landmarks (68, 3) in mm of the face to"
                        " animate (key 'neutral' or 'landmarks'), which is then frame 0"
                        " (default: the model draws the face too)"
                    ),
                ),
            ),
        ),
        in_paper=False,
    ),
    "long": Task(
        "any length: windows joined into one sequence that follows a schedule of"
        " labels (not in the paper)",
        tasks.Long(),
        _long,
        (
            (
                ("--schedule",),
                dict(
                    default=None,
                    help=(
                        "what the face does and for how long, e.g. 'high_smile:3s,"
                        ' neutral:1s, "a broad grin":2s\': labels of the dataset,'
                        " neutral (the given face at rest), free (unguided) or a text"
                        " in quotes (then on --text-dataset, every segment by Alg."
                        " 2), seconds each"
                    ),
                ),
            ),
            (
                ("--seconds",),
                dict(
                    default=None,
                    type=float,
                    help="this many seconds of unguided motion (instead of --schedule)",
                ),
            ),
            (
                ("--neutral",),
                dict(
                    default=None,
                    help=(
                        ".npz with the neutral landmarks (68, 3) in mm of the face"
                        " (key 'neutral' or 'landmarks'), its first frame and every"
                        " rest's last (default: a new face of the world, drawn with"
                        " --seed)"
                    ),
                ),
            ),
        ),
        in_paper=True,
        default_n=1,
        usage=LONG,
        dataset=_long_dataset,
    ),
    "keyframes": Task(
        "chosen landmarks at chosen frames, a natural sequence around them (not in the"
        " paper)",
        tasks.Keyframes(),
        _keyframes,
        (
            (
                ("--constraints",),
                dict(required=True, help="the keyframes, a JSON file (see above)"),
            ),
        ),
        in_paper=False,
        usage=KEYFRAMES,
    ),
}


def _show(value):
    return "none" if value is None else value


def _default(task, name):
    """'default X; --paper: Y' for the help of an option (a task that is not in the
    paper has no --paper)."""
    value = getattr(TASKS[task].settings, name)
    if not TASKS[task].in_paper:
        return f"default {_show(value)}"
    return (
        f"default {_show(value)}; --paper:"
        f" {_show(getattr(TASKS[task].settings.paper(), name))}"
    )


def _converter(kind, name):
    """An argparse type for a field annotated ``kind`` ("int | None", "float", "str",
    ...): 'none' is None where the field allows it; anything else must parse as the
    field's type."""
    base = int if "int" in kind else float if "float" in kind else str
    optional = "None" in kind

    def convert(text):
        if optional and text.lower() == "none":
            return None
        try:
            return base(text)
        except ValueError:
            what = "text" if base is str else base.__name__
            raise argparse.ArgumentTypeError(
                f"--{name.replace('_', '-')} must be {what}"
                f"{' or none' if optional else ''}, got {text!r}"
            ) from None

    convert.__name__ = base.__name__
    return convert


def settings_options(parser, task):
    """An option per field of the task's settings (:data:`INTERNAL` ones excepted), its
    help stating the default; an option not given leaves no attribute (``--x none`` sets
    None where the field allows it).
    """
    group = parser.add_argument_group(
        f"settings (tasks.{type(TASKS[task].settings).__name__})"
    )
    for f in fields(TASKS[task].settings):
        if (task, f.name) in INTERNAL:
            continue
        help = (
            f"{TASK_HELP.get((task, f.name), FIELD_HELP[f.name])}"
            f" ({_default(task, f.name)})"
        )
        flags = ["--" + f.name.replace("_", "-"), *ALIASES.get(f.name, ())]
        if "bool" in str(f.type):
            group.add_argument(
                *flags,
                dest=f.name,
                default=argparse.SUPPRESS,
                action=argparse.BooleanOptionalAction,
                help=help,
            )
            continue
        choices = TASK_CHOICES.get((task, f.name), CHOICES.get(f.name))
        if choices is not None and "None" in str(f.type):
            choices = (*choices, None)
        group.add_argument(
            *flags,
            dest=f.name,
            default=argparse.SUPPRESS,
            type=_converter(str(f.type), f.name),
            choices=choices,
            help=help,
            metavar=f.name.upper() if choices is None else None,
        )


def add_task_parser(parsers, task, io, name=None, note=""):
    """The parser of one task (``name``: another spelling of it, e.g. the top-level
    ``edit``)."""
    spec = TASKS[task]
    p = parsers.add_parser(
        name or task,
        parents=[io],
        help=spec.description + note,
        description=(spec.usage or spec.description) + note,
    )
    p.set_defaults(func=run, task=task)
    if spec.takes_n:
        p.add_argument(
            "--n",
            type=int,
            default=spec.default_n,
            help=f"number of sequences (default {spec.default_n})",
        )
    if spec.in_paper:
        p.add_argument(
            "--paper",
            action="store_true",
            help=(
                "the paper's printed algorithm: all T = 2000 steps, no "
                "addition of the book (options given explicitly still apply)"
            ),
        )
    else:
        p.set_defaults(paper=False)
    for flags, kwargs in spec.inputs:
        p.add_argument(*flags, **kwargs)
    settings_options(p, task)
    return p


def add_parsers(sub):
    io = argparse.ArgumentParser(add_help=False)
    g = io.add_argument_group("every task")
    g.add_argument(
        "--out",
        required=True,
        help=(
            "output .npz (key 'landmarks': (n, F, 68, 3) float32 in mm, "
            "the 'config' that produced it and the sha256 of every checkpoint used)"
        ),
    )
    g.add_argument(
        "--checkpoint",
        default=None,
        help=(
            "denoiser checkpoint (default denoiser_<dataset>, with "
            "--guidance cfg denoiser_<dataset>_cfg)"
        ),
    )
    g.add_argument(
        "--device",
        default=None,
        choices=["cpu", "cuda"],
        help="default: a GPU when torch sees one",
    )
    p = sub.add_parser(
        "sample",
        help=(
            "generate landmark sequences: sample TASK --out out.npz (see sample TASK"
            " --help)"
        ),
    )
    parsers = p.add_subparsers(dest="task", required=True, metavar="TASK")
    for task in TASKS:
        add_task_parser(parsers, task, io)
    add_task_parser(
        sub, "edit", io, note=" [the same as `sample edit`, kept as a spelling of it]"
    )


def settings_of(args):
    """The task's settings: its defaults (``--paper``: the paper's) with the options
    given, the guidance rates and weights resolved to the values the run will use."""
    base = TASKS[args.task].settings
    base = base.paper() if args.paper else base
    settings = replace(
        base,
        **{
            f.name: getattr(args, f.name) for f in fields(base) if hasattr(args, f.name)
        },
    )
    return settings.resolved()


def run(args):
    """Run the task of ``args`` and write its .npz (nothing is written when it
    fails)."""
    if not 1 <= getattr(args, "n", 1) <= tasks.loading.MAX_SEQUENCES:
        raise ValueError(
            "--n must be a positive number of sequences (at most"
            f" {tasks.loading.MAX_SEQUENCES}), got {args.n}"
        )
    out = Path(args.out)
    if out.suffix != ".npz" or out.is_dir() or not out.parent.is_dir():
        raise ValueError(
            f"--out must name an .npz file in an existing folder, got {args.out!r}"
        )
    settings, spec = settings_of(args), TASKS[args.task]
    cfg = getattr(settings, "guidance", None) == "cfg"
    dataset = spec.dataset(args, settings) if spec.dataset else settings.dataset
    checkpoint = args.checkpoint or tasks.denoiser_name(
        dataset, settings.sampler, settings.steps, "cfg" if cfg else None
    )
    if args.task == "long" and settings.join == "learned" and not args.checkpoint:
        checkpoint = tasks.long.join_denoiser_name(
            settings, [] if args.schedule is None else args.schedule
        )
    with checkpoints.recording() as used_checkpoints:
        if args.checkpoint is not None or not cfg:
            denoiser = tasks.load_denoiser(checkpoint)
        else:
            denoiser = tasks.load_conditional_denoiser(
                dataset, settings.sampler, settings.steps
            )
        denoiser.model.to(device_for(args.device))
        landmarks, extra = spec.run(args, settings, denoiser)
    if args.task in INPUT_LENGTH:
        settings = replace(settings, num_frames=landmarks.shape[1])
    # what steered the denoiser
    guides = [name for name in used_checkpoints if name != Path(checkpoint).stem]
    used = {
        "task": args.task,
        "paper": args.paper,
        "n": len(landmarks),
        "checkpoint": checkpoint,
        "checkpoint_sha256": denoiser.meta["sha256"],
        "checkpoints": used_checkpoints,
        "guide": guides[0] if len(guides) == 1 else (guides or None),
        "adagrad_steps": config.ADAGRAD_STEPS,
        **asdict(settings),
        **(
            {"scale": settings.guidance_scale}
            if hasattr(settings, "guidance_scale")
            else {}
        ),
        **(
            {"method": None if cfg else settings.guidance_method}
            if hasattr(settings, "guidance_method")
            else {}
        ),
        **{
            k: getattr(args, k)
            for k in (
                "label",
                "text",
                "input",
                "known",
                "neutral",
                "curve",
                "constraints",
                "schedule",
                "seconds",
            )
            if hasattr(args, k)
        },
    }
    # nothing written: a file of NaN would pass for a result
    if not np.isfinite(landmarks).all():
        raise ValueError(
            f"the {args.task} task returned NaN or infinite landmarks with these"
            f" settings; nothing was written to {args.out}"
        )
    np.savez(
        args.out,
        landmarks=landmarks.astype(np.float32),
        config=json.dumps(used),
        **{k: np.asarray(v) for k, v in extra.items()},
    )
    print(f"wrote {args.out}: landmarks {landmarks.shape} float32 (mm); config {used}")
    return 0
