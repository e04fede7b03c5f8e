"""The fast part of the robustness suite (benchmarks/robustness.py) and force-free states.

* The suite's fast cases (pressure and drag together from rest on elastoplastic blocks, the
  sliding block) with every method and both laws must converge (cutbacks printed); the two beams
  in 15 increments without a cutback, with both laws (docs/robustness.md); in 3 and 5 increments
  the polar law without cutback and equal to the Cartesian law (monolithic median ≤ 4).
* NNEQM1 on prescribed-displacement paths (the cyclic path, a gap closed and re-opened) without
  cutback, equal to the monolithic solver along the whole cyclic path; the monolithic solver on
  the gap without cutback.
* NNEQM2 on the two beams in 3 increments without cutback, the polar law equal to the Cartesian;
  in 15 increments the polar law converges without ever evaluating the Cartesian law.
* A load no state can carry (drag 0.35 p > μ_f p) ends in ConvergenceError for every method.
* A state without forces (body 2 pulled off, every pair open; or moved down before it touches)
  converges: the force scale has a floor (``ContactProblem.force_floor``), else the relative
  test would compare rounding errors with zero.
"""

import sys
from pathlib import Path

import pytest
from mpi4py import MPI

from dolfinx_nnqem.contact.laws import AlartCurnierLaw
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.cases.geometries import StackedBlocksTags as T
from dolfinx_nnqem.cases.geometries import build_stacked_blocks
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet
from dolfinx_nnqem.io import pair_table
from dolfinx_nnqem.solvers import METHODS, NNEQM2Options, SolverOptions, make_solver
from dolfinx_nnqem.solvers import solve_load_steps

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import robustness  # noqa: E402

FAST = {case.name: case for case in robustness.CASES if case.fast}


@pytest.mark.parametrize("law", robustness.LAWS)
@pytest.mark.parametrize("case", ["drag-0.2-hex", "sliding-block-v5"])
def test_fast_cases_converge_without_cutback_and_every_method_agrees(case, law):
    """Each method converges without cutback, and NNEQM1's and NNEQM2's displacements and pair
    forces equal the monolithic solver's to 1e-6 (the matrix's Δ column, docs/robustness.md)."""
    reference = None
    for method in METHODS:  # monolithic first
        cell, solution = robustness.run_cell(FAST[case], method, law, FAST[case].increments)
        if reference is None:
            reference = solution
        elif solution is not None:
            cell.difference = solution.difference(reference)
        print(f"\n  {case} {method}/{law}: {robustness.cell_text(cell)} {'' if cell.converged else cell.message}")
        assert cell.converged and cell.cutbacks == 0, cell.message
        assert cell.difference is None or cell.difference < 1e-6
    assert METHODS[0] == "monolithic"


@pytest.mark.parametrize("law", robustness.LAWS)
def test_nneqm2_equals_the_monolithic_solver_along_the_drag_paths(law):
    """Pressed blocks from rest, drag 0.2 and 0.29 p (μ_f = 0.3; 0.29 is close to sliding off): the
    default NNEQM2 (flow directions unknowns, the radial return) takes every increment whole, its
    path equals the monolithic solver's, and each increment's own values are the radial return's
    (the frozen-direction seed variant was 1.4 % off here and needed a retry)."""
    for name in ("drag-0.2-hex", "drag-0.29-hex"):
        case = next(c for c in robustness.CASES if c.name == name)
        problem = case.build(law)
        states = {}

        def keep(result, problem=problem, states=states):
            states[round(result.load_factor, 12)] = (pair_table(problem)["force_on_body1"].copy(),
                                                     problem.u.x.array.copy())

        solver = make_solver("nneqm2", problem, SolverOptions(rtol=1e-12))
        results = solve_load_steps(problem, solver, case.increments, callbacks=[keep])
        _, _, monolithic = solve_along_the_path(case, "monolithic", law)
        dF, du = path_difference(states, monolithic), path_difference(states, monolithic, 1)
        info = solver.increment_info
        print(f"\n  {name} NNEQM2/{law}: iterations {[r.iterations for r in results]}, cutbacks "
              f"{[r.cutbacks for r in results]}; against the monolithic solver: pair forces {dF:.1e}, u {du:.1e}; "
              f"max |σ − σ_RR|/σ_y {max(i['return_map_difference'] for i in info):.1e}")
        assert len(results) == case.increments and not any(r.cutbacks for r in results)
        assert set(states) == set(monolithic) and dF < 1e-8 and du < 1e-8
        assert all(i["return_map_difference"] < 1e-8 and i["equilibrium_residual"] < 1e-10 for i in info)


