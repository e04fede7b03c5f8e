"""The Gauss-point values an increment commits are not held through the next increment's solve, nor
the material at the Gauss points that the independent check makes.

They are σ and Δε_p at every Gauss point (two tensor arrays: 190 MB a rank on the million-dof
pressed blocks), and the next solve's AMG set-up is where the run's memory peaks
(``docs/performance.md``, "Speed, second round: a million dofs").
"""

import gc
import weakref

from mpi4py import MPI

from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
from dolfinx_nnqem.solvers import MonolithicOptions, checks, solve_load_path, solve_load_steps, stepping
from dolfinx_nnqem.solvers.monolithic import MonolithicSolver


def _watch_committed_values(monkeypatch, solver):
    """Record a weak reference to every increment's values to commit, and, at each solve, whether
    the values of the increments before are still alive."""
    refs: list[weakref.ref] = []
    alive_at_solve: list[int] = []
    values_to_commit = stepping.values_to_commit

    def recorded(problem, report=None):
        values = values_to_commit(problem, report)
        refs.append(weakref.ref(values))
        return values

    solve_increment = solver.solve_increment

    def watched(load_factor):
        gc.collect()
        alive_at_solve.append(sum(ref() is not None for ref in refs))
        return solve_increment(load_factor)

    monkeypatch.setattr(stepping, "values_to_commit", recorded)
    monkeypatch.setattr(solver, "solve_increment", watched)
    return refs, alive_at_solve


def test_committed_values_are_released_before_the_next_solve(monkeypatch):
    problem = pressed_blocks_problem(1, MPI.COMM_SELF)
    with MonolithicSolver(problem, monolithic=MonolithicOptions(linear_solver="direct")) as solver:
        refs, alive = _watch_committed_values(monkeypatch, solver)
        solve_load_steps(problem, solver, 3)
    assert len(refs) == 3
    assert alive == [0, 0, 0]


def test_committed_values_are_released_on_an_explicit_load_path(monkeypatch):
    problem = pressed_blocks_problem(1, MPI.COMM_SELF)
    with MonolithicSolver(problem, monolithic=MonolithicOptions(linear_solver="direct")) as solver:
        refs, alive = _watch_committed_values(monkeypatch, solver)
        solve_load_path(problem, solver, [0.1, 0.2])
    assert len(refs) == 2
    assert alive == [0, 0]


def test_the_check_keeps_no_material_arrays_between_increments(monkeypatch):
    # the material at the Gauss points (five values a point for von Mises) is made for each check
    # and dropped after it: kept, it stayed resident under every later AMG set-up and Krylov solve
    materials: list[weakref.ref] = []
    material_at_points = checks._Forms.material_at_points

    def recorded(self):
        material = material_at_points(self)
        materials.append(weakref.ref(material))
        return material

    monkeypatch.setattr(checks._Forms, "material_at_points", recorded)
    problem = pressed_blocks_problem(1, MPI.COMM_SELF)
    with MonolithicSolver(problem, monolithic=MonolithicOptions(linear_solver="direct")) as solver:
        solve_load_steps(problem, solver, 2)
    gc.collect()
    assert len(materials) == 2
    assert [ref() is None for ref in materials] == [True, True]
