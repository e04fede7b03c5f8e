r"""The independent check of a converged state: nothing is called "converged" on a solver's word.

After a solver reports that an increment converged, :func:`solve_load_steps
<dolfinx_nnqem.solvers.stepping.solve_load_steps>` measures the state itself, with the problem's public
API only, before committing it:

* **equilibrium**: the full residual R = F_int(u) − F_ext(ℓ) − Bᵀλ(z) at the free dofs,
  ‖R_free‖ ≤ tol · F (the solver's atol is not added: a loose absolute tolerance never excuses
  a residual), F = max(‖F_ext(ℓ)‖, ‖F_int‖, ‖Bᵀλ‖) the problem's force scale
  (the one the solvers use). F_int is the material's return map at u from the converged state, except
  for a solver that returns its own Gauss-point stresses (NNEQM2: ``report.gauss_point_values``,
  which is what the commit stores): then F_int = ∫ σ_own : ε(v) dx;
* **contact**: every pair's law H(w, z) (force units, the supports' pinned directions applied),
  ‖H‖ ≤ tol · F, and, independently of how a law is written, the Coulomb conditions of
  the forces λ(z): p_n ≥ −tol·F and |λ_t| ≤ μ_f max(p_n, 0) + tol·F at every pair;
* **the constitutive law** at every Gauss point (:mod:`~dolfinx_nnqem.solvers.constitutive`), of
  the values the commit will store — a solver's own (NNEQM2) or the return map's at u
  (monolithic, NNEQM1): σ = σ_n + C (Δε − Δε_p) with Δε from u itself; Δε_p = Δp N with the
  material's flow direction N (for von Mises deviatoric, |Δε_p| = √(3/2) Δp); N at the end stress
  for the backward-Euler rule; Δp ≥ 0, f ≤ 0, and f = 0 where Δp > 0 (Δγ f = 0), with the
  material's own yield function; each to tol · σ_u with σ_u the material's stress unit
  (min(σ_y0, 10⁻² E) for von Mises);
* **finite values**: u and z hold no NaN or infinity;
* **small strain** (kinematics "small"): a state with a strain (the
  largest ‖sym ∇u‖ at a Gauss point, Frobenius norm) above ``max_strain`` or an infinitesimal
  rotation (the axial vector of skew ∇u) above ``max_rotation`` is refused: past a limit load
  (plastic collapse, friction exceeded) a small-strain model keeps finding "equilibria" with
  ever larger displacements. Both limits can be relaxed (or set to None);
* **finite strain** (kinematics "finite", :mod:`~dolfinx_nnqem.solvers.finite_strain_check`): J = det F > 0
  at every Gauss point (named), equilibrium with F_int = ∫ P : ∇v dX on the reference configuration
  (what the problem assembles), the constitutive law in the logarithmic space (Hencky's law, the flow,
  the yield function of the Kirchhoff stress τ, consistency) or Neo-Hooke's, and in place of the
  small-strain limits the shape of the deformed mesh x + u: a cell the deformation inverted, or whose
  scaled Jacobian fell below ``min_shape_ratio`` times its undeformed one (flattened), is named and
  refused (:mod:`~dolfinx_nnqem.problem.deformed_mesh`).

The tolerance is ``CheckOptions.rtol`` or, by default, derived from the solver's own ``rtol``:
``max(min(max(1e4 · rtol, 1e-7), 1e-3), 10 · rtol)`` (1e-6 for the default rtol = 1e-10; never
below ten times the solver's own rtol): a state that meets the
solver's criterion passes with room for round-off (and for solvers whose own measure differs:
NNEQM1's nested solves, NNEQM2's scaled system) while anything that is not equilibrium fails.

A failed check turns the increment into a non-converged one (cut back, or reported with the
reason); the figures of a passed check are kept in ``IncrementResult.check`` and written to
``summary.json``.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING

import dolfinx.fem as fem
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.contact.laws import STATE_NAMES
from dolfinx_nnqem.material.interface import GaussPointValues, PointwiseMaterial
from dolfinx_nnqem.material.kinematics import strain
from dolfinx_nnqem.problem.contact_problem import assemble_vector
from dolfinx_nnqem.problem.deformed_mesh import deformed_cells
from dolfinx_nnqem.problem.kinematics_choice import kinematics_of
from dolfinx_nnqem.problem.validation import check_real
from dolfinx_nnqem.solvers.constitutive import ConstitutiveCheck, check_constitutive_law
from dolfinx_nnqem.solvers.finite_strain_check import check_finite_strain_law, inverted_points
from dolfinx_nnqem.solvers.options import SolverOptions

if TYPE_CHECKING:
    from dolfinx_nnqem.solvers.contract import SolvableProblem
    from dolfinx_nnqem.solvers.convergence import SolveReport

__all__ = ["CheckOptions", "StateCheck", "check_state", "failure_details", "radial_return_values",
           "values_to_commit"]

DEFAULT_MAX_STRAIN = 0.1
"""Largest strain (Frobenius norm of sym ∇u at a Gauss point) accepted by default."""
DEFAULT_MAX_ROTATION = 0.1
"""Largest infinitesimal rotation (rad, |axial vector of skew ∇u|) accepted by default."""
DEFAULT_MIN_SHAPE_RATIO = 0.05
"""Smallest shape ratio s(x + u)/s(x) of a deformed cell accepted by default at finite strain: sin θ for a
cube sheared to an angle θ; 0.05 is θ ≈ 3° (a shear γ ≈ 20), far past where the cell still resolves anything."""


@dataclass(frozen=True)
class CheckOptions:
    """How strictly a converged state is checked.

    Attributes
    ----------
    rtol
        Relative tolerance of the equilibrium and contact checks (against the force scale F);
        None: ``max(min(max(1e4 · solver rtol, 1e-7), 1e-3), 10 · solver rtol)``. Must be in (0, 1e-2].
    max_strain, max_rotation
        Small-strain limits (see the module docstring); None disables a limit. Not applied with
        kinematics "finite".
    min_shape_ratio
        Finite strain: the smallest ratio of a deformed cell's scaled Jacobian to its undeformed one
        (see the module docstring); None disables the limit (an inverted cell is refused all the same).
    """

    rtol: float | None = None
    max_strain: float | None = DEFAULT_MAX_STRAIN
    max_rotation: float | None = DEFAULT_MAX_ROTATION
    min_shape_ratio: float | None = DEFAULT_MIN_SHAPE_RATIO

    def __post_init__(self):
        if self.rtol is not None:
            check_real("CheckOptions.rtol", self.rtol, low=0.0, high=1e-2)
        for name in ("max_strain", "max_rotation"):
            value = getattr(self, name)
            if value is not None:
                check_real(f"CheckOptions.{name}", value, low=0.0, high=math.inf)
        if self.min_shape_ratio is not None:
            check_real("CheckOptions.min_shape_ratio", self.min_shape_ratio, low=0.0, high=1.0)

    def tolerance(self, solver_rtol: float) -> float:
        """The relative tolerance of the check: ``rtol`` if given, else 10⁴ × the solver's rtol within
        [10⁻⁷, 10⁻³], and never below 10 × the solver's rtol."""
        if self.rtol is not None:
            return float(self.rtol)
        rtol = float(solver_rtol)
        return max(min(max(1e4 * rtol, 1e-7), 1e-3), 10.0 * rtol)


