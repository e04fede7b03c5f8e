"""gmsh model builders returning distributed DOLFINx meshes with cell and facet tags.

Every builder constructs its gmsh model on rank 0 only, optionally writes it to a ``.msh``
file, and distributes it with :func:`dolfinx_nnqem.compat.model_to_mesh`. All meshes are
structured 8-node hexahedra (transfinite curves, surfaces and volumes, recombined), because the
node-to-node contact pairs need coincident (or facing) nodes and the seed uses trilinear bricks.

Bodies that may come into contact are meshed WITHOUT shared nodes: their sub-boxes are
fragmented body by body, never together, so gmsh keeps two copies of the interface (two
surfaces, two sets of nodes) and DOLFINx sees two disconnected parts.

The tag numbers of each model are the class attributes of :class:`TwoBeamsTags`,
:class:`StackedBlocksTags`, :class:`ThickCylinderTags` and :class:`SphereOnBlockTags`.
:func:`build_sphere_on_block` is the exception to the hexahedra: a sphere is meshed with
unstructured tetrahedra (and so is its block, a DOLFINx mesh holding one cell type), for the
non-matching (mortar) interfaces.

Second order: the builders that take ``order = 2`` raise the mesh with gmsh to complete
second-order elements (27-node hexahedra, 10-node tetrahedra) whose new nodes lie on the
geometry (a sphere's facets are curved); ``ContactProblem`` then takes degree 2 by default.
:func:`read_msh` reads a user's ``.msh`` of first or second order; other gmsh volume elements
(20-node hexahedra, third-order ones) are refused with the reason (:func:`unsupported_gmsh_cells`).
"""

from __future__ import annotations

import inspect
import os
from collections.abc import Callable, Sequence
from typing import NamedTuple

from dolfinx_nnqem import compat  # noqa: I001  (first: loads MPI/PETSc for the PyPI wheel)
from dolfinx_nnqem import chatter

import dolfinx
import gmsh
import numpy as np
from mpi4py import MPI

__all__ = [
    "BlockStackTags",
    "MeshAndTags",
    "SphereOnBlockTags",
    "StackedBlocksTags",
    "ThickCylinderTags",
    "TwoBeamsTags",
    "build_block_stack",
    "build_graded_block",
    "build_graded_contact_blocks",
    "build_sphere_on_block",
    "build_stacked_blocks",
    "build_thick_cylinder",
    "build_two_beams",
    "read_msh",
    "unsupported_gmsh_cells",
    "write_xdmf",
]


class MeshAndTags(NamedTuple):
    """A distributed mesh with its cell and facet tags (as returned by every builder)."""

    mesh: dolfinx.mesh.Mesh
    cell_tags: dolfinx.mesh.MeshTags
    facet_tags: dolfinx.mesh.MeshTags


class TwoBeamsTags:
    """Tags of :func:`build_two_beams` (the seed benchmark, ``benchmark-two-beams.md``).

    Cells: ``BODY1`` = 1 (beam 1, lower), ``BODY2`` = 2 (beam 2, upper).
    Facets: ``CLAMP1`` = 11 (beam 1, x = 0), ``CLAMP2`` = 12 (beam 2, x = 3.6),
    ``LOAD`` = 13 (beam 2's top face, y = 0.8), ``CONTACT1`` = 21 (beam 1, y = 0.4,
    x in [1.6, 2.0]), ``CONTACT2`` = 22 (beam 2, y = 0.4, x in [1.6, 2.0]).
    """

    BODY1 = 1
    BODY2 = 2
    CLAMP1 = 11
    CLAMP2 = 12
    LOAD = 13
    CONTACT1 = 21
    CONTACT2 = 22


class StackedBlocksTags:
    """Tags of :func:`build_stacked_blocks` (body 1 below, body 2 on top).

    Cells: ``BODY1`` = 1, ``BODY2`` = 2.
    Facets: ``BOTTOM`` = 11 (body 1's bottom), ``TOP`` = 13 (body 2's top),
    ``CONTACT1`` = 21 (body 1's top), ``CONTACT2`` = 22 (body 2's bottom);
    lateral faces of body 1: ``BODY1_XMIN`` = 31, ``BODY1_XMAX`` = 32, ``BODY1_ZMIN`` = 33,
    ``BODY1_ZMAX`` = 34; of body 2: ``BODY2_XMIN`` = 41, ``BODY2_XMAX`` = 42,
    ``BODY2_ZMIN`` = 43, ``BODY2_ZMAX`` = 44.
    """

    BODY1 = 1
    BODY2 = 2
    BOTTOM = 11
    TOP = 13
    CONTACT1 = 21
    CONTACT2 = 22
    BODY1_XMIN = 31
    BODY1_XMAX = 32
    BODY1_ZMIN = 33
    BODY1_ZMAX = 34
    BODY2_XMIN = 41
    BODY2_XMAX = 42
    BODY2_ZMIN = 43
    BODY2_ZMAX = 44


class BlockStackTags:
    """Tags of :func:`build_block_stack` (blocks numbered k = 1, 2, ... from the bottom up).

    Cells: block k has tag k. Facets of block k: ``bottom(k)`` = 100 + k (y min),
    ``top(k)`` = 200 + k (y max), ``xmin(k)`` = 300 + k, ``xmax(k)`` = 400 + k,
    ``zmin(k)`` = 500 + k, ``zmax(k)`` = 600 + k.
    """

    @staticmethod
    def body(k: int) -> int:
        """The cell tag of block k: k."""
        return k

    @staticmethod
    def bottom(k: int) -> int:
        """The facet tag of block k's bottom face (y min): 100 + k."""
        return 100 + k

    @staticmethod
    def top(k: int) -> int:
        """The facet tag of block k's top face (y max): 200 + k."""
        return 200 + k

    @staticmethod
    def xmin(k: int) -> int:
        """The facet tag of block k's x-min face: 300 + k."""
        return 300 + k

    @staticmethod
    def xmax(k: int) -> int:
        """The facet tag of block k's x-max face: 400 + k."""
        return 400 + k

    @staticmethod
    def zmin(k: int) -> int:
        """The facet tag of block k's z-min face: 500 + k."""
        return 500 + k

    @staticmethod
    def zmax(k: int) -> int:
        """The facet tag of block k's z-max face: 600 + k."""
        return 600 + k


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


