"""Bad input at every public entry point, generated rather than hand-picked (issue 42 item 8).

Hypothesis drives the command line (``python -m facelib sample TASK``) and the task functions with NaN,
infinities, wrong shapes and dtypes, empty and truncated files, out-of-range frames, labels, AUs and steps.
Each must get a clear error: on the command line argparse's exit 2 with a message on stderr that names the
problem, and no output file; from a task function a ValueError or TypeError with a message (never an
IndexError, a RuntimeError or a silent result).  Every chain is tiny (2 steps, 1 sequence), so that an input
wrongly accepted fails the test quickly instead of sampling.  ``pytest -s`` prints how many cases ran.
"""
import collections
import contextlib
import functools
import io
import json
import re
import tempfile
from pathlib import Path

import numpy as np
import pytest
import hypothesis
from hypothesis import HealthCheck, given, settings, strategies as st
from hypothesis.errors import InvalidArgument
from hypothesis.extra import numpy as hnp

from facelib import config, data, tasks
from facelib.__main__ import main
from facelib.face.aus import AU_NAMES

CASES = collections.Counter()  # generated cases run, per test
_TEST = data.load_dataset("coma", "test")
LABELS = _TEST.label_names
VALID = {"seq": np.asarray(_TEST.landmarks[0], dtype=np.float64), "neutral": _TEST.subject_neutrals()[0]}
SETTINGS = dict(deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow,
                                                                        HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module", autouse=True)
def report():
    yield
    print(f"\nbad-input cases generated and run: {dict(CASES)}; total {sum(CASES.values())}")


@pytest.fixture(scope="module")
def files():
    """A folder with valid inputs of every task: the tests spoil one input or option at a time."""
    with tempfile.TemporaryDirectory() as root:
        root = Path(root)
        np.savez(root / "seq.npz", landmarks=VALID["seq"])
        np.savez(root / "neutral.npz", neutral=VALID["neutral"])
        (root / "keys.json").write_text(json.dumps(
            {"keys": [{"frame": 20, "landmark": 54, "displacement": [0, 3, 0]}],
             "neutral": VALID["neutral"].tolist()}))
        yield root


@functools.lru_cache(maxsize=None)
def shipped_denoiser():
    return tasks.load_denoiser("denoiser_coma")


def note(text):
    """hypothesis' note inside a generated case, nothing outside one."""
    with contextlib.suppress(InvalidArgument):
        hypothesis.note(text)


def good_args(task, files):
    """Valid tiny arguments of each task (2 steps, 1 sequence)."""
    return {"unconditional": [], "label": ["--label=high_smile"], "text": ["--text=high smile"],
            "decoder": ["--text=high smile"],
            "fill": [f"--input={files / 'seq.npz'}", "--known=0:10"],
            "geometry": ["--label=mouth_open", f"--neutral={files / 'neutral.npz'}"],
            "edit": ["--label=high_smile", f"--input={files / 'seq.npz'}"],
            "au": ["--curve=AU12:0.5"], "keyframes": [f"--constraints={files / 'keys.json'}"],
            "long": ["--schedule=high_smile:0.5s", f"--neutral={files / 'neutral.npz'}"]}[task]


TAKES_N = ("unconditional", "label", "text", "decoder", "geometry", "au", "keyframes", "long")


def refused(argv, out, pattern):
    """``main(argv + --out out)`` exits 2 (argparse's error) with a message matching ``pattern`` (a regular
    expression, case-insensitive) and no traceback on stderr, and writes nothing."""
    err = io.StringIO()
    note(f"argv: {argv}")
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        with pytest.raises(SystemExit) as exit_:
            main([*argv, f"--out={out}"])
    message = err.getvalue()
    note(f"stderr: {message[-600:]}")
    assert exit_.value.code == 2, message
    assert "error:" in message and "Traceback" not in message
    assert re.search(pattern, message.split("error:", 1)[1], re.IGNORECASE), message
    written = [p for p in (out, out.with_name(out.name + ".npz")) if p.exists()]
    assert not written, f"{written} written despite the error"


def cli_case(files, task, *extra, n="1"):
    return ["sample", task, *good_args(task, files), "--steps=2", *([f"--n={n}"] if task in TAKES_N else []), *extra]


def out_path(files):
    return Path(tempfile.mkdtemp(dir=files)) / "out.npz"


# ------------------------------------------------------------------------------------------ bad option values

not_int = st.text(min_size=0, max_size=8).filter(lambda s: re.fullmatch(r"\s*[+-]?\d+\s*", s) is None
                                                 and s.strip().lower() != "none")
not_float = st.text(max_size=8).filter(lambda s: re.fullmatch(r"\s*[+-]?(\d+\.?\d*|\.\d+)(e[+-]?\d+)?\s*|\s*[+-]?"
                                                              r"(inf|infinity|nan)\s*", s, re.I) is None
                                       and s.strip().lower() != "none")
bad_number = st.one_of(st.floats(max_value=-1e-9, allow_nan=False).map(repr),
                       st.floats(min_value=3.5e38, allow_infinity=False).map(repr),  # beyond float32
                       st.sampled_from(["nan", "inf", "-inf", "NaN", "Infinity"]), not_float)
# a Gaussian's sigma in frames, at most the window's length
bad_feather = st.one_of(st.floats(max_value=-1e-9, allow_nan=False).map(repr),
                        st.floats(min_value=401, allow_nan=False).map(repr),  # > the longest sequence
                        st.sampled_from(["nan", "inf", "-inf"]), not_float)
steps = st.one_of(st.integers(max_value=0).map(str), st.integers(min_value=2001, max_value=10 ** 30).map(str),
                  not_int, st.floats(allow_nan=True).filter(lambda v: v != int(v) if np.isfinite(v) else True)
                  .map(repr))
eta = st.one_of(st.floats(max_value=-1e-9).map(repr), st.floats(min_value=1 + 1e-9).map(repr),
                st.sampled_from(["nan", "-inf", "inf"]), not_float)
unknown_name = st.text(min_size=0, max_size=12)


def options(task):
    """(option, bad value, what the message must name) for ``task``."""
    common = [("--steps", steps, r"steps"),
              ("--seed", st.one_of(not_int, st.integers(max_value=-1).map(str),
                                   st.integers(min_value=2 ** 32, max_value=10 ** 30).map(str)), r"seed"),
              ("--length", st.one_of(st.integers(max_value=1).map(str), st.integers(min_value=401).map(str), not_int),
               r"num[_-]frames|length"),
              ("--dataset", unknown_name.filter(lambda s: s not in data.DATASET_NAMES), r"dataset"),
              ("--sampler", unknown_name.filter(lambda s: s not in ("ddpm", "ddim")), r"sampler"),
              ("--variance", unknown_name.filter(lambda s: s not in ("beta", "posterior", "none")), r"variance"),
              ("--device", unknown_name.filter(lambda s: s not in ("cpu", "cuda")), r"device"),
              ("--checkpoint", st.from_regex(r"no_such_checkpoint_[a-z0-9]{1,8}", fullmatch=True), r"checkpoint")]
    if task in TAKES_N:
        common.append(("--n", st.one_of(st.integers(max_value=0).map(str), st.integers(min_value=10 ** 6).map(str),
                                        not_int), r"--n\b"))
    if task in ("fill", "edit", "long"):  # their length is the input's (long: windows of the model's)
        common.remove(next(o for o in common if o[0] == "--length"))
    per_task = {
        "label": [("--label", unknown_name.filter(lambda s: s not in LABELS), r"label"),
                  ("--lr", bad_number, r"\blr\b"), ("--guidance-weight", bad_number, r"guidance[ _-]weight"),
                  ("--scale", bad_number, r"scale")],
        "text": [("--lr", bad_number, r"\blr\b"), ("--particles", st.integers(max_value=0).map(str), r"particles"),
                 ("--max-time", bad_number, r"max[_-]time")],
        "decoder": [("--start", st.one_of(st.integers(max_value=0), st.integers(min_value=2001)).map(str),
                     r"start")],
        "fill": [("--known", st.one_of(
            st.sampled_from(["", ",", "0:40", "0:0", "5:2", "-1:3", "0:41", "40", "a:b", "1:2:3", "0:10,,"]),
            st.tuples(st.integers(-50, 100), st.integers(-50, 100)).filter(lambda r: not 0 <= r[0] < r[1] < 40)
            .map(lambda r: f"{r[0]}:{r[1]}"), not_int.filter(lambda s: ":" not in s)), r"frame|known"),
                 ("--reconstruction-scale", bad_number, r"reconstruction"),
                 ("--resample", st.one_of(st.integers(max_value=0).map(str), not_int), r"resample")],
        "geometry": [("--label", unknown_name.filter(lambda s: s.split()[:1] not in ([y] for y in LABELS)),
                      r"label|order"), ("--lr", bad_number, r"\blr\b"),
                     ("--passes", st.integers(max_value=0).map(str), r"passes"),
                     ("--renoise-step", st.one_of(st.integers(max_value=0), st.integers(min_value=3)).map(str),
                      r"renoise[_-]step")],
        "edit": [("--label", unknown_name.filter(lambda s: s not in LABELS), r"label"),
                 ("--keep", st.sampled_from(["0:40", "", "x", "0:50", "3:3", ","]), r"keep|frame"),
                 ("--refine", st.integers(max_value=-1).map(str), r"refine")],
        "au": [("--curve", st.one_of(st.sampled_from(
            ["AU12", "AU12:", "AU12:nan", "AU12:inf", "AU12:-inf@0", "AU12:0.5@", "AU12:0.5@1.5", "AU12:0.5@40",
             "AU12:0.5@-1", "AU12:0.1@3,0.2@3", "AU99:0.5", ":0.5", "AU12:0.5:1", "AU12:5", "AU12:0.5@0,"]),
            st.builds(lambda name, v: f"{name}:{v}", st.sampled_from(AU_NAMES), st.floats(min_value=3)
                      | st.floats(max_value=-3)),
            st.builds(lambda v, f: f"AU26:{v}@{f}", st.floats(0, 0.5), st.integers(40) | st.integers(max_value=-1)),
            st.text(max_size=10).filter(lambda s: s.count(":") != 1)), r"AU|curve"),
               ("--tolerance", bad_number, r"tolerance"), ("--au-weight", bad_number, r"AU score|au[_-]weight")],
        "long": [("--schedule", st.one_of(st.sampled_from(
            ["", " ", ",", "high_smile", "high_smile:", ":2s", "smile:2s", "high_smile:0.1s", "high_smile:-1s",
             "high_smile:2m", "high_smile:4000s", "high_smile:2s,,neutral:1s", "high_smile:2s; neutral:1s",
             "neutral:1s, high_smile:nan", "free:3601s", "high_smile:1s:2s", '"":2s', '" ":2s', '"a grin:2s',
             '"a grin":0.1s', '"a grin" 2s', "'a grin':2s, smile:1s", "'a grin':2s,", '"a grin":4000s']),
            st.text(max_size=12).filter(lambda s: ":" not in s)), r"schedule|segment|expression"),
                 ("--seconds", st.one_of(st.sampled_from(["0", "-1", "3601", "nan", "inf", "0.1"]), not_float),
                  r"seconds|segment"),
                 ("--fps", st.one_of(st.integers(max_value=9), st.integers(min_value=61)).map(str), r"fps"),
                 ("--transition", st.one_of(st.integers(max_value=0), st.integers(min_value=21)).map(str),
                  r"transition"),
                 ("--join", unknown_name.filter(lambda s: s not in config.JOIN_METHODS),
                  r"join"), ("--feather", bad_feather, r"feather"),
                 ("--text-lr", bad_number, r"text[_-]lr"),
                 ("--text-opening", unknown_name.filter(lambda s: s not in ("N2E", "E2N", "none")),
                  r"text[_-]opening"),
                 ("--text-guidance-weight", bad_number, r"text[ _-]guidance[ _-]weight")],
        "keyframes": [("--method", unknown_name.filter(lambda s: s not in ("replace", "reconstruction", "both")),
                       r"method"), ("--reconstruction-scale", bad_number, r"reconstruction"),
                      ("--feather", bad_feather, r"feather")],
    }
    return common + per_task.get(task, [])


TASKS = ("unconditional", "label", "text", "decoder", "fill", "geometry", "edit", "au", "keyframes", "long")


@st.composite
def bad_option(draw):
    task = draw(st.sampled_from(TASKS))
    option, values, pattern = draw(st.sampled_from(options(task)))
    return task, option, draw(values), pattern


@settings(max_examples=500, **SETTINGS)
@given(case=bad_option())
def test_cli_refuses_bad_options(files, case):
    task, option, value, pattern = case
    CASES["cli options"] += 1
    argv = cli_case(files, task)
    if option in ("--steps", "--n"):
        argv = [a for a in argv if not a.startswith(option + "=")]
    refused([*argv, f"{option}={value}"], out_path(files), pattern)


@settings(max_examples=30, **SETTINGS)
@given(task=st.sampled_from(TASKS), name=st.sampled_from(["out", "out.npy", "out.npz.txt", "missing/out.npz", "."]))
def test_cli_refuses_bad_out(files, task, name):
    """--out must name an .npz file in an existing folder (np.savez would add '.npz' to another name)."""
    CASES["cli --out"] += 1
    folder = Path(tempfile.mkdtemp(dir=files))
    out = folder / name
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        with pytest.raises(SystemExit) as exit_:
            main([*cli_case(files, task), f"--out={out}"])
    assert exit_.value.code == 2 and "--out must name an .npz file" in err.getvalue()
    assert sorted(p.name for p in folder.iterdir()) == []


# ------------------------------------------------------------------------------------------ bad input files

VALID_SEQ_SHAPES = lambda s: len(s) in (3, 4) and s[-2:] == (68, 3) and 2 <= s[-3] <= 400 and 0 not in s
small_shapes = hnp.array_shapes(min_dims=0, max_dims=5, min_side=0, max_side=5) | st.sampled_from(
    [(40, 67, 3), (40, 68, 2), (0, 68, 3), (40, 0, 3), (68, 3), (1, 68, 3), (2, 68, 3), (1, 40, 68, 3, 1),
     (40, 3, 68), (1, 68), (401, 68, 3)])


@st.composite
def bad_npz(draw, key, valid, finite_frames=None):
    """(bytes of a bad .npz or other file, what the message must name).  ``valid``: the valid array;
    ``finite_frames``: the frames whose values are read (the others may hold anything)."""
    kind = draw(st.sampled_from(["nan", "huge", "shape", "dtype", "object", "missing", "empty", "truncated",
                                 "garbage", "nested"]))
    buffer, pattern = io.BytesIO(), None
    if kind in ("nan", "huge"):
        x = np.array(valid, dtype=np.float64)
        region = x if finite_frames is None else x[finite_frames]
        index = draw(st.tuples(*(st.integers(0, s - 1) for s in region.shape)))
        region[index] = draw(st.sampled_from([np.nan, np.inf, -np.inf]) if kind == "nan" else
                             st.floats(min_value=1e5, max_value=1e308) | st.floats(max_value=-1e5, min_value=-1e308))
        np.savez(buffer, **{key: x})
        pattern = r"NaN|infinite|finite|mm"
    elif kind == "shape":
        shape = draw(small_shapes.filter(lambda s: not (VALID_SEQ_SHAPES(s) if valid.ndim == 3 else
                                                        s in ((68, 3), (1, 68, 3)))))
        x = draw(hnp.arrays(np.float64, shape, elements=st.floats(-100, 100)))
        np.savez(buffer, **{key: x})
        pattern = r"shape|\(F, 68, 3\)|\(68, 3\)|num_frames|frames"
    elif kind == "dtype":
        dtype = draw(st.sampled_from(["U3", "S3", "bool", "complex128", "datetime64[s]", "V4"]))
        x = np.zeros(valid.shape, dtype=dtype)
        np.savez(buffer, **{key: x})
        pattern = r"number|dtype|cannot read"
    elif kind == "object":
        np.savez(buffer, **{key: np.array([None, 1.0, "a"], dtype=object)})
        pattern = r"cannot read|number|dtype"
    elif kind == "missing":
        other = draw(st.sampled_from(["x", "arr_0", "Landmarks", "neutrals", "landmark"]))
        np.savez(buffer, **{other: valid})
        pattern = r"has no"
    elif kind == "nested":  # one coordinate per landmark instead of three
        np.savez(buffer, **{key: valid[..., :1]})
        pattern = r"shape|\(68, 3\)|\(F, 68, 3\)"
    if kind in ("empty", "truncated", "garbage"):
        np.savez(buffer, **{key: valid})
        raw = buffer.getvalue()
        content = (b"" if kind == "empty" else raw[:draw(st.integers(0, len(raw) - 1))] if kind == "truncated"
                   else draw(st.binary(max_size=64)))
        return kind, content, r"cannot read"
    return kind, buffer.getvalue(), pattern


@st.composite
def bad_input_file(draw):
    """(task, option, valid array) with a bad file for its --input or --neutral."""
    seq, neutral = VALID["seq"], VALID["neutral"]
    task, option = draw(st.sampled_from([("fill", "--input"), ("edit", "--input"), ("geometry", "--neutral"),
                                         ("au", "--neutral"), ("long", "--neutral")]))
    key = draw(st.sampled_from(["neutral", "landmarks"])) if option == "--neutral" else "landmarks"
    if option == "--input":
        kind, content, pattern = draw(bad_npz(key, seq, finite_frames=slice(0, 10) if task == "fill" else None))
    else:
        kind, content, pattern = draw(bad_npz(key, neutral))
    return task, option, kind, content, pattern


@settings(max_examples=350, **SETTINGS)
@given(case=bad_input_file(), where=st.sampled_from(["file", "directory", "absent"]))
def test_cli_refuses_bad_input_files(files, case, where):
    task, option, kind, content, pattern = case
    CASES["cli input files"] += 1
    folder = Path(tempfile.mkdtemp(dir=files))
    path = folder / "input.npz"
    if where == "file" or kind not in ("empty", "garbage"):
        path.write_bytes(content)
    elif where == "directory":
        path.mkdir()  # a folder where the file should be
    argv = [a for a in cli_case(files, task) if not a.startswith(option + "=")]
    refused([*argv, f"{option}={path}"], folder / "out.npz", pattern if path.is_file() else r"cannot read|no such")


# ------------------------------------------------------------------------------------------ bad constraints

json_value = st.recursive(st.none() | st.booleans() | st.integers(-10 ** 6, 10 ** 6) | st.floats() | st.text(max_size=5),
                          lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=8), kids,
                                                                                    max_size=3), max_leaves=8)
