"""The one training loop of facelib: every model is a small recipe (settings + model +
loss) run by :func:`fit`.

What the loop owns, once for every model: the seed, the optimiser (Adam or AdamW),
linear warm-up then cosine decay of the learning rate, gradient-norm clipping, an
exponential moving average (EMA) of the weights (which copies the model's buffers),
the loss curves (:class:`TrainingLog`), resuming an interrupted run, and distributed
data parallel training.  What a recipe owns (facelib/training/recipes.py): its data,
how to build the model and the loss of one batch.

Distributed training.  Under ``torchrun --nproc_per_node N -m facelib train ...`` every
process runs this same loop on its own shard of each batch, wrapped in PyTorch's
DistributedDataParallel (gloo on CPU, nccl on GPU), which averages the gradients.  Every
random draw of a step is made for the *global* batch from one stream seeded alike in
every process, and each process keeps its rows (rank, rank + N, ...), the interleaving
of torch's DistributedSampler: N processes see exactly the examples and noise of one
process with the same global batch, and, without dropout, take the same steps up to
float rounding (tests/test_training.py checks it).  Dropout draws from torch's global
stream, which is not sharded: rank 0 keeps a single process's stream and rank r > 0
reseeds it with seed + r once the model is built, so that the processes drop different
units; with dropout, N processes train as well as one but not bit for bit like it.  The
logged values are averaged over the processes (the loss of the global batch).  Only rank
0 writes files; the process group that fit formed is destroyed when it returns.
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import math
import os
import time
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from tqdm.auto import tqdm
from ..files import atomic_write
from .settings import Optimisation



class TrainingLog:
    """Collects per-step values and, every ``every`` steps and at the last one, appends
    their running mean to ``history[name]`` together with the step number and the
    elapsed seconds.

    ``history`` is a plain dict of lists ({"step": [...], name: [...], ..., "seconds":
    [...]}), saved in the checkpoint's JSON and plotted by the chapters."""

    def __init__(self, total_steps, every, history=None):
        self.total_steps, self.every = total_steps, every
        self.history = history or {"step": [], "seconds": []}
        self._running = {}
        self._t0 = time.perf_counter() - (
            self.history["seconds"][-1] if self.history["seconds"] else 0.0
        )

    def add(self, step, **values):
        """Record the values of (0-based) ``step``; a value may be a float or a 0-d
        tensor."""
        for name, value in values.items():
            self._running.setdefault(name, []).append(float(value))
        if (step + 1) % self.every == 0 or step + 1 == self.total_steps:
            self.history["step"].append(step + 1)
            for name, running in self._running.items():
                self.history.setdefault(name, []).append(float(np.mean(running)))
                running.clear()
            self.history["seconds"].append(time.perf_counter() - self._t0)


class Draws:
    """The random draws of one step, made for the global batch and sharded (see the
    module docstring).

    ``draws.randn(F, 68, 3)`` is (local batch, F, 68, 3); ``draws.generator`` is the
    shared stream itself, for draws that are not per example (all processes make them
    alike)."""

    def __init__(
        self, generator, batch_size, rank=0, world=1, device="cpu", indices=None
    ):
        self.generator, self.batch_size, self.rank, self.world, self.device = (
            generator,
            batch_size,
            rank,
            world,
            device,
        )
        self.indices = None if indices is None else self.shard(indices)

    def shard(self, x):
        """The rows of the global batch ``x`` that this process trains on."""
        return x[self.rank :: self.world].to(self.device)

    def randint(self, low, high, *shape):
        return self.shard(
            torch.randint(
                low, high, (self.batch_size, *shape), generator=self.generator
            )
        )

    def randn(self, *shape):
        return self.shard(
            torch.randn((self.batch_size, *shape), generator=self.generator)
        )

    def rand(self, *shape):
        return self.shard(
            torch.rand((self.batch_size, *shape), generator=self.generator)
        )

    def examples(self, size):
        """Indices of this process's examples: the pass's batch (``epochs`` recipes) or
        a uniform draw."""
        return self.indices if self.indices is not None else self.randint(0, size)

    def rows(self, make):
        """``make(global batch size, generator)`` -> a global batch of anything,
        sharded."""
        return self.shard(make(self.batch_size, self.generator))


@dataclass
class Objective:
    """One optimiser's job within a step: ``loss(draws) -> (loss, {name: value})``
    updates ``module``'s parameters, ``repeats`` times per step (a GAN's critic has 5,
    its generator 1)."""

    module: torch.nn.Module
    loss: Callable
    repeats: int = 1


