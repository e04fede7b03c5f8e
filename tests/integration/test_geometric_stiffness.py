"""The consistent linearisation of current-geometry rigid obstacles (issue 27, "a linearisation that
keeps Newton fast"; ``contact/geometric_stiffness.py``, ``docs/theory.md`` "Large sliding").

* the derivatives it is made of: the frame's ∂R/∂n and the obstacles' ∂n/∂x, against central
  differences;
* the monolithic Newton matrix is the derivative of the residuals evaluated with the geometry
  re-evaluated at every iterate (central differences, a frictional sphere sliding), and without the
  geometric terms it is not;
* load stepping: one solve per increment, the frozen geometry's answer to the solver's tolerance
  in fewer Newton iterations; NNEQM1 with ``consistent_geometry=False`` keeps the repeated solves
  (its default: ``tests/integration/test_nneqm1_current_geometry.py``);
* an interface whose slave nodes all leave the master surface is a failed solve: cut back, then a
  ConvergenceError that names the interface.
"""

import logging
from dataclasses import replace

import numpy as np
import pytest
from mpi4py import MPI
from newton_checks import direct_step_in_augmented_system

from dolfinx_nnqem.cases.large_sliding import obstacle_force, sliding_blocks, sliding_sphere
from dolfinx_nnqem.contact.obstacles import Cylinder, Plane, Sphere
from dolfinx_nnqem.contact.surfaces import local_frames, local_frames_derivative
from dolfinx_nnqem.solvers import (ConvergenceError, MonolithicOptions, NNEQM1Options, SolverOptions, make_solver,
                                   solve_load_steps)

OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)


def test_frame_derivative_matches_differences():
    rng = np.random.default_rng(1)
    n = rng.normal(size=(20, 3))
    n[:3] = [[0.0, 1.0, 0.0], [0.3, -0.9, 0.1], [0.0, 0.0, -1.0]]  # the normals of the cases, and an axis
    n /= np.linalg.norm(n, axis=1)[:, None]
    dR = local_frames_derivative(n)
    h = 1e-6
    for l in range(3):
        e = np.zeros(3)
        e[l] = h
        difference = (local_frames(n + e) - local_frames(n - e)) / (2 * h)
        assert np.abs(difference - dR[..., l]).max() < 1e-8


@pytest.mark.parametrize("obstacle", [Plane(point=(0.0, 0.0, 0.0), normal=(0.2, 1.0, 0.0)),
                                      Sphere(centre=(0.1, 0.0, 0.0), radius=0.5),
                                      Cylinder(point=(0.0, 0.2, 0.0), axis=(0.0, 1.0, 1.0), radius=0.5)],
                         ids=["plane", "sphere", "cylinder"])
def test_normal_derivative_matches_differences(obstacle):
    x = np.random.default_rng(2).normal(size=(10, 3))
    dn = obstacle.normal_derivative(x)
    h = 1e-6
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        difference = (obstacle.project(x + e)[1] - obstacle.project(x - e)[1]) / (2 * h)
        assert np.abs(difference - dn[:, :, j]).max() < 1e-8


def _residual(solver) -> np.ndarray:
    """(R_free, H) at the problem's iterate, the geometry re-evaluated there."""
    ev = solver.evaluate()
    return np.concatenate([ev.R_free.getArray(readonly=True).copy(), ev.H.ravel()])


@pytest.mark.parametrize("shape", ["sphere", "cylinder"])
def test_newton_matrix_is_the_residuals_derivative(shape):
    """Sliding with μ_f = 0.3, the obstacle moved on past the converged state: J d against central
    differences of (R, H) along a random d, 1e-6; J without the geometric terms misses by far more."""
    problem = sliding_sphere(8, start=0.3, end=0.7, mu_f=0.3, shape=shape)
    with make_solver("monolithic", problem, OPTIONS) as solver:
        solve_load_steps(problem, solver, 8, final_load_factor=0.5)
        assert solver.consistent_geometry
        model = problem.contact
        problem.apply_prescribed_displacements(0.52)  # the obstacle moves on: a slip a ≠ 0 in W
        rng = np.random.default_rng(3)
        n_u = problem.V.dofmap.index_map.size_local * 3
        free = np.ones(n_u, dtype=bool)
        free[problem.owned_bc_dofs()] = False
        u0 = problem.u.x.array[:n_u].copy()
        z0 = model.z.copy()
        ev = solver.evaluate()
        assert ev.geometric is not None and len(ev.geometric) == problem.num_pairs
        sliding = np.count_nonzero(ev.law.state == 2)
        assert sliding >= 1  # the friction frame turns under a force q ≠ 0
        du = np.where(free, rng.normal(size=n_u), 0.0) * np.abs(u0).max()
        dz = rng.normal(size=z0.shape) * np.abs(z0).max()
        d = np.concatenate([du, dz.ravel()])

        def J_times(evaluation) -> np.ndarray:
            J = solver._newton_matrix(evaluation)
            x, y = J.createVecRight(), J.createVecLeft()
            x.getArray()[:] = d
            J.mult(x, y)
            out = y.getArray(readonly=True).copy()
            for vector in (x, y):
                vector.destroy()
            return out

        consistent = J_times(ev)
        frozen = J_times(replace(ev, geometric=None))
        h = 1e-6
        solver.set_iterate(u0, z0, (du, dz), h, ev.lin)
        plus = _residual(solver)
        solver.set_iterate(u0, z0, (du, dz), -h, ev.lin)
        minus = _residual(solver)
        difference = (plus - minus) / (2 * h)
    scale = np.linalg.norm(difference)
    error, error_frozen = (np.linalg.norm(consistent - difference) / scale,
                           np.linalg.norm(frozen - difference) / scale)
    print(f"\n  {shape}: {sliding} pairs sliding; |J d − ΔF/Δ|/|ΔF/Δ| = {error:.1e} with the geometric terms, {error_frozen:.1e} without")
    assert error < 1e-6
    assert error_frozen > 100 * error


