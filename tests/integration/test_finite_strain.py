"""Finite strain through the whole FE pipeline (issue 41): ``ContactProblem(..., kinematics="finite")``.

* homogeneous states of one hexahedron against closed forms: uniaxial stretch to 100 % with von Mises
  (linear, Voce hardening), the Cauchy stress against the logarithmic strain, 1e-10; simple shear of
  Neo-Hooke, 1e-10 (and the check's deformed-mesh measure, sin θ of the sheared cell);
* a rigid rotation of 90° of a pre-stressed (plastically stretched) body rotates the stress, the
  elastic b_e and the nodal forces, and adds no plastic strain;
* small strain as the limit: at loads of 1e-4 the two kinematics agree to 1e-4;
* a rigid sphere pressed into an elastoplastic block (current contact geometry), monolithic and
  NNEQM1, both pair laws: the same answer, Newton's residuals superlinear at the end;
* the check at finite strain: an inverted state and a flattened deformed cell are named;
* the refusals: a kinematics that does not exist, Neo-Hooke at small strain, NNEQM2 at finite strain,
  a problem file's kinematics.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import box_with_face_tags
from mpi4py import MPI

from dolfinx_nnqem.material import Elastic, VoceHardening, VonMises
from dolfinx_nnqem.material.finite_strain import NeoHooke
from dolfinx_nnqem.problem import ContactProblem, Dirichlet, Traction
from dolfinx_nnqem.problem_file import ProblemFileError, build_problem, load_problem_file
from dolfinx_nnqem.solvers import CheckOptions, SolverOptions, make_solver, solve_load_steps
from dolfinx_nnqem.solvers.checks import check_state

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "mpi_scripts"))
from finite_strain import sphere_into_block  # noqa: E402

E, NU = 2.0e11, 0.3
SIGMA_Y0, H_LIN = 2.5e8, 1.0e9
VOCE = VoceHardening(sigma_0=2.5e8, Q=1.5e8, b=40.0, H=1.0e9)
LARGE = CheckOptions(max_strain=None, max_rotation=None)  # (not applied at finite strain: shown to be so)


def uniaxial_problem(material, stretch: float, kinematics: str = "finite") -> ContactProblem:
    """One hexahedron [0, 1]³ on rollers at x = 0, y = 0, z = 0, its face x = 1 moved by ℓ · ``stretch``."""
    mesh, ft = box_with_face_tags((1, 1, 1))
    return ContactProblem(mesh, None, ft, materials=material, kinematics=kinematics,
                          dirichlet=[Dirichlet(1, 0.0, components=[0]), Dirichlet(3, 0.0, components=[1]),
                                     Dirichlet(5, 0.0, components=[2]), Dirichlet(2, stretch, components=[0])])


def uniaxial_cauchy(yield_stress, eps: float) -> float:
    """σ_xx of uniaxial tension at the logarithmic strain ε = ln λ (Hencky's law in the logarithmic
    space, plastic incompressibility): the Kirchhoff stress τ solves σ_y(p) = τ = E (ε − p) (bisection
    to the last bit) above σ_y(0)/E; then J = exp(tr ε_e) = exp((1 − 2ν) τ / E) and σ = τ / J."""
    if E * eps <= yield_stress(0.0):
        tau = E * eps
    else:
        low, high = 0.0, eps
        for _ in range(200):
            mid = 0.5 * (low + high)
            if yield_stress(mid) < E * (eps - mid):
                low = mid
            else:
                high = mid
        tau = E * (eps - 0.5 * (low + high))
    return tau * math.exp(-(1.0 - 2.0 * NU) * tau / E)


LAWS = {
    "linear": (VonMises(E=E, nu=NU, sigma_y0=SIGMA_Y0, H=H_LIN), lambda p: SIGMA_Y0 + H_LIN * p),
    "voce": (VonMises(E=E, nu=NU, hardening=VOCE), lambda p: float(VOCE.yield_stress(np.array([p]))[0])),
}


@pytest.mark.parametrize("law", sorted(LAWS))
def test_uniaxial_stretch_to_100_percent_matches_the_closed_form(law):
    """Stretched to twice its length in 10 increments: σ_xx (Cauchy) at every increment against the
    closed form at ε = ln(1 + ℓ), 1e-10, every other component 0; the check passes at every increment
    (its measures at finite strain: J > 0, the law in the logarithmic space, the deformed cell)."""
    material, yield_stress = LAWS[law]
    problem = uniaxial_problem(material, 1.0)
    path = []
    results = solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-12)), 10, check=LARGE,
                               callbacks=[lambda r: path.append((r.load_factor, problem.state.sigma_n.x.array
                                                                 .reshape(-1, 3, 3).copy()))])
    worst = 0.0
    print(f"\n  {law}: stretch, ln λ, σ_xx (FE), closed form, relative error")
    for ell, sigma in path:
        eps = math.log(1.0 + ell)
        expected = uniaxial_cauchy(yield_stress, eps)
        error = max(np.abs(sigma[:, 0, 0] - expected).max(), np.abs(sigma.reshape(-1, 9)[:, 1:]).max()) / expected
        worst = max(worst, error)
        print(f"  {1 + ell:.2f}  {eps:.6f}  {sigma[:, 0, 0].mean():.12e}  {expected:.12e}  {error:.1e}")
    print(f"  worst {worst:.1e} (tolerance 1e-10); the check's largest sym grad u {results[-1].check.max_strain:.3f} "
          f"(max_strain not applied), constitutive {results[-1].check.constitutive}")
    assert len(path) == 10 and worst < 1e-10
    assert problem.state.p_n.x.array.min() > 0.5  # far into the plastic range
    assert all(r.check.ok and r.check.min_shape_ratio > 0.999 for r in results)


def test_simple_shear_of_neo_hooke_matches_the_closed_form():
    """One hexahedron, its bottom held and its top moved by ℓ γ e_x (every node prescribed: F = I + ℓγ
    e_x⊗e_y at every Gauss point): σ = μ (b − I) (J = 1): σ_xy = μγ, σ_xx = μγ², the rest 0, 1e-10; the
    check's shape ratio of the deformed cell is sin θ = 1/√(1 + γ²)."""
    gamma, mu = 1.0, E / (2 * (1 + NU))
    mesh, ft = box_with_face_tags((1, 1, 1))
    problem = ContactProblem(mesh, None, ft, materials=NeoHooke(E=E, nu=NU), kinematics="finite",
                             dirichlet=[Dirichlet(3, 0.0), Dirichlet(4, (gamma, 0.0, 0.0))])
    results = solve_load_steps(problem, make_solver("monolithic", problem), 4)
    sigma = problem.state.sigma_n.x.array.reshape(-1, 3, 3)
    expected = np.zeros((3, 3))
    expected[0, 1] = expected[1, 0] = mu * gamma
    expected[0, 0] = mu * gamma**2
    error = np.abs(sigma - expected).max() / (mu * gamma)
    s = results[-1].check.min_shape_ratio
    print(f"\n  simple shear γ = {gamma}: σ (FE) {sigma[0].round(1).tolist()}, closed form "
          f"{expected.round(1).tolist()}, relative error {error:.1e} (tolerance 1e-10); deformed cell s = {s:.15f}, "
          f"1/√(1 + γ²) = {1 / math.sqrt(1 + gamma**2):.15f}")
    assert error < 1e-10 and abs(s - 1 / math.sqrt(1 + gamma**2)) < 1e-12


