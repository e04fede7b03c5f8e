r"""Dual mortar geometry: dual shape functions and segment-to-segment mortar integrals.

``formulation.md`` §2b (dual mortar; Wohlmuth 2000, Popp, Gitterle, Gee, Wall 2010). On each
slave facet e the dual functions are Φ_j = Σ_k a_jk N_k with

    A_e = D_e M_e⁻¹,   D_e = diag(∫_e N_j dA),   M_e = [∫_e N_j N_k dA],

so that ∫_e Φ_j N_k dA = δ_jk ∫_e N_k dA (biorthogonality). The mortar integrals are

    D_jj = ∫_Γs N_j dA,   M_jk = ∫_Γs Φ_j (N_k ∘ π) dA,   g̃_j = ∫_Γs Φ_j g0 dA,

with π the projection onto the master side and g0 the initial gap; the pair set then uses
w_j = R_j (u_j − Σ_k (M_jk / D_jj) u_k) and g0_j = g̃_j / D_jj.

Segment-to-segment integration (Popp et al. 2010, 3D), for each couple (slave facet e, master
facet f):

1. the auxiliary plane through the slave facet's centre x_0 = x_e(ξ = centre), normal to its
   centre normal n_0 = ∂x/∂ξ × ∂x/∂η / |…| (outward for the slave body);
2. both facets' vertices projected onto it along n_0 (2D polygons; x = y + h n_0 with y in
   the plane and h the height above it);
3. the overlap polygon by Sutherland-Hodgman clipping (the projected slave facet is convex);
4. the overlap triangulated from its vertex mean; on each sub-triangle a 7-point rule of
   degree 5; each Gauss point y mapped back to the slave and master local coordinates ξ_s, ξ_m
   by inverting the projected (bilinear or linear) maps, by Newton for quads;
5. g0 = h_m(ξ_m) − h_s(ξ_s) = n_0 · (x_m − x_s): the distance along the slave normal from the
   slave point to the master point it faces (both lie on the same normal line), positive when
   the master lies ahead of the slave's outer side (an open gap), in the reference
   configuration;
6. plane area is converted to slave-facet area with |x_ξ × x_η| / |det ∂y/∂ξ| at ξ_s (1 for
   planar slave facets; the exact area element for warped quads).

Exactness: where slave facets are planar parallelograms or triangles and master facets project
to parallelograms or triangles, Φ_j ∘ ξ_s and N_k ∘ ξ_m are polynomials of degree ≤ 2 in y, so
every integral is exact and the patch property Σ_k M_jk = D_jj holds to round-off at every fully
covered slave node (flat interfaces, and also curved ones made of planar slave facets). On
warped or distorted (non-parallelogram) slave quads the integrands are rational: the identity
then holds up to the quadrature error, which vanishes fast under refinement (a saddle
z = 2 (x − ½)(y − ½) meshed 4², 8², 16²: 7e-6, 1e-7, 3e-9 relative).

Rules (documented choices):

* A couple counts only if the master facet FACES the slave facet: n_m · n_0 < −
  :data:`MIN_FACING_COSINE` (n_m the master's outward centre normal). This ignores master
  facets seen edge-on (their projection is a sliver) and facets on the far side of a thin
  master body.
* An overlap whose area is below ``relative_tolerance`` × the projected slave area is empty.
* Facet vertices may come in any order; they are reordered cyclically (outward, counter-
  clockwise) by :func:`dolfinx_nnqem.contact.projection.cyclic_order`, and local coordinates
  refer to that order (see :mod:`~dolfinx_nnqem.contact.projection`).

The couple kernels below, :func:`dual_coefficients` and :func:`couple_integrals` take real or complex
coordinates from one source: every decision (facing, clipping, the inverse maps' convergence, empty
sub-triangles) on the real part and no modulus of a complex value (√(c · c), the real part's sign), so
that complex coordinates x + i h e_p give the complex-step derivatives of
:mod:`~dolfinx_nnqem.contact.couple_complex_step`; a real evaluation is the arithmetic it always was.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt
import scipy.sparse
from scipy.spatial import cKDTree

from dolfinx_nnqem.contact.projection import (
    _check_facets,
    _cyclic,
    _shape,
    newell_area_vectors,
    shape_derivatives,
    shape_functions,
)

__all__ = [
    "MIN_FACING_COSINE",
    "RELATIVE_TOLERANCE",
    "MortarIntegrals",
    "candidate_couples",
    "couple_integrals",
    "dual_coefficients",
    "facet_rule",
    "mortar_integrals",
    "triangle_rule",
]

MIN_FACING_COSINE = 1e-2
"""A master facet counts for a slave facet only if −n_m · n_0 exceeds this (it faces the slave
facet and is inclined less than about 89.4° to it)."""

RELATIVE_TOLERANCE = 1e-10
"""Overlaps smaller than this × the projected slave facet's area are empty; clipping treats points
within 1e-12 × the slave facet's diameter of a clip line as on it."""