@pytest.mark.parametrize("mu_f", [0.0, 0.3])
def test_slide_in_one_solve_per_increment(mu_f):
    """The sphere slid 0.3 -> 0.7 (6³, 16 increments): the consistent linearisation ends where the frozen
    geometry's repeated solves do (1e-8, both at rtol 1e-10) with one solve per increment and fewer
    Newton iterations."""
    runs = {}
    for consistent in (True, False):
        problem = sliding_sphere(6, mu_f=mu_f)
        with make_solver("monolithic", problem, OPTIONS,
                         monolithic=MonolithicOptions(consistent_geometry=consistent)) as solver:
            results = solve_load_steps(problem, solver, 16)
        runs[consistent] = (obstacle_force(problem), problem.u.x.array.copy(), results)
    (f, u, results), (f_frozen, u_frozen, results_frozen) = runs[True], runs[False]
    iterations = sum(r.iterations for r in results)
    iterations_frozen = sum(r.iterations for r in results_frozen)
    df = np.linalg.norm(f - f_frozen) / np.linalg.norm(f_frozen)
    du = np.abs(u - u_frozen).max() / np.abs(u_frozen).max()
    print(f"\n  μ_f = {mu_f}: {iterations} Newton iterations in {len(results)} solves, frozen geometry "
          f"{iterations_frozen} in {sum(r.report.geometry_passes for r in results_frozen)}; |ΔF|/|F| = {df:.1e}, "
          f"max|Δu|/max|u| = {du:.1e}")
    assert all(r.report.geometry_passes == 1 for r in results)
    assert any(r.report.geometry_passes > 1 for r in results_frozen)
    assert iterations < 0.7 * iterations_frozen
    assert df < 1e-8 and du < 1e-8


def test_iterative_linear_solver_takes_the_geometric_terms(monkeypatch):
    """The iterative solver's augmented system (u rows + c B_freeᵀ D_wᵀ × the pair rows, whose W part the
    u block must carry too) has the direct system's solution: the direct Newton step at a sliding
    iterate leaves a residual of round-off in it, and one without the augmentation's W part does not."""
    from dolfinx_nnqem.solvers.block_system import AugmentedSystem

    problem = sliding_sphere(8, mu_f=0.3, shape="cylinder")
    error, error_without = direct_step_in_augmented_system(
        problem, OPTIONS, lambda: monkeypatch.setattr(AugmentedSystem, "augmented_geometric_blocks",
                                                      lambda self, terms, dH_dw, weights=None: np.zeros_like(terms.W)),
        min_sliding=3)
    print(f"\n  |J_aug d_direct − b_aug|/|b_aug| = {error:.1e}, {error_without:.1e} without the augmentation's W")
    assert error < 1e-12
    assert error_without > 100 * error


def _blocks_and_sphere():
    """The frictional block slide (``cases.large_sliding.sliding_blocks``, μ_f = 0.3) with a sphere
    (μ_f = 0.3) pressed 0.002 into the upper block's trailing side x = 0 and following the slide: an
    obstacle interface after a node-to-surface one."""
    from dolfinx_nnqem.cases.large_sliding import MATERIAL, _press, _slide
    from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet
    from dolfinx_nnqem.cases.geometries import BlockStackTags as T
    from dolfinx_nnqem.cases.geometries import build_block_stack

    mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [0.5, 0.5], [(4, 2, 4), (6, 2, 6)])
    sphere = Sphere(centre=(-0.301, 0.8, 0.5), radius=0.3,
                    motion=lambda ell: (0.003 * _press(ell) + 0.4 * _slide(ell), 0.0, 0.0))
    dirichlet = [Dirichlet(T.bottom(1)), Dirichlet(T.top(2), -0.01, [1], amplitude=_press),
                 Dirichlet(T.top(2), 0.4, [0], amplitude=_slide), Dirichlet(T.top(2), 0.0, [2])]
    contacts = [Contact(T.top(1), T.bottom(2), mu_f=0.3, discretisation="node-to-surface", geometry="current"),
                Contact(sphere, T.xmin(2), mu_f=0.3, geometry="current")]
    return ContactProblem(mesh, ct, ft, materials=MATERIAL, dirichlet=dirichlet, contact=contacts)