class _LossOf(torch.nn.Module):
    """A module whose forward is an objective's loss, so that DistributedDataParallel
    sees the whole computation (recipes call their networks' methods, not only
    forward)."""

    def __init__(self, objective):
        super().__init__()
        self.module, self._loss = objective.module, objective.loss

    def forward(self, draws):
        return self._loss(draws)


@dataclass(frozen=True)
class Distributed:
    """Where this process trains: its rank among ``world`` processes and its device."""

    rank: int = 0
    world: int = 1
    device: torch.device = torch.device("cpu")

    @property
    def is_main(self):
        return self.rank == 0


def device_for(name=None):
    """The torch device for "cpu", "cuda" or None (a GPU when one is visible), with a
    clear error for an absent one (before any process group is formed, so that no
    process is left waiting).
    """
    if name is None:
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name not in ("cpu", "cuda"):
        raise ValueError(f"device must be 'cpu' or 'cuda', got {name!r}")
    if name == "cuda" and not torch.cuda.is_available():
        raise ValueError(
            "device 'cuda' was asked for but torch sees no CUDA device "
            "(torch.cuda.is_available() is False): use --device cpu"
        )
    return torch.device(name)


# torchrun's store, kept for the process group of a later fit
_RENDEZVOUS = {"store": None, "groups": 0}


def start_distributed(device=None, timeout_s=120):
    """Join the process group when started by torchrun (WORLD_SIZE > 1), else a single
    process.

    Each group formed here has its own prefix in torchrun's store: a group formed after
    :func:`fit` destroyed one (e.g. ``train all``) would otherwise read the keys the
    previous group left there.
    """
    world = int(os.environ.get("WORLD_SIZE", "1"))
    dev = device_for(device)
    if world == 1:
        return Distributed(0, 1, dev)
    rank, local_rank = int(os.environ["RANK"]), int(os.environ.get("LOCAL_RANK", "0"))
    if dev.type == "cuda":
        if torch.cuda.device_count() <= local_rank:
            raise ValueError(
                f"process {rank} needs GPU {local_rank} but torch sees"
                f" {torch.cuda.device_count()}: start at most as many processes per"
                " node as there are GPUs"
            )
        dev = torch.device("cuda", local_rank)
        torch.cuda.set_device(dev)
    if not torch.distributed.is_initialized():
        timeout = timedelta(seconds=timeout_s)
        if _RENDEZVOUS["store"] is None:
            _RENDEZVOUS["store"] = next(
                torch.distributed.rendezvous("env://", timeout=timeout)
            )[0]
        _RENDEZVOUS["groups"] += 1
        store = torch.distributed.PrefixStore(
            f"facelib_group{_RENDEZVOUS['groups']}/", _RENDEZVOUS["store"]
        )
        torch.distributed.init_process_group(
            "nccl" if dev.type == "cuda" else "gloo",
            store=store,
            rank=rank,
            world_size=world,
            timeout=timeout,
        )
    return Distributed(rank, world, dev)


def is_main_process():
    """True in a single process and on rank 0 of a distributed run (the one that writes
    files), also once :func:`fit` has destroyed its process group (torchrun's RANK)."""
    if torch.distributed.is_initialized():
        return torch.distributed.get_rank() == 0
    return int(os.environ.get("RANK", "0")) == 0


def learning_rate(settings: Optimisation, step, total_steps):
    """Linear warm-up over ``warmup`` steps, then a cosine from lr to lr *
    final_lr_fraction."""
    if step < settings.warmup:
        return settings.lr * (step + 1) / settings.warmup
    progress = (step - settings.warmup) / max(1, total_steps - settings.warmup)
    f = settings.final_lr_fraction
    return settings.lr * (f + (1 - f) * 0.5 * (1 + math.cos(math.pi * progress)))


def _optimiser(settings, module):
    kind = torch.optim.Adam if settings.optimizer == "adam" else torch.optim.AdamW
    return kind(
        module.parameters(),
        lr=settings.lr,
        betas=tuple(settings.betas),
        weight_decay=settings.weight_decay,
    )


def _batches(settings, size, generator):
    """Global batches of example indices: None for each of ``steps`` steps (the recipe
    draws its batch with replacement), or ``epochs`` passes through a new permutation
    each.  Returns (steps, iterator).
    """
    if settings.epochs is None:
        return settings.steps, itertools.repeat(None)
    per_epoch = math.ceil(size / settings.batch_size)

    def passes():
        for _ in range(settings.epochs):
            order = torch.randperm(size, generator=generator)
            yield from (
                order[i * settings.batch_size : (i + 1) * settings.batch_size]
                for i in range(per_epoch)
            )

    return settings.epochs * per_epoch, passes()


def _state_path(resume_from):
    return Path(resume_from).with_suffix(".state.pt")


