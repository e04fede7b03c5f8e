"""A quarter hemisphere resting on a quarter block, each meshed on its own (Hertz contact on
non-matching meshes): the gmsh geometry, its tetrahedra and its tags (:class:`SphereOnBlockTags`).

The exception to the geometries' hexahedra: a sphere is meshed with unstructured tetrahedra (and
so is its block, a DOLFINx mesh holding one cell type), for the non-matching (mortar) interfaces.
The problem built on it is :mod:`dolfinx_nnqem.cases.sphere_on_block`.
"""

from __future__ import annotations

import os

import gmsh
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem import compat
from dolfinx_nnqem.problem.gmsh_tools import add_group, fragment_boxes, surfaces_in_box, surfaces_of
from dolfinx_nnqem.problem.meshing import MeshAndTags, mesh_from_gmsh

__all__ = ["SphereOnBlockTags", "build_sphere_on_block"]


class SphereOnBlockTags:
    """Tags of :func:`build_sphere_on_block` (quarter model: x ≥ 0, z ≥ 0; the y axis is the sphere's).

    Cells: ``BLOCK`` = 1 (body 1, below y = 0), ``SPHERE`` = 2 (body 2, above).
    Facets of the block: ``BOTTOM`` = 11 (y = −depth), ``CONTACT1`` = 21 (its top, y = 0),
    ``BLOCK_XMIN`` = 31 (x = 0), ``BLOCK_XMAX`` = 32, ``BLOCK_ZMIN`` = 33 (z = 0),
    ``BLOCK_ZMAX`` = 34. Facets of the sphere: ``LOAD`` = 13 (the flat equatorial cut y = R),
    ``CONTACT2`` = 22 (the spherical cap r ≤ ``contact_radius`` around the pole), ``SPHERE_XMIN``
    = 41 (x = 0), ``SPHERE_ZMIN`` = 43 (z = 0), ``SPHERE_FREE`` = 45 (the rest of the curved
    surface).
    """

    BLOCK = 1
    SPHERE = 2
    BOTTOM = 11
    LOAD = 13
    CONTACT1 = 21
    CONTACT2 = 22
    BLOCK_XMIN = 31
    BLOCK_XMAX = 32
    BLOCK_ZMIN = 33
    BLOCK_ZMAX = 34
    SPHERE_XMIN = 41
    SPHERE_ZMIN = 43
    SPHERE_FREE = 45


