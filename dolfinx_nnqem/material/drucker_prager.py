"""Drucker–Prager plasticity: a pressure-dependent cone, associated or non-associated flow, cohesion
hardening of any shape, the return to the smooth cone and to its apex.

``formulation.md`` §1b, de Souza Neto, Perić & Owen (dSN), *Computational Methods for
Plasticity*, §8.3 and boxes 8.8–8.9. With p_h = tr σ/3 (positive in tension), J2 = ½ s:s,

    f = √J2 + η p_h − ξ c(p̄),    flow potential g = √J2 + η̄ p_h,

p̄ the hardening variable (dSN's ε̄_p: ṗ̄ = ξ γ̇; here the material's "p"), c(p̄) the cohesion (a
hardening law of :mod:`.hardening`, linear c₀ + H p̄ by default). η, ξ from the friction angle φ
and η̄ from the dilatancy angle ψ ≤ φ by one of three matches to Mohr–Coulomb
(:func:`cone_coefficients`). From the trial state (s_tr, p_tr) with G = μ and K = κ:

* **the smooth cone**: Δγ solves Φ(Δγ) = √J2_tr − G Δγ + η (p_tr − K η̄ Δγ) − ξ c(p̄_n + ξ Δγ) = 0
  (Φ falls, slope −(G + K η η̄ + ξ² c') ; Newton kept inside [0, f_tr/(G + K η η̄)]), then
  s = (1 − G Δγ/√J2_tr) s_tr, p_h = p_tr − K η̄ Δγ, Δp̄ = ξ Δγ,
  Δε_p = Δγ (s_tr/(2√J2_tr) + (η̄/3) I);
* **the apex**, where that would give √J2_tr − G Δγ ≤ 0: s = 0, and the volumetric plastic
  strain Δε_v solves r(Δε_v) = β c(p̄_n + α Δε_v) − p_tr + K Δε_v = 0, α = ξ/η̄, β = ξ/η;
  p_h = p_tr − K Δε_v, Δp̄ = α Δε_v, Δε_p = s_tr/(2G) + (Δε_v/3) I.

The apex return needs η̄ > 0: without dilatancy the flow has no volumetric part, and a trial
stress beyond the apex in tension has no admissible return (refused with that reason).

Consistent tangents (coordinates of :mod:`.kinematics`, u = the trial deviator's, n = u/|u|,
A = 1/(G + K η η̄ + ξ² c')): on the cone dSN's

    C_alg = 2G(1 − GΔγ/√J2_tr) I_dev + 2G(GΔγ/√J2_tr − G A) n⊗n − √2 G A K (η n⊗I + η̄ I⊗n)
            + K (1 − K η η̄ A) I⊗I,

unsymmetric for η̄ ≠ η; at the apex C_alg = K (1 − K/(K + α β c')) I⊗I (dSN box 8.9). Inside the
apex region the return map is smooth and this is its derivative (s stays 0 whatever the
deviatoric strain; p_h depends on the volumetric strain alone). On the boundary between the two
regions the map has a kink and no derivative: there (√J2_tr − G Δγ = 0 exactly) the apex's is
taken, as dSN do. With perfect plasticity (c' = 0) it is 0: a body all at the apex has no
stiffness left, as it should.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from dolfinx_nnqem.material.hardening import HardeningAtPoints, IsotropicHardening, LinearHardening
from dolfinx_nnqem.material.interface import MaterialPart
from dolfinx_nnqem.material.kinematics import coordinate_tangent, symmetric_coordinates, symmetric_tensors
from dolfinx_nnqem.material.parameters import HIGH, LOW, check_parameters, elastic_checks, lame
from dolfinx_nnqem.material.quadrature_part import QuadraturePart

if TYPE_CHECKING:
    from dolfinx_nnqem.material.state import GaussPointState

__all__ = ["MATCHES", "DruckerPrager", "DruckerPragerAtPoints", "DruckerPragerPart", "cone_coefficients",
           "drucker_prager_plastic_strain", "drucker_prager_return", "drucker_prager_tangent"]

MATCHES = ("outer", "inner", "plane-strain")
"""The cone's matches to Mohr–Coulomb: through its outer edges (triaxial compression), its inner
edges (triaxial extension), and the plane-strain match (the same limit load in plane strain
with associated flow)."""
MAX_ITERATIONS = 100
_SQRT2, _SQRT3 = math.sqrt(2.0), math.sqrt(3.0)


def cone_coefficients(match: str, angle_degrees: float) -> tuple[float, float]:
    """(η, ξ) of the ``match`` for a friction angle (η̄ for a dilatancy angle), ``formulation.md`` §1b."""
    a = math.radians(angle_degrees)
    if match == "outer":
        return 6.0 * math.sin(a) / (_SQRT3 * (3.0 - math.sin(a))), 6.0 * math.cos(a) / (_SQRT3 * (3.0 - math.sin(a)))
    if match == "inner":
        return 6.0 * math.sin(a) / (_SQRT3 * (3.0 + math.sin(a))), 6.0 * math.cos(a) / (_SQRT3 * (3.0 + math.sin(a)))
    if match == "plane-strain":
        root = math.sqrt(9.0 + 12.0 * math.tan(a) ** 2)
        return 3.0 * math.tan(a) / root, 3.0 / root
    raise ValueError(f"DruckerPrager: match = {match!r}: expected one of {list(MATCHES)}")


@dataclass(frozen=True)
class DruckerPrager:
    """Drucker–Prager plasticity matched to Mohr–Coulomb (the module docstring).

    Parameters
    ----------
    E, nu
        Young's modulus (Pa) and Poisson's ratio, as for every material.
    cohesion
        c₀ (Pa), in [1e-20, 1e20]; None with ``hardening`` (which then gives c(p̄)).
    friction_angle
        φ in degrees, 0 ≤ φ < 90 (0: a pressure-independent cylinder, √J2 ≤ ξ c).
    dilatancy_angle
        ψ in degrees, 0 ≤ ψ ≤ φ; None: ψ = φ (associated flow).
    match
        "outer", "inner" or "plane-strain" (:data:`MATCHES`).
    H
        Linear cohesion hardening c = c₀ + H p̄ (Pa), ≥ 0 (0: perfect plasticity).
    density
        Mass density (kg/m³), ≥ 0.
    hardening
        A law c(p̄) of any shape (:class:`~dolfinx_nnqem.material.hardening.VoceHardening`,
        :class:`~dolfinx_nnqem.material.hardening.TabulatedHardening`: its "yield stress" is the
        cohesion) instead of ``cohesion`` and ``H``.
    """

    E: float
    nu: float
    cohesion: float | None
    friction_angle: float
    dilatancy_angle: float | None = None
    match: str = "outer"
    H: float = 0.0
    density: float = 0.0
    hardening: IsotropicHardening | None = None

    def __post_init__(self):
        check_parameters("DruckerPrager", elastic_checks(self.E, self.nu, self.density) + [
            ("friction_angle", self.friction_angle, lambda v: 0.0 <= v < 90.0, "an angle in degrees, 0 <= phi < 90"),
            ("H", self.H, lambda v: 0 <= v <= HIGH,
             f"a value in [0, {HIGH:g}] (H < 0, softening, makes the answer depend on the mesh)"),
        ])
        if self.dilatancy_angle is None:
            object.__setattr__(self, "dilatancy_angle", float(self.friction_angle))
        check_parameters("DruckerPrager", [
            ("dilatancy_angle", self.dilatancy_angle, lambda v: 0.0 <= v <= float(self.friction_angle),
             f"an angle in degrees, 0 <= psi <= friction_angle = {self.friction_angle!r} (a dilatancy above the "
             "friction angle dissipates negative work)")])
        if self.match not in MATCHES:
            raise ValueError(f"DruckerPrager: match = {self.match!r}: expected one of {list(MATCHES)}")
        if self.hardening is None:
            check_parameters("DruckerPrager", [("cohesion", self.cohesion, lambda v: LOW <= v <= HIGH,
                                                f"a cohesion c > 0, in [{LOW:g}, {HIGH:g}]")])
        elif not isinstance(self.hardening, IsotropicHardening):
            raise TypeError(f"DruckerPrager: hardening = {self.hardening!r}: expected a hardening law "
                            "(LinearHardening, VoceHardening, TabulatedHardening) giving the cohesion c(p)")
        elif self.cohesion is not None or self.H != 0.0:
            raise ValueError("DruckerPrager: give either cohesion and H (linear cohesion hardening) or hardening=..., "
                             "not both")

    @property
    def mu(self) -> float:
        """Shear modulus μ = E / (2(1 + ν))."""
        return lame(self.E, self.nu)[0]

    @property
    def lmbda(self) -> float:
        """Lamé's λ = E ν / ((1 + ν)(1 − 2ν))."""
        return lame(self.E, self.nu)[1]

    @property
    def coefficients(self) -> tuple[float, float, float]:
        """(η, ξ, η̄) of the match."""
        eta, xi = cone_coefficients(self.match, float(self.friction_angle))
        eta_bar, _ = cone_coefficients(self.match, float(self.dilatancy_angle))  # type: ignore[arg-type]  # set in __post_init__
        return eta, xi, eta_bar

    @property
    def cohesion_law(self) -> IsotropicHardening:
        """c(p̄) as a hardening law."""
        return LinearHardening(float(self.cohesion), self.H) if self.hardening is None else self.hardening  # type: ignore[arg-type]  # cohesion is given without hardening

    part_kind = "drucker-prager"

    def make_part(self, space: GaussPointState, members: Mapping[int | None, DruckerPrager]) -> MaterialPart:
        """The part of the Drucker–Prager bodies ``members`` ({cell tag: material}) in ``space``."""
        return DruckerPragerPart(space, members)


