"""The consistent linearisation of a rigid obstacle on P2 tetrahedra in the current geometry (issue 41;
``contact/combined_stiffness.py``, ``docs/theory.md`` "Large sliding").

A 6-node triangle's pair acts on the combination d̂_i = Σ_k a_ik u_k of its nodes; re-evaluated at every
Newton iterate, its geometric blocks are the degree-1 pair's at X̂_i + d̂_i, put on its nodes with the
coefficients (a_ik a_il K_i on the u rows, a_il W_i on the pair rows). On the sphere slid 0.3 -> 0.7 over
3³ × 6 P2 tetrahedra (65 pairs, μ_f = 0.3):

* the monolithic Newton matrix is the derivative of the residuals with the pairs re-evaluated at every
  iterate (central differences), both laws; the frozen geometry's matrix is not;
* the iterative linear solver's augmented system has the direct Newton step as its solution, and
  without the augmentation of the combined pairs' W it has not;
* load stepping takes one solve per increment with the monolithic solver (direct and iterative linear
  solvers) and NNEQM1, converging quadratically, and ends in the state of the frozen geometry's repeated
  solves (``consistent_geometry=False``, the path before) to the solver's tolerance.
"""

import numpy as np
import pytest
from newton_checks import direct_step_in_augmented_system, last_step, newton_matrix_against_differences, residuals

from dolfinx_nnqem.cases.large_sliding import PRESSED_AT, obstacle_force, sliding_sphere
from dolfinx_nnqem.solvers import MonolithicOptions, NNEQM1Options, SolverOptions, make_solver, solve_load_steps

OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)


def _p2_sphere(law: str = "alart-curnier", mu_f: float = 0.3):
    return sliding_sphere(3, degree=2, law=law, mu_f=mu_f, cell_type="tetrahedron")


def _solver(problem, method: str, consistent: bool):
    if method == "nneqm1":
        return make_solver("nneqm1", problem, OPTIONS, nneqm1=NNEQM1Options(consistent_geometry=consistent))
    linear = "iterative" if method == "iterative" else "direct"
    return make_solver("monolithic", problem, OPTIONS,
                       monolithic=MonolithicOptions(consistent_geometry=consistent, linear_solver=linear))


@pytest.mark.parametrize("law", ["alart-curnier", "polar"])
def test_newton_matrix_is_the_residuals_derivative(law):
    """Mid-slide (ℓ = 0.5, the sphere moved on to 0.52, a pair sliding), at a state perturbed by 1e-4: J d
    against central differences of (R, H) with the combined pairs re-evaluated, 1e-6; the frozen geometry's
    J misses by more than 100 times that."""
    problem = _p2_sphere(law)
    with make_solver("monolithic", problem, OPTIONS) as solver:
        solve_load_steps(problem, solver, 8, final_load_factor=0.5)
        problem.apply_prescribed_displacements(0.52)
        ev = solver.evaluate()
        assert solver.consistent_geometry and ev.geometric is not None and ev.geometric.combined is not None
        assert len(ev.geometric.combined) == problem.num_pairs == 65
        sliding = np.count_nonzero(ev.law.state == 2)
        error_u, error_H, frozen_u, frozen_H = newton_matrix_against_differences(problem, solver)
    print(f"\n  {law}: {sliding} pairs sliding; |J d − FD|/|FD|: u rows {error_u:.1e}, pair rows {error_H:.1e}; "
          f"the frozen geometry's J: {frozen_u:.1e}, {frozen_H:.1e}")
    assert sliding >= 1
    assert error_u < 1e-6 and error_H < 1e-6
    assert max(frozen_u, frozen_H) > 100 * max(error_u, error_H)


def test_iterative_linear_solver_takes_the_combined_terms(monkeypatch):
    """At the sliding iterate, the direct Newton step leaves a round-off residual in the iterative solver's
    augmented system; without the augmentation of the combined pairs' W part it does not."""
    from dolfinx_nnqem.solvers.block_system import AugmentedSystem

    problem = _p2_sphere("polar")
    error, error_without = direct_step_in_augmented_system(
        problem, OPTIONS, lambda: monkeypatch.setattr(
            AugmentedSystem, "augmented_combined_blocks",
            lambda self, terms, dH_dw: [0.0 * block for _, block in terms.node_blocks()]))
    print(f"\n  |J_aug d_direct − b_aug|/|b_aug| = {error:.1e}, {error_without:.1e} without the combined W's augmentation")
    assert error < 1e-12
    assert error_without > 100 * error


def _slide(method: str, law: str, mu_f: float, consistent: bool):
    problem = _p2_sphere(law, mu_f)
    with _solver(problem, method, consistent) as solver:
        results = solve_load_steps(problem, solver, 16)
    return problem, results


@pytest.mark.parametrize("method, law, mu_f", [("monolithic", "alart-curnier", 0.3), ("monolithic", "polar", 0.3),
                                               ("nneqm1", "alart-curnier", 0.3), ("nneqm1", "polar", 0.3),
                                               ("iterative", "alart-curnier", 0.3)])
def test_one_solve_per_increment_ending_where_the_frozen_geometry_does(method, law, mu_f):
    """Every increment of the slide in one solve, whose last step above round-off ends within 10 ε_k² in the
    sliding increments (direct linear solves and NNEQM1; the iterative solver's inexact steps, its forcing,
    bound its rate); the end state (u, the obstacle's force) that of the frozen geometry's repeated solves
    to 1e-8, in fewer Newton iterations."""
    problem, results = _slide(method, law, mu_f, True)
    frozen, results_frozen = _slide(method, law, mu_f, False)
    print()
    for result in results:
        step = last_step(result.report)
        print(f"  ℓ = {result.load_factor:.4f}: max(|R|, |H|)/F = "
              f"{', '.join(f'{e:.1e}' for e in residuals(result.report))}")
        assert result.report.geometry_passes == 1
        if result.load_factor > PRESSED_AT + 1e-12 and step is not None and method != "iterative":
            assert step[1] <= 10.0 * step[0] ** 2
    f, f_frozen = obstacle_force(problem), obstacle_force(frozen)
    df = np.linalg.norm(f - f_frozen) / np.linalg.norm(f_frozen)
    du = np.abs(problem.u.x.array - frozen.u.x.array).max() / np.abs(frozen.u.x.array).max()
    iterations = [r.iterations for r in results]
    iterations_frozen = [r.iterations for r in results_frozen]
    print(f"  {method}/{law}, μ_f = {mu_f}: Newton iterations per increment {iterations} (sum {sum(iterations)}), "
          f"frozen geometry {iterations_frozen} (sum {sum(iterations_frozen)}) in solves "
          f"{[r.report.geometry_passes for r in results_frozen]}; |ΔF|/|F| = {df:.1e}, max|Δu|/max|u| = {du:.1e}")
    assert [r.load_factor for r in results] == [r.load_factor for r in results_frozen]  # the same increments
    assert any(r.report.geometry_passes > 1 for r in results_frozen)
    assert sum(iterations) < sum(iterations_frozen)
    assert df < 1e-8 and du < 1e-8
