"""Rigid obstacles in the current geometry with degree-2 displacements (issue 41, "Finite strain").

Q2 hexahedra: a 9-node quadrilateral facet gives every node of the contact surface (vertices,
edge and centre nodes) a pair of its own, the node alone, which the current geometry re-evaluates
where the node is, as at degree 1, with its geometric terms in the Newton matrices. P2
tetrahedra: a 6-node triangle's pair acts on a combination of its nodes (the transformed basis);
the current geometry re-evaluates the combined point (``CombinedObstacleTracker``) at every Newton
iterate with the monolithic solver and NNEQM1, its geometric terms on the combined nodes
(``tests/integration/test_p2_obstacle_consistent.py``), and between solves with NNEQM2.

* the issue's sphere slid 0.3 -> 0.7 over a 3³ Q2 block, and over 3³ × 6 P2 tetrahedra, ends with
  the force of a press made in place there, with every solver (monolithic, NNEQM1, NNEQM2) and
  both laws; a cylinder too (Q2);
* the monolithic solver converges quadratically in every increment of the Q2 slide (the obstacle's
  geometric terms, per node, in its Newton matrix) and takes one solve per increment;
* a plane pressed and slid with friction gives the reference geometry's results on Q2 and P2 (its
  geometry is exact in both); a cylinder pressed and slid by d tends to them linearly in d on Q2
  (9e-9 at d = 10⁻⁵, 1e-9 at 10⁻⁶ with R = 0.6);
* the force converges with the mesh (a wider sphere, whose contact patch spans several facets):
  Q2 on 2³, 3³, 6³ against Q1 on 12³ (slow tier);
* ``geometry = "auto"`` moves the Q2 interface to the current geometry once it slides (it stopped
  the run before); the problem file takes ``degree = 2`` with ``geometry = "current"``;
* what stays refused, with the reason (tests/integration/test_large_sliding.py): mortar pairs of
  degree 2 (node-to-surface pairs of degree 2: tests/integration/test_large_sliding_nts_degree2.py).
"""

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.cases.geometries import build_block_stack
from dolfinx_nnqem.cases.large_sliding import MATERIAL, PRESSED_AT, obstacle_force, sliding_sphere
from dolfinx_nnqem.problem import Contact, ContactProblem, Cylinder, Dirichlet, PiecewiseLinearPath, Plane, Sphere
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)
ROUND_OFF = 1e-12  #: residuals below this (relative to the force scale) are round-off: no rate is read there


def _run(problem, method, increments):
    with make_solver(method, problem, OPTIONS) as solver:
        return solve_load_steps(problem, solver, increments)


@pytest.mark.parametrize("method, law", [("monolithic", "alart-curnier"), ("monolithic", "polar"),
                                         ("nneqm1", "alart-curnier"), ("nneqm1", "polar"),
                                         ("nneqm2", "alart-curnier")])
def test_q2_sphere_slid_equals_press_in_place(method, law):
    """The sphere slid 0.3 -> 0.7 over 3³ Q2 hexahedra (every one of the top face's 49 nodes a pair):
    the force of a press made in place at 0.7, 1e-8."""
    slid = sliding_sphere(3, degree=2, law=law)
    results = _run(slid, method, 16)
    in_place = sliding_sphere(3, start=0.7, end=0.7, degree=2, law=law)
    _run(in_place, method, 4)
    f_slid, f_place = obstacle_force(slid), obstacle_force(in_place)
    error = np.linalg.norm(f_slid - f_place) / np.linalg.norm(f_place)
    print(f"\n  {method}/{law}, Q2 3³: slid F = {f_slid}, in place F = {f_place}; |ΔF|/|F| = {error:.1e}; Newton "
          f"iterations per increment {[r.iterations for r in results]}, solves {[r.report.geometry_passes for r in results]}")
    assert slid.num_pairs == 49 and slid.contact.geometry.following == [True]
    assert error < 1e-8 and f_place[1] < 0


@pytest.mark.parametrize("method, law", [("monolithic", "alart-curnier"), ("monolithic", "polar"),
                                         ("nneqm1", "alart-curnier"), ("nneqm1", "polar"),
                                         ("nneqm2", "alart-curnier")])
