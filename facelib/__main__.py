"""Command line of the book: ``python -m facelib {data,train,sample,neutral,animate,chapter,results}`` (see ``--help`` of each)."""
from __future__ import annotations

import argparse
import json
import sys
import time

from . import config, data


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
    from dataclasses import replace

    from . import training
    settings = {"seed": args.seed}
    if args.name in ("denoiser", "guide", "text_head", "evaluator", "actor", "motionclip", "motion3dgan", "lstm_filler"):
        settings["dataset"] = args.dataset or ("coma+bu" if args.name in ("text_head", "motionclip") else "coma")
    if args.name in ("guide", "evaluator"):
        settings["classifier_type"] = args.type
    if args.name == "deformer":
        settings.update(method=args.method, split=args.split)
    if args.variable_length:
        if args.name != "denoiser":
            raise ValueError("--variable-length trains a denoiser (paper App. A): use it with `train denoiser`")
        settings["num_frames"] = (35, 45)
    if args.batch_size:
        settings["batch_size"] = args.batch_size
    recipe = training.recipe(args.name, **settings)
    if args.fast:
        recipe.settings = recipe.settings.fast()
    elif args.steps:
        if recipe.settings.epochs is not None:
            raise ValueError(f"{args.name} trains for a number of epochs ({recipe.settings.epochs}): --steps does not apply")
        recipe.settings = recipe.settings.with_steps(args.steps)
    t0 = time.perf_counter()
    written = training.train_and_save(recipe, name=args.out, device=args.device, resume=args.resume)
    if written:
        print(f"trained in {time.perf_counter() - t0:.0f} s; wrote {written[0]} and {written[1]}")
    return 0


def _read_npz_array(path, keys, what):
    """The first of ``keys`` found in an .npz (a clear error naming the file and the keys otherwise)."""
    import numpy as np
    try:
        with np.load(path) as f:
            for key in keys:
                if key in f:
                    return np.asarray(f[key], dtype=np.float64)
            found = list(f.keys())
    except (OSError, ValueError) as e:
        raise ValueError(f"cannot read {what} from {path}: {e}") from None
    raise ValueError(f"{path} has no {' or '.join(repr(k) for k in keys)} array ({what}); it has {found}")


