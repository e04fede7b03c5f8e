"""Contact surfaces gathered on every rank: facets, nodes, outward normals, local frames.

Every pair set (node-to-node, rigid obstacles, ...) starts from the same data: the facets of
the tagged contact surfaces with their nodes' global dof-block indices, coordinates and
outward area vectors. Contact surfaces are small next to the mesh, so every rank gathers them
all, removes the copies of facets seen by several ranks, and orders them deterministically.
Pair sets are then computed from identical data on every rank: they are the same for any number
of ranks, and an error is detected identically everywhere (all ranks raise together and no rank
waits in a collective call).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from dolfinx_nnqem import compat  # noqa: I001  (first: loads MPI/PETSc for the PyPI wheel)

import basix
import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from dolfinx_nnqem.contact import facet_layout
from dolfinx_nnqem.contact.facet_layout import NodeCombination

__all__ = ["ContactPairError", "NoPairsError", "Facets", "GatheredSurfaces", "SurfaceNodes", "check_contact_space", "check_no_shared_nodes",
           "first_by_position",
           "format_point", "gather_surfaces", "local_frames", "local_frames_derivative", "owned_supports", "raise_together",
           "mesh_tolerance", "symmetry_normals"]

TANGENT_AXIS_BOUND = 0.8
"""t1 is built from the first coordinate axis e_k (in the order x, y, z) with |n_k| <= this
bound. Any bound above 1/sqrt(3) guarantees such an axis; 0.8 keeps the projected axis at
least 0.6 long (well conditioned) and keeps t1 continuous while the normals of a surface stay
more than ~37 degrees away from ±x, e.g. t1 = +x on all of a curved surface facing ±y."""


class ContactPairError(ValueError):
    """Contact surfaces (tags, geometry or function space) that do not define valid pairs."""


class NoPairsError(ContactPairError):
    """No slave node projects onto the master surface (at the start: surfaces that do not face each
    other; in the current geometry: the slave nodes left the master surface)."""


def local_frames(normals: npt.ArrayLike) -> np.ndarray:
    """Orthonormal right-handed frames with the given unit normals as first row.

    Parameters
    ----------
    normals
        Unit normals n, shape ``(m, 3)``.

    Returns
    -------
    np.ndarray
        R, shape ``(m, 3, 3)``, rows (n, t1, t2) with det R = +1: t1 is the normalised projection
        onto the tangent plane of the first coordinate axis e_k (x, y, z in turn) with
        |n_k| <= :data:`TANGENT_AXIS_BOUND`, and t2 = n x t1. For n = +y: t1 = +x, t2 = -z;
        for n = -y: t1 = +x, t2 = +z.
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    k = np.argmax(np.abs(n) <= TANGENT_AXIS_BOUND, axis=1)  # first admissible axis
    e = np.eye(3)[k]
    t1 = e - np.sum(e * n, axis=1)[:, None] * n
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    t2 = np.cross(n, t1)  # t1 x t2 = n: right-handed
    return np.stack([n, t1, t2], axis=1) + 0.0  # + 0.0: no -0.0 entries in printed frames


