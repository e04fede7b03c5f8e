"""Every cell's shape is checked where the mesh enters the package (issue 39, item 3).

A second-order mesh whose mid-edge node was moved across its cell used to run to the end (and
change the contact force); with the node on a contact surface the refusal blamed the other body
("are the bodies overlapping?"). Now ``ContactProblem`` checks det J at the Gauss points of its
rule and at the vertices of every cell first (``problem/mesh_quality.py``): inverted cells are
refused by name (ValueError; exit 3 from the command line, on every rank), badly shaped ones
reported with their scaled Jacobian s and Jacobian ratio ρ.
"""

import logging
import re
import sys
from pathlib import Path

import basix
import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem import compat
from dolfinx_nnqem.cli import EXIT_BAD_INPUT, EXIT_OK, main
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure
from dolfinx_nnqem.problem.mesh_quality import POOR_RATIO, jacobians
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.cases.geometries import build_block_stack
from dolfinx_nnqem.problem.meshing import write_xdmf

from reliability_helpers import env, run_in_session

NUM_VERTICES = {"tetrahedron": 4, "hexahedron": 8}
DIVISIONS = [(4, 2, 4), (3, 2, 3)]  # body 1 (y in [0, 0.5]) under body 2 (y in [0.5, 1])


def blocks(cell_type: str, order: int = 2, comm=MPI.COMM_WORLD):
    return build_block_stack(comm, 1.0, 1.0, [0.5, 0.5], DIVISIONS, cell_type=cell_type, order=order)


def pressed_blocks(mesh, ct, ft) -> ContactProblem:
    material = VonMises(E=1.0e9, nu=0.3)
    return ContactProblem(mesh, ct, ft, materials={1: material, 2: material}, dirichlet=[Dirichlet(T.bottom(1))],
                          tractions=[Pressure(T.top(2), 1.0e6)], contact=Contact(T.top(1), T.bottom(2), mu_f=0.3))


def _node_near(mesh, ct, point, *, vertex: bool, inside: bool = True) -> int:
    """The node of body 2 nearest ``point``: a vertex or not, strictly inside the body or anywhere."""
    x = mesh.geometry.x
    dofmap = compat.geometry_dofmap(mesh)
    nodes = np.unique(dofmap[ct.indices[ct.values == 2]])
    vertices = np.unique(dofmap[:, :NUM_VERTICES[mesh.topology.cell_type.name]])
    nodes = np.intersect1d(nodes, vertices) if vertex else np.setdiff1d(nodes, vertices)
    if inside:
        lo, hi = np.array([0.0, 0.5, 0.0]), np.array([1.0, 1.0, 1.0])
        nodes = nodes[np.all((x[nodes] > lo + 1e-9) & (x[nodes] < hi - 1e-9), axis=1)]
    return int(nodes[np.argmin(np.linalg.norm(x[nodes] - point, axis=1))])


def _named_cells(message: str) -> tuple[int, list[int]]:
    """The count and the input indices a refusal names."""
    count = int(re.search(r"has (\d+) inverted cell\(s\)", message).group(1))
    return count, [int(i) for i in re.findall(r"input cell (\d+)", message)]


def _holding(mesh, node: int, with_neighbours: bool = False) -> np.ndarray:
    """The input indices of the cells whose geometry holds ``node`` (and of the cells that share a
    facet with them)."""
    cells = np.flatnonzero(np.any(compat.geometry_dofmap(mesh) == node, axis=1))
    if with_neighbours:
        tdim = mesh.topology.dim
        for a, b in ((tdim, tdim - 1), (tdim - 1, tdim)):
            mesh.topology.create_connectivity(a, b)
        c2f, f2c = mesh.topology.connectivity(tdim, tdim - 1), mesh.topology.connectivity(tdim - 1, tdim)
        facets = np.unique(np.concatenate([c2f.links(c) for c in cells]))
        cells = np.unique(np.concatenate([cells, *(f2c.links(f) for f in facets)]))
    return mesh.topology.original_cell_index[cells]


# -- the measures on reference cells ----------------------------------------------------------------
@pytest.mark.parametrize("cell", ["tetrahedron", "hexahedron"])
def test_a_mid_edge_node_moving_to_the_quarter_point(cell):
    """The thresholds' figures: a second-order reference cell whose first edge's mid node moves
    along the edge towards a vertex has ρ = 1/30 at 0.235 of the edge off the middle, and det J = 0
    at the vertex at the quarter point (0.25); past it the cell is inverted."""
    kind = getattr(basix.CellType, cell)
    element = basix.create_element(basix.ElementFamily.P, kind, 2, basix.LagrangeVariant.equispaced)
    vertices = basix.geometry(kind)
    a, b = basix.topology(kind)[1][0]
    gauss, _ = basix.make_quadrature(kind, 4)
    dphi = element.tabulate(1, np.concatenate([gauss, vertices]))[1:4, :, :, 0]
    measures = {}
    for shift in (0.0, 0.235, 0.26):
        X = element.points.copy()
        X[len(vertices)] = 0.5 * (vertices[a] + vertices[b]) + shift * (vertices[a] - vertices[b])
        det, s = jacobians(X[None], dphi)
        measures[shift] = (float(det.min() / det.max()), float(s.min()))  # one cell: (p, 1)
    print(f"\n  {cell}: (ρ, s) at shifts 0, 0.235, 0.26 of the edge: {measures}")
    assert measures[0.0] == pytest.approx((1.0, 1.0), abs=1e-12)
    assert measures[0.235][0] == pytest.approx(POOR_RATIO, rel=0.1) and measures[0.235][1] > 0.0
    assert measures[0.26][1] < 0.0 and measures[0.26][0] < 0.0


