"""Files that are either complete or absent: write to a temporary name, then rename.

A crash (SIGKILL, power loss) or a full disk in the middle of a write leaves at most a temporary
file (``.NAME.tmp-PID``), never a truncated file under the real name; a failed write removes its
temporary and raises :class:`OutputError` naming the file. :func:`remove_stale_temporaries`
clears what a killed run left.

A run's increment is made durable at one commit point (:func:`commit`) instead of an ``fsync``
per file: its new files are written (not synced), the index files that will list them are
staged (:class:`StagedFiles`: written to their temporaries), then one sync of the file system
makes all of it durable, and only then are the staged files renamed into place. An index file
therefore never lists a file that a power loss could take away; a rename that the power loss
takes away leaves the previous index, which lists the previous increments. Each rename becomes
durable with the next commit point's sync (or the run's last one, :meth:`StagedFiles.commit_here`).
After a SIGKILL nothing is lost that was written: the kernel keeps the data.
"""

from __future__ import annotations

import errno as _errno
import functools
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from dolfinx_nnqem import interrupts
from dolfinx_nnqem.collective import agree, on_rank0

if TYPE_CHECKING:
    from mpi4py import MPI

__all__ = ["OutputError", "StagedFiles", "atomic_write", "atomic_write_text", "commit", "fsync_directory",
           "remove_stale_temporaries", "remove_temporaries_of", "sync_file_system"]


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
    ``durable=False`` leaves the file to the next commit point's sync (:func:`commit`): no
    ``fsync`` of the file and its folder.
    """
    path = Path(path)
    tmp = _temporary(path)
    _write_temporary(path, tmp, write, durable)
    if durable:
        fsync_directory(path.parent)


def _write_temporary(path: Path, tmp: Path, write: Callable[[Path], object], durable: bool,
                     rename: bool = True) -> None:
    """``write(tmp)``, fsync'd if ``durable``, renamed to ``path`` if ``rename``; any error
    removes ``tmp`` and raises :class:`OutputError` naming ``path``."""
    try:
        write(tmp)
        if durable:
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
        if rename:
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


def atomic_write_text(path: str | os.PathLike, text: str, *, durable: bool = True) -> None:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write`)."""
    atomic_write(path, lambda tmp: tmp.write_text(text), durable=durable)


def sync_file_system(folder: str | os.PathLike) -> None:
    """Make every file written so far on ``folder``'s file system durable: one ``syncfs`` (Linux),
    else ``sync``. Measured on the development machine: eight new 30 kB files and one syncfs
    cost what writing them alone costs, an fsync per file and folder 2.6 times that
    (``docs/performance.md``)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        os.sync()
        return
    try:
        if _syncfs(fd) != 0:
            os.sync()
    finally:
        os.close(fd)


def _syncfs(fd: int) -> int:
    """libc's ``syncfs(fd)``; -1 where there is none (not Linux)."""
    syncfs = _libc_syncfs()
    return -1 if syncfs is None else int(syncfs(fd))


@functools.cache
def _libc_syncfs() -> Callable[[int], int] | None:
    """libc's ``syncfs``, looked up once; None where there is none."""
    try:
        import ctypes

        return ctypes.CDLL(None, use_errno=True).syncfs
    except (OSError, AttributeError):
        return None


class StagedFiles:
    """Files to replace at the next commit point (:func:`commit`): each is written to its
    temporary now and renamed into place after the sync."""

    def __init__(self) -> None:
        self._files: dict[Path, Path] = {}  # real name -> its written temporary

    def __bool__(self) -> bool:
        return bool(self._files)

    def stage(self, path: str | os.PathLike, text: str) -> None:
        """Write ``text`` to ``path``'s temporary (a later stage of the same path replaces it)."""
        path = Path(path)
        tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}-staged")  # not atomic_write's temporary
        with interrupts.held():  # the temporary is written and listed, or neither
            _write_temporary(path, tmp, lambda t: t.write_text(text), durable=False, rename=False)
            self._files[path] = tmp

    def replace_all(self) -> None:
        """Rename every staged file into place, in the order staged (call after a sync)."""
        with interrupts.held():  # every rename, or none (an interrupt half-way left a temporary)
            files, self._files = self._files, {}
            for path, tmp in files.items():
                try:
                    os.replace(tmp, path)
                except OSError as error:
                    raise OutputError(error.errno or _errno.EIO, f"cannot write {path}: {error.strerror}",
                                      str(path)) from error

    def commit_here(self, folder: str | os.PathLike) -> None:
        """Sync and replace on this rank alone (the end of a run, which may be no collective
        moment: an error or an interrupt that some ranks have not seen). Every staged file
        refers to files that were complete when it was staged."""
        if self._files:
            sync_file_system(folder)
            self.replace_all()
        sync_file_system(folder)  # the renames too: nothing follows to make them durable

    def discard(self) -> None:
        """Remove the staged temporaries (nothing is renamed)."""
        with interrupts.held():
            files, self._files = self._files, {}
            for tmp in files.values():
                try:
                    tmp.unlink()
                except OSError:
                    pass


def commit(comm: MPI.Comm | None, folder: str | os.PathLike, *staged: StagedFiles) -> None:
    """The durable commit point of an increment (collective): every rank syncs the file system
    of ``folder`` (its own new files, a checkpoint's rank file among them), then rank 0 renames
    the staged files into place. A failure on any rank is raised on every rank."""
    agree(comm, sync_file_system, folder)
    def replace() -> None:
        for files in staged:
            files.replace_all()

    on_rank0(comm, replace)


def remove_temporaries_of(folder: str | os.PathLike, pid: int) -> list[Path]:
    """Remove the temporaries that process ``pid`` left in ``folder`` (not below it): a picture
    worker the run killed while it drew (:mod:`dolfinx_nnqem.io.picture_worker`)."""
    removed: list[Path] = []
    folder = Path(folder)
    for pattern in (f".*.tmp-{pid}", f".*.tmp-{pid}.*", f".*.tmp-{pid}-staged"):
        for tmp in folder.glob(pattern):
            try:
                tmp.unlink()
                removed.append(tmp)
            except OSError:  # a folder of that name, or gone meanwhile
                pass
    return removed


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
