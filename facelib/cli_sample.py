"""``python -m facelib sample TASK``: one subcommand per task, its options the fields of the task's settings
(facelib/config.py, whose defaults are the book's best measured settings; ``--paper`` the paper's)."""
from __future__ import annotations

import argparse
import json
from dataclasses import asdict, fields, replace

import numpy as np

from . import config, data, inpainting, tasks
from .training.loop import device_for

TASKS = {"unconditional": "the unconditional DDPM (§3.1)", "label": "label control (Alg. 1)",
         "text": "text control (Alg. 2)", "decoder": "a text decoder's sequence refined by the DDPM (not in the paper)",
         "fill": "expression filling (Alg. 3)", "geometry": "geometry-adaptive generation of a given face (Alg. 4)"}
SETTINGS = config.SAMPLING | {"decoder": config.DecoderThenDiffusion()}
EDIT = ("edit --input seq.npz --label X --out edited.npz: each sequence is inverted by DDIM (eta = 0) to the x_T "
        "the chain regenerates it from, then regenerated from there with label guidance towards X: its identity "
        "and timing are kept, its expression changes (not in the paper)")
BEYOND = {"au": "AU-curve control: action units that follow requested intensity curves (not in the paper)",
          "keyframes": "chosen landmarks at chosen frames, a natural sequence around them (not in the paper)"}
KEYFRAMES = ("keyframes --constraints keys.json --out out.npz: sequences that meet landmark keyframes. keys.json: "
             '{"neutral": [[x, y, z], ... 68 rows] (optional, mm; frame 0 is then that face), "keys": [{"frame": 25, '
             '"landmark": 54, "displacement": [0, 8, 0]}, {"frame": 10, "landmark": 8, "position": [x, y, z]}]}: '
             "frames from 0, iBUG-68 landmark indices, positions in mm, displacements in mm from the neutral face")
GUIDES = {"au": "au_regressor_{}", "label": "guide_{}_I", "edit": "guide_{}_I", "text": "guide_{}_text",
          "decoder": "motionclip_{}", "geometry": "guide_{}_S"}


def _default(task, field):
    """'default X; --paper: Y' for the help of an option (a field of the task's settings; a task that is not
    in the paper has no --paper)."""
    show = {None: "None"} if field != "steps" else {None: "all T = 2000"}
    value = getattr(SETTINGS[task], field)
    if task not in TASKS:
        return f"default {show.get(value, value)}"
    paper = getattr(SETTINGS[task].paper(), field)
    return f"default {show.get(value, value)}; --paper: {show.get(paper, paper)}"


def _option(parser, task, field, help, *aliases, **kwargs):
    """An option that sets a field of the task's settings; its help states the default."""
    parser.add_argument("--" + field.replace("_", "-"), *aliases, dest=field, default=None,
                        help=f"{help} ({_default(task, field)})", **kwargs)