def local_frames_derivative(normals: npt.ArrayLike) -> np.ndarray:
    """∂R/∂n of :func:`local_frames`: dR[s, i, k, l] = ∂R_ik/∂n_l at the unit normals ``normals`` (m, 3).

    The frame's tangents follow the normal with the same axis e_k as :func:`local_frames` picks
    (the choice is piecewise constant, so this is the derivative wherever the choice does not
    switch): t1 = v/|v|, v = e − (e·n) n, t2 = n × t1. The normal row is n itself (∂n/∂n = I; the
    caller composes with the normal's own derivative, e.g. (I − n nᵀ)/ρ for a sphere).
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    R = local_frames(n)
    t1 = R[:, 1]
    k = np.argmax(np.abs(n) <= TANGENT_AXIS_BOUND, axis=1)
    e = np.eye(3)[k]
    e_n = np.sum(e * n, axis=1)
    v = e - e_n[:, None] * n
    identity = np.broadcast_to(np.eye(3), (len(n), 3, 3))
    dv = -e_n[:, None, None] * identity - n[:, :, None] * e[:, None, :]  # ∂v/∂n = −(e·n) I − n eᵀ
    projector = (identity - t1[:, :, None] * t1[:, None, :]) / np.linalg.norm(v, axis=1)[:, None, None]
    dt1 = projector @ dv
    dt2 = -_cross_matrix(t1) + _cross_matrix(n) @ dt1  # ∂(n × t1) = −[t1]× dn + [n]× dt1
    return np.stack([identity, dt1, dt2], axis=1)


def _cross_matrix(a: np.ndarray) -> np.ndarray:
    """[a]× (m, 3, 3): [a]× b = a × b."""
    out = np.zeros((len(a), 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -a[:, 2], a[:, 1]
    out[:, 1, 0], out[:, 1, 2] = a[:, 2], -a[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -a[:, 1], a[:, 0]
    return out


SYMMETRY_NORMAL_MIN = 0.5
""":func:`symmetry_normals` moves a normal into the plane of the free components only if at least
this much of its length lies there (the support is a plane crossing the surface)."""


def symmetry_normals(normals: npt.ArrayLike, supported: npt.ArrayLike) -> np.ndarray:
    """Unit normals with the components along a node's supported axes removed.

    A node on a symmetry plane (a support prescribing the displacement component normal to the
    plane, as the planes of a quarter model do) has its surface normal in that plane. The nodal
    normal averaged from the facets on one side of the plane, the only ones the model has, tilts
    out of it, and the tangent frame built on it then mixes the supported axis with a free one:
    the friction force along the support is then nearly undetermined (the support carries it) and
    the Newton matrix nearly singular. With the tilt removed the frame contains the supported axis
    exactly and the contact model pins that direction
    (:func:`~dolfinx_nnqem.contact.constrained_directions.supported_slave_tangents`). Which supports are symmetry planes (the
    master held on them too) is decided by :mod:`~dolfinx_nnqem.contact.symmetry_planes`; this
    function removes the components of whatever axes it is given.

    Parameters
    ----------
    normals
        (m, 3) unit normals.
    supported
        (m, 3) bool: the node's displacement components that a support prescribes.

    Returns
    -------
    np.ndarray
        (m, 3) unit normals. A node with no supported component, or all three, keeps its normal;
        so does one whose normal would keep less than :data:`SYMMETRY_NORMAL_MIN` of its length
        (a support that prescribes the normal motion is no symmetry plane across the surface).
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    flags = np.asarray(supported, dtype=bool).reshape(-1, 3)
    projected = np.where(flags, 0.0, n)
    length = np.linalg.norm(projected, axis=1)
    some = flags.any(axis=1) & ~flags.all(axis=1)
    move = some & (length >= SYMMETRY_NORMAL_MIN)
    out = n.copy()
    out[move] = projected[move] / length[move, None]
    return out


def owned_supports(V: dolfinx.fem.FunctionSpace, supported: np.ndarray, blocks: npt.ArrayLike) -> np.ndarray:
    """(m, 3) bool: the prescribed components of the owned dof blocks ``blocks`` (global indices).

    ``supported`` is laid out like V's local dofs (owned, then ghosts), non-zero at prescribed
    ones. Every block must be owned by this rank (a pair set's slave nodes are).
    """
    start = V.dofmap.index_map.local_range[0]
    local = np.asarray(blocks, dtype=np.int64).reshape(-1) - start
    return np.asarray(supported)[3 * local[:, None] + np.arange(3)] != 0.0


# --------------------------------------------------------------------------------------------
# Collective error handling
# --------------------------------------------------------------------------------------------


def raise_together(comm: MPI.Comm, message: str | None) -> None:
    """Raise :class:`ContactPairError` on every rank if any rank has a message.

    The first message (lowest rank) is raised, so that all ranks report the same error.
    """
    messages = comm.allgather(message)
    for rank, msg in enumerate(messages):
        if msg is not None:
            prefix = f"(detected on rank {rank}) " if comm.size > 1 else ""
            raise ContactPairError(prefix + msg)


