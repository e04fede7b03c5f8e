"""von Mises plasticity with associated flow and isotropic hardening; linear hardening in closed-form UFL.

Formulation (``formulation.md`` §1): from the converged state (σ_n, p_n) and a strain
increment Δε,

    σ_tr = σ_n + C:Δε,  s_tr = dev σ_tr,  q_tr = sqrt(3/2 s_tr:s_tr),
    f_tr = q_tr − σ_y0 − H p_n,  Δp = max(f_tr, 0) / (3μ + H),
    σ = σ_tr − 3μ Δp s_tr / q_tr,  p = p_n + Δp,

and the consistent tangent C_alg = κ I⊗I + 2μ θ1 I_dev − 2μ θ2 n⊗n with n = s_tr/|s_tr|,
θ1 = 1 − 3μΔp/q_tr, θ2 = 3μ/(3μ+H) − 3μΔp/q_tr (θ2 = 0 when elastic).

With linear hardening (:class:`VonMises` without ``hardening``; H = 0 is perfect plasticity)
everything is a closed-form UFL expression of the current displacement ``u`` and the state
(σ_n, p_n, u_n) (:class:`VonMisesPart`), so the forms evaluate the return map exactly at the
Gauss points where the state is stored. A hardening law of another shape (Voce, a table:
:mod:`~dolfinx_nnqem.material.hardening`) needs a scalar Newton iteration per point, which UFL
cannot write: such a material's state is :class:`~dolfinx_nnqem.material.isotropic.IsotropicHardeningPart`,
its return map evaluated on arrays. The same von Mises pieces on numpy arrays of Gauss-point
values (:class:`VonMisesAtPoints`) serve NNEQM2 and the independent check.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import NamedTuple

import dolfinx.fem as fem
import numpy as np
import numpy.typing as npt
import ufl

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.material.hardening import IsotropicHardening, LinearHardening
from dolfinx_nnqem.material.interface import GaussPointValues, MaterialPart, ReturnMapValues
from dolfinx_nnqem.material.isotropic import IsotropicHardeningPart, radial_tangent
from dolfinx_nnqem.material.kinematic import BackStress, KinematicHardeningPart, checked_back_stresses
from dolfinx_nnqem.material.kinematics import (DEVIATORIC_BASIS, deviator_coordinates, deviator_tensors,  # noqa: F401
                                               elastic_stress, equivalent_stress, strain, von_mises_stress)
from dolfinx_nnqem.material.kinematics import equivalent_stress_gradient as flow_direction  # noqa: F401
from dolfinx_nnqem.material.parameters import HIGH, LOW, NU_RANGE, check_parameters, elastic_checks, lame  # noqa: F401
from dolfinx_nnqem.material.state import GaussPointState

PlasticState = GaussPointState
"""The mesh-wide state's name of release 0.1 (it holds every material's state now)."""

__all__ = ["ELASTIC_YIELD_STRESS", "GaussPointValues", "PlasticState", "ReturnMap", "VonMises", "VonMisesAtPoints",
           "VonMisesPart", "can_yield", "radial_return", "radial_tangent", "return_map_plastic_strain", "return_map_tangent",
           "yield_function", "yield_stress_unit"]


@dataclass(frozen=True)
class VonMises:
    """Material parameters: von Mises yield, associated flow, isotropic hardening.

    Parameters
    ----------
    E
        Young's modulus (Pa), in [1e-20, 1e20] (:data:`~dolfinx_nnqem.numerics.ranges.MAX_MAGNITUDE`).
    nu
        Poisson's ratio, in [−0.999, 0.4999] (:data:`~dolfinx_nnqem.material.parameters.NU_RANGE`).
    sigma_y0
        Initial yield stress (Pa), in [1e-20, 1e20]. ``math.inf`` gives a purely elastic material.
    H
        Linear isotropic hardening modulus (Pa), in [0, 1e20] (0: perfect plasticity, for limit loads).
    density
        Mass density (kg/m³), in [0, 1e20]; used by :class:`~dolfinx_nnqem.problem.contact_problem.Gravity`.
    hardening
        A hardening law σ_y(p) of any shape instead of ``sigma_y0`` and ``H``
        (:class:`~dolfinx_nnqem.material.hardening.VoceHardening`,
        :class:`~dolfinx_nnqem.material.hardening.TabulatedHardening`); a
        :class:`~dolfinx_nnqem.material.hardening.LinearHardening` is the same as giving its
        ``sigma_y0`` and ``H`` here.
    kinematic
        Back-stresses (:class:`~dolfinx_nnqem.material.kinematic.BackStress`, or pairs (C, γ)):
        kinematic hardening, linear (Prager, γ = 0) or Armstrong–Frederick (γ > 0), one or more
        (Chaboche), combined with the isotropic law (:mod:`~dolfinx_nnqem.material.kinematic`).
    """

    E: float
    nu: float
    sigma_y0: float = math.inf
    H: float = 0.0
    density: float = 0.0
    hardening: IsotropicHardening | None = None
    kinematic: tuple[BackStress, ...] = ()

    def __post_init__(self):
        check_parameters("VonMises", elastic_checks(self.E, self.nu, self.density) + [
            ("sigma_y0", self.sigma_y0, lambda v: LOW <= v <= HIGH or v == math.inf,
             f"a value in [{LOW:g}, {HIGH:g}], or math.inf for an elastic material"),
            ("H", self.H, lambda v: 0 <= v <= HIGH,
             f"a value in [0, {HIGH:g}] (H < 0, softening, makes the answer depend on the mesh)"),
        ])
        object.__setattr__(self, "kinematic", checked_back_stresses(self.kinematic))
        if self.kinematic and self.hardening is None and self.sigma_y0 == math.inf:
            raise ValueError("VonMises: kinematic hardening needs a yield stress: give sigma_y0 (and H) or "
                             "hardening=..., the isotropic part of the yield stress")
        if self.hardening is None:
            return
        if not isinstance(self.hardening, IsotropicHardening):
            raise TypeError(f"VonMises: hardening = {self.hardening!r}: expected a hardening law "
                            "(LinearHardening, VoceHardening, TabulatedHardening)")
        if self.sigma_y0 != math.inf or self.H != 0.0:
            raise ValueError("VonMises: give either sigma_y0 and H (linear hardening) or hardening=..., not both")
        if isinstance(self.hardening, LinearHardening):  # the closed form, exactly as sigma_y0 and H give it
            object.__setattr__(self, "sigma_y0", self.hardening.sigma_y0)
            object.__setattr__(self, "H", self.hardening.H)
            object.__setattr__(self, "hardening", None)

    @property
    def mu(self) -> float:
        """Shear modulus μ = E / (2(1+ν))."""
        return lame(self.E, self.nu)[0]

    @property
    def lmbda(self) -> float:
        """Lamé's λ = Eν / ((1+ν)(1−2ν))."""
        return lame(self.E, self.nu)[1]

    @property
    def kappa(self) -> float:
        """Bulk modulus κ = λ + 2μ/3."""
        return self.lmbda + 2.0 * self.mu / 3.0

    @property
    def tangent_modulus(self) -> float:
        """Uniaxial elastoplastic modulus E_t = E H / (E + H) (linear hardening)."""
        return self.E * self.H / (self.E + self.H)

    def yield_stress(self, p: npt.ArrayLike) -> np.ndarray | float:
        """σ_y(p): σ_y0 + H p, or the hardening law's (the shape of p; a float for a scalar p)."""
        if self.hardening is not None:
            return self.hardening.yield_stress(np.asarray(p, dtype=float))
        return self.sigma_y0 + self.H * np.asarray(p, dtype=float)

    @property
    def isotropic_law(self) -> IsotropicHardening:
        """σ_y(p) as a hardening law (a :class:`LinearHardening` for ``sigma_y0`` and ``H``)."""
        return LinearHardening(self.sigma_y0, self.H) if self.hardening is None else self.hardening

    @property
    def part_kind(self) -> str:
        """"von-mises" (linear hardening: closed-form UFL), "von-mises-isotropic" (another law) or
        "von-mises-kinematic" (back-stresses)."""
        if self.kinematic:
            return "von-mises-kinematic"
        return "von-mises" if self.hardening is None else "von-mises-isotropic"

    def make_part(self, space: GaussPointState, members: Mapping[int | None, VonMises]) -> MaterialPart:
        """The part of the bodies ``members`` ({cell tag: material}, all of this kind) in ``space``:
        closed-form UFL for linear hardening, a return map on arrays for another law or back-stresses."""
        if self.kinematic:
            return KinematicHardeningPart(space, members)
        if self.hardening is None:
            return VonMisesPart(space, members)
        return IsotropicHardeningPart(space, members)


