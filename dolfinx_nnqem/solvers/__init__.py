"""The solvers and what drives them.

The contract (:mod:`~dolfinx_nnqem.solvers.contract`), the options (:mod:`.options`) and the
registry (:func:`make_solver`) apart; the three methods (:mod:`.monolithic`, :mod:`.nneqm1`,
:mod:`.nneqm2`, the last two composing the condensed contact problem of :mod:`.condensed`); their
linear algebra (:mod:`.condensation`, :mod:`.block_system`, :mod:`.linear_solver`,
:mod:`.preflight`); load stepping (:mod:`.stepping`, :mod:`.step_control`) with the independent
check of every converged state (:mod:`.checks`) and the reports (:mod:`.convergence`).
"""

from dolfinx_nnqem.solvers.checks import CheckOptions
from dolfinx_nnqem.solvers.contract import Solver
from dolfinx_nnqem.solvers.convergence import ConvergenceError, SolveReport
from dolfinx_nnqem.solvers.options import (METHODS, MonolithicOptions, NNEQM1Options, NNEQM2Options,
                                           SolverOptions)
from dolfinx_nnqem.solvers.registry import make_solver
from dolfinx_nnqem.solvers.step_control import AutomaticIncrements
from dolfinx_nnqem.solvers.stepping import IncrementResult, solve_load_path, solve_load_steps

__all__ = ["METHODS", "AutomaticIncrements", "CheckOptions", "ConvergenceError", "IncrementResult",
           "MonolithicOptions", "NNEQM1Options", "NNEQM2Options", "SolveReport", "Solver", "SolverOptions",
           "make_solver", "solve_load_path", "solve_load_steps"]
