"""Linear elasticity as a material of its own: σ = C : ε, no yield, no internal variable.

The state is the stress alone: σ = σ_n + C : (ε(u) − ε(u_n)) in UFL (so that a body's stress
stays the sum of its increments, like every other material's), the tangent C. NNEQM2 gives its
Gauss points no unknown. ``VonMises(E, nu)`` (σ_y0 = inf) is elastic too, through the von Mises
expressions; this material skips them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import dolfinx.fem as fem
import numpy as np
import ufl

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.material.interface import MaterialPart, ReturnMapValues
from dolfinx_nnqem.material.kinematics import strain
from dolfinx_nnqem.material.parameters import check_parameters, elastic_checks, lame

if TYPE_CHECKING:
    from dolfinx_nnqem.material.state import GaussPointState

__all__ = ["Elastic", "ElasticAtPoints", "ElasticPart"]


@dataclass(frozen=True)
class Elastic:
    """Isotropic linear elasticity.

    Parameters
    ----------
    E
        Young's modulus (Pa), in [1e-20, 1e20].
    nu
        Poisson's ratio, in [−0.999, 0.4999].
    density
        Mass density (kg/m³), in [0, 1e20] (gravity).
    """

    E: float
    nu: float
    density: float = 0.0

    def __post_init__(self):
        check_parameters("Elastic", elastic_checks(self.E, self.nu, self.density))

    @property
    def mu(self) -> float:
        """Shear modulus μ = E / (2(1 + ν))."""
        return lame(self.E, self.nu)[0]

    @property
    def lmbda(self) -> float:
        """Lamé's λ = E ν / ((1 + ν)(1 − 2ν))."""
        return lame(self.E, self.nu)[1]

    part_kind = "elastic"

    def make_part(self, space: GaussPointState, members: Mapping[int | None, Elastic]) -> MaterialPart:
        """The part of the elastic bodies ``members`` ({cell tag: material}) in ``space``."""
        return ElasticPart(space, members)


class ElasticPart:
    """The bodies of :class:`Elastic` materials: σ = σ_n + C : Δε in UFL."""

    internal_variables: Mapping[str, tuple[int, ...]] = {}
    symmetric_tangent = True

    def __init__(self, space: GaussPointState, members: Mapping[int | None, Elastic]):
        self.space = space
        self._sigma: tuple[fem.Function, fem.Expression] | None = None
        self._material_expressions: tuple[fem.Expression, ...] | None = None

    def stress(self, u: fem.Function) -> ufl.core.expr.Expr:
        """UFL: σ = σ_n + C : (ε(u) − ε(u_n))."""
        st = self.space
        return st.sigma_n + st.elastic_stress(strain(u) - strain(st.u_n))

    def tangent(self, u: fem.Function, eps_du: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """UFL: C : ``eps_du`` (the tangent is the elastic stiffness)."""
        return self.space.elastic_stress(eps_du)

    def evaluate(self, u: fem.Function) -> None:
        """Nothing: the forms evaluate the closed form at u."""

    def return_map(self, u: fem.Function) -> ReturnMapValues:
        """σ = σ_n + C : Δε at ``u`` on every local Gauss point, Δp = 0, Δε_p = 0."""
        st = self.space
        if self._sigma is None or self._sigma[0] is not u:
            self._sigma = (u, jit.expression(self.stress(u), st._points))
        f = fem.Function(st.W_tensor)
        compat.interpolate_expression(f, self._sigma[1])
        zeros = np.zeros(st.W_scalar.dofmap.index_map.size_local + st.W_scalar.dofmap.index_map.num_ghosts)
        return ReturnMapValues(f.x.array.reshape(-1, 3, 3), zeros, np.zeros((zeros.size, 3, 3)))

    def trial_dp(self, u: fem.Function) -> np.ndarray:
        """Zeros on every local Gauss point: nothing yields."""
        imap = self.space.W_scalar.dofmap.index_map
        return np.zeros(imap.size_local + imap.num_ghosts)

    def updated_internal(self, points: np.ndarray, deps_p: np.ndarray, dp: np.ndarray,
                         internal_n: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """{}: no internal variable besides p."""
        return {}

    def at_points(self, points: np.ndarray) -> ElasticAtPoints:
        """The material at the owned Gauss points ``points``: μ, λ and E there."""
        st = self.space
        if self._material_expressions is None:
            self._material_expressions = tuple(jit.expression(e, st._points) for e in (st.mu, st.lmbda, st.E))
        return ElasticAtPoints(*(st.owned_at_points(e)[points] for e in self._material_expressions))


@dataclass(frozen=True)
class ElasticAtPoints:
    """Linear elasticity at a set of Gauss points (μ, λ, E per point): nothing yields."""

    mu: np.ndarray
    lmbda: np.ndarray
    E: np.ndarray

    yield_criterion = "none"
    deviatoric_flow = True

    @property
    def stress_unit(self) -> np.ndarray:
        """σ_u = 10⁻² E."""
        return 1e-2 * self.E

    @property
    def yields(self) -> np.ndarray:
        """All False: nothing yields."""
        return np.zeros(self.mu.size, dtype=bool)

    def plastic_strain(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(Δε_p, Δp) = (0, 0) (the shapes of t, (n,)): no plastic strain."""
        return np.zeros_like(t), np.zeros(t.shape[0])

    def plastic_strain_tangent(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """Zeros (n, 5, 5)."""
        return np.zeros((t.shape[0], t.shape[1], t.shape[1]))

    def yield_value(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """−inf: no stress reaches a yield surface."""
        return np.full(s.shape[0], -np.inf)

    def flow_direction(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """Zeros: no flow."""
        return np.zeros_like(s)

    def flow_direction_of(self, s: np.ndarray, deps_p: np.ndarray, dp: np.ndarray,
                          internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """Zeros: no flow."""
        return self.flow_direction(s, internal)

    def hardening(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """Zeros (n,)."""
        return np.zeros(self.mu.size)

    def yield_stress(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """inf (n,): no yield surface."""
        return np.full(self.mu.size, np.inf)

    def subset(self, index: slice | np.ndarray) -> ElasticAtPoints:
        """The material at the points ``index`` selects (a slice, a boolean mask or indices)."""
        return ElasticAtPoints(self.mu[index], self.lmbda[index], self.E[index])

    def gathered(self, gather: Callable[[np.ndarray], np.ndarray]) -> ElasticAtPoints:
        """The material with μ, λ and E passed through ``gather``."""
        return ElasticAtPoints(gather(self.mu), gather(self.lmbda), gather(self.E))
