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


def shown_sources():
    """Every ``show_source(X)`` of the notebooks as (notebook, X, object): X is resolved as the notebook
    resolves it, by running the notebook's own import of X's first name (``from facelib... import``)
    and following the attributes (an inherited method resolves to the base class's function, whose
    source is what the page shows).  A name that does not resolve to a facelib object fails."""
    import ast
    import importlib
    import inspect

    shown = []
    for nb in sorted((ROOT / "book").glob("*.ipynb")):
        cells = ["".join(c["source"]) for c in json.loads(nb.read_text())["cells"] if c["cell_type"] == "code"]
        trees = [ast.parse(re.sub(r"(?m)^(\s*)([%!])", r"\1#\2", code)) for code in cells]  # magics out
        imports, calls = {}, []
        for node in (n for tree in trees for n in ast.walk(tree)):
            if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "facelib":
                for alias in node.names:
                    imports[alias.asname or alias.name] = (node.module, alias.name)
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.split(".")[0] == "facelib":
                        imports[alias.asname or alias.name.split(".")[0]] = (None, alias.name.split(".")[0])
            elif isinstance(node, ast.Call) and (getattr(node.func, "attr", None) == "show_source"
                                                 or getattr(node.func, "id", None) == "show_source"):
                assert len(node.args) == 1, f"{nb.name}: show_source takes one object: {ast.unparse(node)}"
                calls.append(ast.unparse(node.args[0]))
        for name in calls:
            first, *attributes = name.split(".")
            assert first in imports, f"{nb.name}: show_source({name}): {first} is not imported from facelib"
            module, imported = imports[first]
            if module is None:
                obj = importlib.import_module(imported)
            else:
                parent = importlib.import_module(module)
                obj = getattr(parent, imported) if hasattr(parent, imported) else importlib.import_module(
                    f"{module}.{imported}")
            for attribute in attributes:
                assert hasattr(obj, attribute), f"{nb.name}: show_source({name}): no attribute {attribute}"
                obj = getattr(obj, attribute)
            assert inspect.isfunction(obj) or inspect.isclass(obj), f"{nb.name}: show_source({name}): {obj!r}"
            assert obj.__module__.split(".")[0] == "facelib", f"{nb.name}: show_source({name}) is not facelib's"
            shown.append((nb.name, name, obj))
    return shown


def test_facelib_code_the_book_shows_fits_the_page_column():
    """viz.show_source prints a facelib function or class in a code block of the page, which wraps lines
    wider than about 88 characters as a notebook's own code does: the source of every object a chapter
    shows keeps within 88 (code as black -l 88 formats it, comments and docstrings wrapped by hand)."""
    import inspect

    shown = shown_sources()
    assert len(shown) >= 40, f"only {len(shown)} show_source calls found"
    too_wide = []
    for nb, name, obj in shown:
        lines, start = inspect.getsourcelines(obj)
        path = Path(inspect.getsourcefile(obj)).relative_to(ROOT)
        too_wide += [f"{nb}: show_source({name}): {path}:{start + i}: {len(line.rstrip(chr(10)))} characters"
                     for i, line in enumerate(lines) if len(line.rstrip("\n")) > 88]
    assert not too_wide, f"{len(too_wide)} lines wider than 88:\n" + "\n".join(too_wide)


PAGES = sorted((ROOT / "book").glob("*.ipynb")) + [ROOT / "book" / n for n in ("intro.md", "errata.md", "notation.md")]
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
    return INLINE.sub(" ", without_code_blocks(text).replace("\n", " "))


def without_code_blocks(text):
    """A page's text without code blocks (a ``` fence that opens a directive keeps its text)."""
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
    return "\n".join(kept)


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