def first_by_position(x: np.ndarray, candidates: np.ndarray) -> int:
    """Of the indices ``candidates`` (or a boolean mask), the one whose point in ``x`` is
    lexicographically smallest: error messages then name the same node for any number of
    ranks (global indices depend on the partition)."""
    candidates = np.flatnonzero(candidates) if candidates.dtype == bool else np.asarray(candidates)
    c = x[candidates]
    return int(candidates[np.lexsort((c[:, 2], c[:, 1], c[:, 0]))[0]])


def format_point(x: npt.ArrayLike) -> str:
    """The point ``x`` as "(x, y, z)", six significant digits, for messages."""
    return "(" + ", ".join(f"{v:.6g}" for v in np.asarray(x, dtype=np.float64).ravel()) + ")"


# --------------------------------------------------------------------------------------------
# Local facet data and its gathering
# --------------------------------------------------------------------------------------------


@dataclass
class Facets:
    """Contact-surface facets: one row per facet (local, or gathered from all ranks)."""

    surface: np.ndarray  # (m,) 1, 2, ...: which of the gathered surfaces (tags) holds the facet
    nodes: np.ndarray  # (m, k) global dof-block indices of the facet's vertices
    x: np.ndarray  # (m, k, 3) their coordinates
    area: np.ndarray  # (m, 3) outward area vector (|area| = facet area)
    num_cells: np.ndarray  # (m,) cells attached to the facet on the rank that saw it

    @classmethod
    def concatenate(cls, parts: list[Facets]) -> Facets:
        """The facets of ``parts``, one after the other."""
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in cls.__dataclass_fields__))

    def take(self, index: np.ndarray) -> Facets:
        """The facets ``index``, in that order."""
        return Facets(*(getattr(self, f)[index] for f in self.__dataclass_fields__))

    @property
    def num_vertices(self) -> int:
        """Vertices per facet (the first nodes of each row)."""
        return facet_layout.NUM_VERTICES[self.nodes.shape[1]]

    @property
    def degree(self) -> int:
        """1 for linear facets (tri3, quad4), 2 for quadratic ones (tri6, quad9)."""
        return 2 if facet_layout.is_quadratic(self.nodes.shape[1]) else 1


def space_degree(V: dolfinx.fem.FunctionSpace) -> int:
    """The Lagrange degree of the displacement space V (1 or 2; see :func:`_check_space`)."""
    layout = V.dofmap.dof_layout
    return 2 if len(layout.entity_dofs(1, 0)) else 1


def _check_space(V: dolfinx.fem.FunctionSpace) -> str | None:
    """Why ``V`` is not a vector P1/P2 (continuous Lagrange, degree 1 or 2, block size 3) space, or None."""
    mesh = V.mesh
    if mesh.geometry.dim != 3 or mesh.topology.dim != 3:
        return f"the mesh must be 3D (gdim = {mesh.geometry.dim}, tdim = {mesh.topology.dim})"
    bs = V.dofmap.index_map_bs
    if bs != 3 or V.dofmap.bs != 3:
        return f"V must be a vector space with block size 3, got block size {bs}"
    layout = V.dofmap.dof_layout
    cell_type = mesh.topology.cell_type
    counts = [[len(layout.entity_dofs(d, i)) for i in range(dolfinx.cpp.mesh.cell_num_entities(cell_type, d))]
              for d in range(3)]
    quadrilateral_faces = cell_type == dolfinx.mesh.CellType.hexahedron
    # one dof (block) per vertex and none elsewhere: P1/Q1; plus one per edge (and per quadrilateral
    # face) and any number inside the cell: P2/Q2
    linear = counts == [[1] * len(counts[0]), [0] * len(counts[1]), [0] * len(counts[2])]
    quadratic = counts == [[1] * len(counts[0]), [1] * len(counts[1]), [int(quadrilateral_faces)] * len(counts[2])]
    if not (linear and layout.num_dofs == len(counts[0]) or quadratic):
        return (
            "V must be continuous Lagrange of degree 1 or 2 (one dof block per vertex, and per edge for degree 2); "
            f"its cells have {layout.num_dofs} dof blocks for {len(counts[0])} vertices"
        )
    return None


