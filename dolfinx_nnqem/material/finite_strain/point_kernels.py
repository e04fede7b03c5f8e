"""The per-point tensor algebra of the logarithmic-strain route (:mod:`.hencky`) before and after the
return map, compiled: one loop over the Gauss points on 3 × 3 arrays (numba, ``cache=True``).

Batched numpy on (n, 3, 3) arrays pays a LAPACK call or a small-matrix product per point and per
operation (``inv``, ``det``, ``eigh``, ``@``): about a microsecond each, twenty of them per point.
Here each point's steps run in one pass:

* :func:`elastic_trial`: F_n⁻¹ (cofactors), f = F F_n⁻¹, f b_e,n, b_e^tr = (f b_e,n) fᵀ, its
  eigen-decomposition (:func:`symmetric_eigen`) and ε^tr = Σ_a ½ ln λ_a q_a ⊗ q_a;
* :func:`coaxial_eigenvalues`: λ_a^e = q_aᵀ ε_e q_a, the eigenvalues of ε_e in the trial's
  eigenvectors (an isotropic law: ε_e coaxial with ε^tr);
* :func:`exponential_map`: b_e = Σ_a exp(2 λ_a^e) q_a ⊗ q_a, F⁻¹, P = τ F⁻ᵀ and σ = τ / J.

**Small strains without cancellation.** At a strain of 10⁻⁵ the entries of b_e^tr are 1 plus
10⁻⁵: formed as such and decomposed, its eigenvalues carry a few ulps of 1, and ln λ_a loses
the digits the 1 took: a relative error of about 10⁻¹⁶ / 10⁻⁵ in the strain, which puts a floor
under the residual that rises as the load falls (10⁻¹⁰ of the force at 10⁻⁵ strain, enough to stall
a solve asked for 10⁻¹⁰, and cutting the increment back only makes it worse). So the trial works
on the departures from the identity: h = f − I = (F − F_n) F_n⁻¹, β = b_e,n − I (both exact
subtractions of nearby numbers) and

    d = b_e^tr − I = h + hᵀ + h hᵀ + f β fᵀ,

decomposed as it is (the Jacobi rotations are scale-free) into λ_a − 1 = eig(d) and the same
eigenvectors, with ½ ln λ_a = ½ log1p(eig(d)). Likewise the exponential map forms
b_e = I + Σ_a expm1(2 λ_a^e) q_a ⊗ q_a. What remains is the rounding of F = I + ∇u itself (one ulp).

**The eigen-decomposition** of a symmetric 3 × 3 tensor is the cyclic Jacobi method (Golub & Van
Loan §8.5): plane rotations that zero one off-diagonal entry at a time, until the off-diagonal part
is negligible against the diagonal. Its eigenvalues are accurate to a few ulps of |A|, its
eigenvectors orthonormal to rounding whatever the eigenvalues' multiplicities (a repeated
eigenvalue needs no rotation: any orthonormal basis of its space is one). The eigenvalues come in
ascending order with their vectors, as ``numpy.linalg.eigh`` gives them.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dolfinx_nnqem.chatter import apply_numba_options

__all__ = ["coaxial_eigenvalues", "elastic_trial", "exponential_map", "inverse_3x3", "symmetric_eigen"]

apply_numba_options()

_MAX_SWEEPS = 50  # cyclic Jacobi converges quadratically: 3 × 3 tensors need 4–6 sweeps


@numba.njit(cache=True, inline="always")
def _rotate(A, V, p, q):  # pragma: no cover  (compiled)
    """One Jacobi rotation in the plane (p, q): A ← Jᵀ A J with (Jᵀ A J)_pq = 0, V ← V J."""
    theta = (A[q, q] - A[p, p]) / (2.0 * A[p, q])
    t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
    c = 1.0 / math.sqrt(t * t + 1.0)
    s = t * c
    for k in range(3):  # columns p and q of A J
        akp, akq = A[k, p], A[k, q]
        A[k, p], A[k, q] = c * akp - s * akq, s * akp + c * akq
    for k in range(3):  # rows p and q of Jᵀ (A J)
        apk, aqk = A[p, k], A[q, k]
        A[p, k], A[q, k] = c * apk - s * aqk, s * apk + c * aqk
    A[p, q] = A[q, p] = 0.0
    for k in range(3):
        vkp, vkq = V[k, p], V[k, q]
        V[k, p], V[k, q] = c * vkp - s * vkq, s * vkp + c * vkq


@numba.njit(cache=True)
def symmetric_eigen(S, lam, Q, A):  # pragma: no cover  (compiled)
    """Eigenvalues ``lam`` (3,) ascending and eigenvectors ``Q`` (3, 3, columns) of the symmetric part
    of S (3, 3), by cyclic Jacobi rotations (the module docstring); ``A`` a work array (3, 3)."""
    for i in range(3):
        for j in range(3):
            A[i, j] = 0.5 * (S[i, j] + S[j, i])
            Q[i, j] = 1.0 if i == j else 0.0
    for _ in range(_MAX_SWEEPS):
        off = abs(A[0, 1]) + abs(A[0, 2]) + abs(A[1, 2])
        if off == 0.0:
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            g = 100.0 * abs(A[p, q])
            if abs(A[p, p]) + g == abs(A[p, p]) and abs(A[q, q]) + g == abs(A[q, q]):
                A[p, q] = A[q, p] = 0.0  # below the rounding of both diagonal entries
            elif A[p, q] != 0.0:
                _rotate(A, Q, p, q)
    for a in range(3):
        lam[a] = A[a, a]
    for a in range(2):  # ascending, with the columns
        m = a
        for b in range(a + 1, 3):
            if lam[b] < lam[m]:
                m = b
        if m != a:
            lam[a], lam[m] = lam[m], lam[a]
            for k in range(3):
                Q[k, a], Q[k, m] = Q[k, m], Q[k, a]


@numba.njit(cache=True, inline="always")
def inverse_3x3(M, out):  # pragma: no cover  (compiled)
    """M⁻¹ of a 3 × 3 matrix by its cofactors."""
    c00 = M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1]
    c01 = M[1, 2] * M[2, 0] - M[1, 0] * M[2, 2]
    c02 = M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]
    det = M[0, 0] * c00 + M[0, 1] * c01 + M[0, 2] * c02
    out[0, 0], out[1, 0], out[2, 0] = c00 / det, c01 / det, c02 / det
    out[0, 1] = (M[0, 2] * M[2, 1] - M[0, 1] * M[2, 2]) / det
    out[1, 1] = (M[0, 0] * M[2, 2] - M[0, 2] * M[2, 0]) / det
    out[2, 1] = (M[0, 1] * M[2, 0] - M[0, 0] * M[2, 1]) / det
    out[0, 2] = (M[0, 1] * M[1, 2] - M[0, 2] * M[1, 1]) / det
    out[1, 2] = (M[0, 2] * M[1, 0] - M[0, 0] * M[1, 2]) / det
    out[2, 2] = (M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]) / det


@numba.njit(cache=True, inline="always")
def _spectral_sum(Q, values, out):  # pragma: no cover  (compiled)
    """out = Σ_a values_a q_a ⊗ q_a (q_a the columns of Q)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = Q[i, 0] * values[0] * Q[j, 0] + Q[i, 1] * values[1] * Q[j, 1] + Q[i, 2] * values[2] * Q[j, 2]


