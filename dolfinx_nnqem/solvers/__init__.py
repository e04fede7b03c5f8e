"""The solvers and what drives them.

The contract (:mod:`~dolfinx_nnqem.solvers.contract`), the options (:mod:`.options`) and the
registry (:func:`make_solver`) apart; the three methods (:mod:`.monolithic`, :mod:`.nneqm1`,
:mod:`.nneqm2`, the last two composing the condensed contact problem of :mod:`.condensed`); their
linear algebra (:mod:`.condensation`, :mod:`.block_system`, :mod:`.linear_solver`,
:mod:`.preflight`); load stepping (:mod:`.stepping`, :mod:`.step_control`) with the independent
check of every converged state (:mod:`.checks`) and the reports (:mod:`.convergence`).

The names below are imported on first use (PEP 562): importing one module of the package (its
options, say) imports no solver, PETSc or DOLFINx with it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from dolfinx_nnqem.solvers.checks import CheckOptions
    from dolfinx_nnqem.solvers.contract import Solver
    from dolfinx_nnqem.solvers.convergence import ConvergenceError, SolveReport
    from dolfinx_nnqem.solvers.options import (METHODS, MonolithicOptions, NNEQM1Options, NNEQM2Options,
                                               SolverOptions)
    from dolfinx_nnqem.solvers.registry import make_solver
    from dolfinx_nnqem.solvers.step_control import AutomaticIncrements
    from dolfinx_nnqem.solvers.stepping import IncrementResult, solve_load_path, solve_load_steps

_WHERE = {
    "CheckOptions": "checks", "Solver": "contract", "ConvergenceError": "convergence", "SolveReport": "convergence",
    "METHODS": "options", "MonolithicOptions": "options", "NNEQM1Options": "options", "NNEQM2Options": "options",
    "SolverOptions": "options", "make_solver": "registry", "AutomaticIncrements": "step_control",
    "IncrementResult": "stepping", "solve_load_path": "stepping", "solve_load_steps": "stepping",
}
"""Each public name of the package and the module that defines it."""

__all__ = ["METHODS", "AutomaticIncrements", "CheckOptions", "ConvergenceError", "IncrementResult",
           "MonolithicOptions", "NNEQM1Options", "NNEQM2Options", "SolveReport", "Solver", "SolverOptions",
           "make_solver", "solve_load_path", "solve_load_steps"]


def __getattr__(name: str) -> Any:
    """The public name ``name``, imported from its module on first use."""
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_WHERE[name]}"), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
