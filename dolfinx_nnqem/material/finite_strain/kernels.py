"""The consistent tangent ∂P/∂F of the logarithmic-strain route (:mod:`.hencky`), compiled: one
loop over the Gauss points, the nine directions δF = e_k ⊗ e_l of each written out on 3 × 3
arrays (numba, ``cache=True``: its disk cache next to this file).

The mathematics is :mod:`.hencky`'s (its module docstring, "Consistent tangent") with
:mod:`.spectral`'s derivatives, per direction δF = e_k ⊗ e_l:

* δf = δF F_n⁻¹ has the one row k, the row l of F_n⁻¹; so δb = δf b_e,n fᵀ + f b_e,n δfᵀ
  = e_k ⊗ h + h ⊗ e_k with h = (f b_e,n) F_n⁻ᵀ e_l;
* Daleckii–Krein (:func:`.spectral.log_derivative`): Ĥ = Qᵀ δb Q = q_k ⊗ ĥ + ĥ ⊗ q_k (q_k the row
  k of Q, ĥ = Qᵀ h), and rᵀ δε^tr r = ½ (rᵀQ) (L ∘ Ĥ) (rᵀQ)ᵀ, L the divided differences of ln
  (:func:`.spectral.log_divided_differences`, the same formula);
* Ω = W(ω), ω = (tr u I − u)⁻¹ axial(rᵀδf − δfᵀr) (:func:`.spectral.rotation_derivative`), with
  (rᵀδf)_ij = r_ki (F_n⁻¹)_lj;
* δε̄ = rᵀ δε^tr r − Ω ε̄ + ε̄ Ω, δτ̄ = D : δε̄, δτ = r (Ω τ̄ − τ̄ Ω + δτ̄) rᵀ,
  δP = δτ F⁻ᵀ − τ F⁻ᵀ δFᵀ F⁻ᵀ = δτ F⁻ᵀ − P e_l ⊗ F⁻¹ e_k.

D is given in the coordinates of the basis B (6, 9) of
:func:`~dolfinx_nnqem.material.kinematics.symmetric_coordinates`: δτ̄ = Bᵀ (D (B δε̄)), δε̄'s
symmetric part taken by B as there. The arrays stay per point (3 × 3, and work arrays allocated
once): no (n, 9, 3, 3) temporaries.

**Where r = I** (an isotropic law, :mod:`.hencky`: Ω's terms cancel, δτ = D : δε^tr) the nine
directions share their work. δε^tr is linear in h: with Λ_kq = ½ d ln b^tr[e_k ⊗ e_q + e_q ⊗ e_k]
= ½ Q (L ∘ (q_k ⊗ q_q + q_q ⊗ q_k)) Qᵀ (symmetric in k, q: six pairs),

    δε^tr = Σ_q h_q Λ_kq,   δP = Σ_q h_q Z_kq − P e_l ⊗ F⁻¹ e_k,   Z_kq = (Bᵀ D B Λ_kq) F⁻ᵀ,

so D, Bᵀ and F⁻ᵀ are applied six times a point instead of nine, and the directions' log
derivatives are not formed one by one (:func:`_pair_responses`, :func:`_coaxial_point`).

Both forms are the numpy form's operations up to their order and grouping: the results agree
to rounding (``tests/unit/test_finite_strain_kernels.py`` compares them).

This module imports numba: :mod:`.hencky` imports it where a tangent is first asked for (numba's
import is kept out of a run that does not need it, ``cli.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dolfinx_nnqem.chatter import apply_numba_options
from dolfinx_nnqem.material.finite_strain.point_kernels import inverse_3x3

__all__ = ["hencky_tangent"]

apply_numba_options()

_PAIR_K = np.array([0, 0, 0, 1, 1, 2])  # the six pairs (k ≤ q) of the coaxial tangent, :func:`_pair_responses`
_PAIR_Q = np.array([0, 1, 2, 1, 2, 2])
_PAIR = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])  # p(k, q) = p(q, k)


@numba.njit(cache=True, inline="always")
def _log_divided_differences(lam, L):  # pragma: no cover  (compiled)
    """L_ab = log1p(d)/(λ_b d), d = (λ_a − λ_b)/λ_b; L_ab = 1/λ_b where d = 0 (:mod:`.spectral`)."""
    for a in range(3):
        for b in range(3):
            d = (lam[a] - lam[b]) / lam[b]
            L[a, b] = 1.0 / lam[b] if d == 0.0 else math.log1p(d) / (lam[b] * d)


@numba.njit(cache=True, inline="always")
def _point_setup(Fn_inv, left, Q, r, u, h, R_Q, M, M_inv):  # pragma: no cover  (compiled)
    """A point's direction-independent arrays: h (row l: (f b_e,n) F_n⁻ᵀ e_l), rᵀQ and
    M⁻¹ = (tr u I − u)⁻¹ (M: a work array)."""
    for ll in range(3):
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += left[j, m] * Fn_inv[ll, m]
            h[ll, j] = s
    for i in range(3):
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += r[m, i] * Q[m, j]
            R_Q[i, j] = s
    tr = u[0, 0] + u[1, 1] + u[2, 2]
    for i in range(3):
        for j in range(3):
            M[i, j] = (tr if i == j else 0.0) - u[i, j]
    inverse_3x3(M, M_inv)


@numba.njit(cache=True, inline="always")
def _rotated_log_derivative(k, h, Q, L, R_Q, X, Y, S):  # pragma: no cover  (compiled)
    """S = rᵀ δε^tr r = ½ (rᵀQ)(L ∘ Ĥ)(rᵀQ)ᵀ, Ĥ = q_k ⊗ ĥ + ĥ ⊗ q_k, ĥ = Qᵀ h (X, Y: work arrays)."""
    h0 = Q[0, 0] * h[0] + Q[1, 0] * h[1] + Q[2, 0] * h[2]
    h1 = Q[0, 1] * h[0] + Q[1, 1] * h[1] + Q[2, 1] * h[2]
    h2 = Q[0, 2] * h[0] + Q[1, 2] * h[1] + Q[2, 2] * h[2]
    for a in range(3):
        h_a = h0 if a == 0 else (h1 if a == 1 else h2)
        X[a, 0] = L[a, 0] * (Q[k, a] * h0 + h_a * Q[k, 0])
        X[a, 1] = L[a, 1] * (Q[k, a] * h1 + h_a * Q[k, 1])
        X[a, 2] = L[a, 2] * (Q[k, a] * h2 + h_a * Q[k, 2])
    for i in range(3):
        for b in range(3):
            Y[i, b] = R_Q[i, 0] * X[0, b] + R_Q[i, 1] * X[1, b] + R_Q[i, 2] * X[2, b]
    for i in range(3):
        for j in range(3):
            S[i, j] = 0.5 * (Y[i, 0] * R_Q[j, 0] + Y[i, 1] * R_Q[j, 1] + Y[i, 2] * R_Q[j, 2])


@numba.njit(cache=True, inline="always")
def _spin(k, ll, r, Fn_inv, M_inv, Omega):  # pragma: no cover  (compiled)
    """Ω = W(ω), ω = (tr u I − u)⁻¹ axial(A − Aᵀ), A_ij = (rᵀδf)_ij = r_ki (F_n⁻¹)_lj."""
    a0 = r[k, 2] * Fn_inv[ll, 1] - r[k, 1] * Fn_inv[ll, 2]  # axial(A − Aᵀ) = (A_21 − A_12, ...)
    a1 = r[k, 0] * Fn_inv[ll, 2] - r[k, 2] * Fn_inv[ll, 0]
    a2 = r[k, 1] * Fn_inv[ll, 0] - r[k, 0] * Fn_inv[ll, 1]
    w0 = M_inv[0, 0] * a0 + M_inv[0, 1] * a1 + M_inv[0, 2] * a2
    w1 = M_inv[1, 0] * a0 + M_inv[1, 1] * a1 + M_inv[1, 2] * a2
    w2 = M_inv[2, 0] * a0 + M_inv[2, 1] * a1 + M_inv[2, 2] * a2
    Omega[0, 0], Omega[0, 1], Omega[0, 2] = 0.0, -w2, w1
    Omega[1, 0], Omega[1, 1], Omega[1, 2] = w2, 0.0, -w0
    Omega[2, 0], Omega[2, 1], Omega[2, 2] = -w1, w0, 0.0


@numba.njit(cache=True, inline="always")
def _commutator(Omega, T, out):  # pragma: no cover  (compiled)
    """out = Ω T − T Ω."""
    for i in range(3):
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += Omega[i, m] * T[m, j] - T[i, m] * Omega[m, j]
            out[i, j] = s


@numba.njit(cache=True, inline="always")
def _stress_rate(D, B, deps_bar, c, Y):  # pragma: no cover  (compiled)
    """Y += δτ̄ = D : δε̄ in the coordinates: Bᵀ (D (B δε̄)) (δε̄ (3, 3), B the basis (6, 3, 3), c a
    work vector (6))."""
    for a in range(6):
        s = 0.0
        for i in range(3):
            for j in range(3):
                s += B[a, i, j] * deps_bar[i, j]
        c[a] = s
    for a in range(6):
        d = D[a, 0] * c[0] + D[a, 1] * c[1] + D[a, 2] * c[2] + D[a, 3] * c[3] + D[a, 4] * c[4] + D[a, 5] * c[5]
        for i in range(3):
            for j in range(3):
                Y[i, j] += B[a, i, j] * d


@numba.njit(cache=True, inline="always")
def _direction(k, ll, g, point, work, c, D, B, out):  # pragma: no cover  (compiled)
    """∂P/∂F_kl at point g into out[g, :, :, k, ll] in the increment's rotated frame (the module
    docstring's steps); ``point`` holds the point's 3 × 3 arrays (:func:`hencky_tangent`), ``work``
    and ``c`` work arrays."""
    Fn_inv, h, Q, L, R_Q, M_inv, r, eps_bar, tau_bar, F_inv, P = (point[0], point[1], point[2], point[3], point[4],
                                                                  point[5], point[6], point[7], point[8], point[9],
                                                                  point[10])
    S, Omega, C, Y, dtau = work[0], work[1], work[2], work[3], work[4]
    _rotated_log_derivative(k, h[ll], Q, L, R_Q, work[5], work[6], S)
    _spin(k, ll, r, Fn_inv, M_inv, Omega)
    _commutator(Omega, eps_bar, C)
    for i in range(3):
        for j in range(3):
            S[i, j] -= C[i, j]  # δε̄ = rᵀ δε^tr r − (Ω ε̄ − ε̄ Ω)
    _commutator(Omega, tau_bar, Y)
    _stress_rate(D, B, S, c, Y)
    for i in range(3):  # δτ = r Y rᵀ
        for p in range(3):
            C[i, p] = r[i, 0] * Y[0, p] + r[i, 1] * Y[1, p] + r[i, 2] * Y[2, p]
    for i in range(3):
        for j in range(3):
            dtau[i, j] = C[i, 0] * r[j, 0] + C[i, 1] * r[j, 1] + C[i, 2] * r[j, 2]
    for i in range(3):
        for j in range(3):
            s = dtau[i, 0] * F_inv[j, 0] + dtau[i, 1] * F_inv[j, 1] + dtau[i, 2] * F_inv[j, 2]
            out[g, i, j, k, ll] = s - P[i, ll] * F_inv[j, k]


@numba.njit(cache=True, inline="always")
def _pair_responses(Q, L, D, B, F_inv, Z, X, Y, c, t):  # pragma: no cover  (compiled)
    """Z[p] = (Bᵀ D B Λ_kq) F⁻ᵀ (Z (6, 3, 3)) for the six pairs p = (k ≤ q) of :data:`_PAIR_K`,
    :data:`_PAIR_Q`: Λ_kq = ½ Q (L ∘ (q̃_k ⊗ q̃_q + q̃_q ⊗ q̃_k)) Qᵀ, q̃_k the row k of Q, is
    ½ d ln b^tr[e_k ⊗ e_q + e_q ⊗ e_k] (X, Y (3, 3), c, t (6): work arrays)."""
    for p in range(6):
        k, q = _PAIR_K[p], _PAIR_Q[p]
        for a in range(3):
            for b in range(3):
                X[a, b] = 0.5 * L[a, b] * (Q[k, a] * Q[q, b] + Q[q, a] * Q[k, b])
        for i in range(3):
            for b in range(3):
                Y[i, b] = Q[i, 0] * X[0, b] + Q[i, 1] * X[1, b] + Q[i, 2] * X[2, b]
        for i in range(3):
            for j in range(3):
                X[i, j] = Y[i, 0] * Q[j, 0] + Y[i, 1] * Q[j, 1] + Y[i, 2] * Q[j, 2]  # Λ_kq
        for a in range(6):
            s = 0.0
            for i in range(3):
                for j in range(3):
                    s += B[a, i, j] * X[i, j]
            c[a] = s
        for a in range(6):
            t[a] = D[a, 0] * c[0] + D[a, 1] * c[1] + D[a, 2] * c[2] + D[a, 3] * c[3] + D[a, 4] * c[4] + D[a, 5] * c[5]
        for i in range(3):
            for j in range(3):
                Y[i, j] = (B[0, i, j] * t[0] + B[1, i, j] * t[1] + B[2, i, j] * t[2] + B[3, i, j] * t[3]
                           + B[4, i, j] * t[4] + B[5, i, j] * t[5])  # ∂τ/∂b^tr along the pair, as a tensor
        for i in range(3):
            for j in range(3):
                Z[p, i, j] = Y[i, 0] * F_inv[j, 0] + Y[i, 1] * F_inv[j, 1] + Y[i, 2] * F_inv[j, 2]


@numba.njit(cache=True, inline="always")
def _coaxial_point(g, Fn_inv, left, Q, L, D, B, F_inv, P, h, Z, X, Y, c, t, out):  # pragma: no cover  (compiled)
    """∂P/∂F at point g into out[g] where r = I (an isotropic law): δP_kl = Σ_q h_q Z[p(k, q)] −
    P e_l ⊗ F⁻¹ e_k, h = (f b_e,n) F_n⁻ᵀ e_l (the module docstring; h, Z, X, Y, c, t: work arrays)."""
    for ll in range(3):
        for j in range(3):
            h[ll, j] = left[j, 0] * Fn_inv[ll, 0] + left[j, 1] * Fn_inv[ll, 1] + left[j, 2] * Fn_inv[ll, 2]
    _pair_responses(Q, L, D, B, F_inv, Z, X, Y, c, t)
    for k in range(3):
        p0, p1, p2 = _PAIR[k, 0], _PAIR[k, 1], _PAIR[k, 2]
        for ll in range(3):
            h0, h1, h2 = h[ll, 0], h[ll, 1], h[ll, 2]
            for i in range(3):
                for j in range(3):
                    out[g, i, j, k, ll] = (h0 * Z[p0, i, j] + h1 * Z[p1, i, j] + h2 * Z[p2, i, j]
                                           - P[i, ll] * F_inv[j, k])


@numba.njit(cache=True)
def hencky_tangent(Fn_inv: np.ndarray, left: np.ndarray, lam: np.ndarray, Q: np.ndarray, r: np.ndarray,
                   u: np.ndarray, eps_bar: np.ndarray, C6: np.ndarray, R: np.ndarray, B: np.ndarray,
                   tau_bar: np.ndarray, F_inv: np.ndarray, P: np.ndarray, rotating: bool, out: np.ndarray
                   ) -> None:  # pragma: no cover  (compiled)
    """∂P_ij/∂F_kl (n, 3, 3, 3, 3) into ``out`` from the trial state's F_n⁻¹, f b_e,n, λ, Q, r, u and
    ε̄, the algorithmic tangent D = C (I − ∂Δε_p/∂ε) (n, 6, 6) in the coordinates of the basis B (6, 9)
    given by its factors C6 (n, 6) and R = ∂Δε_p/∂ε (n, 6, 6) (formed point by point, as numpy's
    ``C6[:, :, None] * (np.eye(6) - R)``), τ̄, F⁻¹ and P = τ F⁻ᵀ (the module docstring): direction by
    direction in the rotated frame if ``rotating``, else (r = I, an isotropic law: :mod:`.hencky`) by
    the six pairs of :func:`_pair_responses`."""
    point, work, c = np.empty((11, 3, 3)), np.empty((8, 3, 3)), np.empty(6)
    Z, t, D = np.empty((6, 3, 3)), np.empty(6), np.empty((6, 6))
    B3 = B.reshape(6, 3, 3)
    for g in range(Fn_inv.shape[0]):
        for i in range(6):
            for j in range(6):
                D[i, j] = C6[g, i] * ((1.0 if i == j else 0.0) - R[g, i, j])
        _log_divided_differences(lam[g], point[3])
        if not rotating:
            _coaxial_point(g, Fn_inv[g], left[g], Q[g], point[3], D, B3, F_inv[g], P[g], point[1], Z, work[0],
                           work[1], c, t, out)
            continue
        _point_setup(Fn_inv[g], left[g], Q[g], r[g], u[g], point[1], point[4], work[7], point[5])
        for m, a in ((0, Fn_inv), (2, Q), (6, r), (7, eps_bar), (8, tau_bar), (9, F_inv), (10, P)):
            point[m] = a[g]
        for k in range(3):
            for ll in range(3):
                _direction(k, ll, g, point, work, c, D, B3, out)
