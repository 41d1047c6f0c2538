"""Text control (Alg. 2): the merged 18-action dataset, the text head, the task, the baseline, the CLI."""
import json
import shutil

import numpy as np
import pytest
import torch

from facelib import baselines, config, data, descriptions, evaluation, guidance, tasks, text
from facelib.text import description_embeddings
from facelib.diffusion import GaussianDiffusion, linear_betas
from facelib.guidance import ContrastiveScore, CosineScore, DenoisedCosineScore, OptimisationGuidance, nearest_wording
from facelib.models.noisy_classifier import NoisyTextHead, TextHeadConfig


@pytest.fixture(scope="module")
def head():
    return tasks.load_text_head()


@pytest.fixture(scope="module")
def denoiser():
    return tasks.load_denoiser("denoiser_coma+bu")


def test_merged_dataset_keeps_every_sequence_face_label_and_split():
    for split in ("train", "test"):
        merged = data.load_dataset("coma+bu", split)
        coma, bu = data.load_dataset("coma", split), data.load_dataset("bu", split)
        assert len(merged) == len(coma) + len(bu) and merged.label_names == coma.label_names + bu.label_names
        assert len(merged.label_names) == 18
        np.testing.assert_array_equal(merged.landmarks[len(coma):], bu.landmarks)
        assert [merged.label_of(len(coma) + i) for i in (0, 7)] == [bu.label_of(0), bu.label_of(7)]
        # a BU subject keeps its own face: subject ids are offset by CoMA's 12 subjects
        i = len(coma) + 5
        np.testing.assert_array_equal(merged.neutral_landmarks(int(merged.subjects[i])),
                                      bu.neutral_landmarks(int(bu.subjects[5])))
    train, test = data.load_dataset("coma+bu", "train"), data.load_dataset("coma+bu", "test")
    assert not set(train.subjects) & set(test.subjects)  # held-out subjects stay held out
    assert set(test.subjects) == set(test.extra["test_subjects"])
    with pytest.raises(ValueError, match="not generated but merged"):
        data.build("coma+bu")
    with pytest.raises(ValueError, match="allowed: coma, bu, coma\\+bu"):
        data.load_dataset("coma+bu4d")


def test_descriptions_put_the_raw_text_first_and_keep_held_out_apart():
    train = descriptions.descriptions("high_smile", "N2E")
    assert train[0] == "high smile" and "from the neutral face to high smile" in train
    assert "from high smile to the neutral face" in descriptions.descriptions("high_smile", "E2N")
    held_out = descriptions.descriptions("high_smile", "N2E", "held_out")
    assert not set(held_out) & set(train)
    assert all(not set(descriptions.descriptions(y, k, "held_out")) & set(descriptions.descriptions(y, k))
               for y in descriptions.ALL_LABELS for k in ("N2E", "E2N"))


def test_text_head_outputs_unit_vectors_of_motion():
    torch.manual_seed(0)
    h = NoisyTextHead(TextHeadConfig(embedding_dim=16, width=32, depth=1, heads=2, ff=32, dropout=0.0)).eval()
    x, t = torch.randn(3, 10, 68, 3), torch.tensor([0.0, 10.0, 500.0])
    e = h.embed(x, t)
    assert e.shape == (3, 16)
    torch.testing.assert_close(e.norm(dim=1), torch.ones(3))
    torch.testing.assert_close(h.embed(x + torch.randn(3, 1, 68, 3), t), e, atol=1e-5, rtol=1e-5)  # motion only
    c = torch.randn(16)
    cos = h.cosine(x, t, c)
    assert cos.shape == (3,) and (cos.abs() <= 1 + 1e-6).all()
    torch.testing.assert_close(cos, torch.nn.functional.cosine_similarity(h(x, t), c[None], dim=1))


