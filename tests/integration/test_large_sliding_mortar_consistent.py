"""Dual mortar pairs linearised consistently in the current geometry (issues 41 and 43).

The block slid 1.6 master facets over another (``cases.large_sliding.sliding_blocks``, 12
increments, dual mortar, geometry = "current", μ_f = 0.3): with the monolithic solver the mortar
integrals are evaluated again at every Newton iterate and their derivatives are in J
(``contact/mortar_linearisation.py``), so

* J d equals central differences of (R, H) along a random d at a state off equilibrium mid-slide
  (the coefficients M_jk / m_j, the weighted gaps and the nodal normals move; pairs slip);
* Newton converges quadratically in every increment of the slide (ε_{k+1} ≤ 10 ε_k²), and the
  solve that load stepping makes at the re-evaluated geometry starts converged (the frozen
  geometry needs several solves per increment: its re-evaluations converge linearly);
* the slid state is the frozen geometry's, in fewer than half the Newton iterations.
"""

import numpy as np
import pytest
from newton_checks import (last_step, newton_matrix_against_differences, recorded_load_steps, residuals,
                           solves_by_increment)

from dolfinx_nnqem.cases.large_sliding import PRESSED_AT, slave_force, sliding_blocks
from dolfinx_nnqem.solvers import MonolithicOptions, SolverOptions, make_solver, solve_load_steps

OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)


def _slide(consistent: bool):
    """The frictional mortar slide; (problem, results, every solve's (load factor, report))."""
    problem = sliding_blocks(slide=0.4, mu_f=0.3, discretisation="mortar")
    with make_solver("monolithic", problem, OPTIONS,
                     monolithic=MonolithicOptions(consistent_geometry=consistent)) as solver:
        results, reports = recorded_load_steps(problem, solver, 12)
    return problem, results, reports


@pytest.fixture(scope="module")
def slides():
    return {consistent: _slide(consistent) for consistent in (True, False)}


def test_newton_converges_quadratically_on_a_mortar_slide(slides):
    """Every increment of the slide: its first solve's last step above round-off ends within
    10 ε_k², and the solve that follows at the re-evaluated geometry starts converged."""
    _, _, reports = slides[True]
    lines = []
    for load_factor, solves in solves_by_increment(reports, PRESSED_AT).items():
        eps = residuals(solves[0])
        step = last_step(solves[0])
        lines.append(f"  ℓ = {load_factor:.4f}: max(|R|, |H|)/F = {', '.join(f'{e:.1e}' for e in eps)}; last step "
                     f"{'–' if step is None else f'{step[0]:.1e} -> {step[1]:.1e}'}; iterates per solve "
                     f"{[len(r.history) for r in solves]}")
    print("\n" + "\n".join(lines))
    for (load_factor, solves), line in zip(solves_by_increment(reports, PRESSED_AT).items(), lines):
        step = last_step(solves[0])
        assert step is not None and step[1] <= 10.0 * step[0] ** 2 and step[1] / step[0] < 1e-3, line
        # the solution was in its own geometry already: the second solve's start is its only iterate
        assert [len(r.history) for r in solves[1:]] == [1] and solves[1].history[0].iteration == 0, line


def test_consistent_and_frozen_mortar_end_in_the_same_state(slides):
    consistent, frozen = slides[True], slides[False]
    f_c, f_f = slave_force(consistent[0]), slave_force(frozen[0])
    n_c, n_f = (sum(r.iterations for r in run[1]) for run in (consistent, frozen))
    du = np.abs(consistent[0].u.x.array - frozen[0].u.x.array).max() / np.abs(frozen[0].u.x.array).max()
    print(f"\n  consistent: F = {f_c}, {n_c} Newton iterations {[r.iterations for r in consistent[1]]}; frozen: "
          f"F = {f_f}, {n_f} {[r.iterations for r in frozen[1]]}; |ΔF|/|F| = "
          f"{np.linalg.norm(f_c - f_f) / np.linalg.norm(f_f):.1e}, max|Δu|/max|u| = {du:.1e}")
    assert np.linalg.norm(f_c - f_f) < 1e-8 * np.linalg.norm(f_f) and du < 1e-8
    assert n_c < 0.5 * n_f


def test_mortar_newton_matrix_matches_finite_differences_mid_slide():
    """J d against central differences of (R, H) at a perturbed state mid-slide (μ_f = 0.3)."""
    problem = sliding_blocks(slide=0.4, mu_f=0.3, discretisation="mortar")
    with make_solver("monolithic", problem, OPTIONS) as solver:
        solve_load_steps(problem, solver, 5, final_load_factor=5 / 12)
        error_u, error_H, frozen_u, frozen_H = newton_matrix_against_differences(problem, solver)
    print(f"\n  |J d − FD| / |FD|: u rows {error_u:.1e}, pair rows {error_H:.1e}; the frozen geometry's J: "
          f"{frozen_u:.1e}, {frozen_H:.1e}")
    assert error_u < 1e-6 and error_H < 1e-5
    assert frozen_u > 1e-4 or frozen_H > 1e-4  # the residuals differentiated are the current geometry's