def _rotated_displacement(problem, R: np.ndarray) -> np.ndarray:
    """u' with X + u' = R (X + u) at every dof (the body turned rigidly about the origin)."""
    X = problem.V.tabulate_dof_coordinates()
    x = X + problem.u.x.array.reshape(-1, 3)
    return (x @ R.T - X).reshape(-1)


def test_a_rigid_rotation_of_a_prestressed_body_rotates_the_stress():
    """Stretched plastically by 20 % (p > 0), then turned by 90° about z as a whole: the update at the
    turned u gives σ' = R σ Rᵀ, b_e' = R b_e Rᵀ, Δp = 0 and nodal forces R f, to 1e-12 relative; the
    commit stores them."""
    problem = uniaxial_problem(LAWS["linear"][0], 0.2)
    solve_load_steps(problem, make_solver("monolithic", problem), 4, check=LARGE)
    st = problem.state
    sigma, b_e, p = (st.sigma_n.x.array.reshape(-1, 3, 3).copy(), st.b_e_n.x.array.reshape(-1, 3, 3).copy(),
                     st.p_n.x.array.copy())
    forces = problem.assemble_internal_force().array.reshape(-1, 3).copy()
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    problem.u.x.array[:] = _rotated_displacement(problem, R)
    turned = problem.assemble_internal_force().array.reshape(-1, 3)
    values = st.trial_values(problem.u)
    scale = np.abs(sigma).max()
    errors = {"σ": np.abs(values["sigma"] - R @ sigma @ R.T).max() / scale,
              "b_e": np.abs(values["b_e"] - R @ b_e @ R.T).max(),
              "Δp": np.abs(values["dp"]).max(), "f": np.abs(turned - forces @ R.T).max() / np.abs(forces).max()}
    st.commit(problem.u)
    errors["σ_n"] = np.abs(st.sigma_n.x.array.reshape(-1, 3, 3) - R @ sigma @ R.T).max() / scale
    errors["p"] = np.abs(st.p_n.x.array - p).max() / p.max()  # no new plastic strain
    print(f"\n  90° about z after a plastic stretch of 20 % (p = {p.max():.4f}): " +
          ", ".join(f"{k} {v:.1e}" for k, v in errors.items()) + " (tolerance 1e-12)")
    assert p.min() > 0.1 and max(errors.values()) < 1e-12