# One symbol, one meaning (book/notation.md).  Each rule is a use of a symbol that the notation page
# settles against: a pattern of a math span, and, where the symbol alone is allowed, a pattern of the text
# around it (80 characters each side) that gives it the forbidden meaning.  A span within a few words after
# "writes", "the paper's" or "their" is the chapter's once-only note of another source's symbol.
NOTATION_RULES = [
    ("tau is a softmax temperature: normalised time is u, a tolerance delta",
     r"\\tau(?!_)", r"normali[sz]ed time|toleran|TOLERANCE|\\tau\s*=\s*\(?f\b|\\tau\^2"),
    ("w is an AU intensity: the guidance scale is omega, a loss weight gamma, a match weight p(r_n | c)",
     r"(?<![A-Za-z\\])w(?![A-Za-z])", r"classifier-free|contrastive|CFG|\^w\b|\\epsilon_w|(?<![A-Za-z\\])w_[in]\b"),
    ("s is an identity: a scale is omega, a score log p",
     r"(?<![A-Za-z\\])s(?:\^\d)?\s*(?:\\,)?\s*\\(?:sqrt|sigma|nabla|cos|mu)|(?<![A-Za-z\\])s\((?:x|\\cdot)", None),
    ("s is an identity: a scale or factor is omega",
     r"^\$\s*s\s*\$$", r"(?:\bscale|\bfactor|shift's)\s*\$\s*s\s*\$"),
    ("lambda is the guidance spring: the deformer's identity weight is kappa", r"\\lambda_\\theta", None),
    ("AU intensities are w and an identity s, not c", r"(?<![A-Za-z\\])c_\{?(?:f\b|id|\\text\{id)", None),
    ("sigma_t is a reverse step's standard deviation: DDIM's choice is sigma_t(eta)", r"\\sigma_t\s*=\s*\\eta", None),
    ("a reverse step's fresh noise is xi (z is a latent code)",
     r"\\sigma_t(?:\(\\eta\))?\s*(?:\\,)?\s*z(?![A-Za-z_])", None),
    ("a loss is written \\mathcal L (L_f is a landmark frame)", r"(?<![A-Za-z\\])(?<!\\mathcal )L_(?:0|T|\{t-1\})", None),
    ("S_K and S_U are the known and unknown frames: a respaced chain has T' steps, best-of-P has P chains",
     r"(?<![A-Za-z\\])(?<!\\mathcal )(?<!S_)[SK](?![A-Za-z])", None),
]
NOTE = re.compile(r"(?:\bwrites?\b|\bpaper's|\btheir\b)[^$]{0,30}$")
MATH = re.compile(r"\$\$.*?\$\$|\$[^$\n]*\$", re.S)


def notation_violations(text):
    """(rule, math span) for every use in a page's markdown that the notation page forbids, and every frame
    counted from 0 in the prose (frames are f = 1..F; code indexes from 0)."""
    body = re.sub(r"`[^`]*`", lambda m: m.group(0).replace("$", ""), without_code_blocks(text))
    found = []
    for m in MATH.finditer(body):
        span, window = m.group(0), body[max(0, m.start() - 80):m.end() + 80]
        if NOTE.search(body[max(0, m.start() - 40):m.start()]):
            continue
        found += [(rule, span) for rule, pattern, near in NOTATION_RULES
                  if re.search(pattern, span) and (near is None or re.search(near, window))]
    found += [("frames are counted from 1 in the prose", f) for f in re.findall(r"\bframe 0\b", prose(text))]
    return found


