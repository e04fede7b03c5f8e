"""Never a silent wrong answer: the independent check of every "converged" state.

A solver's own report is not trusted: a lying solver, a loose atol, tampered Gauss-point stresses,
broken pair forces and a strain far outside the small-strain setting all end as a non-converged
increment with the check's reason; genuine solutions pass with a wide margin.
"""

import json
from dataclasses import replace

import numpy as np
import pytest

from dolfinx_nnqem.solvers.checks import CheckOptions, _beyond_small_strain, check_state
from dolfinx_nnqem.solvers import ConvergenceError, SolveReport
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.io import ResultsWriter
from dolfinx_nnqem.problem import ContactProblem, Dirichlet, Traction
from dolfinx_nnqem.solvers import SolverOptions, make_solver
from dolfinx_nnqem.solvers import solve_load_steps

from conftest import box_with_face_tags

STEEL = VonMises(E=2e11, nu=0.3, sigma_y0=2.5e8, H=1e10)


def _box(dirichlet=(Dirichlet(1),), tractions=(Traction(2, (1e8, 2e7, 0.0)),), material=STEEL):
    mesh, facet_tags = box_with_face_tags((2, 2, 2))
    return ContactProblem(mesh, None, facet_tags, materials=material, dirichlet=list(dirichlet),
                          tractions=list(tractions))


class LyingSolver:
    """Claims convergence after moving nothing but the prescribed dofs."""

    name = "liar"
    timings = {}

    def __init__(self, problem):
        self.problem = problem
        self.options = SolverOptions()

    def solve_increment(self, load_factor):
        self.problem.apply_prescribed_displacements(load_factor)
        return SolveReport(converged=True, iterations=1, message="converged")

    def destroy(self):
        pass


def test_a_lying_solver_is_never_reported_converged(tmp_path):
    problem = _box()
    writer = ResultsWriter(problem, "liar", tmp_path / "out", 3)
    with pytest.raises(ConvergenceError) as error:
        solve_load_steps(problem, LyingSolver(problem), 3, max_cutbacks=1, callbacks=[writer])
    writer.close()
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    failure = summary["failure"]
    print(f"\n  {error.value}\n  summary: status {summary['status']}, converged {summary['converged']}, "
          f"failure at increment {failure['increment']} (load factor {failure['load_factor']:.4g}), "
          f"|R|/F = {failure['equilibrium']:.3e}, worst node {failure['worst_nodes'][0]}")
    assert "independent check failed" in str(error.value) and "equilibrium residual" in str(error.value)
    assert summary["converged"] is False and summary["status"] == "not converged"
    assert failure["increment"] == 1 and failure["equilibrium"] > 0.1 and failure["worst_nodes"]


def test_a_loose_atol_does_not_excuse_a_residual():
    problem = _box()
    solver = make_solver("monolithic", problem, SolverOptions(atol=1e12))
    with pytest.raises(ConvergenceError) as error:
        solve_load_steps(problem, solver, 2, max_cutbacks=0)
    print(f"\n  {error.value}")
    assert "atol" in str(error.value)


@pytest.mark.parametrize("method", ["monolithic", "nneqm2"])
def test_genuine_solutions_pass_with_margin(method):
    problem = _box(tractions=(Traction(2, (3e8, 2e7, 0.0)),))  # beyond first yield
    results = solve_load_steps(problem, make_solver(method, problem), 3)
    for r in results:
        c = r.check
        print(f"\n  {method} increment {r.index}: |R|/F = {c.equilibrium:.2e} (tolerance {c.tolerance:.0e}), "
              f"strain {c.max_strain:.2e}, rotation {c.max_rotation:.2e}, own stresses {c.own_stresses}", end="")
        assert c.ok and c.equilibrium < 1e-3 * c.tolerance
        assert c.own_stresses == (method == "nneqm2")
    assert results[-1].plastic_points > 0


def test_nneqm2_is_checked_with_its_own_stresses():
    """Equilibrium is measured with the Gauss-point stresses NNEQM2 commits: tampering with them fails."""
    problem = _box()
    solver = make_solver("nneqm2", problem)
    report = solver.solve_increment(1.0)
    good = check_state(problem, report, solver.options)
    gpv = report.gauss_point_values
    report.gauss_point_values = replace(gpv, sigma=gpv.sigma * 1.01)
    bad = check_state(problem, report, solver.options)
    print(f"\n  own stresses: |R|/F = {good.equilibrium:.2e}; stresses x 1.01: |R|/F = {bad.equilibrium:.2e}")
    assert good.ok and good.own_stresses and not bad.ok and bad.equilibrium > 1e-3


