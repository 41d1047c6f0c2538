"""``python -m facelib sample TASK``: one subcommand per task, dispatched through one
registry (:data:`TASKS`).

Every option of a task is generated from a field of the task's settings dataclass
(facelib/tasks/settings.py, whose defaults are the book's best measured settings;
``--paper`` the paper's), with its help (the field's, ``options.option``) and its
default, so that the command line reaches every setting; only the fields in
:data:`INTERNAL` (set from the input) have no option. A task's own inputs (``--label``,
``--input``, ...) are listed in its registry entry. Each output ``.npz`` records the
settings used and the sha256 of every checkpoint loaded to make it.
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

from . import checkpoints, config, inpainting, tasks
from .face.sequences import MAX_FRAMES, MIN_FRAMES
from .options import add_option, shown
from .training.loop import device_for

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


def _default(task, name):
    """'default X; --paper: Y' for the help of an option (a task that is not in the
    paper has no --paper)."""
    value = getattr(TASKS[task].settings, name)
    if not TASKS[task].in_paper:
        return f"default {shown(value)}"
    return (
        f"default {shown(value)}; --paper:"
        f" {shown(getattr(TASKS[task].settings.paper(), name))}"
    )


def settings_options(parser, task):
    """An option per field of the task's settings (:data:`INTERNAL` ones excepted), its
    help and choices those of the field (``options.option``) and the help stating
    the default; an option not given leaves no attribute (``--x none`` sets None where
    the field allows it).
    """
    cls = type(TASKS[task].settings)
    group = parser.add_argument_group(f"settings (tasks.{cls.__name__})")
    for f in fields(cls):
        if (task, f.name) not in INTERNAL:
            add_option(
                group,
                cls,
                f.name,
                _default(task, f.name),
                family=tasks.settings.settings_classes(),
                aliases=ALIASES.get(f.name, ()),
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
