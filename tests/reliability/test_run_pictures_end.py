"""The end of a command-line run (issue 39, items 5 and 6): a picture is whole or absent, a
signal while the pictures are drawn ends the run as "interrupted", and ``run --restart`` of a run
that had completed draws what is missing, or says there is nothing to do."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dolfinx_nnqem.cli import EXIT_INTERRUPTED, EXIT_OK, EXIT_TERMINATED, main
from dolfinx_nnqem.io import run_pictures
from dolfinx_nnqem.estimates import INDICATOR_NAME
from dolfinx_nnqem.io.estimate_pictures import ESTIMATE_PICTURE
from dolfinx_nnqem.io.run_pictures import CONTACT_PICTURE, ENV_SWITCH, INDICATOR_FIELD, PICTURES, pictures_of_run

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "demos" / "two_beams.toml"
ALL_PICTURES = tuple(name for name in (*PICTURES, CONTACT_PICTURE) if name != ESTIMATE_PICTURE)
"""The pictures of the example's run: it has no [estimate], so no error_estimates.png."""
PNG_START, PNG_END = b"\x89PNG\r\n\x1a\n", b"\x00\x00\x00\x00IEND\xaeB`\x82"

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="signals a process group")


def _env() -> dict:
    env = {k: v for k, v in os.environ.items() if k != ENV_SWITCH}  # the user's default: pictures on
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _run(out: Path, *extra: str) -> subprocess.Popen:
    """``dolfinx-nnqem run`` of the two-beam example in a session of its own."""
    return subprocess.Popen([sys.executable, "-m", "dolfinx_nnqem", "run", str(EXAMPLE), "--increments", "2",
                             "--out", str(out), *extra], cwd=ROOT, env=_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)


def _finish(run: subprocess.Popen) -> tuple[str, str]:
    try:
        return run.communicate(timeout=600)
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)
            run.communicate()


def _when_drawing(run: subprocess.Popen, out: Path, sig: int) -> None:
    """Send ``sig`` to the run's session once its pictures are being written (the first entry
    in ``out/pictures``: a picture's file, or its temporary); polled, no sleep in between."""
    pictures = out / "pictures"
    deadline = time.monotonic() + 600
    while run.poll() is None and time.monotonic() < deadline:
        try:
            if any(pictures.iterdir()):
                break
        except OSError:  # not made yet
            pass
    assert run.poll() is None, f"the run ended before its pictures were drawn: {run.communicate()}"
    os.killpg(run.pid, sig)


def _pictures(out: Path) -> list[str]:
    """The names of the pictures in ``out/pictures`` (not the hidden temporaries)."""
    return sorted(p.name for p in (out / "pictures").iterdir() if not p.name.startswith("."))


def _broken(out: Path) -> dict[str, int]:
    """The pictures under their own names that are not whole PNG files (name -> size)."""
    broken = {}
    for name in _pictures(out):
        data = (out / "pictures" / name).read_bytes()
        if not (data.startswith(PNG_START) and data.endswith(PNG_END)):
            broken[name] = len(data)
    return broken


def _temporaries(out: Path) -> list[str]:
    return sorted(str(p.relative_to(out)) for p in out.rglob(".*.tmp-*"))


def _summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def _restart(out: Path) -> tuple[subprocess.Popen, str, str]:
    run = _run(out, "--restart")
    stdout, stderr = _finish(run)
    return run, stdout, stderr


@pytest.fixture(scope="module")
def completed(tmp_path_factory) -> Path:
    """A completed run of the example, its pictures drawn (copied by each test that changes it)."""
    out = tmp_path_factory.mktemp("completed") / "out"
    run = _run(out)
    _, stderr = _finish(run)
    assert run.returncode == EXIT_OK, stderr
    assert sorted(p.name for p in (out / "pictures").iterdir()) == sorted(ALL_PICTURES)
    return out


def test_an_interrupted_picture_leaves_no_file(tmp_path, monkeypatch):
    """A picture is written to a temporary and renamed: an interrupt (or a kill) in the middle
    of drawing left a 0-byte PNG under the picture's name."""
    out = tmp_path / "out"
    monkeypatch.setenv(ENV_SWITCH, "0")
    assert main(["-q", "run", str(EXAMPLE), "--increments", "1", "--out", str(out)]) == EXIT_OK

    def interrupted(summary, path, title=""):
        Path(path).write_bytes(b"")  # the file is open, nothing drawn yet: Ctrl-C
        raise KeyboardInterrupt

    monkeypatch.setattr(run_pictures, "draw_load_curve", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_pictures.draw_run_pictures(out)
    left = sorted(p.name for p in (out / "pictures").iterdir())
    print(f"\n  interrupted while drawing load_curve.png: pictures/ holds {left}")
    assert "load_curve.png" not in left and not _temporaries(out)


def test_a_kill_while_drawing_leaves_whole_pictures_and_restart_draws_the_rest(tmp_path):
    """SIGKILL of the run and its picture workers while the first picture is being written:
    every picture under its own name is a whole PNG (a 0-byte one was left before); the
    temporaries are removed by the next run in the folder, a restart, which draws what is
    missing and ends "completed"."""
    out = tmp_path / "out"
    run = _run(out)
    _when_drawing(run, out, signal.SIGKILL)
    _finish(run)
    broken, left = _broken(out), _temporaries(out)
    drawn = _pictures(out)
    print(f"\n  SIGKILL while drawing: exit {run.returncode}; whole pictures {drawn}, broken {broken}, "
          f"temporaries {left}")
    assert run.returncode == -signal.SIGKILL and not broken
    restart, stdout, stderr = _restart(out)
    print(f"  --restart: exit {restart.returncode}; {stdout.strip().splitlines()[-2:]}; status "
          f"{_summary(out)['status']}; temporaries {_temporaries(out)}")
    assert restart.returncode == EXIT_OK and _summary(out)["status"] == "completed", stderr
    assert sorted(p.name for p in (out / "pictures").iterdir()) == sorted(ALL_PICTURES)
    assert not _broken(out) and not _temporaries(out)


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, EXIT_INTERRUPTED), (signal.SIGTERM, EXIT_TERMINATED)])
def test_a_signal_while_drawing_ends_the_run_interrupted(tmp_path, sig, code):
    """Ctrl-C or SIGTERM while the pictures are drawn: exit 130 or 143 and "interrupted" in
    summary.json (it stayed "completed"), every increment kept (``converged`` true), no broken
    picture and no temporary (a killed worker's too); the message's restart draws the rest."""
    out = tmp_path / "out"
    run = _run(out)
    _when_drawing(run, out, sig)
    _, stderr = _finish(run)
    summary = _summary(out)
    print(f"\n  {sig.name} while drawing: exit {run.returncode}, {stderr.strip()!r}; status {summary['status']}, "
          f"converged {summary['converged']}; pictures {_pictures(out)}")
    assert run.returncode == code and stderr.count("\n") == 1 and "Traceback" not in stderr
    assert summary["status"] == "interrupted" and summary["converged"] and len(summary["load_factors"]) == 2
    assert "--restart" in stderr and not _broken(out) and not _temporaries(out)
    restart, stdout, stderr = _restart(out)
    assert restart.returncode == EXIT_OK and _summary(out)["status"] == "completed", stderr
    assert sorted(p.name for p in (out / "pictures").iterdir()) == sorted(ALL_PICTURES)


