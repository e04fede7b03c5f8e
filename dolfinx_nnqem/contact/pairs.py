"""Node-to-node contact pairs: detection, local frames, the matrix B, MPI ownership.

A contact pair i joins node a_i of body 1's contact surface and node b_i of body 2's contact
surface (``formulation.md`` §2). Its local frame R_i has the rows (n_i, t1_i, t2_i), with n_i
body 1's outward unit normal at a_i; the initial gap is g0_i = n_i · (X_b - X_a), and the
relative displacement in the local frame is

    w_i = R_i (u(b_i) - u(a_i)),   i.e.   w = B u,

with B of size 3 NC x ndof: the block R_i in b_i's columns and -R_i in a_i's columns.

Parallel design. Contact surfaces are small next to the mesh, so every rank gathers BOTH
contact surfaces (facets with their nodes' global dof-block indices, coordinates and outward
area vectors), removes the copies of facets seen by several ranks, and computes ALL pairs
from identical data in a deterministic order. A rank keeps the pairs whose node b_i it owns.
Pairs are therefore identical for any number of ranks, errors are detected identically on
every rank (so all raise together and no rank waits in a collective call), and no ghost
layer is needed for node a_i: B is a distributed PETSc matrix whose columns live wherever
V's dofs live.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from dolfinx_nnqem import compat  # noqa: I001  (first: loads MPI/PETSc for the PyPI wheel)

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

__all__ = ["ContactPairError", "ContactPairs", "find_pairs", "local_frames"]

TANGENT_AXIS_BOUND = 0.8
"""t1 is built from the first coordinate axis e_k (in the order x, y, z) with |n_k| <= this
bound. Any bound above 1/sqrt(3) guarantees such an axis; 0.8 keeps the projected axis at
least 0.6 long (well conditioned) and keeps t1 continuous while the normals of a surface stay
more than ~37 degrees away from ±x, e.g. t1 = +x on all of a curved surface facing ±y."""


class ContactPairError(ValueError):
    """Contact surfaces (tags, geometry or function space) that do not define valid pairs."""


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


# --------------------------------------------------------------------------------------------
# Collective error handling
# --------------------------------------------------------------------------------------------


def _raise_together(comm: MPI.Comm, message: str | None) -> None:
    """Raise :class:`ContactPairError` on every rank if any rank has a message.

    The first message (lowest rank) is raised, so that all ranks report the same error.
    """
    messages = comm.allgather(message)
    for rank, msg in enumerate(messages):
        if msg is not None:
            prefix = f"(detected on rank {rank}) " if comm.size > 1 else ""
            raise ContactPairError(prefix + msg)


def _first_by_position(x: np.ndarray, candidates: np.ndarray) -> int:
    """Of the indices ``candidates`` (or a boolean mask), the one whose point in ``x`` is
    lexicographically smallest: error messages then name the same node for any number of
    ranks (global indices depend on the partition)."""
    candidates = np.flatnonzero(candidates) if candidates.dtype == bool else np.asarray(candidates)
    c = x[candidates]
    return int(candidates[np.lexsort((c[:, 2], c[:, 1], c[:, 0]))[0]])


def _fmt(x: npt.ArrayLike) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in np.asarray(x, dtype=np.float64).ravel()) + ")"


# --------------------------------------------------------------------------------------------
# Local facet data and its gathering
# --------------------------------------------------------------------------------------------


@dataclass
class _Facets:
    """Contact-surface facets: one row per facet (local, or gathered from all ranks)."""

    surface: np.ndarray  # (m,) 1 or 2: the body whose contact surface holds the facet
    nodes: np.ndarray  # (m, k) global dof-block indices of the facet's vertices
    x: np.ndarray  # (m, k, 3) their coordinates
    area: np.ndarray  # (m, 3) outward area vector (|area| = facet area)
    num_cells: np.ndarray  # (m,) cells attached to the facet on the rank that saw it

    @classmethod
    def concatenate(cls, parts: list[_Facets]) -> _Facets:
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in cls.__dataclass_fields__))

    def take(self, index: np.ndarray) -> _Facets:
        return _Facets(*(getattr(self, f)[index] for f in self.__dataclass_fields__))


def _check_space(V: dolfinx.fem.FunctionSpace) -> str | None:
    """Why ``V`` is not a vector P1 (continuous Lagrange, degree 1, block size 3) space, or None."""
    mesh = V.mesh
    if mesh.geometry.dim != 3 or mesh.topology.dim != 3:
        return f"the mesh must be 3D (gdim = {mesh.geometry.dim}, tdim = {mesh.topology.dim})"
    bs = V.dofmap.index_map_bs
    if bs != 3 or V.dofmap.bs != 3:
        return f"V must be a vector space with block size 3, got block size {bs}"
    layout = V.dofmap.dof_layout
    num_vertices = dolfinx.cpp.mesh.cell_num_vertices(mesh.topology.cell_type)
    vertex_dofs = [len(layout.entity_dofs(0, v)) for v in range(num_vertices)]
    # exactly one dof (block) per vertex and none elsewhere: continuous P1/Q1 Lagrange
    if layout.num_dofs != num_vertices or vertex_dofs != [1] * num_vertices:
        return (
            "V must be continuous Lagrange of degree 1 (one dof block per vertex); its cells "
            f"have {layout.num_dofs} dof blocks for {num_vertices} vertices"
        )
    return None


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
) -> _Facets:
    """The facets tagged ``tag`` that this rank holds (owned or ghost), as :class:`_Facets`."""
    mesh = V.mesh
    tdim = mesh.topology.dim
    fdim = tdim - 1
    mesh.topology.create_connectivity(fdim, tdim)
    mesh.topology.create_connectivity(tdim, fdim)
    f2c = mesh.topology.connectivity(fdim, tdim)
    c2f = mesh.topology.connectivity(tdim, fdim)
    layout = V.dofmap.dof_layout
    cell_type = mesh.topology.cell_type
    num_cell_facets = dolfinx.cpp.mesh.cell_num_entities(cell_type, fdim)
    # local dof blocks of each local facet of the reference cell
    closure = np.array([layout.entity_closure_dofs(fdim, j) for j in range(num_cell_facets)])
    k = closure.shape[1]

    facets = np.asarray(facet_tags.indices[facet_tags.values == tag], dtype=np.int32)
    m = len(facets)
    if m == 0:
        return _Facets(
            np.empty(0, np.int8), np.empty((0, k), np.int64), np.empty((0, k, 3)),
            np.empty((0, 3)), np.empty(0, np.int32),
        )  # fmt: skip
    num_cells = (f2c.offsets[facets + 1] - f2c.offsets[facets]).astype(np.int32)
    cells = f2c.array[f2c.offsets[facets]]  # the (first) cell holding the facet
    cell_facets = c2f.array[c2f.offsets[cells][:, None] + np.arange(num_cell_facets)]
    local_facet = np.argmax(cell_facets == facets[:, None], axis=1)
    cell_dofs = V.dofmap.list[cells]
    facet_dofs = np.take_along_axis(cell_dofs, closure[local_facet], axis=1)

    # Vertex coordinates straight from the mesh geometry, whose cell nodes start with the
    # vertices in the same local order as P1's dofs (V.tabulate_dof_coordinates() would
    # push reference points forward and add round-off).
    num_vertices = dolfinx.cpp.mesh.cell_num_vertices(cell_type)
    cell_nodes = compat.geometry_dofmap(mesh)[cells][:, :num_vertices]
    facet_nodes = np.take_along_axis(cell_nodes, closure[local_facet], axis=1)
    x = mesh.geometry.x[facet_nodes]
    area = _outward_area_vectors(x, mesh.geometry.x[cell_nodes].mean(axis=1))
    nodes = V.dofmap.index_map.local_to_global(facet_dofs.ravel().astype(np.int32)).reshape(m, k)
    return _Facets(np.full(m, surface, np.int8), nodes.astype(np.int64), x, area, num_cells)


def _unique_facets(facets: _Facets, tags: tuple[int, int]) -> tuple[_Facets, str | None]:
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
        i = _first_by_position(facets.x.mean(axis=1), interior)
        return facets, (
            f"a facet tagged {tags[facets.surface[i] - 1]} is inside a body, not on its boundary "
            f"(vertices {', '.join(_fmt(p) for p in facets.x[i])})"
        )
    unique = facets.take(first)
    # deterministic order for any number of ranks: by surface, then facet centroid
    c = unique.x.mean(axis=1)
    order = np.lexsort((c[:, 2], c[:, 1], c[:, 0], unique.surface))
    return unique.take(order), None


@dataclass
class _SurfaceNodes:
    """The nodes of one contact surface with their outward unit normals."""

    index: np.ndarray  # (p,) global dof-block indices (sorted)
    x: np.ndarray  # (p, 3)
    normal: np.ndarray  # (p, 3) area-weighted mean of the adjacent facets' outward normals


def _surface_nodes(facets: _Facets, surface: int, tag: int) -> tuple[_SurfaceNodes, str | None]:
    sel = facets.surface == surface
    nodes, x, area = facets.nodes[sel], facets.x[sel], facets.area[sel]
    k = nodes.shape[1]
    index, first, inverse = np.unique(nodes.ravel(), return_index=True, return_inverse=True)
    # sum of the adjacent facets' area vectors = area-weighted sum of their unit normals
    normal = np.zeros((len(index), 3))
    np.add.at(normal, inverse.ravel(), np.repeat(area, k, axis=0))
    length = np.linalg.norm(normal, axis=1)
    xs = x.reshape(-1, 3)[first]
    scale = np.repeat(np.linalg.norm(area, axis=1), k).max(initial=0.0)
    degenerate = length <= 1e-12 * max(scale, np.finfo(float).tiny)
    if np.any(degenerate):
        i = _first_by_position(xs, degenerate)
        return _SurfaceNodes(index, xs, normal), (
            f"the facets tagged {tag} around the node at {_fmt(xs[i])} have normals that cancel"
        )
    return _SurfaceNodes(index, xs, normal / length[:, None]), None


# --------------------------------------------------------------------------------------------
# Matching
# --------------------------------------------------------------------------------------------


def _match(
    body1: _SurfaceNodes,
    body2: _SurfaceNodes,
    tags: tuple[int, int],
    tolerance: float,
    search_distance: float | None,
) -> tuple[np.ndarray, np.ndarray, str | None]:
    """For every body-2 node, the body-1 node facing it.

    Returns the indices into ``body1`` and ``body2`` of the pairs (body-2 nodes in a
    deterministic coordinate order) and an error message or None.
    """
    tag1, tag2 = tags
    # body-2 nodes in lexicographic order of their coordinates (rounded to the tolerance, so
    # that the order does not depend on round-off in the mesh generator)
    key = np.round(body2.x / tolerance)
    order2 = np.lexsort((body2.x[:, 2], body2.x[:, 1], body2.x[:, 0], key[:, 2], key[:, 1], key[:, 0]))
    x2 = body2.x[order2]

    tree = cKDTree(body1.x)
    dist, nearest = tree.query(x2, k=1)
    partner = np.where(dist <= tolerance, nearest, -1)

    unmatched = np.flatnonzero(partner < 0)
    if len(unmatched) and search_distance is not None:
        candidates = tree.query_ball_point(x2[unmatched], r=search_distance)
        for j, found in zip(unmatched, candidates):
            if not found:
                continue
            found = np.asarray(found)
            d = x2[j] - body1.x[found]
            g0 = np.einsum("ij,ij->i", body1.normal[found], d)
            ahead = g0 >= -tolerance
            if not np.any(ahead):
                i = found[np.argmin(np.linalg.norm(d, axis=1))]
                return order2, partner, (
                    f"the node at {_fmt(x2[j])} of surface {tag2} (body 2) lies behind surface "
                    f"{tag1} (body 1): its nearest body-1 node at {_fmt(body1.x[i])} with outward "
                    f"normal {_fmt(body1.normal[i])} gives the initial gap "
                    f"{float(np.dot(body1.normal[i], x2[j] - body1.x[i])):.6g} < 0. Are the bodies "
                    "overlapping, or are surface1 and surface2 swapped?"
                )
            found, d = found[ahead], d[ahead]
            distance = np.linalg.norm(d, axis=1)
            xc = body1.x[found]
            best = np.lexsort((xc[:, 2], xc[:, 1], xc[:, 0], distance))[0]  # ties: by coordinates
            partner[j] = found[best]

    if np.any(partner < 0):
        j = int(np.flatnonzero(partner < 0)[0])
        within = (
            f"within the search distance {search_distance:.6g}"
            if search_distance is not None
            else f"coincident with it (tolerance {tolerance:.3g}; pass search_distance for non-coincident pairs)"
        )
        return order2, partner, (
            f"the node at {_fmt(x2[j])} of contact surface {tag2} (body 2) has no partner: "
            f"no node of surface {tag1} (body 1) is {within}"
        )

    used, counts = np.unique(partner, return_counts=True)
    if np.any(counts > 1):
        # the first body-2 node (in coordinate order) whose partner is taken twice
        j = int(np.flatnonzero(np.isin(partner, used[counts > 1]))[0])
        i = int(partner[j])
        twice = np.flatnonzero(partner == i)
        return order2, partner, (
            f"the node at {_fmt(body1.x[i])} of contact surface {tag1} (body 1) is the partner "
            f"of {len(twice)} body-2 nodes of surface {tag2}, at "
            f"{', '.join(_fmt(x2[j]) for j in twice)}; node-to-node pairs need one body-1 node "
            "per body-2 node (refine body 1's surface at least as finely as body 2's)"
        )

    facing = np.einsum("ij,ij->i", body1.normal[partner], body2.normal[order2])
    if np.any(facing >= 0):
        j = int(np.flatnonzero(facing >= 0)[0])
        return order2, partner, (
            f"the contact surfaces do not face each other: at the pair of body-1 node "
            f"{_fmt(body1.x[partner[j]])} (surface {tag1}, outward normal "
            f"{_fmt(body1.normal[partner[j]])}) and body-2 node {_fmt(x2[j])} (surface {tag2}, "
            f"outward normal {_fmt(body2.normal[order2[j]])}) the normals point the same way"
        )
    return order2, partner, None


# --------------------------------------------------------------------------------------------
# The pairs
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _PairPattern:
    """Layout and sparsity shared by B and every blockdiag(D) B of one set of pairs.

    Row 3i + k (component k of pair i) holds the columns 3 b_i + (0, 1, 2) and
    3 a_i + (0, 1, 2), stored sorted as PETSc's CSR input requires.
    """

    comm: MPI.Comm
    num_local: int
    num_global: int
    num_owned_dofs: int  # dof blocks of V owned by this rank
    num_global_dofs: int
    indptr: np.ndarray  # (3 num_local + 1,)
    columns: np.ndarray  # (18 num_local,) global column indices, sorted within rows
    value_order: np.ndarray  # (3 num_local, 6) sorts a row's values [M_i[k], -M_i[k]] likewise

    @classmethod
    def create(
        cls, comm: MPI.Comm, dofs_a: np.ndarray, dofs_b: np.ndarray, num_global: int, index_map
    ) -> _PairPattern:
        n = len(dofs_b)
        columns = np.concatenate([3 * dofs_b[:, None] + np.arange(3), 3 * dofs_a[:, None] + np.arange(3)], axis=1)
        columns = np.repeat(columns, 3, axis=0)  # the same six columns for the 3 rows of pair i
        value_order = np.argsort(columns, axis=1, kind="stable")
        columns = np.take_along_axis(columns, value_order, axis=1)
        return cls(
            comm, n, num_global, index_map.size_local, index_map.size_global,
            np.arange(0, 18 * n + 1, 6, dtype=PETSc.IntType),
            columns.ravel().astype(PETSc.IntType), value_order,
        )  # fmt: skip

    def matrix(self, blocks: np.ndarray) -> PETSc.Mat:
        """The AIJ matrix with the 3x3 blocks M_i in b_i's columns and -M_i in a_i's columns."""
        blocks = np.asarray(blocks, dtype=PETSc.ScalarType).reshape(self.num_local, 3, 3)
        values = np.concatenate([blocks, -blocks], axis=2).reshape(-1, 6)  # row 3i+k: [M_i[k], -M_i[k]]
        values = np.take_along_axis(values, self.value_order, axis=1).ravel()
        A = PETSc.Mat().createAIJ(
            size=((3 * self.num_local, 3 * self.num_global), (3 * self.num_owned_dofs, 3 * self.num_global_dofs)),
            csr=(self.indptr, self.columns, values),
            comm=self.comm,
        )
        A.assemble()
        return A


@dataclass(eq=False)
class ContactPairs:
    """The node-to-node contact pairs owned by this rank, and the relative-displacement matrix B.

    Pair i of this rank is global pair ``offset + i``; global pairs are ordered by the rank
    owning node b_i, then by b_i's coordinates (x, then y, then z). Per-pair arrays hold the
    LOCAL pairs. Use :meth:`gather` for all pairs in global order on every rank.

    Attributes
    ----------
    comm
        The mesh communicator.
    surface1, surface2
        Facet tags of body 1's and body 2's contact surfaces.
    num_local, num_global, offset
        Number of pairs on this rank, in total, and global index of this rank's first pair.
    dofs_a, dofs_b
        Global dof-block indices (in V's index map) of nodes a_i (body 1) and b_i (body 2);
        b_i is owned by this rank, a_i may be owned by any rank.
    X_a, X_b
        Node coordinates, shape ``(num_local, 3)``.
    R
        Local frames, shape ``(num_local, 3, 3)``, rows (n, t1, t2), see :func:`local_frames`.
    g0
        Initial gaps, shape ``(num_local,)``.
    B
        PETSc AIJ matrix of w = B u: rows 3 num_local per rank (row 3i + k = component k of
        w_i), columns laid out like V's owned dofs (global index 3 block + component), R_i in
        b_i's columns and -R_i in a_i's columns.
    tolerance
        Length below which nodes count as coincident.
    """

    comm: MPI.Comm
    surface1: int
    surface2: int
    num_local: int
    num_global: int
    offset: int
    dofs_a: np.ndarray
    dofs_b: np.ndarray
    X_a: np.ndarray
    X_b: np.ndarray
    R: np.ndarray
    g0: np.ndarray
    B: PETSc.Mat
    tolerance: float
    _pattern: _PairPattern = field(repr=False)

    # ---- geometry --------------------------------------------------------------------------

    @property
    def positions(self) -> np.ndarray:
        """Pair positions, the midpoints (X_a + X_b)/2, shape ``(num_local, 3)``."""
        return 0.5 * (self.X_a + self.X_b)

    @property
    def normals(self) -> np.ndarray:
        """Unit normals n_i (first rows of R), shape ``(num_local, 3)``."""
        return self.R[:, 0, :]

    @property
    def global_indices(self) -> np.ndarray:
        """Global indices of the local pairs."""
        return self.offset + np.arange(self.num_local, dtype=np.int64)

    # ---- B and products with it ---------------------------------------------------------

    def scaled_B(self, D: npt.ArrayLike) -> PETSc.Mat:
        """blockdiag(D_i) B: blocks D_i R_i and -D_i R_i, with exactly B's sparsity.

        This is the ∂_wH · B block of the monolithic Jacobian when D_i = ∂H_i/∂w_i; its
        transpose (``A.transpose()``) is Bᵀ blockdiag(D_iᵀ).

        Parameters
        ----------
        D
            Shape ``(num_local, 3, 3)``.
        """
        D = np.asarray(D, dtype=np.float64)
        if D.shape != (self.num_local, 3, 3):
            raise ValueError(f"D must have shape ({self.num_local}, 3, 3), got {D.shape}")
        return self._pattern.matrix(D @ self.R)

    def create_lambda_vector(self) -> PETSc.Vec:
        """A PETSc vector with B's row layout (3 entries per local pair), set to zero."""
        lam = self.B.createVecLeft()
        lam.set(0.0)
        return lam

    def relative_displacement(self, u: PETSc.Vec | dolfinx.fem.Function) -> np.ndarray:
        """w = B u, one row w_i = R_i (u(b_i) - u(a_i)) per local pair.

        Parameters
        ----------
        u
            A PETSc vector laid out like V's owned dofs (e.g. ``uh.x.petsc_vec``), or a
            Function on V. Only owned entries are read: no ghost update is needed.

        Returns
        -------
        np.ndarray
            Shape ``(num_local, 3)``: (normal, t1, t2) components.
        """
        if not isinstance(u, PETSc.Vec):
            u = u.x.petsc_vec
        w = self.B.createVecLeft()
        self.B.mult(u, w)
        out = w.getArray(readonly=True).reshape(-1, 3).copy()
        w.destroy()
        return out

    def global_force(self, lam: npt.ArrayLike | PETSc.Vec, out: PETSc.Vec | None = None) -> PETSc.Vec:
        """The global nodal force Bᵀλ (on body 2: +R_iᵀλ_i at b_i; on body 1: -R_iᵀλ_i at a_i).

        Parameters
        ----------
        lam
            Local contact forces λ_i = (p_n, q1, q2), shape ``(num_local, 3)``, or a vector
            from :meth:`create_lambda_vector`.
        out
            Vector laid out like V's owned dofs to overwrite (e.g. a ghosted vector's
            ``petsc_vec``; its ghosts are not updated). A new vector when None.

        Returns
        -------
        PETSc.Vec
            Bᵀλ in V's (owned) layout.
        """
        if isinstance(lam, PETSc.Vec):
            lam_vec = lam
        else:
            lam = np.asarray(lam, dtype=PETSc.ScalarType)
            if lam.shape != (self.num_local, 3):
                raise ValueError(f"lam must have shape ({self.num_local}, 3), got {lam.shape}")
            lam_vec = self.B.createVecLeft()
            lam_vec.getArray()[:] = lam.ravel()
        if out is None:
            out = self.B.createVecRight()
        self.B.multTranspose(lam_vec, out)
        if lam_vec is not lam:
            lam_vec.destroy()
        return out

    # ---- parallel helpers ---------------------------------------------------------------

    def gather(self, values: npt.ArrayLike) -> np.ndarray:
        """All pairs' values in global pair order, on every rank (collective).

        Parameters
        ----------
        values
            Shape ``(num_local, ...)``.

        Returns
        -------
        np.ndarray
            Shape ``(num_global, ...)``.
        """
        values = np.asarray(values)
        if values.shape[:1] != (self.num_local,):
            raise ValueError(f"values must have {self.num_local} rows, got shape {values.shape}")
        return np.concatenate(self.comm.allgather(values), axis=0)

    def destroy(self) -> None:
        """Free the PETSc matrix B."""
        self.B.destroy()


def find_pairs(
    V: dolfinx.fem.FunctionSpace,
    facet_tags: dolfinx.mesh.MeshTags,
    surface1: int,
    surface2: int,
    *,
    tolerance: float | None = None,
    search_distance: float | None = None,
    initial_gap: Callable[[np.ndarray], np.ndarray] | None = None,
) -> ContactPairs:
    """Node-to-node contact pairs between two tagged surfaces (collective on V's communicator).

    Every node b of body 2's contact surface (``surface2``) is paired with the node a of body
    1's contact surface (``surface1``) that coincides with it within ``tolerance``, or else
    with the nearest body-1 node within ``search_distance`` that does not lie in front of it
    (g0 >= -tolerance). Body-1 nodes may stay unpaired; every body-2 node must find exactly
    one partner of its own.

    Parameters
    ----------
    V
        Vector P1 space (continuous Lagrange of degree 1, block size 3) on a 3D mesh holding
        both bodies, which share no nodes.
    facet_tags
        Facet tags holding ``surface1`` and ``surface2``.
    surface1, surface2
        Tags of body 1's and body 2's contact surfaces. Body 1's outward normal is the pair
        normal.
    tolerance
        Distance below which nodes coincide; default 1e-8 times the diagonal of the mesh's
        bounding box.
    search_distance
        Largest distance of non-coincident partners; None: only coincident nodes pair.
    initial_gap
        Optional g0(x): ``x`` of shape ``(3, N)`` (pair positions, the midpoints of a and b)
        -> gaps of shape ``(N,)``, replacing the geometric gap n · (X_b - X_a), e.g. for
        Hertz-type verification on coincident nodes. Negative values (interference) are
        accepted.

    Returns
    -------
    ContactPairs
        The pairs whose node b_i this rank owns, with the distributed matrix B.

    Raises
    ------
    ContactPairError
        (a ``ValueError``, on every rank) if V is not vector P1, the tags are equal, a tag is
        missing on all ranks, a contact facet is interior, the surfaces share nodes, a body-2
        node has no partner, a body-1 node is matched twice, a body-2 node lies behind body
        1's surface, or paired nodes' normals do not face each other.
    """
    comm = V.mesh.comm
    tags = (int(surface1), int(surface2))
    # --- checks on data that is identical on all ranks: raise directly
    if tags[0] == tags[1]:
        raise ContactPairError(
            f"surface1 and surface2 are the same tag {tags[0]}; the two bodies need their own tags"
        )
    problem = _check_space(V)
    if problem is not None:
        raise ContactPairError(problem)
    if facet_tags.dim != V.mesh.topology.dim - 1:
        raise ContactPairError(
            f"facet_tags has dimension {facet_tags.dim}, expected facets ({V.mesh.topology.dim - 1})"
        )

    # --- geometric tolerance from the global bounding box
    x = V.mesh.geometry.x
    lo = np.array(x.min(axis=0) if len(x) else np.full(3, np.inf), dtype=np.float64)
    hi = np.array(x.max(axis=0) if len(x) else np.full(3, -np.inf), dtype=np.float64)
    comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
    comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
    if tolerance is None:
        tolerance = 1e-8 * float(np.linalg.norm(hi - lo))
    tolerance = float(tolerance)
    if not tolerance > 0:
        raise ContactPairError(f"tolerance must be positive, got {tolerance}")
    if search_distance is not None and not search_distance > 0:
        raise ContactPairError(f"search_distance must be positive or None, got {search_distance}")

    # --- gather both contact surfaces everywhere
    local_error = None
    try:
        local = _Facets.concatenate([_local_facets(V, facet_tags, tags[s], s + 1) for s in (0, 1)])
    except Exception as exc:  # noqa: BLE001  (re-raised on every rank)
        local_error = f"reading the contact facets failed: {type(exc).__name__}: {exc}"
        local = None
    _raise_together(comm, local_error)
    facets = _Facets.concatenate(comm.allgather(local))

    for s, tag in enumerate(tags):
        if not np.any(facets.surface == s + 1):
            present = sorted(set(np.concatenate(comm.allgather(np.unique(facet_tags.values))).tolist()))
            raise ContactPairError(
                f"no facet is tagged {tag} (surface{s + 1}) on any rank; the facet tags present are {present}"
            )
    # From here on every rank works on the same data: errors arise identically everywhere.
    facets, error = _unique_facets(facets, tags)
    if error:
        raise ContactPairError(error)
    body1, error = _surface_nodes(facets, 1, tags[0])
    if error:
        raise ContactPairError(error)
    body2, error = _surface_nodes(facets, 2, tags[1])
    if error:
        raise ContactPairError(error)
    shared = np.intersect1d(body1.index, body2.index)
    if len(shared):
        i = _first_by_position(body1.x, np.isin(body1.index, shared))
        raise ContactPairError(
            f"contact surfaces {tags[0]} and {tags[1]} share {len(shared)} node(s), e.g. at "
            f"{_fmt(body1.x[i])}: the two bodies must be meshed without common nodes"
        )

    order2, partner, error = _match(body1, body2, tags, tolerance, search_distance)
    if error:
        raise ContactPairError(error)

    # --- all pairs, in body-2 coordinate order
    index_a, index_b = body1.index[partner], body2.index[order2]
    X_a, X_b = body1.x[partner], body2.x[order2]
    R = local_frames(body1.normal[partner])
    if initial_gap is None:
        g0 = np.einsum("ij,ij->i", R[:, 0], X_b - X_a)
        # coincident nodes (within the tolerance) have no gap: drop the mesh generator's
        # round-off, which would otherwise enter the Signorini condition
        g0[np.linalg.norm(X_b - X_a, axis=1) <= tolerance] = 0.0
    else:
        g0 = np.asarray(initial_gap((0.5 * (X_a + X_b)).T.copy()), dtype=np.float64)
        if g0.shape != (len(index_b),) or not np.all(np.isfinite(g0)):
            raise ContactPairError(
                f"initial_gap must return {len(index_b)} finite values for x of shape (3, {len(index_b)}), "
                f"got an array of shape {g0.shape}"
            )

    # --- ownership: the rank owning b_i's dof block; global order by owner, then coordinates
    index_map = V.dofmap.index_map
    starts = np.array(comm.allgather(index_map.local_range[0]), dtype=np.int64)
    owner = np.searchsorted(starts, index_b, side="right") - 1
    order = np.argsort(owner, kind="stable")
    counts = np.bincount(owner, minlength=comm.size)
    offset = int(counts[: comm.rank].sum())
    mine = order[offset : offset + counts[comm.rank]]

    dofs_a, dofs_b = index_a[mine], index_b[mine]
    pattern = _PairPattern.create(comm, dofs_a, dofs_b, int(counts.sum()), index_map)
    return ContactPairs(
        comm=comm,
        surface1=tags[0],
        surface2=tags[1],
        num_local=len(mine),
        num_global=int(counts.sum()),
        offset=offset,
        dofs_a=dofs_a,
        dofs_b=dofs_b,
        X_a=X_a[mine],
        X_b=X_b[mine],
        R=R[mine],
        g0=g0[mine],
        B=pattern.matrix(R[mine]),
        tolerance=tolerance,
        _pattern=pattern,
    )
