r"""The derivatives of the integrals of a couple of quadratic facets (issue 43, "Speed, second round").

The couple integrals of :mod:`~dolfinx_nnqem.contact.dual_quadratic` (slave facet e, master facet f,
each split into four linear sub-facets) are M = A_e K and g̃ = A_e G, with the dual coefficients A_e
of the slave facet and the integrals over the overlaps of the sub-facets

    K_ik = ∫ N̂_i (N_k ∘ π) dA,   G_i = ∫ N̂_i g0 dA,   g0 = n_0 · (x_m(ξ_m) − x_s(ξ_s)),

so that ∂M = ∂A_e K + A_e ∂K, with A_e = D_e M_e⁻¹ of
:func:`~dolfinx_nnqem.contact.dual_quadratic.quadratic_dual_coefficients` and
∂A_e = ∂D_e M_e⁻¹ − A_e ∂M_e M_e⁻¹, ∂M_e the quadrature of N̂ N̂ᵀ ∂|x_ξ × x_η|
(:func:`dual_coefficient_derivatives`).

K and G are sums over Gauss points whose places (the clip of two projected sub-facets, the
local coordinates ζ → ξ_s, ξ_m, the ratio of the area elements) depend on the nodes' in-plane
coordinates S_a, P_b in the auxiliary plane only, and whose integrands are explicit in the nodes x
and the plane's normal n_0. With a node coordinate x_p the chain rule is

    dK/dx_p = Σ_a ∂K/∂S_a · dS_a/dx_p + ∂K/∂x_p |fixed points,
    dG/dx_p = Σ_a ∂G/∂S_a · dS_a/dx_p + ∂G/∂x_p |fixed points + ∂G/∂n_0 · dn_0/dx_p,

over the nodes a of both facets:

* ∂K/∂S_a, ∂G/∂S_a: the complex step of the in-plane point S_a (2 directions: S_a + i h e_d, the
  derivative Im K / h, exact to round-off; :mod:`~dolfinx_nnqem.contact.couple_complex_step` says why
  and what the kernels need), where only the pairs of sub-facets that hold node a are integrated
  again, in complex arithmetic (:func:`_in_plane_derivatives`);
* dS_a/dx_p = (t_1, t_2) · (δ_ap e_p − h_a dn_0/dx_p), h_a the height of node a above the plane:
  moving node a, and turning the plane's normal (its axes by the least rotation; the plane's centre
  and the axes' turn within the plane move every projected point rigidly, which changes no
  integral);
* dn_0/dx_p = (I − n_0 n_0ᵀ) ∂(x_ξ × x_η)/∂x_p / |x_ξ × x_η| at the slave facet's centre (zero for a
  master node);
* at fixed points, with c = x_ξ × x_η at the point (:func:`_fixed_point_derivatives`)
  ∂|c|/∂x_bc = (∂_ξN_b (x_η × c)_c + ∂_ηN_b (c × x_ξ)_c) / |c| (slave node b),
  ∂g0/∂x_bc = −N_b(ξ_s) n_0c (slave node b) or N_b(ξ_m) n_0c (master node b), ∂g0/∂n_0 = x_m − x_s.

Against central differences of the whole couple (every node coordinate moved, every pair of
sub-facets integrated again: what ``quadratic_mortar_linearisation`` did before) the result differs
by the differences' round-off, at a fraction of the integrations; against sixth-order differences by
their own error (``tests/unit/test_quadratic_couple_differences.py``).
A couple whose facets do not face each other (or a degenerate facet) has zero derivatives.
"""

from __future__ import annotations

import numba
import numpy as np

from dolfinx_nnqem.contact.dual_quadratic import (SUB_FACETS, _couple_plane, _sub_polygon, _to_parent,
                                                  quadratic_dual_coefficients, segment_rule)
from dolfinx_nnqem.contact.mortar_geometry import (MIN_FACING_COSINE, RELATIVE_TOLERANCE, _clip, _cross, _dot,
                                                   _polygon_area)
from dolfinx_nnqem.contact.quadratic_facets import (reference_nodes, reference_rule, shape_at, shape_derivatives,
                                                    transformation, transformed_shape_functions)

