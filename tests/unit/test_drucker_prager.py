"""Drucker–Prager (issue 40, phase 2): homogeneous triaxial compression and the apex against closed
forms, the consistent tangent of both returns against finite differences, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import box_with_face_tags

from dolfinx_nnqem.material import DruckerPrager
from dolfinx_nnqem.material.drucker_prager import DruckerPragerAtPoints, _Cone, cone_coefficients, drucker_prager_return
from dolfinx_nnqem.material.hardening import HardeningAtPoints, LinearHardening, VoceHardening
from dolfinx_nnqem.material.kinematics import symmetric_coordinates
from dolfinx_nnqem.problem import ContactProblem, Dirichlet, Pressure
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

E, NU, COHESION = 2.0e7, 0.25, 1.0e4
K = E / (3 * (1 - 2 * NU))


@pytest.mark.parametrize("match, psi", [("outer", 30.0), ("outer", 10.0), ("inner", 0.0), ("plane-strain", 20.0)])
def test_triaxial_compression_matches_the_cone(match, psi):
    """A confining pressure p_c on the lateral faces, then axial compression: elastic
    σ_zz = −2ν p_c + E ε_zz, then (perfect plasticity) σ_zz = −p_c − d with the cone's
    d = (ξ c + η p_c)/(1/√3 − η/3), to 1e-10 at every increment; the outer cone's d is
    Mohr–Coulomb's 2c cos φ/(1 − sin φ) + 2 p_c sin φ/(1 − sin φ)."""
    phi, p_c, strain = 30.0, 5.0e4, 0.03
    mesh, ft = box_with_face_tags((1, 1, 1))
    ramp = lambda ell: min(1.0, 2.0 * ell)  # noqa: E731  the confinement, then the axial strain
    press = lambda ell: max(0.0, 2.0 * ell - 1.0)  # noqa: E731
    material = DruckerPrager(E, NU, COHESION, phi, psi, match)
    problem = ContactProblem(mesh, None, ft, materials=material,
                             dirichlet=[Dirichlet(1, 0.0, components=[0]), Dirichlet(3, 0.0, components=[1]),
                                        Dirichlet(5, 0.0, components=[2]),
                                        Dirichlet(6, -strain, components=[2], amplitude=press)],
                             tractions=[Pressure(2, p_c, amplitude=ramp), Pressure(4, p_c, amplitude=ramp)])
    eta, xi = cone_coefficients(match, phi)
    d = (xi * COHESION + eta * p_c) / (1 / math.sqrt(3) - eta / 3)
    if match == "outer":
        s = math.sin(math.radians(phi))
        mohr_coulomb = (2 * COHESION * math.cos(math.radians(phi)) + 2 * p_c * s) / (1 - s)
        assert abs(d - mohr_coulomb) <= 1e-12 * d
    path = []
    solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-12)), 20,
                     callbacks=[lambda r: path.append((r.load_factor, problem.state.sigma_n.x.array.reshape(-1, 3, 3)
                                                       .copy(), problem.state.p_n.x.array.copy()))])
    worst, plastic = 0.0, 0
    print(f"\n  {match}, phi {phi}, psi {psi}: eps_zz, sigma_zz (FE), closed form, p_bar, error / d")
    for ell, sigma, p in path:
        eps = -strain * press(ell)
        elastic = -2 * NU * p_c * ramp(ell) + E * eps
        expected = max(elastic, -p_c - d)
        plastic += expected != elastic
        lateral = np.abs(sigma[:, [0, 1], [0, 1]] + p_c * ramp(ell)).max()
        error = max(np.abs(sigma[:, 2, 2] - expected).max(), lateral, np.abs(sigma.reshape(-1, 9)[:, [1, 2, 3, 5, 6, 7]]).max()) / d
        worst = max(worst, error)
        print(f"  {eps: .4e}  {sigma[:, 2, 2].mean(): .12e}  {expected: .12e}  {p.mean():.3e}  {error:.1e}")
    print(f"  worst {worst:.1e} over {plastic} plastic increments (tolerance 1e-10)")
    assert plastic >= 5 and worst < 1e-10


