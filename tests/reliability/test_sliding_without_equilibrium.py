"""Issue 31, item 5: a body that only friction holds in some direction. Pushed along it past the
friction limit, it slides without resistance and no equilibrium exists; every method must say so
(the body and the direction) instead of only "did not converge", and NNEQM2 must not spend
minutes on it (it took 347 s to fail with yielding blocks: timed by the slow test's print, never
asserted; the tests check what each method reached instead)."""

import json
import math
import time

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem.cli import EXIT_DIVERGED, EXIT_OK, main

from reliability_helpers import ROOT

DRAG = '''[[dirichlet]]
tag = 203             # the top of block 3 dragged along x after the pressure
value = 0.01
components = [0]
amplitude = [[0.0, 0.0], [0.2, 0.0], [1.0, 1.0]]
'''
PUSH = '''[[traction]]
tag = 203             # pushed along x with 2.5 times what the lower interface's friction carries
value = [5.0e5, 0.0, 0.0]
amplitude = [[0.0, 0.0], [0.2, 0.0], [1.0, 1.0]]
'''


def _pushed_blocks(tmp_path, plastic: bool = False):
    """demos/three_blocks.toml with block 3 pushed by a traction instead of dragged: blocks 2 and
    3 are held along x by friction only (μ_f 0.2 below block 2, p = 1 MPa, τ up to 0.5 MPa)."""
    text = (ROOT / "demos" / "three_blocks.toml").read_text()
    mesh = (ROOT / "meshes" / "three_blocks.msh").as_posix()
    text = text.replace('file = "../meshes/three_blocks.msh"', f'file = "{mesh}"')
    assert DRAG in text
    text = text.replace(DRAG, "").replace("[solver]", PUSH + "\n[solver]")
    if plastic:
        text = text.replace("nu = 0.3\n", "nu = 0.3\nsigma_y0 = 2.0e6\nH = 1.0e8\n")
    path = tmp_path / "pushed.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("method", ["monolithic", "nneqm1", "nneqm2"])
def test_a_body_held_only_by_friction_is_named_when_it_slides(tmp_path, capsys, method):
    p = _pushed_blocks(tmp_path)
    assert main(["run", str(p), "--check"]) == EXIT_OK
    header = capsys.readouterr().out
    t0 = time.perf_counter()
    code = main(["-q", "run", str(p), "--out", str(tmp_path / "out"), "--method", method])
    wall = time.perf_counter() - t0
    err = capsys.readouterr().err
    print(f"\n  {method}: exit {code} after {wall:.1f} s\n  " + "\n  ".join(err.strip().splitlines()[-5:]))
    assert "held by friction only: body 2 (cells tagged 2): translation along (1, 0, 0)" in header
    assert code == EXIT_DIVERGED and "friction alone holds" in err
    assert "body 2 (cells tagged 2): translation along (1, 0, 0)" in err
    assert "body 3 (cells tagged 3): translation along (1, 0, 0)" in err
    failure = json.loads((tmp_path / "out" / "summary.json").read_text())["failure"]
    assert failure["friction_held"] == ["body 2 (cells tagged 2): translation along (1, 0, 0)",
                                        "body 3 (cells tagged 3): translation along (1, 0, 0)"]


def test_every_method_stops_at_the_same_load_on_a_sliding_elastoplastic_body(tmp_path, capsys):
    """The same with yielding blocks (768 Gauss points that can yield): every method converges up
    to the same load factor, then names the cause. NNEQM2 used to retry every cutback with
    updated flow directions, creeping for up to 100 Levenberg–Marquardt iterations per attempt."""
    p = _pushed_blocks(tmp_path, plastic=True)
    reached, lines = {}, []
    for method in ("monolithic", "nneqm1", "nneqm2"):
        out = tmp_path / method
        t0 = time.perf_counter()
        code = main(["-q", "run", str(p), "--out", str(out), "--method", method])
        wall = time.perf_counter() - t0
        err = capsys.readouterr().err
        summary = json.loads((out / "summary.json").read_text())
        reached[method] = summary["failure"]["last_converged_load_factor"]
        lines.append(f"  {method}, elastoplastic: exit {code} after {wall:.1f} s, {sum(summary['iterations'])} "
              f"iterations in {len(summary['iterations'])} increments, reached load factor {reached[method]}")
        assert code == EXIT_DIVERGED and "friction alone holds" in err
        assert summary["plastic_gauss_points"][-1] > 0  # the blocks yield before they slide
    print("\n" + "\n".join(lines))  # after the last readouterr, which would swallow it
    assert reached["nneqm1"] == pytest.approx(reached["monolithic"], rel=1e-12)
    assert reached["nneqm2"] == pytest.approx(reached["monolithic"], rel=1e-12)