def _block_under_traction(kinematics: str, scale: float, material) -> ContactProblem:
    """A block 2 × 1 × 1 (4 × 2 × 2 cells) clamped at x = 0, pulled by a traction ``scale`` E on x = 2
    (the clamp makes the state inhomogeneous)."""
    mesh, ft = box_with_face_tags((4, 2, 2), L=(2.0, 1.0, 1.0))
    return ContactProblem(mesh, None, ft, materials=material, kinematics=kinematics, dirichlet=[Dirichlet(1)],
                          tractions=[Traction(2, (scale * E, 0.0, 0.0))])


@pytest.mark.parametrize("material", [VonMises(E=E, nu=NU, sigma_y0=1.6e7, H=E), Elastic(E=E, nu=NU)],
                         ids=["von-mises", "elastic"])
def test_small_strain_is_the_limit_of_finite_strain(material):
    """A traction of 1e-4 E (plastic near the clamp for the von Mises block: σ_y0 = 0.8e-4 E): the
    stresses of the two kinematics agree to 1e-4 and the displacements to 3e-4 (their difference is of
    the order of the strains, about 1e-4); for the elastic block, at 1e-5 E both differences are ten times
    smaller (first order in the load: small strain is the limit)."""
    differences = {}
    for scale in (1e-4, 1e-5):
        answers = {}
        for kinematics in ("small", "finite"):
            problem = _block_under_traction(kinematics, scale, material)
            solve_load_steps(problem, make_solver("monolithic", problem), 2)
            answers[kinematics] = (problem.u.x.array.copy(), problem.state.sigma_n.x.array.copy(),
                                   problem.state.p_n.x.array.max())
        (u_s, s_s, p_s), (u_f, s_f, p_f) = answers["small"], answers["finite"]
        differences[scale] = (np.abs(u_f - u_s).max() / np.abs(u_s).max(), np.abs(s_f - s_s).max() / np.abs(s_s).max())
        print(f"\n  {type(material).__name__}, traction {scale:g} E: |u_finite − u_small|/|u| = {differences[scale][0]:.2e}, "
              f"|σ_finite − σ_small|/|σ| = {differences[scale][1]:.2e}; largest p small {p_s:.3e}, finite {p_f:.3e}")
        if isinstance(material, VonMises) and scale == 1e-4:
            assert p_s > 0.0 and p_f > 0.0
    (du, ds), (du5, ds5) = differences[1e-4], differences[1e-5]
    assert ds < 1e-4 and du < 3e-4
    if isinstance(material, Elastic):  # (the von Mises block is elastic at 1e-5 E: another law)
        assert 0.08 < du5 / du < 0.12 and 0.08 < ds5 / ds < 0.12  # first order in the load


