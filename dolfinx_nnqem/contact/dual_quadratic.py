r"""Dual mortar on quadratic facets: tri6 and quad9 slave and master surfaces (degree-2 displacements).

``formulation.md`` §2c; Popp, Wohlmuth, Gee, Wall, "Dual quadratic mortar finite element methods
for 3D finite deformation contact", SIAM J. Sci. Comput. 34 (2012). The quadratic counterpart of
:mod:`~dolfinx_nnqem.contact.mortar_geometry`:

* The slave displacement is written in the transformed basis N̂ = T N of
  :mod:`~dolfinx_nnqem.contact.quadratic_facets` (tri6: each vertex function takes α = 1/5 of its
  two edge functions; quad9: α = 0, T = I), whose integrals ∫N̂_j dA are all positive. The dual
  functions are built on it, per slave facet e,

      Φ_j = Σ_k a_jk N̂_k,   A_e = D_e M_e⁻¹,   D_e = diag(∫_e N̂_j dA),   M_e = [∫_e N̂_j N̂_k dA],

  so that ∫_e Φ_j N̂_k dA = δ_jk ∫_e N̂_k dA and Σ_j Φ_j = 1. With the plain tri6 basis D_e would
  have zeros at the vertices and no dual basis would exist.
* The mortar integrals over the slave surface Γs, with π the correspondence to the master side,

      D_jj = ∫_Γs N̂_j dA,   M_jk = ∫_Γs Φ_j (N_k ∘ π) dA,   g̃_j = ∫_Γs Φ_j g0 dA,

  N_k the master's plain quadratic functions. The pair of slave node j then acts on the
  transformed nodal displacement d̂_j = Σ_i t_ji u_i (t = T⁻ᵀ,
  :func:`~dolfinx_nnqem.contact.facet_layout.node_combination`): D_jj d̂_j − Σ_k M_jk u_k is the
  weighted relative displacement, D diagonal as in the linear case.

Segment-to-segment integration on curved facets
-----------------------------------------------
Each quadratic facet is split into four linear sub-facets on its nodes (Puso, Laursen, Solberg
2008; Popp et al. 2012): a tri6 into four 3-node triangles, a quad9 into four 4-node
quadrilaterals. For a couple (slave facet e, master facet f):

1. the auxiliary plane through the slave facet's centre x_e(ξ_c), normal to its outward normal
   n_0 there (both from the quadratic map: on a curved facet its tangent plane at the centre);
2. every node of both facets projected onto it along n_0; each slave sub-facet clipped with each
   master sub-facet (Sutherland-Hodgman), the overlap triangulated from its centroid and
   integrated with a collapsed 5 × 5 Gauss rule (degree 9) per triangle;
3. a Gauss point y of the plane is mapped to the local coordinates ζ of the projected slave and
   master sub-facets (linear, or bilinear by Newton) and from there to the parent facets'
   reference coordinates ξ_s, ξ_m, affinely (a sub-facet's nodes sit at fixed reference points);
4. there the QUADRATIC maps and functions are evaluated: N̂(ξ_s), N(ξ_m), the points x_s(ξ_s),
   x_m(ξ_m), the gap g0 = n_0 · (x_m − x_s), and the slave's area element
   |x_ξ × x_η|(ξ_s) · |det ∂ξ/∂ζ| / |det ∂y/∂ζ|.

What is exact and what is approximated. The sub-facets tile each facet's reference domain exactly,
so y ↦ ξ_s is an exact (piecewise smooth) parametrisation of the curved slave facet: D, ∫Φ_j dA and
the coverage are integrals over the true quadratic slave surface, and Σ_k M_jk = ∫Φ_j dA holds at
every fully covered node to the quadrature error (on straight-sided facets whose sub-facets project
to triangles and parallelograms every integrand is a polynomial of degree ≤ 8 in y and the rule is
exact: round-off). The correspondence π between the surfaces is that of the linear sub-facets
projected along n_0, evaluated on the quadratic facets: where the facets are straight-sided it is
the projection along n_0 itself; on curved facets the points x_s(ξ_s) and x_m(ξ_m) lie off n_0's
line by the tangential part of the facets' bulge over their sub-facets (O(h² κ) times the slope),
so the gap measured along n_0 is in error by O(h³ κ²) — the order of the quadratic surfaces' own
geometric error — and π's area distortion enters M at the same order.
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt
import scipy.sparse

from dolfinx_nnqem.contact.mortar_geometry import (MIN_FACING_COSINE, RELATIVE_TOLERANCE, MortarIntegrals,
                                                    _clip, _cross, _dot, _inverse_map_into, _plane_axes, _polygon_area,
                                                    _real_sign_abs,
                                                    candidate_couples)
from dolfinx_nnqem.contact.projection import _cyclic, _shape
from dolfinx_nnqem.contact.quadratic_facets import (NUM_VERTICES, facet_geometry, nodal_integrals, outward_signs,
                                                    reference_nodes, reference_rule, shape_at, transformation,
                                                    transformed_shape_functions)
from dolfinx_nnqem.contact.surfaces import ContactPairError, format_point

__all__ = ["SEGMENT_RULE_POINTS", "SUB_FACETS", "integrate_quadratic_couples", "quadratic_candidate_couples",
           "quadratic_dual_coefficients", "quadratic_mortar_integrals", "segment_rule"]

# numba's on-disk cache invalidates a kernel when ITS file changes, not a callee's: after editing
# mortar_geometry's _clip / _inverse_map(_into) / _polygon_area, projection._shape or
# quadratic_facets.shape_at, clear __pycache__/dual_quadratic*.nbi / *.nbc.

SUB_FACETS = {6: np.array([[0, 5, 4], [5, 1, 3], [4, 3, 2], [3, 4, 5]], dtype=np.int64),
              9: np.array([[0, 4, 8, 5], [4, 1, 6, 8], [5, 8, 7, 2], [8, 6, 3, 7]], dtype=np.int64)}
"""The four linear sub-facets of a tri6 and a quad9 (node positions, counter-clockwise in the
reference coordinates of :mod:`~dolfinx_nnqem.contact.quadratic_facets`; quadrilaterals cyclic)."""

SEGMENT_RULE_POINTS = 5
"""Gauss points per direction of the collapsed rule on each integration triangle: exact for
polynomials of degree 2 × 5 − 1 = 9 (Φ_j N_k of a quad9 on parallelograms has degree 8)."""


def segment_rule(points: int = SEGMENT_RULE_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric points (q, 3) and weights (q,) summing to 1 of the collapsed Gauss rule on a triangle."""
    xi, w = reference_rule(6, points)
    return np.column_stack([1.0 - xi[:, 0] - xi[:, 1], xi[:, 0], xi[:, 1]]), 2.0 * w