def add_parsers(sub):
    io = argparse.ArgumentParser(add_help=False)
    g = io.add_argument_group("every task")
    g.add_argument("--out", required=True, help="output .npz (key 'landmarks': (n, F, 68, 3) float32 in mm, "
                   "and the 'config' that produced it)")
    g.add_argument("--checkpoint", default=None, help="denoiser checkpoint (default denoiser_<dataset>, with "
                   "--guidance cfg denoiser_<dataset>_cfg)")
    g.add_argument("--device", default=None, choices=["cpu", "cuda"], help="default: a GPU when torch sees one")
    common = argparse.ArgumentParser(add_help=False, parents=[io])
    g = common.add_argument_group("every sampling task")
    g.add_argument("--n", type=int, default=16, help="number of sequences (default 16)")
    g.add_argument("--paper", action="store_true", help="the paper's printed algorithm: all T = 2000 steps, no "
                   "addition of the book (options given explicitly still apply)")
    p = sub.add_parser("sample", help="generate landmark sequences: sample TASK --out out.npz (see sample TASK --help)")
    parsers = p.add_subparsers(dest="task", required=True, metavar="TASK")
    t = {}
    for task, description in TASKS.items():
        t[task] = parsers.add_parser(task, parents=[common], help=description, description=description)
        _option(t[task], task, "steps", "reverse steps, respaced from T = 2000", type=int)
        _option(t[task], task, "num_frames", "frames per sequence", "--length", type=int)
        _option(t[task], task, "seed", "the random seed", type=int)
        _option(t[task], task, "dataset", "the data the networks were trained on", choices=list(data.DATASET_NAMES))
        _option(t[task], task, "variance", "the DDPM sampler's sigma_t^2: beta_t (the paper's) or the posterior "
                "beta~_t (DDIM's is eta^2 beta~_t)", choices=["beta", "posterior"])
        _option(t[task], task, "sampler", "the reverse step: DDPM's ancestral step (Eq. 5) or DDIM's",
                choices=list(config.SAMPLERS))
        _option(t[task], task, "eta", "DDIM's noise, in [0, 1] (0: deterministic)", type=float)
        t[task].set_defaults(func=run)
    beyond = argparse.ArgumentParser(add_help=False, parents=[io])
    beyond.add_argument("--n", type=int, default=16, help="number of sequences (default 16)")
    for task, description in BEYOND.items():
        t[task] = parsers.add_parser(task, parents=[beyond], help=description,
                                     description=KEYFRAMES if task == "keyframes" else description)
        t[task].set_defaults(func=run, paper=False)
        for field, text, kind in (("steps", "reverse steps, respaced from T = 2000", int),
                                  ("seed", "the random seed", int)):
            _option(t[task], task, field, text, type=kind)
    t["au"].add_argument("--curve", action="append", required=True, help="an AU curve NAME:value@frame,... (frames "
                         "from 0, linear between keys) or NAME:value (constant), e.g. AU12:0@0,0.8@20,0@39 --curve "
                         "AU26:0; NAME is an AU of the world (AU1 ... AU45) or AU12 (both lip corners); repeat it")
    t["au"].add_argument("--neutral", default=None, help=".npz with the neutral landmarks (68, 3) in mm of the face "
                         "to animate (key 'neutral' or 'landmarks'), which is then frame 0 (default: the model draws "
                         "the face too)")
    _option(t["au"], "au", "method", "adagrad (Alg. 1's steps) or mean_shift", choices=list(config.GUIDANCE_METHODS))
    _option(t["au"], "au", "read", "what the AU regressor reads: x0_hat, the denoiser's estimate, or x_t",
            choices=list(config.HEAD_INPUTS))
    _option(t["au"], "au", "lr", "Adagrad learning rate (None: the book's choice for the steps)", type=float)
    _option(t["au"], "au", "tolerance", "tau of log N(curve | R(x_t, t), tau^2), in intensity units", type=float)
    t["keyframes"].add_argument("--constraints", required=True, help="the keyframes, a JSON file (see above)")
    _option(t["keyframes"], "keyframes", "method", "replace (Alg. 3 on coordinates), reconstruction (guidance) or "
            "both", choices=list(config.KEYFRAME_METHODS))
    _option(t["keyframes"], "keyframes", "reconstruction_scale", "reconstruction guidance zeta", type=float)
    t["edit"] = edit = sub.add_parser("edit", parents=[io], help="change the expression of a given sequence: DDIM "
                                      "inversion, then label control (not in the paper)", description=EDIT)
    edit.set_defaults(func=run, task="edit", paper=False)
    edit.add_argument("--input", required=True, help=".npz whose 'landmarks' (F, 68, 3) or (n, F, 68, 3) in mm "
                      "holds the sequence(s) to edit")
    edit.add_argument("--keep", default=None, help="frames kept as given, as 0-based ranges, e.g. 0:1 for the "
                      "neutral frame of an N2E sequence (default: none; every frame is regenerated)")
    _option(edit, "edit", "steps", "reverse steps, respaced from T = 2000 (inversion and regeneration)", type=int)
    _option(edit, "edit", "refine", "fixed-point iterations per inversion step (0: the plain DDIM inversion)",
            type=int)
    _option(edit, "edit", "dataset", "the data the networks were trained on", choices=list(data.DATASET_NAMES))
    for task in ("label", "edit", "text", "geometry"):
        _option(t[task], task, "lr", "Adagrad learning rate of the guidance (None: the book's choice for the "
                "dataset and the number of steps)", type=float)
        _option(t[task], task, "guidance_weight", "lambda of Alg. 1-2, the weight of log p_theta" +
                (" (None: the book's choice for the text score)" if task == "text" else ""), type=float)
    for task in ("label", "edit", "geometry"):
        t[task].add_argument("--label", required=True, help="an expression label of the dataset, e.g. high_smile" +
                             (" or 'mouth_open E2N'" if task == "geometry" else ""))
    for task in ("label", "edit"):
        _option(t[task], task, "guidance", "classifier: a noisy classifier steers the unconditional denoiser (the "
                "paper's); cfg: classifier-free guidance of the label-conditional denoiser denoiser_<dataset>_cfg",
                choices=list(config.LABEL_GUIDANCE))
        _option(t[task], task, "method", "classifier guidance by adagrad (Alg. 1) or mean_shift (None: adagrad with "
                "the ddpm sampler, mean_shift with ddim)",
                choices=list(config.GUIDANCE_METHODS))
        ms = config.EDIT_MEAN_SHIFT_SCALE if task == "edit" else config.MEAN_SHIFT_SCALE
        _option(t[task], task, "scale", f"the mean shift's gradient scale s (None: {ms:g}) or "
                f"CFG's weight w >= 0 (None: {config.CFG_SCALE:g})", type=float)
    for task in ("text", "decoder"):
        t[task].add_argument("--text", required=True, help='what to show, e.g. "disgust high smile" or "from the '
                             'neutral face to bareteeth"')
    _option(t["text"], "text", "score", "what Alg. 2 climbs: the cosine of Eq. 10 or the text head's "
            "log-probability of the text among the training descriptions", choices=list(config.TEXT_SCORES))
    _option(t["text"], "text", "head_input", "what the head reads: x_t (Alg. 2) or the denoiser's estimate x0_hat",
            choices=list(config.HEAD_INPUTS))
    _option(t["text"], "text", "vocabulary", "with --score contrastive: match the text against every description "
            "known, also those no network has seen", action="store_const", const=True)
    _option(t["text"], "text", "particles", "best-of-K: K guided chains per sequence, the head keeps one at the "
            "time label --select-time", type=int)
    _option(t["text"], "text", "select_time", "the time label where best-of-K picks", type=float)
    _option(t["text"], "text", "max_time", "leave the steps above this time label unguided", type=float)
    _option(t["decoder"], "decoder", "start", "the step of the paper's chain the decoder's sequence is re-noised "
            "to", type=int)
    t["fill"].add_argument("--input", required=True, help=".npz whose 'landmarks' (F, 68, 3) or (n, F, 68, 3) holds "
                           "the sequence(s) to complete")
    t["fill"].add_argument("--known", required=True, help="known frames as 0-based ranges, e.g. 0:10,30:40")
    t["geometry"].add_argument("--neutral", required=True, help=".npz with the neutral landmarks (68, 3) in mm (key "
                               "'neutral' or 'landmarks')")
    _option(t["geometry"], "geometry", "order", "neutral face first (N2E) or last (E2N)", choices=list(data.KIND_NAMES))
    _option(t["geometry"], "geometry", "passes", "harmonising passes of Alg. 4", type=int)
    for task in ("fill", "geometry"):
        _option(t[task], task, "reconstruction_scale", "reconstruction guidance zeta (0: none)", type=float)
        _option(t[task], task, "resample", "RePaint's resampling r (1: none)", type=int)


