"""The material interface: the only door through which the problem, the solvers, the checks and the
writers reach a bulk material.

Four Protocols (checked by the type checker in :mod:`~dolfinx_nnqem.material.conformance` and by
``tests/unit/test_contracts.py``). A material module implements the first, third and fourth; the
second is implemented once, for every material, by :class:`~dolfinx_nnqem.material.state.GaussPointState`,
built by :func:`~dolfinx_nnqem.material.state.material_state` from ``{cell_tag: material}``:

* :class:`Material` — the parameters of one body, as the user gives them, and how the bodies of
  its kind get their Gauss-point state (:meth:`Material.make_part`);
* :class:`MaterialState` — the state of the whole mesh, whatever materials its bodies have: the
  converged stress and named internal variables in quadrature functions, the return map at u
  from the converged state and its consistent tangent as forms (the monolithic solver, NNEQM1),
  the same return map as Gauss-point values (the commit, the independent check), the pointwise
  material (NNEQM2), commit, checkpoint arrays and output fields;
* :class:`MaterialPart` — one material kind's share of that state (the cells of its bodies):
  its stress and consistent tangent in UFL, an ``evaluate`` hook for a return map evaluated on
  arrays at the Gauss points, its return map's values, its pointwise form;
* :class:`PointwiseMaterial` — the return map on numpy arrays of Gauss-point values (what NNEQM2
  and the independent check need): plastic strain increment of a trial deviator and its
  derivative, the yield function, the flow direction, the hardening slope.

Internal variables have names: ``"p"`` (the equivalent plastic strain, scalar; every material
has it, 0 where a material cannot yield) and, per material, others with their value shapes
(``MaterialPart.internal_variables``; e.g. a back-stress ``"alpha_1"`` of shape (3, 3)). Pointwise
methods take them as a mapping name → (n, ...) array. Stresses at points are coordinates in the
orthonormal basis of :mod:`~dolfinx_nnqem.material.kinematics`: (n, 5) deviators, or (n, 6) with
the volumetric coordinate tr σ/√3 last (a pressure-dependent material needs it).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:  # the FEniCS types only name arguments here: no import cost for the interface
    import dolfinx.fem as fem
    import ufl

__all__ = ["GaussPointValues", "Material", "MaterialPart", "MaterialState", "PointwiseMaterial",
           "PointwisePlasticity", "ReturnMapValues"]


@dataclass(frozen=True)
class GaussPointValues:
    """Gauss-point values at the end of an increment: a solver's own, or the return map's at u.

    Attributes
    ----------
    u
        The displacement array (owned and ghost entries) they belong to.
    sigma
        (owned Gauss points, 3, 3) stresses.
    dp
        (owned Gauss points,) equivalent plastic strain increments.
    deps_p
        (owned Gauss points, 3, 3) plastic strain increments (None: not given).
    flow_rule
        How the flow was integrated: "backward-euler" (the return map: the flow direction at the
        end of the increment) or "frozen-directions" (NNEQM2's seed variant: the directions at
        its start). The independent check verifies the values against the rule they claim.
    internal
        The other internal variables at the end of the increment, by name (owned points), for a
        material that has any besides p (None: it has none, or the commit derives them).
    """

    u: np.ndarray
    sigma: np.ndarray
    dp: np.ndarray
    deps_p: np.ndarray | None = None
    flow_rule: str = "backward-euler"
    internal: Mapping[str, np.ndarray] | None = None


@dataclass(frozen=True)
class ReturnMapValues:
    """A part's return map at u on every LOCAL Gauss point of the mesh (owned and ghost, in the
    quadrature spaces' order; only the part's own points are meaningful)."""

    sigma: np.ndarray  #: (N, 3, 3)
    dp: np.ndarray  #: (N,)
    deps_p: np.ndarray  #: (N, 3, 3)


@runtime_checkable
class Material(Protocol):
    """A body's material parameters, and how the bodies of its kind get their Gauss-point state."""

    @property
    def E(self) -> float:
        """Young's modulus."""
        ...

    @property
    def nu(self) -> float:
        """Poisson's ratio."""
        ...

    @property
    def density(self) -> float:
        """Mass density (gravity)."""
        ...

    @property
    def mu(self) -> float:
        """Shear modulus μ = E / (2(1 + ν))."""
        ...

    @property
    def lmbda(self) -> float:
        """Lamé's λ = E ν / ((1 + ν)(1 − 2ν))."""
        ...

    @property
    def part_kind(self) -> str:
        """Bodies whose materials have the same kind share one :class:`MaterialPart` (one set of UFL
        expressions with cell-wise parameters), e.g. "von-mises" or "elastic"."""
        ...

    def make_part(self, space: Any, members: Mapping[int | None, Any]) -> MaterialPart:
        """The part holding the state of the bodies ``members`` ({cell tag: material}, all of this
        kind; tag None: every cell), in the mesh-wide ``space``
        (:class:`~dolfinx_nnqem.material.state.GaussPointState`)."""
        ...