@dataclass
class StateCheck:
    """The figures of one check (every rank holds the same)."""

    ok: bool
    reason: str  #: "" when ok
    equilibrium: float  #: ‖R_free‖ / F
    contact: float  #: ‖H‖ / F (0 without contact)
    coulomb: float  #: largest violation of p_n ≥ 0 and |λ_t| ≤ μ_f p_n, / F
    max_strain: float
    max_rotation: float
    force_scale: float  #: F
    tolerance: float  #: the relative tolerance used
    own_stresses: bool  #: equilibrium measured with the solver's own Gauss-point stresses
    yield_violation: float = 0.0  #: largest f / σ_u outside the yield surface (0 inside; inf if some Δp < 0)
    constitutive: dict = field(default_factory=dict)  #: each relation's largest violation / σ_u (:class:`ConstitutiveCheck`)
    worst_pairs: list = field(default_factory=list)  #: [{pair, position, state, H/F}] (failed checks)
    worst_nodes: list = field(default_factory=list)  #: [{position, |R|/F}] (failed checks)
    min_shape_ratio: float = math.nan  #: finite strain: the smallest s(x + u)/s(x) of the deformed mesh's cells

    def as_dict(self) -> dict:
        """The figures as a dictionary of their fields."""
        return asdict(self)


class _Forms:
    """Compiled objects of one problem used by the check (built on first use).

    Only the compiled expressions and forms are kept between checks: the Gauss-point functions
    they fill (72 bytes a point for a tensor) and the material at the points are made for each
    check and dropped after it, so that they do not add to the memory the linear solver's set-up
    needs in the next increment.
    """

    def __init__(self, problem):
        st = problem.state
        points = compat.interpolation_points(st.W_tensor)
        self.grad_expr = jit.expression(ufl.grad(problem.u), points)
        self.strain_increment_expr = jit.expression(strain(problem.u) - strain(st.u_n), points)
        self._own_force: tuple[fem.Function, fem.Form] | None = None
        # the state, not the problem: this object is the value of a WeakKeyDictionary keyed by
        # the problem, and a reference to its key would keep both alive for the whole process
        self._state = st

    def at_points(self, expr) -> np.ndarray:
        """A compiled tensor expression at the owned Gauss points, (n, 3, 3), in a function of its own."""
        return self._state.owned_at_points(expr, tensor=True)

    def own_force(self, sigma: np.ndarray) -> fem.Form:
        """The internal force form of the Gauss-point stresses ``sigma`` (owned points), kept once made
        (solvers with their own Gauss-point values only)."""
        st = self._state
        if self._own_force is None:
            sigma_f = fem.Function(st.W_tensor)
            v = ufl.TestFunction(st.u_n.function_space)
            self._own_force = (sigma_f, jit.form(ufl.inner(sigma_f, strain(v)) * st.dx))
        sigma_f, form = self._own_force
        sigma_f.x.array[:sigma.size] = sigma.reshape(-1)
        sigma_f.x.scatter_forward()
        return form

    def material_at_points(self) -> PointwiseMaterial:
        """The material at the owned Gauss points, made for each check and dropped after it: kept, its
        arrays (five values a point for von Mises) stayed resident under every later AMG set-up and
        Krylov solve, where a run on several ranks peaks (``docs/performance.md``)."""
        return self._state.at_points()