def test_p2_tetrahedra_sphere_slid_equals_press_in_place(method, law):
    """The sphere slid 0.3 -> 0.7 over a block of 3³ × 6 P2 tetrahedra: its 65 pairs combine the nodes of their
    6-node triangles (CombinedObstacleTracker), evaluated at every Newton iterate (one solve per increment)
    with the monolithic solver and NNEQM1, between solves with NNEQM2; the force of a press made in place at
    0.7, 1e-8."""
    slid = sliding_sphere(3, degree=2, law=law, cell_type="tetrahedron")
    results = _run(slid, method, 16)
    in_place = sliding_sphere(3, start=0.7, end=0.7, degree=2, law=law, cell_type="tetrahedron")
    _run(in_place, method, 4)
    f_slid, f_place = obstacle_force(slid), obstacle_force(in_place)
    error = np.linalg.norm(f_slid - f_place) / np.linalg.norm(f_place)
    print(f"\n  {method}/{law}, P2 tetrahedra: slid F = {f_slid}, in place F = {f_place}; |ΔF|/|F| = {error:.1e}; "
          f"Newton iterations per increment {[r.iterations for r in results]}, solves "
          f"{[r.report.geometry_passes for r in results]}")
    assert slid.num_pairs == 65 and slid.contact.geometry.following == [True]
    assert error < 1e-8 and f_place[1] < 0
    assert all(r.report.geometry_passes == 1 for r in results) == (method != "nneqm2")


def test_q2_cylinder_slid_equals_press_in_place():
    slid = sliding_sphere(3, degree=2, shape="cylinder")
    _run(slid, "monolithic", 16)
    in_place = sliding_sphere(3, start=0.7, end=0.7, degree=2, shape="cylinder")
    _run(in_place, "monolithic", 4)
    f_slid, f_place = obstacle_force(slid), obstacle_force(in_place)
    error = np.linalg.norm(f_slid - f_place) / np.linalg.norm(f_place)
    print(f"\n  cylinder, Q2 3³: slid F = {f_slid}, in place F = {f_place}; |ΔF|/|F| = {error:.1e}")
    assert error < 1e-8 and f_place[1] < 0


def test_q2_sphere_slide_converges_quadratically():
    """The monolithic solver re-evaluates the Q2 pairs at every iterate with their geometric terms:
    every increment of the slide takes one solve, whose last step above round-off ends within
    10 ε_k² (frictional, μ_f = 0.3: the friction frame turns too)."""
    problem = sliding_sphere(3, degree=2, mu_f=0.3)
    results = _run(problem, "monolithic", 16)
    print()
    for result in results:
        eps = np.array([max(r.equilibrium, r.contact) for r in result.report.history])
        steps = [(eps[k], eps[k + 1]) for k in range(len(eps) - 1) if eps[k + 1] > ROUND_OFF]
        print(f"  ℓ = {result.load_factor:.4f}: max(|R|, |H|)/F = {', '.join(f'{e:.1e}' for e in eps)}; "
              f"solves {result.report.geometry_passes}")
        assert result.report.geometry_passes == 1
        if result.load_factor > PRESSED_AT + 1e-12 and steps:
            assert steps[-1][1] <= 10.0 * steps[-1][0] ** 2


def _block(n: int, obstacle, geometry: str, mu_f: float, cell_type: str = "hexahedron") -> ContactProblem:
    mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [1.0], [(n, n, n)], cell_type=cell_type)
    return ContactProblem(mesh, ct, ft, materials=MATERIAL, dirichlet=[Dirichlet(T.bottom(1))], degree=2,
                          contact=Contact(obstacle, T.top(1), mu_f=mu_f, geometry=geometry))


@pytest.mark.parametrize("method, cell_type", [("monolithic", "hexahedron"), ("nneqm1", "hexahedron"),
                                               ("monolithic", "tetrahedron"), ("nneqm1", "tetrahedron")])
