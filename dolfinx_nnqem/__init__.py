"""dolfinx_nnqem: elastoplastic frictional contact in DOLFINx by nonsmooth equations (NNEQM).

``compat`` is imported first: with the PyPI wheel, ``dolfinx_solver`` must be loaded before
``dolfinx`` and ``petsc4py``.
"""

import signal as _signal
import sys as _sys

deferred_signals: list[int] = []
"""Ctrl-C / SIGTERM received while the command line was starting (imports, MPI and PETSc set-up):
:func:`dolfinx_nnqem.cli.main` acts on them once its own handlers are in place."""


received_signals: list[int] = []
"""Ctrl-C / SIGTERM the command line's handlers raised an exception for during this run: an error
raised while one was being handled (e.g. VTK's importer turns the KeyboardInterrupt of a lazy
import into an ImportError) is reported as the interrupt."""


def _defer_signal(signum, frame) -> None:
    deferred_signals.append(signum)


def _is_command_line() -> bool:
    """This process runs ``dolfinx-nnqem`` or ``python -m dolfinx_nnqem`` (not a user's program)."""
    argv = getattr(_sys, "orig_argv", _sys.argv)
    return _sys.argv[0].rsplit("/", 1)[-1] == "dolfinx-nnqem" or any(
        a == "-m" and b == "dolfinx_nnqem" for a, b in zip(argv, argv[1:]))


def _hold_signals_in_command_line() -> None:
    """In the command line only: hold SIGINT and SIGTERM until ``cli.main`` can end the run by the
    exit-code contract. Without this an interrupt during the first 0.3 s (these imports) showed
    a KeyboardInterrupt traceback, and a SIGTERM met PETSc's handler (an error dump, exit 15).
    PETSc takes SIGTERM at the C level when it initialises: it is initialised here at once (after
    dolfinx_solver, as the PyPI wheel needs), and the hold renewed, before the long imports."""
    def hold():
        for signum in (_signal.SIGINT, _signal.SIGTERM):
            _signal.signal(signum, _defer_signal)

    hold()
    try:
        import dolfinx_solver  # noqa: F401  (the PyPI wheel: before petsc4py)
    except ImportError:
        pass
    from petsc4py import PETSc  # noqa: F401

    hold()


if _is_command_line():
    _hold_signals_in_command_line()
from dolfinx_nnqem import compat  # noqa: E402, F401  (before dolfinx / petsc4py in a user's program)

__version__ = "0.1.0"