# -- the return map on coordinates ------------------------------------------------------------------------------
def _bracketed_newton(residual: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], x: np.ndarray,
                      low: np.ndarray, high: np.ndarray, what: str) -> np.ndarray:
    """The root of a strictly monotone residual inside [low, high] (Newton, bisection where a step
    leaves the bracket); ``residual(x)`` gives (r, dr/dx)."""
    rising = residual(low)[0] < 0.0
    todo = np.ones(x.size, dtype=bool)
    for _ in range(MAX_ITERATIONS):
        r, slope = residual(x)
        below = np.where(rising, r < 0.0, r > 0.0)  # the root is above x
        low = np.where(below, x, low)
        high = np.where(~below & (r != 0.0), x, high)
        new = x - r / slope
        outside = (new <= low) | (new >= high)
        new = np.where(outside & (r != 0.0), 0.5 * (low + high), new)
        done = (r == 0.0) | (np.abs(new - x) <= 4.0 * np.finfo(float).eps * np.maximum(np.abs(x), np.abs(new)))
        x = np.where(todo, new, x)
        todo &= ~done
        if not np.any(todo):
            return x
    raise RuntimeError(f"the Drucker–Prager return map's equation for {what} did not converge at "
                       f"{np.count_nonzero(todo)} Gauss points in {MAX_ITERATIONS} steps")


