"""Measurements of text control (§5.2; the text-control chapter and its appendix): what
the text head reads of a noised sequence, how Alg. 2's two gradients compare, whether a
composed prompt mixes its two terms, which order and label a generated sequence has, and
how a new phrasing is matched to the known descriptions.
"""

from __future__ import annotations

import numpy as np
import torch

from . import descriptions, guidance


def order_sentences(label_names, encoder):
    """Embeddings (2, L, D) of every label's first enriched sentence, in the order N2E
    (row 0) and E2N."""
    return torch.stack(
        [
            torch.as_tensor(
                encoder.encode(
                    [descriptions.enriched_texts(y, kind)[0] for y in label_names]
                )
            )
            for kind in descriptions.KIND_NAMES
        ]
    )


def order_read(outputs, orders, labels, kinds):
    """Per head output (n, D): is its own label's sentence of its own order (``kinds``)
    nearer than the other order's?  ``orders``: :func:`order_sentences`."""
    own = torch.arange(len(outputs))
    sims = torch.stack([(outputs @ e.T)[own, torch.as_tensor(labels)] for e in orders])
    return sims.argmax(0).numpy() == np.asarray(kinds)


@torch.no_grad()
def retrieval_by_noise(head, denoiser, dataset, encoder, t_grid, read="x_t", seed=0):
    """Rows [t, sqrt(abar_t), label right %, order right %] of the text head on
    ``dataset``'s sequences noised to each t of ``t_grid`` (Eq. 3): the label is right
    when the nearest raw text to the head's output is the sequence's own, the order as
    :func:`order_read`.  ``read="x0_hat"``: the head reads the denoiser's estimate
    x0_hat(x_t, t) (Eq. 6 solved for x_0) as a clean sequence (t = 0); the noise is the
    same for both.
    """
    x0 = torch.as_tensor(denoiser.normalizer.normalize(dataset.landmarks))
    raw = torch.as_tensor(
        encoder.encode([descriptions.raw_text(y) for y in dataset.label_names])
    )
    orders, gen, rows = (
        order_sentences(dataset.label_names, encoder),
        torch.Generator().manual_seed(seed),
        [],
    )
    for t in t_grid:
        tt = torch.full((len(x0),), t)
        x = denoiser.diffusion.q_sample(x0, tt, generator=gen)
        if read == "x0_hat":
            x = denoiser.diffusion.model_estimates(denoiser.model, x, tt)[1]
            tt = torch.zeros_like(tt)
        out = head.model.embed(x, tt.float())
        label_right = ((out @ raw.T).argmax(1).numpy() == dataset.labels).mean()
        rows.append(
            [
                t,
                float(denoiser.diffusion.alphas_bar[t]) ** 0.5,
                100 * label_right,
                100 * order_read(out, orders, dataset.labels, dataset.kinds).mean(),
            ]
        )
    return rows


def spring_and_text(
    head, denoiser, x0, embeddings, steps, ks, guidance_weight=0.01, seed=1
):
    """Rows [t, median |spring gradient|, median |cosine gradient|, % coordinates where
    the cosine's is larger]: the two gradients that Alg. 2's objective sums (Eq. 10),
    lambda grad log p_theta(x | x_t) and grad cos(BiT(x, t-1), E(c)), at x ~ p_theta(. |
    x_t) with x_t = q_sample(x0, t), for reverse steps ``ks`` of a chain of ``steps``
    respaced steps.  Adagrad's first step moves each coordinate by the rate in the sign
    of the sum, so the larger of the two decides it."""
    chain, rows = denoiser.diffusion_with(steps), []
    if any(not 1 <= k <= steps for k in ks):
        raise ValueError(f"reverse steps ks must lie in 1..{steps}, got {list(ks)}")
    for k in ks:
        # one stream: x_t's noise, then the step's
        generator = torch.Generator().manual_seed(seed * 100_003 + k)
        xt = chain.q_sample(x0, torch.full((len(x0),), k), generator=generator)
        with torch.no_grad():
            out = chain.p_mean_variance(denoiser.model, xt, k)
        x = out["mean"] + out["variance"].sqrt() * torch.randn(
            xt.shape, generator=generator
        )
        t_prev = chain.model_time(k - 1, len(x0))
        spring = guidance.gradient_at(
            x, lambda v: guidance_weight * guidance.log_p_theta(v, out)
        ).abs()
        text = guidance.gradient_at(
            x, lambda v: head.model.cosine(v, t_prev, embeddings)
        ).abs()
        rows.append(
            [
                int(chain.timesteps[k]),
                spring.median().item(),
                text.median().item(),
                100 * (text > spring).float().mean().item(),
            ]
        )
    return rows


