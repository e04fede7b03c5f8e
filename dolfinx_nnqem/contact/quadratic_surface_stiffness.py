r"""The consistent linearisation of node-to-surface pairs on quadratic master facets (issue 41).

The degree-2 counterpart of :func:`~dolfinx_nnqem.contact.surface_stiffness.closest_point_derivatives`:
a slave node s projected onto a 6-node triangle or 9-node quadrilateral of the master (curved or
not), x(ξ) = Σ_k N_k(ξ) x_k with the quadratic N_k of :mod:`~dolfinx_nnqem.contact.quadratic_facets`
(its node order and reference coordinates). With d = x_s − x(ξ), a_α = Σ_k ∂N_k/∂ξ_α x_k and the
second derivatives x_,αβ = Σ_k ∂²N_k/∂ξ_α∂ξ_β x_k (all three non-zero on a quadratic facet),

* the closest point: stationarity d · a_α = 0 gives A δξ = Σ_j G_j δx_j with
  A_αβ = a_α · a_β − d · x_,αβ and G_αj = a_α c_j + d ∂N_j/∂ξ_α (c_s = 1, c_k = −N_k(ξ), ∂N_s = 0);
* a closest point clamped to the facet's boundary moves along its (curved) edge ξ = ξ_e + t e
  (e the edge's direction in reference coordinates): with x_,t = a_α e_α and
  x_,tt = e_α e_β x_,αβ, (x_,t · x_,t − d · x_,tt) δt = Σ_j (x_,t c_j + d ∂N_j/∂ξ_α e_α) δx_j; at a
  corner ξ is held;
* the normal n = ν/|ν|, ν = a₁ × a₂: δn = (I − n nᵀ)/|ν| (δa₁ × a₂ + a₁ × δa₂),
  δa_α = Σ_k ∂N_k/∂ξ_α δx_k + x_,αβ δξ_β.

The gap, slip and force terms W, K built from these are those of linear facets
(:func:`~dolfinx_nnqem.contact.surface_stiffness.pair_terms`, with the quadratic N_k, ∂N_k/∂ξ). They
hold where every pair is one slave node: Q2 hexahedra (9-node quadrilateral slave facets). On P2
tetrahedra a pair acts on a combination of the 6-node triangle's slave nodes (the transformed basis),
each node with its own closest point and these derivatives
(:mod:`~dolfinx_nnqem.contact.combined_surface_stiffness`).
"""

from __future__ import annotations

import numpy as np

from dolfinx_nnqem.contact.projection import Projection
from dolfinx_nnqem.contact.quadratic_facets import _tabulate
from dolfinx_nnqem.contact.surfaces import Facets

__all__ = ["quadratic_closest_point_derivatives", "quadratic_closest_points", "quadratic_shapes"]

# the edges of each reference facet, (start, end), as the projection walks them
_EDGES = {6: np.array([[[0.0, 0.0], [1.0, 0.0]], [[1.0, 0.0], [0.0, 1.0]], [[0.0, 1.0], [0.0, 0.0]]]),
          9: np.array([[[0.0, 0.0], [1.0, 0.0]], [[1.0, 0.0], [1.0, 1.0]], [[1.0, 1.0], [0.0, 1.0]],
                       [[0.0, 1.0], [0.0, 0.0]]])}


