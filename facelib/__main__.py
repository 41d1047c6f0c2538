"""Command line of the book: ``python -m facelib {data,train,sample,neutral,animate,chapter,results}`` (see ``--help`` of each)."""
from __future__ import annotations

import argparse
import io as bytes_io
import json
import sys
import time
from dataclasses import fields, replace

import numpy as np

from . import chapters, config, data, guidance, inpainting, meshio, pipeline, results, tasks, training, viz
from .face import Face, sample_identity


def _data(args):
    names = list(config.DATASETS) if args.name == "all" else [args.name]
    fingerprints = json.loads(data.FINGERPRINT_FILE.read_text()) if data.FINGERPRINT_FILE.exists() else {}
    status = 0
    for name in names:
        t0 = time.perf_counter()
        arrays = data.build(name, args.frames, rebuild=args.rebuild)
        print(data.summary(name, arrays))
        print(f"ready in {time.perf_counter() - t0:.1f} s: {data.cache_path(name, args.frames)}")
        fp = data.fingerprint(arrays)
        key = f"{name}-F{args.frames}"
        if args.write_fingerprints:
            fingerprints[key] = fp
        elif key in fingerprints:
            same = data.fingerprints_match(fp, fingerprints[key])
            print(f"fingerprint {'matches' if same else 'DIFFERS FROM'} {data.FINGERPRINT_FILE.name}")
            status |= not same
        print()
    if args.write_fingerprints:
        data.FINGERPRINT_FILE.write_text(json.dumps(fingerprints, indent=2, sort_keys=True) + "\n")
        data.CONFIG_FILE.write_text(json.dumps(data.generator_config(), indent=2) + "\n")
        print(f"wrote {data.FINGERPRINT_FILE} and {data.CONFIG_FILE}")
    return status


TRAINABLE = ("denoiser", "guide", "text_head", "evaluator", "motion3dgan", "actor", "motionclip", "lstm_filler",
             "deformer")
TASKS = ("unconditional", "label", "text", "fill", "geometry")


def _train(args):
    given = {"dataset": args.dataset, "classifier_type": args.type, "method": args.method, "split": args.split,
             "steps": args.steps, "batch_size": args.batch_size, "seed": args.seed,
             "num_frames": (35, 45) if args.variable_length else None}
    recipe = training.recipe(args.name, fast=args.fast, **{k: v for k, v in given.items() if v is not None})
    t0 = time.perf_counter()
    written = training.train_and_save(recipe, name=args.out, device=args.device, resume=args.resume)
    if written:
        print(f"trained in {time.perf_counter() - t0:.0f} s; wrote {written[0]} and {written[1]}")
    return 0


def _read_npz_array(path, keys, what):
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


def _task_settings(args):
    """The task's defaults (config.SAMPLING: the book's best; ``--paper``: the paper's), with the options given."""
    base = config.SAMPLING[args.task]
    base = base.paper() if args.paper else base
    given = {f.name: getattr(args, f.name) for f in fields(base) if getattr(args, f.name, None) is not None}
    return replace(base, **given)


