"""An MPI job run by a test that explains its own failure (issue 39, item 13).

A fresh-clone CI once saw ``mpiexec`` end with exit 9 in the 3-rank two-beam test, with nothing
else to go on. MPICH's ``mpiexec`` returns the signal number when a rank ends by a signal, and
PETSc catches the catchable ones (SIGSEGV, SIGFPE, SIGBUS, SIGHUP: its "Caught signal" line and
exit 59), so exit 9 means that a rank was killed by SIGKILL, which no process can catch or
report: the kernel (its out-of-memory killer, a hard CPU-time limit) or another process sent it.
:func:`run_mpi_job` therefore records, while the job runs, which process is which rank and how
much memory each used, and the machine's memory and its out-of-memory kills; a failed job's
report says which rank ended how, with every rank's output tagged by its rank.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from dolfinx_nnqem import compat

RANK_VARIABLES = (b"PMI_RANK=", b"OMPI_COMM_WORLD_RANK=", b"PMIX_RANK=")


def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def _descendants(pid: int) -> list[int]:
    found, todo = [], _children(pid)
    while todo:
        child = todo.pop()
        found.append(child)
        todo += _children(child)
    return found


def _rank_of(pid: int) -> int | None:
    try:
        variables = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
    except OSError:
        return None
    for variable in variables:
        for name in RANK_VARIABLES:
            if variable.startswith(name) and variable[len(name):].isdigit():
                return int(variable[len(name):])
    return None


def _status_kb(pid: int, key: str) -> int | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def _meminfo_mb(key: str) -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1]) // 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def oom_kills() -> dict[str, int]:
    """The out-of-memory kills counted so far: the kernel's since boot (``/proc/vmstat``) and
    this process's memory cgroup's (v1 ``memory.oom_control``, v2 ``memory.events``)."""
    counts: dict[str, int] = {}
    try:
        for line in Path("/proc/vmstat").read_text().splitlines():
            if line.startswith("oom_kill "):
                counts["kernel"] = int(line.split()[1])
    except (OSError, ValueError):
        pass
    try:
        cgroups = [line.split(":", 2) for line in Path("/proc/self/cgroup").read_text().splitlines()]
    except OSError:
        cgroups = []
    for _, controllers, path in cgroups:  # v1: the memory controller's; v2: the unified hierarchy's
        if controllers not in ("memory", ""):
            continue
        root = Path("/sys/fs/cgroup") / ("memory" if controllers else "") / path.lstrip("/")
        for name in ("memory.oom_control", "memory.events"):
            try:
                entries = (root / name).read_text().splitlines()
            except OSError:
                continue
            for entry in entries:
                if entry.startswith("oom_kill ") and entry.split()[1].isdigit():
                    counts[f"cgroup {path}"] = int(entry.split()[1])
    return counts


def _kernel_oom_lines() -> list[str]:
    """The kernel log's lines about killed processes, where this process may read it."""
    try:
        log = subprocess.run(["dmesg"], capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError):
        return ["(dmesg not readable here)"]
    return [line for line in log.splitlines() if re.search(r"Out of memory|Killed process|oom-kill|oom_reaper", line)]


class _Watch(threading.Thread):
    """Polls the job's process tree: rank -> pid, each rank's peak memory, the machine's lowest
    available memory."""

    def __init__(self, launcher: subprocess.Popen):
        super().__init__(daemon=True)
        self.launcher = launcher
        self.ranks: dict[int, int] = {}  # rank -> pid
        self.peak_mb: dict[int, int] = {}
        self.gone: dict[int, float] = {}  # rank -> seconds after the start when its process was gone
        self.lowest_available_mb = _meminfo_mb("MemAvailable")
        self.t0 = time.monotonic()
        self.done = threading.Event()

    def run(self) -> None:
        while not self.done.is_set():
            alive = set()
            for pid in _descendants(self.launcher.pid):
                rank = _rank_of(pid)
                if rank is None:
                    continue
                alive.add(rank)
                self.ranks[rank] = pid
                peak = _status_kb(pid, "VmHWM")
                if peak is not None:
                    self.peak_mb[rank] = max(self.peak_mb.get(rank, 0), peak // 1024)
            for rank in set(self.ranks) - alive - set(self.gone):
                self.gone[rank] = time.monotonic() - self.t0
            available = _meminfo_mb("MemAvailable")
            if available is not None and (self.lowest_available_mb is None or available < self.lowest_available_mb):
                self.lowest_available_mb = available
            self.done.wait(0.1)


def _tag_flags() -> list[str]:
    """MPICH's flag that prefixes every output line with its rank (Open MPI 5 renamed its own:
    the output stays as it is there)."""
    from mpi4py import MPI

    return ["-prepend-rank"] if "MPICH" in MPI.Get_library_version() else []


def run_mpi_job(args: list[str], ranks: int, timeout: float, env: dict | None = None
                ) -> tuple[subprocess.CompletedProcess, str]:
    """``mpiexec -n RANKS ARGS`` (every output line tagged with its rank); returns the completed
    process and, where it failed (a code other than 0, or the timeout: then killed), a report
    of which rank ended how, each rank's peak memory, the machine's memory and out-of-memory
    kills during the job, and the ends of its output."""
    command = [*compat.mpiexec(), *_tag_flags(), "-n", str(ranks), *args]
    oom_before = oom_kills()
    launcher = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)
    watch = _Watch(launcher)
    watch.start()
    timed_out = False
    try:
        out, err = launcher.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        timed_out = True
        for pid in [launcher.pid, *watch.ranks.values()]:  # MPICH's ranks have sessions of their own
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        out, err = launcher.communicate()
    watch.done.set()
    watch.join()
    elapsed = time.monotonic() - watch.t0
    done = subprocess.CompletedProcess(command, launcher.returncode, out, err)
    if launcher.returncode == 0 and not timed_out:
        return done, ""
    return done, _report(done, watch, oom_before, oom_kills(), elapsed, timeout, timed_out)


