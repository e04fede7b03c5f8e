"""The compressible Neo-Hookean hyperelastic material (``formulation.md`` §1c).

Strain energy per reference volume, with C = FᵀF, I₁ = tr C, J = det F:

    ψ(F) = μ/2 (I₁ − 3) − μ ln J + λ/2 (ln J)²,

μ, λ the Lamé constants of the linearisation (E, ν as for every material). Then

    P = ∂ψ/∂F = μ (F − F⁻ᵀ) + λ ln J F⁻ᵀ,   σ = (μ (b − I) + λ ln J I) / J  (b = FFᵀ),
    ∂P_ij/∂F_kl = μ δ_ik δ_jl + (μ − λ ln J) F⁻¹_li F⁻¹_jk + λ F⁻¹_ji F⁻¹_lk.

It has no internal variables: the state only records F (and b_e = b, for a uniform interface).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import NoReturn

import numpy as np

from dolfinx_nnqem.material.finite_strain.interface import (FiniteStrainResponse, FiniteStrainState,
                                                            checked_deformation_gradients)
from dolfinx_nnqem.material.parameters import check_parameters, elastic_checks, lame

__all__ = ["NeoHooke", "NeoHookeAtPoints"]


@dataclass(frozen=True)
class NeoHooke:
    """Compressible Neo-Hookean elasticity, ψ = μ/2 (I₁ − 3) − μ ln J + λ/2 (ln J)² (the module docstring).

    Parameters
    ----------
    E
        Young's modulus of the linearisation (Pa), in [1e-20, 1e20].
    nu
        Poisson's ratio of the linearisation, in [−0.999, 0.4999].
    density
        Mass density in the reference configuration (kg/m³), in [0, 1e20].
    """

    E: float
    nu: float
    density: float = 0.0

    def __post_init__(self):
        check_parameters("NeoHooke", elastic_checks(self.E, self.nu, self.density))

    @property
    def mu(self) -> float:
        """Shear modulus μ = E / (2(1 + ν))."""
        return lame(self.E, self.nu)[0]

    @property
    def lmbda(self) -> float:
        """Lamé's λ = E ν / ((1 + ν)(1 − 2ν))."""
        return lame(self.E, self.nu)[1]

    @property
    def part_kind(self) -> str:
        """"neo-hooke": a kind of its own (the :class:`~dolfinx_nnqem.material.interface.Material` Protocol)."""
        return "neo-hooke"

    def make_part(self, space: object, members: Mapping[int | None, object]) -> NoReturn:
        """Refused: a Neo-Hookean body has no small-strain state (its law is written in F).

        Raises
        ------
        ValueError
            Always: the problem must be built with ``kinematics = "finite"``.
        """
        raise ValueError(f"NeoHooke (E = {self.E:g}, nu = {self.nu:g}) is a finite-strain hyperelastic law "
                         "(its stress is written in F = I + grad u): it needs kinematics = 'finite'; at small strain "
                         "use Elastic, its linearisation")

    def at_points(self, n: int) -> NeoHookeAtPoints:
        """The material at n Gauss points."""
        return NeoHookeAtPoints(np.full(n, self.mu), np.full(n, self.lmbda))


def neo_hooke_tangent(F_inv: np.ndarray, log_J: np.ndarray, mu: np.ndarray, lmbda: np.ndarray) -> np.ndarray:
    """∂P_ij/∂F_kl (n, 3, 3, 3, 3) of the module docstring."""
    eye = np.eye(3)
    c = (mu - lmbda * log_J)[:, None, None, None, None]
    return (mu[:, None, None, None, None] * np.einsum("ik,jl->ijkl", eye, eye)[None]
            + c * np.einsum("nli,njk->nijkl", F_inv, F_inv)
            + lmbda[:, None, None, None, None] * np.einsum("nji,nlk->nijkl", F_inv, F_inv))


@dataclass(frozen=True)
class NeoHookeAtPoints:
    """The Neo-Hookean material at n Gauss points (μ, λ per point): a
    :class:`~dolfinx_nnqem.material.finite_strain.interface.FiniteStrainMaterial`."""

    mu: np.ndarray
    lmbda: np.ndarray

    @property
    def size(self) -> int:
        """The number of Gauss points n."""
        return int(self.mu.size)

    def initial_state(self) -> FiniteStrainState:
        """F = b_e = I, p = 0."""
        eye = np.broadcast_to(np.eye(3), (self.size, 3, 3)).copy()
        return FiniteStrainState(eye, eye.copy(), {"p": np.zeros(self.size)})

    def update(self, F: np.ndarray, state: FiniteStrainState, tangent: bool = True,
               J: np.ndarray | None = None) -> FiniteStrainResponse:
        """P, τ, σ at the deformation gradients ``F`` (n, 3, 3) (``state`` only carried: the law has no
        history), with ∂P/∂F if ``tangent``; ``J`` = det F if the caller has it."""
        F, J = checked_deformation_gradients(F, self.size, J)
        F_inv = np.linalg.inv(F)
        F_inv_T = np.swapaxes(F_inv, 1, 2)
        log_J = np.log(J)
        mu, lmbda = self.mu[:, None, None], self.lmbda[:, None, None]
        P = mu * (F - F_inv_T) + lmbda * log_J[:, None, None] * F_inv_T
        b = F @ np.swapaxes(F, 1, 2)
        tau = mu * (b - np.eye(3)) + lmbda * log_J[:, None, None] * np.eye(3)
        new_state = FiniteStrainState(F.copy(), b, {"p": np.asarray(state.internal["p"]).copy()})
        def later(out: np.ndarray | None = None) -> np.ndarray:
            A = neo_hooke_tangent(F_inv, log_J, self.mu, self.lmbda)
            if out is None:
                return A
            out[...] = A
            return out

        return FiniteStrainResponse(P=P, tau=tau, sigma=tau / J[:, None, None], dp=np.zeros(self.size),
                                    state=new_state, tangent=later() if tangent else None,
                                    tangent_later=None if tangent else later)
