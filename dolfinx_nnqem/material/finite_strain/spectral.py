"""Functions of symmetric 3×3 tensors by their spectral decomposition, their first derivatives,
and the polar decomposition with the derivative of its rotation: the tensor algebra of the
logarithmic-strain route (:mod:`.hencky`), on numpy arrays of Gauss points.

**ln and exp of a symmetric positive definite tensor** A = Σ_a λ_a q_a⊗q_a: f(A) = Σ_a f(λ_a)
q_a⊗q_a (``numpy.linalg.eigh``, which returns an orthonormal basis also where eigenvalues
coincide).

**The derivative of ln** (Daleckii–Krein): with Ĥ = Qᵀ H Q,

    d ln(A)[H] = Q (L ∘ Ĥ) Qᵀ,  L_ab = (ln λ_a − ln λ_b)/(λ_a − λ_b)  (a ≠ b),  L_aa = 1/λ_a.

Written as L_ab = log1p(d)/(λ_b d), d = (λ_a − λ_b)/λ_b, the divided difference has no
cancellation as the eigenvalues approach each other: log1p(d)/d → 1 − d/2 with an absolute error
of the order of the rounding of d. Equal and nearly equal eigenvalues take the same formula
(d = 0 exactly: its limit 1/λ_b).

**The polar decomposition** f = r u (r a rotation, u = √(fᵀf)) from the singular value
decomposition, and its rotation's derivative: δr = r Ω with Ω skew, Ω u + u Ω = rᵀδf − δfᵀr.
For a symmetric u and a skew Ω = W(ω) (W(ω)v = ω × v), Ω u + u Ω = W((tr u I − u) ω), so
ω = (tr u I − u)⁻¹ axial(rᵀδf − δfᵀr): the matrix is positive definite (its eigenvalues are sums
of two stretches), whatever the stretches' multiplicities.
"""

from __future__ import annotations

import numpy as np

__all__ = ["axial_vector", "eigen", "log_derivative", "log_divided_differences", "polar_decomposition",
           "rotation_derivative", "skew_tensor", "tensor_function"]


def eigen(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(λ (n, 3), Q (n, 3, 3)) of the symmetric part of tensors A (n, 3, 3): A = Q diag(λ) Qᵀ."""
    lam, Q = np.linalg.eigh(0.5 * (A + np.swapaxes(A, -1, -2)))
    return lam, Q


def tensor_function(Q: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Σ_a values_a q_a⊗q_a (n, 3, 3) for eigenvectors Q (n, 3, 3) (columns) and values (n, 3)."""
    return (Q * values[:, None, :]) @ np.swapaxes(Q, 1, 2)  # (a batched product: einsum's three operands are slower)


def log_divided_differences(lam: np.ndarray) -> np.ndarray:
    """L (n, 3, 3): L_ab = (ln λ_a − ln λ_b)/(λ_a − λ_b), L_aa = 1/λ_a, for eigenvalues λ (n, 3) > 0
    (the module docstring's form, exact as they coincide)."""
    a, b = lam[:, :, None], lam[:, None, :]
    d = (a - b) / b
    same = d == 0.0
    d_safe = np.where(same, 1.0, d)
    return np.where(same, 1.0 / b, np.log1p(d_safe) / (b * d_safe))


def log_derivative(lam: np.ndarray, Q: np.ndarray, H: np.ndarray) -> np.ndarray:
    """d ln(A)[H] (n, m, 3, 3) at A = Q diag(λ) Qᵀ for m directions H (n, m, 3, 3) per point."""
    L = log_divided_differences(lam)
    H_hat = np.einsum("nai,nmab,nbj->nmij", Q, H, Q)
    return np.einsum("nia,nmab,njb->nmij", Q, L[:, None] * H_hat, Q)


def polar_decomposition(f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(r, u) (n, 3, 3) with f = r u, r a rotation, u symmetric positive definite, for tensors f
    (n, 3, 3) with det f > 0."""
    W, s, Vt = np.linalg.svd(f)
    return W @ Vt, np.einsum("nai,na,naj->nij", Vt, s, Vt)


def skew_tensor(omega: np.ndarray) -> np.ndarray:
    """W(ω) (..., 3, 3) with W(ω) v = ω × v, for axial vectors ω (..., 3)."""
    W = np.zeros((*omega.shape[:-1], 3, 3))
    W[..., 0, 1], W[..., 0, 2], W[..., 1, 2] = -omega[..., 2], omega[..., 1], -omega[..., 0]
    W[..., 1, 0], W[..., 2, 0], W[..., 2, 1] = omega[..., 2], -omega[..., 1], omega[..., 0]
    return W


def axial_vector(W: np.ndarray) -> np.ndarray:
    """ω (..., 3) of the skew part of W (..., 3, 3): skew(W) v = ω × v."""
    return 0.5 * np.stack([W[..., 2, 1] - W[..., 1, 2], W[..., 0, 2] - W[..., 2, 0],
                           W[..., 1, 0] - W[..., 0, 1]], axis=-1)


def rotation_derivative(r: np.ndarray, u: np.ndarray, df: np.ndarray) -> np.ndarray:
    """Ω = rᵀ δr (n, m, 3, 3), skew, of the polar rotation of f = r u (n, 3, 3) along m directions
    δf (n, m, 3, 3) (the module docstring)."""
    A = np.einsum("nai,nmaj->nmij", r, df)
    a = axial_vector(A - np.swapaxes(A, -1, -2))
    M = np.trace(u, axis1=1, axis2=2)[:, None, None] * np.eye(3) - u
    omega = np.linalg.solve(M[:, None], a[..., None])[..., 0]
    return skew_tensor(omega)
