"""The solvers by name: ``make_solver("monolithic" | "nneqm1" | "nneqm2", problem, options)``."""

from __future__ import annotations

METHODS = ("monolithic", "nneqm1", "nneqm2")


def make_solver(method: str, problem, options=None, **kwargs):
    """The solver called ``method`` for ``problem`` (:class:`~dolfinx_nnqem.problem.SolverOptions`)."""
    method = method.lower()
    if method == "monolithic":
        from dolfinx_nnqem.monolithic import MonolithicSolver

        return MonolithicSolver(problem, options, **kwargs)
    if method == "nneqm1":
        from dolfinx_nnqem.nneqm1 import NNEQM1Solver

        return NNEQM1Solver(problem, options, **kwargs)
    if method == "nneqm2":
        from dolfinx_nnqem.nneqm2 import NNEQM2Solver

        return NNEQM2Solver(problem, options, **kwargs)
    raise ValueError(f"unknown method {method!r}; expected one of {list(METHODS)}")