def fit(
    recipe,
    progress=True,
    log_every=50,
    device=None,
    resume_from=None,
    save_every=500,
    validate_every=500,
):
    """Train ``recipe``'s model with its settings; returns (model, history) on every
    process.

    The model returned is the EMA of the weights when the settings keep one, with the
    model's buffers (BatchNorm statistics, counters) copied at every step.  A recipe
    with a ``validate(model) -> {name: value}`` method (the denoiser's held-out losses
    per noise level) has it called on the model that would be returned every
    ``validate_every`` steps and at the last; the values go to ``history["held_out"]``
    ({"step": [...], name: [...]}).  ``resume_from``: a path stem; every ``save_every``
    steps and at the last step rank 0 writes the training state to ``<stem>.state.pt``
    (atomically: a temporary file in the same folder, then renamed, so that a kill
    mid-write leaves the previous state intact).  The state holds the step; the weights
    and buffers of the model and of every module an objective trains (a GAN's critic
    too); the EMA; every optimiser; the shared stream of the draws; torch's global
    random state (dropout) of every process (and of its GPU); the loss curves with the
    values not yet averaged into them; and the run's record (recipe name, settings,
    model config, number of processes).  A run given an existing state continues from it
    and ends with the weights, EMA and loss curves of a run that had not stopped, bit
    for bit on a CPU (on a GPU, as far as its kernels are deterministic); the curves'
    wall-clock "seconds" are the only difference.  A state whose record differs from
    this run's is refused with the fields that differ.  Recipes that walk epochs do not
    resume (a state left by one is refused)."""
    owns_group = not torch.distributed.is_initialized()
    dist = start_distributed(device)
    owns_group = owns_group and torch.distributed.is_initialized()
    try:
        return _fit(
            recipe, dist, progress, log_every, resume_from, save_every, validate_every
        )
    finally:
        if owns_group:
            torch.distributed.destroy_process_group()


