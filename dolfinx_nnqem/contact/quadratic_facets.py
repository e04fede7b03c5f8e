r"""Quadratic contact facets: the 6-node triangle (tri6) and the 9-node quadrilateral (quad9).

Lagrange displacements of degree 2 put a node on every vertex and every edge of a contact facet
(tetrahedra: tri6 facets) and, on a hexahedron's facet, on its centre (quad9). This module holds
what every pair set needs of such facets: their node order, shape functions and geometry (curved
on a second-order mesh), a quadrature rule on the reference facet, and the transformed basis that
gives every node a positive weight (``formulation.md`` §2c, ``docs/theory.md``, "Quadratic
facets").

Node order and reference coordinates (basix's, fixed by the facet's vertex order)
---------------------------------------------------------------------------------
* tri6 on the unit triangle: vertices v0 (0, 0), v1 (1, 0), v2 (0, 1), then the nodes of the
  edges (v1, v2), (v0, v2), (v0, v1);
* quad9 on [0, 1]²: vertices v0 (0, 0), v1 (1, 0), v2 (0, 1), v3 (1, 1) (tensor order, the order
  DOLFINx gives a hexahedron's facet), then the nodes of the edges (v0, v1), (v0, v2), (v1, v3),
  (v2, v3), then the centre.

The vertices come in the caller's order, so x_ξ × x_η may point into the body: every function
returning normals or area vectors takes the outward side from the caller.

The transformed basis
---------------------
The vertex functions of a tri6 integrate to zero over a flat facet (∫N_v dA = 0; edge nodes A/3).
Lumped nodal areas then vanish at the corners and the nodal forces of a uniform pressure are zero
there; with any variation of the pressure they turn negative. A node-wise Signorini condition on
such forces is degenerate at the corners and wrong elsewhere, and a dual mortar basis does not
exist. Popp, Wohlmuth, Gee and Wall (SIAM J. Sci. Comput. 34, 2012) transform the slave basis,
N̂ = T N: each vertex function takes a fraction α of its two adjacent edge functions,

    N̂_v = N_v + α Σ_{e ∋ v} N_e,   N̂_e = (1 − 2α) N_e,

with α = 1/5 (their choice, and 4C's): per flat facet ∫N̂_v dA = 2αA/3 = 2A/15 and
∫N̂_e dA = (1 − 2α)A/3 = A/5, all positive, and Σ_j N̂_j = 1. The quad9's own functions integrate
to A/36 (vertices), A/9 (edges) and 4A/9 (centre) on a parallelogram, all positive; they are used
as they are (α = 0, as Popp et al. and 4C do). The transformation changes the basis, not the
displacement space: u = Σ_i N_i d_i = Σ_j N̂_j d̂_j with d̂ = T⁻ᵀ d, that is

    d̂_v = d_v,   d̂_e = (d_e − α (d_a + d_b)) / (1 − 2α)   (a, b the edge's vertices),

the rows of :func:`node_combination`. The pair of slave node j acts on d̂_j, its force λ_j is the
coefficient of N̂_j in the contact traction (≈ pressure × ∫N̂_j dA), and the physical nodal
forces are T⁻¹λ (the consistent forces p ∫N_i dA of a uniform pressure).
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

from dolfinx_nnqem.contact.facet_layout import (ALPHA, EDGES, NUM_VERTICES, QUADRATIC, NodeCombination, is_quadratic,
                                                node_combination)

__all__ = ["ALPHA", "EDGES", "NUM_VERTICES", "QUADRATIC", "NodeCombination", "facet_geometry", "is_quadratic",
           "node_combination", "nodal_integrals", "outward_signs", "reference_nodes", "reference_rule", "shape_at",
           "shape_derivatives", "shape_functions", "transformation", "transformed_shape_functions"]

_TRI6_NODES = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.5, 0.5], [0.0, 0.5], [0.5, 0.0]])
_QUAD9_NODES = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [0.5, 0.0], [0.0, 0.5], [1.0, 0.5],
                         [0.5, 1.0], [0.5, 0.5]])
# quad9 node a = L_i(ξ) L_j(η) with the 1D quadratic Lagrange functions 0: at 0, 1: at 1, 2: at ½
_QUAD9_FACTORS = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [2, 0], [0, 2], [1, 2], [2, 1], [2, 2]])


def reference_nodes(k: int) -> np.ndarray:
    """(k, 2) reference coordinates of the nodes of a tri6 (k = 6) or quad9 (k = 9)."""
    if k == 6:
        return _TRI6_NODES.copy()
    if k == 9:
        return _QUAD9_NODES.copy()
    raise ValueError(f"quadratic facets have 6 or 9 nodes, got {k}")


# --------------------------------------------------------------------------------------------
# Shape functions: one numba kernel, used by the projection kernels and (looped) by numpy callers
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _lagrange_1d(i, s):
    """Value, first and second derivative of the 1D quadratic Lagrange function i (nodes 0, 1, ½) at s."""
    if i == 0:
        return 2.0 * s * s - 3.0 * s + 1.0, 4.0 * s - 3.0, 4.0
    if i == 1:
        return 2.0 * s * s - s, 4.0 * s - 1.0, 4.0
    return 4.0 * s - 4.0 * s * s, 4.0 - 8.0 * s, -8.0


@numba.njit(cache=True)
def shape_at(k: int, s: float, t: float, N: np.ndarray, dN: np.ndarray, d2N: np.ndarray) -> None:
    """Fill N (k,), dN (k, 2) and d2N (k, 3) (∂²/∂ξ², ∂²/∂ξ∂η, ∂²/∂η²) at (ξ, η) = (s, t)."""
    if k == 6:
        l0 = 1.0 - s - t
        N[0] = l0 * (2.0 * l0 - 1.0)
        N[1] = s * (2.0 * s - 1.0)
        N[2] = t * (2.0 * t - 1.0)
        N[3] = 4.0 * s * t
        N[4] = 4.0 * l0 * t
        N[5] = 4.0 * l0 * s
        d0 = 1.0 - 4.0 * l0
        dN[0, 0], dN[0, 1] = d0, d0
        dN[1, 0], dN[1, 1] = 4.0 * s - 1.0, 0.0
        dN[2, 0], dN[2, 1] = 0.0, 4.0 * t - 1.0
        dN[3, 0], dN[3, 1] = 4.0 * t, 4.0 * s
        dN[4, 0], dN[4, 1] = -4.0 * t, 4.0 * (l0 - t)
        dN[5, 0], dN[5, 1] = 4.0 * (l0 - s), -4.0 * s
        d2N[0, 0], d2N[0, 1], d2N[0, 2] = 4.0, 4.0, 4.0
        d2N[1, 0], d2N[1, 1], d2N[1, 2] = 4.0, 0.0, 0.0
        d2N[2, 0], d2N[2, 1], d2N[2, 2] = 0.0, 0.0, 4.0
        d2N[3, 0], d2N[3, 1], d2N[3, 2] = 0.0, 4.0, 0.0
        d2N[4, 0], d2N[4, 1], d2N[4, 2] = 0.0, -4.0, -8.0
        d2N[5, 0], d2N[5, 1], d2N[5, 2] = -8.0, -4.0, 0.0
    else:
        for a in range(9):
            fs, ds, dds = _lagrange_1d(_QUAD9_FACTORS[a, 0], s)
            ft, dt, ddt = _lagrange_1d(_QUAD9_FACTORS[a, 1], t)
            N[a] = fs * ft
            dN[a, 0] = ds * ft
            dN[a, 1] = fs * dt
            d2N[a, 0] = dds * ft
            d2N[a, 1] = ds * dt
            d2N[a, 2] = fs * ddt


@numba.njit(cache=True)
def _tabulate(k, xi):
    n = xi.shape[0]
    N = np.empty((n, k))
    dN = np.empty((n, k, 2))
    d2N = np.empty((n, k, 3))
    for q in range(n):
        shape_at(k, xi[q, 0], xi[q, 1], N[q], dN[q], d2N[q])
    return N, dN, d2N


def _check_k(k: int) -> None:
    if k not in QUADRATIC:
        raise ValueError(f"quadratic facets have 6 or 9 nodes, got {k}")


def shape_functions(k: int, xi: npt.ArrayLike) -> np.ndarray:
    """N_a(ξ), shape ``(n, k)``, of a tri6 or quad9 at the reference points ``xi`` (n, 2)."""
    _check_k(k)
    return _tabulate(k, np.ascontiguousarray(np.atleast_2d(xi), dtype=np.float64))[0]


def shape_derivatives(k: int, xi: npt.ArrayLike) -> np.ndarray:
    """∂N_a/∂ξ_b, shape ``(n, k, 2)``, of a tri6 or quad9 at the reference points ``xi`` (n, 2)."""
    _check_k(k)
    return _tabulate(k, np.ascontiguousarray(np.atleast_2d(xi), dtype=np.float64))[1]


def transformation(k: int, alpha: float | None = None) -> np.ndarray:
    """T (k, k) of the transformed basis N̂ = T N (module docstring); α from :data:`ALPHA` by default."""
    _check_k(k)
    alpha = ALPHA[k] if alpha is None else float(alpha)
    nv = NUM_VERTICES[k]
    T = np.eye(k)
    for e, (a, b) in enumerate(EDGES[k]):
        T[a, nv + e] = T[b, nv + e] = alpha
        T[nv + e, nv + e] = 1.0 - 2.0 * alpha
    return T


def transformed_shape_functions(k: int, xi: npt.ArrayLike) -> np.ndarray:
    """N̂_j(ξ) = Σ_i T_ji N_i(ξ), shape ``(n, k)``."""
    return shape_functions(k, xi) @ transformation(k).T


# --------------------------------------------------------------------------------------------
# Quadrature and geometry
# --------------------------------------------------------------------------------------------

RULE_POINTS = 6
"""Gauss points per direction of :func:`reference_rule` (the triangle's rule is collapsed from the
square's): exact for polynomials of degree 2 × 6 − 2 = 10 in each variable, and to rounding for
the area element of a curved second-order facet, which is not a polynomial."""


def reference_rule(k: int, points: int = RULE_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """Points (q, 2) and weights (q,) on the reference facet (weights sum to ½ on the triangle, 1
    on the square): a tensor Gauss rule, collapsed onto the triangle (ξ, η) = (u, v (1 − u))."""
    g, w = np.polynomial.legendre.leggauss(points)
    g, w = 0.5 * (g + 1.0), 0.5 * w  # on [0, 1]
    u, v = np.meshgrid(g, g, indexing="ij")
    wu, wv = np.meshgrid(w, w, indexing="ij")
    if k in (3, 6):
        return np.column_stack([u.ravel(), (v * (1.0 - u)).ravel()]), (wu * wv * (1.0 - u)).ravel()
    return np.column_stack([u.ravel(), v.ravel()]), (wu * wv).ravel()


def facet_geometry(x: npt.ArrayLike, xi: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Points x(ξ) (m, q, 3) and raw area vectors x_ξ × x_η (m, q, 3) of quadratic facets.

    Parameters
    ----------
    x
        (m, k, 3) the facets' nodes in this module's order (k = 6 or 9).
    xi
        (q, 2) reference points.

    The area vectors follow the vertex order (they may point inwards); see :func:`outward_signs`.
    """
    x = np.asarray(x, dtype=np.float64)
    N, dN, _ = _tabulate(x.shape[1], np.ascontiguousarray(np.atleast_2d(xi), dtype=np.float64))
    points = np.einsum("qa,maj->mqj", N, x)
    J = np.einsum("qab,maj->mqbj", dN, x)  # rows x_ξ, x_η
    return points, np.cross(J[:, :, 0], J[:, :, 1])


def outward_signs(x: npt.ArrayLike, outward: npt.ArrayLike) -> np.ndarray:
    """(m,) ±1: the sign that turns x_ξ × x_η at the facet's reference centre outward."""
    k = np.asarray(x).shape[1]
    centre = np.array([[1.0 / 3.0, 1.0 / 3.0]]) if k == 6 else np.array([[0.5, 0.5]])
    _, area = facet_geometry(x, centre)
    return np.where(np.einsum("mj,mj->m", area[:, 0], np.asarray(outward, dtype=np.float64)) < 0.0, -1.0, 1.0)


def nodal_integrals(x: npt.ArrayLike, outward: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Per facet and node: ∫N̂_a dA (m, k) and ∫N̂_a n dA (m, k, 3), n the outward unit normal.

    The first is the node's share of the facet's area in the transformed basis (positive: module
    docstring); the second, summed over a node's facets and normalised, is its averaged normal (for
    flat facets the area-weighted mean of the facet normals, as for linear facets).
    """
    x = np.asarray(x, dtype=np.float64)
    k = x.shape[1]
    xi, w = reference_rule(k)
    _, area = facet_geometry(x, xi)  # (m, q, 3)
    area *= outward_signs(x, outward)[:, None, None]
    Nhat = transformed_shape_functions(k, xi)  # (q, k)
    weights = np.einsum("q,qa,mq->ma", w, Nhat, np.linalg.norm(area, axis=2))
    moments = np.einsum("q,qa,mqj->maj", w, Nhat, area)
    # a planar facet's normal is its outward vector's direction exactly: no quadrature rounding
    # in the normals of flat surfaces (a facet in a coordinate plane keeps zero components)
    unit = np.asarray(outward, dtype=np.float64)
    unit = unit / np.linalg.norm(unit, axis=1)[:, None]
    height = np.abs(np.einsum("maj,mj->ma", x - x[:, :1], unit)).max(axis=1)
    size = np.linalg.norm(x - x[:, :1], axis=2).max(axis=1)
    planar = height <= 1e-12 * size
    moments[planar] = weights[planar, :, None] * unit[planar, None, :]
    return weights, moments