def _superlinear(residuals: list[float]) -> bool:
    """The last two reductions of a residual sequence are each at least 100-fold, the last the larger."""
    r = [x for x in residuals if x > 0.0]
    return len(r) >= 3 and r[-1] < 1e-2 * r[-2] and r[-2] < 1e-2 * r[-3] and r[-1] / r[-2] < r[-2] / r[-3]


class _NewtonSolves(logging.Handler):
    """The iteration log's residuals max(|R|/F, |H|/F), one list per Newton solve (a solve starts at "it 0")."""

    def __init__(self):
        super().__init__(logging.INFO)
        self.solves: list[list[float]] = []

    def emit(self, record):
        found = re.search(r"\] it +(\d+) +\|R\|/F ([0-9.e+-]+) +\|H\|/F ([0-9.e+-]+)", record.getMessage())
        if found:
            if int(found.group(1)) == 0:
                self.solves.append([])
            self.solves[-1].append(max(float(found.group(2)), float(found.group(3))))


def test_sphere_into_an_elastoplastic_block_every_method_and_law_agree():
    """A rigid sphere pressed 10 % of the block's height (current contact geometry, von Mises with
    linear hardening): monolithic and NNEQM1, "polar" and "alart-curnier", the sphere's force, u and the
    Cauchy stress agree to 1e-8; the last Newton solve of each run that took three iterations or more
    (NNEQM1 solves an increment again once its pairs moved: its last solve starts converged) has
    residuals max(|R|/F, |H|/F) falling superlinearly at its end."""
    runs = {}
    logger = logging.getLogger("dolfinx_nnqem")
    for method in ("monolithic", "nneqm1"):
        for law in ("polar", "alart-curnier"):
            problem = sphere_into_block(law)
            log, level = _NewtonSolves(), logger.level
            logger.addHandler(log)
            logger.setLevel(logging.INFO)
            try:
                with make_solver(method, problem, SolverOptions(rtol=1e-11)) as solver:
                    results = solve_load_steps(problem, solver, 5)
            finally:
                logger.removeHandler(log)
                logger.setLevel(level)
            last = [solve for solve in log.solves if len(solve) >= 3][-1]
            force = problem.assemble_internal_force()
            total = problem.comm.allreduce(float(np.abs(force.array).sum()), op=MPI.SUM)
            runs[method, law] = (problem.u.x.array.copy(), problem.state.sigma_n.x.array.copy(), total, last,
                                 problem.state.p_n.x.array.max(), [r.iterations for r in results])
    u0, s0, f0, _, _, _ = runs["monolithic", "alart-curnier"]
    print()
    for (method, law), (u, s, f, residuals, p, iterations) in runs.items():
        du, ds = np.abs(u - u0).max() / np.abs(u0).max(), np.abs(s - s0).max() / np.abs(s0).max()
        print(f"  {method}/{law}: iterations {iterations}, the last Newton solve's residuals "
              f"{[f'{r:.1e}' for r in residuals]}; u {du:.1e}, σ {ds:.1e} from monolithic/alart-curnier; "
              f"largest p {p:.3f}")
        assert du < 1e-8 and ds < 1e-8 and abs(f - f0) < 1e-8 * f0 and p > 0.0
        assert _superlinear(residuals), residuals


