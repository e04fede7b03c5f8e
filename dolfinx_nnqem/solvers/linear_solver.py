r"""How the monolithic solver solves its Newton systems: a direct or an iterative strategy.

* :class:`DirectSolver`: MUMPS LU (or anything set through ``petsc_options``) on the Newton
  matrix converted to one AIJ matrix. The same matrix object is refilled every iteration, so
  PETSc keeps the symbolic factorisation while the sparsity does not change.
* :class:`IterativeSolver`: for large meshes, no factorisation of the displacement block.
  With contact, FGMRES with a lower Schur-complement fieldsplit on the augmented Newton matrix
  (:class:`dolfinx_nnqem.solvers.block_system.AugmentedSystem`): one GAMG V-cycle (rigid-body
  near-nullspace) on the u block, the "selfp" Schur complement factorised on the pair block.
  Without contact, CG + GAMG. Two policies make it fast:

  - inexact Newton forcing: each Krylov solve stops at a tolerance set from the relative Newton
    residual ε, by the quadratic rule η = min(max(ε², 0.1 rtol/ε), η_max) or Eisenstat and
    Walker's η = 0.9 (ε/ε_prev)² (:meth:`IterativeSolver.set_forcing`);
  - a lagged AMG hierarchy: kept over Newton iterations and increments while fewer than 5 % of
    the pairs change state and lagged solves converge at the rate the last fresh hierarchy had;
    a solve cut short goes on from its iterate with the rebuilt hierarchy.

``theory.md`` states both rules with their reasons.
"""

from __future__ import annotations

import math
import time

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.numerics.heap import release_free_heap
from dolfinx_nnqem.solvers.convergence import logger
from dolfinx_nnqem.numerics.linalg import (ITERATIVE_NO_CONTACT_OPTIONS, ITERATIVE_NO_CONTACT_UNSYMMETRIC_OPTIONS,
                                           ITERATIVE_SOLVER_OPTIONS, clear_options, create_ksp,
                                  products_without_intermediates, relative_residual,
                                  direct_options, rigid_body_modes, vec_norm)
from dolfinx_nnqem.solvers.timings import Timings

__all__ = ["DIRECT_RESIDUAL_TOL", "DirectSolver", "IterativeSolver"]

DIRECT_RESIDUAL_TOL = 1e-6
"""Largest ‖J x − b‖ / ‖b‖ a direct solve may leave; a larger one is a failed solve (the Newton
driver falls back to Levenberg–Marquardt). MUMPS leaves 1e-15 where it factorises well; on 2
ranks with its automatic ordering it returned solutions with residuals from 2.9 to 96 for the
pressed blocks (:func:`dolfinx_nnqem.compat.parallel_mumps_ordering`), which the Newton
iteration took as directions."""


class DirectSolver:
    """A direct solve of the Newton system (MUMPS LU by default).

    Parameters
    ----------
    comm
        The communicator of the system.
    prefix
        A unique PETSc options prefix.
    petsc_options
        Merged over :data:`dolfinx_nnqem.numerics.linalg.DIRECT_SOLVER_OPTIONS`.
    """

    iterative = False

    def __init__(self, comm, prefix: str, petsc_options: dict | None):
        self.prefix = prefix
        self._options = direct_options(petsc_options, comm.size)
        self.ksp = create_ksp(comm, prefix, self._options)
        self._set_up_once = False
        self.timings = Timings()
        self.linear_iterations = 0
        self.amg_setups = 0

    def begin_increment(self) -> None:
        """Nothing to reset (forcing belongs to the iterative strategy)."""

    def set_forcing(self, eps: float, record: bool = True, cap: float | None = None) -> None:
        """A direct solve is exact: no forcing."""

    def solve(self, J: PETSc.Mat, b: PETSc.Vec, x: PETSc.Vec, pair_state: np.ndarray | None = None) -> str | None:
        """Solve J x = b; None on success, else why not (a failed factorisation: the Newton driver
        falls back to Levenberg–Marquardt). PETSc errors are raised."""
        self.ksp.setOperators(J)
        t0 = time.perf_counter()
        try:
            self.ksp.setUp()
            self.timings.add("setup", t0)
            t0 = time.perf_counter()
            self.ksp.solve(b, x)
        except PETSc.Error:
            # a real error (out of memory, an unavailable package, ...), not a singular matrix, which
            # PETSc reports through the converged reason below: it ends the run as itself
            self.ksp.reset()
            raise
        finally:
            self.timings.add("solve", t0)
            self._clear_options()
        self.linear_iterations += self.ksp.getIterationNumber()
        reason = self.ksp.getConvergedReason()
        if reason <= 0 or not np.all(np.isfinite(x.getArray(readonly=True))):  # type: ignore[operator]  # petsc4py's stub: the reason is an int, not the ConvergedReason namespace
            # e.g. a zero pivot: PETSc keeps the failed factor, and reusing the same matrix object
            # (same pattern: numeric factorisation only) would fail from then on
            self.ksp.reset()
            return f"the linear solve failed (KSP reason {reason})"
        residual = relative_residual(J, x, b)
        if not residual <= DIRECT_RESIDUAL_TOL:
            self.ksp.reset()
            return f"the direct solve is inaccurate (relative residual {residual:.1e})"
        return None

    def _clear_options(self) -> None:
        if not self._set_up_once:
            clear_options(self.prefix, self._options)
            self._set_up_once = True

    def destroy(self) -> None:
        """Free the KSP and its options (collective)."""
        self._clear_options()  # a solver never set up (made again when the contact geometry changed) leaves none
        self.ksp.destroy()