def read_npz_array(path, keys, what):
    """The first of ``keys`` found in an .npz (a clear error naming the file and the keys otherwise)."""
    try:
        with np.load(path) as f:
            for key in keys:
                if key in f:
                    return np.asarray(f[key], dtype=np.float64)
            found = list(f.keys())
    except (OSError, ValueError) as e:
        raise ValueError(f"cannot read {what} from {path}: {e}") from None
    raise ValueError(f"{path} has no {' or '.join(repr(k) for k in keys)} array ({what}); it has {found}")


def settings_of(args):
    """The task's settings: its defaults (``--paper``: the paper's) with the options given, the guidance
    rates and weights resolved to the values the run will use."""
    base = SETTINGS[args.task].paper() if args.paper else SETTINGS[args.task]
    settings = replace(base, **{f.name: getattr(args, f.name) for f in fields(base)
                                if getattr(args, f.name, None) is not None})
    if args.task in ("label", "edit") and settings.guidance == "cfg":
        return settings  # classifier-free guidance has no classifier, no Adagrad rate
    if args.task in ("label", "edit") and settings.lr is None:
        settings = replace(settings, lr=tasks.adagrad_lr(settings.dataset, settings.steps))
    if args.task == "text" and settings.guidance_weight is None:
        settings = replace(settings, guidance_weight=tasks.text_guidance_weight(settings.score))
    if args.task == "text" and settings.lr is None:
        settings = replace(settings, lr=tasks.text_lr(settings.steps, score=settings.score))
    return settings