def test_two_bodies_of_different_materials_pressed_together():
    """A Neo-Hookean block pressed (dead load p = 0.05 E on its top) onto a von Mises block (Hencky,
    elastic at this load) through a frictionless node-to-surface interface in the current geometry,
    both on rollers: uniaxial compression of each, P_yy = −p and every other component of P 0 at every
    Gauss point of both bodies, 1e-10, monolithic and NNEQM1."""
    from dolfinx_nnqem.cases.geometries import BlockStackTags as B
    from dolfinx_nnqem.cases.geometries import build_block_stack
    from dolfinx_nnqem.problem import Contact, Pressure

    E_b, p = 1.0e9, 5.0e7
    for method in ("monolithic", "nneqm1"):
        mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, (0.5, 0.5), ((2, 1, 2), (2, 1, 2)))
        problem = ContactProblem(
            mesh, ct, ft, kinematics="finite",
            materials={B.body(1): VonMises(E=E_b, nu=0.3, sigma_y0=5.0e7, H=1.0e8), B.body(2): NeoHooke(E=E_b, nu=0.3)},
            dirichlet=[Dirichlet(B.bottom(1), 0.0, [1])] + [Dirichlet(f(k), 0.0, [c]) for k in (1, 2)
                                                            for f, c in ((B.xmin, 0), (B.zmin, 2))],
            tractions=[Pressure(B.top(2), p)],
            contact=Contact(B.top(1), B.bottom(2), mu_f=0.0, discretisation="node-to-surface", geometry="current"))
        results = solve_load_steps(problem, make_solver(method, problem, SolverOptions(rtol=1e-12)), 5)
        P = problem.state.P_q.x.array.reshape(-1, 9)
        axial, others = np.abs(P[:, 4] + p).max() / p, np.abs(P[:, [0, 1, 2, 3, 5, 6, 7, 8]]).max() / p
        sigma = problem.state.sigma_n.x.array.reshape(-1, 9)[:, 4]
        print(f"\n  {method}: iterations {[r.iterations for r in results]}; |P_yy + p|/p = {axial:.1e}, other P "
              f"{others:.1e} (tolerance 1e-10); Cauchy σ_yy from {sigma.min():.4e} to {sigma.max():.4e} (the "
              "bodies' lateral stretches differ)")
        assert axial < 1e-10 and others < 1e-10
        assert np.ptp(sigma) > 1e-4 * p  # two materials: two Cauchy stresses for one nominal one


def test_the_check_names_an_inverted_state_and_a_flattened_cell():
    """The check at finite strain, on u set by hand: a cell squeezed through itself (F_xx = −0.5) fails
    with det F <= 0 named; a cell sheared to γ = 30 (shape ratio 0.033 < 0.05) with the deformed mesh named."""
    problem = uniaxial_problem(NeoHooke(E=E, nu=NU), 1.0)
    X = problem.V.tabulate_dof_coordinates()
    problem.u.x.array[:] = np.column_stack([-1.5 * X[:, 0], 0 * X[:, 1], 0 * X[:, 2]]).reshape(-1)
    inverted = check_state(problem)
    problem.u.x.array[:] = np.column_stack([30.0 * X[:, 1], 0 * X[:, 1], 0 * X[:, 2]]).reshape(-1)
    sheared = check_state(problem)
    print(f"\n  inverted: {inverted.reason[:160]}...\n  sheared: {sheared.reason[-300:]}")
    assert not inverted.ok and "det F <= 0 at 8 Gauss point(s)" in inverted.reason and "input cell(s) [0]" in inverted.reason
    assert not sheared.ok and "deformed mesh" in sheared.reason and "input cell 0" in sheared.reason
    assert abs(sheared.min_shape_ratio - 1 / math.sqrt(1 + 30.0**2)) < 1e-12


