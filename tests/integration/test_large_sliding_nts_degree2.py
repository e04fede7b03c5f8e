"""Node-to-surface pairs with degree-2 displacements in the current geometry (issue 41, "Finite strain").

The block slid 1.6 master facets over another (``cases.large_sliding.sliding_blocks``, 12 increments),
node-to-surface, geometry = "current", with degree-2 displacements:

* Q2 hexahedra (9-node quadrilateral facets: every slave node a pair of its own): the monolithic solver
  re-evaluates the pairs at every Newton iterate on the moved quadratic master facets, with their
  geometric terms in J (``contact/quadratic_surface_stiffness.py``): J d equals central differences of
  (R, H) mid-slide, Newton converges quadratically in every increment and the solve at the
  re-evaluated geometry starts converged;
* the frictionless slide ends in the state of a press made in place at the slid position, with every
  solver (monolithic, NNEQM1, NNEQM2) and both laws; ``geometry = "auto"`` moves the interface to the
  current geometry once it slides and ends there too;
* P2 tetrahedra (6-node triangles: a pair combines the slave nodes of the transformed basis, each
  projected onto its own master facet): the monolithic solver re-evaluates the combined pairs at every
  Newton iterate with their geometric terms in J (``contact/combined_surface_stiffness.py``): J d equals
  central differences mid-slide, Newton converges quadratically and the solve at the re-evaluated
  geometry starts converged (two solves per increment); NNEQM1 freezes them within a solve and
  re-evaluates between solves; the slide ends in the press in place's state;
* at a tiny slide the current geometry gives the reference geometry's forces;
* the problem file takes ``degree = 2`` with node-to-surface pairs in the current geometry (the CLI run
  gives the Python run's force).
"""

import numpy as np
import pytest
from mpi4py import MPI
from newton_checks import (last_step, newton_matrix_against_differences, recorded_load_steps, residuals,
                           solves_by_increment)
from test_large_sliding import _blocks_file

from dolfinx_nnqem.cases.large_sliding import PRESSED_AT, slave_force, sliding_blocks
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)


def _run(problem, method, increments, **kwargs):
    with make_solver(method, problem, OPTIONS) as solver:
        return solve_load_steps(problem, solver, increments, **kwargs)


def _recorded_slide(**kwargs):
    """The degree-2 block slide with the monolithic solver; (problem, results, every solve's (load factor,
    report))."""
    problem = sliding_blocks(slide=0.4, degree=2, **kwargs)
    with make_solver("monolithic", problem, OPTIONS) as solver:
        results, reports = recorded_load_steps(problem, solver, 12)
    return problem, results, reports


def _assert_quadratic_slip_increments(reports) -> None:
    """The first solve of every slip increment ends within 10 ε_k² of its last step above round-off, and the
    solve that load stepping makes at the re-evaluated geometry starts converged (printing the sequences)."""
    print()
    for load_factor, solves in solves_by_increment(reports, PRESSED_AT).items():
        eps = residuals(solves[0])
        step = last_step(solves[0])
        print(f"  ℓ = {load_factor:.4f}: max(|R|, |H|)/F = {', '.join(f'{e:.1e}' for e in eps)}; last step "
              f"{'–' if step is None else f'{step[0]:.1e} -> {step[1]:.1e}'}; iterates per solve "
              f"{[len(r.history) for r in solves]}")
        assert step is not None and step[1] <= 10.0 * step[0] ** 2
        assert [len(r.history) for r in solves[1:]] == [1] and solves[1].history[0].iteration == 0


@pytest.mark.slow
def test_q2_node_to_surface_slide_converges_quadratically():
    """μ_f = 0.3, Q2: every pair re-evaluated at every iterate (the tracker re-projects, nothing frozen);
    the first solve of every slip increment ends within 10 ε_k² of its last step above round-off, and the
    solve that load stepping makes at the re-evaluated geometry starts converged."""
    problem, _, reports = _recorded_slide(mu_f=0.3)
    assert problem.contact.geometry.following == [True] and problem.contact.geometry.reprojecting == [True]
    _assert_quadratic_slip_increments(reports)


