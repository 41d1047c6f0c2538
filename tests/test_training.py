"""The one training loop: schedule, logging, resume, and distributed data parallel under torchrun."""
import dataclasses
import json
import os
import subprocess
import sys
import zlib

import numpy as np
import pytest
import torch

from facelib import config, training
from facelib.__main__ import main
from facelib.training import Draws, swap_anatomy, training_anatomies
from facelib.training.loop import Objective, TrainingLog, device_for, learning_rate
from facelib.training.recipes import Recipe


def _recipe(steps=6, **settings):
    return training.DenoiserRecipe(training.DenoiserTraining(batch_size=8, **settings).with_steps(steps))


def test_training_log_writes_running_means_every_n_steps_and_at_the_end():
    log = TrainingLog(total_steps=5, every=2)
    for step in range(5):
        log.add(step, loss=float(step), accuracy=torch.tensor(1.0))
    assert log.history["step"] == [2, 4, 5]
    assert log.history["loss"] == [0.5, 2.5, 4.0]
    assert log.history["accuracy"] == [1.0, 1.0, 1.0] and len(log.history["seconds"]) == 3


def test_learning_rate_warms_up_linearly_then_decays_by_a_cosine_to_its_final_fraction():
    s = training.DenoiserTraining(steps=100, warmup=10, lr=1.0, final_lr_fraction=0.05)
    assert learning_rate(s, 0, 100) == pytest.approx(0.1) and learning_rate(s, 9, 100) == pytest.approx(1.0)
    assert learning_rate(s, 10, 100) == pytest.approx(1.0)
    assert learning_rate(s, 55, 100) == pytest.approx(0.05 + 0.95 * 0.5)
    assert learning_rate(s, 100, 100) == pytest.approx(0.05)


def test_the_same_seed_trains_the_same_weights_and_another_seed_does_not():
    a, _ = training.fit(_recipe(3), progress=False)
    b, _ = training.fit(_recipe(3), progress=False)
    c, _ = training.fit(_recipe(3, seed=1), progress=False)
    for (k, va), vb, vc in zip(a.state_dict().items(), b.state_dict().values(), c.state_dict().values()):
        assert torch.equal(va, vb), k
    assert any(not torch.equal(va, vc) for va, vc in zip(a.state_dict().values(), c.state_dict().values()))


def test_a_run_resumed_from_its_saved_state_ends_where_an_uninterrupted_run_ends(tmp_path):
    whole, _ = training.fit(_recipe(6), progress=False)
    broken = _recipe(6)
    calls = {"n": 0}
    loss = broken.loss

    def failing_loss(model, draws):  # the process dies in the fifth step, after the state of step 3 was saved
        calls["n"] += 1
        if calls["n"] == 5:
            raise KeyboardInterrupt
        return loss(model, draws)
    broken.loss = failing_loss
    with pytest.raises(KeyboardInterrupt):
        training.fit(broken, progress=False, resume_from=tmp_path / "run", save_every=3)
    resumed, history = training.fit(_recipe(6), progress=False, resume_from=tmp_path / "run", save_every=3)
    for (k, va), vb in zip(whole.state_dict().items(), resumed.state_dict().values()):
        torch.testing.assert_close(va, vb, rtol=0, atol=0, msg=k)
    assert history["step"][-1] == 6


class _Encoder:
    """A stand-in for the sentence encoder: a fixed random 16-d vector per text (no model to load)."""

    def encode(self, texts):
        return np.stack([np.random.default_rng(zlib.crc32(t.encode())).standard_normal(16) for t in texts]
                        ).astype(np.float32)


def _small_bit(recipe, **sizes):
    """The recipe with a one-layer BiT of width 32 (its dropout of 0.1 kept)."""
    recipe.architecture = dataclasses.replace(recipe.architecture, width=32, depth=1, heads=2, ff=32, **sizes)
    return recipe