def _facet_node_closures(layout, cell_type, degree: int) -> np.ndarray:
    """(facets of the cell, k) local dofs of each facet of the reference cell in the order of
    :mod:`~dolfinx_nnqem.contact.quadratic_facets` (degree 2: vertices, edges by their vertex pairs,
    the quadrilateral's centre); degree 1: the vertices as ``entity_closure_dofs`` lists them."""
    fdim = 2
    num_cell_facets = dolfinx.cpp.mesh.cell_num_entities(cell_type, fdim)
    if degree == 1:
        return np.array([layout.entity_closure_dofs(fdim, j) for j in range(num_cell_facets)])
    sub = basix.cell.sub_entity_connectivity(getattr(basix.CellType, cell_type.name))
    edges = [tuple(sorted(e[0])) for e in sub[1]]
    rows = []
    for j in range(num_cell_facets):
        vertices = sub[fdim][j][0]
        k = 6 if len(vertices) == 3 else 9
        row = [layout.entity_dofs(0, v)[0] for v in vertices]
        row += [layout.entity_dofs(1, edges.index(tuple(sorted((vertices[a], vertices[b])))))[0]
                for a, b in facet_layout.EDGES[k]]
        if k == 9:
            row.append(layout.entity_dofs(fdim, j)[0])
        rows.append(row)
    return np.array(rows)


def _facet_coordinates(mesh, cells: np.ndarray, local_facet: np.ndarray, closure: np.ndarray) -> np.ndarray:
    """(m, k, 3) coordinates of the nodes of the facets ``local_facet`` of ``cells`` (``closure``:
    :func:`_facet_node_closures` of the displacement space).

    Vertices are geometry nodes (a Lagrange dof layout numbers vertex v's dof v, as the geometry
    does). The other nodes of a quadratic facet are geometry nodes too on a second-order mesh,
    whose curved facets this keeps; on a straight-sided mesh they are the edge midpoints and the
    quadrilateral's centre (the map of a bilinear facet at its centre is its vertex mean).
    """
    k = closure.shape[1]
    nv = facet_layout.NUM_VERTICES[k]
    cell_nodes = compat.geometry_dofmap(mesh)[cells]
    x = mesh.geometry.x[np.take_along_axis(cell_nodes, closure[local_facet, :nv], axis=1)]
    if nv == k:
        return x
    cmap = compat.coordinate_element(mesh)
    if cmap.degree == 2:
        geometry = _facet_node_closures(cmap.create_dof_layout(), mesh.topology.cell_type, 2)
        return mesh.geometry.x[np.take_along_axis(cell_nodes, geometry[local_facet], axis=1)]
    if cmap.degree > 2:
        raise ContactPairError(f"contact surfaces on a mesh of geometry degree {cmap.degree}: quadratic contact "
                               "facets need a straight-sided or a second-order mesh")
    extra = [0.5 * (x[:, a] + x[:, b]) for a, b in facet_layout.EDGES[k]]
    if k == 9:
        extra.append(x.mean(axis=1))
    return np.concatenate([x, np.stack(extra, axis=1)], axis=1)


def _outward_area_vectors(x: np.ndarray, cell_centroid: np.ndarray) -> np.ndarray:
    """Area vectors of planar polygons (vertices in any order), pointing away from their cells.

    The vertices are ordered by angle about the facet centroid in the facet's best-fit plane,
    then Newell's sum gives the area vector (exact for planar facets, the mean plane for
    slightly warped quadrilaterals); it is flipped to point away from the centroid of the cell
    that owns the facet, which is outward for a boundary facet of a convex cell.
    """
    centroid = x.mean(axis=1)
    d = x - centroid[:, None, :]
    _, _, vt = np.linalg.svd(d)  # rows of vt: in-plane axes, then the plane normal
    angle = np.arctan2(np.einsum("mkj,mj->mk", d, vt[:, 1]), np.einsum("mkj,mj->mk", d, vt[:, 0]))
    order = np.argsort(angle, axis=1)
    # Newell's sum about the first vertex: coordinate differences of a facet lying in a
    # coordinate plane are then exactly zero, and so are the off-plane normal components
    x = np.take_along_axis(x, order[:, :, None], axis=1)
    d = x - x[:, :1, :]
    area = 0.5 * np.cross(d, np.roll(d, -1, axis=1)).sum(axis=1)
    side = np.einsum("mj,mj->m", area, centroid - cell_centroid)
    return np.where(side[:, None] < 0, -area, area)