@pytest.mark.parametrize("law", robustness.LAWS)
@pytest.mark.parametrize("method", METHODS)
def test_two_beams_in_15_increments(method, law):
    case = FAST["two-beams-15"]
    cell, _ = robustness.run_cell(case, method, law, case.increments)
    print(f"\n  two beams {method}/{law}: {robustness.cell_text(cell)}")
    assert cell.converged and cell.cutbacks == 0, cell.message


def solve_along_the_path(case: robustness.Case, method: str, law: str):
    """The case solved at its increments: (load factors, cutbacks, {ℓ: (pair forces on body 1, u)})."""
    problem = case.build(law)
    states = {}

    def keep(result):
        states[round(result.load_factor, 12)] = (pair_table(problem)["force_on_body1"].copy(), problem.u.x.array.copy())

    results = solve_load_steps(problem, make_solver(method, problem, SolverOptions(rtol=1e-12)), case.increments,
                               callbacks=[keep])
    return [r.load_factor for r in results], sum(1 for r in results if r.cutbacks), states


def path_difference(states: dict, reference: dict, which: int = 0) -> float:
    """Largest difference over the increments of ``reference`` (``which``: 0 the pair forces, 1 u),
    relative to the largest value of ``reference``."""
    scale = max(abs(values[which]).max() for values in reference.values())
    return max(abs(states[ell][which] - reference[ell][which]).max() for ell in reference) / scale


@pytest.mark.parametrize("law", robustness.LAWS)
@pytest.mark.parametrize("method", ["nneqm1", "nneqm2"])
def test_the_cyclic_path_equals_the_monolithic_solver(method, law):
    """Press, drag forward, drag back past the reversal, lift off (prescribed displacements, a
    non-proportional path): NNEQM1 and NNEQM2 lift each jump of the prescribed values into their
    first step and take no cutback (NNEQM1 took 26 with both laws when it factorised at the moved
    boundary layer); every increment equals the monolithic solver's to 1e-8."""
    case = next(c for c in robustness.CASES if c.name == "cyclic")
    factors, cutbacks, path = solve_along_the_path(case, method, law)
    _, _, monolithic = solve_along_the_path(case, "monolithic", law)
    assert cutbacks == 0 and len(factors) == case.increments and set(path) == set(monolithic)
    dF, du = path_difference(path, monolithic), path_difference(path, monolithic, 1)
    print(f"\n  cyclic {law}: {method} against monolithic over {len(monolithic)} increments: pair forces {dF:.1e}, "
          f"u {du:.1e}")
    assert dF < 1e-8 and du < 1e-8


@pytest.mark.parametrize("law", robustness.LAWS)
@pytest.mark.parametrize("method", ["monolithic", "nneqm1"])
def test_a_gap_closed_and_reopened_without_cutback(method, law):
    """The gap closes with slip inside the first increment: the monolithic solver's full steps
    cycled between two pair sets (its watchdog now counts only a halving of Ψ as progress),
    NNEQM1's inner solve likewise (it now retries with monotone steps)."""
    case = next(c for c in robustness.CASES if c.name == "gap-closes-reopens")
    factors, cutbacks, _ = solve_along_the_path(case, method, law)
    print(f"\n  gap {method}/{law}: load factors {factors}, cutbacks {cutbacks}")
    assert cutbacks == 0 and len(factors) == case.increments


@pytest.mark.parametrize("method", ["monolithic", "nneqm1"])
@pytest.mark.parametrize("increments", [3, 5])
def test_polar_law_on_the_two_beams_in_few_increments_equals_the_cartesian_law(method, increments):
    """The two beams in 3 and 5 increments: the polar law without cutback and to the Cartesian
    law's answer (1e-8) at every increment; the monolithic solver's median ≤ 4 Newton iterations.
    (Before: NNEQM1 took 3 cutbacks in 5 increments, its inner solve starting pairs on branches a
    meaningless θ decided; the monolithic solver's median was 9 in 3, its secant predictor
    drawing θ through the angle of pairs without friction force.)"""
    case = robustness.Case(f"two-beams-{increments}", robustness.two_beams, increments, "")
    runs = {law: solve_along_the_path(case, method, law) for law in robustness.LAWS}
    (factors, cutbacks, polar), (_, _, cartesian) = runs["polar"], runs["alart-curnier"]
    dF = path_difference(polar, cartesian)
    print(f"\n  two beams in {increments}, {method}/polar: cutbacks {cutbacks}; pair forces against the "
          f"Cartesian law {dF:.1e}")
    assert cutbacks == 0 and len(factors) == increments and set(polar) == set(cartesian) and dF < 1e-8
    if method == "monolithic":
        cell, _ = robustness.run_cell(case, method, "polar", increments)
        print(f"  {robustness.cell_text(cell)}")
        assert cell.converged and cell.median_per_increment <= 4