def _tiny(name, **settings):
    return training.settings_for(name, steps=6, batch_size=8, **settings)


# the recipes whose models use dropout (torch's global stream), and the GAN (a critic outside its model)
RESUMABLE = {
    "guide": lambda: _small_bit(training.GuideRecipe(_tiny("guide"))),
    "text_head": lambda: _small_bit(training.TextHeadRecipe(_tiny("text_head", dataset="coma"), encoder=_Encoder()),
                                    embedding_dim=16),
    "au_regressor": lambda: _small_bit(training.AURegressorRecipe(_tiny("au_regressor"))),
    "lstm_filler": lambda: training.LSTMFillerRecipe(_tiny("lstm_filler")),
    "motion3dgan": lambda: training.Motion3DGANRecipe(_tiny("motion3dgan", channels=16, critic_steps=2)),
}


def _dies_in_step(recipe, step):
    """The recipe, whose process dies (KeyboardInterrupt) as the 0-based ``step`` begins."""
    objectives, calls = recipe.objectives, [0]

    def dying(model):
        first, *rest = objectives(model)

        def loss(draws):
            if calls[0] == step * first.repeats:
                raise KeyboardInterrupt
            calls[0] += 1
            return first.loss(draws)
        return [Objective(first.module, loss, first.repeats), *rest]
    recipe.objectives = dying
    return recipe


def _same(a, b):
    """Bit-identical nested states (tensors compared with torch.equal)."""
    if isinstance(a, torch.Tensor):
        return isinstance(b, torch.Tensor) and a.dtype == b.dtype and torch.equal(a, b)
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def _without_seconds(history):
    return {k: v for k, v in history.items() if k != "seconds"}


@pytest.mark.parametrize("name", RESUMABLE)
def test_every_recipe_with_dropout_and_the_gan_resume_bit_for_bit(name, tmp_path):
    """6 steps in one go against 3 steps, a death in the 4th, and a resumed run: the same final training
    state (weights, critic, EMA, optimisers, random streams) and the same loss curves, logged every 2 steps."""
    make = RESUMABLE[name]
    whole, whole_history = training.fit(make(), progress=False, log_every=2, resume_from=tmp_path / "whole",
                                        save_every=3)
    with pytest.raises(KeyboardInterrupt):
        training.fit(_dies_in_step(make(), 3), progress=False, log_every=2, resume_from=tmp_path / "run", save_every=3)
    assert torch.load(tmp_path / "run.state.pt", weights_only=False)["step"] == 3
    resumed, history = training.fit(make(), progress=False, log_every=2, resume_from=tmp_path / "run", save_every=3)
    assert _same(whole.state_dict(), resumed.state_dict())
    assert _same(_without_seconds(whole_history), _without_seconds(history)) and history["step"] == [2, 4, 6]
    a, b = (torch.load(tmp_path / f"{stem}.state.pt", weights_only=False) for stem in ("whole", "run"))
    for state in (a, b):
        state["history"] = _without_seconds(state["history"])
    assert a.keys() == b.keys()
    for key in a:
        assert _same(a[key], b[key]), key
    if name == "motion3dgan":
        assert len(a["modules"]) == 2  # the critic and the generator


def test_a_kill_while_the_state_is_written_leaves_the_previous_state_intact(tmp_path, monkeypatch):
    whole, _ = training.fit(_recipe(6), progress=False)
    save, calls = torch.save, []

    def dying_save(obj, f):  # the second state (step 4) is half written when the process dies
        calls.append(1)
        if len(calls) == 2:
            f.write(b"half a state")
            raise KeyboardInterrupt
        save(obj, f)
    monkeypatch.setattr(torch, "save", dying_save)
    with pytest.raises(KeyboardInterrupt):
        training.fit(_recipe(6), progress=False, resume_from=tmp_path / "run", save_every=2)
    monkeypatch.undo()
    assert len(calls) == 2 and [p.name for p in tmp_path.iterdir()] == ["run.state.pt"]
    assert torch.load(tmp_path / "run.state.pt", weights_only=False)["step"] == 2
    resumed, history = training.fit(_recipe(6), progress=False, resume_from=tmp_path / "run", save_every=2)
    assert _same(whole.state_dict(), resumed.state_dict()) and history["step"][-1] == 6


