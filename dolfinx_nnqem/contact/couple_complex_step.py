r"""Exact derivatives of the dual mortar couple integrals by the complex step (issue 41).

The consistent linearisation of current-geometry dual mortar pairs
(:mod:`~dolfinx_nnqem.contact.mortar_linearisation`) needs, for every couple c (slave facet e,
master facet f), the derivatives of its local integrals

    M_c = ∫ Φ_j (N_k ∘ π) dA,   g̃_c = ∫ Φ_j g0 dA,   Φ_j = Σ_l (A_e)_jl N_l,   A_e = D_e M_e⁻¹,

with respect to the P = 3 (k_e + k_f) coordinates of the two facets' vertices: through the
auxiliary plane and its normal, the clip polygon's vertices (edge intersections and contained
vertices), the Gauss points' inverse maps ξ_s, ξ_m, the area-element ratio and the dual
coefficients A_e (Popp, Gee and Wall 2009 differentiate each of these by hand).

Here they are the complex-step derivatives (Squire and Trapp 1998; Martins, Sturdza and Alonso
2003) of the same kernels that integrate a couple (:mod:`~dolfinx_nnqem.contact.mortar_geometry`:
``_couple``, ``_clip``, ``_integrate_overlap``, the inverse maps; :func:`dual_coefficients`): with
the coordinate x_p moved to x_p + i h,

    ∂F/∂x_p = Im F(x + i h e_p) / h + O(h²),

with no subtraction, so that h = :data:`COMPLEX_STEP` × the facet size makes the O(h²) term vanish
below round-off: the derivative is exact to round-off, one (complex) evaluation per coordinate.
It needs the kernels to be complex-analytic on the branch taken, which they are by construction:
every decision (which side of a clip line a point is on, whether a facet faces the other, whether
a sub-triangle or overlap counts, the Newton inverse map's convergence, the clamp of a crossing
parameter to [0, 1]) is made on the real part, where the real evaluation makes it; the modulus is
never taken of a complex value (√(c · c) for |c|, the sign of the real part for |det|), and √ and
division are analytic. numba compiles each kernel once for real and once for complex arguments from
one source; the real evaluation is the arithmetic it was before.

At a branch point (a vertex exactly on the other facet's edge, an overlap appearing) the integrals
are not differentiable; the complex step gives the derivative of the branch the real evaluation
takes (a one-sided derivative), where central differences mix both sides.
"""

from __future__ import annotations

import numpy as np

from dolfinx_nnqem.contact.mortar_geometry import (MIN_FACING_COSINE, RELATIVE_TOLERANCE, _integrate_couples,
                                                   dual_coefficients, triangle_rule)

__all__ = ["COMPLEX_STEP", "couple_derivatives"]

COMPLEX_STEP = 1e-30
"""The imaginary step, relative to the slave surface's facet size: small enough that the O(h²) terms
(relative h² ≈ 1e-60) are far below round-off, large enough that nothing underflows."""


def _directions(x: np.ndarray, ks: int) -> np.ndarray:
    """(c, Q, ks + km, 3) the Q = 3 (ks + km) − 5 directions each couple's vertices x (c, ks + km, 3) are
    moved in: every coordinate of the slave vertices and of the master vertices but the last two (K, L),
    and K along the unit vector from L to K (:func:`_rigid_motion_completion` gives the rest)."""
    c, nv = x.shape[:2]
    Q = 3 * (nv - 2) + 1
    d = np.zeros((c, Q, nv, 3))
    d[:, :Q - 1, :nv - 2] = np.eye(3 * (nv - 2)).reshape(Q - 1, nv - 2, 3)
    e = x[:, nv - 2] - x[:, nv - 1]
    d[:, Q - 1, nv - 2] = e / np.linalg.norm(e, axis=1)[:, None]
    return d


