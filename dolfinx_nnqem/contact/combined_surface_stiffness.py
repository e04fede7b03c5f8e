r"""The consistent linearisation of node-to-surface pairs that combine slave nodes (P2 tetrahedra, issue 41).

On a surface of 6-node triangles pair j acts on the transformed nodes of its row
(:func:`~dolfinx_nnqem.contact.facet_layout.node_combination`): a vertex alone, or an edge node with its
edge's two vertices, with the constant coefficients t_ji. Each slave node i of the row is projected
onto its own master facet f_i (ξ_i, the facet's outward unit normal n_i there, d_i = x_i − x(ξ_i)), as
the re-evaluation between solves does (:func:`~dolfinx_nnqem.contact.node_to_surface.node_to_surface_pairs`),
and the pair is

    gap   g = Σ_i t_ji n_i · d_i                       (the transformed nodal gaps),
    slip  s_α = t_α · Σ_l a_l Δu_l,                    force F_l = a_l Rᵀλ   (Bᵀλ),

with the frame R = (n, t1, t2) on node j's own normal n = n_j (turned into the interface's symmetry
planes where its node lies on one) and the coefficients a_l of the pair's nodes l (the slave nodes of
the row and the nodes of their master facets, a node shared by two facets once):

    a_i = t_ji (slave node i),   a_k = −Σ_i t_ji N_k(ξ_i)  (master node k, over the facets holding it).

Every slave node i brings the derivatives of its own closest point (one slave node on one quadratic
facet: :func:`~dolfinx_nnqem.contact.quadratic_surface_stiffness.quadratic_closest_point_derivatives`,
∂ξ_i/∂x and ∂n_i/∂x over x_i and its facet's 6 nodes), and the pair's pieces are

    ∂a_k/∂x = −Σ_i t_ji ∂N_k/∂ξ_β(ξ_i) ∂ξ_iβ/∂x,
    ∂g/∂x   = Σ_i t_ji (n_i c_i − (n_i · a_iβ) ∂ξ_iβ/∂x + d_iᵀ ∂n_i/∂x)   (c_i = 1 at x_i, −N_k(ξ_i) at x_k),
    ∂n/∂x   = ∂n_j/∂x                                 (node j's columns only),

the chain rule that dual mortar's pairs share (coefficients, gap and normal of a pair with any number
of nodes: :class:`~dolfinx_nnqem.contact.mortar_linearisation.PairGeometry`), whose W and K
(:func:`~dolfinx_nnqem.contact.mortar_linearisation.mortar_terms`) go into the Newton matrix grouped by
the pairs' numbers of nodes: 7 for a vertex, up to 21 for an edge node (fewer where the facets share
nodes). A pair with a slave node beyond the master's boundary by more than the edge allowance is held
open within the solve (its gap a constant), as a pair of one slave node is
(:func:`~dolfinx_nnqem.contact.surface_stiffness.reprojected_pairs`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from dolfinx_nnqem.contact.facet_layout import NodeCombination
from dolfinx_nnqem.contact.mortar_linearisation import MortarPoints, PairGeometry
from dolfinx_nnqem.contact.pairset import PairRows
from dolfinx_nnqem.contact.quadratic_surface_stiffness import (quadratic_closest_point_derivatives,
                                                               quadratic_closest_points, quadratic_shapes)
from dolfinx_nnqem.contact.surface_pairs import SurfacePairs
from dolfinx_nnqem.contact.surface_stiffness import INTERIOR, Supports, _turned_derivative
from dolfinx_nnqem.contact.surfaces import GatheredSurfaces, local_frames, symmetry_normals
from dolfinx_nnqem.contact.symmetry_planes import symmetry_axes

__all__ = ["NodeTerms", "combined_pair_geometry", "combined_reprojected_pairs", "node_terms"]


@dataclass(frozen=True)
class NodeTerms:
    """The closest points of slave nodes on their quadratic master facets and their derivatives, each with
    respect to the 3 (1 + k) coordinates of the node and its facet's k nodes (the slave node's first).

    Attributes
    ----------
    c
        (q, 1 + k) c_i: 1 at the slave node, −N_k(ξ_i) at the facet's nodes.
    dc
        (q, 1 + k, 3 (1 + k)) ∂c_i/∂x (zero in the slave node's row).
    dg
        (q, 3 (1 + k)) ∂(n_i · d_i)/∂x.
    dn
        (q, 3, 3 (1 + k)) ∂n_i/∂x of the facet's outward normal n_i (oriented like the projection's).
    """

    c: np.ndarray
    dc: np.ndarray
    dg: np.ndarray
    dn: np.ndarray


def node_terms(x_s: np.ndarray, x_m: np.ndarray, xi: np.ndarray, interior: np.ndarray, normal: np.ndarray
               ) -> NodeTerms:
    """The :class:`NodeTerms` of slave nodes ``x_s`` (q, 3) on facets ``x_m`` (q, k, 3) at ``xi`` (q, 2)
    (``interior``: the foot of the normal, else clamped to the facet's boundary; ``normal``: the
    projection's outward normals, which orient the facets' a₁ × a₂)."""
    q, k = x_m.shape[:2]
    dxi, dn, n = quadratic_closest_point_derivatives(x_s, x_m, xi, interior)
    sign = np.sign(np.einsum("pj,pj->p", normal, n))
    n, dn = sign[:, None] * n, sign[:, None, None] * dn
    N, dN, _ = quadratic_shapes(k, xi)
    a = np.einsum("pka,pkj->paj", dN, x_m)  # a_β
    d = x_s - np.einsum("pk,pkj->pj", N, x_m)
    c = np.concatenate([np.ones((q, 1)), -N], axis=1)
    dg = ((c[:, :, None] * n[:, None, :]).reshape(q, -1) - np.einsum("pj,pbj,pbc->pc", n, a, dxi)
          + np.einsum("pj,pjc->pc", d, dn))
    dc = np.zeros((q, 1 + k, 3 * (1 + k)))
    dc[:, 1:] = -np.einsum("pkb,pbc->pkc", dN, dxi)
    return NodeTerms(c, dc, dg, dn)


def combined_pair_geometry(blocks: np.ndarray, t: np.ndarray, terms: NodeTerms, dn: np.ndarray, held_open: bool
                           ) -> PairGeometry:
    """The :class:`~dolfinx_nnqem.contact.mortar_linearisation.PairGeometry` of one pair (module docstring).

    Parameters
    ----------
    blocks
        (r, 1 + k) per slave node i of the row: its global dof block, then its master facet's nodes'.
    t
        (r,) the row's coefficients t_ji.
    terms
        The r slave nodes' :class:`NodeTerms`, in the order of ``blocks``.
    dn
        (3, 3 (1 + k)) ∂n/∂x of the pair's normal over the columns of ``blocks[0]`` (node j's own,
        turned into symmetry planes where it was).
    held_open
        The pair's gap is held (∂g = 0).
    """
    r, m = blocks.shape
    cols = np.unique(blocks)
    at = np.searchsorted(cols, blocks)  # (r, 1 + k) each node's position among the pair's
    columns = (3 * at[:, :, None] + np.arange(3)).reshape(r, 3 * m)
    a = np.zeros(len(cols))
    np.add.at(a, at, t[:, None] * terms.c)
    da = np.zeros((len(cols), 3 * len(cols)))
    np.add.at(da, (at[:, :, None], columns[:, None, :]), t[:, None, None] * terms.dc)
    dg = np.zeros(3 * len(cols))
    if not held_open:
        np.add.at(dg, columns, t[:, None] * terms.dg)
    dn_pair = np.zeros((3, 3 * len(cols)))
    dn_pair[:, columns[0]] = dn
    return PairGeometry(cols, a, da, dg, dn_pair)


def _turned(normal: np.ndarray, x_s: np.ndarray, facets: np.ndarray, x_facets: np.ndarray,
            supports: Supports | None) -> tuple[np.ndarray, np.ndarray | None]:
    """(the pairs' normals, the symmetry axes they were turned into or None): node j's normals ``normal``
    (p, 3) turned into the symmetry planes of the interface where it lies on one, the pair's master nodes
    those of its row's facets (``facets`` (p, r) the row's facet indices, −1 past its end; ``x_facets``:
    every master facet's nodes), as :func:`~dolfinx_nnqem.contact.surface_pairs.surface_pairs` does."""
    if supports is None or not supports.slave.any():
        return normal, None
    k = x_facets.shape[1]
    valid = facets >= 0
    counts = k * valid.sum(axis=1)
    indptr = np.concatenate([[0], np.cumsum(counts)])
    x = x_facets[facets[valid]].reshape(-1, 3)
    flags = supports.master[facets[valid]].reshape(-1, 3)
    axes = symmetry_axes(supports.slave, x_s, indptr, x, flags, supports.in_plane)
    return symmetry_normals(normal, axes), axes


def combined_reprojected_pairs(pairs: SurfacePairs, combination: NodeCombination, reference: GatheredSurfaces,
                               moved: GatheredSurfaces, preferred: np.ndarray, u_n_slave: np.ndarray,
                               u_n_master: np.ndarray, gap_rounding: float, allowance: float, size: float,
                               supports: Supports | None = None) -> tuple[SurfacePairs, MortarPoints]:
    """The combined node-to-surface ``pairs`` (the same slave nodes, in the same order) projected again onto
    the moved master surface, and their geometry (module docstring).

    Parameters
    ----------
    pairs
        The interface's :class:`~dolfinx_nnqem.contact.surface_pairs.SurfacePairs` (tri6 slave facets).
    combination
        The rows of the slave surface's nodes (``reference.nodes[1].combination``).
    reference, moved
        The gathered surfaces (master, slave) at rest and at X + u.
    preferred
        (slave nodes,) each slave node's master facet of the last evaluation (−1: none).
    u_n_slave, u_n_master
        u_n at every slave node (``reference.nodes[1].index``) and at the master facets' nodes (m, k, 3).
    gap_rounding, allowance, size
        Gaps within ``gap_rounding`` are zero; the edge allowance; the master's facet size.
    supports
        The prescribed components of the pairs' slave nodes j and of the master's nodes (None: none known).

    Returns
    -------
    (SurfacePairs, MortarPoints): the pairs with their master facets (node j's), weights, frames, rows
    and gaps g0 = g − (B u)_n of the iterate, and their
    :class:`~dolfinx_nnqem.contact.mortar_linearisation.MortarPoints` (per pair its
    :class:`~dolfinx_nnqem.contact.mortar_linearisation.PairGeometry`, normal and Δu at its nodes).
    """
    if pairs.num_local == 0:  # on 3 ranks the slave surface may lie on two of them
        return pairs, MortarPoints([], np.zeros((0, 3)), [])
    master, slaves = moved.facets_of(0), moved.nodes[1]
    rows = combination.take(np.searchsorted(slaves.index, pairs.slave_blocks))
    involved, position = np.unique(rows.columns, return_inverse=True)  # the rows' slave nodes, by position
    x_s = slaves.x[involved]
    p, _, interior = quadratic_closest_points(x_s, master, preferred[involved], allowance, size, INTERIOR)
    f = p.facet
    terms = node_terms(x_s, master.x[f], p.xi, interior, p.normal)
    count = np.diff(rows.indptr)
    pair = np.repeat(np.arange(len(count)), count)
    own = position[rows.indptr[:-1]]  # node j of each pair: its row's first entry
    gap = np.zeros(len(count))
    np.add.at(gap, pair, rows.coefficients * p.g0[position])
    held = np.zeros(len(count), dtype=bool)
    np.logical_or.at(held, pair, p.tangential_offset[position] > allowance)
    gap = np.where(np.abs(gap) <= gap_rounding, 0.0, gap)
    gap[held] = size  # held open: the next re-evaluation between solves drops the pair
    row_facets = np.full((len(count), int(count.max(initial=1))), -1, dtype=np.int64)
    row_facets[pair, np.arange(len(pair)) - rows.indptr[pair]] = f[position]
    normal, turned = _turned(p.normal[own], x_s[own], row_facets, master.x, supports)
    dn = terms.dn[own] if turned is None else _turned_derivative(p.normal[own], terms.dn[own], normal, turned)
    nodes = np.concatenate([slaves.index[involved][:, None], master.nodes[f]], axis=1)  # (q, 1 + k)
    x_ref = np.concatenate([reference.nodes[1].x[involved][:, None], reference.facets_of(0).x[f]], axis=1)
    x_now = np.concatenate([x_s[:, None], master.x[f]], axis=1)
    u_n = np.concatenate([u_n_slave[involved][:, None], u_n_master[f]], axis=1)
    geometry, du = [], []
    g0 = np.empty(len(count))
    for j in range(len(count)):
        span = position[rows.indptr[j]:rows.indptr[j + 1]]
        pg = combined_pair_geometry(nodes[span], rows.coefficients[rows.indptr[j]:rows.indptr[j + 1]],
                                    NodeTerms(terms.c[span], terms.dc[span], terms.dg[span], terms.dn[span]),
                                    dn[j], bool(held[j]))
        first = np.unique(nodes[span], return_index=True)[1]  # a node's first entry among the row's
        u = (x_now[span] - x_ref[span]).reshape(-1, 3)[first]
        g0[j] = gap[j] - normal[j] @ (pg.a @ u)
        geometry.append(pg)
        du.append(u - u_n[span].reshape(-1, 3)[first])
    return _with_geometry(pairs, geometry, normal, g0, f[own], x_now, nodes, position), MortarPoints(geometry, normal, du)


def _with_geometry(pairs: SurfacePairs, geometry: list[PairGeometry], normal: np.ndarray, g0: np.ndarray,
                   facet: np.ndarray, x_nodes: np.ndarray, nodes: np.ndarray, position: np.ndarray) -> SurfacePairs:
    """``pairs`` with the rows, master side, frames and gaps of ``geometry`` (``x_nodes``, ``nodes``: the
    projected slave nodes' and their facets' positions and blocks, (q, 1 + k, 3) and (q, 1 + k))."""
    counts = np.array([len(g.blocks) for g in geometry], dtype=np.int64)
    blocks = np.concatenate([np.zeros(0, dtype=np.int64)] + [g.blocks for g in geometry])
    a = np.concatenate([np.zeros(0)] + [g.a for g in geometry])
    R = local_frames(normal) if len(normal) else np.zeros((0, 3, 3))
    rows = PairRows.from_weighted_nodes(R, np.concatenate([[0], np.cumsum(counts)]), blocks, a)
    master = ~np.isin(blocks, nodes[position, 0])  # the pairs' slave nodes are none of the master's
    pair = np.repeat(np.arange(len(geometry)), counts)
    indptr = np.concatenate([[0], np.cumsum(np.bincount(pair[master], minlength=len(geometry)))]).astype(np.int64)
    order = np.argsort(nodes.ravel(), kind="stable")
    x = x_nodes.reshape(-1, 3)[order][np.searchsorted(nodes.ravel()[order], blocks[master])]
    X_master = np.zeros((len(geometry), 3))
    np.add.at(X_master, pair[master], -a[master][:, None] * x)
    return replace(pairs, master_indptr=indptr, master_blocks=blocks[master], weights=-a[master], X_master=X_master,
                   R=R, g0=g0, rows=rows, master_facet=facet.copy())
