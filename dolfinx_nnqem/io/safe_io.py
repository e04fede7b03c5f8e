"""Files that are either complete or absent: write to a temporary name, then rename.

A crash (SIGKILL, power loss) or a full disk in the middle of a write leaves at most a temporary
file (``.NAME.tmp-PID``), never a truncated file under the real name; a failed write removes its
temporary and raises :class:`OutputError` naming the file. :func:`remove_stale_temporaries`
clears what a killed run left.
"""

from __future__ import annotations

import errno as _errno
import os
from collections.abc import Callable
from pathlib import Path

__all__ = ["OutputError", "atomic_write", "atomic_write_text", "fsync_directory", "remove_stale_temporaries"]


class OutputError(OSError):
    """Writing a result file failed (full disk, no permission, ...); the message names the file."""


def _temporary(path: Path) -> Path:
    return path.with_name(f".{path.name}.tmp-{os.getpid()}")


def fsync_directory(folder: Path) -> None:
    """Make a rename in ``folder`` durable (ignored where directories cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write(path: str | os.PathLike, write: Callable[[Path], object], *, durable: bool = True) -> None:
    """Create ``path`` through ``write(temporary_path)`` and an atomic rename.

    ``write`` writes the whole file at the temporary path it is given (any library can: csv,
    VTK, h5py). On any error the temporary is removed and :class:`OutputError` names ``path``.
    """
    path = Path(path)
    tmp = _temporary(path)
    try:
        write(tmp)
        if durable:
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as error:
        try:
            tmp.unlink()
        except FileNotFoundError:
            pass
        if isinstance(error, OutputError) or not isinstance(error, (OSError, RuntimeError)):
            raise
        code = getattr(error, "errno", None) or _errno.EIO
        reason = getattr(error, "strerror", None) or str(error)
        raise OutputError(code, f"cannot write {path}: {reason}", str(path)) from error
    if durable:
        fsync_directory(path.parent)


def atomic_write_text(path: str | os.PathLike, text: str, *, durable: bool = True) -> None:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write`)."""
    atomic_write(path, lambda tmp: tmp.write_text(text), durable=durable)


def remove_stale_temporaries(folder: str | os.PathLike) -> list[Path]:
    """Remove the temporaries (``.NAME.tmp-PID``) that killed runs left under ``folder``."""
    removed: list[Path] = []
    folder = Path(folder)
    if not folder.is_dir():
        return removed
    for tmp in folder.rglob(".*.tmp-*"):
        try:
            if tmp.is_dir():
                import shutil

                shutil.rmtree(tmp)
            else:
                tmp.unlink()
            removed.append(tmp)
        except OSError:
            pass
    return removed