def test_q2_newton_matrix_matches_finite_differences_mid_slide():
    """J d against central differences of (R, H) at a perturbed state mid-slide (Q2, μ_f = 0.3): the
    quadratic facets' closest points, normals and frames moving with the nodes."""
    problem = sliding_blocks(slide=0.4, mu_f=0.3, degree=2)
    with make_solver("monolithic", problem, OPTIONS) as solver:
        solve_load_steps(problem, solver, 5, final_load_factor=5 / 12)
        error_u, error_H, frozen_u, frozen_H = newton_matrix_against_differences(problem, solver)
    print(f"\n  Q2: |J d − FD| / |FD|: u rows {error_u:.1e}, pair rows {error_H:.1e}; the frozen geometry's J: "
          f"{frozen_u:.1e}, {frozen_H:.1e}")
    assert error_u < 1e-8 and error_H < 1e-5
    assert frozen_u > 1e-4 and frozen_H > 1e-4  # the residuals differentiated are the current geometry's


def _slid_and_in_place(method: str, law: str, cell_type: str = "hexahedron", geometry: str = "current",
                       same_facets: bool = False):
    """The frictionless degree-2 slide (0.4) and a press made in place at 0.4: (slid, in place, results);
    ``same_facets``: the press in place prefers the master facets the slide ended on (``geometry.set_state``)."""
    slid = sliding_blocks(slide=0.4, law=law, degree=2, cell_type=cell_type, geometry=geometry)
    results = _run(slid, method, 12)
    in_place = sliding_blocks(slide=0.0, offset=0.4, law=law, degree=2, cell_type=cell_type)
    if same_facets:
        in_place.contact.geometry.set_state(slid.contact.geometry.state())
    _run(in_place, method, 4)
    return slid, in_place, results


@pytest.mark.slow
@pytest.mark.parametrize("method, law", [("monolithic", "alart-curnier"), ("monolithic", "polar"),
                                         ("nneqm1", "alart-curnier"), ("nneqm1", "polar"),
                                         ("nneqm2", "alart-curnier")])
def test_q2_block_slid_equals_press_in_place(method, law):
    """Frictionless, Q2: the slid state is the press in place's. Made afresh, the press in place puts 10 of the
    169 slave nodes, those on shared edges of the master (z = 0.25, 0.5, 0.75), on the other facet than the
    slide, which keeps a node's facet while it still projects onto it: the normal force then differs by
    4.0e-5 – 4.1e-5 and the resultant by 6.3e-4 – 6.9e-4 (degree 1: 1.9e-7 in the normal force). With the
    slide's master facets preferred, the press in place gives the slid state: 2.9e-15 – 5.3e-15 (monolithic),
    2.0e-11 (NNEQM1), 2.3e-10 (NNEQM2) measured; the slide is path-independent where the facets are the same."""
    slid, in_place, results = _slid_and_in_place(method, law, same_facets=True)
    f_slid, f_place = slave_force(slid), slave_force(in_place)
    error = abs(f_slid[1] - f_place[1]) / abs(f_place[1])
    total = np.linalg.norm(f_slid - f_place) / np.linalg.norm(f_place)
    print(f"\n  {method}/{law}, Q2: pairs {slid.num_pairs} (in place {in_place.num_pairs}); normal force {f_slid[1]:.10g}, "
          f"in place {f_place[1]:.10g}: {error:.1e}; |ΔF|/|F| = {total:.1e}; Newton iterations "
          f"{[r.iterations for r in results]}, solves {[r.report.geometry_passes for r in results]}")
    assert slid.num_pairs == in_place.num_pairs and slid.contact.geometry.following == [True]
    assert error < 1e-7 and total < 1e-6