__all__ = ["dual_coefficient_derivatives", "quadratic_couple_derivatives"]

# numba's on-disk cache invalidates a kernel when ITS file changes, not a callee's: after editing a
# kernel of dual_quadratic, mortar_geometry or quadratic_facets that these call, clear
# __pycache__/quadratic_couple_differences*.nbi / *.nbc.


@numba.njit(cache=True)
def _normal_derivative(xs, sign_s, n0, dn):
    """Fill dn (3, 3ks) with dn_0/dx of the slave facet's normal at its centre (module docstring)."""
    ks = xs.shape[0]
    N, dN, d2N = np.empty(ks), np.empty((ks, 2)), np.empty((ks, 3))
    c = 1.0 / 3.0 if ks == 6 else 0.5
    shape_at(ks, c, c, N, dN, d2N)
    xa, xb, cr = np.zeros(3), np.zeros(3), np.empty(3)
    for a in range(ks):
        for j in range(3):
            xa[j] += dN[a, 0] * xs[a, j]
            xb[j] += dN[a, 1] * xs[a, j]
    _cross(xa, xb, cr)
    length = np.sqrt(_dot(cr, cr))
    e, u, v = np.zeros(3), np.empty(3), np.empty(3)
    for b in range(ks):
        for j in range(3):
            e[:] = 0.0
            e[j] = 1.0
            _cross(e, xb, u)
            _cross(xa, e, v)
            for i in range(3):
                u[i] = dN[b, 0] * u[i] + dN[b, 1] * v[i]
            un = _dot(u, n0)
            for i in range(3):
                dn[i, 3 * b + j] = sign_s * (u[i] - un * n0[i]) / length


@numba.njit(cache=True)
def _fixed_point_derivatives(base, W, gap, length, xa, xb, cr, x_gap, Ns, dNs, Nm, Nhat, n0, fixed):
    """Add one Gauss point's integrand derivatives at fixed points (module docstring) to ``fixed``:
    (dK (3ks, ks, km) and dG (3ks, ks) along the slave coordinates, dG (3km, ks) along the master's, dG
    (3, ks) along n_0); ``base`` the point's weight without the area element |x_ξ × x_η| = ``length``,
    W = base · length, ``x_gap`` = x_m − x_s."""
    dKs, dGs, dGm, dGn = fixed
    ks = Ns.shape[0]
    km = Nm.shape[0]
    u = np.empty(3, xa.dtype)
    v = np.empty(3, xa.dtype)
    _cross(xb, cr, u)
    _cross(cr, xa, v)
    for b in range(ks):
        for c in range(3):
            p = 3 * b + c
            dW = base * (dNs[b, 0] * u[c] + dNs[b, 1] * v[c]) / length
            dgap = -Ns[b] * n0[c]
            for i in range(ks):
                t = Nhat[i] * dW
                for k in range(km):
                    dKs[p, i, k] += t * Nm[k]
                dGs[p, i] += t * gap + W * Nhat[i] * dgap
    for b in range(km):
        for c in range(3):
            f = W * Nm[b] * n0[c]
            for i in range(ks):
                dGm[3 * b + c, i] += f * Nhat[i]
    for c in range(3):
        for i in range(ks):
            dGn[c, i] += W * Nhat[i] * x_gap[c]


