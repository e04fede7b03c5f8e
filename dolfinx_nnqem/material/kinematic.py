"""Kinematic hardening: von Mises yield about back-stresses α_k (linear Prager, nonlinear
Armstrong–Frederick, several of them: Chaboche), combined with isotropic hardening of any shape.

``formulation.md`` §1b: f = q(s − α) − σ_y(p), α = Σ_k α_k (deviatoric), with
α̇_k = (2/3) C_k ε̇_p − γ_k α_k ṗ (γ_k = 0: Prager). Backward Euler gives

    α_k = (α_k,n + (2/3) C_k Δε_p) / (1 + γ_k Δp),

and the return stays radial, in the direction ν of ξ(Δp) = s_tr − Σ_k α_k,n / (1 + γ_k Δp):
Δε_p = √(3/2) Δp ν, with Δp the root of one scalar equation

    r(Δp) = √(3/2) |ξ(Δp)| − (3μ + Σ_k C_k / (1 + γ_k Δp)) Δp − σ_y(p_n + Δp) = 0.

r falls strictly (|α_k| ≤ √(2/3) C_k/γ_k bounds the growth of |ξ|), r(0) = f_tr > 0 and r < 0 at
√(3/2)(|s_tr| + Σ|α_k,n|)/(3μ): Newton's method kept inside that bracket (bisection where a step
leaves it) finds the root, as for isotropic hardening alone (:mod:`.isotropic`).

The consistent tangent (derived here; ``tests/unit/test_kinematic_hardening.py`` checks it against
central differences). With t = s_tr (coordinates), β(Δp) = Σ α_k,n/(1 + γ_k Δp),
β' = −Σ γ_k α_k,n/(1 + γ_k Δp)², and r linearised,

    g = ∂Δp/∂t = √(3/2) ν / D,   D = 3μ + Σ C_k/(1 + γ_k Δp)² + H' + √(3/2) ν·β',
    ∂Δε_p/∂t = √(3/2) [ν ⊗ g + Δp (I − ν⊗ν)(I − β' ⊗ g) / |ξ|],

and C_alg = C − C (∂Δε_p/∂ε) with ∂t/∂ε = 2μ on the deviators. β' ⊗ g makes it unsymmetric
where γ_k α_k,n is not along ν (Armstrong–Frederick); Prager's (γ_k = 0) is symmetric.

:class:`KinematicHardeningPart` holds the bodies' state (the back-stresses "alpha_1", ... as
(3, 3) quadrature functions, checkpointed by name); :class:`KinematicAtPoints` is the pointwise
form for NNEQM2's return-map variant and the independent check.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from dolfinx_nnqem.material.hardening import HardeningAtPoints
from dolfinx_nnqem.material.kinematics import (coordinate_tangent, deviator_coordinates, deviator_tensors,
                                               equivalent_stress, symmetric_coordinates)
from dolfinx_nnqem.material.parameters import HIGH, LOW, check_parameters
from dolfinx_nnqem.material.quadrature_part import QuadraturePart

__all__ = ["BackStress", "KinematicAtPoints", "KinematicHardeningPart", "back_stress_names", "back_stresses",
           "kinematic_plastic_strain", "kinematic_return", "kinematic_tangent"]

MAX_ITERATIONS = 100
"""Newton (or bisection) steps per point."""
_SQRT32 = math.sqrt(1.5)


@dataclass(frozen=True)
class BackStress:
    """One back-stress α_k: α̇_k = (2/3) C ε̇_p − γ α_k ṗ.

    Parameters
    ----------
    C
        Its modulus (Pa), in [1e-20, 1e20].
    gamma
        Its dynamic recovery, in [0, 1e20]: 0 is linear (Prager) hardening; γ > 0 saturates
        (Armstrong–Frederick) at |α_k| = √(2/3) C/γ (uniaxially ±C/γ).
    """

    C: float
    gamma: float = 0.0

    def __post_init__(self):
        check_parameters("BackStress", [
            ("C", self.C, lambda v: LOW <= v <= HIGH, f"a value in [{LOW:g}, {HIGH:g}]"),
            ("gamma", self.gamma, lambda v: 0 <= v <= HIGH,
             f"a value in [0, {HIGH:g}] (0: linear Prager hardening)"),
        ])


def back_stress_names(count: int) -> list[str]:
    """The internal variables' names "alpha_1", ..., "alpha_count"."""
    return [f"alpha_{k + 1}" for k in range(count)]