def test_nneqm2_on_the_two_beams_in_3_increments_without_cutback():
    """NNEQM2 starts its dense solve from the secant extrapolation of the pair forces: no cutback
    in 3 increments with either law (before: one, and 155 iterations with 123 in one increment),
    and the polar law equal to the Cartesian law (1e-8) at every increment."""
    case = robustness.Case("two-beams-3", robustness.two_beams, 3, "")
    runs = {law: solve_along_the_path(case, "nneqm2", law) for law in robustness.LAWS}
    (_, _, polar), (_, _, cartesian) = runs["polar"], runs["alart-curnier"]
    dF = path_difference(polar, cartesian)
    print(f"\n  two beams in 3, NNEQM2: cutbacks {[runs[law][1] for law in robustness.LAWS]} "
          f"({', '.join(robustness.LAWS)}); polar against Cartesian pair forces {dF:.1e}")
    for law in robustness.LAWS:
        factors, cutbacks, _ = runs[law]
        assert cutbacks == 0 and len(factors) == 3, law
    assert set(polar) == set(cartesian) and dF < 1e-8


def test_nneqm2_solves_the_polar_law_without_the_cartesian_law(monkeypatch):
    """NNEQM2 with the polar law on the two beams in 15 increments converges by the polar law's own
    Newton steps: the Cartesian law is never evaluated (before, each dense solve started from its
    solution; the polar law alone, then, took 10 cutbacks), no cutback, and the answer equals the
    Cartesian law's (1e-8) at every increment."""
    case = FAST["two-beams-15"]
    _, _, cartesian = solve_along_the_path(case, "nneqm2", "alart-curnier")

    def refuse(*args, **kwargs):
        raise AssertionError("the Cartesian law was evaluated in a solve with the polar law")

    monkeypatch.setattr(AlartCurnierLaw, "evaluate", refuse)
    monkeypatch.setattr(AlartCurnierLaw, "linearise", refuse)
    factors, cutbacks, polar = solve_along_the_path(case, "nneqm2", "polar")
    dF = path_difference(polar, cartesian)
    print(f"\n  two beams in 15, NNEQM2/polar: cutbacks {cutbacks}; pair forces against the Cartesian law {dF:.1e}")
    assert cutbacks == 0 and len(factors) == case.increments and set(polar) == set(cartesian) and dF < 1e-8


@pytest.mark.parametrize("method", METHODS)
def test_a_drag_beyond_friction_is_reported_not_converged(method):
    case = next(c for c in robustness.CASES if c.name == "drag-0.35-hex")
    cell, _ = robustness.run_cell(case, method, "alart-curnier", case.increments)
    print(f"\n  {method}: {cell.message}")
    assert not cell.converged and "did not converge" in cell.message


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("lift", [3.0e-4, -2.0e-4])
def test_force_free_states_converge(method, lift):
    """Body 2's top moved up (pairs open at once) or down across a 3e-4 m gap it never closes."""
    mesh, ct, ft = build_stacked_blocks(MPI.COMM_WORLD, 1.0, 0.5, 0.5, 1.0, 2, 1, 1, 2, gap=3.0e-4)
    elastic = VonMises(E=2.0e10, nu=0.2)
    problem = ContactProblem(mesh, ct, ft, materials={T.BODY1: elastic, T.BODY2: elastic},
                             dirichlet=[Dirichlet(T.BOTTOM), Dirichlet(T.TOP, (0.0, lift, 0.0))],
                             contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=0.3, search_distance=4.0e-4))
    results = solve_load_steps(problem, make_solver(method, problem, SolverOptions()), 2)
    t = pair_table(problem)
    print(f"\n  {method}, top moved {lift:+.0e} m: iterations {[r.iterations for r in results]}, "
          f"force floor {problem.force_floor:.3g} N, pairs {set(t['state_name'])}")
    assert [r.load_factor for r in results] == [0.5, 1.0] and set(t["state_name"]) == {"open"}
    assert abs(problem.u.x.array).max() == pytest.approx(abs(lift), rel=1e-12)