def _local_facets(
    V: dolfinx.fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags, tag: int, surface: int
) -> Facets:
    """The facets tagged ``tag`` that this rank holds (owned or ghost), as :class:`Facets`."""
    mesh = V.mesh
    tdim = mesh.topology.dim
    fdim = tdim - 1
    mesh.topology.create_connectivity(fdim, tdim)
    mesh.topology.create_connectivity(tdim, fdim)
    f2c = mesh.topology.connectivity(fdim, tdim)
    c2f = mesh.topology.connectivity(tdim, fdim)
    cell_type = mesh.topology.cell_type
    num_cell_facets = dolfinx.cpp.mesh.cell_num_entities(cell_type, fdim)
    # local dof blocks of each local facet of the reference cell
    closure = _facet_node_closures(V.dofmap.dof_layout, cell_type, space_degree(V))
    k = closure.shape[1]

    facets = np.asarray(facet_tags.indices[facet_tags.values == tag], dtype=np.int32)
    m = len(facets)
    if m == 0:
        return Facets(
            np.empty(0, np.int8), np.empty((0, k), np.int64), np.empty((0, k, 3)),
            np.empty((0, 3)), np.empty(0, np.int32),
        )  # fmt: skip
    num_cells = (f2c.offsets[facets + 1] - f2c.offsets[facets]).astype(np.int32)
    cells = f2c.array[f2c.offsets[facets]]  # the (first) cell holding the facet
    cell_facets = c2f.array[c2f.offsets[cells][:, None] + np.arange(num_cell_facets)]
    local_facet = np.argmax(cell_facets == facets[:, None], axis=1)
    cell_dofs = V.dofmap.list[cells]
    facet_dofs = np.take_along_axis(cell_dofs, closure[local_facet], axis=1)

    # Node coordinates straight from the mesh geometry, whose cell nodes start with the vertices
    # in the same local order as the dofs (V.tabulate_dof_coordinates() would push reference
    # points forward and add round-off, different on ranks that see a node through other cells).
    num_vertices = dolfinx.cpp.mesh.cell_num_vertices(cell_type)
    x = _facet_coordinates(mesh, cells, local_facet, closure)
    cell_vertices = compat.geometry_dofmap(mesh)[cells][:, :num_vertices]
    area = _outward_area_vectors(x[:, :facet_layout.NUM_VERTICES[k]], mesh.geometry.x[cell_vertices].mean(axis=1))
    nodes = V.dofmap.index_map.local_to_global(facet_dofs.ravel().astype(np.int32)).reshape(m, k)
    return Facets(np.full(m, surface, np.int8), nodes.astype(np.int64), x, area, num_cells)


def _unique_facets(facets: Facets, tags: Sequence[int]) -> tuple[Facets, str | None]:
    """Remove copies of facets gathered from several ranks; detect facets inside a body.

    A boundary facet has one cell in the whole mesh. A facet with two cells on one rank, or
    whose copies from two ranks point in opposite directions (two cells on different ranks,
    without ghost cells), is interior and cannot be a contact surface.
    """
    if len(facets.surface) == 0:
        return facets, None
    key = np.column_stack([facets.surface.astype(np.int64), np.sort(facets.nodes, axis=1)])
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    same_way = np.einsum("mj,mj->m", facets.area, facets.area[first[inverse]]) > 0
    interior = (facets.num_cells > 1) | ~same_way
    if np.any(interior):
        i = first_by_position(facets.x.mean(axis=1), interior)
        return facets, (
            f"a facet tagged {tags[facets.surface[i] - 1]} is inside a body, not on its boundary "
            f"(vertices {', '.join(format_point(p) for p in facets.x[i, :facets.num_vertices])})"
        )
    unique = facets.take(first)
    # deterministic order for any number of ranks: by surface, then facet centroid
    c = unique.x.mean(axis=1)
    order = np.lexsort((c[:, 2], c[:, 1], c[:, 0], unique.surface))
    return unique.take(order), None