def test_hydrostatic_tension_returns_to_the_apex():
    """Every face pulled out (ε_v = 3ε): past the apex p_h = β c(p̄) with p̄ = α ε_v^p and
    ε_v^p = (K ε_v − β c₀)/(K + α β H) (linear cohesion hardening, non-associated): σ = p_h I and
    p̄ to 1e-10 at every increment, whatever the increments."""
    phi, psi, H = 30.0, 10.0, 2.0e5
    mesh, ft = box_with_face_tags((1, 1, 1))
    eps = 1.0e-3
    material = DruckerPrager(E, NU, COHESION, phi, psi, "outer", H=H)
    problem = ContactProblem(mesh, None, ft, materials=material,
                             dirichlet=[Dirichlet(t, v, components=[c]) for c, (t0, t1) in enumerate([(1, 2), (3, 4), (5, 6)])
                                        for t, v in ((t0, 0.0), (t1, eps))])
    eta, xi = cone_coefficients("outer", phi)
    eta_bar, _ = cone_coefficients("outer", psi)
    alpha, beta = xi / eta_bar, xi / eta
    path = []
    solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-12)), 10,
                     callbacks=[lambda r: path.append((r.load_factor, problem.state.sigma_n.x.array.reshape(-1, 3, 3)
                                                       .copy(), problem.state.p_n.x.array.copy()))])
    worst, at_apex = 0.0, 0
    print("\n  eps_v, p_h (FE), closed form, p_bar (FE), closed form, error")
    for ell, sigma, p in path:
        ev = 3 * eps * ell
        ev_p = max(0.0, (K * ev - beta * COHESION) / (K + alpha * beta * H))
        at_apex += ev_p > 0
        p_h, p_bar = K * (ev - ev_p), alpha * ev_p
        error = max(np.abs(sigma - p_h * np.eye(3)).max() / (beta * COHESION), np.abs(p - p_bar).max() / max(p_bar, 1e-6))
        worst = max(worst, error)
        print(f"  {ev:.3e}  {np.trace(sigma, axis1=1, axis2=2).mean() / 3: .12e}  {p_h: .12e}  {p.mean():.6e}  "
              f"{p_bar:.6e}  {error:.1e}")
    print(f"  worst {worst:.1e} over {at_apex} increments at the apex (tolerance 1e-10)")
    assert at_apex >= 5 and worst < 1e-10


def _points(n, seed, phi, psi, law):
    rng = np.random.default_rng(seed)
    sym = lambda A: 0.5 * (A + A.transpose(0, 2, 1))  # noqa: E731
    mu, kappa = np.full(n, E / (2 * (1 + NU))), np.full(n, K)
    eta, xi = cone_coefficients("outer", phi)
    eta_bar, _ = cone_coefficients("outer", psi)
    cone = _Cone(mu, kappa, np.full(n, eta), np.full(n, xi), np.full(n, eta_bar),
                 HardeningAtPoints(np.zeros(n, dtype=np.int64), [law]))
    sigma_n = sym(rng.standard_normal((n, 3, 3))) * 5e3 - 2e4 * np.eye(3)
    deps = sym(rng.standard_normal((n, 3, 3))) * 1e-3
    deps += np.eye(3) * np.linspace(-1e-3, 4e-3, n)[:, None, None]  # the last ones pulled to the apex
    deps[::5] *= 1e-4  # some stay elastic
    return sigma_n, deps, rng.uniform(0.0, 0.01, n), cone


@pytest.mark.parametrize("psi, law", [(30.0, LinearHardening(COHESION, 2e5)), (10.0, LinearHardening(COHESION, 2e5)),
                                      (10.0, VoceHardening(COHESION, 5e3, 50.0, 1e4)), (0.0, LinearHardening(COHESION, 0.0))],
                         ids=["associated", "non-associated", "voce", "psi-0-perfect"])