def test_one_guided_step_increases_the_cosine_with_the_text(head):
    # Alg. 2 line 10 with lambda = 0: pure ascent of cos(BiT(x, t-1), E(c)) from x_hat_{t-1}.
    diffusion = GaussianDiffusion(linear_betas(2000))
    emb = torch.as_tensor(text.get_encoder().encode(["high smile", "from the neutral face to anger", "sad", "beaming"]))
    score = CosineScore(head.model, emb)
    gen = torch.Generator().manual_seed(0)
    xt = torch.randn(4, 40, 68, 3, generator=gen)
    out = {"mean": xt * 0.99, "variance": torch.full((4, 1, 1, 1), 0.02)}
    x_hat = out["mean"] + 0.14 * torch.randn(xt.shape, generator=gen)
    t = 300
    t_prev = diffusion.model_time(t - 1, 4)
    guided = OptimisationGuidance(score, diffusion, guidance_weight=0.0, lr=0.01)(x_hat, xt, t, out)
    assert (score(guided, t_prev) > score(x_hat, t_prev)).all()


def test_denoised_score_reads_the_denoisers_estimate(head, denoiser):
    # cos(BiT(x0_hat(x, t), 0), E(c)): at t = 0 the estimate is x itself, so it equals Eq. 10 at t = 0;
    # at t > 0 it is the head's cosine on x0_hat = (x - sqrt(1 - abar_t) eps_theta) / sqrt(abar_t).
    emb = torch.as_tensor(text.get_encoder().encode(["high smile", "from surprise to the neutral face"]))
    full = denoiser.diffusion
    score = DenoisedCosineScore(head.model, denoiser.model, full, emb)
    x = torch.randn(2, 40, 68, 3, generator=torch.Generator().manual_seed(3))
    zero = torch.zeros(2)
    with torch.no_grad():
        torch.testing.assert_close(score(x, zero), CosineScore(head.model, emb)(x, zero))
        t = torch.tensor([700.0, 1500.0])
        x0_hat = full.predict_x0(x, t.long(), denoiser.model(x, t))
        torch.testing.assert_close(score(x, t), head.model.cosine(x0_hat, zero, emb))
        assert not torch.allclose(score(x, t), CosineScore(head.model, emb)(x, t))
    # one guided step (lambda = 0) at a large t raises it: the gradient reaches x through the denoiser
    diffusion = full.respace(100)
    xt = torch.randn(2, 40, 68, 3, generator=torch.Generator().manual_seed(4))
    with torch.no_grad():
        out = diffusion.p_mean_variance(denoiser.model, xt, 80)
    t_prev = diffusion.model_time(79, 2)
    guided = OptimisationGuidance(score, diffusion, guidance_weight=0.0, lr=0.01)(out["mean"], xt, 80, out)
    with torch.no_grad():
        assert (score(guided, t_prev) > score(out["mean"], t_prev)).all()


def test_text_control_reading_x0_hat_is_deterministic_and_checked(head, denoiser):
    kwargs = dict(steps=5, seed=2, progress=False, head=head, denoiser=denoiser)
    a = tasks.text_control("from the neutral face to happy", 2, head_input="x0_hat", **kwargs)
    assert a.shape == (2, 40, 68, 3) and np.isfinite(a).all()
    assert np.array_equal(a, tasks.text_control("from the neutral face to happy", 2, head_input="x0_hat", **kwargs))
    assert not np.array_equal(a, tasks.text_control("from the neutral face to happy", 2, **kwargs))
    with pytest.raises(ValueError, match="head_input must be one of"):
        tasks.text_control("sad", 1, head_input="x0", **kwargs)


@pytest.fixture(scope="module")
def description_table():
    return description_embeddings(data.load_dataset("coma+bu", "train"), text.get_encoder())


def test_nearest_wording_contrasts_a_text_with_its_own_template(description_table):
    encoder = text.get_encoder()
    train = data.load_dataset("coma+bu", "train")
    texts = ["from the neutral face to happy", "happy", "a neutral face turning into a big smile"]
    refs = nearest_wording(description_table, encoder.encode(texts))
    assert refs.shape == (3, 36, 384)
    template = [descriptions.enriched_texts(y, k)[0] for y in train.label_names for k in train.kind_names]
    torch.testing.assert_close(refs[0], torch.as_tensor(encoder.encode(template)))  # all 36, the text among them
    raw = [descriptions.raw_text(y) for y in train.label_names for _ in train.kind_names]  # a raw text has no order
    torch.testing.assert_close(refs[1], torch.as_tensor(encoder.encode(raw)))
    assert torch.isclose(refs[2] @ torch.as_tensor(encoder.encode(texts[2:]))[0], torch.tensor(1.0)).any()
    with pytest.raises(ValueError, match="description table"):
        nearest_wording(description_table[0], encoder.encode(texts))