def test_the_output_files_hold_the_cauchy_stress_at_finite_strain(tmp_path):
    """fields.xdmf of a finite-strain run holds the cell means of the Cauchy stress (``cauchy_stress``,
    the closed form of the uniaxial stretch at λ = 2, 1e-10), and its ``von_mises`` is Cauchy's;
    summary.json's checks hold the deformed mesh's smallest scaled Jacobian; a small-strain run's
    fields and summary keys are as before."""
    from dolfinx_nnqem.io.output import ResultsWriter
    from dolfinx_nnqem.io.reader import read_fields

    names = {}
    for kinematics in ("finite", "small"):
        problem = uniaxial_problem(LAWS["linear"][0], 1.0 if kinematics == "finite" else 1e-3, kinematics)
        writer = ResultsWriter(problem, "monolithic", tmp_path / kinematics, 4)
        solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-12)), 4, check=LARGE,
                         callbacks=[writer])
        writer.close()
        checks = json.loads((tmp_path / kinematics / "summary.json").read_text())["checks"]
        names[f"{kinematics} checks"] = sorted(checks[-1])
        last = read_fields(tmp_path / kinematics)[-1]
        names[kinematics] = sorted(last)
        if kinematics == "finite":
            expected = uniaxial_cauchy(LAWS["linear"][1], math.log(2.0))
            sigma = np.asarray(last["cauchy_stress"]).reshape(-1, 3, 3)
            error = max(np.abs(sigma[:, 0, 0] - expected).max(), np.abs(np.asarray(last["von_mises"]) - expected).max(),
                        np.abs(sigma.reshape(-1, 9)[:, 1:]).max()) / expected
    print(f"\n  fields written: finite {names['finite']}, small {names['small']}; cauchy_stress and von_mises against "
          f"the closed form {error:.1e} (tolerance 1e-10)")
    assert error < 1e-10 and "cauchy_stress" not in names["small"]
    assert set(names["finite checks"]) - set(names["small checks"]) == {"min_shape_ratio"}
    assert set(names["finite"]) - set(names["small"]) == {"cauchy_stress"}


def test_a_restart_from_a_checkpoint_equals_an_uninterrupted_run(tmp_path):
    """Kinematic hardening (Armstrong–Frederick + Prager) stretched to λ = 1.5: interrupted after
    increment 3 of 6 and resumed from the checkpoint in a fresh problem (F_n, b_e,n, p and the
    back-stresses restored): σ, p, the back-stresses, F_n and b_e,n equal the uninterrupted run's."""
    from dolfinx_nnqem.io import checkpoint
    from dolfinx_nnqem.material import BackStress

    material = VonMises(E=E, nu=NU, sigma_y0=SIGMA_Y0, kinematic=[BackStress(2.0e10, 100.0), BackStress(2.0e9)])
    ref = uniaxial_problem(material, 0.5)
    solve_load_steps(ref, make_solver("monolithic", ref, SolverOptions(rtol=1e-12)), 6, check=LARGE)
    first = uniaxial_problem(material, 0.5)
    checkpointer = checkpoint.Checkpointer(tmp_path)

    def stop_after_3(problem, stepper_state, result):
        checkpointer(problem, stepper_state, result)
        if result.index == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        solve_load_steps(first, make_solver("monolithic", first, SolverOptions(rtol=1e-12)), 6, check=LARGE,
                         checkpoint=stop_after_3)
    second = uniaxial_problem(material, 0.5)
    state, _ = checkpoint.restore(second, tmp_path)
    solve_load_steps(second, make_solver("monolithic", second, SolverOptions(rtol=1e-12)), 6, check=LARGE, resume=state)
    arrays = {name: (second.state.checkpoint_arrays()[name], a) for name, a in ref.state.checkpoint_arrays().items()}
    worst = {name: float(np.max(np.abs(b - a)) / max(np.max(np.abs(a)), 1e-300)) for name, (b, a) in arrays.items()}
    print(f"\n  resumed at increment {state.index}; relative differences {worst}")
    assert state.index == 3 and {"F_n", "b_e_n", "internal_alpha_1", "internal_alpha_2"} <= set(worst)
    assert ref.state.p_n.x.array.min() > 0.1 and all(v <= 1e-12 for v in worst.values())


def test_a_parameter_study_at_finite_strain_takes_the_new_yield_stress():
    """``problem.update(materials=...)`` with another σ_y0 and H (linear von Mises), solved again: the
    closed form of the new material at λ = 2, 1e-10 (the bodies' finite-strain materials are rebuilt)."""
    problem = uniaxial_problem(LAWS["linear"][0], 1.0)
    solve_load_steps(problem, make_solver("monolithic", problem), 4, check=LARGE)
    first = problem.state.sigma_n.x.array[0]
    sigma_y0, H = 4.0e8, 2.0e9
    problem.update(materials=VonMises(E=E, nu=NU, sigma_y0=sigma_y0, H=H))
    solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-12)), 4, check=LARGE)
    expected = uniaxial_cauchy(lambda p: sigma_y0 + H * p, math.log(2.0))
    error = np.abs(problem.state.sigma_n.x.array.reshape(-1, 9)[:, 0] - expected).max() / expected
    print(f"\n  σ_xx at λ = 2: {first:.6e} (σ_y0 = {SIGMA_Y0:g}), then {expected:.6e} (σ_y0 = {sigma_y0:g}): "
          f"error {error:.1e} (tolerance 1e-10)")
    assert error < 1e-10 and abs(first - expected) > 1e7


