"""Kinematic hardening (issue 40, phase 2): Prager, Armstrong–Frederick and Chaboche back-stresses
combined with isotropic hardening, against closed forms on homogeneous tension–compression cycles,
their consistent tangent against finite differences, and a restart in the middle of a cycle."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import box_with_face_tags

from dolfinx_nnqem.io import checkpoint
from dolfinx_nnqem.material import DEVIATORIC_BASIS, BackStress, LinearHardening, VoceHardening, VonMises
from dolfinx_nnqem.material.hardening import HardeningAtPoints
from dolfinx_nnqem.material.kinematic import KinematicAtPoints, kinematic_return
from dolfinx_nnqem.problem import ContactProblem, Dirichlet
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

E, NU, SY = 2.0e11, 0.3, 2.5e8
DELTA = 0.01  # the strain amplitude of the cycle (50 times the yield strain)


def triangle(ell: float) -> float:
    """0 → +1 → −1 → +1 linearly in thirds of ℓ."""
    if ell <= 1 / 3:
        return 3 * ell
    if ell <= 2 / 3:
        return 1 - 6 * (ell - 1 / 3)
    return -1 + 6 * (ell - 2 / 3)


def uniaxial_problem(material, comm=None):
    """One hexahedron pulled along x (ε_xx = DELTA · triangle(ℓ)), its lateral faces free."""
    mesh, ft = box_with_face_tags((1, 1, 1))
    return ContactProblem(mesh, None, ft, materials=material,
                          dirichlet=[Dirichlet(1, 0.0, components=[0]), Dirichlet(3, 0.0, components=[1]),
                                     Dirichlet(5, 0.0, components=[2]),
                                     Dirichlet(2, DELTA, components=[0], amplitude=triangle)])


def run_cycle(material, increments: int, **kwargs):
    """(ε_xx, σ_xx, p, uniaxial back-stress X = (3/2) α_xx per back-stress) after every increment."""
    problem = uniaxial_problem(material)
    path = []

    def record(result):
        st = problem.state
        sigma = st.sigma_n.x.array.reshape(-1, 3, 3)
        off_axis = float(np.abs(sigma.reshape(-1, 9)[:, 1:]).max())
        X = [1.5 * f.x.array.reshape(-1, 3, 3)[:, 0, 0] for name, f in st.internal_variables.items() if name != "p"]
        path.append((DELTA * triangle(result.load_factor), sigma[:, 0, 0].copy(), st.p_n.x.array.copy(),
                     np.array(X), off_axis))

    solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-12)), increments,
                     callbacks=[record], **kwargs)
    return problem, path


def reference_1d(law, back, eps_path):
    """The uniaxial backward-Euler return, scalar: per strain ε, σ = E(ε − ε_p), |σ − ΣX_k| ≤ σ_y(p),
    X_k = (X_k,n + C_k s Δp)/(1 + γ_k Δp), Δp from its scalar equation by bisection to the last bit."""
    eps_p, p, X = 0.0, 0.0, np.zeros(len(back))
    C, g = np.array([b.C for b in back]), np.array([b.gamma for b in back])
    out = []
    for eps in eps_path:
        xi0 = E * (eps - eps_p) - X.sum()
        s = math.copysign(1.0, xi0)
        if abs(xi0) - law.yield_stress(np.array([p]))[0] > 0.0:
            def r(dp):
                return (abs(E * (eps - eps_p) - (X / (1 + g * dp)).sum()) - (E + (C / (1 + g * dp)).sum()) * dp
                        - law.yield_stress(np.array([p + dp]))[0])
            low, high = 0.0, abs(eps - eps_p) + 1.0
            for _ in range(300):
                mid = 0.5 * (low + high)
                low, high = (mid, high) if r(mid) > 0 else (low, mid)
            dp = 0.5 * (low + high)
            eps_p += s * dp
            p += dp
            X = (X + C * s * dp) / (1 + g * dp)
        out.append((E * (eps - eps_p), p, X.copy()))
    return out


def prager_closed_form(eps: np.ndarray, C: float) -> np.ndarray:
    """σ(ε) of the cycle with Prager's linear back-stress and no isotropic hardening: elastic, then the
    slope E_t = E C/(E + C); each reversal is elastic over 2σ_y (Bauschinger), then E_t again."""
    Et = E * C / (E + C)
    out, turn_eps, turn_sigma, direction = [], 0.0, 0.0, 1.0
    for k, e in enumerate(eps):
        if k and (e - eps[k - 1]) * direction < 0:  # a reversal: the last point is the new origin
            direction = -direction
            turn_eps, turn_sigma = eps[k - 1], out[-1]
        start = SY if k == 0 or turn_eps == 0.0 else 2 * SY  # the elastic range from the turning point
        elastic = turn_sigma + E * (e - turn_eps)
        if direction * (elastic - turn_sigma) <= start:
            out.append(elastic)
        else:
            yield_eps = turn_eps + direction * start / E
            out.append(turn_sigma + direction * start + Et * (e - yield_eps))
    return np.array(out)


def test_prager_cycle_matches_the_closed_form():
    """The stress–strain loop with linear kinematic hardening (H = 0) is piecewise linear: every
    increment of a tension–compression–tension cycle to 1e-10."""
    C = 2.0e10
    _, path = run_cycle(VonMises(E, NU, SY, kinematic=[BackStress(C)]), 30)
    eps = np.array([e for e, *_ in path])
    expected = prager_closed_form(eps, C)
    worst = 0.0
    print("\n  eps_xx, sigma_xx (FE), closed form, relative error")
    for (e, sigma, p, X, off), want in zip(path, expected):
        error = max(np.abs(sigma - want).max(), off) / SY
        worst = max(worst, error)
        print(f"  {e: .4e}  {sigma.mean(): .12e}  {want: .12e}  {error:.1e}")
    print(f"  worst error / sigma_y {worst:.1e} (tolerance 1e-10)")
    assert worst < 1e-10


@pytest.mark.parametrize("law, back", [
    (LinearHardening(SY, 0.0), [BackStress(4.0e10, 400.0)]),
    (VoceHardening(SY, 1.0e8, 30.0, 0.0), [BackStress(6.0e10, 600.0), BackStress(5.0e9, 0.0)]),
], ids=["armstrong-frederick", "chaboche-2-with-voce"])
def test_nonlinear_kinematic_cycle_matches_the_uniaxial_return(law, back):
    """Armstrong–Frederick (and Chaboche with two back-stresses on Voce): σ_xx, p and each
    back-stress at every increment of the cycle against the scalar uniaxial return, to 1e-10."""
    material = VonMises(E, NU, hardening=law, kinematic=back) if not isinstance(law, LinearHardening) else \
        VonMises(E, NU, law.sigma_y0, law.H, kinematic=back)
    _, path = run_cycle(material, 30)
    reference = reference_1d(law, back, [e for e, *_ in path])
    worst = 0.0
    print("\n  eps_xx, sigma_xx (FE), reference, X_k (FE), error / sigma_y")
    for (e, sigma, p, X, off), (s_ref, p_ref, X_ref) in zip(path, reference):
        error = max(np.abs(sigma - s_ref).max(), np.abs(X - X_ref[:, None]).max(), off) / SY
        error = max(error, np.abs(p - p_ref).max() / max(p_ref, 1e-3))
        worst = max(worst, error)
        print(f"  {e: .4e}  {sigma.mean(): .10e}  {s_ref: .10e}  {X.mean(axis=1)}  {error:.1e}")
    print(f"  worst {worst:.1e} (tolerance 1e-10)")
    assert worst < 1e-10


def test_armstrong_frederick_tends_to_the_exponential_closed_form():
    """The uniaxial back-stress under plastic flow of sign s from (p₀, X₀) is
    X = s C/γ + (X₀ − s C/γ) e^{−γ (p − p₀)}: backward Euler approaches it at first order, the
    error falling 4 times when the increments are 4 times smaller."""
    C, gamma = 1.0e10, 100.0
    material = VonMises(E, NU, SY, kinematic=[BackStress(C, gamma)])
    errors = []
    for n in (60, 240):
        _, path = run_cycle(material, n)
        worst, exact, p_last, eps_last = 0.0, 0.0, 0.0, 0.0
        for e, sigma, p, X, off in path:
            sign = math.copysign(1.0, e - eps_last)  # the leg's direction of flow
            pk = float(p.mean())
            exact = sign * C / gamma + (exact - sign * C / gamma) * math.exp(-gamma * (pk - p_last))
            worst = max(worst, abs(float(X[0].mean()) - exact) / (C / gamma))
            p_last, eps_last = pk, e
        errors.append(worst)
    print(f"\n  |X - closed form| / (C/gamma): {errors[0]:.2e} (60 increments), {errors[1]:.2e} (240); "
          f"ratio {errors[0] / errors[1]:.2f} (first order: 4)")
    assert 3.0 < errors[0] / errors[1] < 5.0 and errors[1] < 1e-2


def _plastic_points(n, seed):
    rng = np.random.default_rng(seed)
    sym = lambda A: 0.5 * (A + A.transpose(0, 2, 1))  # noqa: E731
    alpha = rng.standard_normal((n, 2, 5)) * 4e7
    sigma_n = sym(rng.standard_normal((n, 3, 3))) * 1.5e8
    deps = sym(rng.standard_normal((n, 3, 3))) * 2e-3
    deps[::4] *= 1e-3  # every fourth point stays elastic: at the centre of its elastic domain
    sigma_n[::4] = np.einsum("nka,aij->nij", alpha[::4], DEVIATORIC_BASIS.reshape(5, 3, 3))
    return sigma_n, deps, alpha, rng.uniform(0.0, 0.01, n)


@pytest.mark.parametrize("gamma", [(0.0, 0.0), (500.0, 0.0), (800.0, 100.0)], ids=["prager", "af-and-prager", "chaboche"])
def test_consistent_tangent_matches_finite_differences(gamma):
    """C_alg against central differences of σ(Δε), and NNEQM2's ∂Δε_p/∂e against those of Δε_p(e):
    1e-6 relative; Prager's is symmetric, Armstrong–Frederick's is not."""
    n = 16
    sigma_n, deps, alpha, p_n = _plastic_points(n, 7)
    mu, lmbda = np.full(n, E / (2 * (1 + NU))), np.full(n, E * NU / ((1 + NU) * (1 - 2 * NU)))
    law = HardeningAtPoints(np.zeros(n, dtype=np.int64), [VoceHardening(SY, 1e8, 40.0, 1e9)])
    C, g = np.tile([5e10, 1e10], (n, 1)), np.tile(gamma, (n, 1))
    sigma, dp, _, Calg = kinematic_return(sigma_n, deps, alpha, p_n, mu, lmbda, C, g, law)
    assert np.count_nonzero(dp > 0) >= n // 2 and np.count_nonzero(dp == 0) >= n // 8
    h, worst = 1e-9, 0.0
    for k in range(3):
        for m in range(k, 3):
            d = np.zeros((3, 3))
            d[k, m] = d[m, k] = 1.0
            fd = (kinematic_return(sigma_n, deps + h * d, alpha, p_n, mu, lmbda, C, g, law)[0]
                  - kinematic_return(sigma_n, deps - h * d, alpha, p_n, mu, lmbda, C, g, law)[0]) / (2 * h)
            tangent = np.einsum("nijkl,kl->nij", Calg, d)
            worst = max(worst, float(np.max(np.linalg.norm(tangent - fd, axis=(1, 2))
                                            / np.linalg.norm(fd, axis=(1, 2)))))
    asymmetry = float(np.max(np.abs(Calg - Calg.transpose(0, 3, 4, 1, 2))) / np.max(np.abs(Calg)))
    from dolfinx_nnqem.material.kinematics import deviator_coordinates, deviator_tensors
    points = KinematicAtPoints(mu, lmbda, np.full(n, E), law, C, g, ("alpha_1", "alpha_2"))
    internal = {"p": p_n, "alpha_1": deviator_tensors(alpha[:, 0]), "alpha_2": deviator_tensors(alpha[:, 1])}
    t = deviator_coordinates(sigma_n) + 2 * mu[:, None] * deviator_coordinates(deps)
    R = points.plastic_strain_tangent(t, internal)
    worst_nneqm2 = 0.0
    for a in range(5):
        e = np.zeros(5)
        e[a] = 1e-9
        fd = (points.plastic_strain(t + 2 * mu[:, None] * e, internal)[0]
              - points.plastic_strain(t - 2 * mu[:, None] * e, internal)[0]) / (2e-9)
        scale = np.maximum(np.linalg.norm(fd, axis=1), np.abs(R).max())
        worst_nneqm2 = max(worst_nneqm2, float(np.max(np.linalg.norm(R[:, :, a] - fd, axis=1) / scale)))
    print(f"\n  gamma = {gamma}: {np.count_nonzero(dp > 0)} of {n} plastic; C_alg vs FD {worst:.1e}, "
          f"dΔε_p/de vs FD {worst_nneqm2:.1e} (tolerance 1e-6); asymmetry |C - C^T|/|C| {asymmetry:.1e}")
    assert worst < 1e-6 and worst_nneqm2 < 1e-6
    assert (asymmetry < 1e-12) if gamma == (0.0, 0.0) else (asymmetry > 1e-6)


def test_restart_in_the_middle_of_a_cycle_equals_an_uninterrupted_run(tmp_path):
    """Interrupted just after the first reversal (the back-stress not yet turned) and resumed from the
    checkpoint in a fresh problem: the stress, p and the back-stresses equal the uninterrupted run's."""
    material = VonMises(E, NU, SY, kinematic=[BackStress(4.0e10, 400.0), BackStress(5.0e9)])
    n = 12
    ref, _ = run_cycle(material, n)
    first = uniaxial_problem(material)
    checkpointer = checkpoint.Checkpointer(tmp_path)

    def stop_after_5(problem, stepper_state, result):
        checkpointer(problem, stepper_state, result)
        if result.index == 5:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        solve_load_steps(first, make_solver("monolithic", first, SolverOptions(rtol=1e-12)), n,
                         checkpoint=stop_after_5)
    second = uniaxial_problem(material)
    state, _ = checkpoint.restore(second, tmp_path)
    solve_load_steps(second, make_solver("monolithic", second, SolverOptions(rtol=1e-12)), n, resume=state)
    worst = {name: float(np.max(np.abs(second.state.internal_variables[name].x.array - f.x.array))
                         / max(np.max(np.abs(f.x.array)), 1e-300))
             for name, f in ref.state.internal_variables.items()}
    worst["sigma"] = float(np.max(np.abs(second.state.sigma_n.x.array - ref.state.sigma_n.x.array))
                           / np.max(np.abs(ref.state.sigma_n.x.array)))
    print(f"\n  resumed at increment {state.index}; relative differences {worst}")
    assert state.index == 5 and set(worst) == {"p", "alpha_1", "alpha_2", "sigma"}
    assert all(v <= 1e-12 for v in worst.values())
