"""Command line of the book: ``python -m facelib
{data,train,sample,edit,neutral,animate,register,chapter,results}`` (see ``--help`` of
each)."""

from __future__ import annotations

import argparse
import ast
import dataclasses
import io as bytes_io
import json
import os
import pathlib
import sys
import tempfile
import time

import numpy as np

from . import (
    chapters,
    cli_sample,
    config,
    data,
    meshio,
    options,
    pipeline,
    registration,
    results,
    tasks,
    training,
    viz,
)
from .face import Face, sample_identity


def _data(args):
    names = list(config.DATASETS) if args.name == "all" else [args.name]
    fingerprints = (
        json.loads(data.FINGERPRINT_FILE.read_text())
        if data.FINGERPRINT_FILE.exists()
        else {}
    )
    status = 0
    for name in names:
        t0 = time.perf_counter()
        arrays = data.build(name, args.frames, rebuild=args.rebuild)
        print(data.summary(name, arrays))
        print(
            f"ready in {time.perf_counter() - t0:.1f} s:"
            f" {data.cache_path(name, args.frames)}"
        )
        fp = data.fingerprint(arrays)
        key = f"{name}-F{args.frames}"
        if args.write_fingerprints:
            fingerprints[key] = fp
        elif key in fingerprints:
            same = data.fingerprints_match(fp, fingerprints[key])
            print(
                f"fingerprint {'matches' if same else 'DIFFERS FROM'}"
                f" {data.FINGERPRINT_FILE.name}"
            )
            status |= not same
        print()
    if args.write_fingerprints:
        data.FINGERPRINT_FILE.parent.mkdir(parents=True, exist_ok=True)
        data.FINGERPRINT_FILE.write_text(
            json.dumps(fingerprints, indent=2, sort_keys=True) + "\n"
        )
        data.CONFIG_FILE.write_text(
            json.dumps(data.generator_config(), indent=2) + "\n"
        )
        print(f"wrote {data.FINGERPRINT_FILE} and {data.CONFIG_FILE}")
    return status


TRAINABLE = tuple(training.RECIPES)  # every recipe is trainable
# the recipes' settings that `train` has an option for (the rest: --set NAME=VALUE)
RECIPE_OPTIONS = (
    "dataset",
    "classifier_type",
    "method",
    "split",
    "steps",
    "batch_size",
    "seed",
    "conditional",
)


def recipe_options(parser):
    """`train`'s option of each of :data:`RECIPE_OPTIONS`, made from the recipes'
    settings field (options.add_option): its help and choices, and the defaults of
    the recipes that have it."""
    group = parser.add_argument_group("settings of the recipe (training/settings.py)")
    family = list(training.SETTINGS.values())
    for name in RECIPE_OPTIONS:
        having = {m: c for m, c in training.SETTINGS.items() if name in _field_names(c)}
        by_value = {}
        for model, cls in having.items():
            value = options.shown(getattr(cls(), name))
            if name == "steps" and cls().epochs is not None:
                value = f"{cls().epochs} epochs, not steps,"
            by_value.setdefault(value, []).append(model)
        default = "default: the recipe's: " + "; ".join(
            f"{value} for {', '.join(models) if len(models) < len(family) else 'all'}"
            for value, models in by_value.items()
        )
        options.add_option(group, next(iter(having.values())), name, default, family)


def _field_names(cls):
    return {f.name for f in dataclasses.fields(cls)}


