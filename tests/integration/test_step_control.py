"""Automatic incrementation (issue "Every method and both laws converge"): the rule, and runs.

* The rule: grow after an easy increment, shrink after a hard one, bounds, requested load
  factors hit exactly, bad settings refused.
* The sliding block (V5) with ``increments="auto"``: it reaches ℓ = 1, stops at the requested load
  factors, saturates friction at μ_f p A as with fixed increments, and needs fewer increments.
* A load no state can carry ends with ConvergenceError once the step falls below ``min_step``.
* Problem files: ``increments = "auto"`` with a ``[solver.auto]`` table (the seed benchmark), and
  bad settings there.
"""

import json

import numpy as np
import pytest
from mpi4py import MPI
from problem_files import two_beams_demo
from test_contact_verification import ELASTIC, P, sliding_block

from dolfinx_nnqem.cli import EXIT_OK, main
from dolfinx_nnqem.solvers import ConvergenceError
from dolfinx_nnqem.cases.geometries import StackedBlocksTags as T
from dolfinx_nnqem.cases.geometries import build_stacked_blocks
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Traction
from dolfinx_nnqem.problem_file import ProblemFileError, load_problem_file
from dolfinx_nnqem.io import pair_table
from dolfinx_nnqem.solvers import SolverOptions, make_solver
from dolfinx_nnqem.solvers import AutomaticIncrements
from dolfinx_nnqem.solvers import solve_load_steps


def test_the_rule_grows_shrinks_and_keeps_its_bounds():
    auto = AutomaticIncrements(initial_step=0.1, max_step=0.3, min_step=0.01, easy_iterations=3,
                               hard_iterations=6, grow=1.5, shrink=0.5)
    assert auto.next_step(0.1, 3, 1.0) == pytest.approx(0.15)
    assert auto.next_step(0.1, 4, 1.0) == pytest.approx(0.1)
    assert auto.next_step(0.1, 6, 1.0) == pytest.approx(0.05)
    assert auto.next_step(0.25, 1, 1.0) == pytest.approx(0.3)  # max_step
    assert auto.next_step(0.015, 9, 1.0) == pytest.approx(0.01)  # min_step
    assert auto.too_small(0.009, 1.0) and not auto.too_small(0.01, 1.0)


def test_requested_load_factors_are_hit_exactly():
    auto = AutomaticIncrements(load_factors=[0.25, 0.5])
    assert auto.target(0.2, 0.1, 1.0, 1.0, 1.0) == 0.25
    assert auto.target(0.25, 0.1, 1.0, 1.0, 1.0) == pytest.approx(0.35)
    assert auto.target(0.45, 0.3, 1.0, 1.0, 1.0) == 0.5
    assert auto.target(0.9, 0.3, 1.0, 1.0, 1.0) == 1.0
    assert auto.target(0.5, 0.3, 0.0, -1.0, 1.0) == 0.25  # unloading runs downwards
    assert auto.target(0.6, 0.38, 1.0, 1.0, 1.0) == 1.0  # no sliver of an increment left
    assert auto.target(0.6, 0.3, 1.0, 1.0, 1.0) == pytest.approx(0.9)
    bounded = AutomaticIncrements(max_step=0.3)
    assert bounded.target(0.6, 0.3, 1.0, 1.0, 1.0) == pytest.approx(0.9)


@pytest.mark.parametrize("settings", [dict(initial_step=0.0), dict(max_step=1.5), dict(min_step=0.2, initial_step=0.1),
                                      dict(easy_iterations=5, hard_iterations=5), dict(grow=1.0),
                                      dict(shrink=1.0), dict(load_factors=[float("nan")])])
def test_bad_settings_are_refused(settings):
    with pytest.raises((TypeError, ValueError), match="automatic increments|load_factors"):
        AutomaticIncrements(**settings)


def _sliding(increments, method="monolithic"):
    problem, force = sliding_block()
    solver = make_solver(method, problem, SolverOptions(rtol=1e-12, max_iterations=40))
    results = solve_load_steps(problem, solver, increments)
    t = pair_table(problem)
    saturation = abs(abs(t["force_on_body1"][:, 0].sum()) - 0.3 * force) / (0.3 * force)
    return results, saturation, t