def test_contrastive_score_is_the_heads_log_probability_of_the_matched_descriptions(head, description_table):
    # score = log sum_n w_n p(r_n | x, t), p = the head's InfoNCE softmax over the references, w = the
    # text's match to them; when c = r_j and the match is sharp it is log p(r_j | x, t), a log-softmax
    # (the probabilities over the references sum to 1)
    encoder = text.get_encoder()
    refs = nearest_wording(description_table, encoder.encode(["from the neutral face to sad"]))[0]
    x = torch.randn(1, 40, 68, 3, generator=torch.Generator().manual_seed(6)).expand(36, -1, -1, -1)
    t = torch.full((36,), 400.0)
    tau = head.meta["training"]["temperature"]
    with torch.no_grad():
        p = torch.softmax(head.model.embed(x[:1], t[:1]) @ refs.T / tau, -1)[0]
        log_p = ContrastiveScore(head.model, refs, refs.expand(36, -1, -1), tau, match_temperature=1e-4)(x, t)
        torch.testing.assert_close(log_p, p.log(), atol=1e-5, rtol=1e-5)
        assert torch.logsumexp(log_p, 0).abs() < 1e-5
        held_out = torch.as_tensor(encoder.encode(["starting neutral and ending with a sad face"]))
        w = torch.softmax(held_out @ refs.T / config.MATCH_TEMPERATURE, -1)[0]
        got = ContrastiveScore(head.model, held_out, refs[None], tau)(x[:1], t[:1])
        torch.testing.assert_close(got, (w * p).sum().log()[None], atol=1e-5, rtol=1e-5)
    diffusion = GaussianDiffusion(linear_betas(2000))
    out = {"mean": x[:4] * 0.99, "variance": torch.full((4, 1, 1, 1), 0.02)}
    four = ContrastiveScore(head.model, refs[:4], refs.expand(4, -1, -1), tau)
    guided = OptimisationGuidance(four, diffusion, guidance_weight=0.0, lr=0.01)(out["mean"], x[:4], 401, out)
    with torch.no_grad():
        assert (four(guided, t[:4]) > four(out["mean"], t[:4])).all()
    for bad_refs, bad_tau, bad_match in ((refs, tau, 0.01), (refs.expand(36, -1, -1), 0.0, 0.01),
                                         (refs.expand(36, -1, -1), tau, -1.0)):
        with pytest.raises(ValueError, match="references|temperature"):
            ContrastiveScore(head.model, refs, bad_refs, bad_tau, bad_match)


def test_vocabulary_match_is_the_nearest_description_of_each_class(description_table):
    # w_n = softmax_n max_k cos(E(c), E(v_nk)) / tau_w: with one description per class it is the
    # reference match; repeating a description changes nothing; a known phrasing matches its class
    encoder = text.get_encoder()
    e = torch.as_tensor(encoder.encode(["starting neutral and ending with a sad face", "beaming"]))
    refs = nearest_wording(description_table, e)
    torch.testing.assert_close(guidance.vocabulary_log_weights(e[:1], refs[0][:, None]),
                               guidance.match_log_weights(e[:1], refs[:1]))
    table = description_table.flatten(0, 1)  # (36, K, D)
    repeated = torch.cat([table, table[:, :2]], 1)
    torch.testing.assert_close(guidance.vocabulary_log_weights(e, repeated), guidance.vocabulary_log_weights(e, table))
    vocabulary = description_embeddings(data.load_dataset("coma+bu", "train"), encoder, "vocabulary").flatten(0, 1)
    assert vocabulary.shape[0] == 36 and vocabulary.shape[1] > table.shape[1]
    sad = encoder.encode(["a gloomy face"])  # a vocabulary phrasing of sad (no order: both orders equally)
    w = guidance.vocabulary_log_weights(sad, vocabulary).exp()[0].reshape(18, 2)
    assert w.sum(1).argmax() == descriptions.ALL_LABELS.index("sad") and torch.isclose(w[16, 0], w[16, 1])
    with pytest.raises(ValueError, match="vocabulary"):
        guidance.vocabulary_log_weights(e, table[0])
    with pytest.raises(ValueError, match="knows 35 classes"):
        ContrastiveScore(None, e, refs, 0.05, vocabulary=vocabulary[:35])
    with pytest.raises(ValueError, match="match temperature"):
        guidance.vocabulary_log_weights(e, vocabulary, 0.0)


