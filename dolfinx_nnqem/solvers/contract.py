"""The solver contracts: what a solver may read of a problem, and what load stepping, writers and
users may use of a solver.

A solver takes a problem — :class:`SolvableProblem`, which :class:`~dolfinx_nnqem.problem.ContactProblem`
implements — and solves one load increment at a time; :func:`~dolfinx_nnqem.solvers.stepping.solve_load_steps`
drives it. Every solver of the package satisfies :class:`Solver` (the type checker holds them to
both in :mod:`~dolfinx_nnqem.solvers.conformance`; ``tests/unit/test_contracts.py`` checks them at run
time), and frees its PETSc objects when used as a context manager::

    with make_solver("monolithic", problem) as solver:
        solve_load_steps(problem, solver, 15)
"""

from __future__ import annotations

from types import TracebackType
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from dolfinx_nnqem.solvers.convergence import ConvergenceError

if TYPE_CHECKING:
    from petsc4py import PETSc

    from dolfinx_nnqem.contact.model import ContactModel
    from dolfinx_nnqem.material.interface import MaterialState
    from dolfinx_nnqem.material.interface import GaussPointValues
    from dolfinx_nnqem.problem.bodies import RigidModes
    from dolfinx_nnqem.solvers.condensed import CondensedProblem
    from dolfinx_nnqem.solvers.convergence import SolveReport
    from dolfinx_nnqem.solvers.options import SolverOptions

__all__ = ["CondensingSolver", "ReleasesPETSc", "SolvableProblem", "Solver", "contact_model"]


@runtime_checkable
class SolvableProblem(Protocol):
    """What a solver may read of a problem, and do to it.

    The problem owns the displacement u and the pair unknowns z (its contact model's), the
    Gauss-point state, the loads on the load path and the assembly of the pieces solvers combine;
    a solver moves (u, z) to the end of an increment and leaves the commit to load stepping.
    """

    u: Any  #: the displacement (a dolfinx Function); the solvers' iterate
    load_factor: float  #: ℓ of the iterate (:meth:`apply_prescribed_displacements` sets it)
    load_factor_n: float  #: ℓ of the last converged increment

    @property
    def comm(self) -> Any:
        """The MPI communicator."""
        ...

    @property
    def V(self) -> Any:
        """The displacement's function space."""
        ...

    @property
    def state(self) -> MaterialState:
        """The Gauss-point state (:mod:`dolfinx_nnqem.material.interface`)."""
        ...

    @property
    def contact(self) -> ContactModel | None:
        """Every interface's pairs and the pair unknowns z (None without contact)."""
        ...

    @property
    def rigid_modes(self) -> RigidModes:
        """The bodies' free rigid modes (a body held only by contact)."""
        ...

    @property
    def bc_dofs(self) -> np.ndarray:
        """The constrained dofs (local indices, ghosts included)."""
        ...

    @property
    def force_floor(self) -> float:
        """The smallest force scale (:meth:`force_scale`)."""
        ...

    @property
    def petsc_comms(self) -> list:
        """Communicators whose dropped PETSc objects a solver frees."""
        ...

    @property
    def has_contact(self) -> bool:
        """Whether the problem has contact interfaces (a contact model)."""
        ...

    @property
    def num_pairs(self) -> int:
        """The number of contact pairs over all ranks (0 without contact)."""
        ...

    def apply_prescribed_displacements(self, load_factor: float) -> None:
        """Set u = a(ℓ) · value at the constrained dofs (owned and ghost) and ℓ = ``load_factor``."""
        ...

    def extrapolation_factor(self, load_factor: float) -> float | None:
        """β of the secant predictor to ``load_factor``; None where it does not apply (fewer than two
        increments, or a load path that turns)."""
        ...

    def extrapolate(self, load_factor: float) -> bool:
        """Secant predictor u ← u_n + β (u_n − u_{n−1}), the contact unknowns likewise; True if applied."""
        ...

    def predict_contact(self) -> None:
        """Set the starting active set of the contact pairs (``ContactModel.predict``)."""
        ...

    def external_force(self, load_factor: float | None = None, out: PETSc.Vec | None = None) -> PETSc.Vec:
        """F_ext(ℓ) = Σ_k a_k(ℓ) F_k: a new vector, or ``out`` overwritten."""
        ...

    def assemble_internal_force(self, F: PETSc.Vec | None = None) -> PETSc.Vec:
        """F_int(u) = ∫ σ(u) : ε(v) dx, the return map from the converged state: a new vector, or ``F``."""
        ...

    def assemble_tangent(self, A: PETSc.Mat | None = None, extra_bcs: Any = ()) -> PETSc.Mat:
        """K_t(u), the consistent tangent, with identity rows and columns at the constrained dofs (and
        those of ``extra_bcs``): a new matrix, or ``A``."""
        ...

    def assemble_elastic_stiffness(self, A: PETSc.Mat | None = None, extra_bcs: Any = ()) -> PETSc.Mat:
        """K_e, the elastic stiffness, with identity rows and columns at the constrained dofs (and those
        of ``extra_bcs``): a new matrix, or ``A``."""
        ...

    def tangent_action(self, delta: np.ndarray) -> PETSc.Vec:
        """K_t(u) δ with no constrained row or column removed (δ: local array, ghosts included)."""
        ...

    def residual(self, z: np.ndarray | None = None, F_int: PETSc.Vec | None = None, *,
                 F_ext: PETSc.Vec | None = None, contact_force: PETSc.Vec | None = None,
                 out: PETSc.Vec | None = None) -> PETSc.Vec:
        """R = F_int(u) − F_ext(ℓ) − Bᵀλ(z), constrained rows not zeroed (they hold the support
        reactions); the parts the caller has may be passed, ``out`` is overwritten if given."""
        ...

    def free_residual(self, R: PETSc.Vec, out: PETSc.Vec | None = None) -> PETSc.Vec:
        """A copy of ``R`` (a new vector, or into ``out``) with the constrained rows zeroed."""
        ...

    def force_scale(self, F_int: PETSc.Vec, F_ext: PETSc.Vec | None = None,
                    contact_force: PETSc.Vec | None = None) -> float:
        """The force scale F = max(‖F_ext(ℓ)‖, ‖F_int‖, ‖Bᵀλ(z)‖, r ‖Δm‖, F_floor) of the convergence
        tests at the current iterate."""
        ...

    def relative_displacement(self, u: PETSc.Vec | None = None) -> np.ndarray:
        """w = B u + m(ℓ) of the local pairs, (num_local_pairs, 3) (default: the current u)."""
        ...

    def constrained_rows(self) -> np.ndarray:
        """Global (unrolled) PETSc row indices of the constrained dofs this rank owns."""
        ...

    def owned_bc_dofs(self) -> np.ndarray:
        """Unrolled constrained dofs owned by this rank (indices into the owned part of a vector)."""
        ...

    def commit(self, gauss_point_values: GaussPointValues | None = None) -> None:
        """Accept the current iterate as the converged end of the increment (the Gauss-point state from
        the radial return at u, or ``gauss_point_values`` the solver computed for this u)."""
        ...

    def restore(self) -> None:
        """Return to the last converged increment (after a failed attempt)."""
        ...