_NEWTON_MAX_ITERATIONS = 30

_NEARLY_ALONG = 10.0
"""A clipped edge spanning less than this × the clip tolerance (1e-11 of the slave facet's diameter) across
the clip line lies along it, within the tolerance band's round-off: :func:`_crossing` holds its crossing
parameter under a complex step. (1e6, spans below 1e-6 of the diameter, changed the Newton path of the P2
mortar slide's first sliding increment, one step no longer quadratic; 10 is the band's own scale.)"""

# Note on numba's on-disk cache: the kernels below call projection._shape; numba invalidates a
# cached kernel when ITS file changes, not when a callee's file does. After editing _shape,
# clear __pycache__/*.nbi / *.nbc of this module.


# --------------------------------------------------------------------------------------------
# Quadrature
# --------------------------------------------------------------------------------------------


def triangle_rule() -> tuple[np.ndarray, np.ndarray]:
    """The 7-point rule of degree 5 on a triangle (Radon).

    Returns
    -------
    tuple
        Barycentric coordinates, shape ``(7, 3)``, and weights, shape ``(7,)``, summing to 1
        (multiply by the triangle's area).
    """
    r = np.sqrt(15.0)
    a, b = (6.0 - r) / 21.0, (6.0 + r) / 21.0
    wa, wb = (155.0 - r) / 1200.0, (155.0 + r) / 1200.0
    bary = [[1 / 3, 1 / 3, 1 / 3]]
    weights = [9.0 / 40.0]
    for c, w in ((a, wa), (b, wb)):
        for p in range(3):
            row = [c, c, c]
            row[p] = 1.0 - 2.0 * c
            bary.append(row)
            weights.append(w)
    return np.array(bary), np.array(weights)


def facet_rule(k: int) -> tuple[np.ndarray, np.ndarray]:
    """A rule on the reference facet: the 7-point degree-5 rule on the unit triangle (k = 3) or
    the 3 × 3 Gauss rule on [−1, 1]² (k = 4, degree 5 in each variable).

    Returns points ``(q, 2)`` and weights ``(q,)`` (summing to the reference area ½ or 4).
    Both integrate N_j N_k det J exactly on planar facets (det J is constant on a triangle and
    affine in ξ and η on a planar quadrilateral).
    """
    if k == 3:
        bary, w = triangle_rule()
        return bary[:, 1:].copy(), 0.5 * w
    g, wg = np.polynomial.legendre.leggauss(3)
    s, t = np.meshgrid(g, g, indexing="ij")
    return np.column_stack([s.ravel(), t.ravel()]), np.outer(wg, wg).ravel()


# --------------------------------------------------------------------------------------------
# Dual shape functions
# --------------------------------------------------------------------------------------------