class _BatchNormRecipe(Recipe):
    """A linear layer and a BatchNorm, whose running mean (a buffer) moves in training."""

    size = 64

    def __init__(self, steps=6):
        self.settings = training.Optimisation(steps=steps, batch_size=8, ema_decay=0.9)
        self.x = torch.randn(self.size, 3, generator=torch.Generator().manual_seed(0)) + 5

    def build(self, generator):
        return torch.nn.Sequential(torch.nn.Linear(3, 3), torch.nn.BatchNorm1d(3))

    def model_config(self, model):
        return {}

    def objectives(self, model):
        self.trained = model  # the weights the EMA follows
        return super().objectives(model)

    def loss(self, model, draws):
        return model(self.x[draws.examples(self.size)]).pow(2).mean(), {}


def test_the_ema_carries_the_models_buffers_and_resumes_bit_for_bit(tmp_path):
    """Before, the EMA averaged the parameters only: its BatchNorm kept the running
    mean 0 and count 0 it was copied with."""
    recipe = _BatchNormRecipe()
    ema, _ = training.fit(recipe, progress=False)
    bn, trained = ema[1], recipe.trained[1]
    assert int(bn.num_batches_tracked) == 6 and bn.running_mean.abs().min() > 0.1
    assert torch.equal(bn.running_mean, trained.running_mean)
    assert torch.equal(bn.running_var, trained.running_var)
    assert not torch.equal(ema[0].weight, recipe.trained[0].weight)  # weights averaged
    assert list(ema.state_dict()) == list(recipe.trained.state_dict())  # same keys
    with pytest.raises(KeyboardInterrupt):
        training.fit(_dies_in_step(_BatchNormRecipe(), 4), progress=False, resume_from=tmp_path / "run",
                     save_every=3)
    resumed, _ = training.fit(_BatchNormRecipe(), progress=False, resume_from=tmp_path / "run", save_every=3)
    assert _same(ema.state_dict(), resumed.state_dict())


def test_a_resume_with_other_settings_is_refused_with_what_differs(tmp_path):
    training.fit(_recipe(3), progress=False, resume_from=tmp_path / "run")
    state = tmp_path / "run.state.pt"
    with pytest.raises(ValueError, match=r"other settings \(settings\.lr: 0\.0005 saved, 0\.002 now; settings\.seed: "
                                         r"0 saved, 1 now\): resume with the same settings, or delete .*run\.state\.pt "
                                         r"to start afresh"):
        training.fit(_recipe(3, lr=2e-3, seed=1), progress=False, resume_from=tmp_path / "run")
    torch.save({k: v for k, v in torch.load(state, weights_only=False).items() if k != "record"}, state)
    with pytest.raises(ValueError, match="records no settings"):
        training.fit(_recipe(3), progress=False, resume_from=tmp_path / "run")


def test_settings_refuse_impossible_values_with_the_allowed_ones():
    with pytest.raises(ValueError, match="optimizer must be one of"):
        training.DenoiserTraining(optimizer="sgd")
    with pytest.raises(ValueError, match="warmup"):
        training.GuideTraining(steps=100, warmup=100)
    with pytest.raises(ValueError, match="unknown model 'vae'; allowed: denoiser"):
        training.recipe("vae")
    with pytest.raises(ValueError, match="denoiser has no setting method; its settings: steps"):
        training.recipe("denoiser", method="ours")
    with pytest.raises(ValueError, match="evaluator trains for a number of epochs"):
        training.recipe("evaluator", steps=10)


