"""The book builds with notebook execution off and warnings as errors: a broken _toc.yml, link,
cross-reference or markdown fails the tests (notebook execution itself is tested by nbmake).

Numbers in the prose are glued from cells ({glue:text}`key`).  With execution off no cell runs, so
myst-nb cannot find any glued value and warns ([mystnb.glue]): the quick build suppresses that one
warning type and nothing else, and a static test checks instead that every glue role of a chapter
names a key that one of its own cells glues.  The full build (`make book`, -W) executes the cells
and fails on any glue key left unfilled."""
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parent.parent


def test_book_builds_without_warnings(tmp_path):
    cfg = yaml.safe_load((ROOT / "_config.yml").read_text())
    cfg["execute"]["execute_notebooks"] = "off"
    cfg["sphinx"]["config"]["suppress_warnings"] = ["mystnb.glue"]  # no cell ran: nothing is glued
    (tmp_path / "_config.yml").write_text(yaml.safe_dump(cfg))
    jb = Path(sys.executable).with_name("jupyter-book")
    cmd = [str(jb if jb.exists() else shutil.which("jupyter-book")), "build", str(ROOT), "--config",
           str(tmp_path / "_config.yml"), "--path-output", str(tmp_path / "out"), "-W", "--keep-going", "-q"]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    html = tmp_path / "out" / "_build" / "html"
    assert (html / "index.html").exists() and (html / "book" / "01_face_world.html").exists()


GLUE_ROLE = re.compile(r"\{glue(?::\w+)?\}`([^`:]+)(?::[^`]*)?`")
GLUE_CALL = re.compile(r"glue\(\s*(f?)[\"']([^\"'{]+)")
STRING = re.compile(r"[\"']([A-Za-z0-9_]+)[\"']")


def glued_keys(code):
    """Keys a chapter's cells glue: literal keys of glue(...) calls, the fixed prefix of keys glued
    through an f-string (returned as prefixes ending in '*'), and names bound to a glue call's
    variable (any string literal that a cell passes on, e.g. in a loop over (value, key) pairs)."""
    keys = {prefix + ("*" if f else "") for f, prefix in GLUE_CALL.findall(code)}
    if re.search(r"glue\(\s*[A-Za-z_]", code):
        keys |= set(STRING.findall(code))
    return keys


def is_glued(key, keys):
    return key in keys or any(k.endswith("*") and key.startswith(k[:-1]) for k in keys)


def test_every_glued_number_in_the_prose_is_glued_by_a_cell_of_the_same_chapter():
    for nb in sorted((ROOT / "book").glob("*.ipynb")):
        cells = json.loads(nb.read_text())["cells"]
        used = {k for c in cells if c["cell_type"] == "markdown" for k in GLUE_ROLE.findall("".join(c["source"]))}
        glued = set().union(*(glued_keys("".join(c["source"])) for c in cells if c["cell_type"] == "code"))
        missing = sorted(k for k in used if not is_glued(k, glued))
        assert not missing, f"{nb.name}: the prose uses glue keys no cell glues: {missing}"


def test_glue_patterns_find_roles_and_calls():
    assert GLUE_ROLE.findall("a {glue:text}`ch05_acc:.1f` b {glue}`ch05_fig`") == ["ch05_acc", "ch05_fig"]
    keys = glued_keys("glue('ch05_acc', 1.0, display=False)\nglue(f\"ch05_row_{k}\", v)")
    assert is_glued("ch05_acc", keys) and is_glued("ch05_row_ours", keys) and not is_glued("ch05_fid", keys)


def test_notebooks_are_committed_without_outputs_and_listed():
    toc = (ROOT / "_toc.yml").read_text()
    for nb in sorted((ROOT / "book").glob("*.ipynb")):
        cells = json.loads(nb.read_text())["cells"]
        assert not any(c.get("outputs") for c in cells if c["cell_type"] == "code"), f"{nb.name} has outputs"
        assert f"book/{nb.stem}" in toc, f"{nb.name} is not in _toc.yml"
        ids = [c.get("id") for c in cells]
        assert len(set(ids)) == len(ids), f"{nb.name} repeats a cell id (nbformat renames it at every run)"