def _setting(model_name, assignment, settings_class=None):
    """``--set NAME=VALUE`` as (name, value), the value read as the setting's type
    ('none': None; tuples and lists as Python literals); a clear error for an unknown
    name or a value of the wrong type.  The settings are the recipe ``model_name``'s, or
    ``settings_class``'s."""
    name, sep, text = assignment.partition("=")
    known = {
        f.name: f
        for f in dataclasses.fields(settings_class or training.SETTINGS[model_name])
    }
    if not sep or name not in known:
        raise ValueError(
            f"--set {assignment!r}: expected NAME=VALUE with NAME a setting of"
            f" {model_name} ({', '.join(known)})"
        )
    base, optional = options.field_type(
        settings_class or training.SETTINGS[model_name], name
    )
    if text.lower() == "none" and (optional or base is object):
        return name, None
    if base is bool:
        if text.lower() not in ("true", "false"):
            raise ValueError(f"--set {name}: true or false, got {text!r}")
        return name, text.lower() == "true"
    if base in (tuple, object):
        try:
            value = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            raise ValueError(
                f"--set {name}: a Python literal such as (35, 45) or 40, got {text!r}"
            ) from None
        return name, tuple(value) if isinstance(value, list) else value
    try:
        return name, options.converter(base, optional, name)(text)
    except argparse.ArgumentTypeError as e:
        raise ValueError(
            f"--set {name}: {e}".replace(f"--{name.replace('_', '-')} ", "")
        ) from None


def train_settings(args):
    """The settings `train NAME` trains with: the recipe's defaults (``--fast``: its
    fast-mode ones) changed by its options and every --set NAME=VALUE."""
    given = {n: getattr(args, n) for n in RECIPE_OPTIONS if hasattr(args, n)}
    if args.variable_length:
        # mixed lengths: the Gaussian part per frame (denoiser_coma_var's recipe)
        given["num_frames"], given["temporal_prior"] = (35, 45), False
    if args.name == "all":
        if given or args.set:
            raise ValueError(
                "train all trains the shipped checkpoints with their recipes; the"
                " settings options and --set change one recipe's (train NAME)"
            )
        return None
    if args.only or args.missing:
        raise ValueError(
            "--only and --missing pick checkpoints of train all, not of"
            f" {args.name}"
        )
    for assignment in args.set:
        name, value = _setting(args.name, assignment)
        if name in given:
            raise ValueError(
                f"--set {name} repeats a setting given by its own option or an earlier"
                " --set"
            )
        given[name] = value
    return training.settings_for(args.name, fast=args.fast, **given)


def _train(args):
    settings = train_settings(args)
    if args.name == "all":
        rows = training.train_all(
            args.only,
            fast=args.fast,
            out_dir=args.out,
            missing=args.missing,
            resume=args.resume,
        )
        if args.out is None and not args.fast and rows:
            results.store_training_times()  # results/train_all.json
        return 0
    t0 = time.perf_counter()
    written = training.train_and_save(
        training.RECIPES[args.name](settings),
        name=args.out,
        device=args.device,
        resume=args.resume,
    )
    if written:
        print(
            f"trained in {time.perf_counter() - t0:.0f} s; wrote {written[0]} and"
            f" {written[1]}"
        )
    return 0


def _neutral(args):
    if args.out is None or not str(args.out).lower().endswith(".obj"):
        raise ValueError(f"--out must name an .obj file, got {args.out!r}")
    meshio.write_obj(args.out, Face(sample_identity(args.seed)).neutral)
    print(
        f"wrote {args.out}: the neutral face of identity seed {args.seed} (template"
        " topology, mm)"
    )
    return 0


def _registration_settings(args):
    """registration.Registration with --units and every --set NAME=VALUE of `register`
    and `animate`."""
    given = {"units": args.units} if hasattr(args, "units") else {}
    for assignment in args.set:
        name, value = _setting("registration", assignment, registration.Registration)
        if name in given:
            raise ValueError(
                f"--set {name} repeats a setting given by its own option (--units) or"
                " an earlier --set"
            )
        given[name] = value
    return dataclasses.replace(registration.Registration(), **given)


# `animate --schedule`'s GIF: every k-th frame, at most this rate (GIF frame times are
# whole hundredths of a second: 10 fps keeps 30, 20 and 60 fps streams in real time)
GIF_MAX_FPS = 10


