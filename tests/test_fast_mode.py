"""The test command must run the notebooks in fast mode: a broken fast mode must not pass silently."""
import os

from facelib.config import fast_mode


def test_test_run_sets_facelib_fast():
    assert os.environ.get("FACELIB_FAST") == "1", (
        "run the tests with the README's command (`make test`), which sets FACELIB_FAST=1")
    assert fast_mode()


def test_fast_mode_parsing(monkeypatch):
    for value, expected in (("1", True), ("true", True), ("0", False), ("", False), ("no", False)):
        monkeypatch.setenv("FACELIB_FAST", value)
        assert fast_mode() is expected