def test_obstacle_next_to_a_node_to_surface_interface():
    """Both kinds in one model: the obstacle's rows are refreshed in their place after the node-to-surface
    ones, which keep the repeated solves. Each increment's end satisfies the equations in the geometry
    evaluated there (1e-8 of the force scale after the commit, rtol 1e-10; before the first solve
    always got a second, the press's increment 2, solved by the predictor in 0 iterations, ended
    4e-4 off), and ends near the frozen geometry's: the
    frictional node-to-surface pair forces are determined only to about 1e-8 by residuals of that size
    (measured: two states both within 3e-12 of equilibrium differ by 1e-8 in p_n; docs/theory.md)."""
    runs = {}
    for consistent in (True, False):
        problem = _blocks_and_sphere()
        residuals = []

        def check(result, problem=problem):
            problem.update_contact_geometry(result.load_factor)  # the geometry where the increment ended
            ev = solver.evaluate()
            residuals.append(max(ev.norm_R, ev.norm_H) / ev.scale)

        with make_solver("monolithic", problem, OPTIONS,
                         monolithic=MonolithicOptions(consistent_geometry=consistent)) as solver:
            assert solver.consistent_geometry == consistent
            results = solve_load_steps(problem, solver, 12, callbacks=[check])
        model = problem.contact
        sphere_force = model.obstacle_reactions()["sphere-302"]
        runs[consistent] = (sphere_force, problem.u.x.array.copy(), results, max(residuals))
    (f, u, results, residual), (f_frozen, u_frozen, results_frozen, _) = runs[True], runs[False]
    df = np.linalg.norm(f - f_frozen) / np.linalg.norm(f_frozen)
    du = np.abs(u - u_frozen).max() / np.abs(u_frozen).max()
    print(f"\n  sphere force {f}; {sum(r.iterations for r in results)} Newton iterations in "
          f"{sum(r.report.geometry_passes for r in results)} solves, frozen {sum(r.iterations for r in results_frozen)} "
          f"in {sum(r.report.geometry_passes for r in results_frozen)}; largest residual in the geometry of the "
          f"increment's end {residual:.1e}; |ΔF|/|F| = {df:.1e}, max|Δu|/max|u| = {du:.1e}")
    assert np.linalg.norm(f) > 0.01  # the sphere presses
    assert not any(r.report.geometry_consistent for r in results)  # the node-to-surface pairs may change
    assert residual < 1e-8  # rtol 1e-10 of the solve's force scale, which counted the sphere's motion over the increment
    assert df < 1e-5 and du < 1e-6


def test_nneqm1_without_consistent_geometry_keeps_the_repeated_solves():
    problem = sliding_sphere(4, start=0.3, end=0.3)
    with make_solver("nneqm1", problem, OPTIONS, nneqm1=NNEQM1Options(consistent_geometry=False)) as solver:
        results = solve_load_steps(problem, solver, 2, final_load_factor=0.25)
    assert all(not r.report.geometry_consistent for r in results)
    assert any(r.report.geometry_passes > 1 for r in results)


def test_no_pairs_left_is_a_failed_solve(caplog):
    """The upper block slid 1.5 over a lower block as long as itself: past a slide of 1 (plus the edge
    allowance) no slave node projects onto the master; the increment is cut back, and when the
    cutbacks are exhausted the error names the interface."""
    problem = sliding_blocks(slide=1.5)
    with caplog.at_level(logging.WARNING, logger="dolfinx_nnqem"), make_solver("monolithic", problem, OPTIONS) as solver, \
            pytest.raises(ConvergenceError, match=r"after 2 cutbacks: contact 201-102: no pairs in the "
                                                  r"current geometry at load factor"):
        solve_load_steps(problem, solver, 12, max_cutbacks=2)
    cutbacks = [r.message for r in caplog.records if "cutback" in r.message]
    print(f"\n  {problem.load_factor_n:.4g} reached; {cutbacks}")
    assert len(cutbacks) == 2 and all("no pairs in the current geometry" in m for m in cutbacks)
    assert problem.load_factor_n > 0.7  # the block slid past the master's edge before the pairs went
