"""An error on one MPI rank is an error on every rank: agreement helpers.

A rank that raises while the others go on waits for nothing, but the others then wait forever
in their next collective call. Code that may fail on some ranks only (files written by rank 0,
a value one rank finds bad) runs through :func:`agree` / :func:`on_rank0`: every rank learns
whether any rank failed, and every rank raises the same exception (the lowest failing rank's
type and message). What cannot be made collective (a failure inside a collective library call)
is handled by the command line's last resort: :func:`finish_collectively` waits a bounded time
for the other ranks to fail too, and otherwise aborts the whole job with the exit code.
"""

from __future__ import annotations

import faulthandler
import os
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from mpi4py import MPI

__all__ = ["CollectiveError", "abort_unless_ended", "agree", "disarm_abort", "end_job", "finish_collectively",
           "on_rank0", "rebuild"]

ABORT_TIMEOUT_S = float(os.environ.get("NNQEM_ABORT_TIMEOUT", "10"))
"""How long a failing rank waits for the others to fail too before aborting the job (seconds)."""
ABORT_GRACE_S = 0.5
"""Time given to mpiexec to forward the failing rank's message before the abort (seconds)."""


class CollectiveError(RuntimeError):
    """Another rank failed (its exception could not be rebuilt here as its own type)."""


_REBUILDABLE = (ValueError, TypeError, OSError, KeyboardInterrupt, RuntimeError, LookupError)


def _describe(error: BaseException) -> tuple:
    module = type(error).__module__
    errno = getattr(error, "errno", None) if isinstance(error, OSError) else None
    filename = getattr(error, "filename", None) if isinstance(error, OSError) else None
    strerror = getattr(error, "strerror", None) if isinstance(error, OSError) else None
    return (module, type(error).__qualname__, str(error), errno, strerror, filename)


def rebuild(description: tuple) -> BaseException:
    """An exception like the one ``description`` (from another rank) describes."""
    module, name, message, errno, strerror, filename = description
    cls = None
    try:
        import importlib

        cls = getattr(importlib.import_module(module), name.split(".")[-1], None)
    except Exception:
        cls = None
    if isinstance(cls, type) and issubclass(cls, OSError) and errno is not None:
        return cls(errno, strerror or message, filename) if filename else cls(errno, strerror or message)
    if isinstance(cls, type) and issubclass(cls, _REBUILDABLE):
        try:
            return cls(message)
        except Exception:
            pass
    return CollectiveError(f"{name}: {message}")