def test_asking_for_an_absent_gpu_is_a_clear_error():
    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    with pytest.raises(ValueError, match="no CUDA device"):
        device_for("cuda")
    with pytest.raises(SystemExit):
        main(["train", "denoiser", "--fast", "--device", "cuda", "--out", "/nonexistent/never"])


def test_two_processes_under_torchrun_train_the_weights_of_one_process_with_the_same_global_batch(tmp_path):
    """DistributedDataParallel over gloo (CPU): each process trains on its half of every global batch of 8.

    The two runs add the same gradients in another order; Adam divides each gradient by its own running
    size, so a rounding difference in a tiny gradient becomes a difference of up to a few 1e-6 in a
    weight, against steps of lr = 5e-4.  A process that trained on its half alone (no averaging of
    gradients) is off by about a step."""
    args = ["train", "denoiser", "--steps", "3", "--device", "cpu"]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    run = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
                          "-m", "facelib", *args, "--batch-size", "8", "--out", str(tmp_path / "two"), "--resume"],
                         env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    assert main([*args, "--batch-size", "8", "--out", str(tmp_path / "one")]) == 0
    assert main([*args, "--batch-size", "4", "--out", str(tmp_path / "half")]) == 0
    two, one, half = (torch.load(tmp_path / f"{name}.pt", weights_only=True) for name in ("two", "one", "half"))
    assert set(two) == set(one)
    worst = max((two[k] - one[k]).abs().max().item() for k in one)
    assert worst < 3e-5, f"two processes differ from one by {worst:.2g}"
    assert max((half[k] - one[k]).abs().max().item() for k in one) > 10 * 3e-5
    # the logged loss is that of the whole global batch (averaged over the processes), not of rank 0's half
    two, one = (json.loads((tmp_path / f"{name}.json").read_text())["history"]["loss"] for name in ("two", "one"))
    np.testing.assert_allclose(two, one, rtol=1e-4)
    assert not (tmp_path / "two.state.pt").exists()  # saved at the last step (every rank's random state), then removed


def test_anatomy_augmentation_keeps_the_motion_and_swaps_the_neutral_face(coma_train):
    pool = torch.as_tensor(training_anatomies(("coma", "bu")))
    assert pool.shape == (9 + 81, 68, 3)
    x = torch.as_tensor(coma_train.landmarks[:6])
    own = torch.as_tensor(np.stack([coma_train.neutral_landmarks(int(s)) for s in coma_train.subjects[:6]]))
    draws = Draws(torch.Generator().manual_seed(0), len(x))
    assert torch.equal(swap_anatomy(x, own, pool, 0.0, draws), x)
    swapped = swap_anatomy(x, own, pool, 1.0, draws)
    shift = swapped - x
    assert torch.allclose(shift, shift[:, :1].expand_as(shift), atol=1e-4)  # the same offset in every frame
    new_neutral = own + shift[:, 0]
    dist = (new_neutral[:, None] - pool[None]).norm(dim=-1).mean(-1).min(1).values
    assert (dist < 1e-4).all()  # the new neutral face is one of the pool's


def test_every_shipped_checkpoint_is_the_recipe_that_train_all_runs():
    """training.SHIPPED rebuilds data/checkpoints: every checkpoint is there, with the settings it records."""
    shipped = {p.stem for p in config.CHECKPOINT_DIR.glob("*.json")}
    assert shipped == set(training.SHIPPED)
    renamed = {"sequences_per_batch": "batch_size"}  # the deformers' batch, named so before the one loop
    for name, (model, settings) in training.SHIPPED.items():
        recorded = json.loads((config.CHECKPOINT_DIR / f"{name}.json").read_text())["training"]
        # a student records its teacher's data settings, and its own under "distillation"
        recorded = recorded.get("distillation", recorded)
        recorded = {renamed.get(k, k): v for k, v in recorded.items()}
        for key, value in dataclasses.asdict(training.settings_for(model, **settings)).items():
            if key in recorded:
                assert recorded[key] == (list(value) if isinstance(value, tuple) else value), (name, key)