@numba.njit(cache=True)
def _segment(poly, n, Ss, rs, Pm, rm, xs, xm, T, n0, qb, qw, K, G, fixed):
    """Add ∫ N̂ ⊗ N_m and ∫ N̂ g0 over the overlap polygon poly[:n] of a slave sub-facet (Ss, rs) and a
    master sub-facet (Pm, rm) to K and G (the Gauss points of
    :func:`~dolfinx_nnqem.contact.dual_quadratic._integrate_segment`); and their derivatives at fixed points
    to ``fixed`` (:func:`_fixed_point_derivatives`), unless it is empty."""
    ks = xs.shape[0]
    km = xm.shape[0]
    c0 = 0.0
    c1 = 0.0
    for i in range(n):
        c0 += poly[i, 0] / n
        c1 += poly[i, 1] / n
    dtype = poly.dtype  # complex in the complex step of the in-plane points
    Ns, dNs, d2Ns = np.empty(ks, dtype), np.empty((ks, 2), dtype), np.empty((ks, 3), dtype)
    Nm, dNm, d2Nm = np.empty(km, dtype), np.empty((km, 2), dtype), np.empty((km, 3), dtype)
    Nhat = np.empty(ks, dtype)
    zeta, xi_s, xi_m = np.empty(2, dtype), np.empty(2, dtype), np.empty(2, dtype)
    xa, xb, cr, x_gap = np.empty(3, dtype), np.empty(3, dtype), np.empty(3, dtype), np.empty(3, dtype)
    N4, dN4 = np.empty(4, dtype), np.empty((4, 2), dtype)
    for i in range(n):
        j = (i + 1) % n
        cell = 0.5 * ((poly[i, 0] - c0) * (poly[j, 1] - c1) - (poly[j, 0] - c0) * (poly[i, 1] - c1))
        if cell.real <= 0.0:
            continue
        for q in range(qw.shape[0]):
            y0 = qb[q, 0] * c0 + qb[q, 1] * poly[i, 0] + qb[q, 2] * poly[j, 0]
            y1 = qb[q, 0] * c1 + qb[q, 1] * poly[i, 1] + qb[q, 2] * poly[j, 1]
            ratio = _to_parent(Ss, rs, y0, y1, zeta, xi_s, N4, dN4)
            if ratio.real == 0.0 or _to_parent(Pm, rm, y0, y1, zeta, xi_m, N4, dN4).real == 0.0:
                continue
            shape_at(ks, xi_s[0], xi_s[1], Ns, dNs, d2Ns)
            shape_at(km, xi_m[0], xi_m[1], Nm, dNm, d2Nm)
            xa[:] = 0.0
            xb[:] = 0.0
            x_gap[:] = 0.0
            for a in range(ks):
                for c in range(3):
                    xa[c] += dNs[a, 0] * xs[a, c]
                    xb[c] += dNs[a, 1] * xs[a, c]
                    x_gap[c] -= Ns[a] * xs[a, c]
            for b in range(km):
                for c in range(3):
                    x_gap[c] += Nm[b] * xm[b, c]
            gap = _dot(x_gap, n0)
            _cross(xa, xb, cr)
            length = np.sqrt(_dot(cr, cr))
            base = qw[q] * cell * ratio
            W = base * length
            for a in range(ks):
                Nhat[a] = 0.0
                for b in range(ks):
                    Nhat[a] += T[a, b] * Ns[b]
            for a in range(ks):
                for b in range(km):
                    K[a, b] += W * Nhat[a] * Nm[b]
                G[a] += W * Nhat[a] * gap
            if fixed[0].size and length.real > 0.0:
                _fixed_point_derivatives(base, W, gap, length, xa, xb, cr, x_gap, Ns, dNs, Nm, Nhat, n0, fixed)


@numba.njit(cache=True)
def _sub_pair(S, P, sub_s, sub_m, ref_s, ref_m, xs, xm, T, n0, tol, relative_tolerance, qb, qw, K, G, fixed):
    """:func:`_segment` over the overlap of the slave sub-facet ``sub_s`` and the master sub-facet ``sub_m``
    (their node positions), clipped as :func:`~dolfinx_nnqem.contact.dual_quadratic._quadratic_couple` does."""
    Ss, rs = _sub_polygon(S, ref_s, sub_s)
    sub_area = _polygon_area(Ss, Ss.shape[0]).real
    if sub_area <= 0.0:
        return
    Pm, rm = _sub_polygon(P, ref_m, sub_m)
    subject = np.empty((16, 2), S.dtype)
    poly = np.empty((16, 2), S.dtype)
    subject[:Pm.shape[0]] = Pm
    n = _clip(subject, Pm.shape[0], Ss, Ss.shape[0], tol, poly)
    if n < 3 or _polygon_area(poly, n).real <= relative_tolerance * sub_area:
        return
    _segment(poly, n, Ss, rs, Pm, rm, xs, xm, T, n0, qb, qw, K, G, fixed)


@numba.njit(cache=True)
def _holds(nodes, node):
    """True if the sub-facet ``nodes`` holds node ``node``."""
    for a in range(nodes.shape[0]):
        if nodes[a] == node:
            return True
    return False


