"""Guidance (paper §3.2): the hooks (Adagrad optimisation, mean shift, reconstruction guidance, best-of-K) and
the scores they climb (classifier, cosine, contrastive, on the denoiser's estimate)."""
import numpy as np
import pytest
import torch

from facelib import config, data, descriptions, guidance, text
from facelib.diffusion import GaussianDiffusion, linear_betas
from facelib.guidance import (ClassifierScore, ContrastiveScore, CosineScore, DenoisedCosineScore, MeanShiftGuidance,
                              OptimisationGuidance, ReconstructionGuidance, log_p_theta, nearest_wording)
from facelib.text import description_embeddings


def _matched_label(texts, table):
    e = torch.as_tensor(text.get_encoder().encode(list(texts)))
    return guidance.vocabulary_log_weights(e, table.flatten(0, 1)).reshape(len(texts), 18, 2).logsumexp(-1).argmax(1)


def test_reconstruction_guidance_pulls_the_estimate_towards_the_known_frame(denoiser, coma_test):
    from facelib.guidance import ReconstructionGuidance, chain
    diffusion = denoiser.diffusion_with(50)
    x0 = torch.as_tensor(denoiser.normalizer.normalize(np.repeat(coma_test.subject_neutrals()[:2, None], 40, 1)))
    known = torch.zeros(2, 40, dtype=torch.bool)
    known[:, 0] = True
    xt = diffusion.q_sample(torch.as_tensor(denoiser.normalizer.normalize(coma_test.landmarks[5:7])), torch.tensor([20, 20]),
                            generator=torch.Generator().manual_seed(0))  # a sequence of other faces, noised

    def known_error(x, t):
        with torch.no_grad():
            eps = denoiser.model(x, diffusion.model_time(t, 2))
            return ((diffusion.predict_x0(x, t, eps) - x0)[:, 0] ** 2).sum((1, 2))

    hook = ReconstructionGuidance(denoiser.model, diffusion, x0, known, scale=0.05)
    moved = hook(xt, xt, 20, None)  # x_hat = x_t: the step alone
    assert (known_error(moved, 20) < known_error(xt, 20)).all()
    assert torch.equal(chain(None, hook)(xt, xt, 20, None), moved)
    with pytest.raises(ValueError, match="non-negative"):
        ReconstructionGuidance(denoiser.model, diffusion, x0, known, scale=-1.0)


def test_log_p_theta_is_the_gaussian_log_density_up_to_a_constant():
    mean, var = torch.randn(2, 5, 68, 3), torch.full((2, 1, 1, 1), 0.3)
    out = {"mean": mean, "variance": var, "guidance_variance": var}
    x1, x2 = torch.randn(2, 5, 68, 3), torch.randn(2, 5, 68, 3)
    normal = torch.distributions.Normal(mean, var.sqrt())
    exact = lambda x: normal.log_prob(x).flatten(1).sum(1)  # noqa: E731
    assert torch.allclose(log_p_theta(x1, out) - log_p_theta(x2, out), exact(x1) - exact(x2), rtol=1e-4, atol=1e-3)


def test_one_guided_step_increases_the_class_log_probability(small_classifier):
    # Alg. 1 line 10 with lambda = 0: pure ascent of log p_phi(y | x, t-1) from x_hat_{t-1}.
    clf, diffusion = small_classifier
    labels = torch.tensor([0, 1, 2, 1])
    score = ClassifierScore(clf, labels)
    xt = torch.randn(4, 10, 68, 3)
    var = torch.full((4, 1, 1, 1), 0.01)
    out = {"mean": xt * 0.9, "variance": var, "guidance_variance": var}
    x_hat = out["mean"] + 0.1 * torch.randn_like(xt)
    t = 50
    t_prev = diffusion.model_time(t - 1, 4)
    before = score(x_hat, t_prev)
    guided = OptimisationGuidance(score, diffusion, guidance_weight=0.0, lr=1e-3)(x_hat, xt, t, out)
    assert (score(guided, t_prev) > before).all()
    # with lambda > 0 the full objective of Alg. 1 increases, and x stays near the model's mean
    guide = OptimisationGuidance(score, diffusion, guidance_weight=0.01, lr=1e-3)
    guided = guide(x_hat, xt, t, out)
    assert (guide.objective(guided, out, t_prev) > guide.objective(x_hat, out, t_prev)).all()
    assert (guided - x_hat).abs().max() <= 3 * 1e-3 + 1e-6  # 3 Adagrad steps of at most lr each


