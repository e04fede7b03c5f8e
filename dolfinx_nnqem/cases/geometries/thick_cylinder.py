"""A quarter of a thick-walled tube under internal pressure, one hexahedron layer thick (plane
strain, elastoplastic verification): the gmsh geometry, its mesh and its tags
(:class:`ThickCylinderTags`)."""

from __future__ import annotations

import os
from typing import NamedTuple

import gmsh
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.problem.gmsh_tools import EPS, add_group, surfaces_of
from dolfinx_nnqem.problem.meshing import MeshAndTags, mesh_from_gmsh

__all__ = ["ThickCylinderTags", "build_thick_cylinder"]


class ThickCylinderTags:
    """Tags of :func:`build_thick_cylinder` (quarter of a thick-walled tube, one layer in z).

    Cells: ``BODY`` = 1.
    Facets: ``INNER`` = 1 (r = a), ``OUTER`` = 2 (r = b), ``SYMMETRY_X`` = 3 (plane x = 0),
    ``SYMMETRY_Y`` = 4 (plane y = 0), ``FACES_Z`` = 5 (both faces z = 0 and z = t).
    """

    BODY = 1
    INNER = 1
    OUTER = 2
    SYMMETRY_X = 3
    SYMMETRY_Y = 4
    FACES_Z = 5


def build_thick_cylinder(
    comm: MPI.Comm = MPI.COMM_WORLD,
    a: float = 1.0,
    b: float = 2.0,
    t: float = 0.1,
    n_radial: int = 8,
    n_circumferential: int = 12,
    *,
    radial_progression: float = 1.0,
    msh_file: str | os.PathLike | None = None,
) -> MeshAndTags:
    """A quarter of a thick-walled tube, a <= r <= b in the x-y plane, one hexahedron layer thick.

    The quarter annulus (x >= 0, y >= 0) is meshed with ``n_radial x n_circumferential``
    quadrilaterals and extruded by ``t`` in z with a single element layer; plane strain is then
    imposed by u_z = 0 on both z faces (tag 5).

    Parameters
    ----------
    comm
        Communicator of the mesh; the gmsh model is built on its rank 0.
    a, b
        Inner and outer radius.
    t
        Thickness (z) of the single element layer.
    n_radial, n_circumferential
        Element counts across the wall and along the quarter circle.
    radial_progression
        Ratio of consecutive radial element sizes from r = a outwards (1: uniform; > 1 refines
        towards the inner surface, where the plastic zone starts).
    msh_file
        If given, the gmsh model is also written to this ``.msh`` file (by rank 0).

    Returns
    -------
    MeshAndTags
        The mesh and its tags, numbered as in :class:`ThickCylinderTags`.
    """
    if not 0 < a < b:
        raise ValueError(f"need 0 < a < b, got a = {a!r}, b = {b!r}")
    if not t > 0 or not radial_progression > 0:
        raise ValueError(f"t and radial_progression must be positive, got {t!r}, {radial_progression!r}")
    for label, n in (("n_radial", n_radial), ("n_circumferential", n_circumferential)):
        if int(n) != n or n < 1:
            raise ValueError(f"{label} must be a positive integer, got {n!r}")
    return mesh_from_gmsh(
        comm, "thick_cylinder",
        lambda: _build_thick_cylinder_model(a, b, t, n_radial, n_circumferential, radial_progression), msh_file)


class _QuarterTube(NamedTuple):
    """The gmsh entities of the extruded quarter annulus that its meshing and tagging use."""

    volumes: list[int]
    base: int
    """The quarter annulus at z = 0, the extrusion's source (and the transfinite surface)."""
    radial_lines: tuple[int, int]
    """The base's edges on y = 0 and on x = 0, both from r = a to r = b."""
    arcs: tuple[int, int]
    """The base's edges r = a and r = b."""
    corners: tuple[int, int, int, int]
    """The base's corner points (a, 0), (b, 0), (0, b), (0, a)."""


