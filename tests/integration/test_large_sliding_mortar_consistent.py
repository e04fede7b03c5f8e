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

from dolfinx_nnqem.cases.large_sliding import PRESSED_AT, slave_force, sliding_blocks
from dolfinx_nnqem.solvers import MonolithicOptions, SolverOptions, make_solver, solve_load_steps

OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)
ROUND_OFF = 1e-12  #: residuals below this (relative to the force scale) are round-off: no rate is read there


def _slide(consistent: bool):
    """The frictional mortar slide; (problem, results, every solve's (load factor, report))."""
    problem = sliding_blocks(slide=0.4, mu_f=0.3, discretisation="mortar")
    reports = []
    with make_solver("monolithic", problem, OPTIONS,
                     monolithic=MonolithicOptions(consistent_geometry=consistent)) as solver:
        solve_increment = solver.solve_increment

        def recording(load_factor):
            report = solve_increment(load_factor)
            reports.append((load_factor, report))
            return report

        solver.solve_increment = recording
        results = solve_load_steps(problem, solver, 12)
    return problem, results, reports


def _residuals(report) -> np.ndarray:
    """max(|R|/F, |H|/F) of the solve's iterates."""
    return np.array([max(r.equilibrium, r.contact) for r in report.history])


def _last_step(report) -> tuple[float, float] | None:
    """(ε_k, ε_{k+1}) of the solve's last step that ends above round-off, or None."""
    eps = _residuals(report)
    steps = [(eps[k], eps[k + 1]) for k in range(len(eps) - 1) if eps[k + 1] > ROUND_OFF]
    return steps[-1] if steps else None


def _solves_by_increment(reports) -> dict[float, list]:
    """The solves of every increment of the slide (load factor past the press), in order."""
    out: dict[float, list] = {}
    for load_factor, report in reports:
        if load_factor > PRESSED_AT + 1e-12:
            out.setdefault(load_factor, []).append(report)
    return out


@pytest.fixture(scope="module")
def slides():
    return {consistent: _slide(consistent) for consistent in (True, False)}


def test_newton_converges_quadratically_on_a_mortar_slide(slides):
    """Every increment of the slide: its first solve's last step above round-off ends within
    10 ε_k², and the solve that follows at the re-evaluated geometry starts converged."""
    _, _, reports = slides[True]
    lines = []
    for load_factor, solves in _solves_by_increment(reports).items():
        eps = _residuals(solves[0])
        step = _last_step(solves[0])
        lines.append(f"  ℓ = {load_factor:.4f}: max(|R|, |H|)/F = {', '.join(f'{e:.1e}' for e in eps)}; last step "
                     f"{'–' if step is None else f'{step[0]:.1e} -> {step[1]:.1e}'}; iterates per solve "
                     f"{[len(r.history) for r in solves]}")
    print("\n" + "\n".join(lines))
    for (load_factor, solves), line in zip(_solves_by_increment(reports).items(), lines):
        step = _last_step(solves[0])
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
        rng = np.random.default_rng(0)
        n_u = problem.u.x.petsc_vec.getLocalSize()
        free = np.ones(n_u)
        free[problem.owned_bc_dofs()] = 0.0
        problem.u.x.array[:n_u] += 1e-4 * rng.standard_normal(n_u) * free
        problem.u.x.scatter_forward()
        J = solver._newton_matrix(solver.evaluate())
        d = rng.standard_normal(n_u) * free
        x, y = J.createVecRight(), J.createVecLeft()
        x.getArray()[:] = 0.0
        x.getArray()[:n_u] = d
        J.mult(x, y)
        Jd = y.getArray().copy()
        u0 = problem.u.x.array.copy()

        def F(sign: float) -> np.ndarray:
            problem.u.x.array[:] = u0
            problem.u.x.array[:n_u] += sign * 1e-7 * d
            problem.u.x.scatter_forward()
            ev = solver.evaluate()
            return np.concatenate([ev.R_free.getArray().copy(), ev.H.ravel()])

        fd = (F(1.0) - F(-1.0)) / 2e-7
        solver.settings.consistent_geometry = False  # the frozen geometry's J at the same state
        problem.u.x.array[:] = u0
        problem.u.x.scatter_forward()
        solver._newton_matrix(solver.evaluate()).mult(x, y)
        J_frozen_d = y.getArray().copy()
    error_u = np.abs(fd[:n_u] - Jd[:n_u]).max() / np.abs(fd[:n_u]).max()
    error_H = np.abs(fd[n_u:] - Jd[n_u:]).max() / np.abs(fd[n_u:]).max()
    frozen_u = np.abs(fd[:n_u] - J_frozen_d[:n_u]).max() / np.abs(fd[:n_u]).max()
    frozen_H = np.abs(fd[n_u:] - J_frozen_d[n_u:]).max() / np.abs(fd[n_u:]).max()
    print(f"\n  |J d − FD| / |FD|: u rows {error_u:.1e}, pair rows {error_H:.1e}; the frozen geometry's J: "
          f"{frozen_u:.1e}, {frozen_H:.1e}")
    assert error_u < 1e-6 and error_H < 1e-5
    assert frozen_u > 1e-4 or frozen_H > 1e-4  # the residuals differentiated are the current geometry's
