"""NNEQM1 in the current geometry (issue 43, "Speed, second round"; ``solvers/nodal_flexibility.py``).

* the flexibility from the unit loads of the pairs' dofs, with the obstacles' geometric terms by the
  Woodbury update, is the one rebuilt from a factorisation of K_t − K_s (C = (B + W) G_g Bᵀ, and
  the responses G_g r and G_g Bᵀ Δλ);
* ``Condensation.refactorise`` keeps the factors of a tangent that did not change and factorises
  one that did;
* the sphere slide: one solve per increment, one factorisation for the elastic block, the answer of
  the earlier path (``consistent_geometry=False``, its repeated solves) and of the monolithic solver.
"""

import numpy as np
import pytest

from dolfinx_nnqem.cases.large_sliding import obstacle_force, sliding_sphere
from dolfinx_nnqem.solvers import NNEQM1Options, SolverOptions, make_solver, solve_load_steps
from dolfinx_nnqem.solvers.condensation import Condensation
from dolfinx_nnqem.solvers.nodal_flexibility import NodalFlexibility, rows_on_dofs

OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)


@pytest.fixture(scope="module")
def pressed_sphere():
    """A frictional sphere pressed into a 4³ block (NNEQM1, 2 increments), then u moved off the converged
    state so that the pairs slip (W ≠ 0)."""
    problem = sliding_sphere(4, start=0.3, end=0.7, mu_f=0.3)
    with make_solver("nneqm1", problem, OPTIONS) as solver:
        solve_load_steps(problem, solver, 2, final_load_factor=0.3)
    problem.u.x.array[:] += 1e-3 * np.random.default_rng(3).normal(size=problem.u.x.array.shape)
    problem.u.x.array[problem.bc_dofs] = 0.0
    problem.u.x.scatter_forward()
    return problem


def test_nodal_flexibility_is_the_rebuilt_condensation(pressed_sphere):
    p = pressed_sphere
    model = p.contact
    model.geometry.refresh_obstacles(p.u, p.load_factor, p.state.u_n, p.load_factor_n)
    terms = model.geometry.geometric_terms(p.u, p.load_factor, p.state.u_n, p.load_factor_n)
    assert np.abs(terms.K).max() > 0 and np.abs(terms.W).max() > 0  # both kinds of geometric term act
    nodal_side = Condensation(p, "nodal", None)
    nodal_side.factorise(p.assemble_tangent, "K_t")
    nodal = NodalFlexibility(nodal_side)
    positions = nodal.update()
    D = nodal.dofs[positions]
    B_D = rows_on_dofs(model, model.rows.values, D)
    Bc_D = rows_on_dofs(model, terms.rows_values(model.rows), D)
    update = nodal.geometric_update(terms, positions)
    C = nodal.flexibility(positions, B_D, Bc_D, update)

    def with_terms(A, bcs):  # K_t − K_s on the slave nodes' free dofs: the monolithic solver's u block
        K = p.assemble_tangent(A, bcs)
        terms.add_to_tangent(K, (~np.isin(terms.slave_dofs(), p.constrained_rows())).astype(float))
        return K

    rebuilt = Condensation(p, "rebuilt", None)
    rebuilt.factorise(with_terms, "K_t − K_s")
    X, _ = rebuilt.pair_flexibility()
    C_rebuilt = Bc_D @ X[D]
    assert np.abs(C - C_rebuilt).max() < 1e-10 * np.abs(C_rebuilt).max()
    assert np.abs(C - C.T).max() > 1e-6 * np.abs(C).max()  # W makes it unsymmetric: the terms were taken

    r = p.u.x.petsc_vec.duplicate()
    r.getArray()[:] = np.random.default_rng(4).normal(size=r.getLocalSize())
    r.getArray()[p.owned_bc_dofs()] = 0.0
    x, x_D = nodal.free_response(nodal_side.solve(r), positions, update)
    x_rebuilt = rebuilt.solve(r).getArray()
    assert np.abs(x - x_rebuilt).max() < 1e-10 * np.abs(x_rebuilt).max()
    assert np.array_equal(x_D, x[D])
    dlam = np.random.default_rng(5).normal(size=C.shape[0])
    du = nodal.response(B_D.T @ dlam, positions, update)
    assert np.abs(du - X @ dlam).max() < 1e-10 * np.abs(X @ dlam).max()
    for condensation in (nodal_side, rebuilt):
        condensation.destroy()


def test_refactorise_keeps_the_factors_of_an_unchanged_tangent(pressed_sphere):
    p = pressed_sphere
    condensation = Condensation(p, "refactorise", None)
    assert condensation.refactorise(p.assemble_tangent, "K_t")
    r = p.u.x.petsc_vec.duplicate()
    r.getArray()[:] = 1.0
    first = condensation.solve(r).getArray().copy()
    assert not condensation.refactorise(p.assemble_tangent, "K_t")  # the elastic tangent again
    assert condensation.factorisations == 1
    assert np.array_equal(condensation.solve(r).getArray(), first)

    def doubled(A, bcs):
        K = p.assemble_tangent(A, bcs)
        K.scale(2.0)
        return K

    assert condensation.refactorise(doubled, "2 K_t")
    assert condensation.factorisations == 2
    halved = condensation.solve(r).getArray()
    free = np.setdiff1d(np.arange(len(first)), p.owned_bc_dofs())
    assert np.allclose(halved[free], 0.5 * first[free], rtol=1e-12, atol=0.0)
    condensation.destroy()


def _slide(method: str, **settings):
    problem = sliding_sphere(4, start=0.3, end=0.7)
    with make_solver(method, problem, OPTIONS, **settings) as solver:
        results = solve_load_steps(problem, solver, 6)
        factorisations = getattr(solver, "condensation", None)
        count = factorisations.factorisations if factorisations is not None else None
    return problem, results, count


def test_sphere_slide_in_one_solve_per_increment_with_the_same_answer():
    problem, results, factorisations = _slide("nneqm1")
    earlier, results_earlier, _ = _slide("nneqm1", nneqm1=NNEQM1Options(consistent_geometry=False))
    monolithic, _, _ = _slide("monolithic")
    f, f_earlier, f_monolithic = (obstacle_force(p) for p in (problem, earlier, monolithic))
    print(f"\n  NNEQM1: {sum(r.iterations for r in results)} outer iterations in "
          f"{sum(r.report.geometry_passes for r in results)} solves, {factorisations} factorisation(s); "
          f"earlier path: {sum(r.iterations for r in results_earlier)} in "
          f"{sum(r.report.geometry_passes for r in results_earlier)} solves; F = {f}, {f_earlier}, {f_monolithic}")
    assert all(r.report.geometry_passes == 1 and r.report.geometry_consistent for r in results)
    assert any(r.report.geometry_passes > 1 for r in results_earlier)
    assert factorisations == 1  # the elastic block's tangent never changes
    assert np.linalg.norm(f - f_earlier) < 1e-8 * np.linalg.norm(f_earlier)
    assert np.linalg.norm(f - f_monolithic) < 1e-8 * np.linalg.norm(f_monolithic)
    u, u_earlier = problem.u.x.array, earlier.u.x.array
    assert np.abs(u - u_earlier).max() < 1e-8 * np.abs(u_earlier).max()