def radial_return_values(problem: SolvableProblem) -> GaussPointValues:
    """The values the material's return map gives at the problem's u, at the owned Gauss points
    (collective): what the commit stores for a solver without Gauss-point values of its own."""
    return problem.state.return_map_values(problem.u)


def values_to_commit(problem: SolvableProblem, report: SolveReport | None = None) -> GaussPointValues:
    """The Gauss-point values a commit of the problem's current iterate stores (collective): the
    solver's own (``report.gauss_point_values``) where they belong to the current u on every
    rank, else the return map's at u. The check verifies these, and the commit stores them."""
    gpv = getattr(report, "gauss_point_values", None)
    if _own_values(problem, gpv):
        assert gpv is not None  # _own_values: given
        return gpv
    return radial_return_values(problem)


def _own_values(problem, gpv: GaussPointValues | None) -> bool:
    """``gpv`` is given and belongs to the problem's current u, on every rank."""
    own = gpv is not None and np.array_equal(gpv.u, problem.u.x.array)
    return bool(problem.comm.allreduce(int(own), op=MPI.MIN))


_FORMS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _forms(problem) -> _Forms:
    forms = _FORMS.get(problem)
    if forms is None:
        forms = _FORMS[problem] = _Forms(problem)
    return forms


def _allmax(comm, value: float) -> float:
    return comm.allreduce(float(value), op=MPI.MAX)