@dataclass(frozen=True)
class _Cone:
    """The cone's parameters at n points."""

    mu: np.ndarray
    kappa: np.ndarray
    eta: np.ndarray
    xi: np.ndarray
    eta_bar: np.ndarray
    law: HardeningAtPoints

    def subset(self, index) -> _Cone:
        return _Cone(self.mu[index], self.kappa[index], self.eta[index], self.xi[index], self.eta_bar[index],
                     self.law.subset(index))


@dataclass(frozen=True)
class _Return:
    """The return at n points: Δγ on the cone, Δε_v at the apex, and which points are there."""

    dgamma: np.ndarray
    deps_v: np.ndarray
    apex: np.ndarray
    dp: np.ndarray


def _return(tau: np.ndarray, p_n: np.ndarray, cone: _Cone) -> _Return:
    """The return (the module docstring) from trial stresses τ (coordinates (n, 6))."""
    n = tau.shape[0]
    sqrt_j2 = np.linalg.norm(tau[:, :5], axis=1) / _SQRT2
    p_tr = tau[:, 5] / _SQRT3
    G, K, eta, xi, eta_bar = cone.mu, cone.kappa, cone.eta, cone.xi, cone.eta_bar
    f_tr = sqrt_j2 + eta * p_tr - xi * cone.law.yield_stress(p_n)
    dgamma, deps_v, apex = np.zeros(n), np.zeros(n), np.zeros(n, dtype=bool)
    active = np.flatnonzero(f_tr > 0.0)
    if active.size:
        c, law = cone.subset(active), cone.law.subset(active)
        q, p, pn = sqrt_j2[active], p_tr[active], p_n[active]
        soft = c.mu + c.kappa * c.eta * c.eta_bar

        def phi(x):
            return (q - c.mu * x + c.eta * (p - c.kappa * c.eta_bar * x) - c.xi * law.yield_stress(pn + c.xi * x),
                    -soft - c.xi**2 * law.slope(pn + c.xi * x))

        high = f_tr[active] / soft
        x = _bracketed_newton(phi, f_tr[active] / (soft + c.xi**2 * law.slope(pn)), np.zeros_like(q), high, "Δγ")
        dgamma[active] = x
        apex[active] = q - c.mu * x <= 0.0
    at_apex = np.flatnonzero(apex)
    if at_apex.size:
        dgamma[at_apex] = 0.0
        deps_v[at_apex] = _apex_return(p_tr[at_apex], p_n[at_apex], cone.subset(at_apex))
    dp = np.where(apex, cone.xi / np.where(apex, cone.eta_bar, 1.0) * deps_v, cone.xi * dgamma)
    return _Return(dgamma, deps_v, apex, dp)