def _animation_request(args):
    """What `animate` generates, checked before any mesh is read: (keyword arguments of
    pipeline.animate_mesh, what the landmarks file records, GIF stride and rate)."""
    if args.fast and args.steps is not None:
        raise ValueError(
            f"--fast samples with the {config.FAST_STUDENT_STEPS}-step student; give"
            " --fast or --steps, not both"
        )
    if (args.label is None) == (args.schedule is None):
        raise ValueError("give --label or --schedule (one of them)")
    steps = config.FAST_STUDENT_STEPS if args.fast else args.steps
    if args.schedule is None:
        if args.fps is not None:
            raise ValueError(
                "--fps is the frame rate of a --schedule; a --label clip is"
                f" {config.NUM_FRAMES} frames"
            )
        settings = tasks.GeometryAdaptive()
        what = dict(
            label=args.label,
            order=args.order,  # None: tasks.GeometryAdaptive's (N2E for a label)
            steps=settings.steps if steps is None else steps,
            sampler="student" if args.fast else settings.sampler,
        )
        return what, dict(what), 1, 12
    if args.fast or args.order is not None:
        raise ValueError(
            "--fast and --order apply to a --label clip; a --schedule streams with the"
            " chain of tasks.Long and opens every segment from the rest"
        )
    settings = tasks.Long()
    settings = dataclasses.replace(
        settings,
        fps=settings.fps if args.fps is None else args.fps,
        steps=settings.steps if steps is None else steps,
    )
    schedule = tasks.long.read_schedule(args.schedule, settings)
    seconds = sum(s.frames for s in schedule) / config.NATIVE_FPS
    if seconds > config.ANIMATE_MAX_SECONDS:
        raise ValueError(
            f"the schedule lasts {seconds:g} s; `animate` writes an OBJ per frame and"
            f" takes at most {config.ANIMATE_MAX_SECONDS} s (`sample long` takes up to"
            f" {config.LONG_MAX_SECONDS} s of landmarks)"
        )
    what = dict(schedule=schedule, fps=settings.fps, steps=settings.steps)
    used = dict(schedule=args.schedule, fps=settings.fps, steps=settings.steps)
    stride = -(-settings.fps // GIF_MAX_FPS)  # real time, at most GIF_MAX_FPS
    return what, used, stride, settings.fps / stride


def _animate(args):
    what, used, gif_stride, gif_fps = _animation_request(args)
    t0 = time.perf_counter()
    settings = _registration_settings(args)
    mesh = registration.read_mesh(args.mesh, settings.units)
    seconds = {"read mesh": time.perf_counter() - t0}
    anim = pipeline.animate_mesh(
        mesh, registration_settings=settings, seed=args.seed, progress=True, **what
    )
    seconds.update(anim.seconds)
    t0 = time.perf_counter()
    if anim.registration is None:
        shown, faces, colors = anim.frames, None, None
    # rendered in the canonical pose, in mm, with the template's colours carried over
    else:
        r, shift = anim.registration.pose
        shown = anim.frames * registration.UNITS[mesh.units] @ r.T + shift
        faces, colors = mesh.faces, anim.registration.colors()
    frames = [
        np.concatenate(pair, axis=1)
        for pair in zip(
            *(
                viz.mesh_frames(
                    shown[::gif_stride], view=view, faces=faces, colors=colors
                )
                for view in ("front", "three_quarter")
            )
        )
    ]
    seconds["render GIF"] = time.perf_counter() - t0
    used.update(seed=args.seed, mesh=str(args.mesh), units=mesh.units)
    npz = bytes_io.BytesIO()
    np.savez(
        npz, landmarks=anim.landmarks[None].astype(np.float32), config=json.dumps(used)
    )
    extra = {"landmarks.npz": npz.getvalue()}
    if anim.registration is not None:
        extra["registration.json"] = _registration_json(anim.registration).encode()
    t0 = time.perf_counter()
    written = meshio.write_animation(
        args.out,
        anim.frames,
        viz.gif_bytes(frames, gif_fps),
        extra=extra,
        faces=mesh.faces,
        template_meshes=anim.template_frames if args.keep_template else None,
    )
    seconds["write files"] = time.perf_counter() - t0
    print(
        f"wrote {len(written)} files to {args.out}: {len(anim.frames)} OBJ frames of"
        f" {mesh.source} ({len(mesh.vertices)} vertices, {mesh.units}), animation.gif,"
        f" {', '.join(sorted(extra))}"
        + (", template/ (the fitted template's frames)" if args.keep_template else "")
    )
    print("\n".join(f"  {k:<14} {v:7.2f} s" for k, v in seconds.items()))
    print(f"  {'total':<14} {sum(seconds.values()):7.2f} s")
    return 0


def _registration_json(fit):
    """The registration's record: units, the 68 landmarks (user units and pose),
    residuals (mm), seconds."""
    return (
        json.dumps(
            {
                "mesh": fit.mesh.source,
                "units": fit.mesh.units,
                "vertices": len(fit.mesh.vertices),
                "landmarks": np.round(fit.landmarks, 6).tolist(),
                "residual_mm": {k: round(v, 4) for k, v in fit.residual_mm.items()},
                "seconds": {k: round(v, 2) for k, v in fit.seconds.items()},
            },
            indent=1,
        )
        + "\n"
    )


def _register(args):
    out = pathlib.Path(args.out)
    if out.suffix.lower() != ".obj":
        raise ValueError(f"--out must name an .obj file, got {out}")
    settings = _registration_settings(args)
    mesh = registration.read_mesh(args.mesh, settings.units)
    fit = registration.register(mesh, settings)
    record = out.with_suffix(".json")
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out.parent, prefix=f".{out.stem}-") as tmp:
        meshio.write_obj(pathlib.Path(tmp) / out.name, fit.fitted_in_user_units())
        (pathlib.Path(tmp) / record.name).write_text(_registration_json(fit))
        for name in (out.name, record.name):
            os.replace(pathlib.Path(tmp) / name, out.parent / name)
    print(
        f"registered {mesh.source} ({len(mesh.vertices)} vertices, {mesh.units}) in "
        f"{sum(fit.seconds.values()):.1f} s; residual (median, mm): "
        + ", ".join(
            f"{k} {v:.2f}" for k, v in fit.residual_mm.items() if "RMS" not in k
        )
    )
    print(
        f"wrote {out} (the template fitted to it, in its units and pose) and {record}"
        " (68 landmarks, residuals)"
    )
    return 0


