"""Shared by the reliability tests: a small two-beam problem file and subprocess runs of the CLI."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def problem_file(folder: Path, increments: int = 30, extra: str = "", solver: str = "") -> Path:
    text = (ROOT / "demos" / "two_beams.toml").read_text()
    text = text.replace('file = "../meshes/two_beams.msh"', f'file = "{(ROOT / "meshes" / "two_beams.msh").as_posix()}"')
    text = text.replace("increments = 15", f"increments = {increments}\n{solver}")
    text = text.replace('[output]\nfolder = "results/two_beams_toml"', f'[output]\nfolder = "results/two_beams_toml"\n{extra}')
    path = folder / "p.toml"
    path.write_text(text)
    return path


def env() -> dict:
    from dolfinx_nnqem import compat

    e = compat.mpi_environment()
    e["PYTHONPATH"] = str(ROOT) + os.pathsep + e.get("PYTHONPATH", "")
    return e


def start(args, ranks: int = 0, **kwargs) -> subprocess.Popen:
    """``dolfinx-nnqem ARGS`` in a new session (so that a test can signal all its processes)."""
    from dolfinx_nnqem import compat

    prefix = [*compat.mpiexec(), "-n", str(ranks)] if ranks else []
    return subprocess.Popen([*prefix, sys.executable, "-m", "dolfinx_nnqem", *args], env=env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            **kwargs)


def wait_for_checkpoint(out: Path, index: int, process: subprocess.Popen, timeout: float = 120.0) -> int:
    """Wait until ``out`` has a complete checkpoint of at least ``index``; returns its index."""
    latest = out / "checkpoints" / "latest.json"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise AssertionError(f"the run ended before checkpoint {index}: {process.communicate()}")
        try:
            k = json.loads(latest.read_text())["index"]
            if k >= index:
                return k
        except (OSError, ValueError, KeyError):
            pass
        time.sleep(0.005)
    raise AssertionError(f"no checkpoint {index} within {timeout} s")


def kill_session(process: subprocess.Popen, sig=signal.SIGKILL) -> None:
    """Send ``sig`` to every process of the run's session (the test started it: its own ids)."""
    os.killpg(process.pid, sig)