def check_state(problem: SolvableProblem, report: SolveReport | None = None,
                solver_options: SolverOptions | None = None, options: CheckOptions | None = None,
                values: GaussPointValues | None = None) -> StateCheck:
    """Check the problem's current iterate (collective; call before commit).

    Parameters
    ----------
    problem
        The :class:`~dolfinx_nnqem.problem.contact_problem.ContactProblem`, at the iterate the solver left.
    report
        The solver's :class:`~dolfinx_nnqem.solvers.convergence.SolveReport` (its
        ``gauss_point_values``, when they belong to the current u, are what will be committed,
        so equilibrium is measured with them).
    solver_options
        The solver's :class:`~dolfinx_nnqem.solvers.options.SolverOptions` (rtol, atol); default ones if None.
    options
        :class:`CheckOptions`.
    values
        The Gauss-point values the commit will store, as :func:`values_to_commit` gives them
        (computed here if None).
    """
    options = options or CheckOptions()
    solver_options = solver_options or SolverOptions()
    tol = options.tolerance(solver_options.rtol)
    comm = problem.comm
    forms = _forms(problem)
    if not _finite(problem):
        nan = float("nan")
        return StateCheck(False, "the state holds NaN or infinite values", nan, nan, nan, nan, nan, nan, tol, False)
    gpv = getattr(report, "gauss_point_values", None)
    own = _own_values(problem, gpv)
    if values is None:
        values = values_to_commit(problem, report)
    reasons: list[str] = []

    # -- equilibrium (with the stresses the commit will store)
    Rf, F, eq = _equilibrium(problem, forms, gpv if own else None)
    if not eq <= tol:  # the solver's atol is not added: an absolute tolerance never excuses a residual
        atol = float(solver_options.atol)
        hint = (f" (the solver's atol = {atol:g} N is above {tol:.0e} F: it lets the solver stop early)"
                if atol > tol * F else "")
        reasons.append(f"equilibrium residual |R|/F = {eq:.3e} > {tol:.1e} (F = {F:.4g} N){hint}")

    # -- the constitutive law at every Gauss point, of the values the commit will store
    constitutive, yield_violation = _law(problem, forms, values, reasons)
    if comm.allreduce(int(np.any(np.asarray(values.dp) < 0.0)), op=MPI.MAX):
        yield_violation = math.inf
        reasons.append("the Gauss-point values have Δp < 0")
    broken = [f"{_RELATIONS[name]} (by {value:.3e} σ_u)" for name, value in constitutive._asdict().items()
              if not value <= tol]
    if broken:
        source = "the solver's" if own else "the return map's"
        reasons.append(f"{source} Gauss-point values break the constitutive law beyond {tol:.1e} σ_u: "
                       + "; ".join(broken))

    # -- the contact law at every pair
    contact = coulomb = 0.0
    pair_violation = None
    if problem.has_contact:
        contact, coulomb, pair_violation = _contact_law(problem, F)
        if not contact <= tol:
            reasons.append(f"contact complementarity |H|/F = {contact:.3e} > {tol:.1e}")
        if not coulomb <= tol:
            reasons.append(f"Coulomb conditions violated by {coulomb:.3e} F (p_n < 0 or |λ_t| > μ_f p_n)")

    # -- small strain, or the deformed mesh at finite strain
    strain, rotation, shape_ratio = _shape(problem, forms, options, reasons)

    result = StateCheck(not reasons, "; ".join(reasons), float(eq), float(contact), float(coulomb),
                        float(strain), float(rotation), float(F), float(tol), own, float(yield_violation),
                        constitutive._asdict(), min_shape_ratio=float(shape_ratio))
    if reasons:
        result.worst_nodes = _worst_nodes(problem, Rf, F)
        if pair_violation is not None:
            result.worst_pairs = _worst_pairs(problem, pair_violation)
    Rf.destroy()
    return result


