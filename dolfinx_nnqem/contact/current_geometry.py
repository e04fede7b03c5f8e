r"""Contact geometry in the current configuration x = X + u (issue 27, first part).

``Contact(geometry="current")`` re-evaluates an interface's pairs at the current configuration
instead of once in the reference one (``docs/theory.md``, "Large sliding"):

* a rigid obstacle (plane, sphere, cylinder on its path d(ℓ)): the slave node x_s = X_s + u_s is
  projected onto the obstacle at d(ℓ): signed distance g*, normal n*, frame R*;
* node-to-surface: the slave nodes x_s are projected onto the master facets at x_k = X_k + u_k,
  which may be other facets than before (pairs appear, disappear, change their master facet);
* dual mortar: the segments, the dual basis, D, M, the weighted gaps and the nodal normals are
  computed again on the moved facets (slave nodes that the master no longer covers lose their
  pair, newly covered ones gain one).

Between two evaluations the geometry is frozen: B has the rows of the frames R* and weights
N_k(ξ*) of the evaluation point u*, and the gap is its first-order expansion about u*,

    g(u) = g* + n* · (w(u) − w(u*))_n   i.e.   g0 := g* − (B u* + m(ℓ*))_n,

so that the model's g = g0 + (B u + m)_n equals the current distance at u = u*. For a rigid
obstacle n* is the exact derivative of the signed distance, so re-evaluating at the converged u
and solving again is a Newton iteration on the geometry (:func:`dolfinx_nnqem.solvers.stepping`
repeats the increment until a solve starts converged). The monolithic solver evaluates obstacles,
node-to-surface and mortar pairs at every Newton iterate instead, with the derivatives of the
geometry in its Newton matrix (:mod:`~dolfinx_nnqem.contact.geometric_stiffness`,
:mod:`~dolfinx_nnqem.contact.surface_stiffness`, :mod:`~dolfinx_nnqem.contact.mortar_linearisation`).

Pairs are known by their slave node (per interface): the pair unknowns z (in the pair's local
frame) and the states follow the slave node from one evaluation to the next; a new pair starts
force-free. Every rank evaluates node-to-surface pairs from the gathered surfaces
(:func:`~dolfinx_nnqem.contact.surfaces.gather_surfaces`) with the displacements of their nodes
summed over the ranks, so a slave node finds a master facet held by another rank.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from dolfinx_nnqem import compat  # noqa: F401, I001  (first: loads MPI/PETSc for the PyPI wheel)

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.contact.obstacles import ObstaclePairs
from dolfinx_nnqem.contact.pairset import PairRows, rows_matrix
from dolfinx_nnqem.contact.surface_pairs import RUN_INTERFERENCE, SurfacePairs, facet_size
from dolfinx_nnqem.contact.surfaces import (GatheredSurfaces, check_no_shared_nodes, gather_surfaces, local_frames,
                                            mesh_tolerance)

if TYPE_CHECKING:
    import dolfinx

__all__ = ["GEOMETRIES", "CombinedObstacleTracker", "MortarTracker", "ObstacleTracker", "SurfaceTracker", "displacement_at", "match_pairs",
           "moved_surfaces", "remapper", "surface_tracker"]

GEOMETRIES = ("auto", "reference", "current")
"""``Contact(geometry=...)``: ``"reference"``, pairs computed once in the reference configuration;
``"current"``, re-evaluated in the current one from the start; ``"auto"`` (the default), the
reference pairs while the surfaces slide less than
:data:`~dolfinx_nnqem.contact.slip_check.SLIP_LIMIT` × the facet size, re-evaluated in the current
configuration once they slide more (``docs/reliability.md``, "Which contact geometry")."""


EDGE_ALLOWANCE = 0.05
"""Node-to-surface in the current geometry: a slave node up to this fraction of the master's facet
size beyond the master's boundary keeps a pair (projected onto the boundary). Without it a slave
node on the master's edge, which the Poisson effect moves across the edge, gains and loses its
pair from one solve of the increment to the next and the geometry never settles."""


GAP_ROUNDING = 2e-15
"""In the current geometry a gap |g*| ≤ this × the mesh's bounding-box diagonal is zero: the
round-off of x = X + u and of the projection (a few ulps of the coordinates), which r turns into
contact residuals that no solve removes (a master 10⁶ times stiffer than the slave: without it the
geometry did not settle in the first increment). The reference geometry rounds far more, |g0| ≤
10⁻⁸ × the diagonal (``Contact.tolerance``: the mesh generator's round-off on touching surfaces);
in the current configuration that accepted states up to 10⁻⁸ × the diagonal off the master (mortar
patch test after a slide, unstructured tetrahedra: pressures 6.4e-6 off uniform; 2.4e-9 with this
rounding, as with none, 5.9e-9 with 10⁻¹⁴ and 2.5e-8 with 10⁻¹³)."""


def displacement_at(u: dolfinx.fem.Function, blocks: np.ndarray) -> np.ndarray:
    """u at the global dof blocks ``blocks`` (the same on every rank), (len(blocks), 3), on every rank.

    Each rank fills the blocks it owns and the sum over the ranks puts every value everywhere
    (collective); a block has one owner, so the sum adds zeros and is exact.

    Parameters
    ----------
    u
        A DOLFINx vector function on the P1 space.
    blocks
        Global dof-block indices.
    """
    index_map = u.function_space.dofmap.index_map
    start, end = index_map.local_range
    blocks = np.asarray(blocks, dtype=np.int64)
    owned = (blocks >= start) & (blocks < end)
    local = np.zeros((len(blocks), 3))
    local[owned] = u.x.array.reshape(-1, 3)[blocks[owned] - start]
    out = np.empty_like(local)
    u.function_space.mesh.comm.Allreduce(local, out, op=MPI.SUM)
    return out


def moved_surfaces(surfaces: GatheredSurfaces, u: dolfinx.fem.Function) -> GatheredSurfaces:
    """The gathered surfaces with every vertex at X + u (collective).

    The facets' outward area vectors and the nodes' normals stay the reference ones: they only
    orient the facets (their vertices' cyclic order) and check that the surfaces face each other,
    which a small strain does not change; normals and gaps come from the moved vertices.
    """
    facets = surfaces.facets
    m, k = facets.nodes.shape
    moved = replace(facets, x=facets.x + displacement_at(u, facets.nodes.ravel()).reshape(m, k, 3))
    nodes = [replace(n, x=n.x + displacement_at(u, n.index)) for n in surfaces.nodes]
    return GatheredSurfaces(surfaces.tags, moved, nodes)


def with_moved_normals(surfaces: GatheredSurfaces) -> GatheredSurfaces:
    """The surfaces with every facet's area vector computed again from its (moved) vertices.

    :func:`moved_surfaces` keeps the reference area vectors (they only orient the facets there);
    mortar takes its nodal normals from them, so on a moved surface they must be the current
    ones. Each facet keeps its outward side: its vertices are put in the cyclic order that the
    reference area vector orients (:func:`~dolfinx_nnqem.contact.projection.cyclic_order`). A quadratic
    facet's area vector is that of its vertices, as in the reference configuration
    (:func:`~dolfinx_nnqem.contact.surfaces.gather_surfaces`): its edge and centre nodes move with it
    (:func:`moved_surfaces`), the quadratic mortar integrals take them from there.
    """
    from dolfinx_nnqem.contact.projection import cyclic_order, newell_area_vectors

    facets = surfaces.facets
    vertices = facets.x[:, :facets.num_vertices]
    order = cyclic_order(vertices, facets.area)
    area = newell_area_vectors(np.take_along_axis(vertices, order[:, :, None], axis=1))
    return GatheredSurfaces(surfaces.tags, replace(facets, area=area), surfaces.nodes)


def rebased(pairs: SurfacePairs, V: dolfinx.fem.FunctionSpace, u: dolfinx.fem.Function) -> SurfacePairs:
    """The pairs with g0 := g* − (B u*)_n, so that g = g0 + (B u)_n is the gap g* at u = u* (module)."""
    B = rows_matrix(pairs.comm, pairs.rows, pairs.num_global, V.dofmap.index_map)
    w = B.createVecLeft()
    B.mult(u.x.petsc_vec, w)
    w_n = w.getArray(readonly=True).reshape(-1, 3)[:, 0].copy()
    for obj in (B, w):
        obj.destroy()
    return replace(pairs, g0=pairs.g0 - w_n)


def match_pairs(old_keys: np.ndarray, new_keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which new pairs existed before, and where: (found (bool), source index into the old pairs)."""
    if len(old_keys) == 0:
        return np.zeros(len(new_keys), dtype=bool), np.zeros(len(new_keys), dtype=np.int64)
    order = np.argsort(old_keys, kind="stable")
    at = np.minimum(np.searchsorted(old_keys[order], new_keys), len(old_keys) - 1)
    return old_keys[order][at] == new_keys, order[at]


def remapper(old_keys: np.ndarray, new_keys: np.ndarray) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``remap(old, fill)``: the rows of ``old`` (one per old pair) for the new pairs, by key, and those
    of ``fill`` (one row, or an array laid out like the new pairs) for new pairs."""
    found, source = match_pairs(old_keys, new_keys)

    def remap(old: np.ndarray, fill: np.ndarray) -> np.ndarray:
        out = np.broadcast_to(np.asarray(fill, dtype=old.dtype), (len(new_keys),) + old.shape[1:]).copy()
        out[found] = old[source[found]]
        return out

    return remap


@dataclass(frozen=True)
class ObstacleTracker:
    """Re-evaluates a rigid obstacle's pairs at (u, ℓ); the pairs keep their slave nodes."""

    reference: ObstaclePairs

    def pairs_at(self, u: dolfinx.fem.Function, load_factor: float) -> ObstaclePairs:
        """The pairs with the slave nodes at X + u and the obstacle at d(ℓ), gaps rebased (module)."""
        pairs = self.reference
        start = u.function_space.dofmap.index_map.local_range[0]
        u_s = u.x.array.reshape(-1, 3)[pairs.slave_blocks - start]  # the pairs' slave nodes are owned
        relative = u_s - pairs.obstacle.displacement(load_factor)  # the slave node seen from the obstacle
        g, n, p = pairs.obstacle.project(pairs.X_slave + relative)
        R = local_frames(n) if len(n) else np.zeros((0, 3, 3))
        columns = 3 * pairs.slave_blocks[:, None] + np.arange(3)
        return replace(pairs, R=R, g0=g - np.einsum("ij,ij->i", n, relative), X_master=p,
                       rows=PairRows.from_blocks(columns, R))


@dataclass(frozen=True)
class CombinedObstacleTracker:
    """Re-evaluates a rigid obstacle's pairs on 6-node triangle facets (P2 tetrahedra) at (u, ℓ).

    Pair i acts on the transformed displacement d̂_i = Σ_k a_ik u(k) of its nodes
    (:class:`~dolfinx_nnqem.contact.obstacles.CombinedNodes`): it is the point X̂_i + d̂_i, projected
    onto the obstacle at rest like a slave node at degree 1, with the rows R_i a_ik on its nodes. The
    monolithic solver and NNEQM1 evaluate it at every Newton iterate, with its geometric terms on the
    combined nodes (:mod:`~dolfinx_nnqem.contact.combined_stiffness`); with NNEQM2 it is frozen within
    a solve, and load stepping evaluates it again at the solution and solves again until a solve
    starts converged.
    """

    reference: ObstaclePairs

    def displacement(self, pairs: ObstaclePairs, u: dolfinx.fem.Function) -> np.ndarray:
        """d̂ (num_local, 3) of the ``pairs`` (this tracker's, evaluated anywhere: they combine the same
        nodes) at the displacement u (collective)."""
        nodes = pairs.combination
        assert nodes is not None  # a tri6 surface's pairs
        blocks = np.unique(np.concatenate(pairs.comm.allgather(nodes.blocks)))  # the same on every rank
        u_nodes = displacement_at(u, blocks)[np.searchsorted(blocks, nodes.blocks)]
        pair = np.repeat(np.arange(pairs.num_local), np.diff(nodes.indptr))
        u_hat = np.zeros((pairs.num_local, 3))
        np.add.at(u_hat, pair, nodes.coefficients[:, None] * u_nodes)
        return u_hat

    def pairs_at(self, u: dolfinx.fem.Function, load_factor: float) -> ObstaclePairs:
        """The pairs at X̂ + d̂(u) and the obstacle at d(ℓ), gaps rebased (module; collective)."""
        pairs = self.reference
        nodes = pairs.combination
        assert nodes is not None  # a tri6 surface's pairs
        u_hat = self.displacement(pairs, u)
        relative = u_hat - pairs.obstacle.displacement(load_factor)  # the pair's point seen from the obstacle
        g, n, p = pairs.obstacle.project(nodes.X + relative)
        R = local_frames(n) if len(n) else np.zeros((0, 3, 3))
        return replace(pairs, R=R, g0=g - np.einsum("ij,ij->i", n, relative), X_master=p,
                       rows=PairRows.from_weighted_nodes(R, nodes.indptr, nodes.blocks, nodes.coefficients))


@dataclass
class SurfaceTracker:
    """Re-evaluates node-to-surface pairs at u from the reference gathered surfaces (master, slave).

    It remembers each slave node's master facet: a slave node keeps it while it still projects
    onto it (:func:`~dolfinx_nnqem.contact.node_to_surface.keep_preferred`).
    """

    V: Any  #: the displacement space
    surfaces: GatheredSurfaces
    gap_rounding: float  #: gaps within it are zero (:data:`GAP_ROUNDING`)
    search_distance: float | None
    note: str
    supported: np.ndarray | None
    facets: np.ndarray | None = None  #: (slave nodes,) the master facet of the last evaluation (−1: none)

    def pairs_at(self, u: dolfinx.fem.Function, load_factor: float) -> SurfacePairs:
        """The node-to-surface pairs of the moved surfaces, gaps rebased (module; collective)."""
        from dolfinx_nnqem.contact.node_to_surface import node_to_surface_pairs  # numba: only when used

        master_size = facet_size(self.surfaces.facets_of(0))
        pairs = node_to_surface_pairs(self.V, moved_surfaces(self.surfaces, u), tolerance=self.gap_rounding,
                                      search_distance=self.search_distance, note=self.note,
                                      supported=self.supported, edge_allowance=EDGE_ALLOWANCE * master_size,
                                      preferred=self.facets, max_interference=RUN_INTERFERENCE)
        self.facets = self.gathered_facets(pairs)
        return rebased(pairs, self.V, u)

    @property
    def combines_nodes(self) -> bool:
        """True if the pairs act on combinations of slave nodes (6-node triangle slave facets, P2
        tetrahedra: the transformed basis). Re-evaluated at every Newton iterate, such a pair couples
        every node of its combination with each one's own master facet
        (:mod:`~dolfinx_nnqem.contact.combined_surface_stiffness`; one slave node and one master facet
        per pair otherwise: :mod:`~dolfinx_nnqem.contact.surface_stiffness`)."""
        combination = self.surfaces.nodes[1].combination
        return len(combination.columns) != len(self.surfaces.nodes[1].index)

    def gathered_facets(self, pairs: SurfacePairs) -> np.ndarray:
        """Every slave node's master facet (−1: no pair), the same on every rank (collective)."""
        assert pairs.master_facet is not None  # node-to-surface pairs carry it
        blocks = np.concatenate(pairs.comm.allgather(pairs.slave_blocks))
        facets = np.concatenate(pairs.comm.allgather(pairs.master_facet))
        index = self.surfaces.nodes[1].index  # sorted (np.unique)
        out = np.full(len(index), -1, dtype=np.int64)
        out[np.searchsorted(index, blocks)] = facets
        return out


@dataclass
class MortarTracker:
    """Re-evaluates dual mortar pairs at u from the reference gathered surfaces (master, slave).

    Every evaluation integrates the moved surfaces afresh (:func:`~dolfinx_nnqem.contact.mortar.mortar_pairs`):
    the slave facets' dual basis and D, the segments and M, the weighted gaps and the averaged
    nodal normals of the current configuration. Nothing is remembered between evaluations; a
    mortar pair is its slave node, whatever master facets it couples with.
    """

    V: Any  #: the displacement space
    surfaces: GatheredSurfaces
    gap_rounding: float  #: gaps within it are zero (:data:`GAP_ROUNDING`)
    search_distance: float | None
    note: str
    supported: np.ndarray | None

    def pairs_at(self, u: dolfinx.fem.Function, load_factor: float) -> SurfacePairs:
        """The mortar pairs of the moved surfaces, gaps rebased (module; collective)."""
        from dolfinx_nnqem.contact.mortar import mortar_pairs

        moved = with_moved_normals(moved_surfaces(self.surfaces, u))
        pairs = mortar_pairs(self.V, moved, tolerance=self.gap_rounding, search_distance=self.search_distance,
                             note=self.note, supported=self.supported, max_interference=RUN_INTERFERENCE)
        return rebased(pairs, self.V, u)


def surface_tracker(V: dolfinx.fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags, tags: tuple[int, int], *,
                    slave: int | None, search_distance: float | None, supported: np.ndarray | None,
                    discretisation: str = "node-to-surface") -> SurfaceTracker | MortarTracker:
    """The tracker of a node-to-surface or mortar interface between ``tags`` (collective): the
    surfaces gathered once, the slave side chosen as :func:`~dolfinx_nnqem.contact.discretisation.discretise` does."""
    from dolfinx_nnqem.contact.discretisation import slave_side

    surfaces = gather_surfaces(V, facet_tags, tags)
    check_no_shared_nodes(surfaces)
    slave, note = slave_side(surfaces, slave)
    if slave == tags[0]:
        surfaces = surfaces.swapped()  # the builders take (master, slave)
    gap_rounding = mesh_tolerance(V.mesh, GAP_ROUNDING)
    if discretisation == "mortar":
        return MortarTracker(V, surfaces, gap_rounding, search_distance, note + ", current geometry", supported)
    return SurfaceTracker(V, surfaces, gap_rounding, search_distance, note + ", current geometry", supported)