INCLINE = math.radians(30.0)
ALONG_THE_INCLINE = "body 1 (cells tagged 2): translation along (0.866, 0.5, 0)"


def _block_on_an_incline(mu_f: float = 0.2):
    """Two blocks stacked along y, turned by 30° about z: the upper one (cells tagged 2; body 1,
    its smallest node comes first once turned) rests on the lower, clamped one, held in z by its z
    faces and along the incline by friction alone (μ_f = 0.2 < tan 30°: its weight pulls it down
    the incline at any load)."""
    from dolfinx_nnqem.material import VonMises
    from dolfinx_nnqem.problem import BodyForce, Contact, ContactProblem, Dirichlet
    from dolfinx_nnqem.cases.geometries import BlockStackTags as T
    from dolfinx_nnqem.cases.geometries import build_block_stack

    mesh, cell_tags, facet_tags = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [0.5, 0.5], [(2, 1, 2), (2, 1, 2)])
    c, s = math.cos(INCLINE), math.sin(INCLINE)
    mesh.geometry.x[:, :2] = mesh.geometry.x[:, :2] @ np.array([[c, s], [-s, c]])  # (x, y) turned by +30°
    material = VonMises(E=1.0e9, nu=0.3)
    dirichlet = [Dirichlet(T.bottom(1))] + [Dirichlet(tag, 0.0, [2]) for tag in (T.zmin(2), T.zmax(2))]
    return ContactProblem(mesh, cell_tags, facet_tags, materials={1: material, 2: material}, dirichlet=dirichlet,
                          body_forces=[BodyForce((0.0, -1.0e6, 0.0), cell_tag=2)],
                          contact=Contact(T.top(1), T.bottom(2), mu_f=mu_f))


def test_the_motion_friction_holds_is_named_along_the_incline():
    """Issue 39, item 11: the free motion of a block on an incline is the translation along the
    incline's tangent (cos 30°, sin 30°, 0), which no contact normal sees; it was described by the
    free modes it is made of, "translation along (1, 0, 0) / translation along (0, 1, 0)"."""
    problem = _block_on_an_incline()
    print(f"\n  held by friction only: {problem.friction_held.motions}")
    assert problem.friction_held.motions == (ALONG_THE_INCLINE,)
    normals = problem.contact.gather(problem.contact.R)[:, 0, :]  # every pair's normal
    tangent = np.array([math.cos(INCLINE), math.sin(INCLINE), 0.0])
    assert np.abs(normals @ tangent).max() < 1e-12


@pytest.mark.parametrize("method", ["monolithic", "nneqm1", "nneqm2"])
def test_every_solver_names_the_block_that_slides_down_the_incline(method):
    """Issue 39, item 10: from Python, every method's ConvergenceError names the body and the
    motion only friction holds. NNEQM1's did not: its failed inner contact solve left the outer
    iterate's pair states (all sticking), and the cause is named only where pairs slip."""
    from dolfinx_nnqem.solvers import ConvergenceError, SolverOptions, make_solver, solve_load_steps

    problem = _block_on_an_incline()
    with pytest.raises(ConvergenceError) as error:
        solve_load_steps(problem, make_solver(method, problem, SolverOptions()), 2, max_cutbacks=1)
    message = str(error.value)
    print(f"\n  {method}: " + "\n  ".join(message.splitlines()[1:]))
    assert "likely cause: friction alone holds this rigid motion" in message and ALONG_THE_INCLINE in message
    assert error.value.failure["friction_held"] == [ALONG_THE_INCLINE]