def _beyond_small_strain(strain: float, rotation: float, options: CheckOptions) -> list[str]:
    """Why the largest strain or rotation is outside the small-strain setting (empty if it is not)."""
    reasons = []
    if options.max_strain is not None and not strain <= options.max_strain:
        reasons.append(f"largest strain {_beyond(strain, options.max_strain)} exceeds max_strain = "
                       f"{options.max_strain:g}: far outside the small-strain setting (plastic collapse or "
                       "friction exceeded? a large deformation: kinematics = 'finite')")
    if options.max_rotation is not None and not rotation <= options.max_rotation:
        reasons.append(f"largest rotation {_beyond(rotation, options.max_rotation)} rad exceeds max_rotation = "
                       f"{options.max_rotation:g}: far outside the small-rotation setting (a mechanism or collapse? "
                       "a large rotation: kinematics = 'finite')")
    return reasons


def _beyond(value: float, limit: float) -> str:
    """``value`` to three significant digits, or to as many as it takes to read larger than ``limit``
    (0.1002 against 0.1 is not printed "0.1")."""
    for digits in range(3, 10):
        text = f"{value:.{digits}g}"
        if float(text) > limit:
            return text
    return repr(value)


def _law(problem, forms: _Forms, values: GaussPointValues, reasons: list[str]) -> tuple[ConstitutiveCheck, float]:
    """(each relation's largest violation, the yield-surface figure) of the problem's kinematics; at
    finite strain, why the state is inverted is appended to ``reasons`` (collective)."""
    if kinematics_of(problem) != "finite":
        return _constitutive(problem, forms, values)
    constitutive, inverted = _finite_strain_law(problem, forms)
    reasons += [inverted] if inverted else []
    return constitutive, constitutive.yield_surface


def _shape(problem, forms: _Forms, options: CheckOptions, reasons: list[str]) -> tuple[float, float, float]:
    """(the largest strain, rotation, and at finite strain the smallest shape ratio, else NaN); why they
    are out of bounds is appended to ``reasons``: the small-strain limits, or the deformed mesh (collective)."""
    strain, rotation = _largest_strain_and_rotation(problem, forms)
    if kinematics_of(problem) != "finite":
        reasons += _beyond_small_strain(strain, rotation, options)
        return strain, rotation, math.nan
    shape_ratio, distorted = _deformed_mesh(problem, options)
    reasons += [distorted] if distorted else []
    return strain, rotation, shape_ratio


def _finite_strain_law(problem, forms: _Forms) -> tuple[ConstitutiveCheck, str]:
    """Finite strain: the constitutive relations in the logarithmic space and why the state is inverted
    (empty if J > 0 everywhere) (collective; :mod:`~dolfinx_nnqem.solvers.finite_strain_check`)."""
    F = forms.at_points(forms.grad_expr) + np.eye(3)
    inverted = inverted_points(problem.state, F)
    if inverted:
        return ConstitutiveCheck(*([math.inf] * 5)), inverted
    return check_finite_strain_law(problem.state, problem.u, F), ""


def _deformed_mesh(problem, options: CheckOptions) -> tuple[float, str]:
    """Finite strain: the deformed mesh's smallest shape ratio and why its cells are refused (empty if
    none is inverted or below ``options.min_shape_ratio``) (collective)."""
    bound = 0.0 if options.min_shape_ratio is None else options.min_shape_ratio  # inverted cells: always
    cells = deformed_cells(problem.u, problem.cell_tags, problem.state.quadrature_degree, bound)
    return cells.min_shape_ratio, cells.reason(bound)