def test_mean_shift_guidance_moves_along_the_gradient(small_classifier):
    clf, diffusion = small_classifier
    score = ClassifierScore(clf, torch.tensor([2, 2]))
    xt = torch.randn(2, 8, 68, 3)
    var = torch.full((2, 1, 1, 1), 0.02)
    out = {"mean": xt, "variance": var, "guidance_variance": var}
    x_hat = xt + 0.1
    assert torch.equal(MeanShiftGuidance(score, diffusion, scale=0.0)(x_hat, xt, 10, out), x_hat)
    shifted = MeanShiftGuidance(score, diffusion, scale=1.0)(x_hat, xt, 10, out)
    t = diffusion.model_time(10, 2)
    step = 1e-2 * (shifted - x_hat) / (shifted - x_hat).norm()
    assert (score(xt + step, t) > score(xt, t)).all()


@pytest.mark.parametrize("kwargs, message", [
    ({"guidance_weight": -0.1}, "non-negative"), ({"lr": 0.0}, "positive"), ({"num_steps": 0}, "positive integer")])
def test_guidance_rejects_bad_settings(small_classifier, kwargs, message):
    clf, diffusion = small_classifier
    with pytest.raises(ValueError, match=message):
        OptimisationGuidance(ClassifierScore(clf, [0]), diffusion, **kwargs)


def test_one_guided_step_increases_the_cosine_with_the_text(text_head):
    # Alg. 2 line 10 with lambda = 0: pure ascent of cos(BiT(x, t-1), E(c)) from x_hat_{t-1}.
    diffusion = GaussianDiffusion(linear_betas(2000))
    emb = torch.as_tensor(text.get_encoder().encode(["high smile", "from the neutral face to anger", "sad", "beaming"]))
    score = CosineScore(text_head.model, emb)
    gen = torch.Generator().manual_seed(0)
    xt = torch.randn(4, 40, 68, 3, generator=gen)
    var = torch.full((4, 1, 1, 1), 0.02)
    out = {"mean": xt * 0.99, "variance": var, "guidance_variance": var}
    x_hat = out["mean"] + 0.14 * torch.randn(xt.shape, generator=gen)
    t = 300
    t_prev = diffusion.model_time(t - 1, 4)
    guided = OptimisationGuidance(score, diffusion, guidance_weight=0.0, lr=0.01)(x_hat, xt, t, out)
    assert (score(guided, t_prev) > score(x_hat, t_prev)).all()


def test_denoised_score_reads_the_denoisers_estimate(text_head, merged_denoiser):
    # cos(BiT(x0_hat(x, t), 0), E(c)): at t = 0 the estimate is x itself, so it equals Eq. 10 at t = 0;
    # at t > 0 it is the head's cosine on x0_hat = (x - sqrt(1 - abar_t) eps_theta) / sqrt(abar_t).
    emb = torch.as_tensor(text.get_encoder().encode(["high smile", "from surprise to the neutral face"]))
    full = merged_denoiser.diffusion
    score = DenoisedCosineScore(text_head.model, merged_denoiser.model, full, emb)
    x = torch.randn(2, 40, 68, 3, generator=torch.Generator().manual_seed(3))
    zero = torch.zeros(2)
    with torch.no_grad():
        torch.testing.assert_close(score(x, zero), CosineScore(text_head.model, emb)(x, zero))
        t = torch.tensor([700.0, 1500.0])
        x0_hat = full.predict_x0(x, t.long(), merged_denoiser.model(x, t))
        torch.testing.assert_close(score(x, t), text_head.model.cosine(x0_hat, zero, emb))
        assert not torch.allclose(score(x, t), CosineScore(text_head.model, emb)(x, t))
    # one guided step (lambda = 0) at a large t raises it: the gradient reaches x through the denoiser
    diffusion = full.respace(100)
    xt = torch.randn(2, 40, 68, 3, generator=torch.Generator().manual_seed(4))
    with torch.no_grad():
        out = diffusion.p_mean_variance(merged_denoiser.model, xt, 80)
    t_prev = diffusion.model_time(79, 2)
    guided = OptimisationGuidance(score, diffusion, guidance_weight=0.0, lr=0.01)(out["mean"], xt, 80, out)
    with torch.no_grad():
        assert (score(guided, t_prev) > score(out["mean"], t_prev)).all()


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