def test_nneqm2_stresses_outside_the_yield_surface_fail_the_check():
    """A solver's own Gauss-point values must be plastically admissible: the stress of a point that
    yielded, committed with a smaller Δp (the equilibrium unchanged), lies outside the hardened
    yield surface; a negative Δp is refused too."""
    problem = _box(tractions=(Traction(2, (3e8, 2e7, 0.0)),))  # beyond first yield
    solver = make_solver("nneqm2", problem)
    report = solver.solve_increment(1.0)
    good = check_state(problem, report, solver.options)
    gpv = report.gauss_point_values
    assert np.count_nonzero(gpv.dp > 0) > 0
    report.gauss_point_values = replace(gpv, dp=0.5 * gpv.dp)
    softer = check_state(problem, report, solver.options)
    report.gauss_point_values = replace(gpv, dp=np.where(gpv.dp > 0, -gpv.dp, 0.0))
    negative = check_state(problem, report, solver.options)
    print(f"\n  own values: yield violation {good.yield_violation:.1e}; Δp halved: {softer.yield_violation:.2e} "
          f"({softer.reason}); Δp negative: {negative.yield_violation}")
    assert good.ok and good.yield_violation < good.tolerance
    assert not softer.ok and "yield surface" in softer.reason and softer.equilibrium == good.equilibrium
    assert not negative.ok and negative.yield_violation == np.inf


@pytest.mark.parametrize("corruption", ["no plastic strain", "plastic strain turned", "p not advanced"])
def test_plastic_strain_that_does_not_match_the_flow_fails_the_check(corruption):
    """Issue 26's state (the hardening absorbed the overstress, no plastic strain applied) and its
    kin: ε_p,n+1 − ε_p,n ≠ Δγ N, or p_n+1 ≠ p_n + Δγ, at the points that yielded, each named."""
    problem = _box(tractions=(Traction(2, (3e8, 2e7, 0.0)),))  # beyond first yield
    solver = make_solver("nneqm2", problem)
    report = solver.solve_increment(1.0)
    good = check_state(problem, report, solver.options)
    gpv = report.gauss_point_values
    yielded = gpv.dp > 0
    assert np.count_nonzero(yielded) > 0 and gpv.deps_p is not None
    deps_p = np.asarray(gpv.deps_p).reshape(-1, 3, 3)
    if corruption == "no plastic strain":
        bad = replace(gpv, deps_p=np.zeros_like(deps_p))
    elif corruption == "plastic strain turned":  # the same size, another deviatoric direction
        turned = deps_p[:, [1, 2, 0]][:, :, [1, 2, 0]]
        bad = replace(gpv, deps_p=turned)
    else:
        bad = replace(gpv, dp=np.where(yielded, 0.0, gpv.dp))
    report.gauss_point_values = bad
    result = check_state(problem, report, solver.options)
    print(f"\n  {corruption}: ok {result.ok}; {result.reason[:160]}")
    assert good.ok and not result.ok and "constitutive law" in result.reason


def test_broken_pair_forces_fail_the_contact_check():
    from dolfinx_nnqem.cases.two_beams import two_beams_problem

    problem = two_beams_problem()
    solver = make_solver("monolithic", problem)
    report = solver.solve_increment(0.2)
    ok = check_state(problem, report, solver.options)
    problem.contact.z[:, 0] -= 1e3  # tensile normal forces
    bad = check_state(problem, report, solver.options)
    print(f"\n  converged: |H|/F = {ok.contact:.2e}, Coulomb {ok.coulomb:.2e}; p_n - 1 kN: |H|/F = {bad.contact:.2e}, "
          f"Coulomb {bad.coulomb:.2e}; worst pair {bad.worst_pairs[0]}")
    assert ok.ok and not bad.ok and "contact complementarity" in bad.reason and "Coulomb" in bad.reason


def test_large_strain_is_refused_and_can_be_relaxed():
    """A prescribed stretch of 50 %: equilibrium holds, but far outside small strain."""
    elastic = VonMises(E=2e11, nu=0.3)
    problem = _box(dirichlet=[Dirichlet(1), Dirichlet(2, 0.5, components=[0])], tractions=(), material=elastic)
    with pytest.raises(ConvergenceError) as error:
        solve_load_steps(problem, make_solver("monolithic", problem), 1, max_cutbacks=0)
    print(f"\n  {str(error.value).splitlines()[0]}")
    assert "max_strain" in str(error.value) and "kinematics = 'finite'" in str(error.value)
    problem.restore()
    results = solve_load_steps(problem, make_solver("monolithic", problem), 1, max_cutbacks=0,
                               check=CheckOptions(max_strain=None, max_rotation=None))
    print(f"  relaxed: strain {results[0].check.max_strain:.3f} accepted")
    assert results[0].check.max_strain > 0.4


def test_a_strain_just_above_the_limit_reads_above_it():
    """0.1002 against max_strain = 0.1 is printed with the digits that show it is above (not "0.1 exceeds 0.1")."""
    reasons = _beyond_small_strain(0.1002, 0.0, CheckOptions(max_strain=0.1))
    rotations = _beyond_small_strain(0.0, 0.20004, CheckOptions(max_rotation=0.2))
    assert reasons[0].startswith("largest strain 0.1002 exceeds max_strain = 0.1:"), reasons
    assert rotations[0].startswith("largest rotation 0.20004 rad exceeds max_rotation = 0.2:"), rotations