def _report(done: subprocess.CompletedProcess, watch: _Watch, oom_before: dict, oom_after: dict,
            elapsed: float, timeout: float, timed_out: bool) -> str:
    lines = [f"mpiexec ended with {done.returncode} after {elapsed:.1f} s"
             + (f": killed at the test's timeout of {timeout:g} s" if timed_out else f" (timeout {timeout:g} s)")]
    pids = {pid: rank for rank, pid in watch.ranks.items()}
    # MPICH: "PID 123 RUNNING AT host" ... "EXIT STRING: Killed (signal 9)"; Open MPI: "process
    # rank 1 with PID 123 on node host exited on signal 9 (Killed)"
    mpich = re.search(r"PID (\d+) RUNNING AT", done.stdout), re.search(r"EXIT STRING: .* \(signal (\d+)\)", done.stdout)
    openmpi = re.search(r"rank \d+ with PID (\d+) on node \S+ exited on\s+signal (\d+)", done.stdout + done.stderr)
    pid = int(mpich[0].group(1)) if mpich[0] else int(openmpi.group(1)) if openmpi else None
    number = int(mpich[1].group(1)) if mpich[1] else int(openmpi.group(2)) if openmpi else None
    if pid is not None or number is not None:
        who = f"rank {pids[pid]} (pid {pid})" if pid in pids else f"pid {pid} (its rank not seen)"
        how = f"by signal {number} ({signal.Signals(number).name})" if number is not None else "abnormally"
        lines.append(f"the launcher says: {who} ended {how}"
                     + (" (MPICH names one rank; once a rank has died it ends the others with SIGKILL, so the "
                        "rank that died first may be another)" if number == signal.SIGKILL and mpich[0] else ""))
    if number == signal.SIGKILL:
        lines.append("SIGKILL cannot be caught: it came from the kernel (its out-of-memory killer, see the counts "
                     "below; a hard CPU-time limit) or from another process (kill -9, pkill, killall); the "
                     "package never sends it to a rank")
    for rank in sorted(watch.ranks):
        gone = f", gone {watch.gone[rank]:.1f} s after the start" if rank in watch.gone else ""
        lines.append(f"rank {rank}: pid {watch.ranks[rank]}, peak memory {watch.peak_mb.get(rank, '?')} MB{gone}")
    lines.append(f"machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}, memory {_meminfo_mb('MemTotal')} MB, "
                 f"available at the end {_meminfo_mb('MemAvailable')} MB, lowest during the job "
                 f"{watch.lowest_available_mb} MB")
    lines.append(f"out-of-memory kills before the job {oom_before}, after it {oom_after}")
    if any(oom_after.get(key, 0) > count for key, count in oom_before.items()):
        lines += ["the kernel's log:", *_kernel_oom_lines()[-10:]]
    tagged = " (rank-tagged)" if _tag_flags() else ""
    lines += [f"stdout{tagged}:", done.stdout[-4000:], f"stderr{tagged}:", done.stderr[-4000:]]
    return "\n".join(lines)


if __name__ == "__main__":  # a quick look: python tests/mpi_job.py RANKS ARGS...
    result, report = run_mpi_job(sys.argv[2:], int(sys.argv[1]), 600)
    print(report or f"exit {result.returncode}")
