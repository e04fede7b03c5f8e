r"""Node-to-surface contact pairs (``formulation.md`` §2b).

Every slave node j is projected onto the master surface: ξ_j is the closest point on the master
facets (triangles, or bilinear quadrilaterals by a local Newton; edges and corners handled, see
:mod:`~dolfinx_nnqem.contact.projection`), n_j the master's outward unit normal there, and

    w_j = R_j (u_j − Σ_k N_k(ξ_j) u_k),   g0_j = n_j · (X_j − x(ξ_j)),

over the nodes k of the master facet holding ξ_j. Small deformation: ξ_j, n_j and g0_j are
computed once, in the reference configuration, unless the interface follows the bodies
(:mod:`~dolfinx_nnqem.contact.current_geometry`, which calls this on the moved surfaces).

Slave nodes whose closest point is clamped to the master surface's boundary (they lie beyond
its edge) get no pair. Node-to-surface is cheap and familiar (CalculiX's default) but does not
pass the contact patch test on non-matching meshes: a uniform pressure is transmitted as
slave nodal forces that the master's shape functions spread unevenly (``docs/contact.md``
shows the error); use :mod:`~dolfinx_nnqem.contact.mortar` where stresses at the interface matter.

Quadratic facets (degree-2 displacements, ``formulation.md`` §2c): every node of the slave
surface, vertex, edge or face node, is a slave node, projected onto the 6-node triangles or 9-node
quadrilaterals of the master (curved on a second-order mesh;
:mod:`~dolfinx_nnqem.contact.quadratic_projection`) with their quadratic N_k. On a tri6 slave
surface the pairs act on the transformed nodal displacements d̂ = T⁻ᵀ d
(:mod:`~dolfinx_nnqem.contact.quadratic_facets`), whose weights ∫N̂_j dA are positive at every
node: pair j is

    w_j = R_j Σ_i t_ji (u_i − Σ_k N_k(ξ_i) u_k),   g0_j = Σ_i t_ji g0_i,

the transformed nodal values of the gap vector (for a vertex t_ji = δ_ji: the plain pair; for an
edge node its edge's vertices enter with −α/(1 − 2α)). On matching meshes this is dual mortar's
constraint (M_jk / D_jj = (T⁻ᵀ)_jk there), and a slave node's pair needs every node of its row
projected inside the master.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from dolfinx_nnqem.contact.projection import Projection, project_points
from dolfinx_nnqem.contact.facet_layout import NodeCombination
from dolfinx_nnqem.contact.quadratic_projection import project_onto_facets, project_points_quadratic
from dolfinx_nnqem.contact.surface_pairs import MAX_INTERFERENCE, SurfacePairs, facet_size, surface_pairs
from dolfinx_nnqem.contact.surfaces import ContactPairError, Facets, NoPairsError, GatheredSurfaces, first_by_position, format_point

if TYPE_CHECKING:
    import dolfinx

__all__ = ["keep_preferred", "node_to_surface_pairs"]


def node_to_surface_pairs(V: dolfinx.fem.FunctionSpace, surfaces: GatheredSurfaces, *, tolerance: float, search_distance: float | None = None,
                          note: str = "", supported: np.ndarray | None = None,
                          edge_allowance: float | None = None, preferred: np.ndarray | None = None,
                          max_interference: float = MAX_INTERFERENCE) -> SurfacePairs:
    """Node-to-surface pairs of the second gathered surface (slave) on the first (master).

    Parameters
    ----------
    V
        The displacement space (vector P1 or P2).
    surfaces
        The master and slave surfaces, in that order (:func:`~dolfinx_nnqem.contact.surfaces.gather_surfaces`).
    tolerance
        Gaps within it are zero; slave nodes whose closest point lies farther than it beyond the
        master's boundary get no pair.
    search_distance
        Slave nodes farther than this from the master get no pair; default: twice the larger
        facet size of the two surfaces.
    note
        Extra words for the pair set's ``describe``.
    supported
        Laid out like V's local dofs, non-zero at prescribed ones (None: no support is known): the
        normals of slave nodes on symmetry planes of the interface lie in the plane (:func:`surface_pairs`).
    edge_allowance
        Slave nodes whose closest point lies up to this far beyond the master's boundary still get
        a pair (default: ``tolerance``). The current geometry allows a fraction of the facet size,
        so that a slave node on the master's edge, which the Poisson effect moves back and forth
        across it, keeps its pair (:mod:`~dolfinx_nnqem.contact.current_geometry`).
    preferred
        (slave nodes,) a master facet per slave node (−1: none), kept where the slave node still
        projects onto it within ``edge_allowance`` (:func:`keep_preferred`): the current geometry's
        hysteresis against a slave node on a shared edge jumping between two facets.
    max_interference
        How deep behind the master, in its facet size, a slave node may lie
        (:func:`~dolfinx_nnqem.contact.surface_pairs.surface_pairs`).

    Raises
    ------
    ContactPairError
        (on every rank) if no slave node faces the master, a slave node lies deep behind it, or
        the normals at a projection point the same way.
    """
    tags = surfaces.tags[0], surfaces.tags[1]  # (master, slave): the two surfaces gathered
    master, slave = surfaces.facets_of(0), surfaces.facets_of(1)
    nodes = surfaces.nodes[1]
    master_size = facet_size(master)
    if search_distance is None:
        search_distance = 2.0 * max(master_size, facet_size(slave))
    project = project_points_quadratic if master.degree == 2 else project_points
    p = project(nodes.x, master.x, master.area, max_distance=search_distance)
    if preferred is not None:  # current geometry
        p = keep_preferred(p, nodes.x, master, preferred, 0.0 if edge_allowance is None else edge_allowance)
    found = p.facet >= 0
    inside = found & (p.tangential_offset <= (tolerance if edge_allowance is None else edge_allowance))
    _check_projections(p, inside, nodes.x, nodes.normal, tags, search_distance)
    k = master.nodes.shape[1]
    combination = nodes.combination
    if len(combination.columns) == len(nodes.index):  # linear or quad9 slave facets: the node alone
        keep = np.flatnonzero(inside)
        return surface_pairs(
            V, "node-to-surface", tags, nodes.index[keep], nodes.x[keep], nodes.area[keep], p.normal[keep],
            p.g0[keep], np.arange(0, k * len(keep) + 1, k), master.nodes[p.facet[keep]].ravel(), p.N[keep].ravel(),
            master.x[p.facet[keep]].reshape(-1, 3), master_size=master_size, tolerance=tolerance,
            num_slave_nodes=len(nodes.index), note=note, supported=supported, facet=p.facet[keep],
            max_interference=max_interference)
    # tri6 slave facets: pair j acts on d̂_j = Σ_i t_ji d_i, so its master side is Σ_i t_ji u_m(ξ_i)
    every = np.minimum.reduceat(inside[combination.columns].astype(np.int8), combination.indptr[:-1]) > 0
    keep = np.flatnonzero(every)
    rows = combination.take(keep)
    master_indptr, master_index, weights, X_master_nodes = _combined_master_side(rows, p, master.nodes, master.x)
    g0 = rows.apply(np.where(inside, p.g0, 0.0))  # the transformed nodal gaps Σ_i t_ji g0_i
    return surface_pairs(
        V, "node-to-surface", tags, nodes.index[keep], nodes.x[keep], nodes.area[keep], p.normal[keep], g0,
        master_indptr, master_index, weights, X_master_nodes, master_size=master_size, tolerance=tolerance,
        num_slave_nodes=len(nodes.index), note=note, supported=supported, facet=p.facet[keep],
        slave_rows=(rows.indptr, nodes.index[rows.columns], rows.coefficients), max_interference=max_interference)


def _check_projections(p: Projection, inside: np.ndarray, x: np.ndarray, normal: np.ndarray, tags: tuple[int, int],
                       search_distance: float) -> None:
    """Raise if no slave node (positions ``x``, outward normals ``normal``) projects ``inside`` the
    master surface (:class:`NoPairsError`), or if one that does faces the same way as the master
    there (:class:`ContactPairError`); ``tags`` = (master, slave)."""
    if not np.any(inside):
        raise NoPairsError(
            f"no node of the slave surface {tags[1]} projects onto the master surface {tags[0]} within the search "
            f"distance {search_distance:.6g}: do the surfaces face each other? (pass search_distance for "
            "larger initial gaps)")
    facing = np.einsum("ij,ij->i", p.normal[inside], normal[inside])
    if np.any(facing >= 0.0):
        j = first_by_position(x[inside], facing >= 0.0)
        raise ContactPairError(
            f"the contact surfaces do not face each other: the slave node at {format_point(x[inside][j])} "
            f"(surface {tags[1]}, outward normal {format_point(normal[inside][j])}) projects onto surface "
            f"{tags[0]} where its outward normal is {format_point(p.normal[inside][j])}")


def _combined_master_side(rows: NodeCombination, p: Projection, master_nodes: np.ndarray,
                          master_x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The master nodes k and weights c_jk = Σ_i t_ji N_k(ξ_i) of each row j (CSR, a node once per
    row), with the nodes' coordinates: the master side of the transformed slave displacement."""
    k = master_nodes.shape[1]
    row = np.repeat(np.arange(len(rows.indptr) - 1), np.diff(rows.indptr))
    facet = p.facet[rows.columns]  # (entries,) the facet under each slave node of each row
    node = master_nodes[facet].ravel()
    weight = (rows.coefficients[:, None] * p.N[rows.columns]).ravel()
    pair = np.repeat(row, k)
    x = master_x[facet].reshape(-1, 3)
    order = np.lexsort((node, pair))
    pair, node, weight, x = pair[order], node[order], weight[order], x[order]
    first = np.flatnonzero(np.concatenate([[True], (pair[1:] != pair[:-1]) | (node[1:] != node[:-1])]))
    counts = np.bincount(pair[first], minlength=len(rows.indptr) - 1)
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return indptr, node[first], np.add.reduceat(weight, first), x[first]


