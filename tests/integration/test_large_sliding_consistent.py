"""Node-to-surface pairs linearised consistently in the current geometry (issues 41 and 43).

The block slid 1.6 master facets over another (``cases.large_sliding.sliding_blocks``, 12
increments, node-to-surface, geometry = "current"): with the monolithic solver the pairs are
re-evaluated at every Newton iterate and their geometric terms are in J
(``contact/surface_stiffness.py``), so

* J d equals central differences of (R, H) along a random d at a state off equilibrium mid-slide
  (every term: the closest points move, pairs sit clamped on facet edges, μ_f = 0.3 slips);
* Newton converges quadratically in every increment of the slide (ε_{k+1} ≤ 10 ε_k²), and the
  solve that load stepping makes at the re-evaluated geometry starts converged (the frozen
  geometry needs four or more solves per increment: its re-evaluations converge linearly);
* the slid state is the frozen geometry's (both solve the equations in the geometry of their own
  configuration), in fewer Newton iterations;
* NNEQM1 keeps the geometry frozen within a solve (its condensation has no room for the terms)
  and still ends in the same state.
"""

import numpy as np
import pytest
from newton_checks import last_step, newton_matrix_against_differences, residuals, solves_by_increment

from dolfinx_nnqem.cases.large_sliding import PRESSED_AT, slave_force, sliding_blocks
from dolfinx_nnqem.solvers import MonolithicOptions, SolverOptions, make_solver, solve_load_steps

OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)


def _slide(mu_f: float, consistent: bool = True, method: str = "monolithic"):
    """The block slide; (problem, results, every solve's (load factor, report, pairs that changed their
    master facet during the solve))."""
    problem = sliding_blocks(slide=0.4, mu_f=mu_f)
    reports = []
    settings = {"monolithic": MonolithicOptions(consistent_geometry=consistent)} if method == "monolithic" else {}
    with make_solver(method, problem, OPTIONS, **settings) as solver:
        solve_increment = solver.solve_increment

        def recording(load_factor):
            pairs = problem.contact.interfaces[0].pairs
            before = pairs.slave_blocks.copy(), pairs.master_facet.copy()
            report = solve_increment(load_factor)
            after = problem.contact.interfaces[0].pairs
            same = np.array_equal(after.slave_blocks, before[0])
            changed = int(np.count_nonzero(after.master_facet != before[1])) if same else -1
            reports.append((load_factor, report, changed))
            return report

        solver.solve_increment = recording
        results = solve_load_steps(problem, solver, 12)
    return problem, results, reports


@pytest.fixture(scope="module")
def frictional():
    return {consistent: _slide(0.3, consistent) for consistent in (True, False)}


def test_newton_converges_quadratically_on_a_node_to_surface_slide(frictional):
    """Every increment of the slide: its first solve's last step above round-off ends within
    10 ε_k² (quadratic), and the solve that follows at the re-evaluated geometry starts converged;
    in some of them pairs changed their master facet within the solve (B's pattern changed)."""
    _, _, reports = frictional[True]
    changed = [c for load_factor, _, c in reports if load_factor > PRESSED_AT + 1e-12]
    print(f"\n  pairs that changed their master facet within each solve: {changed}")
    assert sum(c > 0 for c in changed) >= 3
    print()
    for load_factor, solves in solves_by_increment(reports, PRESSED_AT).items():
        eps = residuals(solves[0])
        step = last_step(solves[0])
        print(f"  ℓ = {load_factor:.4f}: max(|R|, |H|)/F = {', '.join(f'{e:.1e}' for e in eps)}; last step "
              f"{'–' if step is None else f'{step[0]:.1e} -> {step[1]:.1e}, ratio {step[1] / step[0]:.1e}'}; "
              f"iterates per solve {[len(r.history) for r in solves]}")
        assert step is not None and step[1] <= 10.0 * step[0] ** 2 and step[1] / step[0] < 1e-3
        # the solution was in its own geometry already: the second solve's start is its only iterate
        assert [len(r.history) for r in solves[1:]] == [1] and solves[1].history[0].iteration == 0


def test_frozen_geometry_needs_repeated_solves(frictional):
    """The same slide with the geometry frozen within a solve (consistent_geometry=False): each solve
    is Newton on the frozen equations, and the re-evaluations between them converge linearly (the
    residual each solve starts with, in the geometry of the last one's solution)."""
    _, _, reports = frictional[False]
    print()
    passes = []
    for load_factor, solves in solves_by_increment(reports, PRESSED_AT).items():
        starts = [residuals(r)[0] for r in solves[1:]]
        passes.append(len(solves))
        print(f"  ℓ = {load_factor:.4f}: {len(solves)} solves, starting at {', '.join(f'{e:.1e}' for e in starts)}")
    assert min(passes) >= 4


def test_consistent_and_frozen_end_in_the_same_state(frictional):
    consistent, frozen = frictional[True], frictional[False]
    f_c, f_f = slave_force(consistent[0]), slave_force(frozen[0])
    n_c, n_f = (sum(r.iterations for r in run[1]) for run in (consistent, frozen))
    du = np.abs(consistent[0].u.x.array - frozen[0].u.x.array).max() / np.abs(frozen[0].u.x.array).max()
    print(f"\n  consistent: F = {f_c}, {n_c} Newton iterations; frozen: F = {f_f}, {n_f}; "
          f"|ΔF|/|F| = {np.linalg.norm(f_c - f_f) / np.linalg.norm(f_f):.1e}, max|Δu|/max|u| = {du:.1e}")
    assert np.linalg.norm(f_c - f_f) < 1e-7 * np.linalg.norm(f_f) and du < 1e-7
    assert n_c < 0.5 * n_f


def test_newton_matrix_matches_finite_differences_mid_slide():
    """J d against central differences of (R, H) at a perturbed state mid-slide (μ_f = 0.3)."""
    problem = sliding_blocks(slide=0.4, mu_f=0.3)
    with make_solver("monolithic", problem, OPTIONS) as solver:
        solve_load_steps(problem, solver, 5, final_load_factor=5 / 12)
        error_u, error_H, frozen_u, frozen_H = newton_matrix_against_differences(problem, solver)
    print(f"\n  |J d − FD| / |FD|: u rows {error_u:.1e}, pair rows {error_H:.1e}; the frozen geometry's J: "
          f"{frozen_u:.1e}, {frozen_H:.1e}")
    assert error_u < 1e-8 and error_H < 1e-5
    assert frozen_u > 1e-4 and frozen_H > 1e-4  # the residuals differentiated are the current geometry's


def test_nneqm1_keeps_the_frozen_geometry_and_the_same_state(frictional):
    problem, results, _ = _slide(0.3, method="nneqm1")
    consistent = frictional[True][0]
    f_n, f_c = slave_force(problem), slave_force(consistent)
    passes = [r.report.geometry_passes for r in results]
    print(f"\n  NNEQM1: F = {f_n}, {sum(r.iterations for r in results)} Newton iterations, solves per increment "
          f"{passes}; monolithic (consistent): F = {f_c}")
    assert np.linalg.norm(f_n - f_c) < 1e-7 * np.linalg.norm(f_c)
    assert max(passes) >= 3  # the repeated solves of the frozen geometry