def _matched_label(texts, table):
    e = torch.as_tensor(text.get_encoder().encode(list(texts)))
    return guidance.vocabulary_log_weights(e, table.flatten(0, 1)).reshape(len(texts), 18, 2).logsumexp(-1).argmax(1)


@pytest.mark.parametrize("split", ["held_out", "blind_held_out"])
def test_the_vocabulary_matches_more_held_out_phrasings_to_their_label(split, description_table):
    # chapter 06 section 12: phrasings never seen by a network or by the vocabulary's writer are matched
    # to their own label more often against the vocabulary than against the training descriptions
    phrasings = [(k, p) for k, y in enumerate(descriptions.ALL_LABELS) for p in descriptions.phrasings(y, split)]
    truth = torch.tensor([k for k, _ in phrasings])
    vocabulary = description_embeddings(data.load_dataset("coma+bu", "train"), text.get_encoder(), "vocabulary")
    before = (_matched_label([p for _, p in phrasings], description_table) == truth).float().mean()
    after = (_matched_label([p for _, p in phrasings], vocabulary) == truth).float().mean()
    assert after > before + 0.05, (before, after)  # measured: held_out 0.72 -> 0.81, blind_held_out 0.62 -> 0.84


def test_guided_samples_follow_the_vocabulary_match(head, denoiser, description_table):
    # the held-out phrasings that the vocabulary matches to their own label and the training descriptions
    # to another one: the type-I IC reads the samples guided with the vocabulary as the meant label
    # more often (30 steps, contrastive score)
    phrasings = [(k, p) for split in ("held_out", "blind_held_out") for k, y in enumerate(descriptions.ALL_LABELS)
                 for p in descriptions.phrasings(y, split)]
    vocabulary = description_embeddings(data.load_dataset("coma+bu", "train"), text.get_encoder(), "vocabulary")
    texts, truth = [p for _, p in phrasings], torch.tensor([k for k, _ in phrasings])
    fixed = (_matched_label(texts, vocabulary) == truth) & (_matched_label(texts, description_table) != truth)
    texts, truth = [t for t, f in zip(texts, fixed) if f], truth[fixed].numpy()
    assert len(texts) >= 8
    ic = evaluation.load_evaluator("coma+bu", "I")
    kwargs = dict(steps=30, seed=2, score="contrastive", head=head, denoiser=denoiser, progress=False)
    hit = {v: (ic.features(tasks.text_control(texts, len(texts), vocabulary=v, **kwargs)).argmax(1) == truth).mean()
           for v in (False, True)}
    print(f"{len(texts)} phrasings, IC reads the meant label: {hit}")
    assert hit[True] > hit[False] + 0.3, hit
    again = tasks.text_control(texts[:2], 2, vocabulary=True, **kwargs)
    np.testing.assert_array_equal(again, tasks.text_control(texts[:2], 2, vocabulary=True, **kwargs))
    for bad, message in ((dict(score="cosine", vocabulary=True), "contrastive score"),
                         (dict(vocabulary="yes"), "True or False")):
        with pytest.raises(ValueError, match=message):
            tasks.text_control("beaming", 1, **{**kwargs, **bad, "steps": 2})