def _sample(args):
    settings = _task_settings(args)
    steps = settings.steps
    dataset = args.dataset or (tasks.TEXT_DATASET if args.task == "text" else "coma")
    checkpoint = args.checkpoint or f"denoiser_{dataset}"
    denoiser = tasks.load_denoiser(checkpoint)
    used = {"task": args.task, "paper": args.paper, "n": args.n, "length": args.length, "seed": args.seed,
            "steps": steps or denoiser.diffusion.num_steps, "checkpoint": checkpoint,
            "checkpoint_sha256": denoiser.meta["sha256"], "dataset": dataset}
    extra = {}
    if args.task == "unconditional":
        landmarks = tasks.unconditional(args.n, num_frames=args.length, seed=args.seed, steps=steps, denoiser=denoiser)
    elif args.task == "label":
        lr = tasks.adagrad_lr(dataset, steps) if args.lr is None else args.lr
        landmarks = tasks.label_control(args.label, args.n, dataset=dataset, num_frames=args.length, steps=steps,
                                        guidance_weight=settings.guidance_weight, lr=lr, seed=args.seed,
                                        denoiser=denoiser)
        used.update(label=args.label, guidance_weight=settings.guidance_weight, adagrad_lr=lr,
                    adagrad_steps=guidance.ADAGRAD_STEPS, classifier=f"guide_{dataset}_I")
        extra["labels"] = np.array([args.label] * args.n)
    elif args.task == "text" and args.decoder_start is not None:
        alg2 = {"--lr": args.lr, "--guidance-weight": args.guidance_weight, "--score": args.score,
                "--head-input": args.head_input != "x_t" or None, "--particles": args.particles != 1 or None,
                "--max-time": args.max_time, "--vocabulary": args.vocabulary or None}
        if any(v is not None for v in alg2.values()):
            raise ValueError(f"--decoder-start replaces Alg. 2's guidance: it takes none of {', '.join(alg2)}")
        landmarks = tasks.decoder_then_diffusion(args.text, args.n, start=args.decoder_start, dataset=dataset,
                                                 num_frames=args.length, steps=steps, seed=args.seed,
                                                 denoiser=denoiser)
        used.update(text=args.text, method="decoder_then_diffusion", decoder_start=args.decoder_start,
                    decoder=f"motionclip_{dataset}")
        extra["texts"] = np.array([args.text] * args.n)
    elif args.task == "text":
        weight = tasks.text_guidance_weight(settings.score) if args.guidance_weight is None else args.guidance_weight
        lr = tasks.text_lr(steps, score=settings.score) if args.lr is None else args.lr
        landmarks = tasks.text_control(args.text, args.n, dataset=dataset, num_frames=args.length, steps=steps,
                                       guidance_weight=weight, lr=lr, head_input=args.head_input, score=settings.score,
                                       vocabulary=args.vocabulary, particles=args.particles, max_time=args.max_time,
                                       seed=args.seed, denoiser=denoiser)
        used.update(text=args.text, method="alg2", guidance_weight=weight, adagrad_lr=lr, head_input=args.head_input,
                    score=settings.score, vocabulary=args.vocabulary, adagrad_steps=guidance.ADAGRAD_STEPS,
                    particles=args.particles, select_time=tasks.SELECT_TIME if args.particles > 1 else None,
                    max_time=args.max_time, text_head=f"guide_{dataset}_text")
        extra["texts"] = np.array([args.text] * args.n)
    elif args.task == "fill":
        given = _read_npz_array(args.input, ["landmarks"], "the sequence to fill")
        if given.ndim not in (3, 4) or given.shape[-2:] != (68, 3):
            raise ValueError(f"{args.input}: 'landmarks' must be (F, 68, 3) or (n, F, 68, 3) in mm, got {given.shape}")
        known = inpainting.parse_known(args.known, given.shape[-3])
        landmarks = tasks.fill(given, known, steps=steps, resample=settings.resample,
                               reconstruction_scale=settings.reconstruction_scale, seed=args.seed, denoiser=denoiser)
        used.update(input=args.input, known=args.known, length=int(given.shape[-3]), n=len(landmarks),
                    resample=settings.resample, reconstruction_scale=settings.reconstruction_scale)
        extra["known"] = known
    else:  # geometry
        neutral = _read_npz_array(args.neutral, ["neutral", "landmarks"], "the neutral landmarks")
        label = tasks.order_sensitive_label(args.label, args.order)
        lr = tasks.GEOMETRY_LR if args.lr is None else args.lr
        landmarks = tasks.geometry_adaptive(neutral, label, n=args.n, num_frames=args.length, passes=settings.passes,
                                            steps=steps, reconstruction_scale=settings.reconstruction_scale,
                                            lr=lr, seed=args.seed, dataset=dataset, denoiser=denoiser)
        used.update(label=label, neutral=args.neutral, passes=settings.passes, adagrad_lr=lr,
                    reconstruction_scale=settings.reconstruction_scale, classifier=f"guide_{dataset}_S")
        extra["labels"] = np.array([label] * args.n)
    np.savez(args.out, landmarks=landmarks.astype(np.float32), config=json.dumps(used), **extra)
    print(f"wrote {args.out}: landmarks {landmarks.shape} float32 (mm); config {used}")
    return 0


def _neutral(args):
    if args.out is None or not str(args.out).lower().endswith(".obj"):
        raise ValueError(f"--out must name an .obj file, got {args.out!r}")
    meshio.write_obj(args.out, Face(sample_identity(args.seed)).neutral)
    print(f"wrote {args.out}: the neutral face of identity seed {args.seed} (template topology, mm)")
    return 0


