"""Node-to-node contact pairs: the seed's discretisation (``formulation.md`` §2).

A contact pair i joins node a_i of body 1's contact surface (the master side, ``surface1``) and
node b_i of body 2's contact surface (the slave side, ``surface2``). Its local frame R_i has the
rows (n_i, t1_i, t2_i), with n_i body 1's outward unit normal at a_i; the initial gap is
g0_i = n_i · (X_b - X_a), and the relative displacement in the local frame is

    w_i = R_i (u(b_i) - u(a_i)),   i.e.   w = B u,

with B of size 3 NC x ndof: the block R_i in b_i's columns and -R_i in a_i's columns.

Both surfaces are gathered on every rank (:mod:`dolfinx_nnqem.contact.surfaces`) and ALL pairs
are computed from identical data in a deterministic order; a rank keeps the pairs whose node b_i
it owns. Pairs are therefore identical for any number of ranks, errors are raised identically on
every rank, and no ghost layer is needed for node a_i: B is a distributed PETSc matrix whose
columns live wherever V's dofs live.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from dolfinx_nnqem import compat  # noqa: F401, I001  (first: loads MPI/PETSc for the PyPI wheel)

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.contact.nearest import nearest
from dolfinx_nnqem.contact.pairset import PairRows, rows_matrix
from dolfinx_nnqem.contact.surfaces import (ContactPairError, SurfaceNodes, check_no_shared_nodes, format_point,
                                            gather_surfaces, local_frames, mesh_tolerance)

__all__ = ["ContactPairError", "ContactPairs", "find_pairs", "local_frames", "owned_by_slave"]


# --------------------------------------------------------------------------------------------
# Matching
# --------------------------------------------------------------------------------------------


def _match(
    body1: SurfaceNodes,
    body2: SurfaceNodes,
    tags: tuple[int, int],
    tolerance: float,
    search_distance: float | None,
) -> tuple[np.ndarray, np.ndarray, str | None]:
    """For every body-2 node, the body-1 node facing it.

    Returns the indices into ``body1`` and ``body2`` of the pairs (body-2 nodes in a
    deterministic coordinate order) and an error message or None.
    """
    # body-2 nodes in lexicographic order of their coordinates (rounded to the tolerance, so
    # that the order does not depend on round-off in the mesh generator)
    key = np.round(body2.x / tolerance)
    order2 = np.lexsort((body2.x[:, 2], body2.x[:, 1], body2.x[:, 0], key[:, 2], key[:, 1], key[:, 0]))
    x2 = body2.x[order2]

    dist, closest = nearest(body1.x, x2)
    partner = np.where(dist <= tolerance, closest, -1)

    unmatched = np.flatnonzero(partner < 0)
    error = None
    if len(unmatched) and search_distance is not None:
        error = _partners_within_search(body1, x2, partner, unmatched, tags, tolerance, search_distance)
    if error is None:
        error = _pairing_error(body1, body2, order2, partner, tags, tolerance, search_distance)
    return order2, partner, error


def _partners_within_search(body1: SurfaceNodes, x2: np.ndarray, partner: np.ndarray, unmatched: np.ndarray,
                            tags: tuple[int, int], tolerance: float, search_distance: float) -> str | None:
    """Fill ``partner`` of the body-2 nodes ``unmatched`` (no coincident body-1 node) with the
    nearest body-1 node within ``search_distance`` ahead of its surface (ties by coordinates);
    the error message of a node that lies behind body 1's surface, or None."""
    from scipy.spatial import cKDTree  # non-coincident pairs only: SciPy's import is not paid otherwise

    tag1, tag2 = tags
    candidates = cKDTree(body1.x).query_ball_point(x2[unmatched], r=search_distance)
    for k, found in zip(unmatched, candidates):
        if not found:
            continue
        found = np.asarray(found)
        d = x2[k] - body1.x[found]
        g0 = np.einsum("ij,ij->i", body1.normal[found], d)
        ahead = g0 >= -tolerance
        if not np.any(ahead):
            i = found[np.argmin(np.linalg.norm(d, axis=1))]
            return (
                f"the node at {format_point(x2[k])} of surface {tag2} (body 2) lies behind surface "
                f"{tag1} (body 1): its nearest body-1 node at {format_point(body1.x[i])} with outward "
                f"normal {format_point(body1.normal[i])} gives the initial gap "
                f"{float(np.dot(body1.normal[i], x2[k] - body1.x[i])):.6g} < 0. Are the bodies "
                "overlapping, or are surface1 and surface2 swapped?"
            )
        found, d = found[ahead], d[ahead]
        distance = np.linalg.norm(d, axis=1)
        xc = body1.x[found]
        best = np.lexsort((xc[:, 2], xc[:, 1], xc[:, 0], distance))[0]  # ties: by coordinates
        partner[k] = found[best]
    return None