def agree(comm: MPI.Comm | None, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """``fn(*args, **kwargs)`` on every rank; if it raised on any rank, raise on every rank.

    Every rank raises the exception of the lowest rank that failed (its type, message, errno
    and file name), so every rank stops with the same message. ``fn`` must not be collective
    itself (use this around rank-local work: files, checks of local data).
    """
    error = None
    result = None
    try:
        result = fn(*args, **kwargs)
    except BaseException as exc:  # noqa: BLE001  (KeyboardInterrupt must also reach every rank)
        error = exc
    if comm is None or comm.size == 1:
        if error is not None:
            raise error
        return result
    failures = comm.allgather(None if error is None else _describe(error))
    first = next((f for f in failures if f is not None), None)
    if first is None:
        return result
    if error is not None and failures.index(first) == comm.rank:
        raise error
    raise rebuild(first) from error


def on_rank0(comm: MPI.Comm | None, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """``fn`` on rank 0 only (files of a gathered result); its failure is raised on every rank.
    Returns fn's result on rank 0, None elsewhere."""
    rank = 0 if comm is None else comm.rank
    return agree(comm, lambda: fn(*args, **kwargs) if rank == 0 else None)


_ERROR_COMM = None


def error_comm() -> MPI.Comm | None:
    """A private duplicate of COMM_WORLD used only by :func:`finish_collectively` (created
    collectively at start-up by :func:`init`)."""
    return _ERROR_COMM


def init() -> None:
    """Create the private error communicator (collective; call once at start-up on every rank)."""
    global _ERROR_COMM
    if _ERROR_COMM is None and MPI.COMM_WORLD.size > 1:
        _ERROR_COMM = MPI.COMM_WORLD.Dup()


def finish_collectively(code: int, message: str, *, timeout: float | None = None) -> tuple[int, str]:
    """Agree with the other ranks on how the job ends after an error on this rank.

    Every rank that fails calls this. If all ranks arrive within ``timeout`` seconds, they agree
    on the lowest rank's (code, message), which is returned on every rank (rank 0 prints it).
    If some rank does not arrive (it waits in a collective call for this one), the message is
    printed by this rank and the whole job is aborted with ``code``: no rank hangs.
    """
    comm = _ERROR_COMM
    if comm is None or comm.size == 1:
        return code, message
    timeout = ABORT_TIMEOUT_S if timeout is None else timeout
    request = comm.Ibarrier()
    deadline = time.monotonic() + timeout
    while not request.Test():
        if time.monotonic() > deadline:
            sys.stderr.write(f"{message}\n(rank {comm.rank}: the other ranks did not stop within {timeout:g} s; "
                             f"aborting the job with exit code {code})\n")
            sys.stderr.flush()
            # mpiexec forwards a rank's stderr through a pipe; an abort at once can kill the
            # forwarding before the message is through (seen on CI: exit code right, no message)
            time.sleep(ABORT_GRACE_S)
            MPI.COMM_WORLD.Abort(code)
        time.sleep(0.01)
    outcomes = comm.allgather((code, message))
    return outcomes[0] if outcomes[0][0] != 0 else next((o for o in outcomes if o[0] != 0), (code, message))


def end_job(code: int) -> None:
    """End the process (the whole job under MPI) with ``code`` now, without the libraries'
    clean-up at exit (for a state they cannot clean up, e.g. an HDF5 file that cannot be
    closed). The caller has printed its message."""
    sys.stdout.flush()
    sys.stderr.flush()
    if MPI.COMM_WORLD.size > 1:
        time.sleep(ABORT_GRACE_S)  # let mpiexec forward the message first (see finish_collectively)
        MPI.COMM_WORLD.Abort(code)
    os._exit(code)


_WATCHDOG: threading.Timer | None = None


def abort_unless_ended(code: int, reason: str, timeout: float | None = None) -> None:
    """Abort the whole job with ``code`` if this process has not ended ``timeout`` seconds from now
    (default: twice :data:`ABORT_TIMEOUT_S` plus 5 s); under MPI with several ranks only, armed once.

    For an interrupt: each rank meets the signal wherever it is, and a rank that stops between
    two collective calls can leave another waiting in a call it will never make, a collective
    that neither :func:`agree` nor :func:`finish_collectively` reaches (measured on OpenMPI: 1 of
    6 runs with SIGINT sent to the two ranks alone waited forever). A timer thread aborts the job
    when the main thread waits in MPI (mpi4py releases the GIL there); should the main thread
    hold the GIL inside a library call, ``faulthandler`` ends this rank 10 s later (it needs no
    GIL; exit code 1, the job's launcher then ends the other ranks).
    """
    global _WATCHDOG
    # an interrupt in the start-up can come after mpi4py's import and before MPI_Init (or after
    # MPI_Finalize): no job to hang then, and asking COMM_WORLD its size would abort the process
    if _WATCHDOG is not None or not MPI.Is_initialized() or MPI.Is_finalized() or MPI.COMM_WORLD.size == 1:
        return
    timeout = 2 * ABORT_TIMEOUT_S + 5 if timeout is None else timeout
    rank = MPI.COMM_WORLD.rank

    def fire() -> None:
        sys.stderr.write(f"dolfinx-nnqem: {reason}; rank {rank} had not ended {timeout:g} s later (the ranks "
                         f"stopped at different collective calls): aborting the job with exit code {code}\n")
        sys.stderr.flush()
        time.sleep(ABORT_GRACE_S)  # let mpiexec forward the message first (see finish_collectively)
        MPI.COMM_WORLD.Abort(code)

    _WATCHDOG = threading.Timer(timeout, fire)
    _WATCHDOG.daemon = True
    _WATCHDOG.start()
    faulthandler.dump_traceback_later(timeout + 10, exit=True)


def disarm_abort() -> None:
    """Cancel :func:`abort_unless_ended` (the run ended; an in-process caller goes on)."""
    global _WATCHDOG
    if _WATCHDOG is not None:
        _WATCHDOG.cancel()
        faulthandler.cancel_dump_traceback_later()
        _WATCHDOG = None