# --------------------------------------------------------------------------------------------
# gmsh session handling and distribution
# --------------------------------------------------------------------------------------------

_EPS = 1e-7
"""Relative tolerance for locating gmsh entities by their bounding boxes (OCC boxes are padded
by its own tolerance of ~1e-7, so searches use this times the model size)."""


def _initialize_gmsh() -> bool:
    """Initialise gmsh unless it already is; return whether this call initialised it."""
    if gmsh.isInitialized():
        return False
    # interruptible=False: gmsh must not install a SIGINT handler (that fails off the main
    # thread, e.g. under pytest-xdist); older gmsh versions lack the keyword.
    if "interruptible" in inspect.signature(gmsh.initialize).parameters:
        gmsh.initialize(interruptible=False)
    else:
        gmsh.initialize()
    restore_signal_handlers()
    return True


def restore_signal_handlers() -> None:
    """Give SIGTERM and SIGINT back to the Python handlers gmsh replaced.

    ``gmsh.initialize`` (even with ``interruptible=False``) installs its own C-level SIGTERM
    handler behind Python's back (``signal.getsignal`` still names the Python one): a SIGTERM
    then killed ``dolfinx-nnqem two-beams`` with no message and left its summary "running"
    (issue 31). Setting each Python handler again re-installs it at the C level.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return  # signal handlers belong to the main thread
    for signum in (signal.SIGTERM, signal.SIGINT):
        handler = signal.getsignal(signum)
        if handler is not None:  # None: not installed from Python; nothing to give back
            signal.signal(signum, handler)


GMSH_CELLS = {4: "4-node tetrahedra", 11: "10-node tetrahedra", 5: "8-node hexahedra", 12: "27-node hexahedra"}
"""The gmsh volume elements a mesh may have (by gmsh element type): first- and second-order Lagrange
tetrahedra and hexahedra, the cells DOLFINx reads."""


def unsupported_gmsh_cells(types: Sequence[int]) -> str | None:
    """Why gmsh volume elements of the element ``types`` cannot make the mesh, or None.

    The 20-node (serendipity) hexahedron is not a DOLFINx element: DOLFINx's hexahedra are
    Lagrange (tensor-product) elements of 8 or 27 nodes, and a serendipity geometry has no face
    or cell nodes to give the 27-node one. gmsh meshes of second order are complete when
    ``Mesh.SecondOrderIncomplete = 0`` (the default).
    """
    for t in types:
        if int(t) == 17:
            return ("20-node (serendipity) hexahedra are not a DOLFINx element (its hexahedra are Lagrange "
                    "elements of 8 or 27 nodes): mesh with 27-node hexahedra (gmsh: Mesh.ElementOrder = 2 "
                    "with Mesh.SecondOrderIncomplete = 0) or with 8-node ones")
        if int(t) not in GMSH_CELLS:
            name = gmsh.model.mesh.getElementProperties(int(t))[0] if gmsh.isInitialized() else f"type {t}"
            return (f"gmsh elements {name!r} are not supported; the volumes must be "
                    f"{', '.join(GMSH_CELLS.values())}")
    return None


def _check_order(order: int) -> None:
    """Refuse a mesh order other than 1 and 2 (a ValueError naming it)."""
    if order not in (1, 2):
        raise ValueError(f"order = {order!r}: a mesh of first (1) or second (2) order")


def _second_order() -> dict[str, float]:
    """Raise the current model's mesh to second order: complete elements (10-node tetrahedra, 27-node
    hexahedra), the new nodes placed on the geometry (curved surfaces stay curved); node
    coordinates rounded again, so that straight edges keep exact midpoints. Returns the option it
    changed with its previous value (the caller's gmsh session gets it back)."""
    previous = {"Mesh.SecondOrderIncomplete": gmsh.option.getNumber("Mesh.SecondOrderIncomplete")}
    gmsh.option.setNumber("Mesh.SecondOrderIncomplete", 0)
    gmsh.model.mesh.setOrder(2)
    _round_node_coordinates()
    return previous


def read_msh(file: str | os.PathLike, comm: MPI.Comm = MPI.COMM_WORLD) -> MeshAndTags:
    """A gmsh ``.msh`` file (first or second order: 4- or 10-node tetrahedra, 8- or 27-node
    hexahedra), read on rank 0 and distributed, with its physical groups as cell and facet tags.

    A second-order mesh keeps its curved geometry: ``ContactProblem`` takes degree 2 on it by
    default. Other elements (20-node hexahedra among them) are refused with the reason, on every
    rank, before the collective distribution.
    """
    def check() -> None:
        gmsh.merge(os.fspath(file))
        problem = unsupported_gmsh_cells(gmsh.model.mesh.getElementTypes(3))
        if problem is not None:
            raise ValueError(f"{file}: {problem}")
        if len(gmsh.model.mesh.getElementTypes(3)) > 1:
            raise ValueError(f"{file}: the volumes mix cell types; use one (all tetrahedra or all hexahedra)")

    return _mesh_from_gmsh(comm, "read_msh", check, None, reading=True)


def write_xdmf(file: str | os.PathLike, mesh: dolfinx.mesh.Mesh, cell_tags: dolfinx.mesh.MeshTags,
               facet_tags: dolfinx.mesh.MeshTags) -> None:
    """Write a mesh and its tags to ``file`` (``.xdmf`` + ``.h5``, collective) as a problem file
    reads them by default: grids ``mesh``, ``cell_tags`` and ``facet_tags`` (the three objects
    are given these names).

    DOLFINx reads this format itself; a ``.msh`` needs gmsh's library, whose loading alone costs
    a small run about 18 ms (``docs/performance.md``).
    """
    from dolfinx.io import XDMFFile

    mesh.name = "mesh"
    cell_tags.name = "cell_tags"
    facet_tags.name = "facet_tags"
    with XDMFFile(mesh.comm, os.fspath(file), "w") as xdmf:
        xdmf.write_mesh(mesh)
        xdmf.write_meshtags(cell_tags, mesh.geometry)
        xdmf.write_meshtags(facet_tags, mesh.geometry)


def _mesh_from_gmsh(
    comm: MPI.Comm,
    name: str,
    build: Callable[[], None],
    msh_file: str | os.PathLike | None,
    order: int = 1,
    reading: bool = False,
) -> MeshAndTags:
    """Run ``build`` (geometry, physical groups, meshing) on rank 0 and distribute the mesh.

    ``order = 2`` raises the mesh to second order after ``build`` (:func:`_second_order`).
    ``reading``: ``build`` reads a file; its errors are raised as ValueError with their own words.

    gmsh is initialised if needed and finalised again only if this call initialised it; a
    gmsh session opened by the caller keeps its current model (ours is added and removed).
    An exception on rank 0 is broadcast and raised on every rank, so that no rank is left
    waiting in the collective mesh creation.
    """
    _check_order(order)  # an argument: every rank refuses it alike
    failure = ValueError if reading else RuntimeError
    if comm.rank != 0:
        error = comm.bcast(None, root=0)
        if error is not None:
            raise failure(error)
        mesh, cell_tags, facet_tags = compat.model_to_mesh(None, comm, 0, gdim=3)
        return MeshAndTags(mesh, cell_tags, facet_tags)

    initialised_here = False
    previous_model = None
    previous_options = None
    added_model = None
    error = None
    try:
        try:
            initialised_here = _initialize_gmsh()
            if not initialised_here:
                previous_model = gmsh.model.getCurrent()
            # gmsh's own lines only with -v (dolfinx_nnqem.chatter)
            previous_options = chatter.apply_gmsh_options()
            existing = set(gmsh.model.list())
            while name in existing:  # never touch a model of the caller's with the same name
                name += "_"
            gmsh.model.add(name)
            added_model = name
            build()
            if order == 2:
                previous_options = {**_second_order(), **(previous_options or {})}
            if msh_file is not None:
                gmsh.write(os.fspath(msh_file))
        except Exception as exc:  # reported on every rank, below
            error = str(exc) if reading else f"building the gmsh model {name!r} failed: {type(exc).__name__}: {exc}"
        comm.bcast(error, root=0)
        if error is not None:
            raise failure(error)
        mesh, cell_tags, facet_tags = compat.model_to_mesh(gmsh.model, comm, 0, gdim=3)
    finally:
        if initialised_here:
            gmsh.finalize()
        elif gmsh.isInitialized():  # leave the caller's session as it was
            if added_model is not None and added_model in gmsh.model.list():
                gmsh.model.setCurrent(added_model)
                gmsh.model.remove()
            if previous_model is not None and previous_model in gmsh.model.list():
                gmsh.model.setCurrent(previous_model)
            for option, value in (previous_options or {}).items():
                gmsh.option.setNumber(option, value)
    return MeshAndTags(mesh, cell_tags, facet_tags)


# --------------------------------------------------------------------------------------------
# Small gmsh helpers (current model, rank 0 only)
# --------------------------------------------------------------------------------------------


def _curves_of(volumes: list[int]) -> list[int]:
    """Curve tags on the boundary of the given volumes."""
    surfaces = gmsh.model.getBoundary([(3, v) for v in volumes], combined=False, oriented=False)
    curves = gmsh.model.getBoundary(surfaces, combined=False, oriented=False)
    return sorted({abs(tag) for _, tag in curves})


def _surfaces_of(volumes: list[int]) -> set[int]:
    """Surface tags on the boundary of the given volumes."""
    dim_tags = gmsh.model.getBoundary([(3, v) for v in volumes], combined=False, oriented=False)
    return {abs(tag) for _, tag in dim_tags}


def _surfaces_in_box(
    lower: tuple[float, float, float],
    upper: tuple[float, float, float],
    volumes: list[int],
    size: float,
) -> list[int]:
    """Boundary surfaces of ``volumes`` lying entirely in the box ``[lower, upper]``.

    Restricting to one body's boundary matters: the two contact surfaces occupy the same box.
    """
    pad = _EPS * size
    inside = gmsh.model.getEntitiesInBoundingBox(
        lower[0] - pad, lower[1] - pad, lower[2] - pad,
        upper[0] + pad, upper[1] + pad, upper[2] + pad,
        dim=2,
    )  # fmt: skip
    own = _surfaces_of(volumes)
    found = sorted(tag for _, tag in inside if tag in own)
    if not found:
        raise RuntimeError(f"no boundary surface of volumes {volumes} in the box {lower}-{upper}")
    return found


def _add_group(dim: int, tags: list[int], tag: int, name: str) -> None:
    gmsh.model.addPhysicalGroup(dim, tags, tag)
    gmsh.model.setPhysicalName(dim, tag, name)


def _box_curve_counts(volumes: list[int], count: Callable[[np.ndarray], int]) -> dict[int, int]:
    """Element count of each (straight, axis-aligned) curve of ``volumes``.

    ``count`` receives the curve's extent ``(dx, dy, dz)`` (from its bounding box).
    """
    counts = {}
    for c in _curves_of(volumes):
        box = np.array(gmsh.model.getBoundingBox(1, c))
        counts[c] = count(box[3:] - box[:3])
    return counts


def _structured_hexahedra(curve_counts: dict[int, int], recombine: bool = True) -> None:
    """Transfinite curves (``n`` elements each), surfaces and volumes, recombined: hexahedra
    (not recombined: tetrahedra, each face's triangles with the same diagonals)."""
    for c, n in curve_counts.items():
        gmsh.model.mesh.setTransfiniteCurve(c, n + 1)
    for _, s in gmsh.model.getEntities(2):
        gmsh.model.mesh.setTransfiniteSurface(s)
        if recombine:
            gmsh.model.mesh.setRecombine(2, s)
    for _, v in gmsh.model.getEntities(3):
        gmsh.model.mesh.setTransfiniteVolume(v)


def _round_node_coordinates(decimals: int = 12) -> None:
    """Round all mesh node coordinates to ``decimals`` decimal places.

    gmsh's transfinite interpolation leaves round-off of ~1e-16 in the nodes of box meshes
    (0.39999999999999991 for 0.4), which would tilt the facet normals of flat contact
    surfaces by as much. Rounding restores the exact grid coordinates (up to binary
    representation) and moves no node by more than 0.5e-``decimals``.
    """
    tags, coords, _ = gmsh.model.mesh.getNodes()
    coords = coords.reshape(-1, 3)
    rounded = np.round(coords, decimals) + 0.0  # + 0.0 turns -0.0 into 0.0
    for tag, x, y in zip(tags, coords, rounded):
        if not np.array_equal(x, y):
            gmsh.model.mesh.setNode(int(tag), y.tolist(), [])


def _fragment_boxes(boxes: list[tuple[float, float, float, float, float, float]]) -> list[int]:
    """Add boxes ``(x, y, z, dx, dy, dz)`` and fragment them with each other (one body).

    Fragmenting makes the sub-boxes of ONE body conforming (shared interface nodes); calling
    this once per body keeps different bodies' nodes separate.
    """
    occ = gmsh.model.occ
    tags = [occ.addBox(*box) for box in boxes]
    if len(tags) == 1:
        return tags
    out, _ = occ.fragment([(3, tags[0])], [(3, t) for t in tags[1:]])
    return sorted(tag for dim, tag in out if dim == 3)


# --------------------------------------------------------------------------------------------
# The two beams of the seed benchmark
# --------------------------------------------------------------------------------------------


def build_two_beams(
    comm: MPI.Comm = MPI.COMM_WORLD,
    refine: int = 1,
    msh_file: str | os.PathLike | None = None,
    *,
    refine2: int | None = None,
    order: int = 1,
) -> MeshAndTags:
    """The seed benchmark's two overlapping cantilever beams (``benchmark-two-beams.md``).

    Beam 1: x in [0, 2], y in [0, 0.4], z in [0, 0.4]; beam 2: x in [1.6, 3.6],
    y in [0.4, 0.8], z in [0, 0.4]. Structured hexahedra of edge ``0.2 / refine`` m
    (``refine = 1``: 10 x 2 x 2 = 40 per beam). Each beam is built from two boxes fragmented
    with each other only (beam 1 split at x = 1.6, beam 2 at x = 2.0), so the contact surfaces
    are exactly the overlap x in [1.6, 2.0] on y = 0.4 and the beams share no nodes
    (``(2 refine + 1)**2`` coincident node pairs there). With ``refine2``, beam 2's edge is
    ``0.2 / refine2`` m instead: the contact surfaces no longer match (non-matching interface).

    Parameters
    ----------
    comm
        Communicator of the mesh; the gmsh model is built on its rank 0.
    refine
        Positive integer dividing the element edge 0.2 m.
    msh_file
        If given, the gmsh model is also written to this ``.msh`` file (by rank 0).
    refine2
        Positive integer dividing beam 2's element edge 0.2 m; default ``refine`` (matching
        interface meshes).
    order
        2: 27-node hexahedra (for quadratic elements, ``ContactProblem``'s default on them).

    Returns
    -------
    MeshAndTags
        The mesh and its tags, numbered as in :class:`TwoBeamsTags`.
    """
    for label, n in (("refine", refine), ("refine2", refine if refine2 is None else refine2)):
        if int(n) != n or n < 1:
            raise ValueError(f"{label} must be a positive integer, got {n!r}")
    return _mesh_from_gmsh(comm, "two_beams", lambda: _build_two_beams_model(refine, refine2), msh_file, order)


_BEAM_WIDTH = 0.4
"""The two beams' height (y) and width (z)."""


def _build_two_beams_model(refine: int, refine2: int | None) -> None:
    """The gmsh model of :func:`build_two_beams` (current model, rank 0): geometry, groups, mesh."""
    width = _BEAM_WIDTH
    # each beam in two boxes, split where the other beam starts or ends and fragmented with each
    # other only: the contact surfaces are exactly the overlap, and the beams share no node
    beam1 = _fragment_boxes([(0.0, 0.0, 0.0, 1.6, width, width), (1.6, 0.0, 0.0, 0.4, width, width)])
    beam2 = _fragment_boxes([(1.6, width, 0.0, 0.4, width, width), (2.0, width, 0.0, 1.6, width, width)])
    gmsh.model.occ.synchronize()
    _structured_hexahedra(_two_beams_curve_counts(beam1, beam2, refine, refine2))
    _tag_two_beams(beam1, beam2)
    gmsh.model.mesh.generate(3)
    _round_node_coordinates()


def _two_beams_curve_counts(beam1: list[int], beam2: list[int], refine: int,
                            refine2: int | None) -> dict[int, int]:
    """Element count of each curve of the two beams: edges of 0.2 / ``refine`` m, beam 2's of
    0.2 / ``refine2`` m when it is given."""
    h = 0.2 / int(refine)
    counts = _box_curve_counts(beam1 + beam2, lambda d: max(1, round(float(d.max()) / h)))
    if refine2 is not None:  # the beams share no curve: beam 2's counts are its own
        h2 = 0.2 / int(refine2)
        counts |= _box_curve_counts(beam2, lambda d: max(1, round(float(d.max()) / h2)))
    return counts


def _tag_two_beams(beam1: list[int], beam2: list[int]) -> None:
    """The physical groups of the two beams (:class:`TwoBeamsTags`)."""
    width = _BEAM_WIDTH
    size = 3.6  # the model's length: the scale of _surfaces_in_box's tolerance
    _add_group(3, beam1, TwoBeamsTags.BODY1, "beam1")
    _add_group(3, beam2, TwoBeamsTags.BODY2, "beam2")
    _add_group(
        2, _surfaces_in_box((0, 0, 0), (0, width, width), beam1, size),
        TwoBeamsTags.CLAMP1, "clamp1",
    )  # fmt: skip
    _add_group(
        2, _surfaces_in_box((3.6, width, 0), (3.6, 2 * width, width), beam2, size),
        TwoBeamsTags.CLAMP2, "clamp2",
    )  # fmt: skip
    _add_group(
        2, _surfaces_in_box((1.6, 2 * width, 0), (3.6, 2 * width, width), beam2, size),
        TwoBeamsTags.LOAD, "load",
    )  # fmt: skip
    _add_group(
        2, _surfaces_in_box((1.6, width, 0), (2.0, width, width), beam1, size),
        TwoBeamsTags.CONTACT1, "contact1",
    )  # fmt: skip
    _add_group(
        2, _surfaces_in_box((1.6, width, 0), (2.0, width, width), beam2, size),
        TwoBeamsTags.CONTACT2, "contact2",
    )  # fmt: skip


# --------------------------------------------------------------------------------------------
# Two stacked blocks (patch tests, Hertz-type verification)
# --------------------------------------------------------------------------------------------


def _check_blocks(counts: dict[str, int], lengths: dict[str, float]) -> None:
    """Element counts must be positive integers and lengths positive; the message names the argument."""
    for label, n in counts.items():
        if int(n) != n or n < 1:
            raise ValueError(f"{label} must be a positive integer, got {n!r}")
    for label, length in lengths.items():
        if not length > 0:
            raise ValueError(f"{label} must be positive, got {length!r}")


def build_stacked_blocks(
    comm: MPI.Comm = MPI.COMM_WORLD,
    Lx: float = 1.0,
    Ly1: float = 0.5,
    Ly2: float = 0.5,
    Lz: float = 1.0,
    nx: int = 4,
    ny1: int = 2,
    ny2: int = 2,
    nz: int = 4,
    *,
    y_interface: float | None = None,
    centred: bool = False,
    gap: float = 0.0,
    nx2: int | None = None,
    nz2: int | None = None,
    msh_file: str | os.PathLike | None = None,
    order: int = 1,
) -> MeshAndTags:
    """Body 1, a block below the plane y = ``y_interface``; body 2, a block on top of it.

    Body 1 spans y in [y_interface - Ly1, y_interface], body 2 y in [y_interface + gap,
    y_interface + gap + Ly2]; both span x in [0, Lx] and z in [0, Lz] (or, with ``centred``,
    [-Lx/2, Lx/2] and [-Lz/2, Lz/2]). Structured hexahedra, ``nx x ny1 x nz`` in body 1 and
    ``nx2 x ny2 x nz2`` in body 2 (``nx2 = nx``, ``nz2 = nz`` by default, so that the
    interface nodes coincide when ``gap = 0``). The blocks share no nodes.

    Parameters
    ----------
    comm
        Communicator of the mesh; the gmsh model is built on its rank 0.
    Lx, Ly1, Ly2, Lz
        Block sizes: common width (x) and depth (z), heights of body 1 and body 2.
    nx, ny1, ny2, nz
        Element counts per direction (body 1: nx, ny1, nz; body 2: nx2, ny2, nz2).
    y_interface
        Height of body 1's top face; default ``Ly1`` (body 1 rests on y = 0).
    centred
        Centre both blocks at x = z = 0 (axisymmetric set-ups such as Hertz contact).
    gap
        Initial distance between the blocks (negative: overlapping; for tests of the pair
        search only).
    nx2, nz2
        Body 2's element counts in x and z when they differ from body 1's (non-matching
        interface meshes).
    msh_file
        If given, the gmsh model is also written to this ``.msh`` file (by rank 0).
    order
        2: 27-node hexahedra.

    Returns
    -------
    MeshAndTags
        The mesh and its tags, numbered as in :class:`StackedBlocksTags`.
    """
    nx2 = nx if nx2 is None else nx2
    nz2 = nz if nz2 is None else nz2
    _check_blocks({"nx": nx, "ny1": ny1, "ny2": ny2, "nz": nz, "nx2": nx2, "nz2": nz2},
                  {"Lx": Lx, "Ly1": Ly1, "Ly2": Ly2, "Lz": Lz})
    y_i = Ly1 if y_interface is None else float(y_interface)
    x0 = -Lx / 2 if centred else 0.0
    z0 = -Lz / 2 if centred else 0.0
    return _mesh_from_gmsh(
        comm, "stacked_blocks",
        lambda: _build_stacked_blocks_model(x0, z0, y_i, gap, (Lx, Ly1, Ly2, Lz), (nx, ny1, nz), (nx2, ny2, nz2)),
        msh_file, order)


def _build_stacked_blocks_model(x0: float, z0: float, y_i: float, gap: float,
                                lengths: tuple[float, float, float, float], divisions1: tuple[int, int, int],
                                divisions2: tuple[int, int, int]) -> None:
    """The gmsh model of :func:`build_stacked_blocks` (current model, rank 0): geometry, groups, mesh.

    ``(x0, z0)``: the blocks' lowest corner in x and z; ``y_i``: the height of body 1's top face;
    ``lengths``: (Lx, Ly1, Ly2, Lz); ``divisions1``, ``divisions2``: the element counts (x, y, z)
    of body 1 and of body 2.
    """
    Lx, Ly1, Ly2, Lz = lengths
    y2 = y_i + gap
    body1 = _fragment_boxes([(x0, y_i - Ly1, z0, Lx, Ly1, Lz)])
    body2 = _fragment_boxes([(x0, y2, z0, Lx, Ly2, Lz)])
    gmsh.model.occ.synchronize()
    _structured_hexahedra(_axis_curve_counts(body1, divisions1) | _axis_curve_counts(body2, divisions2))

    size = float(np.linalg.norm([Lx, Ly1 + Ly2 + abs(gap), Lz]))
    _add_group(3, body1, StackedBlocksTags.BODY1, "body1")
    _add_group(3, body2, StackedBlocksTags.BODY2, "body2")
    for body, lower, upper, tag, label in _stacked_block_faces(body1, body2, (x0, x0 + Lx), (z0, z0 + Lz),
                                                               (y_i - Ly1, y_i), (y2, y2 + Ly2)):
        _add_group(2, _surfaces_in_box(lower, upper, body, size), tag, label)
    gmsh.model.mesh.generate(3)
    _round_node_coordinates()


def _axis_curve_counts(volumes: list[int], divisions: tuple[int, int, int]) -> dict[int, int]:
    """Element count of each curve of the boxes ``volumes``: ``divisions`` (x, y, z) by the
    curve's direction, the axis of its (only) non-zero extent."""
    return _box_curve_counts(volumes, lambda d: divisions[int(np.argmax(d))])


def _stacked_block_faces(body1: list[int], body2: list[int], xs: tuple[float, float], zs: tuple[float, float],
                         ys1: tuple[float, float], ys2: tuple[float, float]) -> list[tuple]:
    """(body, box corner low, box corner high, tag, name) of every tagged face of the stacked
    blocks (:class:`StackedBlocksTags`): bottom, top, the two contact faces and the sides."""
    (x0, x1), (z0, z1) = xs, zs
    T = StackedBlocksTags
    faces = [
        (body1, (x0, ys1[0], z0), (x1, ys1[0], z1), T.BOTTOM, "bottom"),
        (body2, (x0, ys2[1], z0), (x1, ys2[1], z1), T.TOP, "top"),
        (body1, (x0, ys1[1], z0), (x1, ys1[1], z1), T.CONTACT1, "contact1"),
        (body2, (x0, ys2[0], z0), (x1, ys2[0], z1), T.CONTACT2, "contact2"),
    ]
    for body, (lo_y, hi_y), base, label in ((body1, ys1, T.BODY1_XMIN, "body1"), (body2, ys2, T.BODY2_XMIN, "body2")):
        faces += [
            (body, (x0, lo_y, z0), (x0, hi_y, z1), base, f"{label}_xmin"),
            (body, (x1, lo_y, z0), (x1, hi_y, z1), base + 1, f"{label}_xmax"),
            (body, (x0, lo_y, z0), (x1, hi_y, z0), base + 2, f"{label}_zmin"),
            (body, (x0, lo_y, z1), (x1, hi_y, z1), base + 3, f"{label}_zmax"),
        ]
    return faces


def build_block_stack(
    comm: MPI.Comm = MPI.COMM_WORLD,
    Lx: float = 1.0,
    Lz: float = 1.0,
    heights: Sequence[float] = (0.5, 0.5, 0.5),
    divisions: Sequence[tuple[int, int, int]] = ((2, 1, 2), (2, 1, 2), (2, 1, 2)),
    *,
    y0: float = 0.0,
    centred: bool = False,
    cell_type: str = "hexahedron",
    structured: bool = False,
    msh_file: str | os.PathLike | None = None,
    order: int = 1,
) -> MeshAndTags:
    """Blocks stacked along y, each meshed on its own (no shared nodes): several contact interfaces.

    Block k (1 at the bottom) spans y in [y0 + Σ_{i<k} h_i, y0 + Σ_{i≤k} h_i] and x in [0, Lx],
    z in [0, Lz] (or, with ``centred``, [-Lx/2, Lx/2] and [-Lz/2, Lz/2]), with
    ``divisions[k-1] = (nx, ny, nz)`` structured hexahedra. Neighbouring blocks with the same nx
    and nz have coincident interface nodes; different ones make non-matching interfaces. With
    ``cell_type="tetrahedron"`` the blocks are meshed with unstructured tetrahedra whose edges
    divide the block's edges into nx, ny, nz parts (the faces are meshed on their own, so even
    equal divisions give non-matching interfaces); with ``structured`` as well, with tetrahedra
    from transfinite volumes, whose faces are all triangulated alike: equal nx and nz then give
    matching interfaces (coincident nodes and triangles). ``order = 2``: a second-order mesh
    (27-node hexahedra, 10-node tetrahedra).

    Returns
    -------
    MeshAndTags
        Tags as in :class:`BlockStackTags`.
    """
    heights = [float(h) for h in heights]
    if len(heights) != len(divisions) or not heights:
        raise ValueError(f"heights ({len(heights)}) and divisions ({len(divisions)}) must have one entry per block")
    for k, (h, n) in enumerate(zip(heights, divisions), start=1):
        if not h > 0:
            raise ValueError(f"block {k}: height must be positive, got {h!r}")
        if len(n) != 3 or any(int(c) != c or c < 1 for c in n):
            raise ValueError(f"block {k}: divisions must be three positive integers, got {n!r}")
    if not (Lx > 0 and Lz > 0):
        raise ValueError(f"Lx and Lz must be positive, got {Lx!r}, {Lz!r}")
    if cell_type not in ("hexahedron", "tetrahedron"):
        raise ValueError(f"cell_type must be 'hexahedron' or 'tetrahedron', got {cell_type!r}")
    return _mesh_from_gmsh(
        comm, "block_stack",
        lambda: _build_block_stack_model(Lx, Lz, heights, divisions, y0, centred, cell_type, structured), msh_file,
        order)


def _build_block_stack_model(Lx: float, Lz: float, heights: Sequence[float],
                             divisions: Sequence[tuple[int, int, int]], y0: float = 0.0,
                             centred: bool = False, cell_type: str = "hexahedron", structured: bool = False) -> None:
    """The gmsh model of :func:`build_block_stack` (current model, rank 0): geometry, groups, mesh."""
    x0 = -Lx / 2 if centred else 0.0
    z0 = -Lz / 2 if centred else 0.0
    bottoms = y0 + np.concatenate([[0.0], np.cumsum(heights)[:-1]])
    volumes = [_fragment_boxes([(x0, yb, z0, Lx, h, Lz)]) for yb, h in zip(bottoms, heights)]
    gmsh.model.occ.synchronize()
    counts: dict[int, int] = {}
    for body, (n_x, n_y, n_z) in zip(volumes, divisions):
        # called before the next body: the lambda needs no default to hold this body's divisions
        counts |= _box_curve_counts(body, lambda d: (n_x, n_y, n_z)[int(np.argmax(d))])
    if cell_type == "hexahedron":
        _structured_hexahedra(counts)
    elif structured:  # transfinite, not recombined: every face's triangles alike (matching interfaces)
        _structured_hexahedra(counts, recombine=False)
    else:  # the edges' divisions only: unstructured triangles on the faces, tetrahedra inside
        for c, n in counts.items():
            gmsh.model.mesh.setTransfiniteCurve(c, n + 1)
    size = float(np.linalg.norm([Lx, sum(heights), Lz]))
    x1, z1 = x0 + Lx, z0 + Lz
    T = BlockStackTags
    for k, (body, yb, h) in enumerate(zip(volumes, bottoms, heights), start=1):
        _add_group(3, body, T.body(k), f"block{k}")
        yt = yb + h
        for lower, upper, tag, label in (
            ((x0, yb, z0), (x1, yb, z1), T.bottom(k), "bottom"),
            ((x0, yt, z0), (x1, yt, z1), T.top(k), "top"),
            ((x0, yb, z0), (x0, yt, z1), T.xmin(k), "xmin"),
            ((x1, yb, z0), (x1, yt, z1), T.xmax(k), "xmax"),
            ((x0, yb, z0), (x1, yt, z0), T.zmin(k), "zmin"),
            ((x0, yb, z1), (x1, yt, z1), T.zmax(k), "zmax"),
        ):
            _add_group(2, _surfaces_in_box(lower, upper, body, size), tag, f"block{k}_{label}")
    gmsh.model.mesh.generate(3)
    _round_node_coordinates()


# --------------------------------------------------------------------------------------------
# Thick-walled cylinder under internal pressure (plane strain, elastoplastic verification)
# --------------------------------------------------------------------------------------------


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
    return _mesh_from_gmsh(
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
        _add_group(2, surfaces, tag, names[tag])
    _add_group(3, tube.volumes, T.BODY, "tube")
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
    tol = _EPS * 10 * b
    for s in sorted(_surfaces_of(volumes)):
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


def graded_nodes(h: float, n_fine: int, length: float, ratio: float = 1.3) -> np.ndarray:
    """Node positions 0 ≤ s ≤ length: ``n_fine`` elements of size ``h``, then sizes growing by
    ``ratio``, the last ones stretched so that the grid ends exactly at ``length``."""
    grid = list(h * np.arange(n_fine + 1))
    size = h
    while grid[-1] < length - 1e-12:
        size *= ratio
        grid.append(grid[-1] + size)
    nodes = np.array(grid)
    s0 = nodes[n_fine]
    nodes[n_fine:] = s0 + (nodes[n_fine:] - s0) * (length - s0) / (nodes[-1] - s0)
    return nodes


def build_graded_contact_blocks(comm: MPI.Comm = MPI.COMM_WORLD, h: float = 0.25, *, fine_width: float = 1.25,
                                fine_depth: float = 0.5, block: float = 6.0, half: bool = False,
                                ratio: float = 1.3) -> MeshAndTags:
    """Two blocks meeting at y = 0, graded towards the contact point x = z = 0 (Hertz-type tests).

    Elements of size ``h`` over |x|, z ≤ ``fine_width`` and ``fine_depth`` on both sides of the
    interface, growing by ``ratio`` beyond, out to ``block`` (half width, depth and height of each
    block). Quarter model (x, z ≥ 0) or, with ``half``, half model (z ≥ 0). The structured mesh of
    :func:`build_stacked_blocks` (unit elements) is mapped onto the graded grid; the same map for
    both bodies keeps the interface nodes coincident. Tags as :class:`StackedBlocksTags`.
    """
    s = graded_nodes(h, round(fine_width / h), block, ratio)
    t = graded_nodes(h, round(fine_depth / h), block, ratio)
    xs = np.concatenate([-s[:0:-1], s]) if half else s
    ys = np.concatenate([-t[:0:-1], t])  # body 1 below y = 0, body 2 above
    zs = s
    nx, ny, nz = len(xs) - 1, len(t) - 1, len(zs) - 1
    mesh, cell_tags, facet_tags = build_stacked_blocks(comm, nx, ny, ny, nz, nx, ny, ny, nz)
    x = mesh.geometry.x
    index = np.rint(x).astype(np.int64)
    if not np.allclose(x, index, atol=1e-9):
        raise RuntimeError("build_graded_contact_blocks: the unit block mesh has non-integer nodes")
    x[:, 0], x[:, 1], x[:, 2] = xs[index[:, 0]], ys[index[:, 1]], zs[index[:, 2]]
    return MeshAndTags(mesh, cell_tags, facet_tags)


def build_graded_block(comm: MPI.Comm = MPI.COMM_WORLD, h: float = 0.25, *, fine_width: float = 1.25,
                       fine_depth: float = 0.5, block: float = 6.0, half: bool = False,
                       ratio: float = 1.3, msh_file: str | os.PathLike | None = None) -> MeshAndTags:
    """One block below y = 0, graded towards the point x = z = 0 of its top (indentation tests).

    Elements of size ``h`` over |x|, z ≤ ``fine_width`` and ``fine_depth`` below the top,
    growing by ``ratio`` beyond, out to ``block`` (half width, depth and height). Quarter model
    (x, z ≥ 0) or, with ``half``, half model (z ≥ 0). Tags as :class:`BlockStackTags` (block 1:
    top = 201, bottom = 101, x = 0 plane 301, z = 0 plane 501). With ``msh_file``, the graded
    mesh is also written to that file (rank 0).
    """
    s = graded_nodes(h, round(fine_width / h), block, ratio)
    t = graded_nodes(h, round(fine_depth / h), block, ratio)
    xs = np.concatenate([-s[:0:-1], s]) if half else s
    ys = -t[::-1]  # from y = -block up to the top y = 0
    zs = s
    nx, ny, nz = len(xs) - 1, len(ys) - 1, len(zs) - 1
    mesh, cell_tags, facet_tags = build_block_stack(comm, nx, nz, [ny], [(nx, ny, nz)])
    x = mesh.geometry.x
    index = np.rint(x).astype(np.int64)
    if not np.allclose(x, index, atol=1e-9):
        raise RuntimeError("build_graded_block: the unit block mesh has non-integer nodes")
    x[:, 0], x[:, 1], x[:, 2] = xs[index[:, 0]], ys[index[:, 1]], zs[index[:, 2]]
    if msh_file is not None:
        _write_graded_msh(msh_file, comm, nx, ny, nz, xs, ys, zs)
    return MeshAndTags(mesh, cell_tags, facet_tags)


def _write_graded_msh(msh_file, comm, nx, ny, nz, xs, ys, zs) -> None:
    """Write the unit block's gmsh model with its nodes moved to the graded grid (rank 0)."""
    if comm.rank != 0:
        return

    def move() -> None:
        tags, coords, _ = gmsh.model.mesh.getNodes()
        coords = coords.reshape(-1, 3)
        index = np.rint(coords).astype(np.int64)
        for tag, i in zip(tags, index):
            gmsh.model.mesh.setNode(int(tag), [xs[i[0]], ys[i[1]], zs[i[2]]], [])

    def build() -> None:
        _build_block_stack_model(nx, nz, [ny], [(nx, ny, nz)])
        move()

    _mesh_from_gmsh(MPI.COMM_SELF, "graded_block", build, msh_file)


# --------------------------------------------------------------------------------------------
# A sphere resting on a block, meshed independently (Hertz contact on non-matching meshes)
# --------------------------------------------------------------------------------------------


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
    return _mesh_from_gmsh(
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
    cap_surfaces = _surfaces_of([cap])
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
    body1 = _fragment_boxes([(0.0, -depth, 0.0, block, depth, block)])
    cap, rest = _quarter_hemisphere(R, contact_radius)
    size = float(max(R, block, depth))
    _add_group(3, body1, T.BLOCK, "block")
    _add_group(3, [cap, rest], T.SPHERE, "sphere")
    for lower, upper, tag, label in (
        ((0, -depth, 0), (block, -depth, block), T.BOTTOM, "bottom"),
        ((0, 0, 0), (block, 0, block), T.CONTACT1, "block_top"),
        ((0, -depth, 0), (0, 0, block), T.BLOCK_XMIN, "block_xmin"),
        ((block, -depth, 0), (block, 0, block), T.BLOCK_XMAX, "block_xmax"),
        ((0, -depth, 0), (block, 0, 0), T.BLOCK_ZMIN, "block_zmin"),
        ((0, -depth, block), (block, 0, block), T.BLOCK_ZMAX, "block_zmax"),
    ):
        _add_group(2, _surfaces_in_box(lower, upper, body1, size), tag, label)
    names = {T.SPHERE_XMIN: "sphere_xmin", T.SPHERE_ZMIN: "sphere_zmin", T.LOAD: "sphere_equator",
             T.CONTACT2: "sphere_cap", T.SPHERE_FREE: "sphere_free"}
    for tag, surfaces in _classify_sphere_surfaces(R, cap, rest).items():
        _add_group(2, surfaces, tag, names[tag])
    _size_field(h_contact, fine_radius, growth, h_max)
    gmsh.model.mesh.generate(3)
    compat.optimize_tetrahedra()  # better-shaped tetrahedra than the default pass leaves
