"""Sequences of any length (tasks/long.py): the schedule, the windows, the stream and its
joins."""
import numpy as np
import pytest

from facelib import config, data, tasks
from facelib.tasks import long

LABELS = data.LABEL_SETS["coma"]


@pytest.fixture(scope="module")
def face(coma_test):
    return coma_test.neutral_landmarks(int(coma_test.subjects[0]))


@pytest.fixture(scope="module")
def guide():
    return tasks.load_guide("coma", "I")


def test_a_schedule_is_read_in_frames_at_the_native_rate():
    segments = long.parse_schedule("high_smile:3s, neutral:1, mouth_open : 0.5s , free:2s", LABELS)
    assert [(s.what, s.frames) for s in segments] == [
        ("high_smile", 3 * config.NATIVE_FPS), ("neutral", config.NATIVE_FPS),
        ("mouth_open", config.NATIVE_FPS // 2), ("free", 2 * config.NATIVE_FPS)]
    assert not any(s.text for s in segments)
    assert long.free_schedule(2) == [long.Segment("free", 2 * config.NATIVE_FPS)]


def test_a_text_in_quotes_is_a_segment_of_its_own_commas_and_colons_included():
    spec = """'mouth open':1s, "a broad grin, then wider: teeth" : 2s ,high_smile:1s,'moving freely':1.5"""
    segments = long.parse_schedule(spec, LABELS)
    assert segments == [long.Segment("mouth open", 30, True), long.Segment("a broad grin, then wider: teeth", 60, True),
                        long.Segment("high_smile", 30), long.Segment("moving freely", 45, True)]
    assert long.has_text(spec) and long.has_text(segments) and not long.has_text("high_smile:1s")


def test_a_schedule_with_a_text_runs_on_the_text_heads_labels():
    # coma+bu's 18 labels (a BU emotion among them) with a text; coma's 12 without
    segments = long.read_schedule('"a broad grin":1s, happy:1s')
    assert [s.what for s in segments] == ["a broad grin", "happy"]
    with pytest.raises(ValueError, match="unknown expression 'happy'.*or a description in quotes"):
        long.read_schedule("happy:1s")


def test_a_text_segment_opens_as_written_or_said_in_order_and_a_label_by_its_raw_text():
    settings = tasks.Long()
    window = long.Window("a broad grin", 10, 30, (), True, True)
    assert long._guiding_text(window, settings) == "a broad grin"
    assert long._guiding_text(long.Window("high_smile", 10, 30, (), False), settings) == "high smile"
    assert long._guiding_text(window, tasks.Long(text_opening="N2E")) == "from the neutral face to a broad grin"


@pytest.mark.parametrize("spec, message", [
    ("", "schedule must be a text"), ("high_smile", "cannot read the schedule item"),
    ("high_smile:2s,", "cannot read the schedule item ''"), ("smile:2s", "unknown expression 'smile'.*high_smile"),
    ("high_smile:0.2s", "shorter than a transition"), ("high_smile:1800s, free:1801s", "at most 3600 s"),
    ("high_smile:-1s", "cannot read"), ("high_smile:2 minutes", "cannot read"),
    ('"":2s', "text is empty"), ('"a grin:2s', "cannot read"), ('"a grin":0.1s', "shorter than a transition"),
    ('"a grin" 2s', "cannot read"), ("high_smile:1s, 'a grin':2s,", "after the last comma"),
    ("high_smile:1s,  ", "after the last comma"), ("'mouth_open':1s", "not a text; write it unquoted"),
    ("high_smile:1s, 'neutral':1s", "'neutral' is a name of the schedule"), ('"free":2s', "not a text")])
def test_a_bad_schedule_is_a_clear_error(spec, message):
    with pytest.raises(ValueError, match=message):
        long.parse_schedule(spec, LABELS)


def test_the_windows_make_every_frame_once_from_the_given_face_and_rest_on_it():
    segments = long.parse_schedule("high_smile:2s, neutral:1s, mouth_open:1.2s", LABELS)
    windows = long.plan_windows(segments, 40, 10)
    assert sum(w.keep for w in windows) == sum(s.frames for s in segments)
    assert windows[0].known == 0 and windows[0].anchors[0] == 0
    assert all(w.known == 10 and w.known + w.keep <= 40 for w in windows[1:])
    rests = [w for w in windows if w.what == "neutral"]
    assert rests and all(w.anchors == (w.known + w.keep - 1,) for w in rests)
    assert [w.opens for w in windows] == [True, False, True, True, False]  # a segment's first window
    assert len(long.join_frames(windows)) == len(windows) - 1
    assert long.join_frames(windows)[0] == windows[0].keep


def test_the_stream_starts_at_the_face_rests_on_it_and_is_deterministic(face, guide, denoiser):
    segments = long.parse_schedule("high_smile:1.5s, neutral:1s, free:1s", LABELS)
    kwargs = dict(steps=3, denoiser=denoiser, guide=guide, progress=False)
    chunks = list(long.stream(face, segments, 2, **kwargs))
    windows = long.plan_windows(segments, 40, tasks.Long().transition)
    assert [c.shape[1] for c in chunks] == [w.keep for w in windows]
    x = np.concatenate(chunks, axis=1)
    assert x.shape == (2, 105, 68, 3) and x.dtype == np.float32 and np.isfinite(x).all()
    assert np.array_equal(x[:, 0], np.broadcast_to(face, (2, 68, 3)).astype(np.float32))
    assert np.array_equal(x[:, 45 + 30 - 1], np.broadcast_to(face, (2, 68, 3)).astype(np.float32))  # the rest's end
    assert np.array_equal(x, long.long_sequence(face, segments, 2, **kwargs))
    assert not np.allclose(x, long.long_sequence(face, segments, 2, seed=1, **kwargs))


def test_a_text_schedule_is_guided_by_the_text_head_on_its_data(face, text_head, merged_denoiser):
    segments = long.read_schedule('"a broad grin":1.5s, neutral:1s, high_smile:1s')
    kwargs = dict(steps=3, denoiser=merged_denoiser, text_head=text_head, progress=False)
    x = long.long_sequence(face, segments, 2, **kwargs)
    assert x.shape == (2, 105, 68, 3) and np.isfinite(x).all()
    assert np.array_equal(x[:, 0], np.broadcast_to(face, (2, 68, 3)).astype(np.float32))
    assert np.array_equal(x, long.long_sequence(face, segments, 2, **kwargs))
    # the texts steer: with a larger rate the text segments change, the rest's anchor does not
    other = long.long_sequence(face, segments, 2, text_lr=1.0, **kwargs)
    assert not np.allclose(x[:, :45], other[:, :45])
    assert np.array_equal(x[:, 74], other[:, 74])  # the rest's end, anchored
    handshake = long.long_sequence(face, segments, 2, join="handshake", **kwargs)
    assert handshake.shape == x.shape and np.isfinite(handshake).all()


def test_the_learned_join_reads_the_known_frames_with_the_join_denoiser(face, guide, denoiser):
    segments = long.parse_schedule("mouth_open:1.5s, neutral:1s, free:1s", LABELS)
    kwargs = dict(steps=3, guide=guide, progress=False)
    x = long.long_sequence(face, segments, 2, join="learned", **kwargs)
    assert x.shape == (2, 105, 68, 3) and np.isfinite(x).all()
    assert np.array_equal(x[:, 0], np.broadcast_to(face, (2, 68, 3)).astype(np.float32))
    assert np.array_equal(x[:, 74], np.broadcast_to(face, (2, 68, 3)).astype(np.float32))  # the rest's end
    # the known frames it reads change the windows that know them (the same network, told them or not)
    join_denoiser = tasks.load_denoiser("denoiser_coma_join")
    filled = long.long_sequence(face, segments, 2, join="fill", denoiser=join_denoiser, **kwargs)
    assert not np.allclose(x[:, 40:], filled[:, 40:])
    with pytest.raises(ValueError, match="join 'learned' needs a join denoiser"):
        long.long_sequence(face, segments, 1, join="learned", denoiser=denoiser, **kwargs)
    with pytest.raises(ValueError, match="none is shipped .* use join fill"):
        long.long_sequence(face, long.read_schedule("'a broad grin':1.5s"), 1, join="learned", progress=False)


def test_labels_and_texts_need_their_own_guides(face, guide, text_head, merged_denoiser, denoiser):
    texts = long.read_schedule('"a broad grin":1.5s')
    with pytest.raises(ValueError, match="guided by the text head"):
        long.long_sequence(face, texts, 1, steps=2, guide=guide, denoiser=merged_denoiser, progress=False)
    with pytest.raises(ValueError, match="a text head guides a schedule with a text"):
        long.long_sequence(face, long.free_schedule(1), 1, steps=2, text_head=text_head, denoiser=denoiser,
                           progress=False)
    with pytest.raises(ValueError, match="unknown label 'smile' for the text head's data"):
        long.long_sequence(face, texts + [long.Segment("smile", 30)], 1, steps=2, text_head=text_head,
                           denoiser=merged_denoiser, progress=False)


def test_a_window_continues_the_frames_it_knows(face, guide, denoiser):
    # the first frames of window 2 are conditioned on the end of window 1: fill joins them more smoothly than
    # independent windows joined end to end
    segments = long.parse_schedule("free:4s", LABELS)
    kwargs = dict(steps=20, denoiser=denoiser, guide=guide, progress=False)
    windows = long.plan_windows(segments, 40, 10)
    joins = long.join_frames(windows)
    step = {}
    for join in ("fill", "concat"):
        x = long.long_sequence(face, segments, 4, join=join, **kwargs)
        step[join] = np.linalg.norm(x[:, joins] - x[:, joins - 1], axis=-1).mean()
    assert step["fill"] < 0.5 * step["concat"]


@pytest.mark.parametrize("join", ["replace", "handshake", "concat"])
def test_every_join_makes_the_schedule_from_the_face(join, face, guide, denoiser):
    segments = long.parse_schedule("mouth_open:1.5s, neutral:0.5s", LABELS)
    x = long.long_sequence(face, segments, 2, join=join, steps=3, denoiser=denoiser, guide=guide, progress=False)
    assert x.shape == (2, 60, 68, 3) and np.isfinite(x).all()
    assert np.array_equal(x[:, 0], np.broadcast_to(face, (2, 68, 3)).astype(np.float32))
    assert np.array_equal(x[:, -1], np.broadcast_to(face, (2, 68, 3)).astype(np.float32))


def test_the_handshake_is_not_a_stream(face, guide, denoiser):
    with pytest.raises(ValueError, match="handshake generates every window at once"):
        next(long.stream(face, long.free_schedule(2), 1, join="handshake", denoiser=denoiser, guide=guide))


def test_a_stream_is_written_window_by_window(face, guide, denoiser):
    # the first window comes before the others are made: memory is that of one window
    made = long.stream(face, long.free_schedule(60), 1, steps=2, denoiser=denoiser, guide=guide, progress=False)
    assert next(made).shape == (1, 40, 68, 3)


def test_the_frame_rate_written_keeps_the_duration():
    x = np.random.default_rng(0).normal(size=(1, 61, 68, 3))
    assert long.resample_fps(x, 15).shape == (1, 31, 68, 3)
    assert long.resample_fps(x, 60).shape == (1, 121, 68, 3)
    np.testing.assert_allclose(long.resample_fps(x, 15)[:, 1], x[:, 2], atol=1e-5)
    with pytest.raises(ValueError, match="fps must be an integer in 10..60"):
        tasks.Long(fps=120)
    with pytest.raises(ValueError, match="transition must be"):
        tasks.Long(transition=21)
    with pytest.raises(ValueError, match="join must be one of"):
        tasks.Long(join="blend")