GOOD_KEY = {"frame": 20, "landmark": 54, "position": [0.0, 1.0, 2.0]}


@st.composite
def bad_key(draw):
    """A key with one field spoiled."""
    key = dict(GOOD_KEY)
    spoil = draw(st.sampled_from(["frame", "landmark", "position", "missing", "both", "extra_type", "not_dict"]))
    if spoil == "frame":
        key["frame"] = draw(st.integers(max_value=-1) | st.integers(min_value=40) | st.booleans()
                            | st.floats() | st.text(max_size=4) | st.none() | st.lists(st.integers(0, 5), max_size=2))
    elif spoil == "landmark":
        key["landmark"] = draw(st.integers(max_value=-1) | st.integers(min_value=68) | st.booleans()
                               | st.floats() | st.text(max_size=4) | st.none())
    elif spoil == "position":
        key["position"] = draw(
            st.lists(st.floats(allow_nan=False, allow_infinity=False, min_value=-100, max_value=100), max_size=6)
            .filter(lambda v: len(v) != 3)
            | st.lists(st.sampled_from([float("nan"), float("inf"), 1e300, "a", None, [1.0], {"x": 1}, True]),
                       min_size=3, max_size=3).filter(lambda v: not all(isinstance(u, bool) for u in v))
            | st.text(max_size=4) | st.none() | st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))
    elif spoil == "missing":
        del key[draw(st.sampled_from(["frame", "landmark", "position"]))]
    elif spoil == "both":
        key["displacement"] = [0, 1, 0]
    elif spoil == "extra_type":
        key = {"frame": 20, "landmark": 54, "displacement": [0, 1, 0]}  # a displacement without a neutral face
    else:
        return draw(json_value.filter(lambda v: not isinstance(v, dict)))
    return key


