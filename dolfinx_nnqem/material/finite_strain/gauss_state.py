"""The Gauss-point state of a mesh at finite strain: the total Lagrangian forms (issue 41).

``formulation.md`` §1c. The displacement u is measured from the reference configuration and
F = I + ∇u. At every Gauss point the state of the last converged increment is (F_n, b_e,n, the
internal variables: p and, for kinematic hardening, spatial back-stresses), stored in quadrature
functions. :meth:`FiniteStrainGaussState.evaluate` interpolates F at the Gauss points with a
compiled expression, calls each body's
:class:`~dolfinx_nnqem.material.finite_strain.interface.FiniteStrainMaterial` (the logarithmic-strain
route of every small-strain material, or Neo-Hooke) on arrays, and stores the first
Piola–Kirchhoff stress P and the consistent tangent A = ∂P/∂F in quadrature functions which the
forms read, on the reference configuration:

    F_int[v] = ∫ P_q : ∇v dX,     K_t[du, v] = ∫ (A_q : ∇du) : ∇v dX   (unsymmetric in general).

``sigma_n`` holds the Cauchy stress σ = τ/J of the converged state (what the outputs show).

A trial iterate that inverts the material somewhere (det F ≤ 0 at a Gauss point: no stress
exists there) gets a P that is not finite at those points: the Newton iteration's residual is then
not finite, which its line search rejects (a shorter step) or which fails the increment (a cut
back); a commit at such an iterate is refused.

What NNEQM2 needs of a state (the small-strain pointwise material, its plastic strains from
stresses, a commit of a solver's own values) has no meaning here and raises
:class:`SmallStrainOnly`, naming the method.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import basix.ufl
import dolfinx.fem as fem
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.material.finite_strain import NeoHooke, finite_strain_material
from dolfinx_nnqem.material.finite_strain.hencky import HenckyAtPoints
from dolfinx_nnqem.material.finite_strain.interface import FiniteStrainMaterial, FiniteStrainState
from dolfinx_nnqem.material.finite_strain.neo_hooke import NeoHookeAtPoints
from dolfinx_nnqem.material.finite_strain.spectral import eigen, tensor_function
from dolfinx_nnqem.material.gauss_fields import GaussPointFields
from dolfinx_nnqem.material.interface import GaussPointValues, PointwiseMaterial
from dolfinx_nnqem.material.kinematics import symmetric_coordinates
from dolfinx_nnqem.material.state import materials_by_tag

__all__ = ["FiniteStrainBody", "FiniteStrainGaussState", "HyperelasticLaw", "LogarithmicLaw", "SmallStrainOnly",
           "finite_strain_state"]


class SmallStrainOnly(TypeError):
    """A method of the small-strain state that has no meaning at finite strain (NNEQM2's needs)."""


@dataclass(frozen=True)
class LogarithmicLaw:
    """One body's values at its owned Gauss points in the logarithmic space (the Hencky route), for
    the independent check: the relations of the small-strain law with σ ← τ, σ_n ← 0, Δε ← ε^tr."""

    trial_strain: np.ndarray  #: (m, 3, 3) ε^tr = ½ ln(f b_e,n fᵀ), f = F F_n⁻¹, from the F given
    tau: np.ndarray  #: (m, 3, 3) the update's Kirchhoff stress
    dp: np.ndarray  #: (m,) its Δp
    plastic_strain: np.ndarray  #: (m, 3, 3) Δε_p = ε^tr − ½ ln b_e, b_e the update's
    internal: dict[str, np.ndarray]  #: the internal variables after the increment
    material: PointwiseMaterial  #: the small-strain return map the route runs, at these points


@dataclass(frozen=True)
class HyperelasticLaw:
    """One Neo-Hookean body's values at its owned Gauss points, for the independent check."""

    F: np.ndarray  #: (m, 3, 3) the deformation gradients given
    tau: np.ndarray  #: (m, 3, 3) the update's Kirchhoff stress
    dp: np.ndarray  #: (m,) its Δp (0)
    mu: np.ndarray  #: (m,)
    lmbda: np.ndarray  #: (m,)


def _log(A: np.ndarray) -> np.ndarray:
    """ln A of symmetric positive definite tensors (m, 3, 3)."""
    lam, Q = eigen(A)
    return tensor_function(Q, np.log(lam))


@dataclass
class FiniteStrainBody:
    """One body's share of the state: its local Gauss points and its material there."""

    tag: int | None  #: the cell tag (None: every cell)
    points: np.ndarray  #: its local Gauss points (owned and ghost), indices into the quadrature spaces
    material: FiniteStrainMaterial  #: at those points, in that order
    #: the same points as a slice where they are consecutive (the quadrature functions' rows written in
    #: place), else ``points``
    rows: slice | np.ndarray


def point_rows(points: np.ndarray) -> slice | np.ndarray:
    """``points`` (sorted, distinct) as a slice where they are consecutive, else themselves."""
    if points.size and int(points[-1]) - int(points[0]) + 1 == points.size:
        return slice(int(points[0]), int(points[-1]) + 1)
    return points


def finite_strain_state(V: fem.FunctionSpace, materials, cell_tags=None,
                        quadrature_degree: int = 2) -> FiniteStrainGaussState:
    """The finite-strain Gauss-point state of the mesh of ``V`` for one material or ``{cell_tag: material}``."""
    return FiniteStrainGaussState(V, materials, cell_tags, quadrature_degree)


class FiniteStrainGaussState(GaussPointFields):
    """Material fields and finite-strain Gauss-point state of a mesh made of one or more bodies.

    Parameters
    ----------
    V
        Vector Lagrange space of the displacement.
    materials
        One material or ``{cell_tag: material}``: ``VonMises`` (any isotropic hardening,
        back-stresses), ``DruckerPrager`` and ``Elastic`` by the logarithmic strain, ``NeoHooke``.
    cell_tags
        Cell tags naming the bodies; required when ``materials`` is a dict.
    quadrature_degree
        Degree of the Gauss rule used by the forms and the state.
    """

    def __init__(self, V: fem.FunctionSpace, materials, cell_tags=None, quadrature_degree: int = 2):
        super().__init__(V, materials_by_tag(materials, cell_tags, V.mesh), cell_tags, quadrature_degree)
        mesh = V.mesh
        W_A = fem.functionspace(mesh, basix.ufl.quadrature_element(
            mesh.topology.cell_name(), value_shape=(3, 3, 3, 3), degree=quadrature_degree))
        self.bodies = [self._body(tag, material) for tag, material in self.materials.items()]
        self.sigma_n = fem.Function(self.W_tensor, name="sigma")  # converged Cauchy stress
        self.p_n = fem.Function(self.W_scalar, name="p")
        self.dp_n = fem.Function(self.W_scalar, name="dp")
        self.u_n = fem.Function(V, name="u_converged")
        self.F_n = fem.Function(self.W_tensor, name="F")  # converged deformation gradient
        self.b_e_n = fem.Function(self.W_tensor, name="b_e")  # converged elastic left Cauchy–Green tensor
        names = sorted({name for body in self.bodies for name in getattr(body.material, "back_stress_names", ())})
        self._others = {name: fem.Function(self.W_tensor, name=name) for name in names}
        self.P_q = fem.Function(self.W_tensor, name="P_q")  # P at the last u evaluated
        self.A_q = fem.Function(W_A, name="A_q")  # ∂P/∂F there
        self.sigma_q = fem.Function(self.W_tensor, name="sigma_q")  # Cauchy stress there
        self.tau_q = fem.Function(self.W_tensor, name="tau_q")  # Kirchhoff stress there
        self.dp_q = fem.Function(self.W_scalar, name="dp_q")
        n_local = self.p_n.x.array.size
        self._trial = {"F": np.zeros((n_local, 3, 3)), "b_e": np.zeros((n_local, 3, 3)), "p": np.zeros(n_local),
                       **{name: np.zeros((n_local, 3, 3)) for name in self._others}}
        self._inverted = np.zeros(n_local, dtype=bool)  # det F ≤ 0 (or F not finite) at the last u evaluated
        self._gradient: tuple[fem.Function, fem.Expression, fem.Function] | None = None
        self._evaluated: tuple[fem.Function, np.ndarray, int] | None = None
        #: per body, what computes the tangent the last update left out (empty: A_q is at that update)
        self._tangent_later: list[tuple[FiniteStrainBody, Callable[..., np.ndarray] | None, np.ndarray, np.ndarray,
                                        FiniteStrainState]] = []
        self.reset()

    def _body(self, tag: int | None, material) -> FiniteStrainBody:
        points = self.points_of(self.cells_of(tag))
        return FiniteStrainBody(tag, points, finite_strain_material(material, points.size), point_rows(points))

    # -- set-up -------------------------------------------------------------------------------------------
    def parameters_changed(self) -> None:
        """Fill E, ν and the density again from :attr:`materials` and make each body's material at
        its points again (a parameter study)."""
        self.fill_cellwise({"E": self.E, "nu": self.nu, "density": self.density})
        self.bodies = [self._body(tag, material) for tag, material in self.materials.items()]
        self._evaluated = None
        self.parameters_version += 1

    def reset(self) -> None:
        """Back to the undeformed, unstressed state: F_n = b_e,n = I, σ_n, p_n, Δp_n, u_n, back-stresses 0."""
        for f in (self.sigma_n, self.p_n, self.dp_n, self.u_n, *self._others.values()):
            f.x.array[:] = 0.0
        for f in (self.F_n, self.b_e_n):
            f.x.array.reshape(-1, 3, 3)[:] = np.eye(3)
        self._evaluated = None
        self.version += 1

    @property
    def symmetric_tangent(self) -> bool:
        """∂P/∂F is symmetric (∂P_ij/∂F_kl = ∂P_kl/∂F_ij) for a hyperelastic law (Neo-Hooke, Hencky
        elasticity); not for the exponential map's plastic update: False where a body can yield."""
        return all(isinstance(m, NeoHooke) or getattr(m, "part_kind", "") == "elastic"
                   for m in self.materials.values())

    @property
    def internal_variables(self) -> dict[str, fem.Function]:
        """Every converged internal variable by name, "p" first."""
        return {"p": self.p_n, **self._others}

    # -- the forms ----------------------------------------------------------------------------------------
    def internal_force_form(self, u: fem.Function, v: ufl.Argument) -> ufl.Form:
        """F_int(u)[v] = ∫ P_q : ∇v dX (reference configuration)."""
        return ufl.inner(self.P_q, ufl.grad(v)) * self.dx

    def tangent_form(self, u: fem.Function, du: ufl.core.expr.Expr, v: ufl.Argument) -> ufl.Form:
        """K_t(u)[du, v] = ∫ (A_q : ∇du) : ∇v dX, A_q = ∂P/∂F at the last ``u`` evaluated."""
        i, j, k, l = ufl.indices(4)
        return ufl.inner(ufl.as_tensor(self.A_q[i, j, k, l] * ufl.grad(du)[k, l], (i, j)), ufl.grad(v)) * self.dx

    def deformation_gradients(self, u: fem.Function) -> np.ndarray:
        """F = I + ∇u at every local Gauss point (N, 3, 3) (the expression compiled once per u)."""
        if self._gradient is None or self._gradient[0] is not u:
            expression = jit.expression(ufl.Identity(3) + ufl.grad(u), self._points)
            self._gradient = (u, expression, fem.Function(self.W_tensor))
        _, expression, values = self._gradient
        compat.interpolate_expression(values, expression)
        return values.x.array.reshape(-1, 3, 3).copy()

    def evaluate(self, u: fem.Function, tangent: bool = True) -> None:
        """P_q, σ_q, τ_q, Δp_q and the trial state at ``u`` from the converged state, and A_q unless
        ``tangent`` is False (the internal force alone: a Newton iteration's last residual needs no
        tangent). Nothing is done twice: at the same u and converged state only a tangent left out
        is computed, from the update's own arrays. P_q is NaN where det F ≤ 0."""
        if not self._evaluated_at(u):
            self._update(u, tangent)
        if tangent and self._tangent_later:
            self._complete_tangent()

    def _evaluated_at(self, u: fem.Function) -> bool:
        """The quadrature data are at ``u`` (the same function, values and converged state)."""
        if self._evaluated is None:
            return False
        u_then, array, version = self._evaluated
        return u_then is u and version == self.version and np.array_equal(array, u.x.array)

    def _update(self, u: fem.Function, tangent: bool) -> None:
        """Every body's update at ``u`` into the quadrature data, and A_q if ``tangent`` (else the means
        to compute it later, :meth:`_complete_tangent`). det F is computed once a point: the inversion
        check's J is the one the materials take."""
        F = self.deformation_gradients(u)
        F_n = self.F_n.x.array.reshape(-1, 3, 3)
        J = np.linalg.det(np.where(np.isfinite(F), F, 1.0))
        self._inverted = ~(np.isfinite(F).all(axis=(1, 2)) & (J > 0.0))
        self._tangent_later = []
        for body in self.bodies:
            rows = body.rows
            bad = self._inverted[rows]
            F_body, J_body = F[rows], J[rows]
            if np.any(bad):  # an inverted point has no stress: the update runs at the converged F there, and P is NaN
                F_body = np.where(bad[:, None, None], F_n[rows], F_body)
                J_body = np.where(bad, np.linalg.det(F_n[rows]), J_body)
            converged = self._converged(body.points)
            response = body.material.update(F_body, converged, tangent=False, J=J_body)
            self._tangent_later.append((body, response.tangent_later, F_body, J_body, converged))
            P = np.where(bad[:, None, None], np.nan, response.P) if np.any(bad) else response.P
            self.P_q.x.array.reshape(-1, 9)[rows] = P.reshape(-1, 9)
            self.sigma_q.x.array.reshape(-1, 9)[rows] = response.sigma.reshape(-1, 9)
            self.tau_q.x.array.reshape(-1, 9)[rows] = response.tau.reshape(-1, 9)
            self.dp_q.x.array[rows] = response.dp
            new = response.state
            self._trial["F"][rows], self._trial["b_e"][rows] = new.F, new.b_e
            for name, value in new.internal.items():
                self._trial[name][rows] = value
        self._evaluated = (u, u.x.array.copy(), self.version)
        if tangent:
            self._complete_tangent()

    def _complete_tangent(self) -> None:
        """A_q of the last update, which left it out: each body's tangent from its update's arrays (written
        into A_q's array where the body's points are consecutive), or by the update again where its
        material keeps none."""
        A_q = self.A_q.x.array.reshape(-1, 3, 3, 3, 3)
        for body, later, F_body, J_body, converged in self._tangent_later:
            if later is not None and isinstance(body.rows, slice):
                later(A_q[body.rows])
                continue
            A = later() if later is not None else body.material.update(F_body, converged, tangent=True,
                                                                       J=J_body).tangent
            assert A is not None
            A_q[body.rows] = A
        self._tangent_later = []

    def _converged(self, points: np.ndarray) -> FiniteStrainState:
        """The converged state (F_n, b_e,n, internal variables) at the local Gauss points ``points`` (copies)."""
        return FiniteStrainState(self.F_n.x.array.reshape(-1, 3, 3)[points],
                                 self.b_e_n.x.array.reshape(-1, 3, 3)[points], self.local_internal(points))

    # -- the return map's values ----------------------------------------------------------------------------
    def num_inverted_points(self, u: fem.Function) -> int:
        """Number of Gauss points (over all ranks) where det F(u) ≤ 0 (collective)."""
        self.evaluate(u, tangent=False)
        n = self.num_owned_points()
        return self.mesh.comm.allreduce(int(np.count_nonzero(self._inverted[:n])), op=MPI.SUM)

    def trial_values(self, u: fem.Function) -> dict[str, np.ndarray]:
        """The update's values at ``u`` at the owned Gauss points (copies): "F", "b_e", "tau",
        "sigma", "dp" and the internal variables after the increment ("p", back-stresses)."""
        self.evaluate(u, tangent=False)
        n = self.num_owned_points()
        out = {name: value[:n].copy() for name, value in self._trial.items()}
        out.update(tau=self.tau_q.x.array[:9 * n].reshape(n, 3, 3).copy(),
                   sigma=self.sigma_q.x.array[:9 * n].reshape(n, 3, 3).copy(), dp=self.dp_q.x.array[:n].copy())
        return out

    def return_map_values(self, u: fem.Function) -> GaussPointValues:
        """The update's values at ``u`` at this rank's owned Gauss points: the Cauchy stress, Δp and the
        internal variables after the increment (no small-strain Δε_p: ``deps_p`` is None)."""
        values = self.trial_values(u)
        internal = {name: values[name] for name in self.internal_variables}
        return GaussPointValues(u.x.array.copy(), values["sigma"], values["dp"], None, "backward-euler", internal)

    def count_trial_plastic_points(self, u: fem.Function) -> int:
        """Number of Gauss points (over all ranks) where the update at ``u`` is plastic."""
        self.evaluate(u, tangent=False)
        n = self.num_owned_points()
        return self.mesh.comm.allreduce(int(np.count_nonzero(self.dp_q.x.array[:n] > 0.0)), op=MPI.SUM)

    def law_values(self, u: fem.Function, F: np.ndarray) -> list[LogarithmicLaw | HyperelasticLaw]:
        """Per body (in the order of :attr:`bodies`, the same on every rank), the update's values at
        ``u`` at the owned Gauss points with the deformation gradients ``F`` (n, 3, 3, owned points, J > 0)
        computed by the caller: what the independent check compares."""
        values = self.trial_values(u)
        n = self.num_owned_points()
        F_n = self.F_n.x.array[:9 * n].reshape(n, 3, 3)
        b_n = self.b_e_n.x.array[:9 * n].reshape(n, 3, 3)
        out: list[LogarithmicLaw | HyperelasticLaw] = []
        for body in self.bodies:
            mine = body.points < n
            pts = body.points[mine]
            material = body.material
            if isinstance(material, NeoHookeAtPoints):
                out.append(HyperelasticLaw(F[pts], values["tau"][pts], values["dp"][pts], material.mu[mine],
                                           material.lmbda[mine]))
                continue
            assert isinstance(material, HenckyAtPoints)  # (finite_strain_material makes one of the two)
            f = F[pts] @ np.linalg.inv(F_n[pts])
            eps_tr = 0.5 * _log(f @ b_n[pts] @ np.swapaxes(f, 1, 2))
            out.append(LogarithmicLaw(eps_tr, values["tau"][pts], values["dp"][pts],
                                      eps_tr - 0.5 * _log(values["b_e"][pts]),
                                      {name: values[name][pts] for name in self.internal_variables},
                                      material.pointwise.subset(mine)))
        return out

    # -- commit ---------------------------------------------------------------------------------------------
    def commit(self, u: fem.Function) -> None:
        """Accept ``u`` as converged: F_n, b_e,n, the internal variables, σ_n (Cauchy), Δp_n, p_n and
        u_n from the update at ``u`` (collective).

        Raises
        ------
        ValueError
            det F ≤ 0 at some Gauss point (on every rank alike).
        """
        inverted = self.num_inverted_points(u)
        if inverted:
            raise ValueError(f"commit: det F <= 0 at {inverted} Gauss point(s): an inverted material state "
                             "cannot be accepted")
        self.F_n.x.array[:] = self._trial["F"].reshape(-1)
        self.b_e_n.x.array[:] = self._trial["b_e"].reshape(-1)
        self.p_n.x.array[:] = self._trial["p"]
        for name, f in self._others.items():
            f.x.array[:] = self._trial[name].reshape(-1)
        self.sigma_n.x.array[:] = self.sigma_q.x.array
        self.dp_n.x.array[:] = self.dp_q.x.array
        self.u_n.x.array[:] = u.x.array
        for f in (self.F_n, self.b_e_n, self.sigma_n, self.p_n, self.dp_n, self.u_n, *self._others.values()):
            f.x.scatter_forward()
        self.version += 1

    def commit_values(self, u: fem.Function, values: GaussPointValues) -> None:
        """Accept ``u`` with ``values`` that are this state's own update at ``u`` (:meth:`return_map_values`,
        which the stepping hands back): the same as :meth:`commit`.

        Raises
        ------
        SmallStrainOnly
            Other values: a solver's own Gauss-point values are small-strain stresses and plastic
            strains (NNEQM2), which have no meaning here.
        """
        self.evaluate(u, tangent=False)
        n = self.num_owned_points()
        own = (np.array_equal(values.u, u.x.array)
               and np.array_equal(np.asarray(values.sigma).reshape(-1), self.sigma_q.x.array[:9 * n])
               and np.array_equal(np.asarray(values.dp).reshape(-1), self.dp_q.x.array[:n]))
        if not self.mesh.comm.allreduce(int(own), op=MPI.MIN):
            raise SmallStrainOnly("commit_values: these Gauss-point values are not the finite-strain update's at u "
                                  "(a solver's own small-strain stresses and plastic strains, NNEQM2's); with "
                                  "kinematics = 'finite' the state is committed from the update at u")
        self.commit(u)

    # -- internal variables ----------------------------------------------------------------------------------
    def local_internal(self, points: np.ndarray) -> dict[str, np.ndarray]:
        """The converged internal variables at the local Gauss points ``points``, by name ("p" first)."""
        out = {"p": self.p_n.x.array[points]}  # (copies: ``points`` is an index array)
        for name, f in self._others.items():
            out[name] = f.x.array.reshape(-1, 3, 3)[points]
        return out

    def internal_at_points(self, values: GaussPointValues | None = None) -> dict[str, np.ndarray]:
        """The internal variables at the owned Gauss points: converged, or those ``values`` carry
        (:meth:`return_map_values` gives them)."""
        n = self.num_owned_points()
        if values is None:
            return self.local_internal(np.arange(n))
        if values.internal is None:
            raise ValueError("the Gauss-point values carry no internal variables; at finite strain "
                             "return_map_values gives them")
        return {name: np.asarray(values.internal[name]) for name in self.internal_variables}

    # -- small strain only ------------------------------------------------------------------------------------
    def at_points(self) -> PointwiseMaterial:
        """Refused: the small-strain pointwise material (NNEQM2's Gauss-point rows)."""
        raise SmallStrainOnly("at_points: the small-strain pointwise material (NNEQM2's Gauss-point yield rows in "
                              "σ and ε) has no meaning with kinematics = 'finite'; the bodies' finite-strain "
                              "materials are FiniteStrainGaussState.bodies")

    def plastic_strain_of(self, u: fem.Function, sigma: np.ndarray) -> np.ndarray:
        """Refused: Δε_p from stresses by the small-strain elasticity."""
        raise SmallStrainOnly("plastic_strain_of: Δε_p = dev Δε − dev Δσ/(2μ) is a small-strain relation; with "
                              "kinematics = 'finite' the plastic flow is in b_e (the logarithmic strain)")

    # -- checkpoints --------------------------------------------------------------------------------------------
    def _stored(self) -> dict[str, fem.Function]:
        return {"u_n": self.u_n, "sigma_n": self.sigma_n, "p_n": self.p_n, "dp_n": self.dp_n, "F_n": self.F_n,
                "b_e_n": self.b_e_n, **{f"internal_{name}": f for name, f in self._others.items()}}

    def checkpoint_arrays(self) -> dict[str, np.ndarray]:
        """The converged state as named local arrays (owned and ghost entries)."""
        return {name: f.x.array for name, f in self._stored().items()}

    def restore_arrays(self, arrays: Mapping[str, np.ndarray]) -> None:
        """Restore :meth:`checkpoint_arrays` (the same mesh and partition)."""
        for name, f in self._stored().items():
            if name not in arrays:
                raise ValueError(f"restore_arrays: no array {name!r} (the checkpoint is of another material or "
                                 "of small-strain kinematics)")
            f.x.array[:] = arrays[name]
        self.version += 1

    # -- outputs ----------------------------------------------------------------------------------------------
    def kirchhoff_stress(self) -> np.ndarray:
        """τ_n = J_n σ_n at every local Gauss point (N, 3, 3)."""
        J = np.linalg.det(self.F_n.x.array.reshape(-1, 3, 3))
        return J[:, None, None] * self.sigma_n.x.array.reshape(-1, 3, 3)

    def yield_function_values(self) -> np.ndarray:
        """f/σ_y of the Kirchhoff stress τ_n at the converged state at every local Gauss point (the
        logarithmic route's yield function; −1 where nothing can yield: Neo-Hooke, elastic bodies)."""
        tau = symmetric_coordinates(self.kirchhoff_stress())
        ratio = np.full(tau.shape[0], -1.0)
        for body in self.bodies:
            if not isinstance(body.material, HenckyAtPoints):
                continue
            pw = body.material.pointwise
            internal = self.local_internal(body.points)
            f, size = pw.yield_value(tau[body.points], internal), pw.yield_stress(internal)
            ok = pw.yields & np.isfinite(size) & (size > 0.0)
            ratio[body.points[ok]] = f[ok] / size[ok]
        return ratio