def test_contrastive_score_steers_the_order_that_the_cosine_cannot(head, denoiser):
    # chapter 06 section 10: on enriched sentences of both orders, the type-S IC's probability of the
    # requested order is far higher when Alg. 2 climbs log p(c | x) than when it climbs the cosine
    # (both at the cosine's rate, and lambda 1e-4 for the contrastive score: the strong end of the sweep)
    ev = evaluation.load_evaluator("coma+bu", "S")
    pairs = [(y, k) for y in ("happy", "surprise", "mouth_open", "bareteeth", "sad", "eyebrow") for k in ("N2E", "E2N")]
    texts = [descriptions.enriched_texts(y, k)[0] for y, k in pairs]
    order = np.array([1 if k == "E2N" else 0 for _, k in pairs])
    kwargs = dict(steps=30, seed=3, head=head, denoiser=denoiser, progress=False)
    p_order = {}
    strong = {"cosine": {}, "contrastive": dict(guidance_weight=1e-4, lr=tasks.text_lr(30))}
    for score in config.TEXT_SCORES:
        x = tasks.text_control(texts, len(texts), score=score, **strong[score], **kwargs)
        p = torch.softmax(torch.as_tensor(ev.features(x)), 1).numpy().reshape(len(x), -1, 2).sum(1)
        p_order[score] = p[np.arange(len(x)), order]
    assert p_order["contrastive"].mean() > p_order["cosine"].mean() + 0.2
    assert p_order["contrastive"][order == 1].mean() > 0.5 and p_order["contrastive"][order == 0].mean() > 0.5
    a = tasks.text_control(texts[:2], 2, score="contrastive", **kwargs)
    assert np.array_equal(a, tasks.text_control(texts[:2], 2, score="contrastive", **kwargs))
    with pytest.raises(ValueError, match="score must be one of"):
        tasks.text_control("sad", 1, score="dot", **kwargs)
    with pytest.raises(ValueError, match="reads x_t"):
        tasks.text_control("sad", 1, score="contrastive", head_input="x0_hat", **kwargs)


def test_particles_pick_the_chain_that_the_head_reads_as_the_requested_order(head, denoiser):
    # chapter 06 section 11: K = 4 contrastive-guided chains per sentence, the head keeps the best at
    # t = SELECT_TIME; the type-S IC's probability of the requested order rises over one chain
    ev = evaluation.load_evaluator("coma+bu", "S")
    pairs = [(y, k) for y in ("happy", "surprise", "mouth_open", "bareteeth", "sad", "eyebrow") for k in ("N2E", "E2N")]
    texts = [descriptions.enriched_texts(y, k)[0] for y, k in pairs]
    order = np.array([1 if k == "E2N" else 0 for _, k in pairs])
    kwargs = dict(steps=30, seed=3, score="contrastive", head=head, denoiser=denoiser, progress=False)
    p_order = {}
    for k in (1, 4):
        x = tasks.text_control(texts, len(texts), particles=k, max_time=config.PARTICLE_MAX_TIME, **kwargs)
        p = torch.softmax(torch.as_tensor(ev.features(x)), 1).numpy().reshape(len(x), -1, 2).sum(1)
        p_order[k] = p[np.arange(len(x)), order]
    assert p_order[4].mean() > p_order[1].mean() + 0.1
    assert p_order[4][order == 1].mean() > 0.6 and p_order[4][order == 0].mean() > 0.6
    a = tasks.text_control(texts[:2], 2, particles=2, **kwargs)
    assert a.shape == (2, 40, 68, 3) and np.array_equal(a, tasks.text_control(texts[:2], 2, particles=2, **kwargs))
    for bad, message in ((dict(particles=0), "particles must be"), (dict(particles=2.5), "particles must be"),
                         (dict(particles=2, select_time=-1), "select_time"),
                         (dict(particles=2, select_time=5000), "first step"),
                         (dict(particles=2, callback=lambda *a: None), "no callback"),
                         (dict(max_time=0), "max_time")):
        with pytest.raises(ValueError, match=message):
            tasks.text_control("sad", 1, **kwargs, **bad)


