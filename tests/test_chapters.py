"""`make chapter N=..` finds chapters by number or name and refuses anything else, listing them."""
import subprocess
import sys

import pytest

from facelib import chapters


def test_chapters_are_found_by_number_stem_or_name():
    known = chapters.chapters()
    assert list(known) == sorted(known) and "05" in known
    for name in ("5", "05", "05_label_control", "label_control", "05_label_control.ipynb"):
        assert chapters.find_chapter(name) == known["05"]


@pytest.mark.parametrize("bad", ["99", "", "intro", "label", "0"])
def test_an_unknown_chapter_lists_the_chapters(bad):
    with pytest.raises(ValueError, match=r"no chapter .*\n  01  01_face_world"):
        chapters.find_chapter(bad)


def test_the_command_line_refuses_an_unknown_chapter_with_the_list():
    r = subprocess.run([sys.executable, "-m", "facelib", "chapter", "99"], capture_output=True, text=True)
    assert r.returncode == 2 and "no chapter '99'" in r.stderr and "10  10_end_to_end" in r.stderr


def test_appendices_are_found_by_their_key():
    known = chapters.chapters()
    appendices = [k for k in known if k.startswith("a")]
    assert appendices and list(known)[-len(appendices):] == appendices
    assert chapters.find_chapter(appendices[0].upper()) == known[appendices[0]]


def test_a_recorded_run_time_reads_back_for_the_header(tmp_path, monkeypatch):
    monkeypatch.setattr(chapters, "TIMES_PATH", tmp_path / "run_times.json")
    path = chapters.find_chapter("05")
    assert chapters.run_time_text(path.stem, "book").startswith("not measured yet")
    chapters.record_time(path, "book", 200.0)
    chapters.record_time(path, "fast", 41.2, load=2.5)
    assert chapters.run_time_text(path.stem, "book").startswith("3.3 min (")
    assert chapters.run_time_text(path.stem, "fast").startswith("41 s (") and "shared with other jobs" in \
        chapters.run_time_text(path.stem, "fast")
    with pytest.raises(ValueError, match="mode must be one of"):
        chapters.run_time_text(path.stem, "slow")
