"""A small step file written in memory (tmpfs) and copied whole into the output folder.

DOLFINx's ``XDMFFile`` saves its XML file again after every ``write_mesh`` and
``write_function``: a step of the fields with its mesh and six functions truncates and rewrites
its ``.xdmf`` seven times. On ext4 (``auto_da_alloc``, the default) closing a file that was
truncated starts its write-back, and the next truncation waits for that write to reach the
disk: every rewrite costs a disk round trip, and more on a disk shared with other jobs
(``docs/performance.md``, "Parameter studies"). Written in a tmpfs folder instead, the step
file is then copied into place as two new files (``.h5``, then ``.xdmf``): the same bytes,
written once each. The copy is complete before the index that lists the step is staged, and the
increment's commit point (:func:`dolfinx_nnqem.io.safe_io.commit`) makes it durable as before.

Only in serial (an HDF5 file written by several ranks must be on a file system that every rank
sees), for step files up to :data:`LARGEST_STEP_BYTES` (a large step file would take its size in
memory; its rewrites of the small XML file are then a small part of its cost), and when the
tmpfs has room for twice the step. A process killed while it wrote a step leaves its memory folder
(``/dev/shm/dolfinx-nnqem-step-PID-*``); the next process that writes a step ten minutes or more
later removes it.
"""

from __future__ import annotations

import errno as _errno
import functools
import os
import shutil
import tempfile
import time
from pathlib import Path

from dolfinx_nnqem.io.safe_io import OutputError

__all__ = ["LARGEST_STEP_BYTES", "MEMORY_FOLDER", "copy_step_files", "memory_folder", "remove_memory_folder"]

MEMORY_FOLDER = Path("/dev/shm")
"""The tmpfs the step files are written in (Linux's shared-memory file system)."""

PREFIX = "dolfinx-nnqem-step-"
"""The memory folders' names: the prefix, the writing process's id, a random part."""

STALE_AFTER_S = 600.0
"""How long a memory folder of a process that is not seen alive stays before it is removed."""

LARGEST_STEP_BYTES = 64 * 1024 * 1024
"""The largest step file (its estimated size) written in memory first."""


def memory_folder(ranks: int, needed: int) -> Path | None:
    """A new empty folder in :data:`MEMORY_FOLDER` for one step file of about ``needed`` bytes, or
    None where the step is to be written in place: several ``ranks``, a step larger than
    :data:`LARGEST_STEP_BYTES`, no writable tmpfs, or less room there than twice ``needed``."""
    if ranks != 1 or needed > LARGEST_STEP_BYTES or not os.access(MEMORY_FOLDER, os.W_OK):
        return None
    try:
        st = os.statvfs(MEMORY_FOLDER)
        if st.f_bavail * st.f_frsize < 2 * needed:
            return None
        _remove_stale_memory_folders()
        return Path(tempfile.mkdtemp(prefix=f"{PREFIX}{os.getpid()}-", dir=MEMORY_FOLDER))
    except OSError:
        return None


@functools.cache
def _remove_stale_memory_folders() -> None:
    """Remove, once per process, the memory folders that killed processes left (a SIGKILL while a
    step was written): the name holds the writing process's id. Only folders untouched for
    :data:`STALE_AFTER_S` as well: a process of another PID namespace that shares the tmpfs (a
    container with the host's IPC) is not seen alive from here, and its step takes seconds."""
    now = time.time()
    for folder in MEMORY_FOLDER.glob(f"{PREFIX}*-*"):
        pid = folder.name[len(PREFIX):].split("-")[0]
        try:
            stale = now - folder.stat().st_mtime > STALE_AFTER_S
        except OSError:  # removed meanwhile
            continue
        if stale and pid.isdigit() and not _alive(int(pid)):
            remove_memory_folder(folder)


def _alive(pid: int) -> bool:
    """True if process ``pid`` exists (or is another user's: its folder is not ours to remove)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def copy_step_files(source: Path, target: Path) -> None:
    """Copy the step file ``source`` (``.xdmf`` and its ``.h5``) to ``target`` (the ``.xdmf``'s
    path), the ``.h5`` first: its XML refers to the ``.h5`` by file name, which stays the same.
    A failed copy (a full disk) removes what it wrote and raises :class:`OutputError` naming the
    file."""
    for suffix in (".h5", ".xdmf"):
        destination = target.with_suffix(suffix)
        try:
            shutil.copyfile(source.with_suffix(suffix), destination)
        except OSError as error:
            for written in (target.with_suffix(".h5"), destination):
                written.unlink(missing_ok=True)
            raise OutputError(error.errno or _errno.EIO, f"cannot write {destination}: {error.strerror or error}",
                              str(destination)) from error


def remove_memory_folder(folder: Path) -> None:
    """Remove ``folder`` (made by :func:`memory_folder`) and what it holds."""
    shutil.rmtree(folder, ignore_errors=True)
