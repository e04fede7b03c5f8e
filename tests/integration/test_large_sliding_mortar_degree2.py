"""Dual mortar pairs of degree 2 in the current geometry (issue 41, "Finite strain").

The frictional block slide (``cases.large_sliding.sliding_blocks``, μ_f = 0.3) on Q2 hexahedra (quad9
facets: every node its own pair) and on P2 tetrahedra (tri6 facets: an edge node's pair acts on d̂_j,
the node and its edge's vertices), 2 × 1 × 2 lower and 3 × 1 × 3 upper cells (the nodes of the
degree-1 case's 4 × 2 × 4 and 6 × 2 × 6), pressed 0.01 and slid 0.4 (0.8 master facets; part of the
upper block then overhangs and its pairs go). With the monolithic solver the quadratic mortar
integrals are evaluated again at every Newton iterate and their derivatives are in J
(``contact/quadratic_mortar_linearisation.py``), so

* Newton converges quadratically in every increment of the slide, and the solve that load stepping
  makes at the re-evaluated geometry starts converged (slow tier);
* J d equals central differences of (R, H) along a random d mid-slide (slow tier);
* every solver (monolithic, NNEQM1, NNEQM2 re-solving with the geometry frozen within a solve) and both
  laws end in the same state; the frozen geometry (``consistent_geometry`` off) too, in more iterations;
* at a tiny slip d the current geometry gives the reference geometry's forces, the difference falling
  linearly with d; the slid force is within 1 % of degree-1 mortar on the same nodes and on a mesh
  twice as fine (slow tier);
* ``geometry = "auto"`` moves a degree-2 mortar interface to the current geometry once it slides, and a
  problem file takes it through the CLI with the Python run's answer.
"""

import numpy as np
import pytest
from mpi4py import MPI
from newton_checks import (newton_matrix_against_differences, recorded_load_steps, residuals,
                           solves_by_increment)
from test_large_sliding import _blocks_file

from dolfinx_nnqem.cases.large_sliding import PRESSED_AT, slave_force, sliding_blocks
from dolfinx_nnqem.solvers import MonolithicOptions, SolverOptions, make_solver, solve_load_steps

OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)
DIVISIONS = ((2, 1, 2), (3, 1, 3))  #: lower and upper blocks, degree 2
INCREMENTS = 8


def _blocks(cell_type: str = "hexahedron", law: str = "alart-curnier", slide: float = 0.4, geometry: str = "current",
            degree: int = 2, divisions=DIVISIONS, depth: float = 0.01):
    return sliding_blocks(slide=slide, mu_f=0.3, law=law, discretisation="mortar", degree=degree, cell_type=cell_type,
                          divisions=divisions, geometry=geometry, depth=depth)


def _run(problem, method: str, increments: int = INCREMENTS, consistent: bool = True):
    """(results, every solve's (load factor, report)); ``method`` "iterative": the monolithic solver with
    the iterative linear solver."""
    options = {}
    if method in ("monolithic", "iterative"):
        linear_solver = "iterative" if method == "iterative" else "direct"
        options = {"monolithic": MonolithicOptions(consistent_geometry=consistent, linear_solver=linear_solver)}
        method = "monolithic"
    with make_solver(method, problem, OPTIONS, **options) as solver:
        return recorded_load_steps(problem, solver, increments)


ROUND_OFF = 1e-13  #: residuals below this (relative to the force scale) are round-off: no rate is read there


def _quadratic_steps(eps: np.ndarray) -> list[tuple[float, float]]:
    """The steps (ε_k, ε_{k+1}) of a solve from ε_k < 10⁻² (where Newton's quadratic term leads) to
    above round-off."""
    return [(eps[k], eps[k + 1]) for k in range(len(eps) - 1) if eps[k] < 1e-2 and eps[k + 1] > ROUND_OFF]


@pytest.mark.slow
@pytest.mark.parametrize("cell_type", ["hexahedron", "tetrahedron"])
def test_newton_converges_quadratically_on_a_degree_2_mortar_slide(cell_type):
    """Every increment of the slide: its first solve's steps from below 10⁻² down to round-off end
    within 10 ε_k² (there is one at least), and the solve that follows at the re-evaluated geometry
    starts converged."""
    problem = _blocks(cell_type)
    _, reports = _run(problem, "monolithic")
    lines = []
    for load_factor, solves in solves_by_increment(reports, PRESSED_AT).items():
        steps = _quadratic_steps(residuals(solves[0]))
        lines.append(f"  ℓ = {load_factor:.4f}: max(|R|, |H|)/F = {', '.join(f'{e:.1e}' for e in residuals(solves[0]))}; "
                     f"steps {', '.join(f'{a:.1e} -> {b:.1e}' for a, b in steps)}; iterates per solve "
                     f"{[len(r.history) for r in solves]}")
    print(f"\n  {cell_type}, {problem.num_pairs} pairs at the end\n" + "\n".join(lines))
    for (load_factor, solves), line in zip(solves_by_increment(reports, PRESSED_AT).items(), lines):
        steps = _quadratic_steps(residuals(solves[0]))
        assert steps and all(b <= 10.0 * a ** 2 for a, b in steps), line
        assert [len(r.history) for r in solves[1:]] == [1] and solves[1].history[0].iteration == 0, line


