"""von Mises plasticity with associated flow and linear isotropic hardening, in UFL.

Formulation (``formulation.md`` §1): from the converged state (σ_n, p_n) and a strain
increment Δε,

    σ_tr = σ_n + C:Δε,  s_tr = dev σ_tr,  q_tr = sqrt(3/2 s_tr:s_tr),
    f_tr = q_tr − σ_y0 − H p_n,  Δp = max(f_tr, 0) / (3μ + H),
    σ = σ_tr − 3μ Δp s_tr / q_tr,  p = p_n + Δp,

and the consistent tangent C_alg = κ I⊗I + 2μ θ1 I_dev − 2μ θ2 n⊗n with n = s_tr/|s_tr|,
θ1 = 1 − 3μΔp/q_tr, θ2 = 3μ/(3μ+H) − 3μΔp/q_tr (θ2 = 0 when elastic).

Everything is a closed-form UFL expression of the current displacement ``u`` and the state
(σ_n, p_n, u_n). The same von Mises pieces on numpy arrays of Gauss-point values (deviators in a
5-dimensional orthonormal basis, q, the flow direction, the radial return) serve NNEQM2, which
solves for the plastic multipliers of all Gauss points at once; a test checks them against the
UFL forms. The state lives in quadrature spaces (``basix.ufl.quadrature_element``) whose
points are the points of the integration measure ``dx``, so the forms evaluate the return map
exactly at the Gauss points where the state is stored; :meth:`PlasticState.commit` interpolates
the converged expressions into the state with ``dolfinx.fem.Expression``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import basix.ufl
import dolfinx.fem as fem
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.numerics.ranges import MAX_MAGNITUDE as HIGH
from dolfinx_nnqem.numerics.ranges import MIN_MODULUS as LOW


NU_RANGE = (-0.999, 0.4999)
"""Supported Poisson's ratios: κ/μ ≤ 5000 and μ/κ ≤ 4500. Every solver converged on the two-beam
benchmark up to ν = 0.49999 (κ/μ = 5e4) and down to −0.9999; at ν = 0.4999999 the monolithic
solver and NNEQM1 fail at the first increment (issue 31): one decade of margin."""


@dataclass(frozen=True)
class VonMises:
    """Material parameters: von Mises yield, associated flow, linear isotropic hardening.

    Parameters
    ----------
    E
        Young's modulus (Pa), in [1e-20, 1e20] (:data:`~dolfinx_nnqem.numerics.ranges.MAX_MAGNITUDE`).
    nu
        Poisson's ratio, in [−0.999, 0.4999] (:data:`NU_RANGE`).
    sigma_y0
        Initial yield stress (Pa), in [1e-20, 1e20]. ``math.inf`` gives a purely elastic material.
    H
        Linear isotropic hardening modulus (Pa), in [0, 1e20] (0: perfect plasticity).
    density
        Mass density (kg/m³), in [0, 1e20]; used by :class:`~dolfinx_nnqem.problem.contact_problem.Gravity`.
    """

    E: float
    nu: float
    sigma_y0: float = math.inf
    H: float = 0.0
    density: float = 0.0

    def __post_init__(self):
        nu_low, nu_high = NU_RANGE
        checks = [
            ("E", self.E, lambda v: LOW <= v <= HIGH, f"a value in [{LOW:g}, {HIGH:g}] (the supported range)"),
            ("nu", self.nu, lambda v: nu_low <= v <= nu_high,
             f"a value in [{nu_low:g}, {nu_high:g}] (the supported range: beyond it the bulk and shear moduli "
             "differ by more than 5000 times and the solvers lose the digits they need)"),
            ("sigma_y0", self.sigma_y0, lambda v: LOW <= v <= HIGH or v == math.inf,
             f"a value in [{LOW:g}, {HIGH:g}], or math.inf for an elastic material"),
            ("H", self.H, lambda v: 0 <= v <= HIGH, f"a value in [0, {HIGH:g}]"),
            ("density", self.density, lambda v: 0 <= v <= HIGH, f"a value in [0, {HIGH:g}]"),
        ]
        for name, value, ok, expected in checks:
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"VonMises: {name} = {value!r} is not a number") from None
            if not ok(value):
                raise ValueError(f"VonMises: {name} = {value!r} is out of range; expected {expected}")

    @property
    def mu(self) -> float:
        """Shear modulus μ = E / (2(1+ν))."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lmbda(self) -> float:
        """Lamé's λ = Eν / ((1+ν)(1−2ν))."""
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def kappa(self) -> float:
        """Bulk modulus κ = λ + 2μ/3."""
        return self.lmbda + 2.0 * self.mu / 3.0

    @property
    def tangent_modulus(self) -> float:
        """Uniaxial elastoplastic modulus E_t = E H / (E + H)."""
        return self.E * self.H / (self.E + self.H)