@st.composite
def bad_constraints(draw):
    """Text (or bytes) of a bad constraints file."""
    kind = draw(st.sampled_from(["key", "keys", "neutral", "top", "empty", "truncated", "bytes"]))
    good = {"keys": [GOOD_KEY]}
    if kind == "key":
        spec = {"keys": [GOOD_KEY, draw(bad_key())] if draw(st.booleans()) else [draw(bad_key())]}
    elif kind == "keys":
        spec = {"keys": draw(json_value.filter(lambda v: not isinstance(v, list) or not v))}
    elif kind == "neutral":
        spec = {**good, "neutral": draw(  # null: no neutral face, which is allowed
            json_value.filter(lambda v: v is not None) | st.lists(st.lists(st.floats(-100, 100), min_size=3, max_size=3), max_size=70)
            .filter(lambda v: len(v) != 68) | st.just([[float("nan")] * 3] * 68)
            | st.just([[1e30] * 3] * 68) | st.just([["a"] * 3] * 68))}
    elif kind == "top":
        spec = draw(json_value.filter(lambda v: not isinstance(v, dict) or "keys" not in v)
                    | st.just({**good, "extra": 1}))
    else:
        text = json.dumps(good)
        if kind == "empty":
            return b""
        if kind == "truncated":
            return text[:draw(st.integers(0, len(text) - 1))].encode()
        return draw(st.binary(min_size=1, max_size=16).filter(lambda b: _not_json(b)))
    return json.dumps(spec).encode()