def build_sphere_on_block(
    comm: MPI.Comm = MPI.COMM_WORLD,
    R: float = 20.0,
    block: float = 10.0,
    h_contact: float = 0.25,
    *,
    depth: float | None = None,
    fine_radius: float = 1.5,
    growth: float = 0.3,
    h_max: float | None = None,
    contact_radius: float = 2.0,
    msh_file: str | os.PathLike | None = None,
    order: int = 1,
) -> MeshAndTags:
    """A quarter of an elastic hemisphere resting on a quarter block, each meshed on its own.

    The block spans x, z in [0, ``block``] and y in [−``depth``, 0]; the hemisphere, of radius
    ``R`` and centre (0, R, 0), spans y in [0, R] (its flat equatorial cut y = R is the loaded
    face) and touches the block's top at one point, its pole x = y = z = 0, with gap zero there.
    The planes x = 0 and z = 0 are symmetry planes of both bodies. Both bodies are unstructured
    tetrahedra meshed apart (no shared nodes, non-matching interface meshes). The cap of the
    sphere within ``contact_radius`` of its axis is a volume of its own, so that its curved
    surface can be the contact surface ``CONTACT2`` and the rest of the sphere ``SPHERE_FREE``.

    The element size is set by a gmsh field of the distance d from the contact point:
    ``h_contact`` for d ≤ ``fine_radius``, then growing by ``growth`` per unit length up to
    ``h_max`` (a fifth of the smaller body size by default) — the same field in both bodies, so
    their interface meshes are equally fine but do not match.

    Parameters
    ----------
    comm
        Communicator of the mesh; the gmsh model is built on its rank 0.
    R
        The sphere's radius.
    block, depth
        The block's half width (x and z) and its height (default ``block``).
    h_contact, fine_radius, growth, h_max
        The size field (see above).
    contact_radius
        Radius (about the y axis) of the spherical cap tagged as contact surface; it should
        exceed the expected contact radius, and be below ``block`` and ``R``.
    msh_file
        If given, the gmsh model is also written to this ``.msh`` file (by rank 0).
    order
        2: 10-node tetrahedra whose new nodes lie on the geometry (the sphere's facets curved).

    Returns
    -------
    MeshAndTags
        The mesh and its tags, numbered as in :class:`SphereOnBlockTags`.
    """
    depth = block if depth is None else float(depth)
    h_max = 0.2 * min(R, block, depth) if h_max is None else float(h_max)
    for label, value in (("R", R), ("block", block), ("depth", depth), ("h_contact", h_contact),
                         ("fine_radius", fine_radius), ("growth", growth), ("h_max", h_max)):
        if not value > 0:
            raise ValueError(f"{label} must be positive, got {value!r}")
    if not 0 < contact_radius < min(R, block):
        raise ValueError(f"contact_radius must lie in (0, min(R, block)) = (0, {min(R, block)!r}), "
                         f"got {contact_radius!r}")
    return mesh_from_gmsh(
        comm, "sphere_on_block",
        lambda: _build_sphere_on_block_model(R, block, depth, h_contact, fine_radius, growth, h_max,
                                             contact_radius), msh_file, order)


def _quarter_hemisphere(R: float, contact_radius: float) -> tuple[int, int]:
    """The quarter hemisphere (x, z ≥ 0, 0 ≤ y ≤ R) split at the height of the contact cap's rim.

    Returns the (cap, rest) volume tags. The split plane y = R − sqrt(R² − r_c²) makes the cap a
    volume of its own (conforming with the rest: one body), so that its curved surface is a
    surface of its own.
    """
    occ = gmsh.model.occ
    sphere = occ.addSphere(0.0, R, 0.0, R)
    quarter, _ = occ.intersect([(3, sphere)], [(3, occ.addBox(0.0, 0.0, 0.0, R, R, R))])
    y_cap = R - float(np.sqrt(R * R - contact_radius * contact_radius))
    pieces, _ = occ.fragment(quarter, [(3, occ.addBox(0.0, 0.0, 0.0, R, y_cap, R))])
    occ.synchronize()
    cap = rest = None
    for dim, v in pieces:
        if dim != 3:
            continue
        centre = np.array(occ.getCenterOfMass(3, v))
        if np.linalg.norm(centre - [0.0, R, 0.0]) > R:  # the cutting box's part outside the sphere
            occ.remove([(3, v)], recursive=True)
        elif centre[1] < y_cap:
            cap = v
        else:
            rest = v
    occ.synchronize()
    if cap is None or rest is None:
        raise RuntimeError("splitting the quarter hemisphere at its contact cap failed")
    return cap, rest