def test_degree_2_current_geometry_equals_reference_for_a_plane(method, cell_type):
    """A plane pressed 10⁻³ and slid 5·10⁻³ with friction: exact in either geometry, so the same forces (on
    P2 tetrahedra too: the plane's distance of X̂ + d̂ is the combination Σ_k a_ik of the nodes' distances)."""
    path = PiecewiseLinearPath([[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, -1e-3, 0.0], [1.0, 5e-3, -1e-3, 0.0]])
    forces = {}
    for geometry in ("reference", "current"):
        plane = Plane(point=(0.0, 1.0, 0.0), normal=(0.0, -1.0, 0.0), motion=path)
        problem = _block(2 if cell_type == "hexahedron" else 3, plane, geometry, 0.3, cell_type)
        _run(problem, method, 8)
        forces[geometry] = obstacle_force(problem)
    error = np.linalg.norm(forces["current"] - forces["reference"]) / np.linalg.norm(forces["reference"])
    print(f"\n  {method}, {cell_type}, degree 2 plane: reference F = {forces['reference']}, current F = {forces['current']}; "
          f"|ΔF|/|F| = {error:.1e}")
    assert error < 1e-8 and abs(forces["reference"][0]) > 0.1 * abs(forces["reference"][1])


def _tiny_press(d: float, geometry: str) -> np.ndarray:
    """The force of a cylinder on the line of Q2 nodes x = 0.5 (vertices and edge nodes) pressed d and slid d
    with friction."""
    path = PiecewiseLinearPath([[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, -d, 0.0], [1.0, d, -d, 0.0]])
    cylinder = Cylinder(point=(0.5, 1.6, 0.5), axis=(0.0, 0.0, 1.0), radius=0.6, motion=path)
    problem = _block(3, cylinder, geometry, 0.3)
    with make_solver("monolithic", problem, SolverOptions(rtol=1e-10, atol=0.0, max_iterations=40)) as solver:
        solve_load_steps(problem, solver, 4)  # atol = 0: the forces are small
    return obstacle_force(problem)


def test_q2_current_geometry_tends_to_reference_at_a_tiny_slip():
    """Pressed and slid d = 10⁻⁵ and 10⁻⁶ (R = 0.6): the current geometry's exact distances differ from
    the reference's linearisation by O(d/R) relative, so the forces agree to 1e-8 and 2e-9, and the
    difference falls linearly with d (the round-off of distances computed at x = X + u, |X| ~ 1, stops
    the solves below 10⁻⁷)."""
    errors = []
    for d in (1e-5, 1e-6):
        f_ref, f_cur = _tiny_press(d, "reference"), _tiny_press(d, "current")
        errors.append(np.linalg.norm(f_cur - f_ref) / np.linalg.norm(f_ref))
        print(f"\n  Q2 cylinder pressed and slid {d:g}: reference F = {f_ref}, current F = {f_cur}; "
              f"|ΔF|/|F| = {errors[-1]:.1e}")
        assert f_ref[1] < 0 and abs(f_ref[0]) > 0.1 * abs(f_ref[1])  # pressed, and sliding with friction
    assert errors[0] < 1e-8 and errors[1] < 2e-9 and 0.05 < errors[1] / errors[0] < 0.2


@pytest.mark.parametrize("cell_type", ["hexahedron", "tetrahedron"])
def test_degree_2_auto_geometry_follows_the_sphere(cell_type):
    """geometry = "auto": the degree-2 interface starts in the reference geometry and moves to the current
    one once the sphere slides (before, degree 2 stopped the run there); the force of the press in place."""
    slid = sliding_sphere(3, degree=2, geometry="auto", cell_type=cell_type)
    results = _run(slid, "monolithic", 16)
    in_place = sliding_sphere(3, start=0.7, end=0.7, degree=2, cell_type=cell_type)
    _run(in_place, "monolithic", 4)
    f_slid, f_place = obstacle_force(slid), obstacle_force(in_place)
    error = np.linalg.norm(f_slid - f_place) / np.linalg.norm(f_place)
    print(f"\n  auto, {cell_type}, degree 2: slid F = {f_slid}, in place F = {f_place}; |ΔF|/|F| = {error:.1e}; solves "
          f"per increment {[r.report.geometry_passes for r in results]}")
    assert slid.contact.geometry.following == [True] and error < 1e-8