def test_the_shape_ratio_is_relative_to_the_undeformed_cell():
    """Tetrahedra of a box (their own s down to 0.41 undeformed) stretched to twice their length: the
    smallest shape ratio falls to 0.32; the check passes with the default bound 0.05 and names the
    cells with a bound of 0.4."""
    mesh, ft = box_with_face_tags((2, 2, 2), cell="tetrahedron")
    problem = ContactProblem(mesh, None, ft, materials=NeoHooke(E=E, nu=NU), kinematics="finite",
                             dirichlet=[Dirichlet(1, 0.0, components=[0]), Dirichlet(3, 0.0, components=[1]),
                                        Dirichlet(5, 0.0, components=[2]), Dirichlet(2, 1.0, components=[0])])
    results = solve_load_steps(problem, make_solver("monolithic", problem), 4)
    ratio = results[-1].check.min_shape_ratio
    strict = check_state(problem, options=CheckOptions(min_shape_ratio=0.4))
    print(f"\n  undeformed smallest s {problem.mesh_quality.min_scaled_jacobian:.3f}; shape ratio at λ = 2: {ratio:.4f}; "
          f"with min_shape_ratio = 0.4: {strict.reason[-200:]}")
    assert results[-1].check.ok and 0.25 < ratio < 0.4 and problem.mesh_quality.min_scaled_jacobian < 0.5
    assert not strict.ok and "below min_shape_ratio = 0.4" in strict.reason and "input cell" in strict.reason


@pytest.mark.parametrize("material", [VonMises(E=E, nu=NU, hardening=VOCE), NeoHooke(E=E, nu=NU)],
                         ids=["hencky-voce", "neo-hooke"])
def test_a_tangent_left_out_by_the_internal_force_is_the_one_computed_with_it(material):
    """The internal force evaluates the state without the tangent (a Newton iteration's last residual
    needs none); the tangent asked for afterwards at the same u is computed from that update's arrays
    and equals, bit for bit, the one of an update that computed both at once; at a new u the tangent is
    not the old one's."""
    problem = uniaxial_problem(material, 0.3)
    solve_load_steps(problem, make_solver("monolithic", problem), 2, final_load_factor=0.5)
    st = problem.state
    problem.u.x.array[:] *= 1.01  # a new iterate, plastic for von Mises
    problem.assemble_internal_force()
    K_later = problem.assemble_tangent().copy()
    A_later = st.A_q.x.array.copy()
    st._evaluated = None  # (the same u evaluated afresh, tangent and stresses at once)
    st.evaluate(problem.u)
    K_now = problem.assemble_tangent()
    assert np.array_equal(A_later, st.A_q.x.array) and np.abs(A_later).max() > 0.0
    K_later.axpy(-1.0, K_now)
    assert K_later.norm() == 0.0
    problem.u.x.array[:] *= 1.01
    problem.assemble_internal_force()
    problem.assemble_tangent()
    assert not np.array_equal(A_later, st.A_q.x.array)