@pytest.mark.slow
def test_degree_2_mortar_newton_matrix_matches_finite_differences_mid_slide():
    """J d against central differences of (R, H) at a perturbed state mid-slide (Q2, μ_f = 0.3)."""
    problem = _blocks()
    with make_solver("monolithic", problem, OPTIONS) as solver:
        solve_load_steps(problem, solver, INCREMENTS, final_load_factor=4 / INCREMENTS)
        error_u, error_H, frozen_u, frozen_H = newton_matrix_against_differences(problem, solver)
    print(f"\n  |J d − FD| / |FD|: u rows {error_u:.1e}, pair rows {error_H:.1e}; the frozen geometry's J: "
          f"{frozen_u:.1e}, {frozen_H:.1e}")
    assert error_u < 1e-6 and error_H < 1e-5
    assert frozen_u > 1e-4 or frozen_H > 1e-4  # the residuals differentiated are the current geometry's


@pytest.fixture(scope="module")
def q2_slide():
    """The Q2 slide with the monolithic solver (Alart-Curnier), the geometry frozen within a solve and
    re-evaluated between solves (``consistent_geometry`` off): (problem, results)."""
    problem = _blocks()
    return problem, _run(problem, "monolithic", consistent=False)[0]


@pytest.mark.parametrize("method, law", [("monolithic", "alart-curnier"), ("monolithic", "polar"),
                                         ("nneqm1", "alart-curnier"), ("nneqm1", "polar"),
                                         ("nneqm2", "alart-curnier"), ("nneqm2", "polar"), ("iterative", "alart-curnier")])
def test_every_solver_and_law_ends_in_the_same_state(q2_slide, method, law):
    """The Q2 slide by every solver and law: the state of the monolithic run whose geometry is frozen
    within a solve (re-evaluated between solves until a solve starts converged), force and displacement
    to 1e-8; the consistent monolithic solver (slow tier; with the direct or the iterative linear solver)
    in fewer Newton iterations."""
    reference, reference_results = q2_slide
    problem = _blocks(law=law)
    results, _ = _run(problem, method)
    f, f_ref = slave_force(problem), slave_force(reference)
    du = np.abs(problem.u.x.array - reference.u.x.array).max() / np.abs(reference.u.x.array).max()
    n, n_ref = sum(r.iterations for r in results), sum(r.iterations for r in reference_results)
    print(f"\n  {method}/{law}: F = {f} (monolithic, frozen geometry: {f_ref}); "
          f"|ΔF|/|F| = {np.linalg.norm(f - f_ref) / np.linalg.norm(f_ref):.1e}, max|Δu|/max|u| = {du:.1e}; "
          f"{problem.num_pairs} pairs; Newton iterations {n} (frozen monolithic {n_ref}); solves per increment "
          f"{[r.report.geometry_passes for r in results]}")
    assert problem.num_pairs == reference.num_pairs and problem.contact.geometry.following == [True]
    assert np.linalg.norm(f - f_ref) < 1e-8 * np.linalg.norm(f_ref) and du < 1e-7
    if method in ("monolithic", "iterative"):  # consistent: one Newton solve per increment, and one to confirm it
        assert n < 0.5 * n_ref


def test_p2_tetrahedra_slide_by_monolithic_and_nneqm1():
    """tri6 pairs on d̂_j: the slide over P2 tetrahedra by the monolithic solver (consistent) and NNEQM1
    (polar law, the geometry frozen within a solve) end in the same state, 1e-8."""
    monolithic, nneqm1 = _blocks("tetrahedron"), _blocks("tetrahedron", law="polar")
    _run(monolithic, "monolithic")
    _run(nneqm1, "nneqm1")
    f_m, f_1 = slave_force(monolithic), slave_force(nneqm1)
    error = np.linalg.norm(f_m - f_1) / np.linalg.norm(f_m)
    print(f"\n  P2 tetrahedra: monolithic F = {f_m}, NNEQM1 (polar) F = {f_1}; |ΔF|/|F| = {error:.1e}; "
          f"{monolithic.num_pairs} pairs")
    assert error < 1e-8 and monolithic.num_pairs == nneqm1.num_pairs


def _tiny_slide_force(d: float, geometry: str) -> np.ndarray:
    """The force of the Q2 blocks pressed d and slid d."""
    problem = _blocks(slide=d, depth=d, geometry=geometry)
    _run(problem, "monolithic", 4)
    return slave_force(problem)


def test_q2_mortar_current_geometry_tends_to_reference_at_a_tiny_slip():
    """Pressed and slid d = 10⁻⁵ and 10⁻⁶: the current geometry's integrals differ from the reference
    ones by O(d), so the forces agree to O(d) relative and the difference falls linearly with d."""
    errors = []
    for d in (1e-5, 1e-6):
        f_ref, f_cur = _tiny_slide_force(d, "reference"), _tiny_slide_force(d, "current")
        errors.append(np.linalg.norm(f_cur - f_ref) / np.linalg.norm(f_ref))
        print(f"\n  Q2 mortar pressed and slid {d:g}: reference F = {f_ref}, current F = {f_cur}; "
              f"|ΔF|/|F| = {errors[-1]:.1e}")
        assert abs(f_ref[0]) > 0.1 * abs(f_ref[1])  # sliding with friction
    assert errors[0] < 1e-6 and 0.05 < errors[1] / errors[0] < 0.2