def keep_preferred(p: Projection, x: np.ndarray, master: Facets, preferred: np.ndarray, allowance: float) -> Projection:
    """``p`` with the rows of slave points moved back to their ``preferred`` master facet where the
    point's closest point on it is within ``allowance`` of the facet (tangentially) and of the best
    distance.

    Two facets that share an edge have different normals once the master deforms; a slave node
    on that edge would otherwise take either, by round-off, from one evaluation to the next.
    """
    changed = np.flatnonzero((preferred >= 0) & (p.facet != preferred))
    if len(changed) == 0:
        return p
    out = Projection(*(np.array(a, copy=True) for a in (p.facet, p.xi, p.N, p.point, p.normal, p.g0, p.distance,
                                                          p.tangential_offset)))
    if master.degree == 2:  # every changed node at once: per node, a projection's set-up costs ~4 ms
        q = project_onto_facets(x[changed], master.x, master.area, preferred[changed])
        nearest = np.where(p.facet[changed] >= 0, p.distance[changed], np.inf)
        kept = (q.tangential_offset <= allowance) & (q.distance <= nearest + allowance)
        for name in ("facet", "xi", "N", "point", "normal", "g0", "distance", "tangential_offset"):
            getattr(out, name)[changed[kept]] = getattr(q, name)[kept]
        return out
    for i in changed:
        f = int(preferred[i])
        q = project_points(x[i:i + 1], master.x[f:f + 1], master.area[f:f + 1])
        best = p.distance[i] if p.facet[i] >= 0 else np.inf
        if q.tangential_offset[0] <= allowance and q.distance[0] <= best + allowance:
            for name in ("xi", "N", "point", "normal", "g0", "distance", "tangential_offset"):
                getattr(out, name)[i] = getattr(q, name)[0]
            out.facet[i] = f
    return out