def test_best_particles_keeps_the_highest_scoring_candidate_of_each_sequence():
    x = torch.arange(6.0).reshape(6, 1) * torch.tensor([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])[:, None]  # 3 particles of 2
    picked = guidance.best_particles(x, lambda x, t: x[:, 0], None, 3)  # score = the value itself
    assert picked.tolist() == [[4.0], [-1.0]]  # sequence 0: candidates 0, 2, 4; sequence 1: -1, -3, -5
    for bad in (0, 4, True):
        with pytest.raises(ValueError, match="particles must be"):
            guidance.best_particles(x, lambda x, t: x[:, 0], None, bad)
    with pytest.raises(ValueError, match="not finite"):
        guidance.best_particles(x, lambda x, t: x[:, 0] / 0.0 * 0.0, None, 3)


def test_guidance_above_max_time_is_left_out():
    diffusion = GaussianDiffusion(linear_betas(2000)).respace(10)
    x = torch.zeros(2, 4, 68, 3)
    out = {"mean": x, "variance": torch.ones(2, 1, 1, 1)}
    g = OptimisationGuidance(lambda x, t: x.sum((1, 2, 3)), diffusion, 0.0, 0.1, max_time=1000)
    high = int(np.flatnonzero(diffusion.timesteps > 1000)[0])
    low = int(np.flatnonzero((diffusion.timesteps <= 1000) & (diffusion.timesteps > 0))[-1])
    assert torch.equal(g(x, x, high, out), x)
    assert (g(x, x, low, out) > 0).all()  # climbs the score


def test_decoder_then_diffusion_trades_fidelity_for_diversity(denoiser):
    # SDEdit from the MotionCLIP-style decoder: deterministic for a seed, different draws for one text,
    # nearer the decoded sequence when re-noised to a smaller step
    decoder = baselines.load_baseline("motionclip", "coma+bu")
    text_ = "from the neutral face to bareteeth"
    decoded = baselines.generate_from_text(decoder, [text_])[0]
    kwargs = dict(steps=50, progress=False, denoiser=denoiser, decoder=decoder)
    near = tasks.decoder_then_diffusion(text_, 3, start=200, seed=0, **kwargs)
    far = tasks.decoder_then_diffusion(text_, 3, start=1500, seed=0, **kwargs)
    assert near.shape == (3, 40, 68, 3) and near.dtype == np.float32
    assert np.array_equal(near, tasks.decoder_then_diffusion(text_, 3, start=200, seed=0, **kwargs))
    assert not np.allclose(near[0], near[1])  # a family of sequences, not one
    dist = lambda x: np.linalg.norm(x - decoded, axis=-1).mean()  # noqa: E731
    assert dist(near) < dist(far)
    for bad in (0, 2001, 3.5, True):
        with pytest.raises(ValueError, match="start must be a step"):
            tasks.decoder_then_diffusion(text_, 1, start=bad, **kwargs)
    with pytest.raises(ValueError, match="empty"):
        tasks.decoder_then_diffusion("", 1, **kwargs)
    with pytest.raises(ValueError, match="use denoiser_coma"):
        tasks.decoder_then_diffusion(text_, 1, steps=5, progress=False, decoder=decoder,
                                     denoiser=tasks.load_denoiser("denoiser_coma"))


def test_text_control_is_deterministic_and_follows_the_text(head, denoiser):
    labels = ["high_smile", "mouth_open", "happy", "surprise", "eyebrow", "anger"]
    texts = [descriptions.raw_text(y) for y in labels]
    kwargs = dict(steps=50, seed=5, progress=False, head=head, denoiser=denoiser)
    guided = tasks.text_control(texts, len(texts), **kwargs)
    assert guided.shape == (6, 40, 68, 3) and guided.dtype == np.float32
    assert np.array_equal(guided, tasks.text_control(texts, len(texts), **kwargs))
    unguided = tasks.unconditional(len(texts), steps=50, seed=5, progress=False, denoiser=denoiser)
    ev = evaluation.load_evaluator("coma+bu")
    targets = [ev.class_index(y) for y in labels]
    p_guided = torch.softmax(torch.as_tensor(ev.features(guided)), 1)[np.arange(6), targets]
    p_unguided = torch.softmax(torch.as_tensor(ev.features(unguided)), 1)[np.arange(6), targets]
    assert p_guided.mean() > p_unguided.mean() + 0.2