def _as_back_stresses(value) -> tuple[BackStress, ...]:
    """``kinematic`` as BackStress objects: each a BackStress or a pair (C, gamma)."""
    out = []
    for k, item in enumerate(value):
        if isinstance(item, BackStress):
            out.append(item)
            continue
        try:
            pair = [float(v) for v in item]
        except (TypeError, ValueError):
            raise ValueError(f"kinematic[{k}] = {item!r}: expected a BackStress or a pair [C, gamma]") from None
        if len(pair) != 2:
            raise ValueError(f"kinematic[{k}] = {item!r}: expected a pair [C, gamma]")
        try:
            out.append(BackStress(*pair))
        except ValueError as error:
            raise ValueError(f"kinematic[{k}]: {error}") from None
    return tuple(out)


# -- the return map on coordinates -------------------------------------------------------------------------
def _relative(t: np.ndarray, alpha_n: np.ndarray, gamma: np.ndarray, dp: np.ndarray) -> np.ndarray:
    """ξ(Δp) = t − Σ_k α_k,n / (1 + γ_k Δp) (n, 5)."""
    return t - np.einsum("nk,nka->na", 1.0 / (1.0 + gamma * dp[:, None]), alpha_n)


def kinematic_plastic_strain(t: np.ndarray, alpha_n: np.ndarray, p_n: np.ndarray, mu: np.ndarray, C: np.ndarray,
                             gamma: np.ndarray, law: HardeningAtPoints) -> tuple[np.ndarray, np.ndarray]:
    """(Δε_p (n, 5), Δp (n,)) of the return from trial deviators t (coordinates) with back-stresses
    α_k,n (n, K, 5), moduli C, γ (n, K) and the isotropic law σ_y(p)."""
    xi = _relative(t, alpha_n, gamma, np.zeros(t.shape[0]))
    f_tr = _SQRT32 * np.linalg.norm(xi, axis=1) - law.yield_stress(p_n)
    dp = np.zeros(t.shape[0])
    active = np.flatnonzero(f_tr > 0.0)
    if active.size:
        dp[active] = _multiplier(t[active], alpha_n[active], p_n[active], mu[active], C[active], gamma[active],
                                 law.subset(active), f_tr[active])
    xi = _relative(t, alpha_n, gamma, dp)
    size = np.linalg.norm(xi, axis=1)
    nu = xi / np.where(dp > 0.0, size, 1.0)[:, None]
    return np.where((dp > 0.0)[:, None], _SQRT32 * dp[:, None] * nu, 0.0), dp


def _multiplier(t, alpha_n, p_n, mu, C, gamma, law, f_tr) -> np.ndarray:
    """Δp > 0 with r(Δp) = 0 (the module docstring) at points whose trial state yields."""
    three_mu = 3.0 * mu
    low = np.zeros_like(p_n)
    high = _SQRT32 * (np.linalg.norm(t, axis=1) + np.linalg.norm(alpha_n, axis=2).sum(axis=1)) / three_mu
    x = f_tr / (three_mu + C.sum(axis=1) + law.slope(p_n))  # Prager's Δp with the slope at p_n
    todo = np.ones(x.size, dtype=bool)
    for _ in range(MAX_ITERATIONS):
        recovery = 1.0 + gamma * x[:, None]
        xi = t - np.einsum("nk,nka->na", 1.0 / recovery, alpha_n)
        size = np.linalg.norm(xi, axis=1)
        r = _SQRT32 * size - (three_mu + (C / recovery).sum(axis=1)) * x - law.yield_stress(p_n + x)
        low = np.where(r > 0.0, x, low)
        high = np.where(r < 0.0, x, high)
        nu = xi / np.maximum(size, np.finfo(float).tiny)[:, None]
        slope = (_SQRT32 * np.einsum("na,na->n", nu, np.einsum("nk,nka->na", gamma / recovery**2, alpha_n))
                 - three_mu - (C / recovery**2).sum(axis=1) - law.slope(p_n + x))
        new = x - r / slope
        outside = (new <= low) | (new >= high)
        new = np.where(outside & (r != 0.0), 0.5 * (low + high), new)
        done = (r == 0.0) | (np.abs(new - x) <= 4.0 * np.finfo(float).eps * np.maximum(x, new))
        x = np.where(todo, new, x)
        todo &= ~done
        if not np.any(todo):
            return x
    raise RuntimeError(f"the kinematic-hardening return map's equation for Δp did not converge at "
                       f"{np.count_nonzero(todo)} Gauss points in {MAX_ITERATIONS} steps")