def _fit(recipe, dist, progress, log_every, resume_from, save_every, validate_every):
    settings = recipe.settings
    torch.manual_seed(settings.seed)
    generator = torch.Generator().manual_seed(settings.seed)
    model = recipe.build(generator).to(dist.device)
    recipe.to(dist.device)
    objectives = recipe.objectives(model)
    if dist.world > 1:
        if not getattr(recipe, "distributed", True):
            raise ValueError(
                f"{type(recipe).__name__} trains on one process only (its draws are not"
                " per example)"
            )
        if settings.batch_size % dist.world:
            raise ValueError(
                f"the batch of {settings.batch_size} does not split into {dist.world}"
                " equal shards"
            )
    losses = [
        (
            _LossOf(o)
            if dist.world == 1
            else torch.nn.parallel.DistributedDataParallel(_LossOf(o))
        )
        for o in objectives
    ]
    if dist.rank:
        # each process its own dropout (see the module docstring)
        torch.manual_seed(settings.seed + dist.rank)
    optimisers = [_optimiser(settings, o.module) for o in objectives]
    ema = (
        copy.deepcopy(model).requires_grad_(False)
        if settings.ema_decay is not None
        else None
    )
    total, batches = _batches(settings, recipe.size, generator)
    log = TrainingLog(total, total // settings.epochs if settings.epochs else log_every)
    trained = _Trained(
        model, [o.module for o in objectives], ema, optimisers, generator, log
    )
    record = _record(recipe, model, dist.world)
    start = 0
    if resume_from is not None and _state_path(resume_from).exists():
        if settings.epochs is not None:
            raise ValueError(
                "resuming works for recipes that draw batches with replacement"
                " (epochs=None)"
            )
        start = _load_state(_state_path(resume_from), trained, record, dist)
    model.train()
    bar = tqdm(
        range(start, total),
        desc=f"train {recipe.name}",
        disable=not (progress and dist.is_main),
    )
    for step, indices in zip(bar, batches):
        for opt in optimisers:
            for group in opt.param_groups:
                group["lr"] = learning_rate(settings, step, total)
        values = {}
        for objective, loss_of, opt in zip(objectives, losses, optimisers):
            for _ in range(objective.repeats):
                draws = Draws(
                    generator,
                    settings.batch_size if indices is None else len(indices),
                    dist.rank,
                    dist.world,
                    dist.device,
                    indices,
                )
                loss, metrics = loss_of(draws)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                if settings.grad_clip is not None:
                    torch.nn.utils.clip_grad_norm_(
                        objective.module.parameters(), settings.grad_clip
                    )
                opt.step()
                values.update(metrics)
        if ema is not None:
            with torch.no_grad():
                decay = min(settings.ema_decay, (1 + step) / (10 + step))
                for pe, pm in zip(ema.parameters(), model.parameters()):
                    pe.lerp_(pm, 1 - decay)
                # buffers (running statistics, counters) are copied, not averaged
                for be, bm in zip(ema.buffers(), model.buffers()):
                    be.copy_(bm)
        log.add(step, **_mean_over_processes(values, dist))
        if hasattr(recipe, "validate") and (
            (step + 1) % validate_every == 0 or step + 1 == total
        ):
            held_out = log.history.setdefault("held_out", {"step": []})
            held_out["step"].append(step + 1)
            for name, value in recipe.validate(
                ema if ema is not None else model
            ).items():
                held_out.setdefault(name, []).append(value)
        if resume_from is not None and (
            (step + 1) % save_every == 0 or step + 1 == total
        ):
            # a collective: every process takes part
            random_states = _random_states(dist)
            if dist.is_main:
                _save_state(
                    _state_path(resume_from), step + 1, trained, record, random_states
                )
    result = (ema if ema is not None else model).eval()
    return result, log.history


def _mean_over_processes(values, dist):
    """The logged values averaged over the processes (each process's are those of its
    shard)."""
    if dist.world == 1 or not values:
        return values
    total = torch.tensor(list(values.values()), dtype=torch.float64, device=dist.device)
    torch.distributed.all_reduce(total)
    return dict(zip(values, (total / dist.world).tolist()))


@dataclass
class _Trained:
    """What a run changes as it trains, i.e. what its state file holds besides the
    random states."""

    model: torch.nn.Module
    modules: list  # the objectives' modules (a GAN's critic is not part of its model)
    ema: torch.nn.Module | None
    optimisers: list
    generator: torch.Generator
    log: TrainingLog


def _record(recipe, model, world):
    """What a resumed run must share with the run that saved the state: {field:
    value}."""
    return {
        "recipe": recipe.name,
        "processes": world,
        **{f"settings.{k}": v for k, v in dataclasses.asdict(recipe.settings).items()},
        **{f"model.{k}": v for k, v in recipe.model_config(model).items()},
    }


def _random_states(dist):
    """torch's global random state (CPU, and the GPU this process trains on) of every
    process, by rank."""
    own = {
        "cpu": torch.get_rng_state(),
        "cuda": (
            torch.cuda.get_rng_state(dist.device)
            if dist.device.type == "cuda"
            else None
        ),
    }
    if dist.world == 1:
        return [own]
    states = [None] * dist.world
    torch.distributed.all_gather_object(states, own)
    return states


def _save_state(path, step, trained, record, random_states):
    """Write the training state to ``path`` atomically: a kill mid-write leaves the
    previous state intact."""
    t = trained
    state = {
        "step": step,
        "record": record,
        "model": t.model.state_dict(),
        "modules": [m.state_dict() for m in t.modules],
        "ema": None if t.ema is None else t.ema.state_dict(),
        "optimisers": [o.state_dict() for o in t.optimisers],
        "generator": t.generator.get_state(),
        "random_states": random_states,
        "history": t.log.history,
        "running": t.log._running,
    }
    atomic_write(path, lambda f: torch.save(state, f))


def _load_state(path, trained, record, dist):
    """Restore a saved training state (refused if its record differs from this run's);
    returns its step."""
    state = torch.load(path, map_location="cpu", weights_only=False)
    saved = state.get("record")
    if saved is None:
        raise ValueError(
            f"{path} records no settings (an older facelib wrote it): delete it to"
            " start afresh"
        )
    differ = [
        k
        for k in sorted(saved.keys() | record.keys())
        if saved.get(k, "(none)") != record.get(k, "(none)")
    ]
    if differ:
        changes = "; ".join(
            f"{k}: {saved.get(k, '(none)')!r} saved, {record.get(k, '(none)')!r} now"
            for k in differ
        )
        raise ValueError(
            f"{path} was saved by a run with other settings ({changes}): resume with"
            f" the same settings, or delete {path} to start afresh"
        )
    t = trained
    t.model.load_state_dict(state["model"])
    for module, saved_module in zip(t.modules, state["modules"]):
        module.load_state_dict(saved_module)
    if t.ema is not None:
        t.ema.load_state_dict(state["ema"])
    for opt, saved_opt in zip(t.optimisers, state["optimisers"]):
        opt.load_state_dict(saved_opt)
    t.generator.set_state(state["generator"])
    own = state["random_states"][dist.rank]
    torch.set_rng_state(own["cpu"])
    if own["cuda"] is not None and dist.device.type == "cuda":
        torch.cuda.set_rng_state(own["cuda"], dist.device)
    t.log.history.clear()
    t.log.history.update(state["history"])
    t.log._running = state["running"]
    t.log._t0 = time.perf_counter() - (
        t.log.history["seconds"][-1] if t.log.history["seconds"] else 0.0
    )
    return state["step"]