def _sample(args):
    import numpy as np

    from . import guidance, inpainting, tasks
    if args.task not in TASKS:
        raise ValueError(f"unknown task {args.task!r}; allowed: {', '.join(TASKS)}")
    if args.task in ("label", "geometry") and args.label is None:
        raise ValueError(f"--task {args.task} needs --label (e.g. --label high_smile)")
    if args.task == "text" and args.text is None:
        raise ValueError('--task text needs --text (e.g. --text "disgust high smile")')
    if args.decoder_start is not None and (args.task != "text" or args.lr is not None or args.guidance_weight is not None
                                           or args.head_input != "x_t" or args.score != "cosine"
                                           or args.particles != 1 or args.max_time is not None or args.vocabulary):
        raise ValueError("--decoder-start belongs to --task text and replaces Alg. 2's guidance: it takes no --lr, "
                         "--guidance-weight, --head-input, --score, --vocabulary, --particles or --max-time")
    if (args.particles != 1 or args.max_time is not None or args.vocabulary) and args.task != "text":
        raise ValueError("--particles, --max-time and --vocabulary belong to --task text")
    dataset = args.dataset or (tasks.TEXT_DATASET if args.task == "text" else "coma")
    denoiser = tasks.load_denoiser(args.checkpoint or f"denoiser_{dataset}")
    used = {"task": args.task, "n": args.n, "length": args.length, "seed": args.seed,
            "steps": args.steps or denoiser.diffusion.num_steps, "checkpoint": args.checkpoint or f"denoiser_{dataset}",
            "checkpoint_sha256": denoiser.meta["sha256"]}
    extra = {}
    lr = args.lr  # None: the task's default Adagrad rate (Alg. 1, 2 and 4)
    if lr is None and args.task in ("text", "geometry", "label"):
        lr = (tasks.text_lr(args.steps, score=args.score) if args.task == "text" else tasks.GEOMETRY_LR if args.task == "geometry"
              else tasks.adagrad_lr(dataset, args.steps))
    weight = ((tasks.text_guidance_weight(args.score) if args.task == "text" else guidance.GUIDANCE_WEIGHT)
              if args.guidance_weight is None else args.guidance_weight)
    if args.task == "unconditional":
        landmarks = tasks.unconditional(args.n, num_frames=args.length, seed=args.seed, steps=args.steps,
                                        denoiser=denoiser)
    elif args.task == "text" and args.decoder_start is not None:
        landmarks = tasks.decoder_then_diffusion(args.text, args.n, start=args.decoder_start, dataset=dataset,
                                                 num_frames=args.length, steps=args.steps, seed=args.seed,
                                                 denoiser=denoiser)
        used.update(dataset=dataset, text=args.text, method="decoder_then_diffusion", decoder_start=args.decoder_start,
                    decoder=f"motionclip_{dataset}")
        extra["texts"] = np.array([args.text] * args.n)
    elif args.task == "text":
        landmarks = tasks.text_control(args.text, args.n, dataset=dataset, num_frames=args.length, steps=args.steps,
                                       guidance_weight=weight, lr=lr, head_input=args.head_input, score=args.score,
                                       vocabulary=args.vocabulary, particles=args.particles, max_time=args.max_time,
                                       seed=args.seed, denoiser=denoiser)
        used.update(dataset=dataset, text=args.text, method="alg2", guidance_weight=weight, adagrad_lr=lr,
                    head_input=args.head_input, score=args.score, vocabulary=args.vocabulary,
                    adagrad_steps=guidance.ADAGRAD_STEPS,
                    particles=args.particles, select_time=tasks.SELECT_TIME if args.particles > 1 else None,
                    max_time=args.max_time, text_head=f"guide_{dataset}_text")
        extra["texts"] = np.array([args.text] * args.n)
    elif args.task == "fill":
        if args.input is None or args.known is None:
            raise ValueError("--task fill needs --input seq.npz (key 'landmarks') and --known ranges, e.g. 0:10,30:40")
        given = _read_npz_array(args.input, ["landmarks"], "the sequence to fill")
        if given.ndim not in (3, 4) or given.shape[-2:] != (68, 3):
            raise ValueError(f"{args.input}: 'landmarks' must be (F, 68, 3) or (n, F, 68, 3) in mm, got {given.shape}")
        known = inpainting.parse_known(args.known, given.shape[-3])
        landmarks = tasks.fill(given, known, steps=args.steps, reconstruction_scale=args.reconstruction_scale,
                               seed=args.seed, denoiser=denoiser)
        used.update(input=args.input, known=args.known, length=int(given.shape[-3]), n=len(landmarks),
                    reconstruction_scale=args.reconstruction_scale)
        extra["known"] = known
    elif args.task == "geometry":
        if args.neutral is None:
            raise ValueError("--task geometry needs --neutral neutral.npz (key 'neutral' or 'landmarks', (68, 3) mm)")
        neutral = _read_npz_array(args.neutral, ["neutral", "landmarks"], "the neutral landmarks")
        label = tasks.order_sensitive_label(args.label, args.order)
        landmarks = tasks.geometry_adaptive(neutral, label, n=args.n, num_frames=args.length, passes=args.passes,
                                            steps=args.steps, reconstruction_scale=args.reconstruction_scale,
                                            guidance_weight=weight, lr=lr, seed=args.seed,
                                            dataset=dataset, denoiser=denoiser)
        used.update(dataset=dataset, label=label, neutral=args.neutral, passes=args.passes,
                    reconstruction_scale=args.reconstruction_scale,
                    guidance_weight=weight, adagrad_lr=lr, classifier="guide_" + dataset + "_S")
        extra["labels"] = np.array([label] * args.n)
    else:
        landmarks = tasks.label_control(args.label, args.n, dataset=dataset, num_frames=args.length,
                                        steps=args.steps, guidance_weight=weight, lr=lr,
                                        seed=args.seed, denoiser=denoiser)
        used.update(dataset=dataset, label=args.label, guidance_weight=weight, adagrad_lr=lr,
                    adagrad_steps=guidance.ADAGRAD_STEPS, classifier="guide_" + dataset + "_I")
        extra["labels"] = np.array([args.label] * args.n)
    np.savez(args.out, landmarks=landmarks.astype(np.float32), config=json.dumps(used), **extra)
    print(f"wrote {args.out}: landmarks {landmarks.shape} float32 (mm); config {used}")
    return 0