def test_notebook_code_fits_the_page_column():
    """Code lines wider than about 88 characters wrap in the rendered book; keep them within 88
    (black -l 88 formats the code, comments and docstrings are wrapped by hand)."""
    for nb in sorted((ROOT / "book").glob("*.ipynb")):
        for cell in json.loads(nb.read_text())["cells"]:
            if cell["cell_type"] != "code":
                continue
            for line in "".join(cell["source"]).split("\n"):
                assert len(line) <= 88, f"{nb.name}, cell {cell.get('id')}: {len(line)} characters: {line}"


PAGES = sorted((ROOT / "book").glob("*.ipynb")) + [ROOT / "book" / "intro.md", ROOT / "book" / "errata.md"]
INLINE = re.compile(r"\{[a-z:]+\}`[^`]*`|`[^`]*`|\$\$.*?\$\$|\$[^$\n]*\$", re.S)
PLAIN_REFERENCE = re.compile(r"\b(?:[Cc]hapters? \d\d|[Aa]ppendix A1|[Ss]ections? \d+(?! of the paper))\b")
REF_ROLE = re.compile(r"\{ref\}`([^`<]*?)\s*<([^>]+)>`")
LABEL = re.compile(r"^\((ch\d\d|a1)(?:-s(\d+))?\)=\n(#+) (?:(\w+) · )?", re.M)


def page_texts(path):
    """The markdown of a book page (every markdown cell of a notebook)."""
    if path.suffix == ".md":
        return [path.read_text()]
    return ["".join(c["source"]) for c in json.loads(path.read_text())["cells"] if c["cell_type"] == "markdown"]


def prose(text):
    """A page's text without code blocks (a ``` fence that opens a directive, e.g. an admonition, keeps its
    text), roles, inline code and math."""
    kept, stack = [], []
    for line in text.split("\n"):
        fence = re.match(r"\s*```(.*)", line)
        if fence:
            info = fence.group(1).strip()
            if info or not stack:  # an opening fence: a directive ({name}) keeps its text, code does not
                stack.append("text" if info.startswith("{") else "code")
            else:
                stack.pop()
            continue
        if "code" not in stack:
            kept.append(line)
    return INLINE.sub(" ", " ".join(kept))


def plain_references(text):
    """Chapter, section and appendix numbers written as plain text (outside code, math and roles)."""
    return PLAIN_REFERENCE.findall(prose(text))


def test_plain_reference_pattern():
    assert plain_references("see chapter 04, section 3 and sections 5 and 6") == ["chapter 04", "section 3",
                                                                                   "sections 5"]
    assert plain_references("{ref}`chapter 04 <ch04>`, `section 3`, Section 4 of the paper, $section 2$") == []
    assert plain_references("```bash\npython x.py  # section 2\n```\n```{admonition} A\nsee section 3\n```") == [
        "section 3"]


def test_every_chapter_and_section_reference_is_a_link_to_the_right_label():
    """Every "chapter NN" or "section M" in the prose is a {ref} link (a build with -W fails on an unknown
    label); a link's text names the chapter and section its label stands on; every chapter title and numbered
    section carries its label (chNN, chNN-sM; a1 for the appendix)."""
    labels = {}
    for path in PAGES:
        for text in page_texts(path):
            for label, sec, hashes, num in LABEL.findall(text):
                labels[f"{label}-s{sec}" if sec else label] = (label, sec)
                on_heading = (hashes, num) == ("##", sec) if sec else (hashes, num.lower()) == ("#", label[-2:])
                assert on_heading, \
                    f"{path.name}: label {label}{'-s' + sec if sec else ''} is not on its heading"
    for path in PAGES:
        texts = page_texts(path)
        for text in texts:
            for heading in re.findall(r"^(# (?:\d\d|A1) · .*|## \d+ · .*)$", text, re.M):
                assert re.search(r"\)=\n" + re.escape(heading), text), f"{path.name}: no label on {heading!r}"
            found = plain_references(text)
            assert not found, f"{path.name}: plain-text references {found}; write them as {{ref}} links"
            for words, target in REF_ROLE.findall(text):
                chapter, sec = labels.get(target, (None, None))
                assert chapter, f"{path.name}: {{ref}} to an unknown label {target!r}"
                named = re.search(r"(?:[Cc]hapter|[Aa]ppendix) (\d\d|A1)", words)
                if named:
                    assert chapter in (f"ch{named.group(1)}", named.group(1).lower()), f"{path.name}: {words!r} -> {target}"
                number = re.search(r"(?:section )?(\d+)$", words)
                if sec and number and not named or (named and sec):
                    assert number and number.group(1) == sec, f"{path.name}: {words!r} links to {target}"