# -- refused: inverted cells ------------------------------------------------------------------------
@pytest.mark.parametrize("cell_type, order, point, shift", [
    ("tetrahedron", 2, (0.5, 0.75, 0.5), 0.3), ("hexahedron", 2, (0.5, 0.75, 0.5), 0.3),
    ("tetrahedron", 1, (1.0, 0.75, 0.5), -0.5), ("hexahedron", 1, (0.5, 0.75, 0.5), 0.5)])
def test_inverted_cells_are_refused_naming_them(cell_type, order, point, shift):
    """A node of body 2 moved along x across its cells (they are 1/3 wide): an interior mid-edge
    (tetrahedra) or mid-face (hexahedra) node of a second-order mesh, a vertex of a first-order
    one (for the unstructured tetrahedra, which have no interior vertex here, one on the face
    x = 1, moved 0.5 into the body). Every cell named holds the moved node. It used to be accepted
    (the second-order tetrahedra solved to the end with a changed contact force). A first-order
    tetrahedron cannot fold within itself: turned over, it lies on the same side of a face as its
    neighbour, and both are named."""
    mesh, ct, ft = blocks(cell_type, order)
    k = _node_near(mesh, ct, point, vertex=order == 1, inside=point[0] < 1.0)
    mesh.geometry.x[k, 0] += shift
    with pytest.raises(ValueError) as error:
        pressed_blocks(mesh, ct, ft)
    message = str(error.value)
    print(f"\n  {cell_type}, order {order}: {message}")
    count, named = _named_cells(message)
    suspects = _holding(mesh, k, with_neighbours=(cell_type, order) == ("tetrahedron", 1))
    assert "cell tag 2" in message and 1 <= len(named) == min(count, 5)
    assert set(named) <= set(suspects.tolist()) and count <= len(suspects)


def test_cells_numbered_against_the_reference_orientation_are_accepted():
    """DOLFINx's ``refine`` numbers half of the children against the reference orientation (det J < 0
    throughout: DOLFINx integrates with |det J|): not inverted. The check used to refuse them all,
    which stopped every adaptive run on tetrahedra."""
    import dolfinx

    from dolfinx_nnqem.problem.mesh_quality import check_cells

    coarse = dolfinx.mesh.create_box(MPI.COMM_WORLD, [np.zeros(3), np.ones(3)], [2, 2, 2],
                                     dolfinx.mesh.CellType.tetrahedron)
    coarse.topology.create_entities(1)
    refined = dolfinx.mesh.refine(coarse)
    mesh = refined[0] if isinstance(refined, tuple) else refined
    x, dofmap = mesh.geometry.x, compat.geometry_dofmap(mesh)
    v = x[dofmap[:, :4]]
    det = np.einsum("ij,ij->i", np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), v[:, 3] - v[:, 0])
    negative = MPI.COMM_WORLD.allreduce(int(np.count_nonzero(det < 0.0)), op=MPI.SUM)
    quality = check_cells(mesh)
    print(f"\n  refined box: {quality.num_cells} cells, {negative} numbered against the reference; "
          f"inverted {quality.num_inverted}, smallest s {quality.min_scaled_jacobian:.3g}")
    assert negative > 0 and quality.num_inverted == 0 and quality.min_scaled_jacobian > 0.3


@pytest.mark.parametrize("cell_type", ["tetrahedron", "hexahedron"])
def test_an_inverted_cell_on_a_contact_surface_is_named_not_the_other_body(cell_type):
    """A second-order node of body 2's contact surface (a mid-edge node of the tetrahedra, a
    facet's centre node of the hexahedra) moved 0.3 up into body 2 (its cells are 0.25 high): the
    refusal names body 2's inverted cells. The tetrahedra's refusal blamed the bodies ("are the
    bodies overlapping, or are the surfaces swapped?": body 1's nodes lay behind the folded
    facets); the hexahedra were accepted."""
    mesh, ct, ft = blocks(cell_type)
    k = _node_near(mesh, ct, [0.5, 0.5, 0.5], vertex=False, inside=False)
    assert abs(mesh.geometry.x[k, 1] - 0.5) < 1e-12  # on the contact surface
    mesh.geometry.x[k, 1] += 0.3
    with pytest.raises(ValueError) as error:
        pressed_blocks(mesh, ct, ft)
    message = str(error.value)
    print(f"\n  {cell_type}: {message}")
    count, named = _named_cells(message)
    assert "cell tag 2" in message and "overlapping" not in message
    assert 1 <= count and set(named) <= set(_holding(mesh, k).tolist())