@pytest.mark.parametrize("method", ["monolithic", "nneqm1"])
def test_sliding_block_with_automatic_increments(method):
    fixed, sat_fixed, _ = _sliding(10, method)
    auto = AutomaticIncrements(initial_step=0.05, load_factors=[0.2, 0.6])
    results, sat_auto, t = _sliding(auto, method)
    factors = [r.load_factor for r in results]
    its_fixed, its_auto = sum(r.iterations for r in fixed), sum(r.iterations for r in results)
    print(f"\n  {method}: fixed 10 increments {its_fixed} Newton iterations; automatic {len(results)} increments "
          f"{its_auto} iterations, load factors {np.round(factors, 4).tolist()}; saturation {sat_fixed:.1e} / {sat_auto:.1e}")
    assert factors[-1] == 1.0 and 0.2 in factors and 0.6 in factors
    assert all(b > a for a, b in zip(factors, factors[1:]))
    assert sat_auto <= 1e-8 and np.all(t["state_name"] == "slip")
    assert len(results) < 10


def test_a_load_no_state_can_carry_ends_in_a_clear_error():
    """A top traction 0.5 p > μ_f p with the pressure p, proportional: no state for any ℓ > 0."""
    mesh, ct, ft = build_stacked_blocks(MPI.COMM_WORLD, 1.0, 0.5, 0.5, 0.5, 4, 2, 2, 2)
    problem = ContactProblem(
        mesh, ct, ft, materials={T.BODY1: ELASTIC, T.BODY2: ELASTIC},
        dirichlet=[Dirichlet(T.BOTTOM)] + [Dirichlet(tag, 0.0, [2]) for tag in
                                           (T.BODY1_ZMIN, T.BODY1_ZMAX, T.BODY2_ZMIN, T.BODY2_ZMAX)],
        tractions=[Traction(T.TOP, (0.5 * P, -P, 0.0))],
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=0.3),
    )
    solver = make_solver("monolithic", problem, SolverOptions(rtol=1e-12, max_iterations=15))
    with pytest.raises(ConvergenceError) as error:
        solve_load_steps(problem, solver, AutomaticIncrements(initial_step=0.25, min_step=0.01), max_cutbacks=50,
                         max_displacement=0.05)
    failure = error.value.failure
    print(f"\n  {str(error.value).splitlines()[0]}\n  last converged load factor {failure['last_converged_load_factor']:.4f}")
    assert failure["last_converged_load_factor"] == 0.0 and "did not converge" in str(error.value)


def _two_beams_file(tmp_path, solver_lines: str):
    text = two_beams_demo(solver_lines=solver_lines)
    path = tmp_path / "auto.toml"
    path.write_text(text)
    return path


def test_problem_file_with_automatic_increments(tmp_path):
    """The seed benchmark from its problem file with increments = "auto" and output points."""
    path = _two_beams_file(tmp_path, 'increments = "auto"\n[solver.auto]\ninitial_step = 0.1\nload_factors = [0.5]')
    assert main(["-q", "run", str(path), "--out", str(tmp_path / "out"), "--no-pictures"]) == EXIT_OK
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    factors = summary["load_factors"]
    print(f"\n  two beams, automatic: {len(factors)} increments at {np.round(factors, 4).tolist()}, "
          f"iterations {summary['iterations']}")
    assert summary["converged"] and summary["increments"] == "auto"
    assert factors[-1] == 1.0 and 0.5 in factors and len(factors) < 15


@pytest.mark.parametrize("solver_lines, message", [
    ('increments = "auto"\n[solver.auto]\nbiggest_step = 0.5', "unknown key"),
    ('increments = "auto"\n[solver.auto]\nmax_step = 2.0', "max_step"),
    ('increments = 15\n[solver.auto]\nmax_step = 0.5', "increments = \\\"auto\\\""),
    ('increments = "automatic"', "increments"),
])
def test_bad_automatic_increments_in_a_problem_file(tmp_path, solver_lines, message):
    path = _two_beams_file(tmp_path, solver_lines)
    with pytest.raises(ProblemFileError, match=message):
        load_problem_file(path)