def _wide_sphere_slide(degree: int, n: int) -> np.ndarray:
    """The force of a frictionless sphere of radius 5 pressed 0.01 at x = 0.4 and slid to 0.6 over an n³ block
    (its contact patch, radius ≈ 0.32, spans several facets even on coarse meshes)."""
    path = PiecewiseLinearPath([[0.0, 0.0, 0.0, 0.0], [0.25, 0.0, -0.01, 0.0], [1.0, 0.2, -0.01, 0.0]])
    sphere = Sphere(centre=(0.4, 6.0, 0.5), radius=5.0, motion=path)
    mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [1.0], [(n, n, n)])
    problem = ContactProblem(mesh, ct, ft, materials=MATERIAL, dirichlet=[Dirichlet(T.bottom(1))], degree=degree,
                             contact=Contact(sphere, T.top(1), mu_f=0.0, geometry="current"))
    _run(problem, "monolithic", 16)
    return obstacle_force(problem)


def test_q2_slide_converges_with_the_mesh():
    """The wide sphere slid over Q2 blocks of 2³, 3³, 6³ and over the Q1 block of 12³ (the nodes of Q2 6³):
    the Q2 force settles (3³ within 1 % of 6³, 2³ 24 % off) and Q1 on the same nodes is within 2 %."""
    q2 = {n: _wide_sphere_slide(2, n) for n in (2, 3, 6)}
    q1 = _wide_sphere_slide(1, 12)
    rel = {n: np.linalg.norm(q2[n] - q2[6]) / np.linalg.norm(q2[6]) for n in (2, 3)}
    to_q1 = np.linalg.norm(q1 - q2[6]) / np.linalg.norm(q2[6])
    print(f"\n  F_y: Q2 2³ {q2[2][1]:.4f}, 3³ {q2[3][1]:.4f}, 6³ {q2[6][1]:.4f}; Q1 12³ {q1[1]:.4f}; Q2 against 6³: "
          f"2³ {rel[2]:.1e}, 3³ {rel[3]:.1e}; Q1 12³ against Q2 6³ {to_q1:.1e}")
    assert rel[3] < 0.01 < 0.1 < rel[2] and to_q1 < 0.02


SPHERE_FILE = """
[mesh]
file = "MESH"
degree = 2
[materials.1]
E = 1.0e3
nu = 0.3
[[contact]]
surface2 = 201
mu_f = 0.0
name = "sphere"
geometry = "current"
[contact.obstacle]
type = "sphere"
centre = [0.3, 1.6, 0.5]
radius = 0.6
motion = [[0.0, 0.0, 0.0, 0.0], [0.25, 0.0, -0.01, 0.0], [1.0, 0.4, -0.01, 0.0]]
[[dirichlet]]
tag = 101
[solver]
method = "monolithic"
increments = 16
rtol = 1e-10
"""


def test_problem_file_q2_sphere_in_current_geometry(tmp_path):
    """The Q2 sphere slide from a problem file (``degree = 2``, ``geometry = "current"``), through the CLI:
    the Python run's force."""
    import json

    from dolfinx_nnqem.cli import EXIT_OK, main

    if MPI.COMM_WORLD.size > 1:
        pytest.skip("the CLI test runs serially")
    build_block_stack(MPI.COMM_SELF, 1.0, 1.0, [1.0], [(3, 3, 3)], msh_file=tmp_path / "block.msh")
    path = tmp_path / "slide.toml"
    path.write_text(SPHERE_FILE.replace("MESH", (tmp_path / "block.msh").as_posix()))
    assert main(["-q", "run", str(path), "--out", str(tmp_path / "out")]) == EXIT_OK
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    force = np.array(summary["obstacle_forces"]["sphere"])
    python = sliding_sphere(3, degree=2)
    _run(python, "monolithic", 16)
    error = np.linalg.norm(force - obstacle_force(python)) / np.linalg.norm(force)
    print(f"\n  problem file: converged {summary['converged']}, F = {force}, Python run's F = {obstacle_force(python)}, "
          f"|ΔF|/|F| = {error:.1e}")
    assert summary["converged"] and error < 1e-8