@numba.njit(cache=True)
def _eliminated_nodes(sub_m, ks, km):
    """The two master nodes (K, L, as indices a of both facets' nodes) whose in-plane derivatives
    :func:`_rigid_motion_completion` gives: those in most master sub-facets (the dearest to integrate again)."""
    count = np.zeros(km, np.int64)
    for i in range(sub_m.shape[0]):
        for j in range(sub_m.shape[1]):
            count[sub_m[i, j]] += 1
    L = int(np.argmax(count))
    count[L] = -1
    return ks + int(np.argmax(count)), ks + L


@numba.njit(cache=True)
def _moved_integrals(Sc, Pc, a, direction, sub_s, sub_m, ref_s, ref_m, xs, xm, T, n0, tol, relative_tolerance, qb,
                     qw, step, K, G, none):
    """K, G (complex) with node a's in-plane point moved by i ``step`` ``direction``: the pairs of sub-facets
    holding the node integrated again."""
    ks = Sc.shape[0]
    slave = a < ks
    points = Sc if slave else Pc
    node = a if slave else a - ks
    at0, at1 = points[node, 0], points[node, 1]
    K[:] = 0.0
    G[:] = 0.0
    points[node, 0] = at0 + 1j * step * direction[0]
    points[node, 1] = at1 + 1j * step * direction[1]
    for i in range(sub_s.shape[0]):
        if slave and not _holds(sub_s[i], node):
            continue
        for j in range(sub_m.shape[0]):
            if not slave and not _holds(sub_m[j], node):
                continue
            _sub_pair(Sc, Pc, sub_s[i], sub_m[j], ref_s, ref_m, xs, xm, T, n0, tol, relative_tolerance, qb, qw, K, G,
                      none)
    points[node, 0] = at0
    points[node, 1] = at1


@numba.njit(cache=True)
def _rigid_motion_completion(points, Kn, Ln, along, dK, dG):
    """Fill the in-plane derivatives of nodes Kn and Ln (dK (ks + km, 2, ks, km), dG (ks + km, 2, ks)) from
    the others' and Kn's along ê = (p_K − p_L)/|p_K − p_L| (``along``: (ks, km) of K, then (ks,) of G). K and
    G do not change when every in-plane point moves rigidly (translation: Σ_a d_a = 0; rotation:
    Σ_a (p_a − p_L) × d_a = 0, × the 2D cross product), so with e = p_K − p_L and
    R = Σ_{a ≠ K, L} (p_a − p_L) × d_a, d_K = (d_K · ê) ê − R / |e| ê⊥ (ê⊥ = ê turned by +90°), and
    d_L = −Σ_{a ≠ L} d_a. ``points`` (ks + km, 2): every node's in-plane point."""
    n, _, ks, km = dK.shape
    e0 = points[Kn, 0] - points[Ln, 0]
    e1 = points[Kn, 1] - points[Ln, 1]
    length = np.sqrt(e0 * e0 + e1 * e1)
    u0, u1 = e0 / length, e1 / length
    for i in range(ks):
        for k in range(km + 1):  # the column km: G
            R = 0.0
            total0 = 0.0
            total1 = 0.0
            for a in range(n):
                if a == Kn or a == Ln:
                    continue
                d0, d1 = (dK[a, 0, i, k], dK[a, 1, i, k]) if k < km else (dG[a, 0, i], dG[a, 1, i])
                R += (points[a, 0] - points[Ln, 0]) * d1 - (points[a, 1] - points[Ln, 1]) * d0
                total0 += d0
                total1 += d1
            alpha = along[i, k]
            beta = -R / length
            k0 = alpha * u0 - beta * u1
            k1 = alpha * u1 + beta * u0
            if k < km:
                dK[Kn, 0, i, k], dK[Kn, 1, i, k] = k0, k1
                dK[Ln, 0, i, k], dK[Ln, 1, i, k] = -(total0 + k0), -(total1 + k1)
            else:
                dG[Kn, 0, i], dG[Kn, 1, i] = k0, k1
                dG[Ln, 0, i], dG[Ln, 1, i] = -(total0 + k0), -(total1 + k1)