def _rigid_motion_completion(x: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """(c, outputs, ks + km, 3) the derivatives of a couple's integrals with respect to all its vertex
    coordinates from the Q of :func:`_directions` (``columns`` (c, outputs, Q)).

    The integrals do not change when both facets move rigidly together (the auxiliary plane, its axes,
    the clip and the gap move with them), so that with d_a = ∂F/∂x_a Σ_a d_a = 0 (translation) and
    Σ_a (x_a − x_L) × d_a = 0 (rotation). With e = x_K − x_L and R = Σ_{a ≠ K, L} (x_a − x_L) × d_a, the
    rotation gives e × d_K = −R (R ⊥ e), so d_K = (−R) × e / |e|² + (d_K · ê) ê, and then
    d_L = −Σ_{a ≠ L} d_a."""
    c, outputs, Q = columns.shape
    nv = x.shape[1]
    d = np.empty((c, outputs, nv, 3))
    d[:, :, :nv - 2] = columns[:, :, :Q - 1].reshape(c, outputs, nv - 2, 3)
    arm = x[:, :nv - 2] - x[:, None, nv - 1]  # (c, nv − 2, 3): x_a − x_L
    R = np.cross(arm[:, None], d[:, :, :nv - 2]).sum(axis=2)  # (c, outputs, 3)
    e = x[:, nv - 2] - x[:, nv - 1]
    length = np.linalg.norm(e, axis=1)
    d[:, :, nv - 2] = (np.cross(-R, e[:, None]) / (length ** 2)[:, None, None]
                       + columns[:, :, Q - 1, None] * (e / length[:, None])[:, None])
    d[:, :, nv - 1] = -d[:, :, :nv - 1].sum(axis=2)
    return d


def _moved_dual_coefficients(xs: np.ndarray, step: float) -> np.ndarray:
    """(m, 3 ks, ks, ks) the complex dual coefficients A_e of the slave facets xs (m, ks, 3) with each of their
    3 ks coordinates moved by i ``step`` in turn (the first 3 ks of :func:`_directions`)."""
    m, ks = xs.shape[:2]
    moved = xs.reshape(m, 1, 3 * ks) + (1j * step) * np.eye(3 * ks)[None]
    return dual_coefficients(moved.reshape(-1, ks, 3))[0].reshape(m, 3 * ks, ks, ks)


def _complex_step_columns(xs: np.ndarray, A: np.ndarray, at: np.ndarray, xm: np.ndarray, step: float,
                          relative_tolerance: float, min_facing_cosine: float) -> tuple[np.ndarray, np.ndarray]:
    """(x (c, ks + km, 3), columns (c, ks·km + ks, Q)): the couples (slave facet xs[at[c]], master facet xm[c]),
    A (ms, ks, ks) the slave facets' dual coefficients, and the derivatives of their (M, g̃) along the
    :func:`_directions`."""
    c, ks, km = len(at), xs.shape[1], xm.shape[1]
    x = np.concatenate([xs[at], xm], axis=1)
    directions = _directions(x, ks)
    Q = directions.shape[1]
    moved = (x[:, None] + (1j * step) * directions).reshape(-1, ks + km, 3)
    slave = 3 * ks  # the directions that move a slave vertex (the first 3 ks) move its dual coefficients
    A_p = np.empty((c, Q, ks, ks), dtype=np.complex128)
    A_p[:, slave:] = A[at][:, None]
    A_p[:, :slave] = _moved_dual_coefficients(xs, step)[at]
    every = np.arange(len(moved), dtype=np.int64)
    qb, qw = triangle_rule()
    M, g, _, _, _ = _integrate_couples(every, every, np.ascontiguousarray(moved[:, :ks]),
                                       np.ascontiguousarray(A_p.reshape(-1, ks, ks)),
                                       np.ascontiguousarray(moved[:, ks:]), qb, qw, relative_tolerance,
                                       min_facing_cosine)
    columns = np.concatenate([M.imag.reshape(c, Q, ks * km), g.imag.reshape(c, Q, ks)], axis=2) / step
    return x, columns.transpose(0, 2, 1)


def couple_derivatives(xs: np.ndarray, xm: np.ndarray, ci: np.ndarray, cj: np.ndarray, step: float,
                       relative_tolerance: float = RELATIVE_TOLERANCE,
                       min_facing_cosine: float = MIN_FACING_COSINE) -> tuple[np.ndarray, np.ndarray]:
    """Complex-step derivatives of the integrals of couples (slave facet ``ci``, master facet ``cj``).

    Parameters
    ----------
    xs, xm
        (ms, ks, 3) and (mm, km, 3): the slave and master facets' vertices, cyclic
        (:func:`~dolfinx_nnqem.contact.mortar_geometry.couple_integrals`).
    ci, cj
        (c,) the couples.
    step
        The imaginary step h (a length: :data:`COMPLEX_STEP` × the facet size).
    relative_tolerance, min_facing_cosine
        As for :func:`~dolfinx_nnqem.contact.mortar_geometry.mortar_integrals`.

    Returns
    -------
    (dM (c, ks, km, P), dg (c, ks, P)): ∂M_c and ∂g̃_c with respect to the P = 3 (ks + km) vertex
    coordinates (the slave facet's vertices, then the master's, each x, y, z). P − 5 complex
    evaluations per couple (:func:`_directions`; the dual coefficients move with the slave facet's
    coordinates), the other 5 derivatives from the integrals' invariance under rigid motions
    (:func:`_rigid_motion_completion`). A couple that does not count at x (no overlap, or facets that
    do not face each other) has zero derivatives: the complex step would take its branch too, so it is
    not evaluated.
    """
    ks, km = xs.shape[1], xm.shape[1]
    P = 3 * (ks + km)
    ci, cj = np.asarray(ci, dtype=np.int64), np.asarray(cj, dtype=np.int64)
    dM, dg = np.zeros((len(ci), ks, km, P)), np.zeros((len(ci), ks, P))
    facets, at = np.unique(ci, return_inverse=True)
    A = dual_coefficients(xs[facets])[0]
    qb, qw = triangle_rule()
    # a couple whose real evaluation does not count takes the same branch at x + i h e_p: zero derivatives
    area = _integrate_couples(at, cj, xs[facets], A, xm, qb, qw, relative_tolerance, min_facing_cosine)[3]
    counted = np.flatnonzero(area > 0.0)
    if len(counted) == 0:
        return dM, dg
    used, at = np.unique(at[counted], return_inverse=True)  # the counted couples' slave facets
    x, columns = _complex_step_columns(xs[facets[used]], A[used], at, xm[cj[counted]], step, relative_tolerance,
                                       min_facing_cosine)
    d = _rigid_motion_completion(x, columns).reshape(len(counted), ks * km + ks, P)
    dM[counted] = d[:, :ks * km].reshape(-1, ks, km, P)
    dg[counted] = d[:, ks * km:]
    return dM, dg
