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


def _moved_dual_coefficients(xs: np.ndarray, facets: np.ndarray, step: float) -> np.ndarray:
    """(len(facets), 3 ks, ks, ks) the complex dual coefficients A_e of the slave facets ``facets`` with
    each of their 3 ks coordinates moved by i ``step`` in turn."""
    ks = xs.shape[1]
    S = 3 * ks
    moved = xs[facets].reshape(-1, 1, S) + (1j * step) * np.eye(S)[None]
    return dual_coefficients(moved.reshape(-1, ks, 3))[0].reshape(len(facets), S, ks, ks)


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
    coordinates (the slave facet's vertices, then the master's, each x, y, z); the dual coefficients
    move with the slave facet's coordinates (once per slave facet and coordinate). A couple that does
    not count at x (no overlap, or facets that do not face each other) has zero derivatives: the
    complex step would take its branch too, so it is not evaluated.
    """
    ks, km = xs.shape[1], xm.shape[1]
    P, S = 3 * (ks + km), 3 * ks
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
    c, at, cj = len(counted), at[counted], cj[counted]
    x = np.concatenate([xs[facets][at], xm[cj]], axis=1).reshape(c, 1, P)
    moved = (x + (1j * step) * np.eye(P)[None]).reshape(-1, ks + km, 3)  # (c·P): coordinate p moved by i h
    xs_p, xm_p = np.ascontiguousarray(moved[:, :ks]), np.ascontiguousarray(moved[:, ks:])
    A_p = np.empty((c, P, ks, ks), dtype=np.complex128)
    A_p[:, S:] = A[at][:, None]  # a master coordinate leaves A_e alone
    used = np.unique(at)
    A_moved = np.empty((len(facets), S, ks, ks), dtype=np.complex128)
    A_moved[used] = _moved_dual_coefficients(xs[facets], used, step)
    A_p[:, :S] = A_moved[at]
    every = np.arange(len(moved), dtype=np.int64)
    M, g, _, _, _ = _integrate_couples(every, every, xs_p, np.ascontiguousarray(A_p.reshape(-1, ks, ks)), xm_p, qb,
                                       qw, relative_tolerance, min_facing_cosine)
    dM[counted] = M.imag.reshape(c, P, ks, km).transpose(0, 2, 3, 1) / step
    dg[counted] = g.imag.reshape(c, P, ks).transpose(0, 2, 1) / step
    return dM, dg