def test_an_evaluation_takes_det_f_once_a_point_and_writes_the_tangent_in_place(monkeypatch):
    """The state's update computes det F once a Gauss point (its inversion check's J is the one the
    material takes), and the material writes its tangent into A_q's own array (the body's points are
    consecutive): A_q equal, bit for bit, to the material's tangent computed on its own."""
    problem = uniaxial_problem(LAWS["voce"][0], 0.3)
    solve_load_steps(problem, make_solver("monolithic", problem), 2, final_load_factor=0.5)
    st = problem.state
    (body,) = st.bodies
    material, outs, determinants = body.material, [], []

    class Recording:  # the body's material, recording where its tangent is written
        size = material.size

        def update(self, F, state, tangent=True, J=None):
            response = material.update(F, state, tangent, **({} if J is None else {"J": J}))
            later = response.tangent_later

            def spy(*out):
                outs.extend(out)
                return later(*out)
            return dataclasses.replace(response, tangent_later=spy if later is not None else None)

    det = np.linalg.det
    monkeypatch.setattr(body, "material", Recording())
    monkeypatch.setattr(np.linalg, "det", lambda a: determinants.append(np.shape(a)[:-2]) or det(a))
    problem.u.x.array[:] *= 1.01  # a new iterate, plastic
    st.evaluate(problem.u)
    monkeypatch.undo()
    assert determinants == [(st.p_n.x.array.size,)]  # one det F a Gauss point
    assert len(outs) == 1 and np.shares_memory(outs[0], st.A_q.x.array)
    reference = material.update(st.deformation_gradients(problem.u)[body.points], st._converged(body.points)).tangent
    assert np.count_nonzero(st.dp_q.x.array > 0.0) > 0
    assert np.array_equal(st.A_q.x.array.reshape(-1, 3, 3, 3, 3)[body.points], reference)
    written = {f: getattr(st, f).x.array.copy() for f in ("A_q", "P_q", "sigma_q", "tau_q", "dp_q")}
    body.rows = body.points  # points that are not consecutive (a body's on some rank): written by index, the same
    st._evaluated = None
    st.evaluate(problem.u)
    assert all(np.array_equal(value, getattr(st, f).x.array) for f, value in written.items())


# -- refusals --------------------------------------------------------------------------------------------
def test_a_kinematics_that_does_not_exist_is_refused_by_name():
    with pytest.raises(ValueError, match=r"kinematics = 'large': expected 'small' .* or 'finite'"):
        uniaxial_problem(LAWS["linear"][0], 0.1, kinematics="large")


def test_neo_hooke_at_small_strain_is_refused_with_the_reason():
    with pytest.raises(ValueError, match=r"materials is NeoHooke, a finite-strain hyperelastic law .* kinematics = 'finite'"):
        uniaxial_problem(NeoHooke(E=E, nu=NU), 0.1, kinematics="small")


def test_nneqm2_refuses_finite_strain_before_solving():
    problem = sphere_into_block("alart-curnier", depth=0.01, n=2)
    with pytest.raises(ValueError, match=r"nneqm2: the problem has kinematics = 'finite'.*small-strain pointwise form"):
        make_solver("nneqm2", problem)
    assert problem.load_factor_n == 0.0


def test_a_problem_file_takes_kinematics_and_neo_hooke(tmp_path):
    """[mesh] kinematics = "finite" and model = "neo-hooke" build a finite-strain problem; another
    kinematics, and Neo-Hooke without "finite", are refused by name."""
    from problem_files import two_beams_minimal

    text = two_beams_minimal()
    finite = text.replace("[mesh]\n", '[mesh]\nkinematics = "finite"\n', 1)
    path = tmp_path / "finite.toml"
    path.write_text(finite)
    spec = load_problem_file(path)
    problem = build_problem(spec, MPI.COMM_WORLD)
    assert problem.kinematics == "finite" and problem.definition.kinematics == "finite"
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("[mesh]\n", '[mesh]\nkinematics = "large"\n', 1))
    with pytest.raises(ProblemFileError, match=r"mesh.kinematics = 'large': expected \"small\""):
        load_problem_file(bad)
    neo = tmp_path / "neo.toml"
    neo.write_text(finite.replace("[materials.1]\n", '[materials.1]\nmodel = "neo-hooke"\n', 1)
                   .replace("sigma_y0", "# sigma_y0").replace("\nH =", "\n# H ="))
    assert isinstance(build_problem(load_problem_file(neo), MPI.COMM_WORLD).state.materials[1], NeoHooke)
    small = tmp_path / "neo_small.toml"
    small.write_text(neo.read_text().replace('kinematics = "finite"\n', ""))
    with pytest.raises(ValueError, match="NeoHooke"):
        build_problem(load_problem_file(small), MPI.COMM_WORLD)