def _finite(problem) -> bool:
    """u and z hold no NaN or infinity, on every rank."""
    n_owned = problem.V.dofmap.index_map.size_local * 3
    finite = bool(np.all(np.isfinite(problem.u.x.array[:n_owned])))
    if problem.has_contact:
        finite &= bool(np.all(np.isfinite(problem.contact.z)))
    return bool(problem.comm.allreduce(int(finite), op=MPI.MIN))


def _equilibrium(problem, forms: _Forms, gpv: GaussPointValues | None):
    """(R at the free dofs, the force scale F, |R_free|/F) with the solver's own Gauss-point stresses
    ``gpv``, or the return map's when None."""
    if gpv is not None:
        F_int = assemble_vector(forms.own_force(np.asarray(gpv.sigma, dtype=float)), problem.V)
    else:
        F_int = problem.assemble_internal_force()
    F_ext = problem.external_force()
    F = max(problem.force_scale(F_int, F_ext), 1e-300)
    R = problem.residual(F_int=F_int)
    Rf = problem.free_residual(R)
    for vec in (F_int, F_ext, R):
        vec.destroy()
    return Rf, F, Rf.norm() / F


def _contact_law(problem, F: float) -> tuple[float, float, np.ndarray]:
    """(|H|/F, the largest violation of the Coulomb conditions / F, each pair's violation / F)."""
    comm, model = problem.comm, problem.contact
    lam = model.force()
    H = model.evaluate(problem.relative_displacement()).H
    contact = math.sqrt(comm.allreduce(float(np.sum(H * H)), op=MPI.SUM)) / F
    pinned = model.constrained
    p_n = np.where(pinned[:, 0], 0.0, lam[:, 0])
    lam_t = np.where(pinned[:, 1:], 0.0, lam[:, 1:])
    cone = np.linalg.norm(lam_t, axis=1) - model.mu_f * np.maximum(p_n, 0.0)
    violation = np.maximum(np.maximum(-p_n, cone), 0.0)
    coulomb = _allmax(comm, np.max(violation, initial=0.0)) / F
    return contact, coulomb, np.maximum(np.linalg.norm(H, axis=1), violation) / F


def _largest_strain_and_rotation(problem, forms: _Forms) -> tuple[float, float]:
    """The largest |sym ∇u| and infinitesimal rotation |axial(skew ∇u)| over the Gauss points."""
    comm = problem.comm
    G = forms.at_points(forms.grad_expr)
    sym = 0.5 * (G + G.transpose(0, 2, 1))
    strain = _allmax(comm, np.max(np.sqrt(np.einsum("nij,nij->n", sym, sym)), initial=0.0))
    rotation = _allmax(comm, np.max(0.5 * np.sqrt((G[:, 2, 1] - G[:, 1, 2]) ** 2 + (G[:, 0, 2] - G[:, 2, 0]) ** 2
                                                  + (G[:, 1, 0] - G[:, 0, 1]) ** 2), initial=0.0))
    return strain, rotation


_RELATIONS = {
    "elasticity": "σ = σ_n + C (Δε − Δε_p)",
    "plastic_strain": "Δε_p of the size Δp |N| (deviatoric for von Mises: √(2/3)|Δε_p| = Δp)",
    "flow_direction": "Δε_p = Δp N(σ) (the flow along the material's direction at the end of the increment)",
    "yield_surface": "the stress within the yield surface, f(σ, p_n + Δp) ≤ 0",
    "complementarity": "Δp ≥ 0 and f = 0 where Δp > 0",
}
"""The relations of :mod:`~dolfinx_nnqem.solvers.constitutive`, as the check's reason names them."""