def strain(u) -> ufl.core.expr.Expr:
    """Small-strain tensor ε(u) = sym(∇u)."""
    return ufl.sym(ufl.grad(u))


@dataclass(frozen=True)
class GaussPointValues:
    """Gauss-point values a solver computed itself, for :meth:`ContactProblem.commit`.

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
        How the flow was integrated: "backward-euler" (the radial return's normal at the end of the
        increment) or "frozen-directions" (NNEQM2's seed variant: the directions at its start).
        The independent check verifies the values against the rule they claim.
    """

    u: np.ndarray
    sigma: np.ndarray
    dp: np.ndarray
    deps_p: np.ndarray | None = None
    flow_rule: str = "backward-euler"


class ReturnMap(NamedTuple):
    """UFL expressions of one return mapping (all evaluated at quadrature points)."""

    sigma: ufl.core.expr.Expr  #: updated stress σ
    dp: ufl.core.expr.Expr  #: equivalent plastic strain increment Δp ≥ 0
    deps_p: ufl.core.expr.Expr  #: plastic strain increment Δε_p = Δp (3/2) s_tr / q_tr
    f_tr: ufl.core.expr.Expr  #: trial yield function
    q_tr: ufl.core.expr.Expr  #: trial von Mises stress
    s_tr: ufl.core.expr.Expr  #: trial deviatoric stress