@pytest.mark.slow
def test_p2_node_to_surface_slide_converges_quadratically():
    """μ_f = 0.3, P2 tetrahedra: the combined pairs re-evaluated at every iterate with their consistent terms;
    the first solve of every slip increment ends within 10 ε_k² of its last step above round-off (measured
    ε_(k+1)/ε_k² 0.3 – 3.6), and the solve that load stepping makes at the re-evaluated geometry starts converged:
    two solves per increment (frozen within a solve before, 6 – 11)."""
    problem, results, reports = _recorded_slide(mu_f=0.3, cell_type="tetrahedron")
    assert problem.contact.geometry.following == [True] and problem.contact.geometry.reprojecting == [True]
    _assert_quadratic_slip_increments(reports)
    assert max(r.report.geometry_passes for r in results) == 2


@pytest.mark.slow
def test_p2_newton_matrix_matches_finite_differences_mid_slide():
    """J d against central differences of (R, H) at a perturbed state mid-slide (P2 tetrahedra, μ_f = 0.3):
    every slave node of a combined pair on its own master facet, closest points, normals and frames moving
    with the nodes (seed 1: seed 0's direction crosses a pair's stick–slip kink within ± 1e-7)."""
    problem = sliding_blocks(slide=0.4, mu_f=0.3, degree=2, cell_type="tetrahedron")
    with make_solver("monolithic", problem, OPTIONS) as solver:
        solve_load_steps(problem, solver, 5, final_load_factor=5 / 12)
        error_u, error_H, frozen_u, frozen_H = newton_matrix_against_differences(problem, solver, seed=1)
    print(f"\n  P2: |J d − FD| / |FD|: u rows {error_u:.1e}, pair rows {error_H:.1e}; the frozen geometry's J: "
          f"{frozen_u:.1e}, {frozen_H:.1e}")
    assert error_u < 1e-8 and error_H < 1e-4
    assert frozen_u > 1e-4 and frozen_H > 1e-3  # the residuals differentiated are the current geometry's


@pytest.mark.slow
@pytest.mark.parametrize("method, law", [("monolithic", "alart-curnier"), ("monolithic", "polar"),
                                         ("nneqm1", "polar")])
def test_p2_tetrahedra_block_slid_equals_press_in_place(method, law):
    """Frictionless, P2 tetrahedra: the monolithic solver re-evaluates the combined pairs at every iterate (two
    solves per increment, the second starting converged); NNEQM1 freezes them within a solve and evaluates
    them again between solves (several solves per slip increment). The slid state is the press in place's:
    the same number of pairs, the normal force to 1e-3 (measured 1.3e-4 monolithic, both laws; 2.0e-4 NNEQM1).
    Unlike Q2 (test_q2_block_slid_equals_press_in_place) the press in place does not reach the slid state to
    round-off when it prefers the slide's master facets (8.5e-5 monolithic): 5 slave nodes lie beyond the edge
    allowance past those facets before the press and end on the neighbouring ones; with the slide's facets the
    slid state is an equilibrium of the press in place (|R|/F 7.7e-14, docs/theory.md)."""
    slid, in_place, results = _slid_and_in_place(method, law, "tetrahedron")
    f_slid, f_place = slave_force(slid), slave_force(in_place)
    error = abs(f_slid[1] - f_place[1]) / abs(f_place[1])
    passes = [r.report.geometry_passes for r in results]
    print(f"\n  {method}/{law}, P2 tetrahedra: pairs {slid.num_pairs} (in place {in_place.num_pairs}); normal force {f_slid[1]:.10g}, "
          f"in place {f_place[1]:.10g}: {error:.1e}; solves per increment {passes}")
    consistent = method == "monolithic"
    assert slid.contact.geometry.following == [True] and slid.contact.geometry.reprojecting == [True]
    assert slid.num_pairs == in_place.num_pairs and error < 1e-3
    if consistent:
        assert max(passes) <= 2
    else:
        assert max(passes[3:]) >= 3  # the re-evaluations between solves