@numba.njit(cache=True)
def _in_plane_derivatives(S, P, sub_s, sub_m, ref_s, ref_m, xs, xm, T, n0, tol, relative_tolerance, qb, qw, step,
                          dK, dG):
    """Fill dK (ks + km, 2, ks, km) and dG (ks + km, 2, ks) with ∂K/∂S_a, ∂G/∂S_a (slave nodes a, then the
    master's P_b): the complex step of the in-plane points (S_a + i ``step`` e_d; the pairs of sub-facets
    holding the node integrated again in complex arithmetic, Im / step), but for two master nodes, whose
    derivatives follow from the integrals' invariance under rigid motions in the plane
    (:func:`_rigid_motion_completion`)."""
    ks = S.shape[0]
    km = P.shape[0]
    Sc, Pc = S.astype(np.complex128), P.astype(np.complex128)
    K, G = np.empty((ks, km), np.complex128), np.empty(ks, np.complex128)
    none = (np.empty((0, 0, 0), np.complex128), np.empty((0, 0), np.complex128), np.empty((0, 0), np.complex128),
            np.empty((0, 0), np.complex128))
    Kn, Ln = _eliminated_nodes(sub_m, ks, km)
    points = np.empty((ks + km, 2))
    points[:ks] = S
    points[ks:] = P
    direction = np.empty(2)
    for a in range(ks + km):
        if a == Kn or a == Ln:
            continue
        for d in range(2):
            direction[0] = 1.0 if d == 0 else 0.0
            direction[1] = 1.0 - direction[0]
            _moved_integrals(Sc, Pc, a, direction, sub_s, sub_m, ref_s, ref_m, xs, xm, T, n0, tol, relative_tolerance,
                             qb, qw, step, K, G, none)
            for i in range(ks):
                for k in range(km):
                    dK[a, d, i, k] = K[i, k].imag / step
                dG[a, d, i] = G[i].imag / step
    length = np.sqrt((points[Kn, 0] - points[Ln, 0]) ** 2 + (points[Kn, 1] - points[Ln, 1]) ** 2)
    direction[0] = (points[Kn, 0] - points[Ln, 0]) / length
    direction[1] = (points[Kn, 1] - points[Ln, 1]) / length
    _moved_integrals(Sc, Pc, Kn, direction, sub_s, sub_m, ref_s, ref_m, xs, xm, T, n0, tol, relative_tolerance, qb,
                     qw, step, K, G, none)
    along = np.empty((ks, km + 1))
    for i in range(ks):
        for k in range(km):
            along[i, k] = K[i, k].imag / step
        along[i, km] = G[i].imag / step
    _rigid_motion_completion(points, Kn, Ln, along, dK, dG)


@numba.njit(cache=True)
def _chain_rule(S, P, xs, xm, frame, dn, dK_plane, dG_plane, fixed, dK, dG):
    """dK (P, ks, km), dG (P, ks) of the node coordinates from the in-plane derivatives, the normal's
    derivative ``dn`` and the derivatives at fixed points (module docstring)."""
    dKs, dGs, dGm, dGn = fixed
    ks = xs.shape[0]
    km = xm.shape[0]
    x0, n0, t1, t2 = frame[0], frame[1], frame[2], frame[3]
    height = np.empty(ks + km)
    for a in range(ks + km):
        x = xs[a] if a < ks else xm[a - ks]
        height[a] = (x[0] - x0[0]) * n0[0] + (x[1] - x0[1]) * n0[1] + (x[2] - x0[2]) * n0[2]
    for p in range(3 * (ks + km)):
        node, c = p // 3, p % 3
        if p < 3 * ks:  # a slave node: it moves, and the plane turns (every point away from it moves)
            dK[p] = dKs[p]
            dG[p] = dGs[p]
            turn1 = t1[0] * dn[0, p] + t1[1] * dn[1, p] + t1[2] * dn[2, p]
            turn2 = t2[0] * dn[0, p] + t2[1] * dn[1, p] + t2[2] * dn[2, p]
            for c2 in range(3):
                dG[p] += dn[c2, p] * dGn[c2]
            for a in range(ks + km):
                d1 = -height[a] * turn1 + (t1[c] if a == node else 0.0)
                d2 = -height[a] * turn2 + (t2[c] if a == node else 0.0)
                dK[p] += d1 * dK_plane[a, 0] + d2 * dK_plane[a, 1]
                dG[p] += d1 * dG_plane[a, 0] + d2 * dG_plane[a, 1]
        else:  # a master node: it moves alone
            dK[p] = t1[c] * dK_plane[node, 0] + t2[c] * dK_plane[node, 1]
            dG[p] = dGm[p - 3 * ks] + t1[c] * dG_plane[node, 0] + t2[c] * dG_plane[node, 1]