def test_contrastive_score_is_the_heads_log_probability_of_the_matched_descriptions(text_head, description_table):
    # score = log sum_n w_n p(r_n | x, t), p = the head's InfoNCE softmax over the references, w = the
    # text's match to them; when c = r_j and the match is sharp it is log p(r_j | x, t), a log-softmax
    # (the probabilities over the references sum to 1)
    encoder = text.get_encoder()
    refs = nearest_wording(description_table, encoder.encode(["from the neutral face to sad"]))[0]
    x = torch.randn(1, 40, 68, 3, generator=torch.Generator().manual_seed(6)).expand(36, -1, -1, -1)
    t = torch.full((36,), 400.0)
    tau = text_head.meta["training"]["temperature"]
    with torch.no_grad():
        p = torch.softmax(text_head.model.embed(x[:1], t[:1]) @ refs.T / tau, -1)[0]
        log_p = ContrastiveScore(text_head.model, refs, refs.expand(36, -1, -1), tau, match_temperature=1e-4)(x, t)
        torch.testing.assert_close(log_p, p.log(), atol=1e-5, rtol=1e-5)
        assert torch.logsumexp(log_p, 0).abs() < 1e-5
        held_out = torch.as_tensor(encoder.encode(["starting neutral and ending with a sad face"]))
        w = torch.softmax(held_out @ refs.T / config.MATCH_TEMPERATURE, -1)[0]
        got = ContrastiveScore(text_head.model, held_out, refs[None], tau)(x[:1], t[:1])
        torch.testing.assert_close(got, (w * p).sum().log()[None], atol=1e-5, rtol=1e-5)
    diffusion = GaussianDiffusion(linear_betas(2000))
    var = torch.full((4, 1, 1, 1), 0.02)
    out = {"mean": x[:4] * 0.99, "variance": var, "guidance_variance": var}
    four = ContrastiveScore(text_head.model, refs[:4], refs.expand(4, -1, -1), tau)
    guided = OptimisationGuidance(four, diffusion, guidance_weight=0.0, lr=0.01)(out["mean"], x[:4], 401, out)
    with torch.no_grad():
        assert (four(guided, t[:4]) > four(out["mean"], t[:4])).all()
    for bad_refs, bad_tau, bad_match in ((refs, tau, 0.01), (refs.expand(36, -1, -1), 0.0, 0.01),
                                         (refs.expand(36, -1, -1), tau, -1.0)):
        with pytest.raises(ValueError, match="references|temperature"):
            ContrastiveScore(text_head.model, refs, bad_refs, bad_tau, bad_match)


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
    var = torch.ones(2, 1, 1, 1)
    out = {"mean": x, "variance": var, "guidance_variance": var}
    g = OptimisationGuidance(lambda x, t: x.sum((1, 2, 3)), diffusion, 0.0, 0.1, max_time=1000)
    high = int(np.flatnonzero(diffusion.timesteps > 1000)[0])
    low = int(np.flatnonzero((diffusion.timesteps <= 1000) & (diffusion.timesteps > 0))[-1])
    assert torch.equal(g(x, x, high, out), x)
    assert (g(x, x, low, out) > 0).all()  # climbs the score


def test_under_ddim_the_mean_shift_moves_the_noise_estimate_as_dhariwal_and_nichols_algorithm_2(small_classifier):
    clf, diffusion = small_classifier
    ddim = diffusion.with_eta(0.0)
    score = ClassifierScore(clf, torch.tensor([1, 2]))
    torch.manual_seed(1)
    xt, eps, t = torch.randn(2, 8, 68, 3), torch.randn(2, 8, 68, 3), 40
    out = ddim.mean_variance_from_eps(xt, t, eps)
    assert torch.equal(out["variance"], torch.zeros_like(out["variance"]))  # eta = 0: no noise...
    assert out["guidance_variance"].item() == pytest.approx(diffusion.betas[t])  # ...but a pull
    x = xt.clone().requires_grad_(True)
    grad = torch.autograd.grad(score(x, diffusion.model_time(t, 2)).sum(), x)[0]
    eps_hat = eps - 2.0 * diffusion.sqrt_one_minus_alphas_bar[t] * grad
    expected = ddim.mean_variance_from_eps(xt, t, eps_hat)["mean"]
    torch.testing.assert_close(MeanShiftGuidance(score, ddim, scale=2.0)(out["mean"], xt, t, out), expected)
    # the deterministic (probability-flow) step carries half the ancestral step's pull, beta_t / (2 alpha_t)
    ddpm_shift = 2.0 * diffusion.betas[t] * grad
    ratio = ((expected - out["mean"]).norm() / ddpm_shift.norm()).item()
    assert ratio == pytest.approx(0.5 / diffusion.alphas[t], rel=0.02)