@pytest.mark.slow
def test_q2_auto_geometry_moves_to_the_current_geometry():
    """geometry = "auto": the Q2 interface starts in the reference geometry and follows the bodies once
    the block slides (before, degree-2 node-to-surface pairs could not follow it and the run stopped); it ends
    in the press in place's state as geometry = "current" does (4.1e-5: test_q2_block_slid_equals_press_in_place)."""
    slid, in_place, results = _slid_and_in_place("monolithic", "alart-curnier", geometry="auto")
    f_slid, f_place = slave_force(slid), slave_force(in_place)
    error = abs(f_slid[1] - f_place[1]) / abs(f_place[1])
    print(f"\n  auto, Q2: following {slid.contact.geometry.following}; normal force {f_slid[1]:.10g}, in place "
          f"{f_place[1]:.10g}: {error:.1e}")
    assert slid.contact.geometry.following == [True] and error < 1e-4


@pytest.mark.parametrize("cell_type", ["hexahedron", "tetrahedron"])
def test_degree_2_current_geometry_tends_to_reference_at_a_tiny_slide(cell_type):
    """Pressed 10⁻² and slid 10⁻⁵ with friction (μ_f = 0.3, the tangential force 3e-4 of the normal one): the
    current geometry's forces are the reference geometry's (both blocks of one material and width: the
    press strains them alike, the interface stays flat and every slave node on its facet; measured 2e-13
    on Q2 hexahedra)."""
    forces = {}
    for geometry in ("reference", "current"):
        problem = sliding_blocks(slide=1e-5, mu_f=0.3, degree=2, cell_type=cell_type, geometry=geometry)
        _run(problem, "monolithic", 4)
        forces[geometry] = slave_force(problem)
    error = np.linalg.norm(forces["current"] - forces["reference"]) / np.linalg.norm(forces["reference"])
    print(f"\n  {cell_type}, degree 2, slid 1e-5: reference F = {forces['reference']}, current F = {forces['current']}; "
          f"|ΔF|/|F| = {error:.1e}")
    assert error < 1e-8 and abs(forces["reference"][0]) > 1e-4 * abs(forces["reference"][1])


BLOCKS_FILE = _blocks_file(E1=1.0e3, press=-0.01, pressed_at=0.25, slide=0.4, z_tags=[202], increments=12,
                          degree=2, discretisation="node-to-surface", rtol=1e-10)


@pytest.mark.slow
@pytest.mark.parametrize("method, law", [("monolithic", "polar"), ("nneqm1", "alart-curnier")])
def test_problem_file_q2_block_slid_in_current_geometry(tmp_path, method, law):
    """The frictional Q2 block slide from a problem file (``degree = 2``, node-to-surface, ``geometry =
    "current"``), through the CLI: the Python run's Newton iterations and reaction at the clamped bottom."""
    import json

    from dolfinx_nnqem.cases.geometries import build_block_stack
    from dolfinx_nnqem.cli import EXIT_OK, main
    from dolfinx_nnqem.io.results import equilibrium_check

    if MPI.COMM_WORLD.size > 1:
        pytest.skip("the CLI test runs serially")
    build_block_stack(MPI.COMM_SELF, 1.0, 1.0, [0.5, 0.5], [(4, 2, 4), (6, 2, 6)], msh_file=tmp_path / "blocks.msh")
    path = tmp_path / "slide.toml"
    path.write_text(BLOCKS_FILE.replace("MESH", (tmp_path / "blocks.msh").as_posix()).replace("METHOD", method)
                    .replace("LAW", law))
    assert main(["-q", "run", str(path), "--out", str(tmp_path / "out")]) == EXIT_OK
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    python = sliding_blocks(slide=0.4, law=law, mu_f=0.3, degree=2)
    iterations = [r.iterations for r in _run(python, method, 12)]
    reaction, cli = equilibrium_check(python)["reactions"][101], np.array(summary["reactions"]["101"])
    error = np.linalg.norm(cli - reaction) / np.linalg.norm(reaction)
    print(f"\n  {method}/{law}: converged {summary['converged']}, iterations {summary['iterations']} (the Python "
          f"run's: {iterations}); reaction at 101 {cli} (Python {reaction}): {error:.1e}")
    assert summary["converged"] and summary["iterations"] == iterations
    assert summary["contact_geometry"] == {python.contact.interfaces[0].contact.label: "current"}
    assert error < 1e-12
