"""The book builds with notebook execution off and warnings as errors: a broken _toc.yml, link,
cross-reference or markdown fails the tests (notebook execution itself is tested by nbmake)."""
import shutil
import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parent.parent


def test_book_builds_without_warnings(tmp_path):
    cfg = yaml.safe_load((ROOT / "_config.yml").read_text())
    cfg["execute"]["execute_notebooks"] = "off"
    (tmp_path / "_config.yml").write_text(yaml.safe_dump(cfg))
    jb = Path(sys.executable).with_name("jupyter-book")
    cmd = [str(jb if jb.exists() else shutil.which("jupyter-book")), "build", str(ROOT), "--config",
           str(tmp_path / "_config.yml"), "--path-output", str(tmp_path / "out"), "-W", "--keep-going", "-q"]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    html = tmp_path / "out" / "_build" / "html"
    assert (html / "index.html").exists() and (html / "book" / "01_face_world.html").exists()


def test_notebooks_are_committed_without_outputs_and_listed():
    import json
    toc = (ROOT / "_toc.yml").read_text()
    for nb in sorted((ROOT / "book").glob("*.ipynb")):
        cells = json.loads(nb.read_text())["cells"]
        assert not any(c.get("outputs") for c in cells if c["cell_type"] == "code"), f"{nb.name} has outputs"
        assert f"book/{nb.stem}" in toc, f"{nb.name} is not in _toc.yml"
