"""The finite-strain constitutive update at Gauss points: its Protocol, its state and its answer.

A :class:`FiniteStrainMaterial` takes the deformation gradient F_{n+1} (n, 3, 3) at the end of an
increment and the converged state of the previous one (:class:`FiniteStrainState`: F_n, the
elastic left Cauchy–Green tensor b_e,n and the internal variables), and answers with the first
Piola–Kirchhoff stress P, the Kirchhoff and Cauchy stresses, the consistent tangent ∂P/∂F and the
state at the end of the increment (:class:`FiniteStrainResponse`). Arrays only: nothing here
knows a mesh, a form or a solver (``docs/materials.md``, "Finite strain").

Tangent layout: ``tangent[g, i, j, k, l]`` = ∂P_ij/∂F_kl at point g ((n, 9, 9) after
``reshape(n, 9, 9)``, row-major components of P and F).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["FiniteStrainMaterial", "FiniteStrainResponse", "FiniteStrainState", "checked_deformation_gradients"]


@dataclass(frozen=True)
class FiniteStrainState:
    """The converged state at the end of an increment, at n Gauss points.

    Attributes
    ----------
    F
        (n, 3, 3) deformation gradients F_n.
    b_e
        (n, 3, 3) elastic left Cauchy–Green tensors b_e,n = F_e F_eᵀ (F_n F_nᵀ for a hyperelastic law).
    internal
        The internal variables by name: "p" (n,), the equivalent plastic strain (0 where nothing
        yields), and a material's others (e.g. spatial back-stresses "alpha_1" (n, 3, 3)).
    """

    F: np.ndarray
    b_e: np.ndarray
    internal: Mapping[str, np.ndarray]


@dataclass(frozen=True)
class FiniteStrainResponse:
    """The constitutive update's answer at n Gauss points.

    Attributes
    ----------
    P
        (n, 3, 3) first Piola–Kirchhoff stresses P = τ F⁻ᵀ.
    tau
        (n, 3, 3) Kirchhoff stresses τ = J σ.
    sigma
        (n, 3, 3) Cauchy stresses σ = τ / J.
    dp
        (n,) equivalent plastic strain increments (0 for a hyperelastic law).
    state
        The state at the end of the increment (:class:`FiniteStrainState`).
    tangent
        (n, 3, 3, 3, 3) consistent tangent ∂P_ij/∂F_kl; None when not asked for.
    tangent_later
        Where the tangent was not asked for: a function that computes it from this update's own
        arrays (the same values as ``tangent``, without the update again), or None where the
        material gives none (the caller updates again with ``tangent=True``). A Newton iteration
        needs the tangent at every iterate but the last, whose residual alone it evaluates.
        Called as ``tangent_later()`` (a new array) or ``tangent_later(out)``: into ``out``, a
        C-contiguous (n, 3, 3, 3, 3) array (the Gauss-point state's quadrature function), returned.
    """

    P: np.ndarray
    tau: np.ndarray
    sigma: np.ndarray
    dp: np.ndarray
    state: FiniteStrainState
    tangent: np.ndarray | None = None
    tangent_later: Callable[..., np.ndarray] | None = None


@runtime_checkable
class FiniteStrainMaterial(Protocol):
    """A material at n Gauss points in the total Lagrangian finite-strain setting."""

    @property
    def size(self) -> int:
        """The number of Gauss points n."""
        ...

    def initial_state(self) -> FiniteStrainState:
        """The undeformed, unstressed state: F = b_e = I, every internal variable 0."""
        ...

    def update(self, F: np.ndarray, state: FiniteStrainState, tangent: bool = True,
               J: np.ndarray | None = None) -> FiniteStrainResponse:
        """The stresses at the deformation gradients ``F`` (n, 3, 3) from the converged ``state``
        (the return map, for an elastoplastic law), with the consistent tangent ∂P/∂F if ``tangent``.
        ``J`` (n,): det F where the caller has computed it (``numpy.linalg.det`` of the same F, as
        the Gauss-point state's inversion check does), not computed again.

        Raises
        ------
        ValueError
            ``F`` not (n, 3, 3), not finite, or with det F ≤ 0 at some point (named); ``J`` not (n,).
        """
        ...


def checked_deformation_gradients(F: np.ndarray, n: int, J: np.ndarray | None = None
                                  ) -> tuple[np.ndarray, np.ndarray]:
    """(F as floats (n, 3, 3), J = det F (n,)), or a ValueError naming what is wrong: the shape, a
    value that is not finite, a point with J ≤ 0 (an inverted or degenerate material element).
    ``J`` given: the caller's det F (``numpy.linalg.det`` of the same F), checked but not computed
    again."""
    F = np.asarray(F, dtype=float)
    if F.shape != (n, 3, 3):
        raise ValueError(f"F has shape {F.shape}; expected ({n}, 3, 3), one deformation gradient per Gauss point")
    bad = ~np.isfinite(F).all(axis=(1, 2))
    if np.any(bad):
        raise ValueError(f"F is not finite at {np.count_nonzero(bad)} Gauss point(s) (first: {np.flatnonzero(bad)[0]})")
    if J is None:
        J = np.linalg.det(F)
    else:
        J = np.asarray(J, dtype=float)
        if J.shape != (n,):
            raise ValueError(f"J has shape {J.shape}; expected ({n},), det F at every Gauss point")
    inverted = J <= 0.0
    if np.any(inverted):
        k = int(np.argmin(J))
        raise ValueError(f"det F <= 0 at {np.count_nonzero(inverted)} Gauss point(s) (smallest J = {J[k]:.6g} at "
                         f"point {k}): the material is inverted there; a deformation needs J > 0")
    return F, J