class ReturnMap(NamedTuple):
    """UFL expressions of one return mapping (all evaluated at quadrature points)."""

    sigma: ufl.core.expr.Expr  #: updated stress σ
    dp: ufl.core.expr.Expr  #: equivalent plastic strain increment Δp ≥ 0
    deps_p: ufl.core.expr.Expr  #: plastic strain increment Δε_p = Δp (3/2) s_tr / q_tr
    f_tr: ufl.core.expr.Expr  #: trial yield function
    q_tr: ufl.core.expr.Expr  #: trial von Mises stress
    s_tr: ufl.core.expr.Expr  #: trial deviatoric stress


ELASTIC_YIELD_STRESS = np.finfo(float).max / 1e10
"""How the yield stress σ_y0 = inf of an elastic material is stored in the cell-wise fields
(finite, so that the UFL expressions of the yield function stay finite)."""


class VonMisesPart:
    """The bodies of linear-hardening von Mises materials: the radial return in closed-form UFL.

    Parameters
    ----------
    space
        The mesh-wide state (σ_n, p_n, u_n, the cell-wise moduli).
    members
        ``{cell tag: VonMises}`` of these bodies (tag None: every cell).
    """

    internal_variables: Mapping[str, tuple[int, ...]] = {}
    symmetric_tangent = True

    def __init__(self, space: GaussPointState, members: Mapping[int | None, VonMises]):
        self.space = space
        self.sigma_y0 = fem.Function(space.Q0, name="sigma_y0")
        self.H = fem.Function(space.Q0, name="H")
        fields = {"sigma_y0": self.sigma_y0, "H": self.H}
        # finite in every cell (an elastic material's "inf" too), so that the expressions stay finite
        _set_cellwise(space, fields, members)
        self._return_map_expressions: tuple[fem.Expression, fem.Expression, fem.Expression] | None = None
        self._return_map_u: fem.Function | None = None
        self._trial_dp: fem.Function | None = None
        self._material_expressions: tuple[fem.Expression, ...] | None = None

    def refill_parameters(self, members: Mapping[int | None, VonMises]) -> None:
        """σ_y0 and H again from ``members`` after their parameters changed (a parameter study,
        :meth:`~dolfinx_nnqem.material.state.GaussPointState.parameters_changed`): the forms read
        these fields, nothing is compiled."""
        _set_cellwise(self.space, {"sigma_y0": self.sigma_y0, "H": self.H}, members)

    # -- the return map in UFL ---------------------------------------------------------------------
    def ufl_return_map(self, u: fem.Function) -> ReturnMap:
        """Radial return from the converged state for the displacement ``u``."""
        st = self.space
        deps = strain(u) - strain(st.u_n)
        sigma_tr = st.sigma_n + st.elastic_stress(deps)
        s_tr = ufl.dev(sigma_tr)
        q_tr = ufl.sqrt(1.5 * ufl.inner(s_tr, s_tr))
        f_tr = q_tr - self.sigma_y0 - self.H * st.p_n
        dp = ufl.max_value(f_tr, 0) / (3 * st.mu + self.H)
        # q_tr > 0 whenever f_tr > 0; the guard only keeps the elastic branch free of 0/0.
        q_safe = ufl.conditional(ufl.gt(f_tr, 0), q_tr, 1.0)
        sigma = sigma_tr - 3 * st.mu * dp / q_safe * s_tr
        deps_p = 1.5 * dp / q_safe * s_tr  # so that σ = σ_tr − 2μ Δε_p
        return ReturnMap(sigma=sigma, dp=dp, deps_p=deps_p, f_tr=f_tr, q_tr=q_tr, s_tr=s_tr)

    def stress(self, u: fem.Function) -> ufl.core.expr.Expr:
        """UFL: σ of the radial return at ``u``."""
        return self.ufl_return_map(u).sigma

    def tangent(self, u: fem.Function, eps_du: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """C_alg : ε(du), the consistent tangent at ``u`` applied to the strain ``eps_du``."""
        rm = self.ufl_return_map(u)
        mu = self.space.mu
        plastic = ufl.gt(rm.f_tr, 0)
        q_safe = ufl.conditional(plastic, rm.q_tr, 1.0)
        theta1 = 1 - 3 * mu * rm.dp / q_safe
        theta2 = ufl.conditional(plastic, 3 * mu / (3 * mu + self.H) - 3 * mu * rm.dp / q_safe, 0.0)
        # n = s_tr / |s_tr| with |s_tr| = sqrt(2/3) q_tr
        n = rm.s_tr / (math.sqrt(2.0 / 3.0) * q_safe)
        return (
            self.space.kappa * ufl.tr(eps_du) * ufl.Identity(3)
            + 2 * mu * theta1 * ufl.dev(eps_du)
            - 2 * mu * theta2 * ufl.inner(n, eps_du) * n
        )

    def evaluate(self, u: fem.Function) -> None:
        """Nothing: the forms evaluate the closed form at u themselves."""

    # -- its values at the Gauss points --------------------------------------------------------------
    def return_map_expressions(self, u: fem.Function) -> tuple[fem.Expression, fem.Expression, fem.Expression]:
        """The radial return's σ, Δp and Δε_p at ``u``, compiled for the Gauss points.

        Compiled once per ``u`` (they refer to it symbolically, and to the state's functions)
        and shared by the commit, the count of plastic points and the solvers' independent
        check, which evaluate the same return map: each compile costs a form signature and a
        kernel load (4-10 ms).
        """
        if self._return_map_expressions is None or u is not self._return_map_u:
            rm = self.ufl_return_map(u)
            points = self.space._points
            self._return_map_u = u
            self._return_map_expressions = (jit.expression(rm.sigma, points), jit.expression(rm.dp, points),
                                            jit.expression(rm.deps_p, points))
        return self._return_map_expressions

    def return_map(self, u: fem.Function) -> ReturnMapValues:
        """The radial return's σ, Δp and Δε_p at ``u`` on every local Gauss point."""
        st = self.space
        e_sigma, e_dp, e_deps = self.return_map_expressions(u)
        values = []
        for expression, space in ((e_sigma, st.W_tensor), (e_dp, st.W_scalar), (e_deps, st.W_tensor)):
            f = fem.Function(space)
            compat.interpolate_expression(f, expression)
            values.append(f.x.array)
        return ReturnMapValues(values[0].reshape(-1, 3, 3), values[1], values[2].reshape(-1, 3, 3))

    def trial_dp(self, u: fem.Function) -> np.ndarray:
        """Δp of the radial return at ``u`` on every local Gauss point."""
        if self._trial_dp is None:
            self._trial_dp = fem.Function(self.space.W_scalar)
        compat.interpolate_expression(self._trial_dp, self.return_map_expressions(u)[1])
        return self._trial_dp.x.array

    def updated_internal(self, points: np.ndarray, deps_p: np.ndarray, dp: np.ndarray,
                         internal_n: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """{}: no internal variable besides p."""
        return {}

    def at_points(self, points: np.ndarray) -> VonMisesAtPoints:
        """The material at the owned Gauss points ``points`` (interpolated at every call, so that a
        caller holds them only while it needs them; the compiled expressions are kept)."""
        st = self.space
        if self._material_expressions is None:
            self._material_expressions = tuple(jit.expression(e, st._points)
                                               for e in (st.mu, st.lmbda, self.sigma_y0, self.H, st.E))
        return VonMisesAtPoints(*(st.owned_at_points(e)[points] for e in self._material_expressions))


def _set_cellwise(space: GaussPointState, fields: Mapping[str, fem.Function], members) -> None:
    """The parts' own cell-wise fields: the members' values, inf as :data:`ELASTIC_YIELD_STRESS`."""
    space.fill_cellwise(fields, default={"sigma_y0": ELASTIC_YIELD_STRESS, "H": 0.0}, tags=list(members))
    for f in fields.values():
        f.x.array[~np.isfinite(f.x.array)] = ELASTIC_YIELD_STRESS


def yield_function(q: np.ndarray, sigma_y0: np.ndarray, H: np.ndarray, p: np.ndarray) -> np.ndarray:
    """f = q − σ_y0 − H p: von Mises with linear isotropic hardening at equivalent plastic strain p."""
    return q - sigma_y0 - H * p


def yield_stress_unit(sigma_y0: np.ndarray, E: np.ndarray) -> np.ndarray:
    """σ_u = min(σ_y0, 10⁻² E): the stress unit of yield-function values (the cap only matters for
    an elastic material, stored with a huge σ_y0)."""
    return np.minimum(sigma_y0, 1e-2 * np.asarray(E))


def can_yield(sigma_y0: np.ndarray) -> np.ndarray:
    """True where ``sigma_y0`` is a real yield stress, False where it stands for an elastic material."""
    return np.asarray(sigma_y0) < ELASTIC_YIELD_STRESS


# -- the same math on numpy arrays of Gauss-point values -------------------------------------------
_SQRT32 = math.sqrt(1.5)


def return_map_plastic_strain(t: np.ndarray, mu: np.ndarray, sigma_y0: np.ndarray, H: np.ndarray,
                              p_n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The radial return of trial deviators t (coordinates, (n, 5)): the plastic strain increment
    Δε_p (coordinates, (n, 5)) and Δp (n,).

    Δp = max(q_tr − σ_y0 − H p_n, 0) / (3μ + H), Δε_p = Δp (3/2) t / q_tr (= Δp N at the returned
    stress, which is parallel to t for von Mises).
    """
    q = equivalent_stress(t)
    dp = np.maximum(yield_function(q, sigma_y0, H, p_n), 0.0) / (3.0 * mu + H)
    q_safe = np.where(dp > 0.0, q, 1.0)
    return (1.5 * dp / q_safe)[:, None] * t, dp


def return_map_tangent(t: np.ndarray, mu: np.ndarray, sigma_y0: np.ndarray, H: np.ndarray,
                       p_n: np.ndarray) -> np.ndarray:
    """∂Δε_p/∂e (n, 5, 5) of :func:`return_map_plastic_strain` for t = s_n + 2μ e, e the deviatoric
    strain increment (coordinates) (:func:`radial_tangent`)."""
    _, dp = return_map_plastic_strain(t, mu, sigma_y0, H, p_n)
    return radial_tangent(t, mu, dp, H)


@dataclass(frozen=True)
class VonMisesAtPoints:
    """Von Mises plasticity with linear hardening at a set of Gauss points, on numpy arrays: the
    material's :class:`~dolfinx_nnqem.material.interface.PointwiseMaterial`. Its fields are the
    (n,) material values μ, λ, σ_y0, H and E at the points (σ_y0 = :data:`ELASTIC_YIELD_STRESS`
    for an elastic material).
    """

    mu: np.ndarray
    lmbda: np.ndarray
    sigma_y0: np.ndarray
    H: np.ndarray
    E: np.ndarray

    yield_criterion = "von-mises"
    deviatoric_flow = True

    @property
    def stress_unit(self) -> np.ndarray:
        """σ_u = min(σ_y0, 10⁻² E) (:func:`yield_stress_unit`)."""
        return yield_stress_unit(self.sigma_y0, self.E)

    @property
    def yields(self) -> np.ndarray:
        """(n,) bool: σ_y0 is a real yield stress (not an elastic material's)."""
        return can_yield(self.sigma_y0)

    def plastic_strain(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(Δε_p (n, 5), Δp (n,)) of the radial return from p_n = ``internal["p"]``
        (:func:`return_map_plastic_strain`)."""
        return return_map_plastic_strain(t, self.mu, self.sigma_y0, self.H, internal["p"])

    def plastic_strain_tangent(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """∂Δε_p/∂e (n, 5, 5) of the radial return (:func:`return_map_tangent`)."""
        return return_map_tangent(t, self.mu, self.sigma_y0, self.H, internal["p"])

    def yield_value(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """f = q(s) − σ_y0 − H p (n,)."""
        return yield_function(equivalent_stress(s), self.sigma_y0, self.H, internal["p"])

    def flow_direction(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """N = (3/2) s / q on the deviatoric coordinates (|N| = √(3/2); the volumetric one 0), 0 where q = 0."""
        q = equivalent_stress(s)
        N = (1.5 / np.where(q > 0.0, q, 1.0))[:, None] * s * (q > 0.0)[:, None]
        N[:, 5:] = 0.0
        return N

    def flow_direction_of(self, s: np.ndarray, deps_p: np.ndarray, dp: np.ndarray,
                          internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """N = (3/2) s / q (:meth:`flow_direction`): unique wherever q > 0."""
        return self.flow_direction(s, internal)

    def hardening(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """H (n,)."""
        return self.H

    def yield_stress(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """σ_y0 + H p (n,), inf where the material is elastic."""
        return np.where(self.yields, self.sigma_y0 + self.H * internal["p"], np.inf)

    def subset(self, index: slice | np.ndarray) -> VonMisesAtPoints:
        """The material at the points ``index`` selects (a slice, a boolean mask or indices)."""
        return VonMisesAtPoints(self.mu[index], self.lmbda[index], self.sigma_y0[index], self.H[index], self.E[index])

    def gathered(self, gather: Callable[[np.ndarray], np.ndarray]) -> VonMisesAtPoints:
        """The material with μ, λ, σ_y0, H and E passed through ``gather``."""
        return VonMisesAtPoints(gather(self.mu), gather(self.lmbda), gather(self.sigma_y0), gather(self.H),
                                gather(self.E))


def radial_return(sigma_n: np.ndarray, deps: np.ndarray, p_n: np.ndarray, lmbda: np.ndarray, mu: np.ndarray,
                  sigma_y0: np.ndarray, H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The return map of :class:`VonMisesPart` on arrays: (σ (n, 3, 3), Δp (n,)).

    σ_tr = σ_n + C:Δε, f_tr = q_tr − σ_y0 − H p_n, Δp = max(f_tr, 0)/(3μ + H),
    σ = σ_tr − 3μ Δp s_tr / q_tr.
    """
    sigma_tr = sigma_n + elastic_stress(deps, lmbda, mu)
    s_tr = sigma_tr - np.trace(sigma_tr, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3.0
    q_tr = np.sqrt(1.5 * np.einsum("nij,nij->n", s_tr, s_tr))
    dp = np.maximum(yield_function(q_tr, sigma_y0, H, p_n), 0.0) / (3.0 * mu + H)
    q_safe = np.where(dp > 0.0, q_tr, 1.0)
    return sigma_tr - (3.0 * mu * dp / q_safe)[:, None, None] * s_tr, dp