def test_consistent_tangent_matches_finite_differences(psi, law):
    """C_alg of both returns (the cone, the apex inside its region) against central differences of
    σ(Δε): 1e-6 relative; symmetric for ψ = φ only."""
    n = 40
    sigma_n, deps, p_n, cone = _points(n, 5, 30.0, psi, law)
    if psi == 0.0:
        deps = 3.0 * (deps - np.trace(deps, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3) - 1e-3 * np.eye(3)
        deps[::5] *= 1e-4  # no dilatancy: no apex return (sheared and compressed); some elastic
    sigma, dp, _, Calg = drucker_prager_return(sigma_n, deps, p_n, cone)
    points = DruckerPragerAtPoints(cone, cone.kappa - 2 * cone.mu / 3, np.full(n, E))
    apex = np.linalg.norm(symmetric_coordinates(sigma)[:, :5], axis=1) <= 1e-9 * COHESION
    h, worst = 1e-8, 0.0  # strains ~1e-3: round-off grows below, truncation above
    for k in range(3):
        for m in range(k, 3):
            d = np.zeros((3, 3))
            d[k, m] = d[m, k] = 1.0
            fd = (drucker_prager_return(sigma_n, deps + h * d, p_n, cone)[0]
                  - drucker_prager_return(sigma_n, deps - h * d, p_n, cone)[0]) / (2 * h)
            tangent = np.einsum("nijkl,kl->nij", Calg, d)
            scale = np.maximum(np.linalg.norm(fd, axis=(1, 2)), 1e-3 * E)
            worst = max(worst, float(np.max(np.linalg.norm(tangent - fd, axis=(1, 2)) / scale)))
    asymmetry = float(np.max(np.abs(Calg - Calg.transpose(0, 3, 4, 1, 2))) / np.max(np.abs(Calg)))
    f = points.yield_value(symmetric_coordinates(sigma), {"p": p_n + dp})
    print(f"\n  psi {psi}: {np.count_nonzero(dp > 0) - np.count_nonzero(apex)} on the cone, {np.count_nonzero(apex)} at the "
          f"apex, {np.count_nonzero(dp == 0)} elastic; C_alg vs FD {worst:.1e} (tolerance 1e-6); "
          f"|C - C^T|/|C| {asymmetry:.1e}; max f/c on the plastic points {np.abs(f[dp > 0]).max() / COHESION:.1e}")
    assert np.count_nonzero(dp == 0) >= 4 and np.count_nonzero(dp > 0) - np.count_nonzero(apex) >= 5
    assert psi == 0.0 or np.count_nonzero(apex) >= 5
    assert worst < 1e-6 and np.abs(f[dp > 0]).max() < 1e-9 * COHESION
    assert (asymmetry < 1e-12) if psi == 30.0 else (psi == 0.0 or asymmetry > 1e-6)


def test_zero_dilatancy_beyond_the_apex_is_refused_with_the_reason():
    """ψ = 0 gives no volumetric plastic strain: a trial stress beyond the apex has no return."""
    n = 4
    sigma_n, deps, p_n, cone = _points(n, 1, 30.0, 0.0, LinearHardening(COHESION, 0.0))
    with pytest.raises(ValueError, match="dilatancy_angle = 0 .* beyond the cone's apex"):
        drucker_prager_return(sigma_n, deps + 1e-2 * np.eye(3), p_n, cone)


@pytest.mark.parametrize("make, match", [
    (lambda: DruckerPrager(E, NU, COHESION, 90.0), "friction_angle = 90.0"),
    (lambda: DruckerPrager(E, NU, COHESION, -5.0), "friction_angle = -5.0"),
    (lambda: DruckerPrager(E, NU, COHESION, 30.0, 35.0), "dilatancy_angle = 35.0 .* psi <= friction_angle"),
    (lambda: DruckerPrager(E, NU, COHESION, 30.0, -1.0), "dilatancy_angle = -1.0"),
    (lambda: DruckerPrager(E, NU, 0.0, 30.0), "cohesion = 0.0"),
    (lambda: DruckerPrager(E, NU, -1.0, 30.0), "cohesion = -1.0"),
    (lambda: DruckerPrager(E, NU, COHESION, 30.0, match="middle"), "match = 'middle'"),
    (lambda: DruckerPrager(-E, NU, COHESION, 30.0), "E = -2"),
    (lambda: DruckerPrager(E, NU, COHESION, 30.0, H=-1.0), "H = -1.0"),
    (lambda: DruckerPrager(E, NU, COHESION, 30.0, hardening=LinearHardening(COHESION, 0.0)), "not both"),
])
def test_bad_input_is_refused_naming_the_key(make, match):
    with pytest.raises(ValueError, match=match):
        make()