def class_shares(evaluator, sequences):
    """The evaluator's softmax over its classes, averaged over ``sequences``:
    (num_classes,)."""
    return (
        torch.softmax(torch.as_tensor(evaluator.features(sequences)), 1).numpy().mean(0)
    )


def composition_row(evaluator, a, b, composed, alone_a, alone_b):
    """[P(a), P(b), P(b) when asked for a alone, P(a) when asked for b alone, mixes?] of
    the type-I IC for sequences made for a composed prompt "a b" and for each term alone
    (:func:`class_shares`).  It mixes when each term holds at least 0.1 of the
    probability and more than the other term's own samples give it.
    """
    ia, ib = evaluator.class_index(a), evaluator.class_index(b)
    both, only_a, only_b = (
        class_shares(evaluator, x) for x in (composed, alone_a, alone_b)
    )
    mixes = (
        min(both[ia], both[ib]) > 0.1
        and both[ib] > only_a[ib]
        and both[ia] > only_b[ia]
    )
    return [
        float(both[ia]),
        float(both[ib]),
        float(only_a[ib]),
        float(only_b[ia]),
        bool(mixes),
    ]


def label_and_order_right(sequences, ev_label, ev_order, dataset):
    """Per sequence made for ``dataset``'s sequences: is its label right (type-I IC
    ``ev_label``), and is its order right (the order of the type-S IC's class; chance
    1/2)?"""
    return (
        ev_label.features(sequences).argmax(1) == dataset.targets("I"),
        ev_order.features(sequences).argmax(1) % 2 == dataset.kinds,
    )


def decision_curves(denoiser, evaluators, steps, num_chains, seed=11):
    """When does an unguided chain decide?  ``num_chains`` chains of ``steps`` respaced
    steps; after every step, the order (type-S IC) and the label (type-I IC) of the
    denoiser's estimate x0_hat(x_t) are compared with the final sample's.  Returns
    {"order": [(t, % of chains that agree)], "label": [...]}. ``evaluators`` = (type-I
    IC, type-S IC)."""
    ev_label, ev_order = evaluators
    chain, estimates = denoiser.diffusion_with(steps), []
    final = denoiser.to_mm(
        chain.sample(
            denoiser.model,
            (num_chains, 40, 68, 3),
            seed=seed,
            progress=False,
            callback=lambda t, x, out: estimates.append(
                (int(chain.timesteps[t]), denoiser.to_mm(out["x0"]))
            ),
        )
    )
    read = {
        "order": lambda x: ev_order.features(x).argmax(1) % 2,
        "label": lambda x: ev_label.features(x).argmax(1),
    }
    return {
        k: [(t, 100 * (f(e) == f(final)).mean()) for t, e in estimates]
        for k, f in read.items()
    }


def settled_from(curve, level=90):
    """The largest t from which on, down to t = 0, a curve [(t, agreement %)] stays at
    or above ``level``."""
    found = 0
    for t, agree in sorted(curve):
        if agree < level:
            break
        found = t
    return found


def matched_classes(texts, table, encoder):
    """The (label, order) class, label * 2 + order, that the match weights of each text
    put first, against a description table (L, 2, K, D)
    (guidance.vocabulary_log_weights)."""
    weights = guidance.vocabulary_log_weights(
        torch.as_tensor(encoder.encode(list(texts))), table.flatten(0, 1)
    )
    return weights.argmax(1).numpy()