@dataclass
class SurfaceNodes:
    """The nodes of one contact surface with their outward unit normals (identical on every rank).

    Every node of the surface's facets: the vertices, and for quadratic facets (degree-2
    displacements) the edge and face nodes too.
    """

    index: np.ndarray  # (p,) global dof-block indices (sorted)
    x: np.ndarray  # (p, 3)
    normal: np.ndarray  # (p, 3) area-weighted mean of the adjacent facets' outward normals
    area: np.ndarray  # (p,) tributary area ∫ N̂_j dA (linear facets: each facet's area shared equally by its vertices)
    combination: NodeCombination  # the pair rows' slave nodes: d̂ = T⁻ᵀ d (quadratic_facets; identity if linear)


def _surface_nodes(facets: Facets, surface: int, tag: int) -> tuple[SurfaceNodes, str | None]:
    sel = facets.surface == surface
    nodes, x, area = facets.nodes[sel], facets.x[sel], facets.area[sel]
    k = nodes.shape[1]
    index, first, inverse = np.unique(nodes.ravel(), return_index=True, return_inverse=True)
    xs = x.reshape(-1, 3)[first]
    if facet_layout.is_quadratic(k):
        # each node's share ∫ N̂_j dA of its facets and its normal ∫ N̂_j n dA; imported here, as
        # its numba kernels are needed only where quadratic facets are (facet_layout)
        from dolfinx_nnqem.contact import quadratic_facets

        weights, moments = quadratic_facets.nodal_integrals(x, area)
        tributary = np.bincount(inverse.ravel(), weights.ravel(), minlength=len(index))
        normal = np.zeros((len(index), 3))
        np.add.at(normal, inverse.ravel(), moments.reshape(-1, 3))
        combination = facet_layout.node_combination(nodes, index)
    else:
        # sum of the adjacent facets' area vectors = area-weighted sum of their unit normals
        normal = np.zeros((len(index), 3))
        np.add.at(normal, inverse.ravel(), np.repeat(area, k, axis=0))
        # ∫ N_j dA over a triangle or a parallelogram is its area / (number of vertices)
        tributary = np.bincount(inverse.ravel(), np.repeat(np.linalg.norm(area, axis=1) / k, k), minlength=len(index))
        combination = NodeCombination.identity(len(index))
    length = np.linalg.norm(normal, axis=1)
    scale = np.repeat(np.linalg.norm(area, axis=1), k).max(initial=0.0)
    degenerate = length <= 1e-12 * max(scale, np.finfo(float).tiny)
    if np.any(degenerate):
        i = first_by_position(xs, degenerate)
        return SurfaceNodes(index, xs, normal, tributary, combination), (
            f"the facets tagged {tag} around the node at {format_point(xs[i])} have normals that cancel"
        )
    if np.any(tributary <= 0.0):  # a quadratic facet so distorted that a node's share is not positive
        i = first_by_position(xs, tributary <= 0.0)
        return SurfaceNodes(index, xs, normal, tributary, combination), (
            f"the node at {format_point(xs[i])} of the facets tagged {tag} has a tributary area "
            f"∫ N_j dA = {tributary[i]:.3g} <= 0: its quadratic facets are too distorted for contact")
    return SurfaceNodes(index, xs, normal / length[:, None], tributary, combination), None


# --------------------------------------------------------------------------------------------
# The collective entry point
# --------------------------------------------------------------------------------------------


@dataclass
class GatheredSurfaces:
    """Contact surfaces gathered on every rank (the same data on every rank).

    Attributes
    ----------
    tags
        The facet tags, in the order asked for.
    facets
        All their facets, copies removed, ordered by surface, then by centroid.
    nodes
        One :class:`SurfaceNodes` per tag.
    """

    tags: tuple[int, ...]
    facets: Facets
    nodes: list[SurfaceNodes]

    def facets_of(self, k: int) -> Facets:
        """The facets of the ``k``-th surface (0-based, in the order of :attr:`tags`)."""
        return self.facets.take(np.flatnonzero(self.facets.surface == k + 1))

    def swapped(self) -> GatheredSurfaces:
        """The same two surfaces in the other order."""
        if len(self.tags) != 2:
            raise ValueError(f"swapped() needs two surfaces, got {len(self.tags)}")
        facets = self.facets.take(np.arange(len(self.facets.surface)))
        facets.surface = (3 - facets.surface).astype(self.facets.surface.dtype)
        return GatheredSurfaces((self.tags[1], self.tags[0]), facets, [self.nodes[1], self.nodes[0]])


