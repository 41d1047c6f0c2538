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