def test_restart_of_a_completed_run(completed, tmp_path):
    """Issue 39, item 5: ``run --restart`` of a run that had completed left "running" in
    summary.json, exited 0 and drew no picture. Now it solves nothing, draws the pictures
    that are missing (the others are left as they are), ends "completed", and says "nothing to
    do" when every picture is there."""
    out = tmp_path / "out"
    shutil.copytree(completed, out)
    (out / "pictures" / PICTURES[0]).unlink()
    kept = {name: (out / "pictures" / name).stat().st_mtime_ns for name in ALL_PICTURES[1:]}
    summary_before = _summary(out)
    restart, stdout, stderr = _restart(out)
    after = _summary(out)
    print(f"\n  --restart, {PICTURES[0]} missing: exit {restart.returncode}; {stdout.strip().splitlines()}; "
          f"status {after['status']}")
    assert restart.returncode == EXIT_OK and after["status"] == "completed", stderr
    assert "nothing to solve" in stdout and f"pictures: {PICTURES[0]} in" in stdout
    assert (out / "pictures" / PICTURES[0]).is_file() and not _broken(out)
    assert {name: (out / "pictures" / name).stat().st_mtime_ns for name in kept} == kept
    assert after["load_factors"] == summary_before["load_factors"] and after["iterations"] == summary_before["iterations"]
    again, stdout, stderr = _restart(out)
    print(f"  --restart again: exit {again.returncode}; {stdout.strip().splitlines()[-1]}; "
          f"status {_summary(out)['status']}")
    assert again.returncode == EXIT_OK and _summary(out)["status"] == "completed", stderr
    assert stdout.strip().splitlines()[-1] == f"nothing to do: every picture is in {out}/pictures/"


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, EXIT_INTERRUPTED), (signal.SIGTERM, EXIT_TERMINATED)])
def test_a_signal_after_the_pictures_keeps_the_outcome(tmp_path, sig, code):
    """A signal once every picture is written (the run closing, its workers ending, PETSc and MPI
    finalising) ended the command with 130 or 143 while summary.json said "completed". The exit
    code and the status agree now: once the outcome is final the signal is held and the run
    exits 0 ("completed"); one that came just before it is an interrupt ("interrupted")."""
    out = tmp_path / "out"
    run = _run(out)
    deadline = time.monotonic() + 600
    while run.poll() is None and time.monotonic() < deadline:
        try:
            if _pictures(out) == sorted(ALL_PICTURES):
                break
        except OSError:
            pass
    if run.poll() is None:  # (it may have ended already: a reaped process's group id may be another's)
        os.killpg(run.pid, sig)
    _, stderr = _finish(run)
    status = _summary(out)["status"]
    print(f"\n  {sig.name} once the pictures were written: exit {run.returncode}, status {status}, "
          f"stderr {stderr.strip()!r}")
    assert (run.returncode, status) in ((EXIT_OK, "completed"), (code, "interrupted")), stderr
    assert "Traceback" not in stderr and not _broken(out) and not _temporaries(out)


def test_a_restart_looks_only_for_the_pictures_the_run_makes(completed, tmp_path):
    """``error_estimates.png`` belongs to a run with an estimate, ``deformed.png`` and
    ``error_indicator.png`` to one with fields: a restart looked for the estimate's picture
    of every run, and so drew "the rest" again on each restart, never "nothing to do"."""
    assert INDICATOR_FIELD == INDICATOR_NAME
    out = tmp_path / "out"
    shutil.copytree(completed, out)
    assert pictures_of_run(out) == ALL_PICTURES
    summary = _summary(out)
    summary["error_estimates"] = {}
    (out / "summary.json").write_text(json.dumps(summary))
    assert ESTIMATE_PICTURE in pictures_of_run(out)
    (out / "fields.xdmf").unlink()
    assert not {"deformed.png", "error_indicator.png"} & set(pictures_of_run(out))
