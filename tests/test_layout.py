"""The package's layout: every import points down the map of facelib/__init__.py (facelib.LAYERS), and none
hides in a function."""
import ast
from pathlib import Path

import facelib

ROOT = Path(facelib.__file__).parent
LAYERS = facelib.LAYERS


def _unit(module):
    """facelib.tasks -> "tasks", facelib.face.aus -> "face", facelib -> None."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def _targets(node, package):
    """The facelib modules an import node names (none for other nodes): every spelling, `from facelib import x`,
    `import facelib.x`, `from facelib.x import y` and relative imports from ``package``."""
    if isinstance(node, ast.ImportFrom) and node.level:
        base = package.split(".")[:len(package.split(".")) - node.level + 1]
        names = [node.module] if node.module else [a.name for a in node.names]
        return [".".join(base + [name]) for name in names]
    if isinstance(node, ast.ImportFrom) and node.module == "facelib":  # from facelib import tasks
        return [f"facelib.{a.name}" for a in node.names]
    if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("facelib"):
        return [node.module]
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name.startswith("facelib")]
    return []


def _imports():
    """(source file, source unit, imported facelib module, line, inside a function) for every import."""
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT.parent).with_suffix("")
        module = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
        tree = ast.parse(path.read_text())
        inside = {id(n) for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
                  for n in ast.walk(f)}
        for node in ast.walk(tree):
            for target in _targets(node, package):
                yield path.relative_to(ROOT.parent), _unit(module), target, node.lineno, id(node) in inside


def test_every_unit_of_the_package_has_a_layer():
    units = {p.stem if p.is_file() else p.name for p in ROOT.iterdir()
             if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").exists()}
    assert units == set(LAYERS), f"give these a layer in facelib/__init__.py's map: {units ^ set(LAYERS)}"


def allowed_imports(unit):
    """The units ``unit`` may import: those of a lower layer (and its own modules, e.g. tasks.au from tasks.fill);
    never a sibling of the same layer (deformation and evaluation are both layer 5: neither imports the other)."""
    return sorted(u for u, layer in LAYERS.items() if layer < LAYERS[unit])


def test_imports_point_down_the_map():
    upward = [f"{path}:{line} imports {target} (layer {LAYERS[_unit(target)]}) from {unit} (layer {LAYERS[unit]}); "
              f"{unit} may import {', '.join(allowed_imports(unit))}"
              for path, unit, target, line, _ in _imports()
              if unit is not None and _unit(target) not in (None, unit) and LAYERS[_unit(target)] >= LAYERS[unit]]
    assert not upward, "imports that point up or sideways:\n" + "\n".join(upward)


def test_the_layout_check_sees_every_spelling_of_an_import(tmp_path):
    """`from facelib import tasks`, `import facelib.tasks`, `from ..tasks import x` and `from facelib.tasks import x`
    all name the unit imported."""
    source = ("from facelib import tasks, data\nimport facelib.viz\nfrom facelib.tasks.fill import fill\n"
              "from .. import metrics\nfrom ..guidance import chain\n")
    seen = [t for node in ast.walk(ast.parse(source)) for t in _targets(node, "facelib.deformation")]
    assert {_unit(t) for t in seen} == {"tasks", "data", "viz", "metrics", "guidance"}
    assert "evaluation" not in allowed_imports("deformation") and "data" in allowed_imports("deformation")


def test_no_facelib_import_hides_inside_a_function():
    hidden = [f"{path}:{line} imports {target} inside a function" for path, _, target, line, inside in _imports()
              if inside]
    assert not hidden, "\n".join(hidden)


def test_no_module_shadows_the_standard_library():
    import sys
    shadowing = [p.stem for p in ROOT.glob("*.py") if p.stem in sys.stdlib_module_names]
    assert not shadowing, f"facelib modules named like standard modules: {shadowing}"


def test_the_packages_dependencies_are_pinned_as_requirements_txt():
    """`pip install .` (pyproject.toml) and `make` (requirements.txt) install the same versions."""
    import re
    import tomllib
    root = ROOT.parent
    pins = dict(re.findall(r"^([A-Za-z0-9_.\-]+)==(\S+)", (root / "requirements.txt").read_text(), re.M))
    declared = tomllib.loads((root / "pyproject.toml").read_text())["project"]["dependencies"]
    assert declared, "pyproject.toml declares no runtime dependencies"
    for requirement in declared:
        name, version = requirement.split("==")
        assert pins.get(name) == version, f"pyproject pins {requirement}, requirements.txt {pins.get(name)}"


def test_every_facelib_line_fits_the_page_column():
    """The book prints facelib's source (viz.show_source) in a code block that wraps lines
    wider than about 88 characters, and a reader opens the files beside the pages: every
    line of facelib keeps within 88 (code as ``black -l 88`` formats it; comments and
    docstrings wrapped to the same width)."""
    too_wide = [f"{path.relative_to(ROOT.parent)}:{i}: {len(line)} characters"
                for path in sorted(ROOT.rglob("*.py"))
                for i, line in enumerate(path.read_text().splitlines(), 1) if len(line) > 88]
    assert not too_wide, f"{len(too_wide)} lines wider than 88:\n" + "\n".join(too_wide[:20])
