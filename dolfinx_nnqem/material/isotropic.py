"""von Mises plasticity with isotropic hardening of any shape σ_y(p): the return map on arrays.

``formulation.md`` §1b: from the trial state σ_tr = σ_n + C:Δε, q_tr = q(σ_tr), the return is
radial and solves one scalar equation for Δp,

    r(Δp) = q_tr − 3μ Δp − σ_y(p_n + Δp) = 0,

by Newton's method started at the linear-hardening Δp = f_tr / (3μ + H'(p_n)) and kept inside the
bracket [0, f_tr/(3μ)] (σ_y never falls, so r(0) = f_tr > 0 ≥ r(f_tr/(3μ)); a step that leaves it
is replaced by bisection). For a table, Newton lands on the root within the segment that holds
it after a few steps (r is linear there). The consistent tangent is §1's with H replaced by
H' = σ_y'(p_n + Δp) (a table's kink: the slope of the segment that holds p_n + Δp).

The bodies of this kind share one :class:`IsotropicHardeningPart` (a
:class:`~dolfinx_nnqem.material.quadrature_part.QuadraturePart`); its pointwise form
:class:`IsotropicAtPoints` serves NNEQM2 and the independent check.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from dolfinx_nnqem.material.hardening import HardeningAtPoints
from dolfinx_nnqem.material.kinematics import deviator, elastic_stress, equivalent_stress
from dolfinx_nnqem.material.quadrature_part import QuadraturePart

__all__ = ["IsotropicAtPoints", "IsotropicHardeningPart", "consistent_tangent", "isotropic_return",
           "plastic_multiplier", "radial_tangent"]

MAX_ITERATIONS = 100
"""Newton (or bisection) steps per point; a smooth law needs 3-6, a table at most a few per segment."""
_SQRT32 = math.sqrt(1.5)
_I = np.eye(3)
_II = np.einsum("ij,kl->ijkl", _I, _I)
_I_SYM = 0.5 * (np.einsum("ik,jl->ijkl", _I, _I) + np.einsum("il,jk->ijkl", _I, _I))
_I_DEV = _I_SYM - _II / 3.0


def plastic_multiplier(q_tr: np.ndarray, p_n: np.ndarray, mu: np.ndarray, hardening: HardeningAtPoints
                       ) -> np.ndarray:
    """Δp ≥ 0 (n,) with q_tr − 3μ Δp = σ_y(p_n + Δp) where the trial state yields, 0 elsewhere."""
    f_tr = q_tr - hardening.yield_stress(p_n)
    dp = np.zeros_like(q_tr)
    active = np.flatnonzero(f_tr > 0.0)
    if active.size == 0:
        return dp
    law = hardening.subset(active)
    q, p, three_mu, f = q_tr[active], p_n[active], 3.0 * mu[active], f_tr[active]
    low, high = np.zeros_like(q), f / three_mu
    x = f / (three_mu + law.slope(p))  # the linear-hardening Δp with the slope at p_n
    todo = np.ones(q.size, dtype=bool)
    for _ in range(MAX_ITERATIONS):
        r = q - three_mu * x - law.yield_stress(p + x)
        low = np.where(r > 0.0, x, low)
        high = np.where(r < 0.0, x, high)
        step = r / (three_mu + law.slope(p + x))
        new = x + step
        outside = (new <= low) | (new >= high)
        new = np.where(outside & (r != 0.0), 0.5 * (low + high), new)
        done = (r == 0.0) | (np.abs(new - x) <= 4.0 * np.finfo(float).eps * np.maximum(x, new))
        x = np.where(todo, new, x)
        todo &= ~done
        if not np.any(todo):
            break
    else:
        raise RuntimeError(f"the return map's equation for Δp did not converge at {np.count_nonzero(todo)} Gauss "
                           f"points in {MAX_ITERATIONS} steps")
    dp[active] = x
    return dp


def radial_tangent(t: np.ndarray, mu: np.ndarray, dp: np.ndarray, slope: np.ndarray) -> np.ndarray:
    """∂Δε_p/∂e (n, 5, 5) of a radial return (trial deviators t, coordinates) with Δp and the
    hardening slope H' where it ends, e the deviatoric strain increment (t = s_n + 2μ e).

    With n̂ = t/|t|: 2μ √(3/2) [√(3/2)/(3μ + H') n̂⊗n̂ + Δp/|t| (I − n̂⊗n̂)] where the return is
    plastic, 0 elsewhere. C − 2μ·2μ of it on the deviators is the consistent tangent C_alg
    (``formulation.md`` §1, H replaced by H' for a hardening law of another shape, §1b).
    """
    plastic = dp > 0.0
    size = np.linalg.norm(t, axis=1)
    n_hat = t / np.where(plastic, size, 1.0)[:, None]
    nn = np.einsum("ja,jb->jab", n_hat, n_hat)
    radial = (_SQRT32 / (3.0 * mu + slope))[:, None, None] * nn
    turning = (dp / np.where(plastic, size, 1.0))[:, None, None] * (np.eye(5) - nn)
    out = (2.0 * mu * _SQRT32)[:, None, None] * (radial + turning)
    out[~plastic] = 0.0
    return out


def consistent_tangent(mu: np.ndarray, lmbda: np.ndarray, s_tr: np.ndarray, q_tr: np.ndarray, dp: np.ndarray,
                       slope: np.ndarray) -> np.ndarray:
    """C_alg (n, 3, 3, 3, 3) = κ I⊗I + 2μ θ1 I_dev − 2μ θ2 n⊗n (``formulation.md`` §1, H → H')."""
    plastic = dp > 0.0
    q_safe = np.where(plastic, q_tr, 1.0)
    kappa = lmbda + 2.0 * mu / 3.0
    theta1 = 1.0 - 3.0 * mu * dp / q_safe
    theta2 = np.where(plastic, 3.0 * mu / (3.0 * mu + slope) - 3.0 * mu * dp / q_safe, 0.0)
    n = s_tr / (math.sqrt(2.0 / 3.0) * q_safe)[:, None, None]
    return (kappa[:, None, None, None, None] * _II + (2.0 * mu * theta1)[:, None, None, None, None] * _I_DEV
            - (2.0 * mu * theta2)[:, None, None, None, None] * np.einsum("nij,nkl->nijkl", n, n))


def isotropic_return(sigma_n: np.ndarray, deps: np.ndarray, p_n: np.ndarray, mu: np.ndarray, lmbda: np.ndarray,
                     hardening: HardeningAtPoints) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The radial return of the module docstring at n points: (σ, Δp, Δε_p, C_alg)."""
    sigma_tr = sigma_n + elastic_stress(deps, lmbda, mu)
    s_tr = deviator(sigma_tr)
    q_tr = np.sqrt(1.5 * np.einsum("nij,nij->n", s_tr, s_tr))
    dp = plastic_multiplier(q_tr, p_n, mu, hardening)
    q_safe = np.where(dp > 0.0, q_tr, 1.0)
    sigma = sigma_tr - (3.0 * mu * dp / q_safe)[:, None, None] * s_tr
    deps_p = (1.5 * dp / q_safe)[:, None, None] * s_tr
    C = consistent_tangent(mu, lmbda, s_tr, q_tr, dp, hardening.slope(p_n + dp))
    return sigma, dp, deps_p, C


class IsotropicHardeningPart(QuadraturePart):
    """The bodies of von Mises materials with a hardening law of any shape (``VonMises(hardening=...)``).

    Parameters
    ----------
    space
        The mesh-wide state.
    members
        ``{cell tag: VonMises}`` with their ``hardening`` laws (tag None: every cell).
    """

    def __init__(self, space, members: Mapping):
        super().__init__(space, members)
        laws = [m.hardening for m in members.values()]
        imap = space.W_scalar.dofmap.index_map
        law_index = np.zeros(imap.size_local + imap.num_ghosts, dtype=np.int64)
        for k, tag in enumerate(members):
            law_index[space.points_of(space.cells_of(tag))] = k
        self.hardening = HardeningAtPoints(law_index, laws)  # at every local point (only the part's used)
        self.mu = self.values_at_local_points(space.mu)
        self.lmbda = self.values_at_local_points(space.lmbda)
        self.E = self.values_at_local_points(space.E)

    def pointwise_return_map(self, sigma_n: np.ndarray, deps: np.ndarray, internal: Mapping[str, np.ndarray]
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(σ, Δp, Δε_p, C_alg) of the radial return at the part's points (:func:`isotropic_return`)."""
        pts = self.points
        return isotropic_return(sigma_n, deps, internal["p"], self.mu[pts], self.lmbda[pts],
                                self.hardening.subset(pts))

    def at_points(self, points: np.ndarray) -> IsotropicAtPoints:
        """The material at the local Gauss points ``points``: μ, λ, E and the hardening laws there."""
        return IsotropicAtPoints(self.mu[points], self.lmbda[points], self.E[points], self.hardening.subset(points))


@dataclass(frozen=True)
class IsotropicAtPoints:
    """von Mises with isotropic hardening of any shape at a set of Gauss points: the material's
    :class:`~dolfinx_nnqem.material.interface.PointwiseMaterial` (trial deviators t and stresses
    s as coordinates, ``internal["p"]`` the equivalent plastic strain)."""

    mu: np.ndarray
    lmbda: np.ndarray
    E: np.ndarray
    law: HardeningAtPoints

    yield_criterion = "von-mises"
    deviatoric_flow = True

    @property
    def stress_unit(self) -> np.ndarray:
        """σ_u = min(σ_y(0), 10⁻² E)."""
        return np.minimum(self.law.yield_stress(np.zeros(self.mu.size)), 1e-2 * self.E)

    @property
    def yields(self) -> np.ndarray:
        """All True: every point of this material can yield."""
        return np.ones(self.mu.size, dtype=bool)

    def plastic_strain(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Δε_p = Δp (3/2) t / q(t) with Δp of :func:`plastic_multiplier`."""
        q = equivalent_stress(t)
        dp = plastic_multiplier(q, internal["p"], self.mu, self.law)
        q_safe = np.where(dp > 0.0, q, 1.0)
        return (1.5 * dp / q_safe)[:, None] * t, dp

    def plastic_strain_tangent(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """∂Δε_p/∂e (n, 5, 5) of the radial return, with the slope H'(p_n + Δp) (:func:`radial_tangent`)."""
        _, dp = self.plastic_strain(t, internal)
        return radial_tangent(t, self.mu, dp, self.law.slope(internal["p"] + dp))

    def yield_value(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """f = q(s) − σ_y(p) (n,)."""
        return equivalent_stress(s) - self.law.yield_stress(internal["p"])

    def flow_direction(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """N = (3/2) s / q on the deviatoric coordinates (the volumetric one 0), 0 where q = 0."""
        q = equivalent_stress(s)
        N = (1.5 / np.where(q > 0.0, q, 1.0))[:, None] * s * (q > 0.0)[:, None]
        N[:, 5:] = 0.0
        return N

    def flow_direction_of(self, s: np.ndarray, deps_p: np.ndarray, dp: np.ndarray,
                          internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """N = (3/2) s / q (:meth:`flow_direction`): unique wherever q > 0."""
        return self.flow_direction(s, internal)

    def hardening(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """H'(p) = dσ_y/dp (n,)."""
        return self.law.slope(internal["p"])

    def yield_stress(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """σ_y(p) (n,)."""
        return self.law.yield_stress(internal["p"])

    def subset(self, index: slice | np.ndarray) -> IsotropicAtPoints:
        """The material at the points ``index`` selects (a slice, a boolean mask or indices)."""
        return IsotropicAtPoints(self.mu[index], self.lmbda[index], self.E[index], self.law.subset(index))

    def gathered(self, gather: Callable[[np.ndarray], np.ndarray]) -> IsotropicAtPoints:
        """The material with μ, λ, E and the law indices passed through ``gather``."""
        return IsotropicAtPoints(gather(self.mu), gather(self.lmbda), gather(self.E), self.law.gathered(gather))
