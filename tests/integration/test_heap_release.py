"""The C heap's free pages are given back before the phases where a run peaks (``numerics/heap.py``).

Before every Krylov solve (its AMG set-up and its basis are where the million-dof run peaks) and
before every increment (after the last one's check and commit freed their Gauss-point arrays),
the free memory glibc keeps is handed back to the operating system; no value changes
(``docs/performance.md``, "Speed, second round: a million dofs").
"""

import ctypes.util

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
from dolfinx_nnqem.numerics import heap
from dolfinx_nnqem.solvers import MonolithicOptions, linear_solver, solve_load_steps, stepping
from dolfinx_nnqem.solvers.monolithic import MonolithicSolver

INCREMENTS = 2

glibc = pytest.mark.skipif("libc.so.6" != ctypes.util.find_library("c"), reason="malloc_trim is glibc's")


def _run(monkeypatch, release) -> tuple[np.ndarray, list[str]]:
    """The pressed blocks (level 1, iterative) with ``release`` as the heap release; (u, the calls in order)."""
    calls: list[str] = []

    def recorded_release() -> bool:
        calls.append("release")
        return release()

    krylov_solve = linear_solver.IterativeSolver._krylov_solve

    def recorded_krylov_solve(self, b, x, pair_state):
        calls.append("krylov")
        return krylov_solve(self, b, x, pair_state)

    solve_increment = MonolithicSolver.solve_increment

    def recorded_increment(self, load_factor):
        calls.append("increment")
        return solve_increment(self, load_factor)

    monkeypatch.setattr(linear_solver, "release_free_heap", recorded_release)
    monkeypatch.setattr(stepping, "release_free_heap", recorded_release)
    monkeypatch.setattr(linear_solver.IterativeSolver, "_krylov_solve", recorded_krylov_solve)
    monkeypatch.setattr(MonolithicSolver, "solve_increment", recorded_increment)
    problem = pressed_blocks_problem(1, MPI.COMM_SELF)
    with MonolithicSolver(problem, monolithic=MonolithicOptions(linear_solver="iterative")) as solver:
        solve_load_steps(problem, solver, INCREMENTS)
    return problem.u.x.array.copy(), calls


def test_the_heap_is_released_before_every_krylov_solve_and_increment(monkeypatch):
    _, calls = _run(monkeypatch, heap.release_free_heap)
    krylov = [i for i, call in enumerate(calls) if call == "krylov"]
    increments = [i for i, call in enumerate(calls) if call == "increment"]
    assert len(increments) == INCREMENTS and len(krylov) >= INCREMENTS
    assert all(calls[i + 1] == "release" for i in krylov)  # first thing in the solve, before the AMG set-up
    assert all(calls[i - 1] == "release" for i in increments)


def test_releasing_the_heap_changes_no_value(monkeypatch):
    released, _ = _run(monkeypatch, heap.release_free_heap)
    kept, _ = _run(monkeypatch, lambda: False)
    assert np.abs(released).max() > 0.0
    assert np.array_equal(released, kept)


@glibc
def test_freed_heap_memory_is_given_back():
    # blocks below glibc's mmap threshold come from the heap; freeing all but every tenth leaves
    # whole free pages between live blocks, which only a trim gives back
    blocks = [np.ones(6_000) for _ in range(800)]  # 47 kB each
    kept = blocks[::10]
    del blocks
    assert heap.release_free_heap()
    assert all(float(block.sum()) == 6_000.0 for block in kept)  # the live blocks untouched