def kinematic_tangent(t: np.ndarray, alpha_n: np.ndarray, p_n: np.ndarray, mu: np.ndarray, C: np.ndarray,
                      gamma: np.ndarray, law: HardeningAtPoints, dp: np.ndarray) -> np.ndarray:
    """∂Δε_p/∂e (n, 5, 5), e the deviatoric strain increment (t = s_n + 2μ e), at the return's Δp
    (the module docstring's formula; 0 where the return is elastic)."""
    plastic = dp > 0.0
    recovery = 1.0 + gamma * dp[:, None]
    xi = t - np.einsum("nk,nka->na", 1.0 / recovery, alpha_n)
    size = np.where(plastic, np.linalg.norm(xi, axis=1), 1.0)
    nu = xi / size[:, None]
    beta_prime = -np.einsum("nk,nka->na", gamma / recovery**2, alpha_n)
    D = (3.0 * mu + (C / recovery**2).sum(axis=1) + law.slope(p_n + dp)
         + _SQRT32 * np.einsum("na,na->n", nu, beta_prime))
    g = _SQRT32 * nu / D[:, None]
    eye = np.eye(5)
    across = eye - np.einsum("na,nb->nab", nu, nu)
    turning = np.einsum("nab,nbc->nac", across, eye - np.einsum("na,nb->nab", beta_prime, g))
    out = _SQRT32 * (np.einsum("na,nb->nab", nu, g) + (dp / size)[:, None, None] * turning)
    out *= (2.0 * mu)[:, None, None]
    out[~plastic] = 0.0
    return out


def back_stresses(alpha_n: np.ndarray, deps_p: np.ndarray, dp: np.ndarray, C: np.ndarray, gamma: np.ndarray
                  ) -> np.ndarray:
    """α_k = (α_k,n + (2/3) C_k Δε_p) / (1 + γ_k Δp) (n, K, 5), all in coordinates."""
    return ((alpha_n + (2.0 / 3.0) * C[:, :, None] * deps_p[:, None, :])
            / (1.0 + gamma * dp[:, None])[:, :, None])