# -- reported: badly shaped cells --------------------------------------------------------------------
def test_badly_shaped_cells_are_reported(caplog):
    """An interior mid-edge node moved 0.24 of its edge towards a vertex (ρ = 0.02 < 1/30, s > 0):
    the problem is built, with a warning naming the cells sharing that edge and their measures."""
    mesh, ct, ft = blocks("tetrahedron")
    k = _node_near(mesh, ct, [0.5, 0.75, 0.5], vertex=False)
    dofmap = compat.geometry_dofmap(mesh)
    cell = int(np.flatnonzero(np.any(dofmap == k, axis=1))[0])
    local = int(np.flatnonzero(dofmap[cell] == k)[0])
    a, b = basix.topology(basix.CellType.tetrahedron)[1][local - 4]
    x = mesh.geometry.x
    x[k] += 0.24 * (x[dofmap[cell, a]] - x[dofmap[cell, b]])
    with caplog.at_level(logging.WARNING, logger="dolfinx_nnqem"):
        problem = pressed_blocks(mesh, ct, ft)
    warnings = [r.getMessage() for r in caplog.records if "badly shaped" in r.getMessage()]
    quality = problem.mesh_quality
    print(f"\n  {quality.num_poor} poor cells, smallest ρ {quality.min_ratio:.3g}, s {quality.min_scaled_jacobian:.3g}; "
          f"{warnings}")
    assert len(warnings) == 1 and quality.num_poor >= 2 and quality.num_inverted == 0
    assert quality.min_ratio < POOR_RATIO and "cell tag 2" in warnings[0] and "ρ = 0.02" in warnings[0]


def test_the_package_meshes_pass_silently(caplog):
    """The meshes of the package's own builders: no warning (second-order tetrahedra here)."""
    mesh, ct, ft = blocks("tetrahedron")
    with caplog.at_level(logging.WARNING, logger="dolfinx_nnqem"):
        problem = pressed_blocks(mesh, ct, ft)
    quality = problem.mesh_quality
    print(f"\n  {quality.num_cells} cells, {quality.num_points} points each: smallest s "
          f"{quality.min_scaled_jacobian:.3g}, smallest ρ {quality.min_ratio:.3g}")
    assert quality.num_poor == 0 and quality.num_cells == 360 and not caplog.records


# -- the command line, on 1 and 2 ranks ---------------------------------------------------------------
PROBLEM = """
[mesh]
file = "blocks.xdmf"
[materials.1]
E = 1.0e9
nu = 0.3
[materials.2]
E = 1.0e9
nu = 0.3
[[contact]]
surface1 = 201
surface2 = 102
mu_f = 0.3
[[dirichlet]]
tag = 101
[[pressure]]
tag = 202
p = 1.0e6
[solver]
increments = 1
"""


def _problem_file(folder: Path, distorted: bool) -> Path:
    mesh, ct, ft = blocks("tetrahedron", comm=MPI.COMM_SELF)
    if distorted:
        mesh.geometry.x[_node_near(mesh, ct, [0.5, 0.75, 0.5], vertex=False), 0] += 0.3
    write_xdmf(folder / "blocks.xdmf", mesh, ct, ft)
    path = folder / "blocks.toml"
    path.write_text(PROBLEM)
    return path


def test_the_command_line_refuses_an_inverted_cell_with_exit_3(tmp_path, capsys):
    good = main(["-q", "run", str(_problem_file(tmp_path, False)), "--check"])
    capsys.readouterr()
    code = main(["-q", "run", str(_problem_file(tmp_path, True)), "--check"])
    err = capsys.readouterr().err.strip()
    print(f"\n  undistorted: exit {good}; distorted: exit {code}: {err}")
    assert good == EXIT_OK and code == EXIT_BAD_INPUT
    assert "bad input: the mesh has" in err and "inverted cell(s)" in err and "Traceback" not in err


@pytest.mark.mpi
def test_two_ranks_refuse_an_inverted_cell_alike(tmp_path, capsys):
    """Each rank checks its own cells; the cells are gathered, so both ranks raise the same error
    whichever owns them: one message, exit 3, naming the cells as on one rank."""
    path = _problem_file(tmp_path, True)
    serial = main(["-q", "run", str(path), "--check"])
    serial_line = capsys.readouterr().err.strip()
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, "-m", "dolfinx_nnqem", "-q", "run", str(path), "--check"]
    run = run_in_session(cmd, 120, env=env())
    lines = [line for line in run.stderr.splitlines() if line.startswith("dolfinx-nnqem")]
    print(f"\n  2 ranks: exit {run.returncode}: {lines}")
    assert serial == EXIT_BAD_INPUT
    assert run.returncode == EXIT_BAD_INPUT and len(lines) == 1
    assert "inverted cell(s)" in lines[0] and lines[0] == serial_line