class PlasticState:
    """Material fields and Gauss-point state of a mesh made of one or more bodies.

    Parameters
    ----------
    V
        Vector Lagrange space of the displacement.
    materials
        One :class:`VonMises` for the whole mesh, or ``{cell_tag: VonMises}``.
    cell_tags
        Cell tags naming the bodies; required when ``materials`` is a dict.
    quadrature_degree
        Degree of the Gauss rule used by the forms and the state (2 gives 2×2×2 points on
        hexahedra and 4 points on tetrahedra).
    """

    def __init__(self, V: fem.FunctionSpace, materials, cell_tags=None, quadrature_degree: int = 2):
        mesh = V.mesh
        self.V = V
        self.mesh = mesh
        self.quadrature_degree = quadrature_degree
        self.materials = _materials_by_tag(materials, cell_tags, mesh)

        # Piecewise-constant material fields (one value per cell), so that several bodies
        # with different materials share one form.
        Q0 = fem.functionspace(mesh, ("DG", 0))
        self.E = fem.Function(Q0, name="E")
        self.nu = fem.Function(Q0, name="nu")
        self.sigma_y0 = fem.Function(Q0, name="sigma_y0")
        self.H = fem.Function(Q0, name="H")
        self.density = fem.Function(Q0, name="density")
        _fill_cellwise(self, self.materials, cell_tags, Q0)
        E, nu = self.E, self.nu
        self.mu = E / (2 * (1 + nu))
        self.lmbda = E * nu / ((1 + nu) * (1 - 2 * nu))
        self.kappa = self.lmbda + 2 * self.mu / 3

        cell = mesh.topology.cell_name()
        self.dx = ufl.Measure(
            "dx", domain=mesh,
            metadata={"quadrature_degree": quadrature_degree, "quadrature_scheme": "default"},
        )
        W_tensor = fem.functionspace(
            mesh, basix.ufl.quadrature_element(cell, value_shape=(3, 3), degree=quadrature_degree)
        )
        W_scalar = fem.functionspace(
            mesh, basix.ufl.quadrature_element(cell, value_shape=(), degree=quadrature_degree)
        )
        self.W_tensor, self.W_scalar = W_tensor, W_scalar
        self.sigma_n = fem.Function(W_tensor, name="sigma")  # converged stress
        self.p_n = fem.Function(W_scalar, name="p")  # converged equivalent plastic strain
        self.dp_n = fem.Function(W_scalar, name="dp")  # Δp of the last converged increment
        self.u_n = fem.Function(V, name="u_converged")  # converged displacement
        self._points = compat.interpolation_points(W_scalar)
        # compiled at the first commit and count_trial_plastic_points, for the u they are given
        self._return_map_expressions: tuple[fem.Expression, fem.Expression, fem.Expression] | None = None
        self._return_map_u: fem.Function | None = None
        self._commit_u: fem.Function | None = None
        self._trial_dp: fem.Function | None = None
        self._material_expressions: tuple[fem.Expression, ...] | None = None  # compiled at the first at_points

    # -- the return map -------------------------------------------------------------------
    def elastic_stress(self, eps) -> ufl.core.expr.Expr:
        """σ = λ tr(ε) I + 2μ ε."""
        return self.lmbda * ufl.tr(eps) * ufl.Identity(3) + 2 * self.mu * eps

    def return_map(self, u) -> ReturnMap:
        """Radial return from the converged state for the displacement ``u``."""
        deps = strain(u) - strain(self.u_n)
        sigma_tr = self.sigma_n + self.elastic_stress(deps)
        s_tr = ufl.dev(sigma_tr)
        q_tr = ufl.sqrt(1.5 * ufl.inner(s_tr, s_tr))
        f_tr = q_tr - self.sigma_y0 - self.H * self.p_n
        dp = ufl.max_value(f_tr, 0) / (3 * self.mu + self.H)
        # q_tr > 0 whenever f_tr > 0; the guard only keeps the elastic branch free of 0/0.
        q_safe = ufl.conditional(ufl.gt(f_tr, 0), q_tr, 1.0)
        sigma = sigma_tr - 3 * self.mu * dp / q_safe * s_tr
        deps_p = 1.5 * dp / q_safe * s_tr  # so that σ = σ_tr − 2μ Δε_p
        return ReturnMap(sigma=sigma, dp=dp, deps_p=deps_p, f_tr=f_tr, q_tr=q_tr, s_tr=s_tr)

    def tangent(self, u, eps_du) -> ufl.core.expr.Expr:
        """C_alg : ε(du), the consistent tangent at ``u`` applied to the strain ``eps_du``."""
        rm = self.return_map(u)
        mu = self.mu
        plastic = ufl.gt(rm.f_tr, 0)
        q_safe = ufl.conditional(plastic, rm.q_tr, 1.0)
        theta1 = 1 - 3 * mu * rm.dp / q_safe
        theta2 = ufl.conditional(plastic, 3 * mu / (3 * mu + self.H) - 3 * mu * rm.dp / q_safe, 0.0)
        # n = s_tr / |s_tr| with |s_tr| = sqrt(2/3) q_tr
        n = rm.s_tr / (math.sqrt(2.0 / 3.0) * q_safe)
        return (
            self.kappa * ufl.tr(eps_du) * ufl.Identity(3)
            + 2 * mu * theta1 * ufl.dev(eps_du)
            - 2 * mu * theta2 * ufl.inner(n, eps_du) * n
        )

    # -- forms ------------------------------------------------------------------------------
    def internal_force_form(self, u, v) -> ufl.Form:
        """F_int(u)[v] = ∫ σ(u) : ε(v) dx."""
        return ufl.inner(self.return_map(u).sigma, strain(v)) * self.dx

    def tangent_form(self, u, du, v) -> ufl.Form:
        """K_t(u)[du, v] = ∫ (C_alg : ε(du)) : ε(v) dx."""
        return ufl.inner(self.tangent(u, strain(du)), strain(v)) * self.dx

    def elastic_stiffness_form(self, du, v) -> ufl.Form:
        """K_e[du, v] = ∫ (C : ε(du)) : ε(v) dx."""
        return ufl.inner(self.elastic_stress(strain(du)), strain(v)) * self.dx

    # -- state update -----------------------------------------------------------------------
    def return_map_expressions(self, u: fem.Function) -> tuple[fem.Expression, fem.Expression, fem.Expression]:
        """The radial return's σ, Δp and Δε_p at ``u``, compiled for the Gauss points.

        Compiled once per ``u`` (they refer to it symbolically, and to the state's functions)
        and shared by :meth:`commit`, :meth:`count_trial_plastic_points` and the solvers'
        independent check, which evaluate the same return map: each compile costs a form
        signature and a kernel load (4-10 ms).
        """
        if self._return_map_expressions is None or u is not self._return_map_u:
            rm = self.return_map(u)
            self._return_map_u = u
            self._return_map_expressions = (jit.expression(rm.sigma, self._points),
                                            jit.expression(rm.dp, self._points),
                                            jit.expression(rm.deps_p, self._points))
        return self._return_map_expressions

    def commit(self, u: fem.Function) -> None:
        """Accept ``u`` as converged: update σ_n, p_n, Δp_n and u_n at every Gauss point by the
        radial return."""
        if self._commit_u is None:
            self._commit_u = u
        elif u is not self._commit_u:
            raise ValueError("PlasticState.commit must always be given the same displacement Function")
        e_sigma, e_dp, _ = self.return_map_expressions(u)
        sigma_new = fem.Function(self.W_tensor)
        compat.interpolate_expression(sigma_new, e_sigma)
        compat.interpolate_expression(self.dp_n, e_dp)
        self.sigma_n.x.array[:] = sigma_new.x.array
        self.p_n.x.array[:] += self.dp_n.x.array
        self.u_n.x.array[:] = u.x.array
        for f in (self.sigma_n, self.p_n, self.dp_n, self.u_n):
            f.x.scatter_forward()

    def commit_values(self, u: fem.Function, sigma: np.ndarray, dp: np.ndarray) -> None:
        """Accept ``u`` as converged with Gauss-point values computed by the caller.

        For solvers whose stress update is not this class's radial return (NNEQM2's own
        integration): σ_n ← ``sigma``, Δp_n ← ``dp``, p_n ← p_n + ``dp``, u_n ← ``u``.

        Parameters
        ----------
        sigma
            Stresses at this rank's OWNED Gauss points, shape ``(n_owned, 3, 3)`` (or flat),
            in the order of :attr:`W_tensor`'s owned dofs.
        dp
            Equivalent plastic strain increments at the owned Gauss points, shape ``(n_owned,)``.
        """
        n = self.W_scalar.dofmap.index_map.size_local
        sigma = np.asarray(sigma, dtype=float).reshape(-1)
        dp = np.asarray(dp, dtype=float).reshape(-1)
        if sigma.size != 9 * n or dp.size != n:
            raise ValueError(f"commit_values: expected {n} owned Gauss points, got sigma of size "
                             f"{sigma.size} (9 per point) and dp of size {dp.size}")
        self.sigma_n.x.array[:9 * n] = sigma
        self.dp_n.x.array[:n] = dp
        self.p_n.x.array[:n] += dp
        self.u_n.x.array[:] = u.x.array
        for f in (self.sigma_n, self.p_n, self.dp_n, self.u_n):
            f.x.scatter_forward()

    def plastic_strain_of(self, u: fem.Function, sigma: np.ndarray) -> np.ndarray:
        """dev Δε − dev(σ − σ_n)/(2μ) at the owned Gauss points (n, 3, 3), Δε = ε(u) − ε(u_n)."""
        n = sigma.shape[0]
        dev_increment = self.owned_at_points(jit.expression(ufl.dev(strain(u) - strain(self.u_n)), self._points),
                                             tensor=True)
        mu = self.values_at_points(self.mu)
        dsigma = sigma - self.sigma_n.x.array[:9 * n].reshape(n, 3, 3)
        dev_dsigma = dsigma - np.trace(dsigma, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3.0
        return dev_increment - dev_dsigma / (2.0 * mu[:, None, None])

    def count_plastic_points(self) -> int:
        """Number of Gauss points (over all ranks) that yielded in the last converged increment."""
        imap = self.W_scalar.dofmap.index_map
        n_local = imap.size_local * self.W_scalar.dofmap.index_map_bs
        local = int(np.count_nonzero(self.dp_n.x.array[:n_local] > 0.0))
        return self.mesh.comm.allreduce(local, op=MPI.SUM)

    def count_trial_plastic_points(self, u: fem.Function) -> int:
        """Number of Gauss points (over all ranks) where the return map at ``u`` is plastic."""
        if self._trial_dp is None:
            self._trial_dp = fem.Function(self.W_scalar)
        dp = self._trial_dp
        compat.interpolate_expression(dp, self.return_map_expressions(u)[1])
        n_local = self.W_scalar.dofmap.index_map.size_local * self.W_scalar.dofmap.index_map_bs
        return self.mesh.comm.allreduce(int(np.count_nonzero(dp.x.array[:n_local] > 0.0)), op=MPI.SUM)

    def num_gauss_points(self) -> int:
        """Total number of Gauss points (over all ranks)."""
        imap = self.W_scalar.dofmap.index_map
        return imap.size_global * self.W_scalar.dofmap.index_map_bs

    def at_points(self) -> VonMisesAtPoints:
        """The material at this rank's owned Gauss points (interpolated at every call, so that a caller
        holds them only while it needs them; the compiled expressions are kept)."""
        if self._material_expressions is None:
            self._material_expressions = tuple(jit.expression(e, self._points)
                                               for e in (self.mu, self.lmbda, self.sigma_y0, self.H, self.E))
        return VonMisesAtPoints(*(self.owned_at_points(e) for e in self._material_expressions))

    def values_at_points(self, expr) -> np.ndarray:
        """A scalar UFL expression (e.g. a material field) at this rank's owned Gauss points."""
        return self.owned_at_points(jit.expression(expr, self._points)).copy()

    def owned_at_points(self, compiled: fem.Expression, tensor: bool = False) -> np.ndarray:
        """A compiled expression at this rank's owned Gauss points: (n,) for a scalar, (n, 3, 3) for
        a ``tensor``; a view of a function of its own (kept alive by the view, dropped with it)."""
        f = fem.Function(self.W_tensor if tensor else self.W_scalar)
        compat.interpolate_expression(f, compiled)
        n = self.W_scalar.dofmap.index_map.size_local
        return f.x.array[:9 * n].reshape(n, 3, 3) if tensor else f.x.array[:n]


ELASTIC_YIELD_STRESS = np.finfo(float).max / 1e10
"""How the yield stress σ_y0 = inf of an elastic material is stored in the cell-wise fields
(finite, so that the UFL expressions of the yield function stay finite)."""


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


def _materials_by_tag(materials, cell_tags, mesh) -> dict:
    if isinstance(materials, VonMises):
        return {None: materials}
    if not isinstance(materials, dict) or not materials:
        raise TypeError("materials must be a VonMises or a non-empty dict {cell_tag: VonMises}")
    if cell_tags is None:
        raise ValueError("materials given per cell tag, but no cell_tags were given")
    for tag, m in materials.items():
        if not isinstance(m, VonMises):
            raise TypeError(f"materials[{tag}] is {type(m).__name__}, expected VonMises")
        n = mesh.comm.allreduce(int(np.count_nonzero(cell_tags.values == tag)), op=MPI.SUM)
        if n == 0:
            present = sorted(set(np.concatenate(mesh.comm.allgather(np.unique(cell_tags.values))).tolist()))
            raise ValueError(f"materials: cell tag {tag} has no cells; the mesh's cell tags are {present}")
    return dict(materials)


def _fill_cellwise(state: PlasticState, materials: dict, cell_tags, Q0) -> None:
    fields = {"E": state.E, "nu": state.nu, "sigma_y0": state.sigma_y0, "H": state.H,
              "density": state.density}
    tdim = state.mesh.topology.dim
    num_cells = state.mesh.topology.index_map(tdim).size_local + state.mesh.topology.index_map(tdim).num_ghosts
    assigned = np.zeros(num_cells, dtype=bool)
    for tag, material in materials.items():
        cells = np.arange(num_cells, dtype=np.int32) if tag is None else cell_tags.find(tag)
        dofs = Q0.dofmap.list[cells, 0]
        assigned[cells] = True
        for name, f in fields.items():
            value = getattr(material, name)
            f.x.array[dofs] = value if math.isfinite(value) else ELASTIC_YIELD_STRESS
    n_owned = state.mesh.topology.index_map(tdim).size_local
    missing = np.flatnonzero(~assigned[:n_owned])
    n_missing = state.mesh.comm.allreduce(len(missing), op=MPI.SUM)
    if n_missing:
        raise ValueError(
            f"materials: {n_missing} cells carry none of the tags {sorted(materials)}; "
            "every cell needs a material"
        )
    for f in fields.values():
        f.x.scatter_forward()


# -- the same math on numpy arrays of Gauss-point values -------------------------------------------
_S2, _S6 = 1.0 / math.sqrt(2.0), 1.0 / math.sqrt(6.0)
DEVIATORIC_BASIS = np.array([
    [_S2, 0, 0, 0, -_S2, 0, 0, 0, 0],
    [_S6, 0, 0, 0, _S6, 0, 0, 0, -2 * _S6],
    [0, _S2, 0, _S2, 0, 0, 0, 0, 0],
    [0, 0, _S2, 0, 0, 0, _S2, 0, 0],
    [0, 0, 0, 0, 0, _S2, 0, _S2, 0],
])
"""D (5 × 9): an orthonormal basis of the symmetric deviatoric 3×3 tensors (rows: the 9
components, row-major); T:D_a are the coordinates of dev T, and |dev T|² = Σ_a (T:D_a)²."""
_SQRT32 = math.sqrt(1.5)


def deviator_coordinates(tensors: np.ndarray) -> np.ndarray:
    """Coordinates (n, 5) of dev T in :data:`DEVIATORIC_BASIS` for tensors (n, 3, 3) or (n, 9)."""
    return np.asarray(tensors).reshape(-1, 9) @ DEVIATORIC_BASIS.T


def deviator_tensors(coordinates: np.ndarray) -> np.ndarray:
    """The deviators (n, 3, 3) with the given coordinates (n, 5)."""
    return (np.asarray(coordinates) @ DEVIATORIC_BASIS).reshape(-1, 3, 3)


def equivalent_stress(s: np.ndarray) -> np.ndarray:
    """q = sqrt(3/2 s:s) of deviators given by their coordinates (n, 5)."""
    return _SQRT32 * np.linalg.norm(s, axis=-1)


def von_mises_stress(sigma: np.ndarray) -> np.ndarray:
    """q = sqrt(3/2 s:s) of full stress tensors, shape (..., 3, 3)."""
    sigma = np.asarray(sigma, dtype=float)
    return equivalent_stress(deviator_coordinates(sigma.reshape(-1, 3, 3))).reshape(sigma.shape[:-2])


def flow_direction(s: np.ndarray, stress_unit: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray:
    """N = ∂f/∂σ = (3/2) s / q (coordinates, (n, 5)); 0 (or ``fallback``) where q ≤ 10⁻⁸ × the stress unit."""
    q = equivalent_stress(s)
    ok = q > 1e-8 * stress_unit
    N = np.zeros_like(s) if fallback is None else fallback.copy()
    N[ok] = 1.5 * s[ok] / q[ok, None]
    return N


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
    strain increment (coordinates).

    With n̂ = t/|t|: 2μ √(3/2) [√(3/2)/(3μ + H) n̂⊗n̂ + Δp/|t| (I − n̂⊗n̂)] where the return is
    plastic, 0 elsewhere. C − 2μ·2μ of it on the deviators is the consistent tangent C_alg of
    :meth:`PlasticState.tangent` (``formulation.md`` §1).
    """
    _, dp = return_map_plastic_strain(t, mu, sigma_y0, H, p_n)
    plastic = dp > 0.0
    size = np.linalg.norm(t, axis=1)
    n_hat = t / np.where(plastic, size, 1.0)[:, None]
    nn = np.einsum("ja,jb->jab", n_hat, n_hat)
    radial = (_SQRT32 / (3.0 * mu + H))[:, None, None] * nn
    turning = (dp / np.where(plastic, size, 1.0))[:, None, None] * (np.eye(5) - nn)
    out = (2.0 * mu * _SQRT32)[:, None, None] * (radial + turning)
    out[~plastic] = 0.0
    return out


@dataclass(frozen=True)
class VonMisesAtPoints:
    """Von Mises plasticity at a set of Gauss points, on numpy arrays: the material's
    :class:`~dolfinx_nnqem.material.interface.PointwisePlasticity` (what NNEQM2 needs). Its fields
    are the (n,) material values μ, λ, σ_y0, H and E at the points (σ_y0 =
    :data:`ELASTIC_YIELD_STRESS` for an elastic material).
    """

    mu: np.ndarray
    lmbda: np.ndarray
    sigma_y0: np.ndarray
    H: np.ndarray
    E: np.ndarray

    @property
    def stress_unit(self) -> np.ndarray:
        """σ_u = min(σ_y0, 10⁻² E) (:func:`yield_stress_unit`)."""
        return yield_stress_unit(self.sigma_y0, self.E)

    @property
    def yields(self) -> np.ndarray:
        return can_yield(self.sigma_y0)

    def plastic_strain(self, t: np.ndarray, p_n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return return_map_plastic_strain(t, self.mu, self.sigma_y0, self.H, p_n)

    def plastic_strain_tangent(self, t: np.ndarray, p_n: np.ndarray) -> np.ndarray:
        return return_map_tangent(t, self.mu, self.sigma_y0, self.H, p_n)

    def yield_value(self, s: np.ndarray, p: np.ndarray) -> np.ndarray:
        return yield_function(equivalent_stress(s), self.sigma_y0, self.H, p)

    def flow_direction(self, s: np.ndarray) -> np.ndarray:
        """N = (3/2) s / q (|N| = √(3/2)), 0 where q = 0."""
        q = equivalent_stress(s)
        return (1.5 / np.where(q > 0.0, q, 1.0))[:, None] * s * (q > 0.0)[:, None]

    def hardening(self) -> np.ndarray:
        return self.H

    def subset(self, index: slice) -> VonMisesAtPoints:
        return VonMisesAtPoints(self.mu[index], self.lmbda[index], self.sigma_y0[index], self.H[index], self.E[index])


def elastic_stress(eps: np.ndarray, lmbda: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """σ = λ tr(ε) I + 2μ ε for strains (n, 3, 3) and per-point Lamé parameters (n,)."""
    return (lmbda[:, None, None] * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(3)
            + 2.0 * mu[:, None, None] * eps)


def radial_return(sigma_n: np.ndarray, deps: np.ndarray, p_n: np.ndarray, lmbda: np.ndarray, mu: np.ndarray,
                  sigma_y0: np.ndarray, H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The return map of :meth:`PlasticState.return_map` on arrays: (σ (n, 3, 3), Δp (n,)).

    σ_tr = σ_n + C:Δε, f_tr = q_tr − σ_y0 − H p_n, Δp = max(f_tr, 0)/(3μ + H),
    σ = σ_tr − 3μ Δp s_tr / q_tr.
    """
    sigma_tr = sigma_n + elastic_stress(deps, lmbda, mu)
    s_tr = sigma_tr - np.trace(sigma_tr, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3.0
    q_tr = np.sqrt(1.5 * np.einsum("nij,nij->n", s_tr, s_tr))
    dp = np.maximum(yield_function(q_tr, sigma_y0, H, p_n), 0.0) / (3.0 * mu + H)
    q_safe = np.where(dp > 0.0, q_tr, 1.0)
    return sigma_tr - (3.0 * mu * dp / q_safe)[:, None, None] * s_tr, dp