def _apex_return(p_tr: np.ndarray, p_n: np.ndarray, c: _Cone) -> np.ndarray:
    """Δε_v ≥ 0 with β c(p̄_n + α Δε_v) = p_tr − K Δε_v (α = ξ/η̄, β = ξ/η)."""
    if np.any(c.eta_bar <= 0.0):
        raise ValueError(
            f"DruckerPrager: dilatancy_angle = 0 at {np.count_nonzero(c.eta_bar <= 0.0)} Gauss point(s) whose trial "
            "stress lies beyond the cone's apex in hydrostatic tension: without dilatancy the plastic flow has no "
            "volumetric part and no admissible stress exists there; give a dilatancy angle > 0")
    alpha, beta = c.xi / c.eta_bar, c.xi / c.eta

    def r(y):
        return (beta * c.law.yield_stress(p_n + alpha * y) - p_tr + c.kappa * y,
                alpha * beta * c.law.slope(p_n + alpha * y) + c.kappa)

    high = (p_tr - beta * c.law.yield_stress(p_n)) / c.kappa
    return _bracketed_newton(r, high * c.kappa / (c.kappa + alpha * beta * c.law.slope(p_n)),
                             np.zeros_like(p_tr), high, "the apex's volumetric plastic strain")


def drucker_prager_plastic_strain(tau: np.ndarray, p_n: np.ndarray, cone: _Cone) -> tuple[np.ndarray, np.ndarray]:
    """(Δε_p (n, 6), Δp̄ (n,)) of the return from trial stresses τ (coordinates (n, 6))."""
    ret = _return(tau, p_n, cone)
    out = np.zeros_like(tau)
    size = np.linalg.norm(tau[:, :5], axis=1)
    cone_pts = ret.dgamma > 0.0
    out[cone_pts, :5] = (ret.dgamma / (_SQRT2 * np.where(cone_pts, size, 1.0)))[cone_pts, None] * tau[cone_pts, :5]
    out[cone_pts, 5] = ret.dgamma[cone_pts] * cone.eta_bar[cone_pts] / _SQRT3
    out[ret.apex, :5] = tau[ret.apex, :5] / (2.0 * cone.mu[ret.apex, None])
    out[ret.apex, 5] = ret.deps_v[ret.apex] / _SQRT3
    return out, ret.dp


def drucker_prager_tangent(tau: np.ndarray, p_n: np.ndarray, cone: _Cone) -> np.ndarray:
    """R = ∂Δε_p/∂ε (n, 6, 6) in coordinates (τ = σ_n + C ε): the derivative of
    :func:`drucker_prager_plastic_strain` (the apex's inside its region and on its boundary)."""
    ret = _return(tau, p_n, cone)
    G, K, eta, xi, eta_bar = cone.mu, cone.kappa, cone.eta, cone.xi, cone.eta_bar
    R = np.zeros((tau.shape[0], 6, 6))
    on_cone = ret.dgamma > 0.0
    size = np.where(on_cone, np.linalg.norm(tau[:, :5], axis=1), 1.0)
    n_hat = tau[:, :5] / size[:, None]
    A = 1.0 / (G + K * eta * eta_bar + xi**2 * cone.law.slope(p_n + ret.dp))
    g = np.concatenate([(A * _SQRT2 * G)[:, None] * n_hat, (A * K * eta * _SQRT3)[:, None]], axis=1)  # ∂Δγ/∂ε
    nn = np.einsum("na,nb->nab", n_hat, n_hat)
    R[:, :5, :] = np.einsum("na,nb->nab", n_hat / _SQRT2, g)
    R[:, :5, :5] += (ret.dgamma * _SQRT2 * G / size)[:, None, None] * (np.eye(5) - nn)
    R[:, 5, :] = (eta_bar / _SQRT3)[:, None] * g
    R[~on_cone] = 0.0
    apex = ret.apex
    if np.any(apex):
        alpha = xi[apex] / eta_bar[apex]
        slope = cone.law.slope(p_n + ret.dp)[apex]
        R[apex, :5, :5] = np.eye(5)
        R[apex, 5, 5] = K[apex] / (K[apex] + alpha * xi[apex] / eta[apex] * slope)
    return R