def _chapter(args):
    mode = "fast" if args.fast else "book"
    path = chapters.find_chapter(args.name)
    print(
        f"executing {path.relative_to(config.PROJECT_ROOT)} in {mode} mode ...",
        flush=True,
    )
    seconds, out = chapters.run_chapter(args.name, fast=args.fast)
    budget = chapters.BUDGET_S[mode]
    print(
        f"{path.stem}: {seconds:.0f} s in {mode} mode (budget {budget}"
        f" s{'' if seconds <= budget else ', OVER'}); executed notebook:"
        f" {out.relative_to(config.PROJECT_ROOT)}"
    )
    return 0


def _results(args):
    entries = results.catalogue()
    for e in entries:
        state = (
            "ok"
            if not e["problems"]
            else "STALE OR MALFORMED: " + "; ".join(e["problems"])
        )
        print(
            f"{e['name']:<24} {e['minutes']:6.1f} min on {e['cores']} cores,"
            f" {e['threads']} torch thread(s), {e['date']}  {state}\n    {e['command']}"
        )
        for change in e["changes"]:
            print(f"    made before a code change that moves its numbers: {change}")
        if e["unrecorded"]:
            print(
                f"    records no {' or '.join(e['unrecorded'])} (stored before results"
                " recorded them): its staleness is checked on its checkpoints only"
            )
    print(
        f"{len(entries)} stored results in {results.RESULTS_DIR}; re-run a command to"
        " rewrite its file"
    )
    return 1 if any(e["problems"] for e in entries) else 0