def check_contact_space(V: dolfinx.fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags | None) -> None:
    """Raise :class:`ContactPairError` unless V is vector P1 or P2 on a 3D mesh and ``facet_tags`` tags facets."""
    problem = _check_space(V)
    if problem is not None:
        raise ContactPairError(problem)
    if facet_tags is None:
        raise ContactPairError("contact needs facet tags naming the contact surfaces; no facet_tags were given")
    if facet_tags.dim != V.mesh.topology.dim - 1:
        raise ContactPairError(
            f"facet_tags has dimension {facet_tags.dim}, expected facets ({V.mesh.topology.dim - 1})"
        )


def mesh_tolerance(mesh: dolfinx.mesh.Mesh, relative: float = 1e-8) -> float:
    """``relative`` times the diagonal of the mesh's bounding box (over all ranks)."""
    comm = mesh.comm
    x = mesh.geometry.x
    lo = np.array(x.min(axis=0) if len(x) else np.full(3, np.inf), dtype=np.float64)
    hi = np.array(x.max(axis=0) if len(x) else np.full(3, -np.inf), dtype=np.float64)
    comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
    comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
    return relative * float(np.linalg.norm(hi - lo))


def gather_surfaces(V: dolfinx.fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags,
                    tags: Sequence[int], roles: Sequence[str] | None = None) -> GatheredSurfaces:
    """Gather the contact surfaces tagged ``tags`` on every rank (collective on V's communicator).

    Parameters
    ----------
    V
        Vector P1 or P2 space on a 3D mesh.
    facet_tags
        Facet tags holding every tag of ``tags``.
    tags
        The facet tags of the surfaces.
    roles
        How error messages name each surface (default ``surface1``, ``surface2``, ...).

    Raises
    ------
    ContactPairError
        On every rank, if V is not vector P1 or P2, a tag has no facet on any rank, a facet is inside
        a body, or the normals around a node cancel.
    """
    comm = V.mesh.comm
    tags = tuple(int(t) for t in tags)
    roles = list(roles) if roles is not None else [f"surface{k + 1}" for k in range(len(tags))]
    check_contact_space(V, facet_tags)
    local_error = None
    try:
        local = Facets.concatenate([_local_facets(V, facet_tags, tag, k + 1) for k, tag in enumerate(tags)])
    except Exception as exc:  # noqa: BLE001  (re-raised on every rank)
        local_error = f"reading the contact facets failed: {type(exc).__name__}: {exc}"
        local = None
    raise_together(comm, local_error)
    facets = Facets.concatenate(comm.allgather(local))
    for k, tag in enumerate(tags):
        if not np.any(facets.surface == k + 1):
            present = sorted(set(np.concatenate(comm.allgather(np.unique(facet_tags.values))).tolist()))
            raise ContactPairError(
                f"no facet is tagged {tag} ({roles[k]}) on any rank; the facet tags present are {present}"
            )
    # From here on every rank works on the same data: errors arise identically everywhere.
    facets, error = _unique_facets(facets, tags)
    if error:
        raise ContactPairError(error)
    nodes = []
    for k, tag in enumerate(tags):
        surface, error = _surface_nodes(facets, k + 1, tag)
        if error:
            raise ContactPairError(error)
        nodes.append(surface)
    return GatheredSurfaces(tags, facets, nodes)


def check_no_shared_nodes(surfaces: GatheredSurfaces) -> None:
    """Refuse two contact surfaces with common nodes (the bodies must be meshed apart)."""
    first, second = surfaces.nodes
    shared = np.intersect1d(first.index, second.index)
    if len(shared):
        i = first_by_position(first.x, np.isin(first.index, shared))
        raise ContactPairError(
            f"contact surfaces {surfaces.tags[0]} and {surfaces.tags[1]} share {len(shared)} node(s), e.g. at "
            f"{format_point(first.x[i])}: the two bodies must be meshed without common nodes")