def _not_json(raw):
    try:
        json.loads(raw.decode())
    except (UnicodeDecodeError, json.JSONDecodeError):
        return True
    return False


@settings(max_examples=350, **SETTINGS)
@given(content=bad_constraints())
def test_cli_refuses_bad_constraints(files, content):
    CASES["cli constraints"] += 1
    folder = Path(tempfile.mkdtemp(dir=files))
    path = folder / "keys.json"
    path.write_bytes(content)
    note(f"constraints: {content[:300]!r}")
    argv = [a for a in cli_case(files, "keyframes") if not a.startswith("--constraints=")]
    refused([*argv, f"--constraints={path}"], folder / "out.npz", r"key|neutral|json|constraints|frame|landmark")


def test_cli_refuses_unreadable_constraints(files):
    """A folder or an absent file where the constraints should be: a message, exit 2."""
    for path in (files, files / "absent.json"):
        refused([*[a for a in cli_case(files, "keyframes") if not a.startswith("--constraints=")],
                 f"--constraints={path}"], out_path(files), r"cannot read|no such|directory")


# ------------------------------------------------------------------------------------------ the task functions

def rejected(call):
    """``call()`` raises a ValueError or TypeError with a message (not an IndexError, a RuntimeError, a result)."""
    try:
        result = call()
    except (ValueError, TypeError) as e:
        assert not isinstance(e, (IndexError, KeyError)), repr(e)
        assert str(e).strip(), f"{type(e).__name__} without a message"
        note(f"{type(e).__name__}: {e}")
        return e
    raise AssertionError(f"accepted: returned {type(result).__name__} {np.shape(result)}")