class IterativeSolver:
    """Krylov solves with an AMG-preconditioned displacement block (see the module docstring).

    Parameters
    ----------
    V
        The displacement space (for GAMG's rigid-body near-nullspace).
    prefix
        A unique PETSc options prefix.
    petsc_options
        Merged over the package's defaults (:data:`dolfinx_nnqem.numerics.linalg.ITERATIVE_SOLVER_OPTIONS`,
        or ``ITERATIVE_NO_CONTACT_OPTIONS``).
    rtol
        The Newton tolerance (the forcing aims at it).
    num_pairs
        Pairs over all ranks (0 without contact).
    lag_preconditioner
        Keep the u block's AMG hierarchy while it works (with contact).
    symmetric
        The tangent is symmetric; False (non-associated flow): GMRES instead of CG without contact.
    forcing
        The inexact-Newton rule of the Krylov tolerances: one of :data:`FORCING_RULES`
        (:meth:`set_forcing`).
    max_forcing
        The loosest Krylov tolerance a Newton step gets.
    """

    iterative = True

    def __init__(self, V, prefix: str, petsc_options: dict | None, rtol: float, num_pairs: int,
                 lag_preconditioner: bool = True, symmetric: bool = True, forcing: str = "eisenstat-walker",
                 max_forcing: float = 1e-2):
        self.V = V
        self.forcing = forcing
        self.max_forcing = max_forcing
        self.comm = V.mesh.comm
        self.prefix = prefix
        self.rtol = rtol
        self.num_pairs = num_pairs
        defaults = (ITERATIVE_SOLVER_OPTIONS if num_pairs else ITERATIVE_NO_CONTACT_OPTIONS if symmetric
                    else ITERATIVE_NO_CONTACT_UNSYMMETRIC_OPTIONS)
        self._options = {**defaults, **(petsc_options or {})}
        self.ksp = create_ksp(self.comm, prefix, self._options)
        self._set_up_once = False
        self._rtol_floor, _, _, self._max_it = self.ksp.getTolerances()
        self._configured = False
        self._keep: tuple[PETSc.IS | PETSc.NullSpace, ...] = ()  # what PETSc holds by reference only
        self._residual_work: PETSc.Vec | None = None  # b − J x of a lagged solve cut short
        self._lagging = bool(num_pairs) and lag_preconditioner
        self.refresh_fraction = 0.05
        self._refresh = True
        self._lag_state: np.ndarray | None = None  # the pair states the lagged hierarchy was built at
        self._lag_refreshed = True
        self._fresh_rate: float | None = None  # Krylov convergence rate right after the last AMG set-up
        self._last_forcing: tuple[float, float] | None = None  # (ε, η) of the last inexact Newton step of the increment
        self.timings = Timings()
        self.linear_iterations = 0  #: Krylov iterations over all solves
        self.amg_setups = 0  #: AMG hierarchies built (with contact)

    def begin_increment(self) -> None:
        """Forget the last step's forcing (the "finishing step" rule is per increment)."""
        self._last_forcing = None

    def set_forcing(self, eps: float, record: bool = True, cap: float | None = None) -> None:
        """Inexact Newton: the Krylov tolerance η of the next step, by :attr:`forcing`'s rule, at
        most ``cap`` if given (the lifted predictor's ``lift_forcing``).

        Both rules share a floor and a finishing step. 0.1·rtol/ε, ε the relative residual, is
        just the accuracy that lets the step reach the tolerance; η is never below ``ksp_rtol`` of
        the options. If the last step (``record``-ed, in this increment) cut the residual by no
        less than its Krylov tolerance allowed (ε ≤ 2 η_prev ε_prev), the problem behaves
        linearly here (an elastic increment, no pair changing state): η = 0.1·rtol/ε, so that
        this step finishes the increment instead of one more Newton iteration for the same
        Krylov work.
        """
        floor = 0.1 * self.rtol / max(eps, 1e-300)
        if self.forcing == "eisenstat-walker":
            eta = self._eisenstat_walker(eps, floor)
        else:
            eta = self._quadratic(eps, floor)
        if self._last_forcing is not None:
            eps_prev, eta_prev = self._last_forcing
            if eps <= 2.0 * eta_prev * eps_prev:
                eta = min(eta, floor)
        if cap is not None:
            eta = min(eta, cap)
        eta = max(eta, self._rtol_floor)
        self._last_forcing = (eps, eta) if record else None
        self.ksp.setTolerances(rtol=eta)

    def _eisenstat_walker(self, eps: float, floor: float) -> float:
        """η = γ (ε/ε_prev)², γ = 0.9 (Eisenstat–Walker's second choice), between ``floor`` and
        ``max_forcing``.

        The step is solved only as accurately as the last Newton step's own reduction of the
        residual suggests the linear model to be: a step that cut the residual by 3 (a semismooth
        iteration whose active set still moves, a plastic zone that grows) gets the cap, one that
        cut it by 100 (the quadratic phase) 1e-4. The first step of an increment gets the cap;
        a step after one whose tolerance was large keeps at least γ η_prev² (their safeguard,
        when it is above 0.1).
        """
        eta = self.max_forcing
        if self._last_forcing is not None:
            eps_prev, eta_prev = self._last_forcing
            eta = 0.9 * (eps / max(eps_prev, 1e-300)) ** 2
            safeguard = 0.9 * eta_prev ** 2
            if safeguard > 0.1:
                eta = max(eta, safeguard)
        return min(max(eta, floor), self.max_forcing)

    def _quadratic(self, eps: float, floor: float) -> float:
        """η = min(max(ε², ``floor``), ``max_forcing``), ε the relative residual.

        η = O(ε) keeps Newton's local order (Dembo–Eisenstat–Steihaug); ε² leaves the step as
        good as an exact one where the quadratic term dominates. Early iterations, far from the
        solution, are not solved to full accuracy.
        """
        return min(max(eps * eps, floor), self.max_forcing)

    def _configure(self, J: PETSc.Mat) -> None:
        """Field split (u, z) and the rigid-body near-nullspace for GAMG, once."""
        if self._configured:
            return
        nullspace = rigid_body_modes(self.V)
        if not self.num_pairs:
            J.setNearNullSpace(nullspace)  # K is assembled into the same matrix every iteration
            self._keep = (nullspace,)
        else:
            (is_u, is_z), _ = J.getNestISs()
            is_u.compose("nearnullspace", nullspace)  # PCFIELDSPLIT passes it to the u block's GAMG
            self.ksp.getPC().setFieldSplitIS(("u", is_u), ("z", is_z))
            self._keep = (is_u, is_z, nullspace)
        self._configured = True

    def solve(self, J: PETSc.Mat, b: PETSc.Vec, x: PETSc.Vec, pair_state: np.ndarray | None = None) -> str | None:
        """Solve J x = b to the current forcing tolerance; None on success, else why not.

        ``pair_state`` (the pairs' states at the iterate) decides whether the lagged AMG
        hierarchy still fits (with contact).
        """
        self.ksp.setOperators(J)
        self._configure(J)
        self._krylov_solve(b, x, pair_state)
        if self._lagging and self._lagged_solve_is_poor(b):
            # the lagged AMG hierarchy no longer fits K + BᵀPB: rebuild it and go on from where the
            # lagged solve stopped (the tolerance is relative to ‖b‖ whatever the start)
            self._refresh = True
            start = self._resume_from(J, b, x)
            self._krylov_solve(b, x, pair_state)
            self.ksp.setInitialGuessNonzero(False)
            self._lagged_solve_is_poor(b, start)  # records the fresh hierarchy's convergence rate
        reason = self.ksp.getConvergedReason()
        if reason <= 0 or not np.all(np.isfinite(x.getArray(readonly=True))):  # type: ignore[operator]  # as in DirectSolver.solve
            return f"the linear solve failed (KSP reason {reason})"
        return None

    def _krylov_solve(self, b: PETSc.Vec, x: PETSc.Vec, pair_state) -> None:
        """Set up (lagging the u block's AMG where it may) and solve; PETSc errors are raised."""
        release_free_heap()  # the set-up and the Krylov basis are where a run peaks: not on top of freed memory
        t0 = time.perf_counter()
        try:
            # the AMG set-up happens within the solve; its products' reuse data would outlive it
            with products_without_intermediates():
                self.ksp.setUp()
                self._lag_u_preconditioner(pair_state)
                self.timings.add("setup", t0)
                t0 = time.perf_counter()
                self.ksp.solve(b, x)
        except PETSc.Error:
            self._refresh = True  # whatever failed, do not lag from it
            raise
        finally:
            self.timings.add("solve", t0)
            if not self._set_up_once:
                clear_options(self.prefix, self._options)
                self._set_up_once = True
        self.linear_iterations += self.ksp.getIterationNumber()

    def _lag_u_preconditioner(self, state) -> None:
        """Keep the u block's AMG hierarchy over Newton iterations and increments while it works.

        GAMG's set-up (aggregation and Galerkin products) costs many Krylov iterations; the
        hierarchy of an earlier Newton matrix stays a good preconditioner for the next ones
        (FGMRES still solves with the current matrix). It is rebuilt when more than
        ``refresh_fraction`` of the pairs changed state since it was built (the penalty BᵀPB
        changes there), and when a lagged solve needs more than twice the iterations the last
        fresh hierarchy's convergence rate predicts (that solve is then cut short and redone).
        """
        if not self._lagging:
            return
        if self._lag_state is None or self._lag_state.shape != state.shape or self._fresh_rate is None:
            self._refresh = True
        else:
            changed = self.comm.allreduce(int(np.count_nonzero(state != self._lag_state)), op=MPI.SUM)
            if changed > self.refresh_fraction * self.num_pairs:
                self._refresh = True
        ksp_u = self.ksp.getPC().getFieldSplitSubKSP()[0]
        ksp_u.getPC().setReusePreconditioner(not self._refresh)
        if self._refresh:
            self._lag_state = state.copy()
            self.amg_setups += 1
            self.ksp.setTolerances(max_it=self._max_it)
        else:
            rtol = self.ksp.getTolerances()[0]
            assert self._fresh_rate is not None  # without a rate the hierarchy is refreshed (above)
            expected = math.log(rtol) / math.log(self._fresh_rate)
            self.ksp.setTolerances(max_it=int(2 * expected) + 5)
        self._lag_refreshed = self._refresh
        self._refresh = False

    def _resume_from(self, J: PETSc.Mat, b: PETSc.Vec, x: PETSc.Vec) -> float:
        """Start the next solve from ``x`` (the cut-short lagged solve's iterate) if it is finite and
        better than zero, else from zero; returns the starting residual norm."""
        r = self._residual_work = self._residual_work or b.duplicate()
        norm_b = vec_norm(b)
        if np.all(np.isfinite(x.getArray(readonly=True))):
            J.mult(x, r)
            r.aypx(-1.0, b)  # r = b − J x
            norm_r = vec_norm(r)
            if norm_r < norm_b:
                self.ksp.setInitialGuessNonzero(True)
                return norm_r
        x.zeroEntries()
        return norm_b

    def _lagged_solve_is_poor(self, b: PETSc.Vec, start: float | None = None) -> bool:
        """True if this solve used a lagged hierarchy and did not converge within its budget.

        After a fresh set-up, records its convergence rate (``start``: the solve's starting residual
        norm, default ‖b‖)."""
        if self._lag_refreshed:
            its = max(self.ksp.getIterationNumber(), 1)
            reduction = self.ksp.getResidualNorm() / max(vec_norm(b) if start is None else start, 1e-300)
            self._fresh_rate = min(max(reduction ** (1.0 / its), 1e-3), 0.95)
            return False
        return self.ksp.getConvergedReason() <= 0  # type: ignore[operator]  # as in DirectSolver.solve

    def destroy(self) -> None:
        """Free the KSP, its options and the objects it keeps (collective)."""
        if not self._set_up_once:  # never set up (made again when the contact geometry changed): its options go
            clear_options(self.prefix, self._options)
            self._set_up_once = True
        self.ksp.destroy()
        for obj in self._keep:
            obj.destroy()
        if self._residual_work is not None:
            self._residual_work.destroy()