def contact_model(problem: SolvableProblem) -> ContactModel:
    """The problem's contact model, for code that runs only with contact (NNEQM1, the pair steps).

    Raises
    ------
    ValueError
        If the problem has no contact.
    """
    if problem.contact is None:
        raise ValueError("the problem has no contact (no Contact was given); this needs one")
    return problem.contact


@runtime_checkable
class Solver(Protocol):
    """What load stepping, writers and users may use of a solver."""

    name: str  #: "monolithic", "nneqm1" or "nneqm2"
    options: SolverOptions  #: the tolerances the independent check derives its own from
    #: True if the solver takes interfaces whose pairs are re-evaluated in the current configuration
    #: (``geometry = "current"``, and ``"auto"`` once the surfaces slid past the slip limit)
    follows_contact_geometry: bool

    @property
    def timings(self) -> dict[str, float]:
        """Seconds per phase, accumulated over the run."""
        ...

    def solve_increment(self, load_factor: float) -> SolveReport:
        """Solve for the load factor ``load_factor`` from the last converged state.

        The problem's iterate (u, z) is left at the solution (or the last iterate if the
        report says it did not converge); the problem's converged state is not touched: the
        caller commits (with ``report.gauss_point_values``) or restores.
        """
        ...

    def destroy(self) -> None:
        """Free the solver's PETSc objects."""
        ...

    def __enter__(self) -> Solver: ...

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None: ...


@runtime_checkable
class CondensingSolver(Solver, Protocol):
    """A solver that solves the contact forces on a condensed (dense) problem, and keeps the last
    one: what :func:`~dolfinx_nnqem.io.fclib.write_nneqm1_problem` exports (NNEQM1)."""

    @property
    def problem(self) -> SolvableProblem:
        """The problem it solves."""
        ...

    @property
    def last_condensed(self) -> CondensedProblem | None:
        """The latest outer iteration's condensed problem (C, w_free, g0, ...); None before the first."""
        ...


class ReleasesPETSc:
    """``with solver: ...`` calls ``solver.destroy()`` at the end, as DOLFINx's own solvers do.

    Not after an exception that only some ranks may have raised: destroying PETSc objects is
    collective, and a rank waiting for the others inside a solve would never join (the job
    hung instead of ending with the error's exit code). A :class:`ConvergenceError` is raised
    on every rank together, so the objects are destroyed then; after any other exception they
    are left to the garbage collector.
    """

    def destroy(self) -> None:  # pragma: no cover - every solver defines its own
        """Free the solver's PETSc objects (collective)."""
        raise NotImplementedError

    def __enter__(self):
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None:
        if kind is None or issubclass(kind, ConvergenceError):
            self.destroy()