def test_default_text_rate_is_the_sweep_pick_at_100_steps_and_scales_with_one_over_steps(head, denoiser):
    assert tasks.text_lr(config.TEXT_LR_REFERENCE_STEPS) == pytest.approx(config.TEXT_LR)
    assert tasks.text_lr(4 * config.TEXT_LR_REFERENCE_STEPS, score="contrastive") == pytest.approx(config.CONTRASTIVE_LR / 4)
    assert tasks.text_guidance_weight("contrastive") == config.CONTRASTIVE_GUIDANCE_WEIGHT == config.GUIDANCE_WEIGHT
    for fn in (tasks.text_lr, tasks.text_guidance_weight):
        with pytest.raises(ValueError, match="score must be one of"):
            fn(score="dot")
    assert tasks.text_lr(4 * config.TEXT_LR_REFERENCE_STEPS) == pytest.approx(config.TEXT_LR / 4)
    assert tasks.text_lr(None) == pytest.approx(config.TEXT_LR * config.TEXT_LR_REFERENCE_STEPS / 2000)
    assert tasks.step_scaled_lr(0.1, 100, 400) == pytest.approx(0.05)  # the default power 0.5 of label control
    # text_control's default is that rate: passing it explicitly gives the same samples
    kwargs = dict(steps=5, seed=1, progress=False, head=head, denoiser=denoiser)
    default = tasks.text_control("sad", 2, **kwargs)
    assert np.array_equal(default, tasks.text_control("sad", 2, lr=tasks.text_lr(5), **kwargs))
    assert not np.array_equal(default, tasks.text_control("sad", 2, lr=config.TEXT_LR, **kwargs))


@pytest.mark.parametrize("bad, message", [("", "empty"), ("   ", "empty"), (42, "string"), (["sad", 3], "string"),
                                          ("smile " * 300, "word pieces")])
def test_text_control_refuses_bad_text(bad, message, head, denoiser):
    n = len(bad) if isinstance(bad, list) else 1
    with pytest.raises(ValueError, match=message):
        tasks.text_control(bad, n, steps=2, progress=False, head=head, denoiser=denoiser)


def test_text_control_checks_n_and_the_head(head, denoiser):
    with pytest.raises(ValueError, match="list of n=3"):
        tasks.text_control(["sad", "happy"], 3, steps=2, progress=False, head=head, denoiser=denoiser)
    with pytest.raises(ValueError, match="positive integer"):
        tasks.text_control("sad", 0, steps=2, progress=False, head=head, denoiser=denoiser)
    with pytest.raises(ValueError, match="needs a text head"):
        tasks.text_control("sad", 1, steps=2, progress=False, head=tasks.load_guide("coma"), denoiser=denoiser)
    with pytest.raises(ValueError, match="normalise landmarks differently"):
        tasks.text_control("sad", 1, steps=2, progress=False, head=head, denoiser=tasks.load_denoiser("denoiser_coma"))