@numba.njit(cache=True)
def _couple_derivatives(xs, sign_s, xm, sign_m, T, sub_s, sub_m, ref_s, ref_m, qb, qw, relative_tolerance, min_cos,
                        step, K, G, dK, dG):
    """K (ks, km), G (ks) of one couple and their derivatives dK (P, ks, km), dG (P, ks) with respect to
    the P = 3 (ks + km) node coordinates (module docstring); zero if the couple does not count."""
    ks = xs.shape[0]
    km = xm.shape[0]
    S, P, frame = np.empty((ks, 2)), np.empty((km, 2)), np.empty((4, 3))
    tol = _couple_plane(xs, sign_s, xm, sign_m, min_cos, S, P, frame)
    if tol < 0.0:
        return
    n0 = frame[1].copy()
    fixed = (np.zeros((3 * ks, ks, km)), np.zeros((3 * ks, ks)), np.zeros((3 * km, ks)), np.zeros((3, ks)))
    for i in range(sub_s.shape[0]):
        for j in range(sub_m.shape[0]):
            _sub_pair(S, P, sub_s[i], sub_m[j], ref_s, ref_m, xs, xm, T, n0, tol, relative_tolerance, qb, qw, K, G,
                      fixed)
    dK_plane, dG_plane = np.empty((ks + km, 2, ks, km)), np.empty((ks + km, 2, ks))
    _in_plane_derivatives(S, P, sub_s, sub_m, ref_s, ref_m, xs, xm, T, n0, tol, relative_tolerance, qb, qw, step,
                          dK_plane, dG_plane)
    dn = np.empty((3, 3 * ks))
    _normal_derivative(xs, sign_s, n0, dn)
    _chain_rule(S, P, xs, xm, frame, dn, dK_plane, dG_plane, fixed, dK, dG)


@numba.njit(cache=True)
def _all_couple_derivatives(ci, cj, xs, sign_s, xm, sign_m, T, sub_s, sub_m, ref_s, ref_m, qb, qw,
                            relative_tolerance, min_cos, step):
    """:func:`_couple_derivatives` of the couples (ci[c], cj[c]): K (c, ks, km), G (c, ks), dK (c, P, ks, km),
    dG (c, P, ks)."""
    nc = ci.shape[0]
    ks = xs.shape[1]
    km = xm.shape[1]
    P = 3 * (ks + km)
    K = np.zeros((nc, ks, km))
    G = np.zeros((nc, ks))
    dK = np.zeros((nc, P, ks, km))
    dG = np.zeros((nc, P, ks))
    for c in range(nc):
        _couple_derivatives(xs[ci[c]], sign_s[ci[c]], xm[cj[c]], sign_m[cj[c]], T, sub_s, sub_m, ref_s, ref_m, qb,
                            qw, relative_tolerance, min_cos, step, K[c], G[c], dK[c], dG[c])
    return K, G, dK, dG


