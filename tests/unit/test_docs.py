"""The documentation builds without a warning (Sphinx -W, the command in docs/user-guide.md)."""

import subprocess
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parents[2] / "docs"


def test_docs_build_without_warnings(tmp_path):
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(DOCS), str(tmp_path)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    print(f"\n  {' '.join(cmd[2:])}: exit {run.returncode}\n{run.stderr[-3000:]}")
    assert run.returncode == 0, run.stderr[-3000:]
    assert (tmp_path / "index.html").is_file() and (tmp_path / "api.html").is_file()


def test_the_architecture_figure_shows_the_packages_modules():
    """docs/figures/architecture.png is drawn from the package (scripts/architecture_figure.py):
    a module added, moved or removed without redrawing it fails here."""
    script = Path(__file__).resolve().parents[2] / "scripts" / "architecture_figure.py"
    result = subprocess.run([sys.executable, str(script), "--check"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


def test_the_user_guide_example_runs(tmp_path, monkeypatch):
    """The first example of docs/user-guide.md, as printed, writes a completed run."""
    import json

    text = (DOCS / "user-guide.md").read_text()
    block = text.split("```python\n", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(tmp_path)
    exec(compile(block, str(DOCS / "user-guide.md"), "exec"), {"__name__": "user_guide"})
    summary = json.loads((tmp_path / "results" / "run" / "summary.json").read_text())
    print(f"\n  {summary['status']}, {len(summary['load_factors'])} increments, iterations {summary['iterations']}")
    assert summary["status"] == "completed" and len(summary["load_factors"]) == 15


def test_a_results_writer_in_a_with_statement_records_how_the_run_ended(tmp_path):
    """An exception inside ``with ResultsWriter(...)``: summary.json says "error" with the
    message, and the folder's lock is released (a second writer can open it)."""
    import json

    import pytest

    from dolfinx_nnqem.cases.two_beams import two_beams_problem
    from dolfinx_nnqem.io import ResultsWriter

    problem = two_beams_problem()
    with pytest.raises(RuntimeError, match="a user's callback failed"):
        with ResultsWriter(problem, "monolithic", tmp_path / "run", 15):
            raise RuntimeError("a user's callback failed")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["status"] == "error" and "a user's callback failed" in json.dumps(summary)
    ResultsWriter(problem, "monolithic", tmp_path / "run", 15, overwrite=True).close()