def test_nneqm2_frozen_directions_refuse_a_dense_system_too_large_before_solving():
    """The seed's variant has a dense matrix over the Gauss points; the default has none."""
    problem = robustness.pressed_and_dragged(0.2)("alart-curnier")
    with pytest.raises(ValueError, match="dense system would have order") as error:
        make_solver("nneqm2", problem, SolverOptions(),
                    nneqm2=NNEQM2Options(flow_directions="frozen", max_dense_order=100))
    print(f"\n  {error.value}")
    make_solver("nneqm2", problem, SolverOptions(), nneqm2=NNEQM2Options(max_dense_order=100)).destroy()


def test_the_dense_methods_refuse_a_condensation_that_does_not_fit_before_solving():
    """Issue 32: NNEQM1 (and NNEQM2's default variant) hold Bᵀ made dense, X = G Bᵀ and its copy
    (displacement dofs × 3NC each) and the dense contact system; a problem whose condensation
    needs more than ``max_memory_gb`` (default: the memory available) is refused before anything
    is assembled, with the sizes; within the limit the solver is made."""
    from dolfinx_nnqem.solvers import NNEQM1Options
    from dolfinx_nnqem.solvers.condensation import dense_memory

    problem = robustness.pressed_and_dragged(0.2)("alart-curnier")
    need = sum(dense_memory(problem).values())
    n_u, m = 3 * problem.V.dofmap.index_map.size_global, 3 * problem.num_pairs
    assert dense_memory(problem)["columns"] == 3 * 8 * 3 * problem.V.dofmap.index_map.size_local * m
    for method, options in (("nneqm1", {"nneqm1": NNEQM1Options(max_memory_gb=0.5 * need / 1e9)}),
                            ("nneqm2", {"nneqm2": NNEQM2Options(max_memory_gb=0.5 * need / 1e9)})):
        with pytest.raises(ValueError, match=rf"{method}: the dense condensation .* needs about .* GB") as error:
            make_solver(method, problem, SolverOptions(), **options)
        print(f"\n  {error.value}")
        assert f"{n_u:,} displacement dofs" in str(error.value) and f"{m:,} columns" in str(error.value)
    make_solver("nneqm1", problem, SolverOptions(), nneqm1=NNEQM1Options(max_memory_gb=2 * need / 1e9)).destroy()
    make_solver("nneqm2", problem, SolverOptions(), nneqm2=NNEQM2Options(max_memory_gb=2 * need / 1e9)).destroy()
    with pytest.raises(ValueError, match="max_memory_gb"):
        NNEQM1Options(max_memory_gb=0.0)


@pytest.mark.parametrize("law", ["alart-curnier", "polar"])
def test_a_stiffness_contrast_converges(law):
    """Body 1 of the pressed blocks 10⁴ times stiffer than body 2 (μ_f = 0.3, pressure then drag):
    every method converges, to the pair forces of the monolithic solver on the same load path (1e-6;
    friction makes the answer path dependent). The default r takes the softer body's modulus; with
    r = 999 times that (where the stiffer body's put it before), the monolithic solver and NNEQM2
    stalled at the drag onset after 5 cutbacks. Every method takes the 6 increments without a
    cutback, except NNEQM2 with the polar law, which with the PyPI packages of a venv made on
    2026-11-28 needs one at the drag onset, as the code of the day before does there (with Debian
    13's packages, and with the PyPI packages CI installed a day earlier, it took none): the case
    is at the edge of NNEQM2's globalisation, which has no Levenberg–Marquardt variant
    (docs/robustness.md)."""
    import numpy as np

    from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
    from dolfinx_nnqem.solvers import solve_load_path

    def solve(method, path=None):
        problem = pressed_blocks_problem(2, mu_f=0.3, body1_stiffer=1e4, law=law)
        with make_solver(method, problem, SolverOptions(rtol=1e-10, max_iterations=40)) as solver:
            results = (solve_load_steps(problem, solver, 6) if path is None
                       else solve_load_path(problem, solver, path))
        return [r.load_factor for r in results], [r.iterations for r in results], \
            pair_table(problem)["force_on_body1"]

    for method in METHODS:
        path, iterations, forces = solve(method)
        _, _, reference = solve("monolithic", path)
        error = np.abs(forces - reference).max() / np.abs(reference).max()
        print(f"\n  {law}/{method}: iterations {iterations}; pair forces against the monolithic solver on the same "
              f"path {error:.1e} (tolerance 1e-6)")
        # cutbacks: NNEQM2 with the polar law takes one or none by the packages (PyPI: one; Debian 13:
        # none, 24 iterations at the drag onset)
        assert len(path) <= 7 if (method, law) == ("nneqm2", "polar") else len(path) == 6, method
        assert error < 1e-6, method
