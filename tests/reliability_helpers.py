"""Shared by the reliability tests: a small two-beam problem file and subprocess runs of the CLI."""

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from problem_files import TWO_BEAMS_MSH, two_beams_demo

ROOT = Path(__file__).resolve().parents[1]


def problem_file(folder: Path, increments: int = 30, extra: str = "", solver: str = "") -> Path:
    # the .msh: gmsh's reader under test too
    text = two_beams_demo(TWO_BEAMS_MSH, solver_lines=f"increments = {increments}\n{solver}")
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


def catches(pid: int, sig: int) -> bool:
    """Process ``pid`` has a handler for ``sig`` (its ``SigCgt`` mask in ``/proc``)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("SigCgt:"):
                return bool(int(line.split()[1], 16) >> (sig - 1) & 1)
    except (OSError, ValueError):
        pass
    return False


def wait_until_held(process: subprocess.Popen, timeout: float = 120.0) -> None:
    """Wait (polling, no sleep) until the command line started as ``process`` holds Ctrl-C and
    SIGTERM: the package's first line has run (Python itself has no SIGTERM handler, so the
    handler's bit in ``SigCgt`` appears with ``dolfinx_nnqem.interrupts.hold``)."""
    deadline = time.monotonic() + timeout
    while not catches(process.pid, signal.SIGTERM):
        if process.poll() is not None or time.monotonic() > deadline:
            raise AssertionError(f"the package's hold never came: {process.poll()}")


def finish(process: subprocess.Popen, timeout: float = 120.0) -> tuple[str, str]:
    """``process.communicate(timeout)``; on a timeout every process of its session is killed
    first (a hung MPI job's ranks would otherwise outlive the test and load the machine)."""
    try:
        return process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        kill_session(process)
        process.communicate()
        raise


def run_in_session(command: list[str], timeout: float = 120.0, **kwargs) -> subprocess.CompletedProcess:
    """``subprocess.run(command, capture_output=True, text=True)`` in a new session, killed whole
    on a timeout (see :func:`finish`)."""
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True, **kwargs)
    out, err = finish(process, timeout)
    return subprocess.CompletedProcess(command, process.returncode, out, err)


def kill_session(process: subprocess.Popen, sig=signal.SIGKILL) -> None:
    """Send ``sig`` to every process of the run's session (the test started it: its own ids)."""
    os.killpg(process.pid, sig)


def signal_ranks(process: subprocess.Popen, sig: int) -> int:
    """Send ``sig`` to the Python processes of the run's session (the MPI ranks), not to the
    launcher; returns how many were signalled."""
    python = os.path.realpath(sys.executable)
    count = 0
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == process.pid:
            continue
        try:
            if os.getsid(int(entry.name)) == process.pid and os.path.realpath(entry / "exe") == python:
                os.kill(int(entry.name), sig)
                count += 1
        except OSError:
            pass  # the process ended meanwhile, or is not ours to inspect
    return count


@contextlib.contextmanager
def small_file_system(folder: Path, size: str = "1m"):
    """A tmpfs of ``size`` mounted at ``folder`` for the test (a full disk gives ENOSPC, which
    RLIMIT_FSIZE's EFBIG does not imitate everywhere: VTK crashed on ENOSPC only). Skips with
    the reason where this process cannot mount (not root, or no mount permission)."""
    import pytest

    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root (a real ENOSPC; RLIMIT_FSIZE gives EFBIG, "
                    "which does not reach the code paths that failed on a full disk)")
    folder.mkdir(parents=True, exist_ok=True)
    mount = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)],
                           capture_output=True, text=True)
    if mount.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({mount.stderr.strip()})")
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], capture_output=True)


def fill(folder: Path, leave: int) -> None:
    """Fill ``folder``'s file system up to ``leave`` free bytes with the file ``filler``."""
    (folder / "filler").unlink(missing_ok=True)
    st = os.statvfs(folder)
    with open(folder / "filler", "wb") as fh:
        os.posix_fallocate(fh.fileno(), 0, max(st.f_bavail * st.f_frsize - leave, 1))