def test_a_plain_function_score_receives_the_noise_levels_time_as_guided_diffusions_spaced_cond_fn():
    """On a respaced chain a reader's own score f(x, time) is given the model's time label timesteps[t], not the
    chain's step t (guided-diffusion's SpacedDiffusion wraps cond_fn like the model).  The reference below is
    guided-diffusion's condition_mean written out: mean + variance * grad log p(y | x_t, timestep_map[t])."""
    chain = GaussianDiffusion(linear_betas(2000)).respace(100)
    target = torch.randn(2, 8, 68, 3, generator=torch.Generator().manual_seed(1))
    seen = []

    def log_p(x, time):  # a "classifier" whose pull depends on the noise level
        seen.append(time.clone())
        return -(time[:, None, None, None] / 2000.0 * (x - target) ** 2).flatten(1).sum(1)

    xt = torch.randn(2, 8, 68, 3, generator=torch.Generator().manual_seed(2))
    for t in (50, 100):
        var = torch.full((2, 1, 1, 1), float(chain.sigmas[t] ** 2))
        out = {"mean": xt, "variance": var, "guidance_variance": var}
        shifted = MeanShiftGuidance(log_p, chain, scale=1.0)(xt, xt, t, out)
        assert torch.equal(seen[-1], torch.full((2,), float(chain.timesteps[t])))
        time = torch.full((2,), float(chain.timesteps[t]))
        reference = xt + var * (-2 * time[:, None, None, None] / 2000.0 * (xt - target))
        assert torch.allclose(shifted, reference, rtol=1e-5, atol=1e-6)
    # the chain's step itself (the old behaviour) would have been 19-27 % off: it is not what f received
    assert not torch.equal(seen[-1], torch.full((2,), 100.0))


def test_alg1_on_a_chain_with_the_posterior_variance_stays_finite_at_the_last_step(small_classifier):
    # beta~_1 = 0: log p_theta(x | x_1) would divide by it (NaN on every frame of a guided window of
    # a long sequence); the pull weighs with beta_1 there, the variance elsewhere is the step's own.
    clf, _ = small_classifier
    chain = GaussianDiffusion(linear_betas(2000), variance="posterior").respace(10)
    zero = lambda x, t, *a: torch.zeros_like(x)
    xt = torch.randn(2, 40, 68, 3, generator=torch.Generator().manual_seed(0))
    out = chain.p_mean_variance(zero, xt, 1)
    assert float(out["variance"].max()) == 0.0
    assert float(chain.betas[1]) > 0
    assert float(out["guidance_variance"].max()) == pytest.approx(float(chain.betas[1]))
    assert float(chain.p_mean_variance(zero, xt, 5)["guidance_variance"].flatten()[0]) == pytest.approx(float(chain.sigmas[5] ** 2))
    guided = OptimisationGuidance(ClassifierScore(clf, [0, 1]), chain, lr=0.01)(out["mean"], xt, 1, out)
    assert torch.isfinite(guided).all()


def test_reconstruction_guidance_leaves_a_sequence_with_nothing_known_alone(denoiser):
    # a batch of windows where one shares no frame (DoubleTake's windows, chapter "Any length"): the norm's
    # gradient at zero is undefined (NaN on every frame before the clamp); that sequence is not pulled
    chain = denoiser.diffusion_with(10, "posterior")
    x0 = torch.randn(2, 40, 68, 3, generator=torch.Generator().manual_seed(1))
    known = torch.zeros(2, 40, dtype=torch.bool)
    known[0, :5] = True
    guide = ReconstructionGuidance(denoiser.model, chain, x0, known, 2.0)
    xt = torch.randn(2, 40, 68, 3, generator=torch.Generator().manual_seed(2))
    x_hat = torch.zeros_like(xt)
    step = guide(x_hat, xt, 5, {})
    assert torch.isfinite(step).all()
    assert torch.equal(step[1], x_hat[1]) and not torch.equal(step[0], x_hat[0])