@numba.njit(cache=True)
def elastic_trial(F: np.ndarray, F_n: np.ndarray, b_n: np.ndarray, F_n_inv: np.ndarray, f: np.ndarray,
                  left: np.ndarray, lam: np.ndarray, Q: np.ndarray, eps_tr: np.ndarray
                  ) -> None:  # pragma: no cover  (compiled)
    """The elastic trial state at n points into the outputs: F_n⁻¹, f = F F_n⁻¹, ``left`` = f b_e,n,
    the eigenvalues ``lam`` (n, 3) (ascending) and eigenvectors ``Q`` of b_e^tr = f b_e,n fᵀ, and
    ε^tr = ½ ln b_e^tr (all (n, 3, 3) but ``lam``)."""
    dF, h, beta, f_beta, d, A = (np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)),
                                 np.empty((3, 3)), np.empty((3, 3)))
    d_lam, half_log = np.empty(3), np.empty(3)
    for g in range(F.shape[0]):
        inverse_3x3(F_n[g], F_n_inv[g])
        for i in range(3):
            for j in range(3):
                dF[i, j] = F[g, i, j] - F_n[g, i, j]
                beta[i, j] = b_n[g, i, j] - (1.0 if i == j else 0.0)
        for i in range(3):
            for j in range(3):
                h[i, j] = dF[i, 0] * F_n_inv[g, 0, j] + dF[i, 1] * F_n_inv[g, 1, j] + dF[i, 2] * F_n_inv[g, 2, j]
                f[g, i, j] = h[i, j] + (1.0 if i == j else 0.0)
        for i in range(3):
            for j in range(3):
                left[g, i, j] = f[g, i, 0] * b_n[g, 0, j] + f[g, i, 1] * b_n[g, 1, j] + f[g, i, 2] * b_n[g, 2, j]
                f_beta[i, j] = f[g, i, 0] * beta[0, j] + f[g, i, 1] * beta[1, j] + f[g, i, 2] * beta[2, j]
        for i in range(3):  # d = b_e^tr − I = h + hᵀ + h hᵀ + f β fᵀ (the module docstring)
            for j in range(3):
                d[i, j] = (h[i, j] + h[j, i] + h[i, 0] * h[j, 0] + h[i, 1] * h[j, 1] + h[i, 2] * h[j, 2]
                           + f_beta[i, 0] * f[g, j, 0] + f_beta[i, 1] * f[g, j, 1] + f_beta[i, 2] * f[g, j, 2])
        symmetric_eigen(d, d_lam, Q[g], A)
        for a in range(3):
            lam[g, a] = 1.0 + d_lam[a]
            half_log[a] = 0.5 * math.log1p(d_lam[a]) if d_lam[a] > -1.0 else np.nan
        _spectral_sum(Q[g], half_log, eps_tr[g])