def test_notation_rules_catch_the_conflicts_the_notation_page_settles():
    wrong = ["Time is normalised, $\\tau = f/(F-1)$ for frame $f$ of $F$.",
             "and $\\tau$ = `config.AU_CURVE_TOLERANCE`, in intensity units",
             "classifier-free guidance at MDM's weight $w = 2.5$",
             "a contrastive term $- w \\log \\frac{a}{b}$",
             "$\\tilde\\epsilon = \\epsilon_\\theta(x_t, t) - s\\,\\sqrt{1-\\bar\\alpha_t}\\;\\nabla_{x_t}\\log p_\\phi$",
             "the mean shift with DDIM, scale $s$ = `config.MEAN_SHIFT_SCALE`",
             "the score $s(x) = \\log \\mathcal N(c \\mid R(x))$",
             "$z = \\lambda_\\theta z_{id} + \\Delta L_f$", "A request gives curves $c_{f,a}$",
             "as interactions $\\Delta L_f \\otimes c_{id}$", "$\\sigma_t = \\eta\\,\\sqrt{\\tilde\\beta_t}$",
             "draw $\\hat x_{t-1} = \\mu_\\theta + \\sigma_t z$", "the last step is $L_0 = -\\log p_\\theta(x_0 \\mid x_1)$",
             "on a subset $S = \\{s_1 < \\dots < s_K\\}$ of the steps", "keeping the best of $K$ chains",
             "its neutral landmarks are frame 0, kept as Alg. 3 keeps a known frame"]
    for text in wrong:
        assert notation_violations(text), text
    right = ["a softmax at temperature $\\tau$", "identity $s$ with AU intensities $w \\in \\mathbb{R}^{20}$",
             "$\\mathcal S_K = \\{1\\}$ or $x_t|_{\\mathcal S_U}$", "the guidance scale $\\omega$ (Dhariwal & Nichol write $s$)",
             "$\\mathcal L_0$ and $\\mathcal L_{t-1}$", "$+ \\sigma_t(\\eta)\\, \\xi$", "(the paper writes $\\lambda_\\theta$)",
             "frame 1 (`index 0`) and `--known 0:10`", "```python\nx = f(frame 0)\n```"]
    for text in right:
        assert not notation_violations(text), text


def test_chapters_follow_the_notation_page():
    assert (ROOT / "book" / "notation.md").exists() and "book/notation" in (ROOT / "_toc.yml").read_text()
    for nb in sorted((ROOT / "book").glob("*.ipynb")):
        found = [(rule, span) for text in page_texts(nb) for rule, span in notation_violations(text)]
        assert not found, f"{nb.name} uses a symbol against book/notation.md: {found}"


def prerequisites(nb):
    """The chapters a notebook's **Prerequisites:** line names ("02–04" is a range; "... is not needed" is not)."""
    first = "".join(json.loads(nb.read_text())["cells"][0]["source"])
    line = re.search(r"\*\*Prerequisites:\*\*(.*?)(?:\n\n|$)", first, re.S)
    if line is None:
        return None
    text = re.sub(r"\{ref\}`[^`]*<ch(\w\w)>`(?:[^{]*?is not needed)", "", line.group(1))
    found = set()
    for a, b in re.findall(r"<ch(\d\d)>`–\{ref\}`[^`]*<ch(\d\d)>", text):
        found |= {f"{k:02d}" for k in range(int(a), int(b) + 1)}
    return found | set(re.findall(r"<ch(\d\d|a1)>", text))


def test_the_chapter_map_draws_the_prerequisites():
    """book/_static/make_diagrams.py's chapter map (direct dependencies) agrees with every chapter's
    **Prerequisites:** line: each prerequisite is reachable along the map's arrows, and each arrow into a
    chapter comes from a prerequisite or from something a prerequisite builds on."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("diagrams", ROOT / "book" / "_static" / "make_diagrams.py")
    diagrams = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(diagrams)
    parents = {}
    for a, c in diagrams.EDGES:
        parents.setdefault(c, set()).add(a)

    def ancestors(c):
        found, todo = set(), list(parents.get(c, ()))
        while todo:
            a = todo.pop()
            if a not in found:
                found.add(a)
                todo += parents.get(a, ())
        return found

    chapters = {p.stem[:2]: p for p in (ROOT / "book").glob("*.ipynb")}
    assert set(diagrams.CHAPTERS) == set(chapters), "every chapter is a box of the map, and only chapters"
    for key, path in chapters.items():
        needs = prerequisites(path)
        assert needs is not None, f"{path.name} has no **Prerequisites:** line"
        assert needs <= ancestors(key), f"{path.name}: prerequisites {sorted(needs - ancestors(key))} not on the map"
        covered = needs.union(*(ancestors(n) for n in needs)) if needs else set()
        assert parents.get(key, set()) <= covered, \
            f"{path.name}: the map draws {sorted(parents[key] - covered)} into it, its prerequisites do not"