def _build_thick_cylinder_model(a: float, b: float, t: float, n_radial: int, n_circumferential: int,
                                radial_progression: float) -> None:
    """The gmsh model of :func:`build_thick_cylinder` (current model, rank 0): geometry, mesh sizes,
    groups, mesh."""
    tube = _quarter_tube(a, b, t)
    for line in tube.radial_lines:
        gmsh.model.mesh.setTransfiniteCurve(line, n_radial + 1, "Progression", radial_progression)
    for arc in tube.arcs:
        gmsh.model.mesh.setTransfiniteCurve(arc, n_circumferential + 1)
    gmsh.model.mesh.setTransfiniteSurface(tube.base, cornerTags=list(tube.corners))
    gmsh.model.mesh.setRecombine(2, tube.base)

    T = ThickCylinderTags
    names = {
        T.INNER: "inner", T.OUTER: "outer", T.SYMMETRY_X: "symmetry_x",
        T.SYMMETRY_Y: "symmetry_y", T.FACES_Z: "faces_z",
    }  # fmt: skip
    for tag, surfaces in _classify_tube_surfaces(tube.volumes, a, b).items():
        if not surfaces:
            raise RuntimeError(f"no surface found for tag {tag} ({names[tag]})")
        add_group(2, surfaces, tag, names[tag])
    add_group(3, tube.volumes, T.BODY, "tube")
    gmsh.model.mesh.generate(3)


def _quarter_tube(a: float, b: float, t: float) -> _QuarterTube:
    """The quarter annulus a ≤ r ≤ b (x, y ≥ 0) at z = 0, extruded by ``t`` in z with one
    recombined element layer (hexahedra); the OCC model synchronised."""
    occ = gmsh.model.occ
    centre = occ.addPoint(0, 0, 0)
    p_ax, p_bx = occ.addPoint(a, 0, 0), occ.addPoint(b, 0, 0)
    p_ay, p_by = occ.addPoint(0, a, 0), occ.addPoint(0, b, 0)
    # both radial lines run from r = a to r = b, so one progression grades them alike
    line_y0 = occ.addLine(p_ax, p_bx)
    line_x0 = occ.addLine(p_ay, p_by)
    arc_b = occ.addCircleArc(p_bx, centre, p_by)
    arc_a = occ.addCircleArc(p_ay, centre, p_ax)
    loop = occ.addCurveLoop([line_y0, arc_b, line_x0, arc_a])
    base = occ.addPlaneSurface([loop])
    occ.remove([(0, centre)])
    out = occ.extrude([(2, base)], 0, 0, t, numElements=[1], recombine=True)
    occ.synchronize()
    volumes = [tag for dim, tag in out if dim == 3]
    return _QuarterTube(volumes, base, (line_y0, line_x0), (arc_a, arc_b), (p_ax, p_bx, p_by, p_ay))


def _classify_tube_surfaces(volumes: list[int], a: float, b: float) -> dict[int, list[int]]:
    """The tube's boundary surfaces by tag of :class:`ThickCylinderTags` (by bounding boxes), in
    the order INNER, OUTER, SYMMETRY_X, SYMMETRY_Y, FACES_Z; RuntimeError for a surface that is
    none of them."""
    T = ThickCylinderTags
    groups: dict[int, list[int]] = {tag: [] for tag in (T.INNER, T.OUTER, T.SYMMETRY_X, T.SYMMETRY_Y, T.FACES_Z)}
    tol = EPS * 10 * b
    for s in sorted(surfaces_of(volumes)):
        lo = np.array(gmsh.model.getBoundingBox(2, s)[:3])
        hi = np.array(gmsh.model.getBoundingBox(2, s)[3:])
        if hi[2] - lo[2] < tol:
            groups[T.FACES_Z].append(s)
        elif hi[0] < tol:
            groups[T.SYMMETRY_X].append(s)
        elif hi[1] < tol:
            groups[T.SYMMETRY_Y].append(s)
        elif abs(hi[0] - a) < 1e-3 * a:  # the curved faces, by their largest x: r = a or r = b
            groups[T.INNER].append(s)
        elif abs(hi[0] - b) < 1e-3 * b:
            groups[T.OUTER].append(s)
        else:
            raise RuntimeError(f"cannot classify surface {s} with bounding box {lo}-{hi}")
    return groups