def _pairing_error(body1: SurfaceNodes, body2: SurfaceNodes, order2: np.ndarray, partner: np.ndarray,
                   tags: tuple[int, int], tolerance: float, search_distance: float | None) -> str | None:
    """Why the pairs (body-2 nodes ``order2``, their body-1 ``partner``) are not node-to-node pairs:
    a body-2 node without a partner, a body-1 node taken twice, or surfaces that do not face each
    other; None if they are."""
    tag1, tag2 = tags
    x2 = body2.x[order2]
    if np.any(partner < 0):
        j = int(np.flatnonzero(partner < 0)[0])
        within = (
            f"within the search distance {search_distance:.6g}"
            if search_distance is not None
            else f"coincident with it (tolerance {tolerance:.3g}; pass search_distance for non-coincident pairs)"
        )
        return (
            f"the node at {format_point(x2[j])} of contact surface {tag2} (body 2) has no partner: "
            f"no node of surface {tag1} (body 1) is {within}"
        )

    used, counts = np.unique(partner, return_counts=True)
    if np.any(counts > 1):
        # the first body-2 node (in coordinate order) whose partner is taken twice
        j = int(np.flatnonzero(np.isin(partner, used[counts > 1]))[0])
        i = int(partner[j])
        twice = np.flatnonzero(partner == i)
        return (
            f"the node at {format_point(body1.x[i])} of contact surface {tag1} (body 1) is the partner "
            f"of {len(twice)} body-2 nodes of surface {tag2}, at "
            f"{', '.join(format_point(x2[j]) for j in twice)}; node-to-node pairs need one body-1 node "
            "per body-2 node (refine body 1's surface at least as finely as body 2's)"
        )

    facing = np.einsum("ij,ij->i", body1.normal[partner], body2.normal[order2])
    if np.any(facing >= 0):
        j = int(np.flatnonzero(facing >= 0)[0])
        return (
            f"the contact surfaces do not face each other: at the pair of body-1 node "
            f"{format_point(body1.x[partner[j]])} (surface {tag1}, outward normal "
            f"{format_point(body1.normal[partner[j]])}) and body-2 node {format_point(x2[j])} (surface {tag2}, "
            f"outward normal {format_point(body2.normal[order2[j]])}) the normals point the same way"
        )
    return None


# --------------------------------------------------------------------------------------------
# The pairs
# --------------------------------------------------------------------------------------------


def owned_by_slave(comm: MPI.Comm, index_map: dolfinx.common.IndexMap, slave_blocks: np.ndarray) -> tuple[np.ndarray, int, int]:
    """Ownership of pairs given (on every rank, in the same order) by their slave dof blocks.

    Returns the indices of this rank's pairs (in global pair order: by owner rank, then in
    the given order), the global index of this rank's first pair, and the number of pairs.
    """
    starts = np.array(comm.allgather(index_map.local_range[0]), dtype=np.int64)
    owner = np.searchsorted(starts, slave_blocks, side="right") - 1
    order = np.argsort(owner, kind="stable")
    counts = np.bincount(owner, minlength=comm.size)
    offset = int(counts[: comm.rank].sum())
    return order[offset: offset + counts[comm.rank]], offset, int(counts.sum())