def test_plastic_collapse_ends_in_a_clear_report():
    """Perfect plasticity loaded far beyond its limit load: no "converged" state with huge displacements."""
    perfect = VonMises(E=2e11, nu=0.3, sigma_y0=2.5e8, H=0.0)
    problem = _box(tractions=(Traction(2, (1e9, 0.0, 0.0)),), material=perfect)  # 4x the limit load
    with pytest.raises(ConvergenceError) as error:
        solve_load_steps(problem, make_solver("monolithic", problem), 4, max_cutbacks=3)
    u_max = np.max(np.abs(problem.u.x.array))
    print(f"\n  {str(error.value).splitlines()[0]}\n  last accepted load factor {problem.load_factor_n:.4g}, "
          f"max |u| {u_max:.3g} m (unit box)")
    assert "max_strain" in str(error.value) and u_max < 0.1


def test_summary_residuals_are_meaningful_when_only_displacements_are_prescribed(tmp_path):
    """No applied load: the summary's free-dof residual is measured against the force scale
    (it used to be divided by ‖F_ext‖ = 0), and the check's figures are written."""
    elastic = VonMises(E=2e11, nu=0.3)
    problem = _box(dirichlet=[Dirichlet(1), Dirichlet(2, 1e-3, components=[0])], tractions=(), material=elastic)
    writer = ResultsWriter(problem, "monolithic", tmp_path / "out", 2)
    solve_load_steps(problem, make_solver("monolithic", problem), 2, callbacks=[writer])
    writer.close()
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    print(f"\n  converged {s['converged']}: free-dof residual {s['free_dof_residual']:.1e}, global imbalance "
          f"{s['equilibrium_residual']:.1e}, checks {[round(c['equilibrium'], 20) for c in s['checks']]}")
    assert s["converged"] and s["status"] == "completed"
    assert s["free_dof_residual"] < 1e-8 and s["equilibrium_residual"] < 1e-8 and len(s["checks"]) == 2


def test_check_tolerance_follows_the_solver_rtol():
    tol = {rtol: CheckOptions().tolerance(rtol) for rtol in (1e-14, 1e-10, 1e-6, 1e-4, 1e-2)}
    print(f"\n  solver rtol -> check tolerance: {tol}")
    assert tol[1e-10] == pytest.approx(1e-6) and tol[1e-14] == 1e-7 and tol[1e-6] == 1e-3
    assert all(t >= 10 * r for r, t in tol.items() if r >= 1e-8)
    problem = _box()
    results = solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-2)), 2)
    assert all(r.check.ok for r in results)


class DivergingSolver(LyingSolver):
    """An iterate that overflowed: u and the residual history hold NaN and infinity."""

    name = "diverging"

    def solve_increment(self, load_factor):
        from dolfinx_nnqem.solvers.convergence import IterationRecord

        self.problem.u.x.array[:] = np.nan
        history = [IterationRecord(0, float("nan"), float("inf"), float("nan"), "newton")]
        return SolveReport(converged=False, iterations=1, message="the residual is not finite", history=history)


def test_summary_json_is_valid_json_when_values_are_not_finite(tmp_path):
    """Issue 31, item 3: a diverged iterate's NaN reached summary.json as a bare NaN (not JSON).
    Now such a value is null and ``non_finite`` names the key and the value it had."""
    problem = _box()
    writer = ResultsWriter(problem, "diverging", tmp_path / "out", 2)
    with pytest.raises(ConvergenceError):
        solve_load_steps(problem, DivergingSolver(problem), 2, max_cutbacks=0, callbacks=[writer])
    writer.close()
    text = (tmp_path / "out" / "summary.json").read_text()

    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")

    summary = json.loads(text, parse_constant=refuse)  # strict: NaN, Infinity are refused
    print(f"\n  status {summary['status']}; failure.equilibrium = {summary['failure']['equilibrium']}; "
          f"non_finite: {dict(list(summary['non_finite'].items())[:3])} ({len(summary['non_finite'])} keys)")
    assert summary["status"] == "not converged" and summary["failure"]["equilibrium"] is None
    assert summary["non_finite"]["failure.equilibrium"] == "nan"


@pytest.mark.parametrize("method", ["monolithic", "nneqm1"])  # NNEQM2: F of the increment start
def test_a_huge_atol_reports_one_residual(method):
    """Issue 31, item 9: with atol = 1e30 the failure said "|R|/F = 4.4e-01" (the check) and
    "last iterate: |R|/F = 3.5e-28" (the solver divided by max(F, atol)): both now use F."""
    from dolfinx_nnqem.cases.two_beams import two_beams_problem

    problem = two_beams_problem()
    with pytest.raises(ConvergenceError) as error:
        solve_load_steps(problem, make_solver(method, problem, SolverOptions(atol=1e30)), 2, max_cutbacks=0)
    text = str(error.value)
    check = float(text.split("|R|/F = ")[1].split()[0])
    last = float(text.split("last iterate: |R|/F = ")[1].split(",")[0])
    print(f"\n  {method}: check |R|/F = {check:.3e}, last iterate |R|/F = {last:.3e}")
    assert "atol = 1e+30" in text and check == pytest.approx(last, rel=1e-6) and check > 1e-3
