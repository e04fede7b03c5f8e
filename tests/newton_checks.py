"""What the tests of a consistent linearisation read from a monolithic solver: the residual
sequences of its solves and its Newton matrix against central differences of the residuals."""

from __future__ import annotations

import numpy as np

ROUND_OFF = 1e-12  #: residuals below this (relative to the force scale) are round-off: no rate is read there


def residuals(report) -> np.ndarray:
    """max(|R|/F, |H|/F) of the solve's iterates."""
    return np.array([max(r.equilibrium, r.contact) for r in report.history])


def last_step(report) -> tuple[float, float] | None:
    """(ε_k, ε_{k+1}) of the solve's last step that ends above round-off, or None."""
    eps = residuals(report)
    steps = [(eps[k], eps[k + 1]) for k in range(len(eps) - 1) if eps[k + 1] > ROUND_OFF]
    return steps[-1] if steps else None


def solves_by_increment(reports, pressed_at: float) -> dict[float, list]:
    """The solves of every increment past the load factor ``pressed_at``, in order; ``reports`` holds
    (load factor, report, ...) per solve."""
    out: dict[float, list] = {}
    for load_factor, report, *_ in reports:
        if load_factor > pressed_at + 1e-12:
            out.setdefault(load_factor, []).append(report)
    return out


def newton_matrix_against_differences(problem, solver, seed: int = 0) -> tuple[float, float, float, float]:
    """J d against central differences of (R, H) at the solver's state perturbed by 1e-4 (random, free
    dofs), along a random free direction d: the relative errors of the u rows and the pair rows, then
    the same for the frozen geometry's J at that state (``consistent_geometry`` off: the residuals
    differentiated are the current geometry's, so it must be off). Leaves the solver with the frozen
    geometry."""
    rng = np.random.default_rng(seed)
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

    def error(rows: slice, Jx: np.ndarray) -> float:
        return float(np.abs(fd[rows] - Jx[rows]).max() / np.abs(fd[rows]).max())

    u_rows, pair_rows = slice(0, n_u), slice(n_u, None)
    return error(u_rows, Jd), error(pair_rows, Jd), error(u_rows, J_frozen_d), error(pair_rows, J_frozen_d)


def direct_step_in_augmented_system(problem, options, leave_out, min_sliding: int = 1) -> tuple[float, float]:
    """The direct solver's Newton step at a sliding iterate (load factor 0.52 after 8 increments to 0.5),
    put into the iterative solver's augmented system: |J_aug d − b_aug| / |b_aug|, then the same after
    ``leave_out()`` (which takes a part of the augmentation away, e.g. by a monkeypatch). The first is
    round-off where the augmented system holds every term of the direct one."""
    from dolfinx_nnqem.solvers import MonolithicOptions, make_solver, solve_load_steps

    settings = {kind: MonolithicOptions(linear_solver=kind) for kind in ("direct", "iterative")}
    with make_solver("monolithic", problem, options, monolithic=settings["direct"]) as direct, \
            make_solver("monolithic", problem, options, monolithic=settings["iterative"]) as iterative:
        solve_load_steps(problem, direct, 8, final_load_factor=0.5)
        problem.apply_prescribed_displacements(0.52)
        ev = direct.evaluate()
        assert np.count_nonzero(ev.law.state == 2) >= min_sliding
        du, dz = direct.newton_direction(ev)

        def residual() -> float:
            J, b = iterative._augmented_system(iterative.evaluate())
            x, r = b.duplicate(), b.duplicate()
            x.getArray()[:] = np.concatenate([du, dz.ravel()])
            J.mult(x, r)
            r.axpy(-1.0, b)
            out = r.norm() / b.norm()
            for vector in (x, r):
                vector.destroy()
            return out

        error = residual()
        leave_out()
        return error, residual()


def recorded_load_steps(problem, solver, increments: int, **kwargs) -> tuple[list, list]:
    """``solve_load_steps`` with every solve the solver makes recorded: (its results, [(load factor, report)]
    per solve, in order)."""
    from dolfinx_nnqem.solvers import solve_load_steps

    reports: list = []
    solve_increment = solver.solve_increment

    def recording(load_factor):
        report = solve_increment(load_factor)
        reports.append((load_factor, report))
        return report

    solver.solve_increment = recording
    return solve_load_steps(problem, solver, increments, **kwargs), reports