@dataclass(eq=False)
class ContactPairs:
    """The node-to-node contact pairs owned by this rank, and the relative-displacement matrix B.

    A :class:`~dolfinx_nnqem.contact.pairset.PairSet`. Pair i of this rank is global pair
    ``offset + i``; global pairs are ordered by the rank owning node b_i, then by b_i's
    coordinates (x, then y, then z). Per-pair arrays hold the LOCAL pairs. Use :meth:`gather`
    for all pairs in global order on every rank.

    Attributes
    ----------
    comm
        The mesh communicator.
    surface1, surface2
        Facet tags of body 1's (master) and body 2's (slave) contact surfaces.
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
    area
        Tributary areas of the nodes b_i on body 2's surface, shape ``(num_local,)``.
    rows
        B's local rows (:class:`~dolfinx_nnqem.contact.pairset.PairRows`).
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
    area: np.ndarray
    rows: PairRows
    B: PETSc.Mat
    tolerance: float
    kind: str = "node-to-node"
    pins_supported_slave_tangents: bool = False  #: see contact.constrained_directions.supported_slave_tangents

    # ---- the pair-set contract -----------------------------------------------------------

    @property
    def X_slave(self) -> np.ndarray:
        """(num_local, 3) the slave nodes' positions, X_b."""
        return self.X_b

    @property
    def X_master(self) -> np.ndarray:
        """(num_local, 3) the master nodes' positions, X_a."""
        return self.X_a

    @property
    def slave_blocks(self) -> np.ndarray:
        """(num_local,) the slave nodes' global dof blocks, dofs_b."""
        return self.dofs_b

    def motion(self, load_factor: float) -> np.ndarray:
        """Zero: both sides are deformable, their motion is in u."""
        return np.zeros((self.num_local, 3))

    def motion_amplitudes(self, load_factor: float) -> np.ndarray:
        """Empty: neither side moves besides u."""
        return np.zeros(0)

    def describe(self) -> str:
        """The kind, the number of pairs and the two surfaces, in one line."""
        return f"node-to-node, {self.num_global} pairs between surfaces {self.surface1} and {self.surface2}"

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

    # ---- products with B ---------------------------------------------------------------

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
            laid out like B's rows.
        out
            Vector laid out like V's owned dofs to overwrite (e.g. a ghosted vector's
            ``petsc_vec``; its ghosts are not updated). A new vector when None.
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


def node_to_node_rows(dofs_a: np.ndarray, dofs_b: np.ndarray, R: np.ndarray) -> PairRows:
    """B's rows of node-to-node pairs: R_i in b_i's columns, -R_i in a_i's."""
    columns = np.concatenate([3 * dofs_b[:, None] + np.arange(3), 3 * dofs_a[:, None] + np.arange(3)], axis=1)
    return PairRows.from_blocks(columns, np.concatenate([R, -R], axis=2))


def _transformed_rows(combination, order2: np.ndarray, index_a: np.ndarray, index_b: np.ndarray, R: np.ndarray,
                      g0: np.ndarray, mine: np.ndarray) -> tuple[PairRows, np.ndarray]:
    """B's rows and the gaps of node-to-node pairs on a tri6 slave surface: each pair (in the
    coordinate order ``order2`` of body 2's nodes) combines the physical pairs of the slave nodes of
    its row of d̂ = T⁻ᵀ d, with its own frame; the local pairs ``mine``."""
    pair_of = np.empty(len(order2), dtype=np.int64)
    pair_of[order2] = np.arange(len(order2))  # body-2 node position -> its physical pair
    rows = combination.take(order2)
    g0 = rows.apply(g0[pair_of])
    local = rows.take(mine)
    pairs = pair_of[local.columns]
    counts = 2 * np.diff(local.indptr)
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    nodes = np.column_stack([index_b[pairs], index_a[pairs]]).ravel()
    coefficients = np.column_stack([local.coefficients, -local.coefficients]).ravel()
    return PairRows.from_weighted_nodes(R[mine], indptr, nodes, coefficients), g0


def _check_search(V, tags: tuple[int, int], tolerance: float | None, search_distance: float | None) -> float:
    """Refuse equal tags and non-positive distances; the tolerance (default: the mesh's)."""
    if tags[0] == tags[1]:
        raise ContactPairError(
            f"surface1 and surface2 are the same tag {tags[0]}; the two bodies need their own tags"
        )
    tolerance = float(mesh_tolerance(V.mesh) if tolerance is None else tolerance)
    if not tolerance > 0:
        raise ContactPairError(f"tolerance must be positive, got {tolerance}")
    if search_distance is not None and not search_distance > 0:
        raise ContactPairError(f"search_distance must be positive or None, got {search_distance}")
    return tolerance


