"""The iterative solver's inexact-Newton forcing rules and the resumed solve after a lagged AMG
hierarchy is rebuilt (``dolfinx_nnqem.solvers.linear_solver.IterativeSolver``)."""

import math

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

import dolfinx.fem as fem
import dolfinx.mesh

from dolfinx_nnqem.solvers.linear_solver import IterativeSolver
from dolfinx_nnqem.solvers.options import FORCING_RULES, MonolithicOptions

RTOL = 1e-10


def _solver(forcing: str, max_forcing: float = 1e-2) -> IterativeSolver:
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 1, 1, 1)
    V = fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    return IterativeSolver(V, f"test_forcing_{forcing}_{id(mesh)}_", None, RTOL, num_pairs=0,
                           forcing=forcing, max_forcing=max_forcing)


def _eta(solver: IterativeSolver, eps: float) -> float:
    solver.set_forcing(eps)
    return solver.ksp.getTolerances()[0]


def test_eisenstat_walker_follows_the_last_reduction_of_the_residual():
    """η = 0.9 (ε/ε_prev)², capped by max_forcing, floored by 0.1 rtol/ε; the first step of an
    increment gets max_forcing; the finishing step as with the quadratic rule."""
    solver = _solver("eisenstat-walker", max_forcing=0.05)
    try:
        assert _eta(solver, 1.0) == pytest.approx(0.05)  # the increment's first step
        assert _eta(solver, 0.5) == pytest.approx(0.05)  # 0.9 · 0.25 capped
        assert _eta(solver, 0.06) == pytest.approx(0.9 * 0.12 ** 2)
        assert _eta(solver, 0.006) == pytest.approx(0.9 * 0.1 ** 2)  # the residual fell by 10
        # the last step cut ε by its whole tolerance (0.006 → 1e-5 ≤ 2 · 0.009 · 0.006): finish
        assert _eta(solver, 1e-5) == pytest.approx(0.1 * RTOL / 1e-5)
        solver.begin_increment()
        assert _eta(solver, 1e-3) == pytest.approx(0.05)  # a new increment: its first step again
        assert _eta(solver, 9e-4) == pytest.approx(0.05)
        assert _eta(solver, 5e-9) == pytest.approx(0.1 * RTOL / 5e-9)  # the floor 2e-3 (0.9 · 3e-11 below)
    finally:
        solver.destroy()


def test_quadratic_rule_is_the_one_before():
    """η = min(max(ε², 0.1 rtol/ε), max_forcing), and the finishing step after a linear-looking one."""
    solver = _solver("quadratic")
    try:
        assert _eta(solver, 1.0) == pytest.approx(1e-2)
        assert _eta(solver, 0.5) == pytest.approx(1e-2)  # ε² = 0.25 capped
        assert _eta(solver, 0.05) == pytest.approx(0.0025)
        # the last step cut ε by its whole tolerance (0.05 → 1e-4 ≤ 2 · 0.0025 · 0.05): finish
        assert _eta(solver, 1e-4) == pytest.approx(0.1 * RTOL / 1e-4)
    finally:
        solver.destroy()


@pytest.mark.parametrize("forcing, max_forcing, match", [("exact", 1e-2, "forcing = 'exact'"),
                                                         ("quadratic", 0.0, "max_forcing = 0"),
                                                         ("quadratic", 1.0, "max_forcing = 1"),
                                                         ("quadratic", math.nan, "max_forcing = nan")])
def test_bad_forcing_options_are_refused(forcing, max_forcing, match):
    with pytest.raises(ValueError, match=match):
        MonolithicOptions(linear_solver="iterative", forcing=forcing, max_forcing=max_forcing)


def test_the_lifted_predictor_is_solved_to_lift_forcing():
    """The increment's lifted step (ε = 1, not recorded) gets min(η, lift_forcing) under either rule:
    it sets the pairs' starting states (``MonolithicOptions.lift_forcing``)."""
    for forcing in FORCING_RULES:
        solver = _solver(forcing, max_forcing=1e-2)
        try:
            solver.set_forcing(1.0, record=False, cap=MonolithicOptions().lift_forcing)
            assert solver.ksp.getTolerances()[0] == pytest.approx(1e-4)
            assert _eta(solver, 1.0) == pytest.approx(1e-2)  # the Newton steps after it: η_max again
        finally:
            solver.destroy()


@pytest.mark.parametrize("value", [0.0, 1.0, math.nan])
def test_a_bad_lift_forcing_is_refused(value):
    with pytest.raises(ValueError, match="lift_forcing"):
        MonolithicOptions(linear_solver="iterative", lift_forcing=value)


def test_forcing_rules_are_listed():
    assert set(FORCING_RULES) == {"eisenstat-walker", "quadratic"}
    assert MonolithicOptions().forcing in FORCING_RULES


def _system(n: int = 8) -> tuple[PETSc.Mat, PETSc.Vec]:
    A = PETSc.Mat().createAIJ(((n, PETSc.DECIDE), (n, PETSc.DECIDE)), nnz=1, comm=MPI.COMM_WORLD)
    start, end = A.getOwnershipRange()
    for i in range(start, end):
        A.setValue(i, i, 2.0)
    A.assemble()
    b = A.createVecLeft()
    b.set(1.0)
    return A, b


def test_a_rebuilt_hierarchy_resumes_from_the_lagged_iterate():
    """After a lagged solve is cut short, the solve with the rebuilt hierarchy starts from where
    it stopped (its residual, not ‖b‖), unless that iterate is no better than zero or not finite."""
    solver = _solver("quadratic")
    A, b = _system()
    x = b.duplicate()
    try:
        x.set(0.4)  # residual 1 − 0.8 = 0.2 per row
        start = solver._resume_from(A, b, x)
        assert start == pytest.approx(0.2 * math.sqrt(8)) and solver.ksp.getInitialGuessNonzero()
        assert np.allclose(x.getArray(), 0.4)  # kept
        solver.ksp.setInitialGuessNonzero(False)
        x.set(2.0)  # residual −3 per row: worse than zero
        assert solver._resume_from(A, b, x) == pytest.approx(math.sqrt(8))
        assert not solver.ksp.getInitialGuessNonzero() and np.all(x.getArray() == 0.0)
        x.set(math.nan)
        assert solver._resume_from(A, b, x) == pytest.approx(math.sqrt(8))
        assert not solver.ksp.getInitialGuessNonzero() and np.all(x.getArray() == 0.0)
    finally:
        for obj in (A, b, x):
            obj.destroy()
        solver.destroy()