def test_train_all_writes_the_chosen_checkpoints_and_their_times(tmp_path):
    rows = training.train_all(["ic_coma_I", "actor_bu"], fast=True, out_dir=tmp_path, progress=False)
    assert [r[0] for r in rows] == ["ic_coma_I", "actor_bu"] and all(r[3] > 0 for r in rows)
    assert (tmp_path / "ic_coma_I.pt").exists() and (tmp_path / "actor_bu.json").exists()
    with pytest.raises(ValueError, match="no shipped checkpoint 'ic_coma_X'; the shipped ones: denoiser_coma"):
        training.train_all(["ic_coma_X"], fast=True, out_dir=tmp_path)


def test_train_all_missing_skips_what_this_world_already_has_and_retrains_another_worlds(tmp_path):
    first = training.train_all(["ic_coma_I"], fast=True, out_dir=tmp_path, progress=False)
    assert [r[0] for r in first] == ["ic_coma_I"]
    assert training.train_all(["ic_coma_I"], fast=True, out_dir=tmp_path, progress=False, missing=True) == []
    js = tmp_path / "ic_coma_I.json"
    meta = json.loads(js.read_text())
    js.write_text(json.dumps({**meta, "world": {"version": 3 - config.WORLD, "fingerprint": None}}))
    again = training.train_all(["ic_coma_I"], fast=True, out_dir=tmp_path, progress=False, missing=True)
    assert [r[0] for r in again] == ["ic_coma_I"]
    meta = json.loads(js.read_text())  # trained with other settings than the recipe's now: retrained too
    js.write_text(json.dumps({**meta, "training": {**meta["training"], "lr": 0.5}}))
    assert len(training.train_all(["ic_coma_I"], fast=True, out_dir=tmp_path, progress=False, missing=True)) == 1


def test_a_conditional_denoiser_trains_with_label_dropout_and_is_named_cfg():
    recipe = training.recipe("denoiser", fast=True, conditional=True, condition_dropout=0.5, steps=3)
    assert recipe.checkpoint_name() == "denoiser_coma_cfg" and recipe.architecture.num_classes == 12
    model, history = training.fit(recipe, progress=False)
    assert model.label_embedding.num_embeddings == 13 and np.isfinite(history["loss"]).all()
    with pytest.raises(ValueError, match="condition_dropout is a probability"):
        training.DenoiserTraining(conditional=True, condition_dropout=1.0)


def test_mirroring_swaps_left_and_right_keeps_each_regions_motion_and_draws_nothing_when_off(coma_train):
    from facelib import data, metrics
    from facelib.training.recipes import mirror_faces
    normalizer = data.LandmarkNormalizer.fit(coma_train)
    x = torch.as_tensor(normalizer.normalize(coma_train.landmarks[:6]))
    gen = torch.Generator().manual_seed(0)
    before = gen.get_state()
    assert mirror_faces(x, normalizer, 0.0, Draws(gen, 6)) is x
    assert torch.equal(gen.get_state(), before)  # a run without mirroring keeps its draws
    once = mirror_faces(x, normalizer, 1.0, Draws(gen, 6))
    torch.testing.assert_close(mirror_faces(once, normalizer, 1.0, Draws(gen, 6)), x, atol=1e-4, rtol=1e-4)
    mm, mirrored = coma_train.landmarks[:6], normalizer.denormalize(once).numpy()
    np.testing.assert_allclose(mirrored[:, :, 48, 0], -mm[:, :, 54, 0], atol=1e-3)  # the corners swap sides
    for region, amplitude in metrics.amplitudes(mirrored).items():
        np.testing.assert_allclose(amplitude, metrics.amplitudes(mm)[region], atol=1e-3)
    half = mirror_faces(x.repeat(50, 1, 1, 1), normalizer, 0.5, Draws(gen, 300))
    share = (half - x.repeat(50, 1, 1, 1)).abs().amax((1, 2, 3)).gt(1e-3).float().mean().item()
    assert 0.4 < share < 0.6