@pytest.mark.slow
def test_q2_mortar_slide_agrees_with_degree_1_mortar_on_finer_meshes():
    """The slid force (the frozen-geometry NNEQM1 runs: the same states, fewer derivatives) of Q2 mortar on
    2 × 1 × 2 | 3 × 1 × 3 and 4 × 2 × 4 | 6 × 2 × 6 cells against degree-1 mortar on the same nodes (4 × 2 × 4 |
    6 × 2 × 6 and 8 × 4 × 8 | 12 × 4 × 12 cells): within 1 % on either mesh, and each degree's force falls
    with the mesh towards the other's."""
    fine = ((4, 2, 4), (6, 2, 6))
    finer = ((8, 4, 8), (12, 4, 12))
    forces = {}
    for degree, divisions, name in ((2, DIVISIONS, "Q2 coarse"), (2, fine, "Q2 fine"), (1, fine, "Q1 coarse"),
                                    (1, finer, "Q1 fine")):
        problem = _blocks(degree=degree, divisions=divisions)
        _run(problem, "nneqm1", 12)
        forces[name] = slave_force(problem)
    print("\n  " + "; ".join(f"{name}: F = {np.array2string(f, precision=5)}" for name, f in forces.items()))
    for q2, q1 in (("Q2 coarse", "Q1 coarse"), ("Q2 fine", "Q1 fine")):
        assert np.linalg.norm(forces[q2] - forces[q1]) < 0.01 * np.linalg.norm(forces[q1])
    assert forces["Q1 fine"][1] < forces["Q1 coarse"][1] and forces["Q2 fine"][1] < forces["Q2 coarse"][1]


def test_degree_2_mortar_auto_geometry_follows_the_slide(q2_slide):
    """geometry = "auto": the Q2 mortar interface starts in the reference geometry and moves to the current
    one once the block slides (before, degree 2 stopped the run there); at the end every pair slides, so
    the force is the current geometry's from the start, 1e-8."""
    current, _ = q2_slide
    problem = _blocks(geometry="auto")
    results, _ = _run(problem, "monolithic")
    f, f_current = slave_force(problem), slave_force(current)
    error = np.linalg.norm(f - f_current) / np.linalg.norm(f_current)
    print(f"\n  auto: F = {f}, current from the start F = {f_current}; |ΔF|/|F| = {error:.1e}; solves per increment "
          f"{[r.report.geometry_passes for r in results]}")
    assert problem.contact.geometry.following == [True] and error < 1e-8


BLOCKS_FILE = _blocks_file(E1=1.0e3, press=-0.01, pressed_at=0.25, slide=0.4, z_tags=[202], increments=8,
                          degree=2, discretisation="mortar", rtol=1e-10)


@pytest.mark.parametrize("method, law", [("monolithic", "alart-curnier"), ("nneqm1", "polar")])
def test_problem_file_q2_mortar_slide_in_current_geometry(tmp_path, method, law):
    """The Q2 mortar slide from a problem file (``degree = 2``, ``discretisation = "mortar"``,
    ``geometry = "current"``), through the CLI: the Python run's iterations and reaction at the top."""
    import json

    from dolfinx_nnqem.cases.geometries import build_block_stack
    from dolfinx_nnqem.cli import EXIT_OK, main
    from dolfinx_nnqem.io.results import equilibrium_check

    if MPI.COMM_WORLD.size > 1:
        pytest.skip("the CLI test runs serially")
    build_block_stack(MPI.COMM_SELF, 1.0, 1.0, [0.5, 0.5], list(DIVISIONS), msh_file=tmp_path / "blocks.msh")
    path = tmp_path / "slide.toml"
    path.write_text(BLOCKS_FILE.replace("MESH", (tmp_path / "blocks.msh").as_posix()).replace("METHOD", method)
                    .replace("LAW", law))
    assert main(["-q", "run", str(path), "--out", str(tmp_path / "out")]) == EXIT_OK
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    python = _blocks(law=law)
    results, _ = _run(python, method)
    reaction = np.array(summary["reactions"]["202"])
    expected = equilibrium_check(python)["reactions"][202]
    error = np.linalg.norm(reaction - expected) / np.linalg.norm(expected)
    print(f"\n  {method}/{law}: converged {summary['converged']}, iterations {summary['iterations']} (the Python "
          f"run's: {[r.iterations for r in results]}); reaction at the top {reaction} (Python {expected}, "
          f"|Δ|/|R| = {error:.1e})")
    assert summary["converged"] and summary["iterations"] == [r.iterations for r in results]
    assert error < 1e-8 and np.linalg.norm(expected + slave_force(python)) < 1e-8 * np.linalg.norm(expected)