def _animate(args):
    t0 = time.perf_counter()
    neutral = meshio.read_neutral_mesh(args.mesh)
    seconds = {"read mesh": time.perf_counter() - t0}
    steps = config.GeometrySampling().steps if args.steps is None else args.steps
    meshes, landmarks, stages = pipeline.animate(neutral, args.label, order=args.order, steps=steps,
                                                    seed=args.seed, progress=True)
    seconds.update(stages)
    t0 = time.perf_counter()
    frames = [np.concatenate(pair, axis=1) for pair in zip(viz.mesh_frames(meshes, view="front"),
                                                           viz.mesh_frames(meshes, view="three_quarter"))]
    seconds["render GIF"] = time.perf_counter() - t0
    used = {"label": args.label, "order": args.order, "steps": steps, "seed": args.seed, "mesh": str(args.mesh)}
    npz = bytes_io.BytesIO()
    np.savez(npz, landmarks=landmarks[None].astype(np.float32), config=json.dumps(used))
    t0 = time.perf_counter()
    written = meshio.write_animation(args.out, meshes, viz.gif_bytes(frames, 12), extra={"landmarks.npz": npz.getvalue()})
    seconds["write files"] = time.perf_counter() - t0
    print(f"wrote {len(written)} files to {args.out}: {len(meshes)} OBJ frames, animation.gif, landmarks.npz")
    print("\n".join(f"  {k:<12} {v:7.2f} s" for k, v in seconds.items()))
    print(f"  {'total':<12} {sum(seconds.values()):7.2f} s")
    return 0


def _chapter(args):
    mode = "fast" if args.fast else "book"
    path = chapters.find_chapter(args.name)
    print(f"executing {path.relative_to(config.PROJECT_ROOT)} in {mode} mode ...", flush=True)
    seconds, out = chapters.run_chapter(args.name, fast=args.fast)
    budget = chapters.BUDGET_S[mode]
    print(f"{path.stem}: {seconds:.0f} s in {mode} mode (budget {budget} s{'' if seconds <= budget else ', OVER'}); "
          f"executed notebook: {out.relative_to(config.PROJECT_ROOT)}")
    return 0


def _results(args):
    entries = results.catalogue()
    for e in entries:
        state = "ok" if not e["problems"] else "STALE OR MALFORMED: " + "; ".join(e["problems"])
        print(f"{e['name']:<24} {e['minutes']:6.1f} min on {e['cores']} cores, {e['threads']} torch thread(s), "
              f"{e['date']}  {state}\n    {e['command']}")
    print(f"{len(entries)} stored results in {results.RESULTS_DIR}; re-run a command to rewrite its file")
    return 1 if any(e["problems"] for e in entries) else 0


def _default(task, field):
    """'default X; --paper: Y' for the help of a sampling option (config.SAMPLING)."""
    value, paper = (getattr(c, field) for c in (config.SAMPLING[task], config.SAMPLING[task].paper()))
    return f"default {'all T = 2000' if value is None else value}; --paper: {'all T = 2000' if paper is None else paper}"


