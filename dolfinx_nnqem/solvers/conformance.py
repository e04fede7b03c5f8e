"""The package's implementations, held to their contracts by the type checker.

Each function below returns an implementation as its Protocol; the type checker (mypy, run by
``.ci/run``) verifies that the implementation has every member of the Protocol with compatible
signatures, and ``tests/unit/test_contracts.py`` calls these functions on real objects to check the
same at run time. A new solver, pair set or obstacle adds a line here; a material, in
:mod:`dolfinx_nnqem.material.conformance` (re-exported here) (``CONTRIBUTING.md``).
"""

from __future__ import annotations

from dolfinx_nnqem.contact.obstacles import ObstaclePairs
from dolfinx_nnqem.contact.pairs import ContactPairs
from dolfinx_nnqem.contact.pairset import PairSet
from dolfinx_nnqem.contact.surface_pairs import SurfacePairs
from dolfinx_nnqem.material.conformance import (as_material, as_material_part, as_material_state,  # noqa: F401
                                                as_pointwise_material, as_pointwise_plasticity)
from dolfinx_nnqem.problem.contact_problem import ContactProblem
from dolfinx_nnqem.solvers.contract import CondensingSolver, SolvableProblem, Solver
from dolfinx_nnqem.solvers.monolithic import MonolithicSolver
from dolfinx_nnqem.solvers.nneqm1 import NNEQM1Solver
from dolfinx_nnqem.solvers.nneqm2 import NNEQM2Solver

__all__ = ["as_condensing_solver", "as_material", "as_material_part", "as_material_state", "as_pair_set",
           "as_pointwise_material", "as_pointwise_plasticity", "as_problem", "as_solver"]


def as_solver(solver: MonolithicSolver | NNEQM1Solver | NNEQM2Solver) -> Solver:
    """``solver`` as a :class:`~dolfinx_nnqem.solvers.contract.Solver` (checked by the type checker)."""
    return solver


def as_condensing_solver(solver: NNEQM1Solver) -> CondensingSolver:
    """``solver`` as a :class:`~dolfinx_nnqem.solvers.contract.CondensingSolver`, what the FCLIB
    export reads of it (checked by the type checker)."""
    return solver


def as_problem(problem: ContactProblem) -> SolvableProblem:
    """``problem`` as a :class:`~dolfinx_nnqem.solvers.contract.SolvableProblem` (checked by the type checker)."""
    return problem


def as_pair_set(pairs: ContactPairs | SurfacePairs | ObstaclePairs) -> PairSet:
    """``pairs`` as a :class:`~dolfinx_nnqem.contact.pairset.PairSet` (checked by the type checker)."""
    return pairs
