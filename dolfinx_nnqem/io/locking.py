"""One run per output folder: a lock held for the run's lifetime, and no mixing with old results.

:class:`OutputLock` takes ``.nnqem.lock`` in the output folder with ``fcntl.flock`` (exclusive,
non-blocking) and keeps the file open until the run ends. The kernel releases the lock when the
process dies, however it dies (SIGKILL included): a lock file left by a killed run is stale and
is simply taken over; a lock held by a live run makes the second run refuse with a message naming
the holder (process id, host, start time). Only rank 0 takes it (MPI runs share one folder).

:func:`previous_outputs` lists what an earlier run left in a folder and :func:`clear_outputs`
removes exactly those files (never anything else the user keeps there).
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import socket
import time
from pathlib import Path

__all__ = ["LOCK_NAME", "OUTPUT_NAMES", "FolderInUse", "OutputLock", "clear_outputs", "previous_outputs"]

LOCK_NAME = ".nnqem.lock"
OUTPUT_NAMES = ("summary.json", "fields.xdmf", "fields.h5", "fields", "fields_p2.pvd", "fields_deformed.xdmf",
                "pairs.pvd", "pairs", "checkpoints", "pictures")
"""What a run writes into its folder (files and folders); cleared by ``--overwrite``."""


class FolderInUse(OSError):
    """Another live run holds the output folder's lock."""


class OutputLock:
    """An exclusive lock on an output folder (see the module docstring)."""

    def __init__(self, folder: str | os.PathLike):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_NAME
        self._fd: int | None = None
        self._info_bytes = 0

    def acquire(self) -> OutputLock:
        """Take the lock, creating the folder, and write this process's id, host and start time into
        the lock file; this lock. Raises :class:`FolderInUse` naming the run that holds it."""
        self.folder.mkdir(parents=True, exist_ok=True)
        for _ in range(100):
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                self._refuse(fd)
            try:  # the holder may have released (and removed) the file between open and flock
                if os.fstat(fd).st_ino == os.stat(self.path).st_ino:
                    break
            except FileNotFoundError:
                pass
            os.close(fd)
        else:
            raise FolderInUse(16, f"cannot lock output folder {self.folder}", str(self.folder))
        info = json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "started": time.time()}).encode()
        os.ftruncate(fd, 0)
        os.pwrite(fd, info, 0)
        self._fd, self._info_bytes = fd, len(info)
        return self

    def reserve(self, nbytes: int) -> None:
        """Hold ``nbytes`` of disk space in the lock file (after its JSON), so that the run's last
        words (``summary.json`` saying "error" or "not converged") can still be written when the
        disk fills up: :meth:`free_reserve` gives the space back just before. Best effort: a
        file system that cannot allocate leaves the reserve as it was."""
        if self._fd is None:
            return
        try:
            os.posix_fallocate(self._fd, 0, max(int(nbytes), self._info_bytes))
        except OSError:
            pass

    def free_reserve(self) -> None:
        """Give the reserved space back (the lock file keeps its JSON)."""
        if self._fd is not None:
            try:
                os.ftruncate(self._fd, self._info_bytes)
            except OSError:
                pass

    def _refuse(self, fd: int) -> None:
        holder = ""
        try:
            info = json.loads(self.path.read_bytes().rstrip(b"\0") or b"{}")  # the reserve is zeros
            holder = (f" (process {info.get('pid')} on {info.get('host')}, started "
                      f"{time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(info.get('started', 0)))})")
        except (OSError, ValueError):
            pass
        os.close(fd)
        raise FolderInUse(16, f"output folder {self.folder} is in use by another run{holder}; wait for it "
                              "to finish or choose another folder", str(self.folder)) from None

    def release(self) -> None:
        """Remove the lock file and let the lock go (nothing if it is not held)."""
        if self._fd is not None:
            try:
                os.unlink(self.path)  # still ours: nobody else can hold it while we do
            except OSError:
                pass
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> OutputLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


def previous_outputs(folder: str | os.PathLike) -> list[Path]:
    """The files and folders of an earlier run in ``folder`` (see :data:`OUTPUT_NAMES`)."""
    folder = Path(folder)
    found = []
    for name in OUTPUT_NAMES:
        path = folder / name
        if path.is_dir() and not path.is_symlink():
            if any(p.is_file() for p in path.rglob("*")):  # empty folders hold no results
                found.append(path)
        elif path.exists() or path.is_symlink():
            found.append(path)
    return found


def clear_outputs(folder: str | os.PathLike) -> list[Path]:
    """Remove an earlier run's outputs from ``folder`` (nothing else); returns what was removed."""
    removed = previous_outputs(folder)
    for path in removed:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()
    return removed