def test_the_denoiser_logs_held_out_losses_per_noise_level_with_fixed_draws():
    r = _recipe(steps=4)
    model, history = training.fit(r, progress=False, validate_every=2)
    held_out = history["held_out"]
    assert held_out["step"] == [2, 4]
    assert set(held_out) == {"step", "t 1-500", "t 501-1000", "t 1001-1500", "t 1501-2000"}
    assert r.validate(model) == {k: v[-1] for k, v in held_out.items() if k != "step"}  # the same draws
    assert held_out["t 1-500"][-1] > held_out["t 1501-2000"][-1] > 0  # at low noise eps is hard to tell


@pytest.mark.parametrize("prediction", ["x0", "v"])
def test_a_denoiser_with_another_target_or_weighting_trains_and_samples_by_its_recorded_config(prediction, tmp_path):
    from facelib import tasks
    r = _recipe(steps=3, prediction=prediction, min_snr_gamma=5.0, mirror=0.5)
    assert r.build(torch.Generator()).config.prediction == prediction
    pt, js = training.train_and_save(r, name=str(tmp_path / "d"), progress=False)
    denoiser = tasks.load_denoiser(str(tmp_path / "d"))
    assert denoiser.model.config.prediction == prediction
    assert tasks.unconditional(2, steps=3, denoiser=denoiser, progress=False).shape == (2, 40, 68, 3)
    meta = json.loads(js.read_text())
    meta["training"]["schedule"] = "cosine"  # a record that the network does not match is refused
    js.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="differs from its network's .* cannot be sampled correctly"):
        tasks.load_denoiser(str(tmp_path / "d"))


def test_the_motion_weight_reaches_the_loss_and_is_checked():
    r, plain = _recipe(steps=2, motion_weight=4.0), _recipe(steps=2)
    model = plain.build(torch.Generator().manual_seed(0))
    with torch.no_grad():  # the same batch, noise and model: only the weighting differs
        weighted = r.loss(model, training.Draws(torch.Generator().manual_seed(1), 8))[0].item()
        simple = plain.loss(model, training.Draws(torch.Generator().manual_seed(1), 8))[0].item()
    assert weighted > 1.5 * simple  # a fresh model's error moves from frame to frame
    for bad in (0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="motion_weight must be a number >= 0.01"):
            training.DenoiserTraining(motion_weight=bad)
    with pytest.raises(ValueError, match="motion_weight weighs the DDPM's loss, not the flow's"):
        training.DenoiserTraining(schedule="flow", prediction="u", motion_weight=2.0)


def test_a_temporal_prior_is_fitted_to_whole_sequences_saved_and_loaded(tmp_path):
    from facelib import tasks
    r = _recipe(steps=2, temporal_prior=True)
    assert r.architecture.prior_length == r.settings.num_frames
    model = r.build(torch.Generator().manual_seed(0))
    spectrum = model.prior_spectrum.sum(1)
    assert spectrum[:3].min() > 5 * spectrum[-10:].max()  # motion is slow: low frequencies hold the variance
    training.train_and_save(r, name=str(tmp_path / "d"), progress=False)
    loaded = tasks.load_denoiser(str(tmp_path / "d")).model
    assert loaded.config.prior_length == r.settings.num_frames
    torch.testing.assert_close(loaded.prior_spectrum, model.prior_spectrum)
    with pytest.raises(ValueError, match="temporal_prior fits the Gaussian to sequences of one length"):
        training.DenoiserTraining(temporal_prior=True, num_frames=(35, 45))