bad_n = (st.integers(max_value=0) | st.integers(min_value=10 ** 6) | st.floats() | st.text(max_size=3) | st.none()
         | st.booleans() | st.just(np.float64(2.0)))


def spoiled(valid, finite_frames=None):
    """Bad landmark arrays built from a valid one: NaN/inf (in the frames read), wrong ndim or shape,
    text/object/complex/bool dtypes, empty arrays, ragged lists, non-arrays."""
    valid = np.asarray(valid, dtype=np.float64)

    def poke(args):
        value, index = args
        x = valid.copy()
        region = x if finite_frames is None else x[finite_frames]
        region[tuple(i % s for i, s in zip(index, region.shape))] = value
        return x

    nan = st.tuples(st.sampled_from([np.nan, np.inf, -np.inf, 1e300, -1e30]),
                    st.tuples(*(st.integers(0, 10 ** 6) for _ in range(valid.ndim)))).map(poke)
    shape = small_shapes.filter(lambda s: not (VALID_SEQ_SHAPES(s) if valid.ndim == 3 else
                                               s in ((68, 3), (1, 68, 3)))) \
        .flatmap(lambda s: hnp.arrays(np.float64, s, elements=st.floats(-100, 100)))
    dtype = st.sampled_from(["U3", "O", "complex128", "bool", "S2"]).map(lambda d: np.zeros(valid.shape, dtype=d))
    other = st.sampled_from([None, "landmarks", [], [[1.0, 2.0], [3.0]], {"a": 1}, 3.0,
                             [[[1.0] * 3] * 68, [[1.0] * 2] * 68]])
    return nan | shape | dtype | other