def _classify_sphere_surfaces(R: float, cap: int, rest: int) -> dict[int, list[int]]:
    """The hemisphere's outer surfaces by tag of :class:`SphereOnBlockTags` (by centres of mass).

    Bounding boxes of curved OCC surfaces are loose, so each surface is placed by its centre of
    mass: on a symmetry plane, on the equatorial cut, or curved (inside the sphere) below or
    above the cap's rim. The internal face between cap and rest is no boundary of the body.
    """
    T = SphereOnBlockTags
    tol = 1e-6 * R
    boundary = gmsh.model.getBoundary([(3, cap), (3, rest)], combined=True, oriented=False)
    cap_surfaces = surfaces_of([cap])
    groups: dict[int, list[int]] = {T.SPHERE_XMIN: [], T.SPHERE_ZMIN: [], T.LOAD: [], T.CONTACT2: [],
                                    T.SPHERE_FREE: []}
    for s in sorted({abs(tag) for _, tag in boundary}):
        c = gmsh.model.occ.getCenterOfMass(2, s)
        if abs(c[0]) < tol:
            groups[T.SPHERE_XMIN].append(s)
        elif abs(c[2]) < tol:
            groups[T.SPHERE_ZMIN].append(s)
        elif abs(c[1] - R) < tol:
            groups[T.LOAD].append(s)
        elif s in cap_surfaces:
            groups[T.CONTACT2].append(s)
        else:
            groups[T.SPHERE_FREE].append(s)
    for tag, surfaces in groups.items():
        if len(surfaces) != (2 if tag in (T.SPHERE_XMIN, T.SPHERE_ZMIN) else 1):
            raise RuntimeError(f"sphere surfaces of tag {tag}: found {surfaces}")
    return groups


def _size_field(h_contact: float, fine_radius: float, growth: float, h_max: float) -> None:
    """Element size h(d) = min(h_max, h_contact + growth · max(d − fine_radius, 0)), d = |x|.

    A MathEval background field: the size depends on the distance from the contact point only,
    so that both bodies are refined alike towards it; sizes from points, curvature and
    boundaries are switched off so that the field alone decides.
    """
    field = gmsh.model.mesh.field
    f = field.add("MathEval")
    field.setString(f, "F", f"Min({h_max!r}, {h_contact!r} + {growth!r} * Max(0, Sqrt(x*x + y*y + z*z)"
                            f" - {fine_radius!r}))")
    field.setAsBackgroundMesh(f)
    for option in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
        gmsh.option.setNumber(option, 0)


def _build_sphere_on_block_model(R: float, block: float, depth: float, h_contact: float, fine_radius: float,
                                 growth: float, h_max: float, contact_radius: float) -> None:
    """The gmsh model of :func:`build_sphere_on_block` (current model, rank 0): geometry, groups, mesh."""
    T = SphereOnBlockTags
    # the block and the sphere are separate OCC solids, never fragmented together: they keep
    # their own copies of the contact point, hence no shared node
    body1 = fragment_boxes([(0.0, -depth, 0.0, block, depth, block)])
    cap, rest = _quarter_hemisphere(R, contact_radius)
    size = float(max(R, block, depth))
    add_group(3, body1, T.BLOCK, "block")
    add_group(3, [cap, rest], T.SPHERE, "sphere")
    for lower, upper, tag, label in (
        ((0, -depth, 0), (block, -depth, block), T.BOTTOM, "bottom"),
        ((0, 0, 0), (block, 0, block), T.CONTACT1, "block_top"),
        ((0, -depth, 0), (0, 0, block), T.BLOCK_XMIN, "block_xmin"),
        ((block, -depth, 0), (block, 0, block), T.BLOCK_XMAX, "block_xmax"),
        ((0, -depth, 0), (block, 0, 0), T.BLOCK_ZMIN, "block_zmin"),
        ((0, -depth, block), (block, 0, block), T.BLOCK_ZMAX, "block_zmax"),
    ):
        add_group(2, surfaces_in_box(lower, upper, body1, size), tag, label)
    names = {T.SPHERE_XMIN: "sphere_xmin", T.SPHERE_ZMIN: "sphere_zmin", T.LOAD: "sphere_equator",
             T.CONTACT2: "sphere_cap", T.SPHERE_FREE: "sphere_free"}
    for tag, surfaces in _classify_sphere_surfaces(R, cap, rest).items():
        add_group(2, surfaces, tag, names[tag])
    _size_field(h_contact, fine_radius, growth, h_max)
    gmsh.model.mesh.generate(3)
    compat.optimize_tetrahedra()  # better-shaped tetrahedra than the default pass leaves
