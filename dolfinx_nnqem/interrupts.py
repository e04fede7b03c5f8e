"""Ctrl-C and SIGTERM in the command line: held during the start-up, remembered during the run,
held again once the run's outcome is final.

The command line ends every run by its exit-code contract (130 after Ctrl-C, 143 after SIGTERM,
one line, the summary saying "interrupted"; ``docs/reliability.md``). What stood in its way is
handled here:

* an interrupt during the first imports showed a KeyboardInterrupt traceback, and a SIGTERM met
  PETSc's own handler (an error dump, exit 15): :func:`hold` defers both signals from the
  package's first line on, in the command line only (never in a user's program), and
  :func:`hold_in_command_line` renews the hold after PETSc's set-up;
* an error raised while an interrupt was being handled (VTK's lazy importer turns the
  KeyboardInterrupt into an ImportError) must still be reported as the interrupt:
  :data:`received` remembers the signals the command line's handlers acted on;
* a signal after the run's outcome is final (``summary.json`` written, the pictures drawn) ended
  the command with 130 while the summary said "completed": :func:`end_of_run` makes the command
  line's handlers hold such a signal instead (:data:`run_over`).

This module imports nothing of the package, and only ``signal`` and ``sys`` before the hold:
``dolfinx_nnqem/__init__.py`` imports it first, and in the command line importing it holds
the signals (:func:`hold`).
"""

from __future__ import annotations

import signal
import sys

__all__ = ["deferred", "received", "run_over", "defer", "end_of_run", "hold", "is_command_line",
           "hold_in_command_line", "held"]

deferred: list[int] = []
"""Signals received while the command line was starting (imports, MPI and PETSc set-up), or
after its run's outcome was final: :func:`dolfinx_nnqem.cli.main` acts on the first ones once
its own handlers are in place, and ignores the last ones (the exit code is the run's)."""

received: list[int] = []
"""Signals the command line's handlers raised an exception for during this run."""

run_over = False
"""The run's outcome is final (:func:`end_of_run`): the command line's handlers only record a
signal in :data:`deferred` (``dolfinx_nnqem.cli`` resets it when it starts another run)."""


def defer(signum: int, frame: object) -> None:
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


if is_command_line():  # the package's first line runs this: hold before anything else is imported
    hold()


def end_of_run() -> None:
    """The run's outcome is final: ``summary.json`` has its last status and the pictures are
    drawn (called at the end of :meth:`~dolfinx_nnqem.io.output.ResultsWriter.close`). In the
    command line a signal from now on is held, not acted on: the exit code stays the one
    ``summary.json`` gives. Elsewhere (a user's program) it does nothing."""
    global run_over
    if is_command_line():
        run_over = True


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


class held:
    """``with held():`` holds SIGINT and SIGTERM for a short block that must not stop half-way
    (the renames of a commit point: an interrupt between two of them left a staged temporary
    behind); a signal received meanwhile is raised again, to the handler in place before, when
    the block ends. Never around a collective call (a rank held there could not be interrupted
    at all). Outside the main thread, where Python runs no handler, it holds nothing."""

    def __enter__(self) -> None:
        import threading

        self._pending: list[int] = []
        main = threading.current_thread() is threading.main_thread()
        signums = (signal.SIGINT, signal.SIGTERM) if main else ()
        self._previous = {int(signum): signal.getsignal(signum) for signum in signums}
        for signum in signums:
            signal.signal(signum, lambda number, frame: self._pending.append(number))

    def __exit__(self, *exc_info) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)
        if self._pending:
            _deliver(self._pending[0], self._previous[self._pending[0]])


def _deliver(signum: int, handler) -> None:
    """Act on a held signal as ``handler`` would have, here and now: a Python handler is called
    directly, so that its exception rises at this point of the program (``signal.raise_signal``
    would run it at the next bytecode, which may be inside a finaliser, where Python only prints
    the exception and the run goes on)."""
    if callable(handler):
        handler(signum, None)
    elif handler == signal.SIG_DFL:
        signal.raise_signal(signum)