def match_rates(label_names, split, table, encoder):
    """[% of ``split``'s phrasings matched to their label, % of its enriched sentences
    matched to their label, % matched to their order] against a description table
    (:func:`matched_classes`)."""
    raw = [
        (k, p)
        for k, y in enumerate(label_names)
        for p in descriptions.phrasings(y, split)
    ]
    enriched = [
        (2 * k + o, s)
        for k, y in enumerate(label_names)
        for o, kind in enumerate(descriptions.KIND_NAMES)
        for s in descriptions.enriched_texts(y, kind, split)
    ]
    raw_hit = matched_classes([p for _, p in raw], table, encoder) // 2 == np.array(
        [k for k, _ in raw]
    )
    got, truth = matched_classes([s for _, s in enriched], table, encoder), np.array(
        [c for c, _ in enriched]
    )
    return [
        100 * raw_hit.mean(),
        100 * (got // 2 == truth // 2).mean(),
        100 * (got % 2 == truth % 2).mean(),
    ]


def balanced_subset(dataset, num_labels):
    """Two test sequences for each of ``num_labels`` labels spread over the label list,
    the two of a label of one order and the orders alternating over the labels: the
    small sets of the text-control chapter.
    """
    if not 1 <= num_labels <= len(dataset.label_names):
        raise ValueError(
            f"num_labels must be in 1..{len(dataset.label_names)}, got {num_labels!r}"
        )
    chosen = (
        np.linspace(0, len(dataset.label_names) - 1, num_labels).round().astype(int)
    )
    picked = [
        np.flatnonzero((dataset.labels == k) & (dataset.kinds == i % 2))[:2]
        for i, k in enumerate(chosen)
    ]
    short = [dataset.label_names[k] for k, p in zip(chosen, picked) if len(p) < 2]
    if short:
        raise ValueError(f"fewer than 2 test sequences of the needed order for {short}")
    return dataset.subset(np.concatenate(picked))


def prompts_for(dataset, seed=1):
    """The description of each of ``dataset``'s sequences, by task: its raw text, a
    random held-out phrasing of its label, its first enriched sentence, and a random
    held-out enriched sentence of its order.
    """
    rng = np.random.default_rng(seed)
    labels = [dataset.label_of(i) for i in range(len(dataset))]
    kinds = [dataset.kind_names[k] for k in dataset.kinds]
    return {
        "raw": [descriptions.raw_text(y) for y in labels],
        "raw, held-out phrasing": [
            str(rng.choice(descriptions.phrasings(y, "held_out"))) for y in labels
        ],
        "enriched": [
            descriptions.enriched_texts(y, k)[0] for y, k in zip(labels, kinds)
        ],
        "enriched, held-out phrasing": [
            str(rng.choice(descriptions.enriched_texts(y, k, "held_out")))
            for y, k in zip(labels, kinds)
        ],
    }


def scorer(dataset, ev_label, ev_order):
    """score(x, task): the IC scores (with 95 % intervals, 200 resamples) of sequences
    made for ``dataset``'s descriptions of a task of :func:`prompts_for`: raw tasks by
    the type-I IC, enriched ones by the type S.
    """

    def score(sequences, task):
        ev, kind = (ev_label, "I") if task.startswith("raw") else (ev_order, "S")
        return ev.score(
            sequences, dataset.targets(kind), intervals=True, num_resamples=200
        )

    return score


def branch_agreement(
    denoiser, head, encoder, dataset, evaluators, steps, branch_at, num_chains, seed=3
):
    """When does an unguided chain decide its sequence, and what can the text head read
    then?  Rows [t, % of chains whose four continuations agree on the order, % on the
    label, % of ``dataset``'s sequences noised to t whose order the head reads right, %
    whose label]: ``num_chains`` chains of ``steps`` respaced steps are stopped at each
    reverse step of ``branch_at`` and continued four times with fresh noise;
    ``evaluators`` = (type-I IC, type-S IC) read the continuations; the head compares
    its output with the 36 sentences "from the neutral face to X" / "from X to the
    neutral face".
    """
    ev_label, ev_order = evaluators
    if any(not 1 <= k < steps for k in branch_at):
        raise ValueError(
            f"branch points must lie in 1..{steps - 1} (x_k is stored after step k +"
            f" 1), got {list(branch_at)}"
        )
    chain, states = denoiser.diffusion_with(steps), {}
    chain.sample(
        denoiser.model,
        (num_chains, *dataset.landmarks.shape[1:]),
        seed=seed,
        progress=False,
        callback=lambda t, x, out: states.__setitem__(t - 1, x.clone()),
    )
    # (2, L, D)
    orders = torch.nn.functional.normalize(
        order_sentences(dataset.label_names, encoder), dim=-1
    )
    x0 = torch.as_tensor(denoiser.normalizer.normalize(dataset.landmarks))
    rows = []
    # continuation s runs on stream seed + 97 + s, never the chain's own (seed)
    for k in branch_at:
        ends = [
            denoiser.normalizer.denormalize(
                chain.run(
                    denoiser.model,
                    states[k],
                    seed + 97 + s,
                    chain.schedule(start=k),
                    progress=False,
                )
            ).numpy()
            for s in range(4)
        ]
        o = np.stack([ev_order.features(e).argmax(1) % 2 for e in ends])
        lab = np.stack([ev_label.features(e).argmax(1) for e in ends])
        t = int(chain.timesteps[k])
        xt = denoiser.diffusion.q_sample(
            x0, torch.full((len(x0),), t), generator=torch.Generator().manual_seed(k)
        )
        with torch.no_grad():
            sims = torch.einsum(
                "bd,kld->bkl",
                head.model.embed(xt, torch.full((len(x0),), float(t))),
                orders,
            )
        read_order = (
            sims[torch.arange(len(x0)), :, torch.as_tensor(dataset.labels)]
            .argmax(1)
            .numpy()
            == dataset.kinds
        ).mean()
        read_label = (sims.amax(1).argmax(1).numpy() == dataset.labels).mean()
        rows.append(
            [
                t,
                100 * (o == o[:1]).all(0).mean(),
                100 * (lab == lab[:1]).all(0).mean(),
                100 * read_order,
                100 * read_label,
            ]
        )
    return rows