@runtime_checkable
class MaterialPart(Protocol):
    """One material kind's share of the mesh's Gauss-point state."""

    internal_variables: Mapping[str, tuple[int, ...]]
    """Internal variables besides p, by name, with their value shapes (e.g. {"alpha_1": (3, 3)})."""

    symmetric_tangent: bool
    """The consistent tangent is symmetric (False: non-associated flow, Armstrong–Frederick's
    back-stresses): the linear solvers must not assume a symmetric matrix (no Cholesky, no CG)."""

    def stress(self, u: fem.Function) -> ufl.core.expr.Expr:
        """UFL: σ at ``u`` by the return map from the converged state (the internal force reads it)."""
        ...

    def tangent(self, u: fem.Function, eps_du: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """UFL: C_alg : ``eps_du``, the consistent tangent at ``u``."""
        ...

    def evaluate(self, u: fem.Function) -> None:
        """Bring what :meth:`stress` and :meth:`tangent` read to ``u`` (a return map evaluated on
        arrays at the Gauss points); nothing for a return map written in UFL."""
        ...

    def return_map(self, u: fem.Function) -> ReturnMapValues:
        """The return map's σ, Δp and Δε_p at ``u`` on every local Gauss point."""
        ...

    def trial_dp(self, u: fem.Function) -> np.ndarray:
        """Δp of the return map at ``u`` on every local Gauss point (counting the plastic points)."""
        ...

    def at_points(self, points: np.ndarray) -> PointwiseMaterial:
        """The material at the local Gauss points ``points`` (indices into the quadrature spaces)."""
        ...

    def updated_internal(self, points: np.ndarray, deps_p: np.ndarray, dp: np.ndarray,
                         internal_n: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The internal variables besides p at the end of an increment, at the local Gauss points
        ``points``, from its plastic strain Δε_p (m, 3, 3), Δp (m,) and the converged ``internal_n``
        there (by name); {} for a material that has none (the commit calls it)."""
        ...


@runtime_checkable
class MaterialState(Protocol):
    """The material fields and Gauss-point state of a mesh (one instance per problem)."""

    W_tensor: Any  #: quadrature space of tensors (the stresses)
    W_scalar: Any  #: quadrature space of scalars
    dx: Any  #: the integration measure whose points are the quadrature spaces'
    sigma_n: Any  #: converged stress
    p_n: Any  #: converged equivalent plastic strain (0 where a material cannot yield)
    dp_n: Any  #: its increment in the last converged increment
    u_n: Any  #: converged displacement
    E: Any  #: Young's modulus per cell
    mu: Any  #: shear modulus per cell, E / (2(1 + ν)) in UFL
    lmbda: Any  #: Lamé's λ per cell, E ν / ((1 + ν)(1 − 2ν)) in UFL
    density: Any  #: mass density per cell

    @property
    def internal_variables(self) -> Mapping[str, Any]:
        """Every converged internal variable by name ("p" first), as quadrature functions."""
        ...

    @property
    def symmetric_tangent(self) -> bool:
        """Every part's consistent tangent is symmetric."""
        ...

    def evaluate(self, u: fem.Function, tangent: bool = True) -> None:
        """Bring the quadrature data the forms read to ``u``: call before assembling the internal
        force or the tangent at a new iterate (:class:`~dolfinx_nnqem.problem.ContactProblem` does).
        ``tangent`` False: the internal force's data alone are needed (a state may then leave the
        tangent's out until it is asked for at the same ``u``)."""
        ...

    def elastic_stress(self, eps: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """UFL: C : ε."""
        ...

    def internal_force_form(self, u: fem.Function, v: ufl.Argument) -> ufl.Form:
        """UFL: F_int(u)[v] = ∫ σ(u) : ε(v) dx, σ(u) the parts' stresses."""
        ...

    def tangent_form(self, u: fem.Function, du: ufl.core.expr.Expr, v: ufl.Argument) -> ufl.Form:
        """UFL: K_t(u)[du, v] = ∫ (C_alg : ε(du)) : ε(v) dx, the consistent tangent at ``u`` (``du`` a
        trial function, or a function for the tangent's action)."""
        ...

    def elastic_stiffness_form(self, du: ufl.core.expr.Expr, v: ufl.Argument) -> ufl.Form:
        """UFL: K_e[du, v] = ∫ (C : ε(du)) : ε(v) dx."""
        ...

    def return_map_values(self, u: fem.Function) -> GaussPointValues:
        """The return map's values at ``u`` at this rank's owned Gauss points."""
        ...

    def commit(self, u: fem.Function) -> None:
        """Accept ``u``: the state from the return map."""
        ...

    def commit_values(self, u: fem.Function, values: GaussPointValues) -> None:
        """Accept ``u`` with Gauss-point values a solver computed itself."""
        ...

    def internal_at_points(self, values: GaussPointValues | None = None) -> dict[str, np.ndarray]:
        """The internal variables at the owned Gauss points: converged, or after ``values``."""
        ...

    def values_at_points(self, expr: ufl.core.expr.Expr) -> np.ndarray:
        """A scalar UFL expression (e.g. a material field) at this rank's owned Gauss points (n,)."""
        ...

    def owned_at_points(self, compiled: fem.Expression, tensor: bool = False) -> np.ndarray:
        """A compiled expression at this rank's owned Gauss points: (n,), or (n, 3, 3) for a ``tensor``."""
        ...

    def count_plastic_points(self) -> int:
        """Number of Gauss points (over all ranks) with Δp > 0 in the last converged increment."""
        ...

    def count_trial_plastic_points(self, u: fem.Function) -> int:
        """Number of Gauss points (over all ranks) where the return map at ``u`` is plastic."""
        ...

    def num_gauss_points(self) -> int:
        """Number of Gauss points over all ranks."""
        ...

    def plastic_strain_of(self, u: fem.Function, sigma: np.ndarray) -> np.ndarray:
        """Δε_p = dev Δε − dev(σ − σ_n)/(2μ) (n, 3, 3) at the owned Gauss points, for the stresses
        ``sigma`` (n, 3, 3) at ``u`` (Δε = ε(u) − ε(u_n))."""
        ...

    def at_points(self) -> PointwiseMaterial:
        """The material at this rank's owned Gauss points (:class:`PointwiseMaterial`)."""
        ...

    def checkpoint_arrays(self) -> dict[str, np.ndarray]:
        """The converged state as named local arrays (a checkpoint)."""
        ...

    def restore_arrays(self, arrays: Mapping[str, np.ndarray]) -> None:
        """Restore :meth:`checkpoint_arrays`' arrays (the same mesh and partition)."""
        ...

    def back_stress_values(self) -> np.ndarray | None:
        """q(α) of the total back-stress at every local Gauss point; None without back-stresses."""
        ...

    def yield_function_values(self) -> np.ndarray:
        """f/σ_y at the converged state at every local Gauss point (−1 where nothing can yield)."""
        ...


@runtime_checkable
class PointwiseMaterial(Protocol):
    """The return map on numpy arrays of Gauss points (what NNEQM2 and the independent check need).

    ``t`` is a trial deviator s_n + 2μ dev Δε (coordinates, (n, 5)), ``s`` a stress as coordinates
    ((n, 5), or (n, 6) with tr σ/√3 last), ``internal`` the internal variables by name ("p": (n,)).
    """

    @property
    def mu(self) -> np.ndarray:
        """Shear modulus (n,)."""
        ...

    @property
    def lmbda(self) -> np.ndarray:
        """Lamé's λ (n,)."""
        ...

    @property
    def stress_unit(self) -> np.ndarray:
        """σ_u (n,), the unit of the yield rows and of the check."""
        ...

    @property
    def yields(self) -> np.ndarray:
        """(n,) bool: the points of a material that can yield."""
        ...

    @property
    def yield_criterion(self) -> str:
        """"von-mises" (f = q(s) − σ_y(p), N = (3/2) s/q: isotropic hardening of any shape), "none"
        (cannot yield), or a material's own name; "mixed" where the points' criteria differ."""
        ...

    @property
    def deviatoric_flow(self) -> bool:
        """The plastic strain is deviatoric with Δp = √(2/3)|Δε_p| (what NNEQM2's unknowns assume)."""
        ...

    def plastic_strain(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(Δε_p (n, 5), Δp (n,)) of the return map from the converged ``internal`` for trial deviators t."""
        ...

    def plastic_strain_tangent(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """∂Δε_p/∂e (n, 5, 5), e the deviatoric strain increment (t = s_n + 2μ e)."""
        ...

    def yield_value(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """f (n,) of the stresses s with the internal variables ``internal`` (≤ 0: admissible)."""
        ...

    def flow_direction(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """N (the shape of s) at the stresses s (0 where undefined): the flow is Δε_p = Δp N."""
        ...

    def flow_direction_of(self, s: np.ndarray, deps_p: np.ndarray, dp: np.ndarray,
                          internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """The flow direction N at s that the plastic strain ``deps_p`` (coordinates, the shape of s)
        with Δp = ``dp`` is checked against: :meth:`flow_direction` where it is unique; where it is not
        (a cone's apex), the element of the normal cone there nearest Δε_p/Δp."""
        ...

    def hardening(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """dσ_y/dp (n,) at p = ``internal["p"]`` (H for linear hardening)."""
        ...

    def yield_stress(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """The size of the elastic domain in stress units (n,): σ_y(p) for von Mises, inf where
        nothing yields (the unit of the output f/σ_y)."""
        ...

    def subset(self, index: slice | np.ndarray) -> PointwiseMaterial:
        """The material at the points ``index`` selects (a slice, a boolean mask or indices)."""
        ...

    def gathered(self, gather: Callable[[np.ndarray], np.ndarray]) -> PointwiseMaterial:
        """The material with every per-point array passed through ``gather`` (e.g. over the ranks)."""
        ...


PointwisePlasticity = PointwiseMaterial
"""The name of release 0.1."""