def quadratic_shapes(k: int, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """N (p, k), ∂N/∂ξ (p, k, 2) and the second derivatives (p, k, 3) (∂ξ², ∂ξ∂η, ∂η²) at ``xi`` (p, 2)."""
    return _tabulate(k, np.ascontiguousarray(np.reshape(xi, (-1, 2)), dtype=np.float64))


def _second_derivatives(d2N: np.ndarray, x_m: np.ndarray) -> np.ndarray:
    """x_,αβ (p, 2, 2, 3) of the facets' maps."""
    h = np.einsum("pkc,pkj->pcj", d2N, x_m)
    return np.stack([np.stack([h[:, 0], h[:, 1]], axis=1), np.stack([h[:, 1], h[:, 2]], axis=1)], axis=1)


def _weights(N: np.ndarray, dN: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(c_j (p, 1 + k), ∂N_j/∂ξ (p, 1 + k, 2)) over the pair's nodes: the slave node, then the master's."""
    p = len(N)
    return (np.concatenate([np.ones((p, 1)), -N], axis=1),
            np.concatenate([np.zeros((p, 1, 2)), dN], axis=1))


def _edge_derivative(a: np.ndarray, h: np.ndarray, d: np.ndarray, c: np.ndarray, dNj: np.ndarray, xi: np.ndarray,
                     k: int) -> np.ndarray:
    """∂ξ/∂x (q, 2, 3 (1 + k)) of closest points clamped to a (curved) edge of their facets (module
    docstring); zero at a corner."""
    q = len(xi)
    edges = _EDGES[k]
    start, along = edges[:, 0], edges[:, 1] - edges[:, 0]  # (e, 2)
    t = np.einsum("pea,ea->pe", xi[:, None, :] - start[None], along) / np.sum(along ** 2, axis=1)
    off = np.linalg.norm(xi[:, None, :] - start[None] - np.clip(t, 0.0, 1.0)[:, :, None] * along[None], axis=2)
    edge = np.argmin(off, axis=1)
    rows = np.arange(q)
    t_e = np.clip(t[rows, edge], 0.0, 1.0)
    corner = (t_e < 1e-12) | (t_e > 1.0 - 1e-12)
    e = along[edge]  # (q, 2)
    x_t = np.einsum("pa,paj->pj", e, a)
    x_tt = np.einsum("pa,pb,pabj->pj", e, e, h)
    A_t = np.einsum("pj,pj->p", x_t, x_t) - np.einsum("pj,pj->p", d, x_tt)
    G_t = (x_t[:, None, :] * c[:, :, None] + d[:, None, :] * np.einsum("pja,pa->pj", dNj, e)[:, :, None])
    dt = G_t.reshape(q, 3 * c.shape[1]) / A_t[:, None]
    dt[corner] = 0.0
    return e[:, :, None] * dt[:, None, :]


def quadratic_closest_point_derivatives(x_s: np.ndarray, x_m: np.ndarray, xi: np.ndarray, interior: np.ndarray
                                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """∂ξ/∂x and ∂n/∂x of closest points on quadratic facets (module docstring).

    Parameters
    ----------
    x_s
        (p, 3) the slave nodes.
    x_m
        (p, k, 3) their master facets' nodes (k = 6 or 9, :mod:`~dolfinx_nnqem.contact.quadratic_facets`' order).
    xi
        (p, 2) the closest points' reference coordinates on those facets.
    interior
        (p,) True where ξ is the foot of the normal; elsewhere it is clamped to the facet's boundary.

    Returns
    -------
    (dxi (p, 2, c), dn (p, 3, c), n (p, 3)): the derivatives with respect to the c = 3 (1 + k) node
    coordinates (the slave node's, then the master nodes', each x, y, z), and n = a₁ × a₂ / |a₁ × a₂|.
    """
    p, k = x_m.shape[:2]
    N, dN, d2N = quadratic_shapes(k, xi)
    a = np.einsum("pka,pkj->paj", dN, x_m)  # a_α
    h = _second_derivatives(d2N, x_m)  # x_,αβ
    d = x_s - np.einsum("pk,pkj->pj", N, x_m)
    c, dNj = _weights(N, dN)
    G = (a[:, :, None, :] * c[:, None, :, None]
         + d[:, None, None, :] * np.transpose(dNj, (0, 2, 1))[:, :, :, None]).reshape(p, 2, -1)
    A = np.einsum("paj,pbj->pab", a, a) - np.einsum("pj,pabj->pab", d, h)
    dxi = np.linalg.solve(A, G) if p else np.zeros((0, 2, G.shape[2]))
    clamped = ~interior
    dxi[clamped] = _edge_derivative(a[clamped], h[clamped], d[clamped], c[clamped], dNj[clamped], xi[clamped], k)
    # δa_α = Σ_k ∂N_k/∂ξ_α δx_k + x_,αβ δξ_β
    da = np.einsum("pja,il->paijl", dNj, np.eye(3)).reshape(p, 2, 3, -1)
    da += np.einsum("pabi,pbc->paic", h, dxi)
    nu = np.cross(a[:, 0], a[:, 1])
    length = np.linalg.norm(nu, axis=1)
    n = nu / length[:, None]
    dnu = np.cross(da[:, 0], a[:, 1][:, :, None], axis=1) + np.cross(a[:, 0][:, :, None], da[:, 1], axis=1)
    projector = (np.eye(3) - n[:, :, None] * n[:, None, :]) / length[:, None, None]
    return dxi, projector @ dnu, n


def quadratic_closest_points(x_s: np.ndarray, master: Facets, preferred: np.ndarray, allowance: float,
                             size: float, interior_tolerance: float) -> tuple[Projection, np.ndarray, np.ndarray]:
    """The slave nodes ``x_s`` projected onto the quadratic ``master`` facets (at their current positions),
    a node kept on its ``preferred`` facet by the rule of
    :func:`~dolfinx_nnqem.contact.node_to_surface.keep_preferred`; (projection, the node order of each
    node's facet (the facets' own), interior flags: the foot of the normal, within
    ``interior_tolerance`` × ``size``)."""
    from dolfinx_nnqem.contact.node_to_surface import keep_preferred
    from dolfinx_nnqem.contact.quadratic_projection import project_points_quadratic

    p = keep_preferred(project_points_quadratic(x_s, master.x, master.area), x_s, master, preferred, allowance)
    order = np.broadcast_to(np.arange(master.x.shape[1]), (len(p.facet), master.x.shape[1])).copy()
    return p, order, p.tangential_offset <= interior_tolerance * size
