"""Small-strain kinematics and the tensor algebra every material shares.

The strain ε(u) = sym ∇u (UFL), and on numpy arrays of Gauss-point values: Hooke's law, the
deviator's coordinates in an orthonormal basis, the von Mises equivalent stress q = √(3/2 s:s)
and its gradient. No material lives here: the return maps (``von_mises``, ``isotropic``,
``elastic``) are written in these terms, so that a later kinematics (the logarithmic strain of
``formulation.md`` §1c) can wrap them without touching them.

Coordinates. A symmetric tensor T has the 6 coordinates T:D_a in the orthonormal basis
D_1..D_5 of :data:`DEVIATORIC_BASIS` (the deviators) and D_6 = I/√3 (the volumetric part):
(n, 5) arrays describe deviators, (n, 6) arrays full symmetric tensors
(:func:`symmetric_coordinates`); |T|² = Σ_a (T:D_a)².
"""

from __future__ import annotations

import math

import numpy as np
import ufl

__all__ = ["DEVIATORIC_BASIS", "coordinate_tangent", "deviator", "deviator_coordinates", "deviator_tensors",
           "elastic_stress", "equivalent_stress", "equivalent_stress_gradient", "strain", "symmetric_coordinates",
           "symmetric_tensors", "von_mises_stress"]


def strain(u: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """Small-strain tensor ε(u) = sym(∇u)."""
    return ufl.sym(ufl.grad(u))


_S2, _S6 = 1.0 / math.sqrt(2.0), 1.0 / math.sqrt(6.0)
DEVIATORIC_BASIS = np.array([
    [_S2, 0, 0, 0, -_S2, 0, 0, 0, 0],
    [_S6, 0, 0, 0, _S6, 0, 0, 0, -2 * _S6],
    [0, _S2, 0, _S2, 0, 0, 0, 0, 0],
    [0, 0, _S2, 0, 0, 0, _S2, 0, 0],
    [0, 0, 0, 0, 0, _S2, 0, _S2, 0],
])
"""D (5 × 9): an orthonormal basis of the symmetric deviatoric 3×3 tensors (rows: the 9
components, row-major); T:D_a are the coordinates of dev T, and |dev T|² = Σ_a (T:D_a)²."""
_SYMMETRIC_BASIS = np.vstack([DEVIATORIC_BASIS, np.eye(3).reshape(1, 9) / math.sqrt(3.0)])
_SQRT32 = math.sqrt(1.5)


def deviator_coordinates(tensors: np.ndarray) -> np.ndarray:
    """Coordinates (n, 5) of dev T in :data:`DEVIATORIC_BASIS` for tensors (n, 3, 3) or (n, 9)."""
    return np.asarray(tensors).reshape(-1, 9) @ DEVIATORIC_BASIS.T


def deviator_tensors(coordinates: np.ndarray) -> np.ndarray:
    """The deviators (n, 3, 3) with the given coordinates (n, 5)."""
    return (np.asarray(coordinates) @ DEVIATORIC_BASIS).reshape(-1, 3, 3)


def symmetric_coordinates(tensors: np.ndarray) -> np.ndarray:
    """Coordinates (n, 6) of symmetric tensors (n, 3, 3): the deviator's 5, then tr T/√3."""
    return np.asarray(tensors).reshape(-1, 9) @ _SYMMETRIC_BASIS.T


def symmetric_tensors(coordinates: np.ndarray) -> np.ndarray:
    """The symmetric tensors (n, 3, 3) with the given coordinates (n, 6) (or deviators, (n, 5))."""
    coordinates = np.asarray(coordinates)
    return (coordinates @ _SYMMETRIC_BASIS[:coordinates.shape[-1]]).reshape(-1, 3, 3)


def deviator(tensors: np.ndarray) -> np.ndarray:
    """dev T = T − (tr T / 3) I for tensors (n, 3, 3)."""
    return tensors - np.trace(tensors, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3.0


def equivalent_stress(s: np.ndarray) -> np.ndarray:
    """q = sqrt(3/2 s:s) of deviators given by their coordinates (n, 5) (the first 5 of (n, 6))."""
    return _SQRT32 * np.linalg.norm(s[..., :5], axis=-1)


def von_mises_stress(sigma: np.ndarray) -> np.ndarray:
    """q = sqrt(3/2 s:s) of full stress tensors, shape (..., 3, 3)."""
    sigma = np.asarray(sigma, dtype=float)
    return equivalent_stress(deviator_coordinates(sigma.reshape(-1, 3, 3))).reshape(sigma.shape[:-2])


def equivalent_stress_gradient(s: np.ndarray, stress_unit: np.ndarray, fallback: np.ndarray | None = None
                               ) -> np.ndarray:
    """∂q/∂s = (3/2) s / q (coordinates, (n, 5)): the von Mises flow direction N; 0 (or ``fallback``)
    where q ≤ 10⁻⁸ × the stress unit."""
    q = equivalent_stress(s)
    ok = q > 1e-8 * stress_unit
    N = np.zeros_like(s) if fallback is None else fallback.copy()
    N[ok] = 1.5 * s[ok] / q[ok, None]
    return N


def elastic_stress(eps: np.ndarray, lmbda: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """σ = λ tr(ε) I + 2μ ε for strains (n, 3, 3) and per-point Lamé parameters (n,)."""
    return (lmbda[:, None, None] * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(3)
            + 2.0 * mu[:, None, None] * eps)


def coordinate_tangent(M: np.ndarray) -> np.ndarray:
    """The fourth-order tensors (n, 3, 3, 3, 3) of linear maps of symmetric tensors given in
    coordinates (n, 6, 6) (:func:`symmetric_coordinates`): T_ijkl = Σ_ab D_a,ij M_ab D_b,kl."""
    return np.einsum("ai,nab,bj->nij", _SYMMETRIC_BASIS, M, _SYMMETRIC_BASIS).reshape(-1, 3, 3, 3, 3)