@st.composite
def task_call(draw, seq, neutral, denoiser):
    """(name, a call of a task function with one bad argument)."""
    tiny = dict(steps=2, progress=False, denoiser=denoiser)
    which = draw(st.sampled_from(["fill", "fill_known", "geometry", "geometry_label", "keyframes", "keyframes_neutral",
                                  "au", "au_neutral", "edit", "edit_label", "edit_keep", "label", "unconditional",
                                  "n", "settings"]))
    if which == "fill":
        x = draw(spoiled(seq, finite_frames=slice(0, 10)))
        return which, lambda: tasks.fill(x, np.arange(40) < 10, **tiny)
    if which == "fill_known":
        known = draw(st.one_of(
            st.lists(st.booleans(), min_size=0, max_size=60).filter(lambda v: len(v) != 40 or all(v) or not any(v)),
            hnp.arrays(np.float64, 40, elements=st.sampled_from([0.5, 2.0, -1.0, np.nan])),
            st.sampled_from(["0:10", None, 3, [[True] * 40], np.zeros((2, 3, 40), bool)])))
        return which, lambda: tasks.fill(seq, known, **tiny)
    if which == "geometry":
        x = draw(spoiled(neutral))
        return which, lambda: tasks.geometry_adaptive(x, "mouth_open", 1, **tiny)
    if which == "geometry_label":
        label = draw(unknown_name.filter(lambda s: s.split()[:1] not in ([y] for y in LABELS))
                     | st.none() | st.integers() | st.lists(st.sampled_from(LABELS), min_size=2, max_size=3))
        return which, lambda: tasks.geometry_adaptive(neutral, label, 1, **tiny)
    if which in ("keyframes", "keyframes_neutral"):
        keys = draw(st.lists(bad_key(), min_size=1, max_size=2) | json_value.filter(
            lambda v: not isinstance(v, list) or not v)) if which == "keyframes" else [GOOD_KEY]
        face = None if which == "keyframes" else draw(spoiled(neutral).filter(lambda v: v is not None))
        note(f"keys {keys!r}, neutral {type(face).__name__}")
        return which, lambda: tasks.keyframes(keys, 1, face, **tiny)
    if which in ("au", "au_neutral"):
        curves = draw(st.lists(st.sampled_from(["AU12:nan", "AU12:0.5@40", "AU99:0", "AU12", "AU12:9", "AU1:0@-1"])
                               | st.text(max_size=8), min_size=1, max_size=2) | st.sampled_from(
            ["AU12:0.5", [], None, [["AU12:0.5"], ["AU26:0"]], [1, 2]])) if which == "au" else ["AU12:0.5"]
        face = None if which == "au" else draw(spoiled(neutral).filter(lambda v: v is not None))
        return which, lambda: tasks.au_control(curves, 1, face, **tiny)
    if which == "edit":
        x = draw(spoiled(seq))
        return which, lambda: tasks.edit(x, "high_smile", **tiny)
    if which == "edit_label":
        label = draw(unknown_name.filter(lambda s: s not in LABELS) | st.none() | st.integers()
                     | st.lists(st.sampled_from(LABELS), min_size=2, max_size=3))
        return which, lambda: tasks.edit(seq, label, **tiny)
    if which == "edit_keep":
        keep = draw(st.sampled_from(["0:40", "", "a", "0:99", np.ones(40, bool), np.zeros(7, bool), 3,
                                     np.full(40, 0.5)]))
        return which, lambda: tasks.edit(seq, "high_smile", keep=keep, **tiny)
    if which == "label":
        label = draw(unknown_name.filter(lambda s: s not in LABELS) | st.none() | st.integers()
                     | st.lists(st.sampled_from(LABELS), min_size=2, max_size=3))
        return which, lambda: tasks.label_control(label, 1, **tiny)
    if which == "unconditional":
        return which, lambda: tasks.unconditional(draw(bad_n), **tiny)
    if which == "n":
        n = draw(bad_n)
        call = draw(st.sampled_from([
            lambda: tasks.label_control("high_smile", n, **tiny),
            lambda: tasks.geometry_adaptive(neutral, "mouth_open", n, **tiny),
            lambda: tasks.keyframes([GOOD_KEY], n, None, **tiny),
            lambda: tasks.au_control(["AU12:0.5"], n, None, **tiny)]))
        return which, call
    field, value = draw(st.sampled_from([
        ("steps", st.integers(max_value=0) | st.integers(min_value=2001, max_value=10 ** 30) | st.floats()
         | st.text(max_size=3) | st.booleans()),
        ("num_frames", st.integers(max_value=1) | st.integers(min_value=401) | st.floats() | st.none()),
        ("seed", st.floats() | st.text(max_size=3) | st.none() | st.integers(max_value=-1)
         | st.integers(min_value=2 ** 32)),
        ("eta", st.floats().filter(lambda v: not 0 <= v <= 1) | st.text(max_size=3)),
        ("variance", st.text(max_size=5).filter(lambda s: s not in ("beta", "posterior"))),
        ("sampler", st.text(max_size=5).filter(lambda s: s not in ("ddpm", "ddim"))),
        ("no_such_setting", st.integers())]))
    value = draw(value)
    overrides = {**tiny, field: value, **({"sampler": "ddim"} if field == "eta" else {})}
    task = draw(st.sampled_from(["unconditional", "label", "keyframes"]))
    call = {"unconditional": lambda: tasks.unconditional(1, **overrides),
            "label": lambda: tasks.label_control("high_smile", 1, **overrides),
            "keyframes": lambda: tasks.keyframes([GOOD_KEY], 1, None, **overrides)}[task]
    return f"settings.{field}", call


@settings(max_examples=500, **SETTINGS)
@given(data_=st.data())
def test_task_functions_refuse_bad_input(data_):
    name, call = data_.draw(task_call(VALID["seq"], VALID["neutral"], shipped_denoiser()))
    CASES["task functions"] += 1
    note(name)
    rejected(call)