def build_parser():
    """The command line's parser: a subcommand per command, each option with its help
    and default (``sample TASK``'s generated from the task's settings,
    cli_sample.add_parsers)."""
    parser = argparse.ArgumentParser(prog="python -m facelib", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser(
        "data",
        help="build (or verify) the synthetic dataset caches and print a summary",
    )
    p.add_argument("--name", default="all", choices=["all", *config.DATASETS])
    p.add_argument(
        "--frames",
        type=int,
        default=40,
        help="frames per sequence (default 40, as in the paper)",
    )
    p.add_argument(
        "--rebuild", action="store_true", help="regenerate even if a valid cache exists"
    )
    p.add_argument(
        "--write-fingerprints",
        action="store_true",
        help="record the datasets' fingerprints in data/synthetic/fingerprints.json",
    )
    p.set_defaults(func=_data)

    p = sub.add_parser(
        "train",
        help=(
            "train a model and save it in data/checkpoints (.pt + .json); under"
            " `torchrun --nproc_per_node N -m facelib train ...` on N processes"
            " (distributed data parallel)"
        ),
    )
    p.add_argument(
        "name",
        choices=[*TRAINABLE, "all"],
        help=(
            "all: every shipped checkpoint with its recipe (training.SHIPPED; --only to"
            " pick some, --out a folder to write them to); denoiser: eps_theta of §3.1;"
            " guide: the noisy classifier of Alg. 1/4; text_head: BiT(x_t, t) of Alg."
            " 2; evaluator: the independent LSTM classifier of §5; motion3dgan, actor:"
            " the baselines of Table 1; motionclip: the baseline of Table 2;"
            " lstm_filler: the baseline of Table 3; deformer: the mesh deformation of"
            " §3.3 and the baselines of Table 5; au_regressor: R(x_t, t) of AU-curve"
            " control (the fine-control chapter); student: one round of progressive"
            " distillation (--set teacher=NAME --set teacher_steps=N: a student of N/2"
            " steps); a rectified flow is the denoiser with --set schedule=flow --set"
            " prediction=u"
        ),
    )
    recipe_options(p)
    p.add_argument(
        "--variable-length",
        action="store_true",
        help="denoiser: train on lengths 35-45 (paper App. A; num_frames=(35, 45))",
    )
    p.add_argument(
        "--fast",
        action="store_true",
        help="the recipe's fast-mode settings (a few steps, for tests)",
    )
    p.add_argument(
        "--device",
        default=None,
        choices=["cpu", "cuda"],
        help="default: a GPU when torch sees one",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help=(
            "continue from <out>.state.pt if a run left one "
            "(the state is written every 500 steps; train all: each checkpoint's)"
        ),
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help=(
            "any other setting of the recipe (facelib/training/settings.py;"
            " repeatable), e.g. denoiser: --set prediction=v --set min_snr_gamma=5"
            " --set mirror=0.5 --set schedule=cosine; 'none' for None"
        ),
    )
    p.add_argument(
        "--only",
        nargs="+",
        default=None,
        help="train all: only these shipped checkpoints",
    )
    p.add_argument(
        "--missing",
        action="store_true",
        help=(
            "train all: skip the checkpoints that exist and were "
            "trained on this world's datasets (config.WORLD)"
        ),
    )
    p.add_argument(
        "--out",
        default=None,
        help=(
            "checkpoint name or path stem (default: denoiser_<dataset>[_var],"
            " guide_<dataset>_<type>, ic_<dataset>_<type>, deform_<method>_<split>,"
            " <baseline>_<dataset>); train all: a folder (default"
            f" {config.CHECKPOINT_DIR})"
        ),
    )
    p.set_defaults(func=_train)

    cli_sample.add_parsers(sub)

    p = sub.add_parser(
        "neutral",
        help=(
            "write the neutral mesh of a new synthetic identity as OBJ (template"
            " topology)"
        ),
    )
    p.add_argument("--seed", type=int, default=0, help="identity seed")
    p.add_argument("--out", required=True, help="output .obj")
    p.set_defaults(func=_neutral)

    p = sub.add_parser(
        "animate",
        help=(
            "animate a neutral mesh: landmarks, geometry-adaptive generation (Alg. 4),"
            " deformation (§3.3); writes an OBJ per frame, animation.gif and"
            " landmarks.npz"
        ),
    )
    p.add_argument(
        "--mesh",
        required=True,
        help=(
            "a neutral face mesh (OBJ, PLY, STL or OFF) of any topology, units and"
            " pose: registered to the template first (see `register`), the frames"
            " written on its own vertices; a template mesh in the canonical pose (from"
            " `neutral`) is animated as it is"
        ),
    )
    options.add_option(
        p, registration.Registration, "units", "default: detected from its size"
    )
    p.add_argument(
        "--keep-template",
        action="store_true",
        help=(
            "also write the fitted template's frames "
            "(template/frame_*.obj, mm, canonical pose)"
        ),
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help=(
            "any setting of the registration (registration.Registration; repeatable),"
            " e.g. --set samples=20000 --set max_residual_mm=4"
        ),
    )
    p.add_argument(
        "--label",
        default=None,
        help=(
            "expression label of the CoMA-like set, e.g. high_smile: one clip of"
            f" {config.NUM_FRAMES} frames"
        ),
    )
    p.add_argument(
        "--schedule",
        default=None,
        help=(
            'instead of --label, expressions of any length, e.g. "high_smile:3s,'
            ' neutral:1s, mouth_open:2s" (labels, neutral, free; the chapter "Any'
            ' length"); the GIF plays in real time'
        ),
    )
    p.add_argument(
        "--fps",
        type=int,
        default=None,
        help=(
            "frames per second of a --schedule's OBJ frames (default: tasks.Long,"
            f" {tasks.Long().fps}; {config.LONG_FPS_RANGE[0]}.."
            f"{config.LONG_FPS_RANGE[1]})"
        ),
    )
    options.add_option(
        p,
        tasks.GeometryAdaptive,
        "order",
        "--label only; default: N2E",
        tasks.settings.settings_classes(),
    )
    p.set_defaults(order=None)
    p.add_argument(
        "--steps",
        type=int,
        default=None,
        help=(
            "reverse steps per pass of Alg. 4, or per window of a --schedule (default:"
            " tasks.GeometryAdaptive, tasks.Long: 100, the book's respaced chain)"
        ),
    )
    p.add_argument(
        "--fast",
        action="store_true",
        help=(
            "sample with the distilled student of config.FAST_STUDENT_STEPS steps"
            " (chapter 14) instead of the DDPM chain"
        ),
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--out",
        required=True,
        help="output folder (written all at once, or not at all)",
    )
    p.set_defaults(func=_animate)

    p = sub.add_parser(
        "register",
        help=(
            "fit the template to a face mesh of any topology, units and pose (rigid"
            " alignment, the identity model, non-rigid ICP); writes the fitted template"
            " (OBJ, in the mesh's units and pose) and a JSON with its 68 landmarks and"
            " the fit's residuals"
        ),
    )
    p.add_argument(
        "--mesh", required=True, help="a neutral face mesh: OBJ, PLY, STL or OFF"
    )
    options.add_option(
        p, registration.Registration, "units", "default: detected from its size"
    )
    p.add_argument(
        "--out",
        required=True,
        help="output .obj (the landmarks and residuals go beside it as .json)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help=(
            "any setting of the registration (registration.Registration; repeatable),"
            " e.g. --set samples=20000 --set max_residual_mm=4"
        ),
    )
    p.set_defaults(func=_register)

    p = sub.add_parser(
        "chapter",
        help=(
            "execute one chapter (book mode unless --fast), print its time; the"
            " executed notebook goes to _build/chapters/ (make chapter N=05)"
        ),
    )
    p.add_argument(
        "name",
        help=(
            "chapter number (05), file stem (05_label_control) or name (label_control)"
        ),
    )
    p.add_argument(
        "--fast",
        action="store_true",
        help="fast mode (FACELIB_FAST=1), as the tests run it",
    )
    p.set_defaults(func=_chapter)

    p = sub.add_parser(
        "results",
        help=(
            "list the stored full-scale results (results/*.json): wall time, date, "
            "whether each is fresh, and the command that rewrites it"
        ),
    )
    p.set_defaults(func=_results)
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    # bad input, a checkpoint not trained yet: a message, no traceback
    except (ValueError, FileNotFoundError) as e:
        parser.error(str(e))


if __name__ == "__main__":
    sys.exit(main())
