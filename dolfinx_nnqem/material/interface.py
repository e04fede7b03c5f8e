"""The material interface: what the problem and the solvers use of a bulk material.

Three parts, each a Protocol that :mod:`~dolfinx_nnqem.material.von_mises` implements (checked by
the type checker in :mod:`~dolfinx_nnqem.solvers.conformance` and by ``tests/test_contracts.py``);
a second material implements the same three and no solver changes:

* :class:`Material` — the parameters of one body, as the user gives them;
* :class:`MaterialState` — the material fields and the Gauss-point state of the whole mesh, in UFL
  (the return map at u from the converged state, its consistent tangent, the forms of the
  internal force and of the stiffnesses) and in quadrature functions; the monolithic solver and
  NNEQM1 use the forms, every solver commits through it;
* :class:`PointwisePlasticity` — what NNEQM2 needs besides: the same return map on numpy arrays of
  Gauss-point values, in the orthonormal coordinates of the deviators
  (:data:`~dolfinx_nnqem.material.von_mises.DEVIATORIC_BASIS`): the plastic strain increment of a
  trial deviator and its derivative, and the yield function, so that the plastic strains can be
  unknowns of its nonsmooth system.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["Material", "MaterialState", "PointwisePlasticity"]


@runtime_checkable
class Material(Protocol):
    """A body's material parameters."""

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
    def mu(self) -> float: ...

    @property
    def lmbda(self) -> float: ...


@runtime_checkable
class MaterialState(Protocol):
    """The material fields and Gauss-point state of a mesh (one instance per problem)."""

    W_tensor: Any  #: quadrature space of tensors (the stresses)
    W_scalar: Any  #: quadrature space of scalars
    dx: Any  #: the integration measure whose points are the quadrature spaces'
    sigma_n: Any  #: converged stress
    p_n: Any  #: converged equivalent plastic strain
    dp_n: Any  #: its increment in the last converged increment
    u_n: Any  #: converged displacement
    E: Any
    mu: Any
    lmbda: Any
    sigma_y0: Any
    H: Any

    def return_map(self, u) -> Any:
        """UFL: the update from the converged state for the displacement ``u`` (σ, Δp, Δε_p, ...)."""
        ...

    def return_map_expressions(self, u) -> tuple[Any, Any, Any]:
        """The return map's σ, Δp and Δε_p at ``u``, compiled for the Gauss points (once per ``u``)."""
        ...

    def elastic_stress(self, eps) -> Any:
        """UFL: C : ε."""
        ...

    def internal_force_form(self, u, v) -> Any: ...

    def tangent_form(self, u, du, v) -> Any: ...

    def elastic_stiffness_form(self, du, v) -> Any: ...

    def commit(self, u) -> None:
        """Accept ``u``: the state from the return map."""
        ...

    def commit_values(self, u, sigma: np.ndarray, dp: np.ndarray) -> None:
        """Accept ``u`` with Gauss-point values a solver computed itself."""
        ...

    def values_at_points(self, expr) -> np.ndarray: ...

    def count_plastic_points(self) -> int: ...

    def count_trial_plastic_points(self, u) -> int: ...

    def num_gauss_points(self) -> int: ...

    def plastic_strain_of(self, u, sigma: np.ndarray) -> np.ndarray: ...

    def at_points(self) -> PointwisePlasticity:
        """The material at this rank's owned Gauss points (:class:`PointwisePlasticity`)."""
        ...


@runtime_checkable
class PointwisePlasticity(Protocol):
    """The return map on numpy arrays of this rank's Gauss points (what NNEQM2 needs).

    Deviators are (n, 5) coordinates in the orthonormal deviatoric basis; ``t`` is a trial
    deviator s_n + 2μ dev Δε, ``p`` the equivalent plastic strain.
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
        """σ_u (n,), the unit of the yield rows."""
        ...

    @property
    def yields(self) -> np.ndarray:
        """(n,) bool: the points of a material that can yield."""
        ...

    def plastic_strain(self, t: np.ndarray, p_n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Δε_p (n, 5), Δp (n,)) of the return map from p_n for the trial deviators t."""
        ...

    def plastic_strain_tangent(self, t: np.ndarray, p_n: np.ndarray) -> np.ndarray:
        """∂Δε_p/∂e (n, 5, 5), e the deviatoric strain increment (t = s_n + 2μ e)."""
        ...

    def yield_value(self, s: np.ndarray, p: np.ndarray) -> np.ndarray:
        """f (n,) of the stress deviators s at the equivalent plastic strain p (≤ 0: admissible)."""
        ...

    def flow_direction(self, s: np.ndarray) -> np.ndarray:
        """N = ∂f/∂σ (n, 5) at the stress deviators s (0 where s = 0); the flow is Δε_p = Δp N."""
        ...

    def hardening(self) -> np.ndarray:
        """dσ_y/dp (n,): the slope of the yield stress in p (H for linear hardening)."""
        ...

    def subset(self, index: slice) -> PointwisePlasticity:
        """The material at the points ``index`` selects (a check goes through the points in chunks)."""
        ...
