"""The documentation builds without a warning (Sphinx -W, the command in docs/user-guide.md)."""

import subprocess
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1] / "docs"


def test_docs_build_without_warnings(tmp_path):
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(DOCS), str(tmp_path)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    print(f"\n  {' '.join(cmd[2:])}: exit {run.returncode}\n{run.stderr[-3000:]}")
    assert run.returncode == 0, run.stderr[-3000:]
    assert (tmp_path / "index.html").is_file() and (tmp_path / "api.html").is_file()


def test_the_architecture_figure_shows_the_packages_modules():
    """docs/figures/architecture.png is drawn from the package (scripts/architecture_figure.py):
    a module added, moved or removed without redrawing it fails here."""
    script = Path(__file__).resolve().parents[1] / "scripts" / "architecture_figure.py"
    result = subprocess.run([sys.executable, str(script), "--check"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