def run(args):
    settings = settings_of(args)
    cfg = getattr(settings, "guidance", None) == "cfg"
    checkpoint = args.checkpoint or f"denoiser_{settings.dataset}" + ("_cfg" if cfg else "")
    given = args.checkpoint is not None or not cfg
    denoiser = tasks.load_denoiser(checkpoint) if given else tasks.load_conditional_denoiser(settings.dataset)
    denoiser.model.to(device_for(args.device))
    n, extra = getattr(args, "n", None), {}
    if args.task == "unconditional":
        landmarks = tasks.unconditional(n, settings, denoiser)
    elif args.task == "label":
        landmarks, extra["labels"] = tasks.label_control(args.label, n, settings, denoiser), [args.label] * n
    elif args.task == "text":
        landmarks, extra["texts"] = tasks.text_control(args.text, n, settings, denoiser), [args.text] * n
    elif args.task == "decoder":
        landmarks, extra["texts"] = tasks.decoder_then_diffusion(args.text, n, settings, denoiser), [args.text] * n
    elif args.task == "edit":
        given = tasks.check_sequences(read_npz_array(args.input, ["landmarks"], "the sequences to edit"))
        settings = replace(settings, num_frames=given.shape[1])
        landmarks = tasks.edit(given, args.label, args.keep, settings, denoiser)
        extra["labels"] = [args.label] * len(landmarks)
    elif args.task == "au":
        neutral = None if args.neutral is None else read_npz_array(args.neutral, ["neutral", "landmarks"],
                                                                    "the neutral landmarks")
        landmarks = tasks.au_control(args.curve, n, neutral, settings, denoiser)
        extra["curves"] = args.curve
    elif args.task == "keyframes":
        keys, neutral = tasks.read_constraints(args.constraints)
        landmarks = tasks.keyframes(keys, n, neutral, settings, denoiser)
    elif args.task == "fill":
        given = read_npz_array(args.input, ["landmarks"], "the sequence to fill")
        if given.ndim not in (3, 4) or given.shape[-2:] != (68, 3):
            raise ValueError(f"{args.input}: 'landmarks' must be (F, 68, 3) or (n, F, 68, 3) in mm, got {given.shape}")
        extra["known"] = inpainting.parse_known(args.known, given.shape[-3])
        landmarks = tasks.fill(given, extra["known"], settings, denoiser)
    else:
        neutral = read_npz_array(args.neutral, ["neutral", "landmarks"], "the neutral landmarks")
        extra["labels"] = [tasks.order_sensitive_label(args.label, settings.order)] * n
        landmarks = tasks.geometry_adaptive(neutral, extra["labels"], n, settings, denoiser)
    used = {"task": args.task, "paper": args.paper, "n": len(landmarks), "checkpoint": checkpoint,
            "checkpoint_sha256": denoiser.meta["sha256"],
            "guide": None if cfg else GUIDES.get(args.task, "").format(settings.dataset),
            "adagrad_steps": config.ADAGRAD_STEPS, **asdict(settings),
            **({"scale": settings.guidance_scale} if hasattr(settings, "guidance_scale") else {}),
            **({"method": settings.guidance_method} if hasattr(settings, "guidance_method") else {}),
            **{k: getattr(args, k) for k in ("label", "text", "input", "known", "neutral", "keep", "curve",
                                             "constraints") if hasattr(args, k)}}
    np.savez(args.out, landmarks=landmarks.astype(np.float32), config=json.dumps(used),
             **{k: np.asarray(v) for k, v in extra.items()})
    print(f"wrote {args.out}: landmarks {landmarks.shape} float32 (mm); config {used}")
    return 0