def kinematic_return(sigma_n: np.ndarray, deps: np.ndarray, alpha_n: np.ndarray, p_n: np.ndarray, mu: np.ndarray,
                     lmbda: np.ndarray, C: np.ndarray, gamma: np.ndarray, law: HardeningAtPoints
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(σ, Δp, Δε_p, C_alg) of the return from σ_n (n, 3, 3) for strain increments Δε (n, 3, 3),
    back-stresses α_k,n in coordinates (n, K, 5)."""
    kappa = lmbda + 2.0 * mu / 3.0
    e = symmetric_coordinates(deps)
    t = deviator_coordinates(sigma_n) + 2.0 * mu[:, None] * e[:, :5]
    deps_p, dp = kinematic_plastic_strain(t, alpha_n, p_n, mu, C, gamma, law)
    sigma = sigma_n + symmetric_tensors_of(2.0 * mu[:, None] * (e[:, :5] - deps_p), 3.0 * kappa * e[:, 5])
    M = np.zeros((t.shape[0], 6, 6))
    M[:, :5, :5] = (2.0 * mu)[:, None, None] * (np.eye(5) - kinematic_tangent(t, alpha_n, p_n, mu, C, gamma, law, dp))
    M[:, 5, 5] = 3.0 * kappa
    return sigma, dp, deviator_tensors(deps_p), coordinate_tangent(M)


def symmetric_tensors_of(deviatoric: np.ndarray, volumetric: np.ndarray) -> np.ndarray:
    """The symmetric tensors (n, 3, 3) with deviatoric coordinates (n, 5) and tr T/√3 = ``volumetric``."""
    return deviator_tensors(deviatoric) + (volumetric / math.sqrt(3.0))[:, None, None] * np.eye(3)


# -- the bodies' state -----------------------------------------------------------------------------------------
class KinematicHardeningPart(QuadraturePart):
    """The bodies of von Mises materials with back-stresses (``VonMises(..., kinematic=[...])``).

    Every body of the part has as many back-stresses as the one with most (the missing ones
    have C = γ = 0 and stay 0); each is an internal variable "alpha_k" of shape (3, 3).
    """

    def __init__(self, space, members: Mapping):
        super().__init__(space, members)
        count = max(len(m.kinematic) for m in members.values())
        self.internal_variables = {name: (3, 3) for name in back_stress_names(count)}
        imap = space.W_scalar.dofmap.index_map
        size = imap.size_local + imap.num_ghosts
        law_index = np.zeros(size, dtype=np.int64)
        self.C, self.gamma = np.zeros((size, count)), np.zeros((size, count))
        for k, (tag, material) in enumerate(members.items()):
            pts = space.points_of(space.cells_of(tag))
            law_index[pts] = k
            for j, back in enumerate(material.kinematic):
                self.C[pts, j], self.gamma[pts, j] = back.C, back.gamma
        self.hardening = HardeningAtPoints(law_index, [m.isotropic_law for m in members.values()])
        self.symmetric_tangent = not np.any(self.gamma > 0.0)
        self.mu = self.values_at_local_points(space.mu)
        self.lmbda = self.values_at_local_points(space.lmbda)
        self.E = self.values_at_local_points(space.E)

    def _alpha(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """The back-stresses of ``internal`` as coordinates (m, K, 5)."""
        return np.stack([deviator_coordinates(internal[name]) for name in self.internal_variables], axis=1)

    def pointwise_return_map(self, sigma_n: np.ndarray, deps: np.ndarray, internal: Mapping[str, np.ndarray]
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(σ, Δp, Δε_p, C_alg) of the return with back-stresses at the part's points (:func:`kinematic_return`)."""
        pts = self.points
        return kinematic_return(sigma_n, deps, self._alpha(internal), internal["p"], self.mu[pts], self.lmbda[pts],
                                self.C[pts], self.gamma[pts], self.hardening.subset(pts))

    def updated_internal(self, points: np.ndarray, deps_p: np.ndarray, dp: np.ndarray,
                         internal_n: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The back-stresses α_k at the end of the increment at the local Gauss points ``points``, by
        name, (m, 3, 3) each, from Δε_p (m, 3, 3), Δp (m,) and the converged ``internal_n``
        (:func:`back_stresses`)."""
        alpha = back_stresses(self._alpha(internal_n), deviator_coordinates(deps_p), dp, self.C[points],
                              self.gamma[points])
        return {name: deviator_tensors(alpha[:, k]) for k, name in enumerate(self.internal_variables)}

    def at_points(self, points: np.ndarray) -> KinematicAtPoints:
        """The material at the local Gauss points ``points``: μ, λ, E, the hardening laws, C_k and γ_k there."""
        return KinematicAtPoints(self.mu[points], self.lmbda[points], self.E[points], self.hardening.subset(points),
                                 self.C[points], self.gamma[points], tuple(self.internal_variables))


@dataclass(frozen=True)
class KinematicAtPoints:
    """von Mises with back-stresses at a set of Gauss points: the material's
    :class:`~dolfinx_nnqem.material.interface.PointwiseMaterial` (``internal`` holds "p" and the
    back-stresses by name, (n, 3, 3))."""

    mu: np.ndarray
    lmbda: np.ndarray
    E: np.ndarray
    law: HardeningAtPoints
    C: np.ndarray  #: (n, K)
    gamma: np.ndarray  #: (n, K)
    names: tuple[str, ...]  #: the back-stresses' names

    yield_criterion = "von-mises-kinematic"
    deviatoric_flow = True

    @property
    def stress_unit(self) -> np.ndarray:
        """σ_u = min(σ_y(0), 10⁻² E)."""
        return np.minimum(self.law.yield_stress(np.zeros(self.mu.size)), 1e-2 * self.E)

    @property
    def yields(self) -> np.ndarray:
        """All True: every point of this material can yield."""
        return np.ones(self.mu.size, dtype=bool)

    def back_stress(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """α = Σ_k α_k as coordinates (n, 5)."""
        return sum((deviator_coordinates(internal[name]) for name in self.names), np.zeros((self.mu.size, 5)))

    def _alpha(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        return np.stack([deviator_coordinates(internal[name]) for name in self.names], axis=1)

    def plastic_strain(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(Δε_p (n, 5), Δp (n,)) of the return with back-stresses (:func:`kinematic_plastic_strain`)."""
        return kinematic_plastic_strain(t, self._alpha(internal), internal["p"], self.mu, self.C, self.gamma, self.law)

    def plastic_strain_tangent(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """∂Δε_p/∂e (n, 5, 5) at the return's Δp (:func:`kinematic_tangent`)."""
        _, dp = self.plastic_strain(t, internal)
        return kinematic_tangent(t, self._alpha(internal), internal["p"], self.mu, self.C, self.gamma, self.law, dp)

    def yield_value(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """f = q(s − α) − σ_y(p)."""
        return equivalent_stress(s[:, :5] - self.back_stress(internal)) - self.law.yield_stress(internal["p"])

    def flow_direction(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """N = (3/2)(s − α)/q(s − α) on the deviatoric coordinates (the volumetric one 0), 0 where q = 0."""
        relative = s[:, :5] - self.back_stress(internal)
        q = equivalent_stress(relative)
        N = np.zeros_like(s)
        N[:, :5] = (1.5 / np.where(q > 0.0, q, 1.0))[:, None] * relative * (q > 0.0)[:, None]
        return N

    def flow_direction_of(self, s: np.ndarray, deps_p: np.ndarray, dp: np.ndarray,
                          internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """N = (3/2)(s − α)/q(s − α) (:meth:`flow_direction`): unique wherever q > 0."""
        return self.flow_direction(s, internal)

    def hardening(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """σ_y'(p) + Σ_k C_k: the slope of the yield stress in the back-stresses' frame (Prager's)."""
        return self.law.slope(internal["p"]) + self.C.sum(axis=1)

    def yield_stress(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """σ_y(p) (n,), the isotropic part: the size of the elastic domain around α."""
        return self.law.yield_stress(internal["p"])

    def subset(self, index: slice | np.ndarray) -> KinematicAtPoints:
        """The material at the points ``index`` selects (a slice, a boolean mask or indices)."""
        return KinematicAtPoints(self.mu[index], self.lmbda[index], self.E[index], self.law.subset(index),
                                 self.C[index], self.gamma[index], self.names)

    def gathered(self, gather: Callable[[np.ndarray], np.ndarray]) -> KinematicAtPoints:
        """The material with every per-point array passed through ``gather``."""
        return KinematicAtPoints(gather(self.mu), gather(self.lmbda), gather(self.E), self.law.gathered(gather),
                                 gather(self.C), gather(self.gamma), self.names)


def checked_back_stresses(value: Sequence) -> tuple[BackStress, ...]:
    """``VonMises(kinematic=...)`` as BackStress objects, or a ValueError naming the entry."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise ValueError(f"kinematic = {value!r}: expected a list of back-stresses [[C_1, gamma_1], ...]")
    return _as_back_stresses(value)