def _add_sample_parsers(sub):
    """``sample TASK``: one subcommand per task; each option says its default (config.SAMPLING)."""
    common = argparse.ArgumentParser(add_help=False)
    g = common.add_argument_group("every task")
    g.add_argument("--out", required=True, help="output .npz (key 'landmarks': (n, F, 68, 3) float32 in mm, "
                   "and the 'config' that produced it)")
    g.add_argument("--n", type=int, default=16, help="number of sequences (default 16)")
    g.add_argument("--length", type=int, default=40, help="frames per sequence (default 40)")
    g.add_argument("--seed", type=int, default=0, help="default 0")
    g.add_argument("--dataset", default=None, choices=list(data.DATASET_NAMES),
                   help="default coma (text: coma+bu, the paper's merged set)")
    g.add_argument("--checkpoint", default=None, help="denoiser checkpoint (default denoiser_<dataset>)")
    g.add_argument("--paper", action="store_true", help="the paper's printed algorithm: all T = 2000 steps, no "
                   "addition of the book (options given explicitly still apply)")
    p = sub.add_parser("sample", help="generate landmark sequences: sample TASK --out out.npz (see sample TASK --help)")
    tasks = p.add_subparsers(dest="task", required=True, metavar="TASK")
    descriptions = {"unconditional": "the unconditional DDPM (§3.1)", "label": "label control (Alg. 1)",
                    "text": "text control (Alg. 2)", "fill": "expression filling (Alg. 3)",
                    "geometry": "geometry-adaptive generation of a given face (Alg. 4)"}
    parsers = {}
    for task in TASKS:
        parsers[task] = t = tasks.add_parser(task, parents=[common], help=descriptions[task],
                                             description=descriptions[task])
        t.add_argument("--steps", type=int, default=None, help="reverse steps, respaced from T = 2000 ("
                       + _default(task, "steps") + ")")
        t.set_defaults(func=_sample)
    for task in ("label", "text", "geometry"):
        parsers[task].add_argument("--lr", type=float, default=None, help="Adagrad learning rate of the guidance "
                                   "(default: the book's choice for the dataset and the number of steps)")
    t = parsers["label"]
    t.add_argument("--label", required=True, help="an expression label of the dataset, e.g. high_smile")
    t.add_argument("--guidance-weight", type=float, default=None, help="lambda of Alg. 1 ("
                   + _default("label", "guidance_weight") + ")")
    t = parsers["text"]
    t.add_argument("--text", required=True, help='what to show, e.g. "disgust high smile" or "from the neutral face '
                   'to bareteeth"')
    t.add_argument("--score", default=None, choices=["cosine", "contrastive"], help="what Alg. 2 climbs: the cosine "
                   "of Eq. 10 or the text head's log-probability of the text among the training descriptions ("
                   + _default("text", "score") + ")")
    t.add_argument("--guidance-weight", type=float, default=None, help="lambda of Alg. 2 (default: the book's "
                   "choice for the score, tasks.text_guidance_weight)")
    t.add_argument("--head-input", default="x_t", choices=["x_t", "x0_hat"], help="what the text head reads: x_t "
                   "(Alg. 2) or the denoiser's estimate of the clean sequence (default x_t)")
    t.add_argument("--vocabulary", action="store_true", help="with --score contrastive: match the text against "
                   "every description of the vocabulary, also those no network has seen")
    t.add_argument("--particles", type=int, default=1, help="best-of-K: K guided chains per sequence, the text "
                   "head keeps one at the time label tasks.SELECT_TIME (default 1)")
    t.add_argument("--max-time", type=float, default=None, help="leave the steps above this time label unguided "
                   "(default: guide all)")
    t.add_argument("--decoder-start", type=int, default=None, help="instead of Alg. 2: re-noise the MotionCLIP-style "
                   "decoder's sequence to this step and denoise it (tasks.DECODER_START = 400 in the book)")
    t = parsers["fill"]
    t.add_argument("--input", required=True, help=".npz whose 'landmarks' (F, 68, 3) or (n, F, 68, 3) holds the "
                   "sequence(s) to complete")
    t.add_argument("--known", required=True, help="known frames as 0-based ranges, e.g. 0:10,30:40")
    t.add_argument("--reconstruction-scale", type=float, default=None, help="reconstruction guidance zeta ("
                   + _default("fill", "reconstruction_scale") + ")")
    t.add_argument("--resample", type=int, default=None, help="RePaint's resampling r (" + _default("fill", "resample")
                   + ")")
    t = parsers["geometry"]
    t.add_argument("--label", required=True, help="an expression label, e.g. mouth_open (or 'mouth_open E2N')")
    t.add_argument("--neutral", required=True, help=".npz with the neutral landmarks (68, 3) in mm (key 'neutral' or "
                   "'landmarks')")
    t.add_argument("--order", default=None, choices=["N2E", "E2N"], help="neutral face first (N2E, the default) or last")
    t.add_argument("--passes", type=int, default=None, help="harmonising passes of Alg. 4 (" + _default("geometry",
                   "passes") + ")")
    t.add_argument("--reconstruction-scale", type=float, default=None, help="reconstruction guidance zeta ("
                   + _default("geometry", "reconstruction_scale") + ")")


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m facelib", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("data", help="build (or verify) the synthetic dataset caches and print a summary")
    p.add_argument("--name", default="all", choices=["all", *config.DATASETS])
    p.add_argument("--frames", type=int, default=40, help="frames per sequence (default 40, as in the paper)")
    p.add_argument("--rebuild", action="store_true", help="regenerate even if a valid cache exists")
    p.add_argument("--write-fingerprints", action="store_true",
                   help="record the datasets' fingerprints in data/synthetic/fingerprints.json")
    p.set_defaults(func=_data)

    p = sub.add_parser("train", help="train a model and save it in data/checkpoints (.pt + .json); under "
                       "`torchrun --nproc_per_node N -m facelib train ...` on N processes (distributed data parallel)")
    p.add_argument("name", choices=list(TRAINABLE), help="denoiser: eps_theta of §3.1; guide: the noisy classifier of "
                   "Alg. 1/4; text_head: BiT(x_t, t) of Alg. 2; evaluator: the independent LSTM classifier of §5; "
                   "motion3dgan, actor: the baselines of Table 1; motionclip: the baseline of Table 2; lstm_filler: "
                   "the baseline of Table 3; deformer: the mesh deformation of §3.3 and the baselines of Table 5")
    p.add_argument("--dataset", default=None, choices=list(data.DATASET_NAMES),
                   help="default: the recipe's (coma; coma+bu for text_head and motionclip, as §5.2)")
    p.add_argument("--type", default=None, choices=list(data.CLASSIFIER_TYPES), help="guide, evaluator: I = label, "
                   "S = label x N2E/E2N (default I)")
    p.add_argument("--variable-length", action="store_true", help="denoiser: train on lengths 35-45 (paper App. A)")
    p.add_argument("--method", default=None, choices=["ours", "no_attention", "s2d", "coma", "linear"],
                   help="deformer: a row of Table 5 (default ours)")
    p.add_argument("--split", default=None, choices=["identity", "expression"], help="deformer: 3 subjects "
                   "or 3 expressions held out, as §6 (default identity)")
    p.add_argument("--steps", type=int, default=None, help="training steps (default: the recipe's, facelib/config.py)")
    p.add_argument("--batch-size", type=int, default=None, help="global batch, split over the processes "
                   "(default: the recipe's)")
    p.add_argument("--fast", action="store_true", help="the recipe's fast-mode settings (a few steps, for tests)")
    p.add_argument("--seed", type=int, default=None, help="default: the recipe's (0)")
    p.add_argument("--device", default=None, choices=["cpu", "cuda"], help="default: a GPU when torch sees one")
    p.add_argument("--resume", action="store_true", help="continue from <out>.state.pt if a run left one "
                   "(the state is written every 500 steps)")
    p.add_argument("--out", default=None, help="checkpoint name or path stem (default: denoiser_<dataset>[_var], "
                   "guide_<dataset>_<type>, ic_<dataset>_<type>, deform_<method>_<split>, <baseline>_<dataset>)")
    p.set_defaults(func=_train)

    _add_sample_parsers(sub)

    p = sub.add_parser("neutral", help="write the neutral mesh of a new synthetic identity as OBJ (template topology)")
    p.add_argument("--seed", type=int, default=0, help="identity seed")
    p.add_argument("--out", required=True, help="output .obj")
    p.set_defaults(func=_neutral)

    p = sub.add_parser("animate", help="animate a neutral mesh: landmarks, geometry-adaptive generation (Alg. 4), "
                       "deformation (§3.3); writes an OBJ per frame, animation.gif and landmarks.npz")
    p.add_argument("--mesh", required=True, help="neutral mesh (.obj, ...) with the template topology")
    p.add_argument("--label", required=True, help="expression label of the CoMA-like set, e.g. high_smile")
    p.add_argument("--order", default="N2E", choices=["N2E", "E2N"], help="neutral face first (N2E) or last (E2N)")
    p.add_argument("--steps", type=int, default=None, help="reverse steps per pass of Alg. 4 (default: "
                   "config.GeometrySampling: 100, the book's respaced chain)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True, help="output folder (written all at once, or not at all)")
    p.set_defaults(func=_animate)

    p = sub.add_parser("chapter", help="execute one chapter (book mode unless --fast), print its time; the executed "
                       "notebook goes to _build/chapters/ (make chapter N=05)")
    p.add_argument("name", help="chapter number (05), file stem (05_label_control) or name (label_control)")
    p.add_argument("--fast", action="store_true", help="fast mode (FACELIB_FAST=1), as the tests run it")
    p.set_defaults(func=_chapter)

    p = sub.add_parser("results", help="list the stored full-scale results (results/*.json): wall time, date, "
                       "whether each is fresh, and the command that rewrites it")
    p.set_defaults(func=_results)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ValueError as e:
        parser.error(str(e))


if __name__ == "__main__":
    sys.exit(main())