def _neutral(args):
    from .face import Face, sample_identity
    from .io import write_obj
    if args.out is None or not str(args.out).lower().endswith(".obj"):
        raise ValueError(f"--out must name an .obj file, got {args.out!r}")
    write_obj(args.out, Face(sample_identity(args.seed)).neutral)
    print(f"wrote {args.out}: the neutral face of identity seed {args.seed} (template topology, mm)")
    return 0


def _animate(args):
    import io as bytes_io

    import numpy as np

    from . import deformation, io, viz
    t0 = time.perf_counter()
    neutral = io.read_neutral_mesh(args.mesh)
    seconds = {"read mesh": time.perf_counter() - t0}
    steps = deformation.ANIMATE_STEPS if args.steps is None else args.steps
    meshes, landmarks, stages = deformation.animate(neutral, args.label, order=args.order, steps=steps,
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
    written = io.write_animation(args.out, meshes, frames, fps=12, extra={"landmarks.npz": npz.getvalue()})
    seconds["write files"] = time.perf_counter() - t0
    print(f"wrote {len(written)} files to {args.out}: {len(meshes)} OBJ frames, animation.gif, landmarks.npz")
    print("\n".join(f"  {k:<12} {v:7.2f} s" for k, v in seconds.items()))
    print(f"  {'total':<12} {sum(seconds.values()):7.2f} s")
    return 0


def _chapter(args):
    from . import chapters
    mode = "fast" if args.fast else "book"
    path = chapters.find_chapter(args.name)
    print(f"executing {path.relative_to(config.PROJECT_ROOT)} in {mode} mode ...", flush=True)
    seconds, out = chapters.run_chapter(args.name, fast=args.fast)
    budget = chapters.BUDGET_S[mode]
    print(f"{path.stem}: {seconds:.0f} s in {mode} mode (budget {budget} s{'' if seconds <= budget else ', OVER'}); "
          f"executed notebook: {out.relative_to(config.PROJECT_ROOT)}")
    return 0


def _results(args):
    from . import results
    entries = results.catalogue()
    for e in entries:
        state = "ok" if not e["problems"] else "STALE OR MALFORMED: " + "; ".join(e["problems"])
        print(f"{e['name']:<24} {e['minutes']:6.1f} min on {e['cores']} cores, {e['threads']} torch thread(s), "
              f"{e['date']}  {state}\n    {e['command']}")
    print(f"{len(entries)} stored results in {results.RESULTS_DIR}; re-run a command to rewrite its file")
    return 1 if any(e["problems"] for e in entries) else 0


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
                   help="default: coma (coma+bu for text_head and motionclip, as §5.2)")
    p.add_argument("--type", default="I", choices=list(data.CLASSIFIER_TYPES), help="guide, evaluator: I = label, "
                   "S = label x N2E/E2N (default I)")
    p.add_argument("--variable-length", action="store_true", help="denoiser: train on lengths 35-45 (paper App. A)")
    p.add_argument("--method", default="ours", choices=["ours", "no_attention", "s2d", "coma", "linear"],
                   help="deformer: a row of Table 5 (default ours)")
    p.add_argument("--split", default="identity", choices=["identity", "expression"], help="deformer: 3 subjects "
                   "or 3 expressions held out, as §6 (default identity)")
    p.add_argument("--steps", type=int, default=None, help="training steps (default: the recipe's, facelib/config.py)")
    p.add_argument("--batch-size", type=int, default=None, help="global batch, split over the processes "
                   "(default: the recipe's)")
    p.add_argument("--fast", action="store_true", help="the recipe's fast-mode settings (a few steps, for tests)")
    p.add_argument("--seed", type=int, default=0, help="default 0")
    p.add_argument("--device", default=None, choices=["cpu", "cuda"], help="default: a GPU when torch sees one")
    p.add_argument("--resume", action="store_true", help="continue from <out>.state.pt if a run left one "
                   "(the state is written every 500 steps)")
    p.add_argument("--out", default=None, help="checkpoint name or path stem (default: denoiser_<dataset>[_var], "
                   "guide_<dataset>_<type>, ic_<dataset>_<type>, deform_<method>_<split>, <baseline>_<dataset>)")
    p.set_defaults(func=_train)

    p = sub.add_parser("sample", help="generate landmark sequences and write them to an .npz")
    p.add_argument("--task", default="unconditional", help="unconditional, label (Alg. 1), text (Alg. 2), "
                   "fill (Alg. 3) or geometry (Alg. 4)")
    p.add_argument("--dataset", default=None, choices=list(data.DATASET_NAMES),
                   help="default: coma (coma+bu, the paper's merged set, for --task text)")
    p.add_argument("--label", default=None, help="expression label for --task label or geometry (e.g. high_smile)")
    p.add_argument("--text", default=None, help='--task text: what to show, e.g. "disgust high smile" or '
                   '"from the neutral face to bareteeth"')
    p.add_argument("--guidance-weight", type=float, default=None, help="lambda of Alg. 1-2 (default: the paper's 0.01; "
                   "tasks.text_guidance_weight(score) for --task text, chapter 06)")
    p.add_argument("--lr", type=float, default=None, help="Adagrad learning rate of Alg. 1, 2 and 4 "
                   "(default: the book's choice for the task and the number of steps)")
    p.add_argument("--head-input", default="x_t", choices=["x_t", "x0_hat"], help="--task text: what the text head "
                   "reads, x_t (Alg. 2) or x0_hat (the denoiser's estimate of the clean sequence; not in the paper, "
                   "chapter 06 section 8)")
    p.add_argument("--score", default="cosine", choices=["cosine", "contrastive"], help="--task text: the score "
                   "that Alg. 2 climbs, the cosine of Eq. 10 or the text head's log-probability of the text against "
                   "the training descriptions (not in the paper; chapter 06 section 10)")
    p.add_argument("--vocabulary", action="store_true", help="--task text with --score contrastive: match the text "
                   "against the vocabulary, the training descriptions and those written blind (not in the paper; "
                   "chapter 06 section 12)")
    p.add_argument("--particles", type=int, default=1, help="--task text: best-of-K, K guided chains per sequence "
                   "until the time label tasks.SELECT_TIME, where the text head keeps one (not in the paper; chapter 06 "
                   "section 11; default 1)")
    p.add_argument("--max-time", type=float, default=None, help="--task text: leave the steps above this time label "
                   "unguided (not in the paper; chapter 06 section 11 uses tasks.PARTICLE_MAX_TIME; default: guide all)")
    p.add_argument("--decoder-start", type=int, default=None, help="--task text: instead of Alg. 2, re-noise the "
                   "MotionCLIP-style decoder's sequence to this step and denoise it (not in the paper; chapter 06 "
                   "section 9 uses facelib.tasks.DECODER_START)")
    p.add_argument("--order", default=None, choices=["N2E", "E2N"], help="--task geometry: neutral face first "
                   "(N2E, the default) or last (E2N)")
    p.add_argument("--passes", type=int, default=5, help="--task geometry: harmonising passes of Alg. 4 (default 5)")
    p.add_argument("--reconstruction-scale", type=float, default=0.0, help="--task fill or geometry: reconstruction "
                   "guidance step (not in the paper; chapters 07-08 use facelib.tasks.RECONSTRUCTION_SCALE; default 0 = "
                   "Alg. 3 / Alg. 4 as printed)")
    p.add_argument("--input", default=None, help="--task fill: .npz whose 'landmarks' (F, 68, 3) or (n, F, 68, 3) "
                   "holds the sequence(s) to complete")
    p.add_argument("--known", default=None, help="--task fill: known frames as 0-based ranges, e.g. 0:10,30:40")
    p.add_argument("--neutral", default=None, help="--task geometry: .npz with the neutral landmarks (68, 3) in mm "
                   "(key 'neutral' or 'landmarks')")
    p.add_argument("--n", type=int, default=16, help="number of sequences")
    p.add_argument("--length", type=int, default=40, help="frames per sequence")
    p.add_argument("--steps", type=int, default=None, help="reverse steps (default: all T = 2000; fewer = respaced)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--checkpoint", default=None, help="denoiser checkpoint (default: denoiser_<dataset>)")
    p.add_argument("--out", required=True, help="output .npz (key 'landmarks': (n, F, 68, 3) float32 in mm)")
    p.set_defaults(func=_sample)

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
                   "facelib.deformation.ANIMATE_STEPS, the book's respaced chain)")
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
