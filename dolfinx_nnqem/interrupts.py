"""Ctrl-C and SIGTERM in the command line: held during the start-up, remembered during the run.

The command line ends every run by its exit-code contract (130 after Ctrl-C, 143 after SIGTERM,
one line, the summary saying "interrupted"). Two things stood in its way and are handled here:

* an interrupt during the first imports showed a KeyboardInterrupt traceback, and a SIGTERM met
  PETSc's own handler (an error dump, exit 15): :func:`hold` defers both signals from the
  package's first import on, in the command line only (never in a user's program), and
  :func:`hold_in_command_line` renews the hold after PETSc's set-up;
* an error raised while an interrupt was being handled (VTK's lazy importer turns the
  KeyboardInterrupt into an ImportError) must still be reported as the interrupt:
  :data:`received` remembers the signals the command line's handlers acted on.

This module imports nothing of the package: ``dolfinx_nnqem/__init__.py`` calls it first.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator

__all__ = ["deferred", "received", "defer", "hold", "is_command_line", "hold_in_command_line"]

deferred: list[int] = []
"""Signals received while the command line was starting (imports, MPI and PETSc set-up):
:func:`dolfinx_nnqem.cli.main` acts on them once its own handlers are in place."""

received: list[int] = []
"""Signals the command line's handlers raised an exception for during this run."""


def defer(signum: int, frame) -> None:
    """A signal handler that only records the signal in :data:`deferred`."""
    deferred.append(signum)


def is_command_line() -> bool:
    """This process runs ``dolfinx-nnqem`` or ``python -m dolfinx_nnqem`` (not a user's program)."""
    argv = getattr(sys, "orig_argv", sys.argv)
    return sys.argv[0].rsplit("/", 1)[-1] == "dolfinx-nnqem" or any(
        a == "-m" and b == "dolfinx_nnqem" for a, b in zip(argv, argv[1:]))


def hold() -> None:
    """Defer SIGINT and SIGTERM (record them in :data:`deferred`)."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, defer)


def hold_in_command_line() -> None:
    """Defer SIGINT and SIGTERM until ``cli.main`` can end the run by the exit-code contract.

    PETSc installs its SIGTERM handler at the C level when it initialises: it is initialised here
    at once (after ``dolfinx_solver``, as the PyPI wheel needs) and the hold renewed, before the
    long imports. The command line calls this once it has read its arguments (``--help`` and a
    bad command line need no MPI and no PETSc).
    """
    hold()
    try:
        import dolfinx_solver  # noqa: F401  (the PyPI wheel: before petsc4py)
    except ImportError:
        pass
    from petsc4py import PETSc  # noqa: F401

    hold()


@contextlib.contextmanager
def held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM for a short block that must not stop half-way (the renames of a
    commit point: an interrupt between two of them left a staged temporary behind); a signal
    received meanwhile is raised again, to the handler in place before, when the block ends.
    Never around a collective call (a rank held there could not be interrupted at all). Outside
    the main thread, where Python runs no handler, it holds nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    signums = (signal.SIGINT, signal.SIGTERM)
    previous = {int(signum): signal.getsignal(signum) for signum in signums}
    for signum in signums:
        signal.signal(signum, lambda number, frame: pending.append(number))
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        if pending:
            _deliver(pending[0], previous[pending[0]])


def _deliver(signum: int, handler) -> None:
    """Act on a held signal as ``handler`` would have, here and now: a Python handler is called
    directly, so that its exception rises at this point of the program (``signal.raise_signal``
    would run it at the next bytecode, which may be inside a finaliser, where Python only prints
    the exception and the run goes on)."""
    if callable(handler):
        handler(signum, None)
    elif handler == signal.SIG_DFL:
        signal.raise_signal(signum)