def _constitutive(problem, forms: _Forms, values: GaussPointValues) -> tuple[ConstitutiveCheck, float]:
    """The constitutive relations at the owned Gauss points for ``values`` (collective), and the
    yield-surface figure alone."""
    st = problem.state
    n = st.W_scalar.dofmap.index_map.size_local
    deps_p = values.deps_p
    if deps_p is None:  # values given without their plastic strains: what the stresses leave over
        deps_p = st.plastic_strain_of(problem.u, np.asarray(values.sigma).reshape(n, 3, 3))
    result = check_constitutive_law(
        problem.comm, forms.at_points(forms.strain_increment_expr),
        np.asarray(values.sigma, dtype=float).reshape(n, 3, 3), np.asarray(values.dp, dtype=float).reshape(n),
        np.asarray(deps_p, dtype=float).reshape(n, 3, 3), values.flow_rule,
        st.sigma_n.x.array[:9 * n].reshape(n, 3, 3), st.internal_at_points(values), forms.material_at_points())
    return result, result.yield_surface


def _worst_nodes(problem, Rf, F: float, count: int = 5) -> list:
    """The ``count`` nodes with the largest free residual, over all ranks."""
    comm = problem.comm
    n_owned = problem.V.dofmap.index_map.size_local
    r = np.linalg.norm(Rf.getArray(readonly=True).reshape(-1, 3)[:n_owned], axis=1) / F
    order = np.argsort(-r)[:count]
    x = problem.V.tabulate_dof_coordinates()[:n_owned]
    local = [(float(r[i]), x[i].tolist()) for i in order]
    every = sorted((item for part in comm.allgather(local) for item in part), key=lambda t: -t[0])[:count]
    return [{"position": pos, "residual": val} for val, pos in every]


def _worst_pairs(problem, violation: np.ndarray, count: int = 5) -> list:
    """The ``count`` pairs with the largest |H|/F or Coulomb violation (global pair order)."""
    model = problem.contact
    X = np.concatenate([i.pairs.X_slave for i in model.interfaces]).reshape(-1, 3)
    state = model.evaluate(problem.relative_displacement()).state
    local = np.column_stack([violation, X, state.astype(float)])
    g = model.gather(local)
    order = np.argsort(-g[:, 0])[:count]
    return [{"pair": int(i), "position": g[i, 1:4].tolist(), "state": STATE_NAMES[int(g[i, 4])],
             "violation": float(g[i, 0])} for i in order]


def failure_details(problem) -> dict:
    """What would not settle at the problem's current (failed) iterate: the worst nodes (free
    equilibrium residual), the worst pairs (|H|) and the Gauss points on the plastic branch
    (collective; call before ``problem.restore()``)."""
    try:
        F_int = problem.assemble_internal_force()
        F_ext = problem.external_force()
        out: dict[str, object] = {}
        finite_forces = not problem.has_contact or problem.comm.allreduce(
            int(np.all(np.isfinite(problem.contact.force()))), op=MPI.MIN)  # the same choice on every rank
        if finite_forces:
            scale = problem.force_scale(F_int, F_ext)
        else:  # the failed iterate's pair forces are not finite: the scale of the loads alone
            scale = max(F_ext.norm(), F_int.norm(), problem.force_floor)
        F = max(scale, 1e-300)
        R = problem.residual(F_int=F_int)
        Rf = problem.free_residual(R)
        out["equilibrium"] = float(Rf.norm() / F)
        out["worst_nodes"] = _worst_nodes(problem, Rf, F)
        if problem.has_contact:
            H = problem.contact.evaluate(problem.relative_displacement()).H
            out["worst_pairs"] = _worst_pairs(problem, np.linalg.norm(H, axis=1) / F)
        out["trial_plastic_gauss_points"] = problem.state.count_trial_plastic_points(problem.u)
        for obj in (F_int, F_ext, R, Rf):
            obj.destroy()
        return out
    except Exception as error:  # a report must never hide the original failure
        return {"error": f"{type(error).__name__}: {error}"}