def dual_coefficient_derivatives(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The dual coefficients A_e (m, k, k) of quadratic slave facets
    (:func:`~dolfinx_nnqem.contact.dual_quadratic.quadratic_dual_coefficients`) and their derivatives
    (m, 3k, k, k) with respect to the facets' node coordinates: ∂A_e = ∂D_e M_e⁻¹ − A_e ∂M_e M_e⁻¹,
    ∂M_e = Σ_q w_q N̂(ξ_q) N̂(ξ_q)ᵀ ∂|x_ξ × x_η|(ξ_q) and ∂D_e its row sums (module docstring)."""
    x = np.asarray(x, dtype=np.float64)
    m, k = x.shape[:2]
    A, _ = quadratic_dual_coefficients(x)
    xi, w = reference_rule(k)
    dN = shape_derivatives(k, xi)  # (q, k, 2)
    Nhat = transformed_shape_functions(k, xi)  # (q, k)
    J = np.einsum("qab,maj->mqbj", dN, x)  # rows x_ξ, x_η
    c = np.cross(J[:, :, 0], J[:, :, 1])
    length = np.linalg.norm(c, axis=2)
    u, v = np.cross(J[:, :, 1], c), np.cross(c, J[:, :, 0])  # ∂|c|/∂x_b = (∂_ξN_b u + ∂_ηN_b v) / |c|
    d_length = ((dN[None, :, :, 0, None] * u[:, :, None] + dN[None, :, :, 1, None] * v[:, :, None])
                / length[:, :, None, None]).reshape(m, len(w), 3 * k)
    NN = (Nhat[:, :, None] * Nhat[:, None, :]).reshape(len(w), k * k)
    Me = ((w * length) @ NN).reshape(m, k, k)
    dMe = (np.swapaxes(d_length * w[None, :, None], 1, 2) @ NN).reshape(m, 3 * k, k, k)
    inverse = np.linalg.inv(Me)[:, None]
    dA = dMe.sum(axis=3)[..., None] * inverse - A[:, None] @ dMe @ inverse
    return A, dA


def quadratic_couple_derivatives(xs: np.ndarray, sign_s: np.ndarray, xm: np.ndarray, sign_m: np.ndarray,
                                 ci: np.ndarray, cj: np.ndarray, step: float,
                                 relative_tolerance: float = RELATIVE_TOLERANCE,
                                 min_facing_cosine: float = MIN_FACING_COSINE) -> tuple[np.ndarray, np.ndarray]:
    """The derivatives of the integrals of couples (slave facet ``ci``, master facet ``cj``) of quadratic
    facets (module docstring).

    Parameters
    ----------
    xs, xm
        (ms, ks, 3), (mm, km, 3) the facets' nodes (:mod:`~dolfinx_nnqem.contact.quadratic_facets`' order).
    sign_s, sign_m
        (ms,), (mm,) their :func:`~dolfinx_nnqem.contact.quadratic_facets.outward_signs`.
    ci, cj
        (c,) the couples.
    step
        The imaginary step of the in-plane points (a length: ``mortar_linearisation.STEP`` × the facet
        size).
    relative_tolerance, min_facing_cosine
        As for :func:`~dolfinx_nnqem.contact.dual_quadratic.integrate_quadratic_couples`.

    Returns
    -------
    (dM (c, ks, km, P), dg (c, ks, P)): ∂M_c and ∂g̃_c with respect to the P = 3 (ks + km) node
    coordinates (the slave facet's nodes, then the master's, each x, y, z).
    """
    ks, km = xs.shape[1], xm.shape[1]
    S = 3 * ks
    xs = np.ascontiguousarray(xs, dtype=np.float64)
    xm = np.ascontiguousarray(xm, dtype=np.float64)
    facets, at = np.unique(ci, return_inverse=True)  # the slave facets of the couples
    A, dA = dual_coefficient_derivatives(xs[facets])
    A, dA = A[at], dA[at]  # (c, ks, ks), (c, S, ks, ks)
    qb, qw = segment_rule()
    K, G, dK, dG = _all_couple_derivatives(np.asarray(ci, dtype=np.int64), np.asarray(cj, dtype=np.int64), xs,
                                           np.asarray(sign_s, dtype=np.float64), xm,
                                           np.asarray(sign_m, dtype=np.float64), transformation(ks), SUB_FACETS[ks],
                                           SUB_FACETS[km], reference_nodes(ks), reference_nodes(km), qb, qw,
                                           relative_tolerance, min_facing_cosine, float(step))
    dM = np.einsum("cji,cpik->cjkp", A, dK)  # ∂M = A ∂K + ∂A K
    dM[..., :S] += np.einsum("cpji,cik->cjkp", dA, K)
    dg = np.einsum("cji,cpi->cjp", A, dG)
    dg[..., :S] += np.einsum("cpji,ci->cjp", dA, G)
    return dM, dg