def _initial_gaps(R: np.ndarray, X_a: np.ndarray, X_b: np.ndarray, tolerance: float,
                  initial_gap: Callable[[np.ndarray], np.ndarray] | None) -> np.ndarray:
    """g0 = n · (X_b − X_a), 0 for coincident nodes, or the user's ``initial_gap`` at the midpoints."""
    if initial_gap is None:
        g0 = np.einsum("ij,ij->i", R[:, 0], X_b - X_a)
        # coincident nodes (within the tolerance) have no gap: drop the mesh generator's
        # round-off, which would otherwise enter the Signorini condition
        g0[np.linalg.norm(X_b - X_a, axis=1) <= tolerance] = 0.0
        return g0
    g0 = np.asarray(initial_gap((0.5 * (X_a + X_b)).T.copy()), dtype=np.float64)
    if g0.shape != (len(X_b),) or not np.all(np.isfinite(g0)):
        raise ContactPairError(
            f"initial_gap must return {len(X_b)} finite values for x of shape (3, {len(X_b)}), "
            f"got an array of shape {g0.shape}"
        )
    return g0


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
        Vector P1 or P2 space (continuous Lagrange, block size 3) on a 3D mesh holding both
        bodies, which share no nodes. With P2 every surface node (vertices and edge nodes) gets
        a pair; on tetrahedra the pairs act on the transformed nodal displacements of
        :mod:`~dolfinx_nnqem.contact.quadratic_facets` (the mortar constraint of matching meshes).
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
    tags = (int(surface1), int(surface2))
    tolerance = _check_search(V, tags, tolerance, search_distance)
    surfaces = gather_surfaces(V, facet_tags, tags)
    check_no_shared_nodes(surfaces)
    body1, body2 = surfaces.nodes

    order2, partner, error = _match(body1, body2, tags, tolerance, search_distance)
    if error:
        raise ContactPairError(error)
    return _owned_pairs(V, body1, body2, order2, partner, tags, tolerance, initial_gap)


def _owned_pairs(V: dolfinx.fem.FunctionSpace, body1: SurfaceNodes, body2: SurfaceNodes, order2: np.ndarray,
                 partner: np.ndarray, tags: tuple[int, int], tolerance: float,
                 initial_gap: Callable[[np.ndarray], np.ndarray] | None) -> ContactPairs:
    """The :class:`ContactPairs` of the matched nodes (body-2 nodes ``order2``, their body-1
    ``partner``) whose node b this rank owns: frames, initial gaps, the rows of B (collective)."""
    comm = V.mesh.comm
    # --- all pairs, in body-2 coordinate order
    index_a, index_b = body1.index[partner], body2.index[order2]
    X_a, X_b = body1.x[partner], body2.x[order2]
    R = local_frames(body1.normal[partner])
    g0 = _initial_gaps(R, X_a, X_b, tolerance, initial_gap)

    # --- ownership: the rank owning b_i's dof block; global order by owner, then coordinates
    mine, offset, num_global = owned_by_slave(comm, V.dofmap.index_map, index_b)
    dofs_a, dofs_b = index_a[mine], index_b[mine]
    combination = body2.combination
    if len(combination.columns) == len(body2.index):  # linear or quad9 facets: the two nodes alone
        rows = node_to_node_rows(dofs_a, dofs_b, R[mine])
    else:  # tri6: pair j acts on Σ_i t_ji (u(b_i) − u(a_i)) (quadratic_facets), gap Σ_i t_ji g0_i
        rows, g0 = _transformed_rows(combination, order2, index_a, index_b, R, g0, mine)
    return ContactPairs(
        comm=comm,
        surface1=tags[0],
        surface2=tags[1],
        num_local=len(mine),
        num_global=num_global,
        offset=offset,
        dofs_a=dofs_a,
        dofs_b=dofs_b,
        X_a=X_a[mine],
        X_b=X_b[mine],
        R=R[mine],
        g0=g0[mine],
        area=body2.area[order2][mine],
        rows=rows,
        B=rows_matrix(comm, rows, num_global, V.dofmap.index_map),
        tolerance=tolerance,
    )