@numba.njit(cache=True)
def exponential_map(F: np.ndarray, J: np.ndarray, tau: np.ndarray, Q_e: np.ndarray, lam_e: np.ndarray,
                    b_e: np.ndarray, F_inv: np.ndarray, P: np.ndarray, sigma: np.ndarray
                    ) -> None:  # pragma: no cover  (compiled)
    """After the return map, at n points: b_e = Σ_a exp(2 λ_a^e) q_a ⊗ q_a from the elastic
    logarithmic strain's eigen-pairs (``lam_e`` (n, 3), ``Q_e``), F⁻¹, P = τ F⁻ᵀ and σ = τ / J
    (into ``b_e``, ``F_inv``, ``P``, ``sigma``, all (n, 3, 3))."""
    stretch = np.empty(3)
    for g in range(F.shape[0]):
        for a in range(3):
            stretch[a] = math.expm1(2.0 * lam_e[g, a])
        _spectral_sum(Q_e[g], stretch, b_e[g])  # b_e − I, then the identity (the module docstring)
        for a in range(3):
            b_e[g, a, a] += 1.0
        inverse_3x3(F[g], F_inv[g])
        for i in range(3):
            for j in range(3):
                P[g, i, j] = tau[g, i, 0] * F_inv[g, j, 0] + tau[g, i, 1] * F_inv[g, j, 1] + tau[g, i, 2] * F_inv[g, j, 2]
                sigma[g, i, j] = tau[g, i, j] / J[g]


@numba.njit(cache=True)
def coaxial_eigenvalues(A: np.ndarray, Q: np.ndarray, lam: np.ndarray) -> None:  # pragma: no cover  (compiled)
    """lam[g, a] = q_aᵀ A q_a (n, 3) for symmetric tensors A (n, 3, 3) and orthonormal vectors Q (n, 3, 3,
    columns q_a): the eigenvalues of A where Q are its eigenvectors."""
    for g in range(A.shape[0]):
        for a in range(3):
            s = 0.0
            for i in range(3):
                s += Q[g, i, a] * (A[g, i, 0] * Q[g, 0, a] + A[g, i, 1] * Q[g, 1, a] + A[g, i, 2] * Q[g, 2, a])
            lam[g, a] = s