def test_a_rectified_flow_trains_on_the_same_network_and_loop_and_samples_from_its_checkpoint(tmp_path):
    from facelib import tasks
    from facelib.flow import RectifiedFlow
    r = _recipe(steps=4, schedule="flow", prediction="u")
    assert isinstance(r.diffusion, RectifiedFlow)
    model, history = training.fit(r, progress=False, validate_every=2)
    assert set(history["held_out"]) == {"step", "t 1-500", "t 501-1000", "t 1001-1500", "t 1501-2000"}
    assert all(np.isfinite(v).all() for v in history["held_out"].values())
    pt, js = training.train_and_save(r, name=str(tmp_path / "f"), progress=False)
    denoiser = tasks.load_denoiser(str(tmp_path / "f"))
    assert (denoiser.model.config.schedule, denoiser.model.config.prediction) == ("flow", "u")
    x = RectifiedFlow(denoiser.model.config.num_diffusion_steps).sample(
        denoiser.model, (2, 40, 68, 3), 4, solver="heun", generator=torch.Generator().manual_seed(0))
    assert x.shape == (2, 40, 68, 3) and torch.isfinite(x).all()


def test_a_join_denoiser_starts_as_its_unconditional_one_and_learns_with_known_first_frames():
    # fine-tuned from denoiser_coma: the known frames' embedding starts at zero, so the join denoiser starts
    # as the unconditional one whatever it is given
    from facelib import tasks
    from facelib.inpainting import KnownInput
    recipe = training.recipe("denoiser", known_frames=0.75, start_from="denoiser_coma", steps=2)
    assert recipe.checkpoint_name() == "denoiser_coma_join" and recipe.architecture.known_input
    model, base = recipe.build(torch.Generator().manual_seed(0)), tasks.load_denoiser("denoiser_coma").model
    model.eval()  # as the loaded one (the transformer's eval path)
    x, t = torch.randn(2, 40, 68, 3), torch.tensor([10.0, 1500.0])
    known = torch.zeros(2, 40, dtype=torch.bool)
    known[:, :10] = True
    with torch.no_grad():
        assert torch.equal(model(x, t), base(x, t))
        assert torch.equal(KnownInput(model, torch.randn(2, 40, 68, 3), known)(x, t), base(x, t))
    # the known frames of a batch: the first 1..F/2 frames, the last frame now and then, or none
    m = recipe.known_mask(Draws(torch.Generator().manual_seed(0), 4096), 40)
    first = m[:, :20].sum(1)
    assert (m[:, :20] == (torch.arange(20)[None] < first[:, None])).all()  # a prefix
    assert not m[:, 20:39].any() and 0.3 < m[:, 39].float().mean() < 0.45  # 0.75 / 2
    assert abs((first == 0).float().mean().item() - 0.25) < 0.03 and first.max() == 20
    _, history = training.fit(recipe, progress=False)
    assert np.isfinite(history["loss"]).all()


def test_a_join_denoiser_is_refused_where_it_does_not_fit():
    from facelib import tasks
    from facelib.inpainting import KnownInput
    base = tasks.load_denoiser("denoiser_coma").model
    x = torch.zeros(1, 40, 68, 3)
    with pytest.raises(ValueError, match="does not read known frames"):
        base(x, torch.ones(1), known=(x, torch.ones(1, 40, dtype=torch.bool)))
    with pytest.raises(ValueError, match="does not read known frames: use a join denoiser"):
        KnownInput(base, x, torch.ones(1, 40, dtype=torch.bool))
    with pytest.raises(ValueError, match="cannot start from denoiser_coma: its network differs"):
        training.recipe("denoiser", known_frames=0.5, start_from="denoiser_coma", prediction="v", steps=1).build(
            torch.Generator())
    with pytest.raises(ValueError, match="known_frames is a probability"):
        training.DenoiserTraining(known_frames=1.5)
    with pytest.raises(ValueError, match="train on one length"):
        training.DenoiserTraining(known_frames=0.5, num_frames=(35, 45))
    with pytest.raises(ValueError, match="start_from names a denoiser checkpoint"):
        training.DenoiserTraining(start_from="guide_coma_I")