def _area_elements(x_cyclic: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """|∂x/∂ξ × ∂x/∂η|, shape (m, q), of facets (m, k, 3) at reference points (q, 2).

    √(c · c) without the modulus (np.linalg.norm's arithmetic for real c, bit for bit): analytic in
    complex coordinates, for the complex-step derivatives (:mod:`~dolfinx_nnqem.contact.couple_derivatives`)."""
    dN = shape_derivatives(x_cyclic.shape[1], xi)  # (q, k, 2)
    J = np.einsum("qka,mkj->mqaj", dN, x_cyclic)
    c = np.cross(J[:, :, 0], J[:, :, 1])
    return np.sqrt(np.add.reduce(c * c, axis=2))


def dual_coefficients(x_cyclic: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients A_e = D_e M_e⁻¹ of the dual functions Φ_j = Σ_k a_jk N_k of each facet.

    Parameters
    ----------
    x_cyclic
        (m, k, 3) facet vertices in cyclic order (:func:`~dolfinx_nnqem.contact.projection.cyclic_order`);
        real, or complex for complex-step derivatives (the results are then complex).

    Returns
    -------
    A
        (m, k, k) a_jk, so that ∫_e Φ_j N_k dA = δ_jk ∫_e N_k dA.
    D
        (m, k) ∫_e N_j dA.

    Notes
    -----
    M_e and D_e use :func:`facet_rule`: exact for triangles and planar (possibly distorted)
    quadrilaterals; for warped quadrilaterals, biorthogonality holds for that rule. Since
    Σ_k N_k = 1, D_e is M_e's row sum. For a triangle, Φ_j = 3 N_j − N_{j+1} − N_{j+2}.
    """
    x_cyclic = np.asarray(x_cyclic)
    x_cyclic = x_cyclic.astype(np.result_type(x_cyclic.dtype, np.float64), copy=False)
    k = x_cyclic.shape[1]
    xi, w = facet_rule(k)
    N = shape_functions(k, xi)
    dA = w * _area_elements(x_cyclic, xi)  # (m, q)
    M = np.einsum("mq,qj,qk->mjk", dA, N, N)
    D = M.sum(axis=2)
    # A = D M⁻¹ = (M⁻¹ D)ᵀ since M is symmetric and D diagonal
    A = np.linalg.solve(M, D[:, :, None] * np.eye(k)).transpose(0, 2, 1)
    return np.ascontiguousarray(A), D


# --------------------------------------------------------------------------------------------
# Segment-to-segment integration of one couple (numba)
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _cross(a, b, out):
    """out = a × b for 3-vectors (hand-written: numba's np.cross is slow to compile)."""
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@numba.njit(cache=True)
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@numba.njit(cache=True)
def _centre_frame(x, k):
    """Centre x(ξ_c) (the vertex mean for quads, the centroid for triangles), unit normal
    ∂x/∂ξ × ∂x/∂η / |…| there, and |∂x/∂ξ × ∂x/∂η| (0 for a degenerate facet)."""
    N = np.empty(k)
    dN = np.empty((k, 2))
    c = 1.0 / 3.0 if k == 3 else 0.0
    _shape(k, c, c, N, dN)
    centre = np.zeros(3, x.dtype)
    xs = np.zeros(3, x.dtype)
    xt = np.zeros(3, x.dtype)
    for a in range(k):
        for j in range(3):
            centre[j] += N[a] * x[a, j]
            xs[j] += dN[a, 0] * x[a, j]
            xt[j] += dN[a, 1] * x[a, j]
    n = np.empty(3, x.dtype)
    _cross(xs, xt, n)
    length = np.sqrt(_dot(n, n))
    if length.real > 0.0:
        n /= length
    return centre, n, length


@numba.njit(cache=True)
def _inverse_map(P, k, y0, y1, xi):
    """Local coordinates ξ with Σ_a N_a(ξ) P_a = y for a 2D (projected) facet P (k, 2).

    tri3: one linear solve. quad4: Newton from the centre (converges in a few steps for a convex
    quadrilateral and y inside it; one step for a parallelogram). Returns False on failure.
    """
    if k == 3:
        return _inverse_map_triangle(P, y0, y1, xi)
    return _inverse_map_quadrilateral(P, y0, y1, xi, np.empty(4, P.dtype), np.empty((4, 2), P.dtype))


@numba.njit(cache=True)
def _inverse_map_into(P, k, y0, y1, xi, N, dN):
    """:func:`_inverse_map` with the caller's work arrays N (4,) and dN (4, 2) for a quad4's shape
    functions (no allocation per point: the degree-2 couple differences call it millions of times)."""
    if k == 3:
        return _inverse_map_triangle(P, y0, y1, xi)
    return _inverse_map_quadrilateral(P, y0, y1, xi, N, dN)


@numba.njit(cache=True)
def _inverse_map_triangle(P, y0, y1, xi):
    """:func:`_inverse_map` of a tri3: one linear solve."""
    a0 = P[1, 0] - P[0, 0]
    a1 = P[1, 1] - P[0, 1]
    b0 = P[2, 0] - P[0, 0]
    b1 = P[2, 1] - P[0, 1]
    r0 = y0 - P[0, 0]
    r1 = y1 - P[0, 1]
    det = a0 * b1 - a1 * b0
    if det.real == 0.0:
        return False
    xi[0] = (r0 * b1 - r1 * b0) / det
    xi[1] = (a0 * r1 - a1 * r0) / det
    return True


@numba.njit(cache=True)
def _inverse_map_quadrilateral(P, y0, y1, xi, N, dN):
    """:func:`_inverse_map` of a quad4: Newton from the centre, N (4,) and dN (4, 2) its work arrays."""
    xi[0] = 0.0
    xi[1] = 0.0
    size = np.inf
    for _ in range(_NEWTON_MAX_ITERATIONS):
        _shape(4, xi[0], xi[1], N, dN)
        F0 = -y0
        F1 = -y1
        J00 = 0.0
        J01 = 0.0
        J10 = 0.0
        J11 = 0.0
        for a in range(4):
            F0 += N[a] * P[a, 0]
            F1 += N[a] * P[a, 1]
            J00 += dN[a, 0] * P[a, 0]
            J01 += dN[a, 1] * P[a, 0]
            J10 += dN[a, 0] * P[a, 1]
            J11 += dN[a, 1] * P[a, 1]
        det = J00 * J11 - J01 * J10
        if det.real == 0.0:
            return False
        d0 = -(J11 * F0 - J01 * F1) / det
        d1 = -(-J10 * F0 + J00 * F1) / det
        xi[0] += d0
        xi[1] += d1
        size = max(abs(d0.real), abs(d1.real))  # complex ξ: its imaginary part converges with it
        if size < 1e-13:
            return True
    return size < 1e-9


@numba.njit(cache=True)
def _clip(subject, n, clipper, kc, tol, out):
    """Sutherland-Hodgman: the part of polygon ``subject[:n]`` inside the convex polygon
    ``clipper[:kc]``, both counter-clockwise, into ``out``; returns its vertex count.

    A point within ``tol`` of a clip line counts as inside, so coincident and collinear edges
    are kept (not clipped away by round-off); crossing parameters are clamped to [0, 1];
    consecutive vertices closer than ``tol`` are merged afterwards.
    """
    poly = np.empty((16, 2), subject.dtype)
    for i in range(n):
        poly[i, 0] = subject[i, 0]
        poly[i, 1] = subject[i, 1]
    buf = np.empty((16, 2), subject.dtype)
    for e in range(kc):
        if n == 0:
            break
        a0 = clipper[e, 0]
        a1 = clipper[e, 1]
        ex = clipper[(e + 1) % kc, 0] - a0
        ey = clipper[(e + 1) % kc, 1] - a1
        L = np.sqrt(ex * ex + ey * ey)
        if L.real == 0.0:
            continue
        m = 0
        for i in range(n):
            p0 = poly[i, 0]
            p1 = poly[i, 1]
            q0 = poly[(i + 1) % n, 0]
            q1 = poly[(i + 1) % n, 1]
            dp = (ex * (p1 - a1) - ey * (p0 - a0)) / L  # signed distance, > 0 on the inner (left) side
            dq = (ex * (q1 - a1) - ey * (q0 - a0)) / L
            inside_p = dp.real >= -tol  # decisions on the real part (complex step: the same branch)
            inside_q = dq.real >= -tol
            if inside_p and m < 16:
                buf[m, 0] = p0
                buf[m, 1] = p1
                m += 1
            if inside_p != inside_q and m < 16:
                t = _crossing(dp, dq, tol)
                buf[m, 0] = p0 + t * (q0 - p0)
                buf[m, 1] = p1 + t * (q1 - p1)
                m += 1
        for i in range(m):
            poly[i, 0] = buf[i, 0]
            poly[i, 1] = buf[i, 1]
        n = m
    # merge near-coincident consecutive vertices (clipping along a shared edge duplicates them)
    m = 0
    for i in range(n):
        if m > 0 and abs((poly[i, 0] - out[m - 1, 0]).real) <= tol and abs((poly[i, 1] - out[m - 1, 1]).real) <= tol:
            continue
        out[m, 0] = poly[i, 0]
        out[m, 1] = poly[i, 1]
        m += 1
    while m > 1 and abs((out[m - 1, 0] - out[0, 0]).real) <= tol and abs((out[m - 1, 1] - out[0, 1]).real) <= tol:
        m -= 1
    return m


@numba.njit(cache=True)
def _crossing(dp, dq, tol):
    """The parameter t = dp / (dp − dq) in [0, 1] where an edge with signed distances dp, dq crosses a clip
    line (:func:`_clamped_to_unit`). An edge that spans less than :data:`_NEARLY_ALONG` × tol across the
    line lies nearly along it (coincident edges): its crossing's place is ill-conditioned, and so is its
    derivative (∝ 1 / (dp − dq)); there t is held fixed under a complex step (its real part alone), so
    the vertex moves with the edge's end points. A real t is the same either way."""
    t = _clamped_to_unit(dp / (dp - dq))
    if abs((dp - dq).real) <= _NEARLY_ALONG * tol:
        return t.real + 0.0 * t
    return t


@numba.njit(cache=True)
def _clamped_to_unit(t):
    """t clamped to [0, 1] by its real part (min(1, max(0, t)) for a real t; a clamped complex t is
    constant, its imaginary part 0)."""
    if t.real < 0.0:
        return t * 0.0 + 0.0
    if t.real > 1.0:
        return t * 0.0 + 1.0
    return t


@numba.njit(cache=True)
def _polygon_area(P, n):
    """Signed area (counter-clockwise positive) of the 2D polygon P[:n]."""
    s = 0.0
    for i in range(n):
        j = (i + 1) % n
        s += P[i, 0] * P[j, 1] - P[j, 0] * P[i, 1]
    return 0.5 * s


@numba.njit(cache=True)
def _plane_axes(xs, n0):
    """The in-plane axes of a couple's plane normal to n0: t1 along the first slave edge (its
    in-plane part, normalised), t2 = n0 × t1 (right-handed with n0)."""
    t1 = np.empty(3, xs.dtype)
    t2 = np.empty(3, xs.dtype)
    for j in range(3):
        t1[j] = xs[1, j] - xs[0, j]
    tn = _dot(t1, n0)
    for j in range(3):
        t1[j] -= tn * n0[j]
    tl = np.sqrt(_dot(t1, t1))
    for j in range(3):
        t1[j] /= tl
    _cross(n0, t1, t2)
    return t1, t2


@numba.njit(cache=True)
def _in_plane(xs, ks, xm, km, x0, n0):
    """Both facets' nodes in the plane through x0 normal to n0: the in-plane coordinates S (ks, 2)
    and Pm (km, 2), the heights hs (ks,) and hm (km,) above the plane, and the slave facet's
    diameter. In-plane axes: :func:`_plane_axes`."""
    t1, t2 = _plane_axes(xs, n0)
    d = np.empty(3, xs.dtype)
    S = np.empty((ks, 2), xs.dtype)
    hs = np.empty(ks, xs.dtype)
    diameter = 0.0
    for a in range(ks):
        for j in range(3):
            d[j] = xs[a, j] - x0[j]
        S[a, 0] = _dot(d, t1)
        S[a, 1] = _dot(d, t2)
        hs[a] = _dot(d, n0)
        diameter = max(diameter, 2.0 * np.sqrt(S[a, 0].real ** 2 + S[a, 1].real ** 2))  # a tolerance: real
    Pm = np.empty((km, 2), xs.dtype)
    hm = np.empty(km, xs.dtype)
    for a in range(km):
        for j in range(3):
            d[j] = xm[a, j] - x0[j]
        Pm[a, 0] = _dot(d, t1)
        Pm[a, 1] = _dot(d, t2)
        hm[a] = _dot(d, n0)
    return S, hs, Pm, hm, diameter


@numba.njit(cache=True)
def _couple(xs, A, xm, qb, qw, relative_tolerance, min_cos, M, g, cov):
    """Add one couple's integrals to M (ks, km), g (ks,), cov (ks,) (see the module doc).

    Returns the overlap area on the slave facet (0 if the couple does not count) and the number
    of Gauss points whose inverse map failed (skipped).
    """
    ks = xs.shape[0]
    km = xm.shape[0]
    x0, n0, js = _centre_frame(xs, ks)
    _, nm, jm = _centre_frame(xm, km)
    if js.real == 0.0 or jm.real == 0.0 or _dot(nm, n0).real > -min_cos:
        return 0.0, 0
    S, hs, Pm, hm, diameter = _in_plane(xs, ks, xm, km, x0, n0)
    slave_area = _polygon_area(S, ks).real
    if slave_area <= 0.0:
        return 0.0, 0
    # the master facet turns counter-clockwise about its own (opposite) normal: reverse it
    subject = np.empty((16, 2), xs.dtype)
    reverse = _polygon_area(Pm, km).real < 0.0
    for a in range(km):
        b = km - 1 - a if reverse else a
        subject[a, 0] = Pm[b, 0]
        subject[a, 1] = Pm[b, 1]
    tol = 1e-12 * diameter
    poly = np.empty((16, 2), xs.dtype)
    n = _clip(subject, km, S, ks, tol, poly)
    if n < 3:
        return 0.0, 0
    if _polygon_area(poly, n).real <= relative_tolerance * slave_area:
        return 0.0, 0
    return _integrate_overlap(poly, n, xs, S, hs, Pm, hm, A, qb, qw, M, g, cov)


@numba.njit(cache=True)
def _real_sign_abs(d):
    """|d| for a real d; d times the sign of its real part for a complex d (analytic, unlike the
    modulus: the complex step differentiates it)."""
    return d if d.real >= 0.0 else -d


@numba.njit(cache=True)
def _integrate_overlap(poly, n, xs, S, hs, Pm, hm, A, qb, qw, M, g, cov):
    """Integrate Φ_j N_k, Φ_j g and N_j over the overlap polygon poly[:n], triangulated from its
    centroid, with the Gauss points mapped back to both facets; add them to M, g, cov. Returns
    the area integrated and the number of Gauss points whose inverse map failed (skipped)."""
    ks = S.shape[0]
    km = Pm.shape[0]
    c0 = 0.0
    c1 = 0.0
    for i in range(n):
        c0 += poly[i, 0] / n
        c1 += poly[i, 1] / n
    dtype = S.dtype
    Ns = np.empty(ks, dtype)
    dNs = np.empty((ks, 2), dtype)
    Nm = np.empty(km, dtype)
    dNm = np.empty((km, 2), dtype)
    xi_s = np.empty(2, dtype)
    xi_m = np.empty(2, dtype)
    phi = np.empty(ks, dtype)
    xa = np.empty(3, dtype)
    xb = np.empty(3, dtype)
    cr = np.empty(3, dtype)
    total = 0.0
    failed = 0
    for i in range(n):
        j = (i + 1) % n  # the sub-triangle (centroid, poly[i], poly[j])
        cell = 0.5 * ((poly[i, 0] - c0) * (poly[j, 1] - c1) - (poly[j, 0] - c0) * (poly[i, 1] - c1))
        if cell.real <= 0.0:
            continue
        for q in range(qw.shape[0]):
            y0 = qb[q, 0] * c0 + qb[q, 1] * poly[i, 0] + qb[q, 2] * poly[j, 0]
            y1 = qb[q, 0] * c1 + qb[q, 1] * poly[i, 1] + qb[q, 2] * poly[j, 1]
            # Ns, dNs and Nm, dNm are the quad4 Newton's work arrays (no allocation per point)
            if not (_inverse_map_into(S, ks, y0, y1, xi_s, Ns, dNs)
                    and _inverse_map_into(Pm, km, y0, y1, xi_m, Nm, dNm)):
                failed += 1
                continue
            _shape(ks, xi_s[0], xi_s[1], Ns, dNs)
            _shape(km, xi_m[0], xi_m[1], Nm, dNm)
            # slave area element over plane area element at ξ_s (1 for a planar slave facet)
            xa[:] = 0.0
            xb[:] = 0.0
            J00 = 0.0
            J01 = 0.0
            J10 = 0.0
            J11 = 0.0
            h_s = 0.0
            for a in range(ks):
                for c in range(3):
                    xa[c] += dNs[a, 0] * xs[a, c]
                    xb[c] += dNs[a, 1] * xs[a, c]
                J00 += dNs[a, 0] * S[a, 0]
                J01 += dNs[a, 1] * S[a, 0]
                J10 += dNs[a, 0] * S[a, 1]
                J11 += dNs[a, 1] * S[a, 1]
                h_s += Ns[a] * hs[a]
            _cross(xa, xb, cr)
            ratio = np.sqrt(_dot(cr, cr)) / _real_sign_abs(J00 * J11 - J01 * J10)
            h_m = 0.0
            for b in range(km):
                h_m += Nm[b] * hm[b]
            gap = h_m - h_s
            w = qw[q] * cell * ratio
            total += w
            for a in range(ks):
                phi[a] = 0.0
                for b in range(ks):
                    phi[a] += A[a, b] * Ns[b]
            for a in range(ks):
                for b in range(km):
                    M[a, b] += w * phi[a] * Nm[b]
                g[a] += w * phi[a] * gap
                cov[a] += w * Ns[a]
    return total.real, failed


@numba.njit(cache=True)
def _integrate_couples(ci, cj, xs, A, xm, qb, qw, relative_tolerance, min_cos):
    """:func:`_couple` for the couples (ci[c], cj[c]); one row of each output per couple."""
    nc = ci.shape[0]
    ks = xs.shape[1]
    km = xm.shape[1]
    M = np.zeros((nc, ks, km), xs.dtype)
    g = np.zeros((nc, ks), xs.dtype)
    cov = np.zeros((nc, ks), xs.dtype)
    area = np.zeros(nc)
    failed = np.zeros(nc, np.int64)
    for c in range(nc):
        area[c], failed[c] = _couple(xs[ci[c]], A[ci[c]], xm[cj[c]], qb, qw, relative_tolerance, min_cos,
                                     M[c], g[c], cov[c])
    return M, g, cov, area, failed


def couple_integrals(xs_cyclic: npt.ArrayLike, A: npt.ArrayLike, xm_cyclic: npt.ArrayLike,
                     relative_tolerance: float = RELATIVE_TOLERANCE,
                     min_facing_cosine: float = MIN_FACING_COSINE) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The mortar integrals of one (slave facet, master facet) couple.

    Parameters
    ----------
    xs_cyclic
        (ks, 3) slave facet vertices, cyclic and counter-clockwise about its outward normal.
    A
        (ks, ks) the slave facet's dual coefficients (:func:`dual_coefficients`).
    xm_cyclic
        (km, 3) master facet vertices, cyclic and counter-clockwise about ITS outward normal.
    relative_tolerance, min_facing_cosine
        As for :func:`mortar_integrals`.

    All real, or any of them complex (complex-step derivatives,
    :mod:`~dolfinx_nnqem.contact.couple_complex_step`): M, weighted_gap and covered are then complex.

    Returns
    -------
    M
        (ks, km) ∫_overlap Φ_j (N_k ∘ π) dA.
    weighted_gap
        (ks,) ∫_overlap Φ_j g0 dA.
    covered
        (ks,) ∫_overlap N_j dA.
    area
        The overlap's area on the slave facet (0: no overlap, or the master does not face the slave).
    """
    dtype = np.result_type(np.asarray(xs_cyclic).dtype, np.asarray(A).dtype, np.asarray(xm_cyclic).dtype, np.float64)
    xs = np.ascontiguousarray(xs_cyclic, dtype=dtype)
    xm = np.ascontiguousarray(xm_cyclic, dtype=dtype)
    qb, qw = triangle_rule()
    M, g, cov, area, _ = _integrate_couples(np.zeros(1, np.int64), np.zeros(1, np.int64), xs[None],
                                            np.ascontiguousarray(A, dtype=dtype)[None], xm[None], qb, qw,
                                            relative_tolerance, min_facing_cosine)
    return M[0], g[0], cov[0], float(area[0])


# --------------------------------------------------------------------------------------------
# The driver
# --------------------------------------------------------------------------------------------


@dataclass
class MortarIntegrals:
    """Assembled dual mortar data of one interface, one row per slave node.

    Attributes
    ----------
    slave_index
        (p,) the slave nodes' global indices (sorted).
    x
        (p, 3) their coordinates.
    normal
        (p, 3) averaged nodal normals: the area-weighted mean of the adjacent slave facets'
        outward unit normals (normalised sum of their outward area vectors), pointing from the
        slave body towards the master.
    D
        (p,) D_jj = ∫_Γs N_j dA (over the slave facets, covered or not).
    M
        (p, q) CSR matrix M_jk = ∫_Γs Φ_j (N_k ∘ π) dA; column c is master node ``master_index[c]``.
    master_index
        (q,) the master nodes' global indices (sorted; all master nodes, coupled or not).
    weighted_gap
        (p,) g̃_j = ∫_Γs Φ_j g0 dA (g0 > 0: open gap).
    coverage
        (p,) ∫_covered N_j dA / D_jj: 1 where master facets cover node j's support (Σ_k M_jk = D_jj
        there; both up to quadrature error on warped slave quads), < 1 on a partially covered
        node (at the boundary of the master), 0 for an uncovered one, > 1 where master facets
        overlap in projection (e.g. a folded master).
    num_couples
        Couples with a non-empty overlap.
    num_failed_points
        Gauss points skipped because an inverse map failed (0 for sane meshes).
    """

    slave_index: np.ndarray
    x: np.ndarray
    normal: np.ndarray
    D: np.ndarray
    M: scipy.sparse.csr_matrix
    master_index: np.ndarray
    weighted_gap: np.ndarray
    coverage: np.ndarray
    num_couples: int
    num_failed_points: int

    @property
    def g0(self) -> np.ndarray:
        """(p,) nodal initial gaps g̃_j / D_jj."""
        return self.weighted_gap / self.D

    def master_nodes_of(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """The master nodes' global indices k and M_jk of slave node row j."""
        row = slice(self.M.indptr[j], self.M.indptr[j + 1])
        return self.master_index[self.M.indices[row]], self.M.data[row]


def _radii(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertex means and largest centroid-to-vertex distances of facets (m, k, 3)."""
    centroid = x.mean(axis=1)
    return centroid, np.linalg.norm(x - centroid[:, None, :], axis=2).max(axis=1)


def candidate_couples(xs_cyclic: np.ndarray, xm_cyclic: np.ndarray, search_distance: float,
                      margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(slave, master) facet couples whose projections may overlap, sorted by slave then master.

    A KD-tree gives master facets whose centroid lies within r_s,max + r_m,max + search_distance
    of the slave centroid (r: largest centroid-to-vertex distance, plus ``margin`` / 2: curved
    quadratic facets reach beyond their vertices); kept are those whose centroid is within
    r_s + r_m of the slave centroid in the slave's plane and within search_distance + r_s + r_m
    along its normal.
    """
    cs, rs = _radii(xs_cyclic)
    cm, rm = _radii(xm_cyclic)
    rs, rm = rs + 0.5 * margin, rm + 0.5 * margin
    reach = float(rs.max() + rm.max() + search_distance)
    found = cKDTree(cs).sparse_distance_matrix(cKDTree(cm), reach, output_type="ndarray")
    ci, cj = found["i"].astype(np.int64), found["j"].astype(np.int64)
    normal = newell_area_vectors(xs_cyclic)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    d = cm[cj] - cs[ci]
    dn = np.einsum("cj,cj->c", d, normal[ci])
    dt = np.linalg.norm(d - dn[:, None] * normal[ci], axis=1)
    r = (rs[ci] + rm[cj]) * (1.0 + 1e-9)
    keep = (dt <= r) & (np.abs(dn) <= search_distance + r)
    ci, cj = ci[keep], cj[keep]
    order = np.lexsort((cj, ci))
    return ci[order], cj[order]


def mortar_integrals(slave_nodes: npt.ArrayLike, slave_x: npt.ArrayLike, slave_area: npt.ArrayLike,
                     master_nodes: npt.ArrayLike, master_x: npt.ArrayLike, master_area: npt.ArrayLike,
                     search_distance: float | None = None, relative_tolerance: float = RELATIVE_TOLERANCE,
                     min_facing_cosine: float = MIN_FACING_COSINE) -> MortarIntegrals:
    """Dual mortar integrals D, M, g̃ of a slave surface against a master surface.

    Parameters
    ----------
    slave_nodes, master_nodes
        (m, k) global node indices of each facet's vertices (k = 3 or 4; the sides may differ).
    slave_x, master_x
        (m, k, 3) their coordinates, vertices in any order (``Facets.x``).
    slave_area, master_area
        (m, 3) outward area vectors (``Facets.area``).
    search_distance
        Largest normal distance between a slave facet and the master facets it is coupled with;
        default: the largest facet diameter of either surface.
    relative_tolerance
        Overlaps below this fraction of the slave facet's area are empty.
    min_facing_cosine
        See :data:`MIN_FACING_COSINE`.

    Returns
    -------
    MortarIntegrals
    """
    slave_nodes = np.asarray(slave_nodes, dtype=np.int64)
    master_nodes = np.asarray(master_nodes, dtype=np.int64)
    slave_x = np.asarray(slave_x, dtype=np.float64)
    master_x = np.asarray(master_x, dtype=np.float64)
    slave_area = np.asarray(slave_area, dtype=np.float64)
    master_area = np.asarray(master_area, dtype=np.float64)
    _check_facets(slave_x, slave_area, "slave facets")
    _check_facets(master_x, master_area, "master facets")
    if slave_nodes.shape != slave_x.shape[:2] or master_nodes.shape != master_x.shape[:2]:
        raise ValueError(f"node arrays {slave_nodes.shape}, {master_nodes.shape} do not match the "
                         f"coordinates {slave_x.shape}, {master_x.shape}")
    xs, perm_s = _cyclic(slave_x, slave_area)
    xm, perm_m = _cyclic(master_x, master_area)
    nodes_s = np.take_along_axis(slave_nodes, perm_s, axis=1)
    nodes_m = np.take_along_axis(master_nodes, perm_m, axis=1)
    A, De = dual_coefficients(xs)
    if search_distance is None:
        search_distance = 2.0 * max(_radii(xs)[1].max(), _radii(xm)[1].max())
    ci, cj = candidate_couples(xs, xm, float(search_distance))
    qb, qw = triangle_rule()
    Mc, gc, covc, area, failed = _integrate_couples(ci, cj, xs, A, xm, qb, qw, relative_tolerance,
                                                    min_facing_cosine)
    used = area > 0.0
    ci, cj, Mc, gc, covc = ci[used], cj[used], Mc[used], gc[used], covc[used]

    slave_index, first, s_pos = np.unique(nodes_s.ravel(), return_index=True, return_inverse=True)
    s_pos = s_pos.reshape(nodes_s.shape)
    master_index, m_pos = np.unique(nodes_m.ravel(), return_inverse=True)
    m_pos = m_pos.reshape(nodes_m.shape)
    p, q = len(slave_index), len(master_index)
    ks = xs.shape[1]
    D = np.bincount(s_pos.ravel(), De.ravel(), minlength=p)
    rows = np.broadcast_to(s_pos[ci][:, :, None], Mc.shape).ravel()
    cols = np.broadcast_to(m_pos[cj][:, None, :], Mc.shape).ravel()
    M = scipy.sparse.coo_matrix((Mc.ravel(), (rows, cols)), shape=(p, q)).tocsr()
    M.sum_duplicates()
    M.sort_indices()
    weighted_gap = np.bincount(s_pos[ci].ravel(), gc.ravel(), minlength=p)
    coverage = np.bincount(s_pos[ci].ravel(), covc.ravel(), minlength=p) / D
    normal = np.zeros((p, 3))
    np.add.at(normal, s_pos.ravel(), np.repeat(slave_area, ks, axis=0))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    x = xs.reshape(-1, 3)[first]
    return MortarIntegrals(slave_index, x, normal, D, M, master_index, weighted_gap, coverage,
                           int(used.sum()), int(failed.sum()))