def test_text_head_checkpoint_checks_its_encoder_and_labels(tmp_path):
    pt, js = (config.CHECKPOINT_DIR / f"guide_coma+bu_text{s}" for s in (".pt", ".json"))
    shutil.copy(pt, tmp_path / "head.pt")
    meta = json.loads(js.read_text())
    meta["text_encoder"] = "openai/clip-vit-base-patch32"
    (tmp_path / "head.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="text encoder"):
        tasks.load_text_head(name=str(tmp_path / "head"))
    with pytest.raises(ValueError, match="has classes"):
        tasks.load_text_head("coma", name="guide_coma+bu_text")


def test_motionclip_baseline_is_deterministic():
    model = baselines.load_baseline("motionclip", "coma+bu")
    a = baselines.generate_from_text(model, ["disgust high smile", "sad"])
    b = baselines.generate_from_text(model, ["disgust high smile", "sad"])
    assert a.shape == (2, 40, 68, 3) and a.dtype == np.float32 and np.array_equal(a, b)
    assert not np.allclose(a[0], a[1])  # the text changes the motion
    with pytest.raises(ValueError, match="empty"):
        baselines.generate_from_text(model, [""])


def test_cli_text_task_writes_npz(tmp_path, capsys):
    from facelib.__main__ import main
    out = tmp_path / "text.npz"
    assert main(["sample", "text", "--text", "disgust high smile", "--n", "2", "--steps", "5",
                 "--out", str(out)]) == 0
    npz = np.load(out)
    assert npz["landmarks"].shape == (2, 40, 68, 3) and list(npz["texts"]) == ["disgust high smile"] * 2
    used = json.loads(str(npz["config"]))
    assert used["dataset"] == "coma+bu" and used["guidance"] == "guide_coma+bu_text"
    assert used["lr"] == pytest.approx(tasks.text_lr(5))
    assert used["guidance_weight"] == config.TEXT_GUIDANCE_WEIGHT and used["head_input"] == "x_t"
    assert used["particles"] == 1 and used["max_time"] is None
    assert main(["sample", "text", "--text", "from sad to the neutral face", "--n", "1", "--steps", "3",
                 "--head-input", "x0_hat", "--out", str(out)]) == 0
    assert json.loads(str(np.load(out)["config"]))["head_input"] == "x0_hat"
    assert main(["sample", "text", "--text", "from sad to the neutral face", "--n", "1", "--steps", "3",
                 "--score", "contrastive", "--out", str(out)]) == 0
    used = json.loads(str(np.load(out)["config"]))
    assert used["score"] == "contrastive" and used["guidance_weight"] == config.CONTRASTIVE_GUIDANCE_WEIGHT
    assert used["lr"] == pytest.approx(tasks.text_lr(3, score="contrastive"))
    assert main(["sample", "text", "--text", "from sad to the neutral face", "--n", "2", "--steps", "10",
                 "--score", "contrastive", "--particles", "3", "--max-time", "1400", "--out", str(out)]) == 0
    used = json.loads(str(np.load(out)["config"]))
    assert used["particles"] == 3 and used["select_time"] == config.SELECT_TIME and used["max_time"] == 1400
    assert np.load(out)["landmarks"].shape == (2, 40, 68, 3)
    assert used["vocabulary"] is False
    assert main(["sample", "text", "--text", "beaming", "--n", "1", "--steps", "3", "--score", "contrastive",
                 "--vocabulary", "--out", str(out)]) == 0
    assert json.loads(str(np.load(out)["config"]))["vocabulary"] is True
    with pytest.raises(SystemExit):
        main(["sample", "text", "--text", "beaming", "--n", "1", "--steps", "3", "--vocabulary",
              "--out", str(out)])
    assert "vocabulary is matched by the contrastive score" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["sample", "label", "--label", "happy", "--particles", "2", "--out", str(out)])
    assert "unrecognized arguments: --particles" in capsys.readouterr().err  # an option of text only
    assert main(["sample", "decoder", "--text", "from sad to the neutral face", "--n", "2", "--steps", "20",
                 "--start", "400", "--out", str(out)]) == 0
    used = json.loads(str(np.load(out)["config"]))
    assert used["task"] == "decoder" and used["start"] == 400 and used["guidance"] == "motionclip_coma+bu"
    assert np.load(out)["landmarks"].shape == (2, 40, 68, 3)
    for extra in (["--lr", "0.1"], ["--head-input", "x0_hat"], ["--score", "contrastive"], ["--particles", "2"],
                  ["--vocabulary"]):  # options of Alg. 2, which the decoder route does not run
        with pytest.raises(SystemExit):
            main(["sample", "decoder", "--text", "sad", "--n", "1", "--steps", "5", *extra, "--out", str(out)])
        assert "unrecognized arguments" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["sample", "text", "--n", "2", "--out", str(out)])