# --------------------------------------------------------------------------------------------
# The dual basis on the transformed quadratic basis
# --------------------------------------------------------------------------------------------


def quadratic_dual_coefficients(x: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """A_e = D_e M_e⁻¹ of the dual functions Φ_j = Σ_k a_jk N̂_k of each quadratic slave facet.

    Parameters
    ----------
    x
        (m, k, 3) the facets' nodes (k = 6 or 9) in :mod:`~dolfinx_nnqem.contact.quadratic_facets`' order.

    Returns
    -------
    A
        (m, k, k) a_jk, so that ∫_e Φ_j N̂_k dA = δ_jk ∫_e N̂_k dA.
    D
        (m, k) ∫_e N̂_j dA.

    Raises
    ------
    ContactPairError
        If a facet has a node with ∫_e N̂_j dA ≤ 0 (a facet too distorted for a dual basis).

    Notes
    -----
    M_e and D_e use :func:`~dolfinx_nnqem.contact.quadratic_facets.reference_rule` with the
    quadratic area element: exact on straight-sided flat facets; on curved ones biorthogonality
    holds for that rule, which integrates the rational area element to about 1e-7 relative on a
    strongly curved, distorted facet (``tests/unit/test_dual_quadratic.py``) and far better on a
    mesh's facets.
    """
    x = np.asarray(x, dtype=np.float64)
    k = x.shape[1]
    xi, w = reference_rule(k)
    _, area = facet_geometry(x, xi)
    dA = w * np.linalg.norm(area, axis=2)  # (m, q)
    Nhat = transformed_shape_functions(k, xi)  # (q, k)
    Me = np.einsum("mq,qj,qk->mjk", dA, Nhat, Nhat)
    De = Me.sum(axis=2)
    bad = De <= 0.0
    if np.any(bad):
        f = int(np.flatnonzero(bad.any(axis=1))[0])
        raise ContactPairError(
            f"the quadratic slave facet with vertices {', '.join(format_point(p) for p in x[f, :NUM_VERTICES[k]])} "
            f"has a node whose weight ∫ N̂_j dA = {De[f].min():.3g} is not positive: too distorted for dual mortar")
    A = np.linalg.solve(Me, De[:, :, None] * np.eye(k)).transpose(0, 2, 1)  # (M⁻¹ D)ᵀ, M symmetric
    return np.ascontiguousarray(A), De


# --------------------------------------------------------------------------------------------
# Segment-to-segment integration of one couple (numba)
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _quadratic_frame(x, k, sign):
    """Centre x(ξ_c) and outward unit normal there (quadratic map); the normal's raw length (0: degenerate)."""
    N = np.empty(k)
    dN = np.empty((k, 2))
    d2N = np.empty((k, 3))
    c = 1.0 / 3.0 if k == 6 else 0.5
    shape_at(k, c, c, N, dN, d2N)
    centre = np.zeros(3)
    xs = np.zeros(3)
    xt = np.zeros(3)
    for a in range(k):
        for j in range(3):
            centre[j] += N[a] * x[a, j]
            xs[j] += dN[a, 0] * x[a, j]
            xt[j] += dN[a, 1] * x[a, j]
    n = np.empty(3)
    _cross(xs, xt, n)
    length = np.sqrt(_dot(n, n))
    if length > 0.0:
        for j in range(3):
            n[j] *= sign / length
    return centre, n, length


@numba.njit(cache=True)
def _plane_coordinates(x, x0, n0, t1, t2):
    """In-plane coordinates (k, 2) of the points x (k, 3) in the plane through x0 with axes t1, t2."""
    P = np.empty((x.shape[0], 2))
    d = np.empty(3)
    for a in range(x.shape[0]):
        for j in range(3):
            d[j] = x[a, j] - x0[j]
        P[a, 0] = _dot(d, t1)
        P[a, 1] = _dot(d, t2)
    return P


@numba.njit(cache=True)
def _couple_plane(xs, sign_s, xm, sign_m, min_cos, S, P, frame):
    """A couple's auxiliary plane (steps 1-2 of the module docstring): fill the in-plane coordinates
    S (ks, 2), P (km, 2) and ``frame`` (4, 3): its centre x_0, normal n_0 and axes t_1, t_2; return the
    clip tolerance, or −1 if the couple does not count (a degenerate facet, or facets not facing each other)."""
    ks = xs.shape[0]
    x0, n, js = _quadratic_frame(xs, ks, sign_s)
    _, nm, jm = _quadratic_frame(xm, xm.shape[0], sign_m)
    if js == 0.0 or jm == 0.0 or _dot(nm, n) > -min_cos:
        return -1.0
    t1, t2 = _plane_axes(xs, n)
    S[:] = _plane_coordinates(xs, x0, n, t1, t2)
    P[:] = _plane_coordinates(xm, x0, n, t1, t2)
    frame[0] = x0
    frame[1] = n
    frame[2] = t1
    frame[3] = t2
    diameter = 0.0
    for a in range(ks):
        diameter = max(diameter, 2.0 * np.sqrt(S[a, 0] ** 2 + S[a, 1] ** 2))
    return 1e-12 * diameter


@numba.njit(cache=True)
def _sub_polygon(P, ref, nodes):
    """A sub-facet's projected polygon (nv, 2) and its nodes' reference coordinates (nv, 2),
    counter-clockwise in the plane (reversed if needed; a reversed quadrilateral stays cyclic)."""
    nv = nodes.shape[0]
    poly = np.empty((nv, 2), P.dtype)
    r = np.empty((nv, 2))
    for a in range(nv):
        poly[a, 0] = P[nodes[a], 0]
        poly[a, 1] = P[nodes[a], 1]
        r[a, 0] = ref[nodes[a], 0]
        r[a, 1] = ref[nodes[a], 1]
    if _polygon_area(poly, nv).real < 0.0:
        for a in range(nv // 2):
            b = nv - 1 - a
            for c in range(2):
                tmp = poly[a, c]
                poly[a, c] = poly[b, c]
                poly[b, c] = tmp
                tmp = r[a, c]
                r[a, c] = r[b, c]
                r[b, c] = tmp
    return poly, r


@numba.njit(cache=True)
def _to_parent(poly, r, y0, y1, zeta, xi, N, dN):
    """ξ of the parent facet at the plane point y through the sub-facet (poly, r); returns
    |det ∂ξ/∂ζ| / |det ∂y/∂ζ| (0 on failure of the inverse map). N (4,), dN (4, 2): work arrays.
    Complex poly and y (complex-step derivatives): the moduli are the real part's sign
    (:func:`~dolfinx_nnqem.contact.mortar_geometry._real_sign_abs`)."""
    nv = poly.shape[0]
    if not _inverse_map_into(poly, nv, y0, y1, zeta, N, dN):
        return 0.0 * y0
    _shape(nv, zeta[0], zeta[1], N, dN)
    xi[0] = 0.0
    xi[1] = 0.0
    a00 = 0.0
    a01 = 0.0
    a10 = 0.0
    a11 = 0.0
    b00 = 0.0
    b01 = 0.0
    b10 = 0.0
    b11 = 0.0
    for a in range(nv):
        xi[0] += N[a] * r[a, 0]
        xi[1] += N[a] * r[a, 1]
        a00 += dN[a, 0] * r[a, 0]
        a01 += dN[a, 1] * r[a, 0]
        a10 += dN[a, 0] * r[a, 1]
        a11 += dN[a, 1] * r[a, 1]
        b00 += dN[a, 0] * poly[a, 0]
        b01 += dN[a, 1] * poly[a, 0]
        b10 += dN[a, 0] * poly[a, 1]
        b11 += dN[a, 1] * poly[a, 1]
    det_y = _real_sign_abs(b00 * b11 - b01 * b10)
    if det_y.real == 0.0:
        return det_y * 0.0
    return _real_sign_abs(a00 * a11 - a01 * a10) / det_y


@numba.njit(cache=True)
def _integrate_segment(poly, n, Ss, rs, Pm, rm, xs, xm, T, A, n0, qb, qw, M, g):
    """Integrate Φ_j N_k and Φ_j g0 over the overlap polygon poly[:n] of the slave sub-facet
    (Ss, rs) and the master sub-facet (Pm, rm) (module docstring, steps 3 and 4); add them to
    M and g. Returns the slave area integrated and the Gauss points whose inverse map failed."""
    ks = xs.shape[0]
    km = xm.shape[0]
    c0 = 0.0
    c1 = 0.0
    for i in range(n):
        c0 += poly[i, 0] / n
        c1 += poly[i, 1] / n
    Ns = np.empty(ks)
    dNs = np.empty((ks, 2))
    d2Ns = np.empty((ks, 3))
    Nm = np.empty(km)
    dNm = np.empty((km, 2))
    d2Nm = np.empty((km, 3))
    Nhat = np.empty(ks)
    phi = np.empty(ks)
    zeta = np.empty(2)
    xi_s = np.empty(2)
    xi_m = np.empty(2)
    xa = np.empty(3)
    xb = np.empty(3)
    cr = np.empty(3)
    N4 = np.empty(4)
    dN4 = np.empty((4, 2))
    total = 0.0
    failed = 0
    for i in range(n):
        j = (i + 1) % n
        cell = 0.5 * ((poly[i, 0] - c0) * (poly[j, 1] - c1) - (poly[j, 0] - c0) * (poly[i, 1] - c1))
        if cell <= 0.0:
            continue
        for q in range(qw.shape[0]):
            y0 = qb[q, 0] * c0 + qb[q, 1] * poly[i, 0] + qb[q, 2] * poly[j, 0]
            y1 = qb[q, 0] * c1 + qb[q, 1] * poly[i, 1] + qb[q, 2] * poly[j, 1]
            ratio = _to_parent(Ss, rs, y0, y1, zeta, xi_s, N4, dN4)
            if ratio == 0.0 or _to_parent(Pm, rm, y0, y1, zeta, xi_m, N4, dN4) == 0.0:
                failed += 1
                continue
            shape_at(ks, xi_s[0], xi_s[1], Ns, dNs, d2Ns)
            shape_at(km, xi_m[0], xi_m[1], Nm, dNm, d2Nm)
            xa[:] = 0.0
            xb[:] = 0.0
            gap = 0.0
            for a in range(ks):
                for c in range(3):
                    xa[c] += dNs[a, 0] * xs[a, c]
                    xb[c] += dNs[a, 1] * xs[a, c]
                    gap -= Ns[a] * xs[a, c] * n0[c]
            for b in range(km):
                for c in range(3):
                    gap += Nm[b] * xm[b, c] * n0[c]
            _cross(xa, xb, cr)
            w = qw[q] * cell * ratio * np.sqrt(_dot(cr, cr))
            total += w
            for a in range(ks):
                Nhat[a] = 0.0
                for b in range(ks):
                    Nhat[a] += T[a, b] * Ns[b]
            for a in range(ks):
                phi[a] = 0.0
                for b in range(ks):
                    phi[a] += A[a, b] * Nhat[b]
            for a in range(ks):
                for b in range(km):
                    M[a, b] += w * phi[a] * Nm[b]
                g[a] += w * phi[a] * gap
    return total, failed


@numba.njit(cache=True)
def _quadratic_couple(xs, sign_s, T, A, xm, sign_m, sub_s, sub_m, ref_s, ref_m, qb, qw, relative_tolerance,
                      min_cos, M, g):
    """Add one couple's integrals to M (ks, km) and g (ks,); return the slave area of the
    overlap (0: the couple does not count) and the Gauss points whose inverse map failed."""
    S, P, frame = np.empty((xs.shape[0], 2)), np.empty((xm.shape[0], 2)), np.empty((4, 3))
    tol = _couple_plane(xs, sign_s, xm, sign_m, min_cos, S, P, frame)
    if tol < 0.0:
        return 0.0, 0
    n0 = frame[1]
    poly = np.empty((16, 2))
    subject = np.empty((16, 2))
    total = 0.0
    failed = 0
    for a in range(sub_s.shape[0]):
        Ss, rs = _sub_polygon(S, ref_s, sub_s[a])
        sub_area = _polygon_area(Ss, Ss.shape[0])
        if sub_area <= 0.0:
            continue
        for b in range(sub_m.shape[0]):
            Pm, rm = _sub_polygon(P, ref_m, sub_m[b])
            for c in range(Pm.shape[0]):
                subject[c, 0] = Pm[c, 0]
                subject[c, 1] = Pm[c, 1]
            n = _clip(subject, Pm.shape[0], Ss, Ss.shape[0], tol, poly)
            if n < 3 or _polygon_area(poly, n) <= relative_tolerance * sub_area:
                continue
            area, bad = _integrate_segment(poly, n, Ss, rs, Pm, rm, xs, xm, T, A, n0, qb, qw, M, g)
            total += area
            failed += bad
    return total, failed


@numba.njit(cache=True)
def _integrate_quadratic_couples(ci, cj, xs, sign_s, T, A, xm, sign_m, sub_s, sub_m, ref_s, ref_m, qb, qw,
                                 relative_tolerance, min_cos):
    """:func:`_quadratic_couple` for the couples (ci[c], cj[c]); one row of each output per couple."""
    nc = ci.shape[0]
    ks = xs.shape[1]
    km = xm.shape[1]
    M = np.zeros((nc, ks, km))
    g = np.zeros((nc, ks))
    area = np.zeros(nc)
    failed = np.zeros(nc, np.int64)
    for c in range(nc):
        area[c], failed[c] = _quadratic_couple(xs[ci[c]], sign_s[ci[c]], T, A[ci[c]], xm[cj[c]], sign_m[cj[c]],
                                               sub_s, sub_m, ref_s, ref_m, qb, qw, relative_tolerance, min_cos,
                                               M[c], g[c])
    return M, g, area, failed


# --------------------------------------------------------------------------------------------
# The driver
# --------------------------------------------------------------------------------------------


def _reach_beyond_vertices(x: np.ndarray, nv: int) -> float:
    """The largest distance by which a facet's nodes lie farther from its vertex mean than its
    farthest vertex (a curved facet's bulging edges; 0 for straight-sided facets)."""
    centre = x[:, :nv].mean(axis=1, keepdims=True)
    d = np.linalg.norm(x - centre, axis=2)
    return float(max((d.max(axis=1) - d[:, :nv].max(axis=1)).max(), 0.0))


def quadratic_candidate_couples(xs: np.ndarray, slave_area: np.ndarray, xm: np.ndarray, master_area: np.ndarray,
                                search_distance: float) -> tuple[np.ndarray, np.ndarray]:
    """The couples (slave facet, master facet) of quadratic facets that may overlap: from their
    vertices (cyclic), their reach widened by how far curved facets' nodes lie beyond them (0 for
    straight-sided facets); see :func:`~dolfinx_nnqem.contact.mortar_geometry.candidate_couples`."""
    ks, km = xs.shape[1], xm.shape[1]
    vs, _ = _cyclic(xs[:, :NUM_VERTICES[ks]], slave_area)
    vm, _ = _cyclic(xm[:, :NUM_VERTICES[km]], master_area)
    margin = 2.0 * max(_reach_beyond_vertices(xs, NUM_VERTICES[ks]), _reach_beyond_vertices(xm, NUM_VERTICES[km]))
    return candidate_couples(vs, vm, float(search_distance), margin)


def integrate_quadratic_couples(ci: np.ndarray, cj: np.ndarray, xs: np.ndarray, sign_s: np.ndarray, A: np.ndarray,
                                xm: np.ndarray, sign_m: np.ndarray, relative_tolerance: float = RELATIVE_TOLERANCE,
                                min_facing_cosine: float = MIN_FACING_COSINE
                                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The integrals of the couples (slave facet ``ci[c]``, master facet ``cj[c]``) of quadratic facets.

    Parameters
    ----------
    xs, xm
        (ms, ks, 3), (mm, km, 3) the facets' nodes (:mod:`~dolfinx_nnqem.contact.quadratic_facets`' order).
    sign_s, sign_m
        (ms,), (mm,) :func:`~dolfinx_nnqem.contact.quadratic_facets.outward_signs` of the facets.
    A
        (ms, ks, ks) the slave facets' dual coefficients (:func:`quadratic_dual_coefficients`).

    Returns
    -------
    (M (c, ks, km), g̃ (c, ks), the slave area of each overlap (0: the couple does not count), the
    Gauss points whose inverse map failed (c,)).
    """
    ks, km = xs.shape[1], xm.shape[1]
    qb, qw = segment_rule()
    return _integrate_quadratic_couples(ci, cj, xs, sign_s, transformation(ks), A, xm, sign_m, SUB_FACETS[ks],
                                        SUB_FACETS[km], reference_nodes(ks), reference_nodes(km), qb, qw,
                                        relative_tolerance, min_facing_cosine)


def _area_coverage(s_pos: np.ndarray, facet_area: np.ndarray, covered_area: np.ndarray) -> np.ndarray:
    """(p,) the covered fraction of the area of each slave node's facets: 1 where master facets cover
    them (to the quadrature error), 0 where none does, above 1 where master facets overlap in projection.

    Parameters
    ----------
    s_pos
        (m, k) each slave facet's nodes as rows of the result.
    facet_area, covered_area
        (m,) each slave facet's area and its area covered by master facets.
    """
    p = int(s_pos.max()) + 1
    k = s_pos.shape[1]
    return (np.bincount(s_pos.ravel(), np.repeat(covered_area, k), minlength=p)
            / np.bincount(s_pos.ravel(), np.repeat(facet_area, k), minlength=p))


def quadratic_mortar_integrals(slave_nodes: npt.ArrayLike, slave_x: npt.ArrayLike, slave_area: npt.ArrayLike,
                               master_nodes: npt.ArrayLike, master_x: npt.ArrayLike, master_area: npt.ArrayLike,
                               search_distance: float, relative_tolerance: float = RELATIVE_TOLERANCE,
                               min_facing_cosine: float = MIN_FACING_COSINE) -> MortarIntegrals:
    """Dual mortar integrals D, M, g̃ of a quadratic slave surface against a quadratic master surface.

    Parameters
    ----------
    slave_nodes, master_nodes
        (m, k) global node indices of each facet's nodes (k = 6 or 9; the sides may differ).
    slave_x, master_x
        (m, k, 3) their coordinates in :mod:`~dolfinx_nnqem.contact.quadratic_facets`' order
        (``Facets.x``; vertices in any order).
    slave_area, master_area
        (m, 3) outward area vectors (``Facets.area``).
    search_distance
        Largest normal distance between a slave facet and the master facets it is coupled with.
    relative_tolerance, min_facing_cosine
        As for :func:`~dolfinx_nnqem.contact.mortar_geometry.mortar_integrals`.

    Returns
    -------
    MortarIntegrals
        As for linear facets, with D_jj = ∫ N̂_j dA, M_jk = ∫ Φ_j (N_k ∘ π) dA and the normals
        ∫ N̂_j n dA normalised (those of :class:`~dolfinx_nnqem.contact.surfaces.SurfaceNodes`). The
        coverage is the covered fraction of the area of node j's facets, not ∫_covered N̂_j dA / D_jj:
        the quadratic functions change sign, so that ratio exceeds 1 at partly covered nodes (1.044
        at quad9 nodes whose facets are 90 % covered) and could not tell a folded master. Row j is
        the TRANSFORMED slave node j: its pair acts on d̂_j
        (:func:`~dolfinx_nnqem.contact.facet_layout.node_combination`).
    """
    slave_nodes = np.asarray(slave_nodes, dtype=np.int64)
    master_nodes = np.asarray(master_nodes, dtype=np.int64)
    xs = np.ascontiguousarray(slave_x, dtype=np.float64)
    xm = np.ascontiguousarray(master_x, dtype=np.float64)
    slave_area = np.asarray(slave_area, dtype=np.float64)
    master_area = np.asarray(master_area, dtype=np.float64)
    A, De = quadratic_dual_coefficients(xs)
    ci, cj = quadratic_candidate_couples(xs, slave_area, xm, master_area, search_distance)
    Mc, gc, area, failed = integrate_quadratic_couples(ci, cj, xs, outward_signs(xs, slave_area), A, xm,
                                                       outward_signs(xm, master_area), relative_tolerance,
                                                       min_facing_cosine)
    used = area > 0.0
    ci, cj, Mc, gc = ci[used], cj[used], Mc[used], gc[used]

    slave_index, first, s_pos = np.unique(slave_nodes.ravel(), return_index=True, return_inverse=True)
    s_pos = s_pos.reshape(slave_nodes.shape)
    master_index, m_pos = np.unique(master_nodes.ravel(), return_inverse=True)
    m_pos = m_pos.reshape(master_nodes.shape)
    p, q = len(slave_index), len(master_index)
    D = np.bincount(s_pos.ravel(), De.ravel(), minlength=p)
    rows = np.broadcast_to(s_pos[ci][:, :, None], Mc.shape).ravel()
    cols = np.broadcast_to(m_pos[cj][:, None, :], Mc.shape).ravel()
    M = scipy.sparse.coo_matrix((Mc.ravel(), (rows, cols)), shape=(p, q)).tocsr()
    M.sum_duplicates()
    M.sort_indices()
    weighted_gap = np.bincount(s_pos[ci].ravel(), gc.ravel(), minlength=p)
    coverage = _area_coverage(s_pos, De.sum(axis=1), np.bincount(ci, area[used], minlength=len(xs)))
    _, moments = nodal_integrals(xs, slave_area)
    normal = np.zeros((p, 3))
    np.add.at(normal, s_pos.ravel(), moments.reshape(-1, 3))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    x = xs.reshape(-1, 3)[first]
    return MortarIntegrals(slave_index, x, normal, D, M, master_index, weighted_gap, coverage,
                           int(used.sum()), int(failed.sum()))