def _elastic_coordinates(mu: np.ndarray, kappa: np.ndarray) -> np.ndarray:
    """C in coordinates: diag(2μ × 5, 3κ) (n, 6)."""
    return np.concatenate([np.repeat((2.0 * mu)[:, None], 5, axis=1), (3.0 * kappa)[:, None]], axis=1)


def drucker_prager_return(sigma_n: np.ndarray, deps: np.ndarray, p_n: np.ndarray, cone: _Cone
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(σ, Δp̄, Δε_p, C_alg) at n points from σ_n and the strain increments Δε (n, 3, 3)."""
    C6 = _elastic_coordinates(cone.mu, cone.kappa)
    tau = symmetric_coordinates(sigma_n) + C6 * symmetric_coordinates(deps)
    deps_p, dp = drucker_prager_plastic_strain(tau, p_n, cone)
    sigma = symmetric_tensors(tau - C6 * deps_p)
    R = drucker_prager_tangent(tau, p_n, cone)
    M = C6[:, :, None] * (np.eye(6) - R)
    return sigma, dp, symmetric_tensors(deps_p), coordinate_tangent(M)


# -- the bodies' state ------------------------------------------------------------------------------------------
class DruckerPragerPart(QuadraturePart):
    """The bodies of :class:`DruckerPrager` materials: the return map on arrays at their points."""

    def __init__(self, space, members: Mapping):
        super().__init__(space, members)
        imap = space.W_scalar.dofmap.index_map
        size = imap.size_local + imap.num_ghosts
        law_index = np.zeros(size, dtype=np.int64)
        eta, xi, eta_bar = np.zeros(size), np.ones(size), np.zeros(size)
        for k, (tag, material) in enumerate(members.items()):
            pts = space.points_of(space.cells_of(tag))
            law_index[pts] = k
            eta[pts], xi[pts], eta_bar[pts] = material.coefficients
        self.symmetric_tangent = all(m.dilatancy_angle == m.friction_angle for m in members.values())
        self.mu = self.values_at_local_points(space.mu)
        self.lmbda = self.values_at_local_points(space.lmbda)
        self.E = self.values_at_local_points(space.E)
        self.cone = _Cone(self.mu, self.lmbda + 2.0 * self.mu / 3.0, eta, xi, eta_bar,
                          HardeningAtPoints(law_index, [m.cohesion_law for m in members.values()]))

    def pointwise_return_map(self, sigma_n: np.ndarray, deps: np.ndarray, internal: Mapping[str, np.ndarray]
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(σ, Δp̄, Δε_p, C_alg) of the cone's return at the part's points (:func:`drucker_prager_return`)."""
        return drucker_prager_return(sigma_n, deps, internal["p"], self.cone.subset(self.points))

    def at_points(self, points: np.ndarray) -> DruckerPragerAtPoints:
        """The material at the local Gauss points ``points``: the cone, λ and E there."""
        return DruckerPragerAtPoints(self.cone.subset(points), self.lmbda[points], self.E[points])


@dataclass(frozen=True)
class DruckerPragerAtPoints:
    """Drucker–Prager at a set of Gauss points: the material's
    :class:`~dolfinx_nnqem.material.interface.PointwiseMaterial`. Stresses are full coordinates
    (n, 6) (the volumetric one last): the cone needs the pressure; its plastic strain has a
    volumetric part (``deviatoric_flow`` False: NNEQM2 refuses it)."""

    cone: _Cone
    lmbda: np.ndarray
    E: np.ndarray

    yield_criterion = "drucker-prager"
    deviatoric_flow = False

    @property
    def mu(self) -> np.ndarray:
        """Shear modulus (n,)."""
        return self.cone.mu

    @property
    def stress_unit(self) -> np.ndarray:
        """σ_u = min(ξ c(0), 10⁻² E): the cone's √J2 where p_h = 0."""
        return np.minimum(self.cone.xi * self.cone.law.yield_stress(np.zeros(self.mu.size)), 1e-2 * self.E)

    @property
    def yields(self) -> np.ndarray:
        """All True: every point of this material can yield."""
        return np.ones(self.mu.size, dtype=bool)

    @staticmethod
    def _full(s: np.ndarray, what: str) -> np.ndarray:
        if s.shape[-1] != 6:
            raise ValueError(f"Drucker–Prager's {what} needs full stress coordinates (n, 6) with the pressure "
                             f"tr σ/√3 last; got shape {s.shape} (a deviator alone does not give the pressure)")
        return s

    def plastic_strain(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(Δε_p (n, 6), Δp̄) for trial stresses t = σ_n + C Δε as coordinates (n, 6)."""
        return drucker_prager_plastic_strain(self._full(t, "return map"), internal["p"], self.cone)

    def plastic_strain_tangent(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """∂Δε_p/∂ε (n, 6, 6) for trial stresses t (coordinates (n, 6))."""
        return drucker_prager_tangent(self._full(t, "return map"), internal["p"], self.cone)

    def yield_value(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """f = √J2 + η p_h − ξ c(p̄)."""
        s = self._full(s, "yield function")
        return (np.linalg.norm(s[:, :5], axis=1) / _SQRT2 + self.cone.eta * s[:, 5] / _SQRT3
                - self.cone.xi * self.cone.law.yield_stress(internal["p"]))

    def _at_apex(self, s: np.ndarray) -> np.ndarray:
        return np.linalg.norm(s[:, :5], axis=1) / _SQRT2 <= 1e-8 * self.stress_unit

    def flow_direction(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """N = (s/(2√J2) + (η̄/3) I)/ξ (so that Δε_p = Δp̄ N); at the apex its volumetric part only."""
        s = self._full(s, "flow direction")
        sqrt_j2 = np.linalg.norm(s[:, :5], axis=1) / _SQRT2
        apex = self._at_apex(s)
        N = np.zeros_like(s)
        N[:, :5] = np.where(apex[:, None], 0.0, s[:, :5] / (2.0 * np.where(apex, 1.0, sqrt_j2))[:, None])
        N[:, 5] = self.cone.eta_bar / _SQRT3
        return N / self.cone.xi[:, None]

    def flow_direction_of(self, s: np.ndarray, deps_p: np.ndarray, dp: np.ndarray,
                          internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """At the apex the normal cone of g: deviatoric parts up to |N_dev| = 1/(√2 ξ); the one nearest
        Δε_p/Δp̄ (elsewhere :meth:`flow_direction`)."""
        N = self.flow_direction(s, internal)
        apex = self._at_apex(s) & (dp > 0.0)
        if np.any(apex):
            wanted = deps_p[apex, :5] / dp[apex, None]
            size = np.linalg.norm(wanted, axis=1)
            radius = 1.0 / (_SQRT2 * self.cone.xi[apex])
            N[apex, :5] = wanted * np.minimum(1.0, radius / np.maximum(size, np.finfo(float).tiny))[:, None]
        return N

    def hardening(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """ξ c'(p̄): the slope of the cone's size ξ c."""
        return self.cone.xi * self.cone.law.slope(internal["p"])

    def yield_stress(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """ξ c(p̄): the cone's √J2 where p_h = 0 (the unit of the output f/σ_y)."""
        return self.cone.xi * self.cone.law.yield_stress(internal["p"])

    def subset(self, index: slice | np.ndarray) -> DruckerPragerAtPoints:
        """The material at the points ``index`` selects (a slice, a boolean mask or indices)."""
        return DruckerPragerAtPoints(self.cone.subset(index), self.lmbda[index], self.E[index])

    def gathered(self, gather: Callable[[np.ndarray], np.ndarray]) -> DruckerPragerAtPoints:
        """The material with every per-point array of the cone, λ and E passed through ``gather``."""
        c = self.cone
        return DruckerPragerAtPoints(_Cone(gather(c.mu), gather(c.kappa), gather(c.eta), gather(c.xi),
                                           gather(c.eta_bar), c.law.gathered(gather)), gather(self.lmbda),
                                     gather(self.E))
