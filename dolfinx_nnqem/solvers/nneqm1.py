r"""NNEQM1: a nonsmooth Newton on the contact unknowns nested in Newton–Raphson (seed §3).

For the load factor ℓ of an increment, outer iteration m (``formulation.md`` §5):

1. r_m = F_ext(ℓ) − F_int(u_m) + Bᵀλ_m (constrained rows zero);
2. one factorisation of the consistent tangent K_m (:class:`~dolfinx_nnqem.solvers.condensation.Condensation`);
   X = G Bᵀ (3NC right-hand sides solved together), the contact flexibility C_m = B X (dense,
   3NC × 3NC) and x_r = G r_m, w_free = B x_r;
3. inner: H(w(z), z) = 0 with w(z) = w_m + w_free + C_m (λ(z) − λ_m), a dense nonsmooth system
   of order 3NC, by the package's Newton driver (:func:`dolfinx_nnqem.numerics.nonsmooth.solve_nonsmooth`);
4. du = x_r + X (λ − λ_m); u ← u + du, then the return map at the Gauss points;
5. converged when ‖R‖ and ‖H‖ are below tolerance relative to the load scale.

Where prescribed displacements move in the increment, the first outer iteration starts from the
converged state with their jump lifted into the right-hand side (as the monolithic solver does):
r_0 = −R(u_n) − K_t(u_n) Δu_D on the free rows and du = Δu_D on the constrained ones. Moving
the constrained dofs first and factorising there would linearise at a state whose boundary
layer alone has been moved; in a plastic body that layer yields spuriously, and the first step
(and the pair states it predicts) is then far off.

The outer iteration is the same Newton driver with full steps (no line search): its step is a
whole condensed contact solve.

Floating bodies: where a body has free rigid modes N (held only by contact), G is K's generalised
inverse on self-equilibrated loads and the inner system gets the mode amplitudes α as n_r more
unknowns, with the self-equilibrium rows Nᵀ(r_m + Bᵀ(λ − λ_m)) = 0:

    w = w_m + w_free + C (λ − λ_m) + (B N) α,    du = x_r + X (λ − λ_m) + N α.

``NNEQM1Options(modified=True)`` keeps K, X and C from the first iteration of the increment
(modified Newton): cheaper iterations, linear convergence.

The dense contact problem is small (3NC + n_r); every rank solves it redundantly with the same
data, so all ranks take the same decisions.
"""

from __future__ import annotations

import math
import time

import numpy as np
from petsc4py import PETSc

from dolfinx_nnqem.solvers.condensation import Condensation, check_dense_memory
from dolfinx_nnqem.solvers.condensed import CondensedProblem, CondensedSystem, newton_step, rigid_start
from dolfinx_nnqem.solvers.nodal_flexibility import NodalFlexibility, rows_on_dofs
from dolfinx_nnqem.contact.laws import LawEvaluation
from dolfinx_nnqem.contact.pair_laws import PairLaws
from dolfinx_nnqem.solvers.contract import ReleasesPETSc, contact_model
from dolfinx_nnqem.solvers.convergence import IterationRecord, SolveReport, count_states, iteration_log_on, logger
from dolfinx_nnqem.numerics.linalg import free_dropped_objects, global_norm, vec_norm
from dolfinx_nnqem.numerics.newton import Globalisation, Merit, solve
from dolfinx_nnqem.numerics.roundoff import floor_note, residual_floor
from dolfinx_nnqem.numerics.nonsmooth import Fallback, NonsmoothResult, solve_dense
from dolfinx_nnqem.problem.contact_problem import ContactProblem
from dolfinx_nnqem.solvers.options import NNEQM1Options, SolverOptions
from dolfinx_nnqem.solvers.prediction import newton_right_hand_side, predict_increment
from dolfinx_nnqem.solvers.timings import Timings, summed

__all__ = ["CondensedProblem", "NNEQM1Solver", "rigid_start"]  # the first and last live in .condensed

FULL_STEPS = Globalisation(line_search=False, levenberg_marquardt=False)
"""NNEQM1's outer Newton–Raphson: every step is a solved condensed problem, taken in full."""


class NNEQM1Solver(ReleasesPETSc):
    """Nested NNEQM: contact flexibility + dense nonsmooth Newton inside Newton–Raphson.

    Parameters
    ----------
    problem
        A :class:`~dolfinx_nnqem.problem.contact_problem.ContactProblem` with contact.
    options
        Tolerances, outer iteration limit, ``petsc_options`` for the tangent solves.
    nneqm1
        This solver's own options (:class:`~dolfinx_nnqem.solvers.options.NNEQM1Options`).
    """

    name = "nneqm1"
    follows_contact_geometry = True

    def __init__(self, problem: ContactProblem, options: SolverOptions | None = None,
                 nneqm1: NNEQM1Options | None = None):
        if not problem.has_contact:
            raise ValueError("NNEQM1 solves contact problems: the problem has no Contact")
        self.problem = problem
        self.options = options or SolverOptions()
        self.settings = nneqm1 or NNEQM1Options()
        check_dense_memory(problem, self.name, self.settings.max_memory_gb)  # before anything is built
        self.condensation = Condensation(problem, self.name, self.options.petsc_options)
        self._timings = Timings()
        self.last_condensed: CondensedProblem | None = None  #: the latest outer iteration's dense problem
        self._geometry_version = contact_model(problem).geometry.version
        self._nodal: NodalFlexibility | None = None  # made at the first increment that follows the geometry

    @property
    def nodal(self) -> NodalFlexibility | None:
        """The flexibility from the unit loads of the pairs' dofs, where it is used: current-geometry
        contact, ``consistent_geometry``, not ``modified``, no free rigid mode (asked anew at every
        use: ``geometry = "auto"`` moves an interface to the current geometry during a run)."""
        settings = self.settings
        if (not settings.consistent_geometry or settings.modified or self.condensation.num_modes
                or not contact_model(self.problem).geometry.follows_bodies):
            return None
        if self._nodal is None:
            self._nodal = NodalFlexibility(self.condensation)
        return self._nodal

    @property
    def consistent_geometry(self) -> bool:
        """True if current-geometry obstacles are re-evaluated at every outer iterate, their geometric
        terms in the outer linearisation (:class:`~dolfinx_nnqem.solvers.nodal_flexibility.NodalFlexibility`)."""
        return self.nodal is not None and contact_model(self.problem).geometry.obstacles_follow

    @property
    def timings(self) -> dict[str, float]:
        """Seconds per phase: assembly, factorisation, flexibility, solve, contact."""
        return summed(self.condensation.timings, self._timings)

    def solve_increment(self, load_factor: float) -> SolveReport:
        """Solve for the load factor ``load_factor`` from the last converged state: outer Newton
        iterations on u, each with the dense nonsmooth solve of the contact problem condensed onto
        the pairs (:meth:`inner_solve`)."""
        p = self.problem
        model = contact_model(p)
        if model.geometry.version != self._geometry_version:
            # the contact geometry changed (current geometry): the flexibility C = B G Bᵀ is rebuilt
            # from the new B at the next factorisation, whether the pairing or only the rows changed
            self._geometry_version = model.geometry.version
            self.condensation.pairs_changed()
        # the outer iteration starts where the monolithic solver's Newton does: from the secant
        # extrapolation of the last two increments (u and the pair unknowns) while the load path
        # goes on in the same direction, else with the jump of the prescribed values lifted
        start = predict_increment(p, load_factor, self.settings.extrapolate)
        report = SolveReport(converged=False, iterations=0,
                             system_order=3 * p.num_pairs + self.condensation.num_modes)
        system = _OuterSystem(self, report)
        lifted = False
        if start.lift:
            p.u.x.array[p.bc_dofs] = start.u_bc
            lifted = system.lifted_step(start.delta_bc)
            if not lifted:  # its contact solve failed: the plain start, from the moved boundary
                p.apply_prescribed_displacements(load_factor)
                system.inner_failure, report.inner_states = None, None
        outcome = solve(system, FULL_STEPS, self.options.max_iterations, first_iteration=1 if lifted else 0,
                        first_kind="lifted" if lifted else "", first_step_length=1.0 if lifted else math.nan)
        report.iterations, report.converged = outcome.iterations, outcome.converged
        # every iterate was evaluated in its own geometry, and no pair can have changed: no second solve
        report.geometry_consistent = self.consistent_geometry and not model.geometry.surfaces_follow
        final = report.final
        if outcome.converged:
            report.message = "converged"
        elif system.inner_failure is not None:
            report.message = system.inner_failure
        else:
            assert final is not None  # the driver recorded the start at least
            note = system.roundoff_note()
            report.message = (f"no convergence in {self.options.max_iterations} outer iterations "
                              f"(|R|/F = {final.equilibrium:.3e}, |H|/F = {final.contact:.3e})"
                              + ("" if note is None else f": {note}"))
        return report

    def inner_solve(self, cond: CondensedProblem, laws: PairLaws, z_m: np.ndarray, tol: float,
                    scale: float) -> tuple[NonsmoothResult, CondensedSystem]:
        """Dense nonsmooth Newton/LM on x = (z, α) of the condensed problem ``cond``
        (:class:`~dolfinx_nnqem.solvers.condensed.CondensedSystem`: unknowns and rows scaled by
        the load scale F, so that the LM parameter ν = c |H̃| sees a residual and a Jacobian of
        order one). Returns the driver's result and the system (to read z and α off ``result.x``).

        The start is z_m with the free rigid modes' amplitudes that undo the predictor's rigid
        motion (:func:`~dolfinx_nnqem.solvers.condensed.rigid_start`); with free modes, then one
        Newton step with every pair's branch frozen at the outer iterate
        (:meth:`~dolfinx_nnqem.solvers.condensed.CondensedSystem.pair_rows`): the elastic
        predictor w_free is the response to the out-of-balance load before the pair forces
        change, and where that load is not in balance (a body held only by contact, whose
        generalised inverse fixes it at its fixing dofs) pairs evaluated there start on the wrong
        branch. Where every body is supported the predictor is the physical response and the
        seed's start from it is kept; the frozen-branch start is then the last fallback, tried only
        when every attempt from the predictor failed.
        """
        system = CondensedSystem(laws, cond, scale)
        x0 = system.scaled(z_m, alpha=rigid_start(cond.BN, cond.w_free))
        if system.n_r:
            x0 = newton_step(system.residual(x0, frozen=system.at(cond.w_m, z_m)), x0, system.advance)
        # The polar angles follow the slip only if the plain iteration fails: measured on the
        # robustness suite, following always costs cutbacks elsewhere (docs/robustness.md)
        fallbacks = []
        if laws.slip_following:
            fallbacks.append(Fallback("with the polar angles on the slip", system.on_the_slip(x0),
                                      system.advance_on_the_slip))
        # Last, where every body is supported: from the laws linearised at the outer iterate (a
        # floating body's x0 is that already). The predictor can open pairs the increment keeps
        # pressed; a full step then takes all their force away, every pair penetrates, and from
        # there the polar law's iteration can fail with every attempt (docs/theory.md, NNEQM1)
        if not system.n_r:
            fallbacks.append(Fallback(
                "from the outer iterate's pair states",
                lambda: newton_step(system.residual(x0, frozen=system.at(cond.w_m, z_m)), x0, system.advance),
                system.advance))
        result = solve_dense(system.residual, x0, tol=tol / scale, max_iter=self.settings.inner_max_iterations,
                             globalisations=self.settings.inner_globalisations, advance=system.advance,
                             fallback=fallbacks)
        return result, system

    def destroy(self) -> None:
        """Free the condensation's PETSc objects (collective)."""
        self.condensation.destroy()


_Evaluation = tuple[PETSc.Vec, np.ndarray, LawEvaluation, float, float, float]
"""The outer iterate's (R_free, w, law, F, |R_free|, |H|)."""


class _OuterSystem:
    """NNEQM1's outer Newton–Raphson as a backend of the Newton driver (full steps only)."""

    def __init__(self, solver: NNEQM1Solver, report: SolveReport):
        self.solver = solver
        self.problem = solver.problem
        self.contact = contact_model(self.problem)  # the problem's, which NNEQM1Solver asks for
        self.report = report
        self.consistent = solver.consistent_geometry  # fixed for the solve
        self.laws = self.contact.gathered_laws()
        self.w_prev = self.contact.gather(self.contact.w_n)
        self.steps = 0
        self.inner_iterations = 0
        self.inner_failure: str | None = None
        self.current: _Evaluation | None = None  #: set by evaluate()
        self._count_plastic = iteration_log_on(self.problem.comm)  # trial plastic points, for the log only
        self._step: tuple[np.ndarray, np.ndarray] | None = None  #: (du, z_new), set by newton_direction

    def evaluate(self) -> Merit:
        p, s = self.problem, self.solver
        if self.consistent:  # the obstacles' pairs at this iterate: their frames, gaps, w_n and laws
            self.contact.geometry.refresh_obstacles(p.u, p.load_factor, p.state.u_n, p.load_factor_n)
            self.laws = self.contact.gathered_laws()
            self.w_prev = self.contact.gather(self.contact.w_n)
        t0 = time.perf_counter()
        F_int = p.assemble_internal_force()
        s._timings.add("assembly", t0)
        R_free = p.free_residual(p.residual(F_int=F_int))
        w = p.relative_displacement()
        law = self.contact.evaluate(w)
        scale = p.force_scale(F_int)
        norm_R, norm_H = vec_norm(R_free), global_norm(law.H, p.comm)
        self.current = (R_free, w, law, scale, norm_R, norm_H)
        opts = s.options
        tol = opts.rtol * scale + opts.atol
        return Merit(0.5 * (norm_R ** 2 + norm_H ** 2), norm_R <= tol and norm_H <= tol)

    def record(self, iteration: int, step_length: float, kind: str) -> None:
        p = self.problem
        free_dropped_objects(p.petsc_comms)  # once per iteration, on every rank
        assert self.current is not None  # the driver evaluates before it records
        _, _, law, scale, norm_R, norm_H = self.current
        ref = scale  # F, as the independent check has it (atol is no scale: issue 31)
        plastic = p.state.count_trial_plastic_points(p.u) if self._count_plastic else None
        record = IterationRecord(iteration, norm_R / ref, norm_H / ref, step_length, "newton" if iteration else "",
                                 count_states(law.state, p.comm), plastic, self.inner_iterations)
        self.report.history.append(record)
        logger.info(record.line(self.solver.name))

    def snapshot(self):
        return self.problem.u.x.array.copy(), self.contact.z.copy(), self.current

    def restore(self, snapshot) -> Merit:
        u, z, self.current = snapshot
        self.problem.u.x.array[:] = u
        self.contact.z = z.copy()
        return self.evaluate()

    def start_step(self) -> None:
        """Nothing to keep: every step is taken in full."""

    def lifted_step(self, delta_bc: np.ndarray) -> bool:
        """The first outer iteration from the converged state, the prescribed jump ``delta_bc``
        (at ``problem.bc_dofs``) lifted; the iterate then holds the new prescribed values.

        Returns False (and sets :attr:`inner_failure`) when the condensed contact solve failed;
        the iterate is then the converged state.
        """
        p = self.problem
        self.evaluate()
        delta = np.zeros_like(p.u.x.array)
        delta[p.bc_dofs] = delta_bc
        if self.newton_direction(None, lift=delta) is not None:
            return False
        self.move(1.0)
        return True

    def newton_direction(self, merit: Merit | None, lift: np.ndarray | None = None) -> str | None:
        """One condensed contact solve: the step (du, z_new).

        ``lift``: a jump of the prescribed displacements (local array, zero off the constrained
        dofs) that the step makes, with K_t δ on the right-hand side (:meth:`lifted_step`).
        """
        p, s, cond_solver = self.problem, self.solver, self.solver.condensation
        model = self.contact
        assert self.current is not None  # evaluate() ran at this iterate
        R_free, w, _, scale, _, _ = self.current
        r = newton_right_hand_side(p, R_free, lift)
        nodal = s.nodal
        if nodal is not None:
            C, w_free, du_free, response = self._nodal_condensation(nodal, r)
        else:
            if not (s.settings.modified and self.steps > 0):
                cond_solver.factorise(p.assemble_tangent, "the tangent stiffness K_t")
                self._X, self._C = cond_solver.pair_flexibility()
            x_r = cond_solver.solve(r)
            C, w_free = self._C, model.gather(model.B_times(x_r)).reshape(-1)
            du_free = x_r.getArray(readonly=True).copy()
            x_r.destroy()
            X = self._X

            def response(dlam: np.ndarray) -> np.ndarray:
                return X @ dlam
        z_m = model.gather(model.z)
        lam_m, _ = self.laws.force(z_m)
        cond = CondensedProblem(
            C=C, w_free=w_free, w_m=model.gather(w).reshape(-1),
            lam_m=lam_m.reshape(-1), mu_f=self.laws.mu_f, g0=self.laws.g0, w_prev=self.w_prev,
            r=self.laws.r_max, BN=cond_solver.mode_coupling(),
            e=cond_solver.mode_loads(r))
        s.last_condensed = cond
        opts = s.options
        tol = opts.rtol * scale + opts.atol
        t0 = time.perf_counter()
        result, system = s.inner_solve(cond, self.laws, z_m, tol, max(tol / max(opts.rtol, 1e-300), 1e-300))
        s._timings.add("contact", t0)
        self.inner_iterations = result.iterations
        if not result.converged:
            self.inner_failure = f"inner nonsmooth solve failed at outer iteration {self.steps}: {result.message}"
            # where its pairs were (slipping, say): the outer iterate keeps the states it started from
            states = np.bincount(system.pair_rows(result.x).state.astype(np.int64), minlength=3)[:3]
            self.report.inner_states = (int(states[0]), int(states[1]), int(states[2]))  # gathered: every rank's
            return self.inner_failure
        z_new = system.pair_unknowns(result.x)
        lam_new, _ = self.laws.force(z_new)
        du = du_free + response(lam_new.reshape(-1) - cond.lam_m)
        if cond_solver.num_modes:
            du += cond_solver.mode_array() @ system.modes(result.x)
        self._step = (du, model.local_rows(z_new).copy())
        return None

    def _nodal_condensation(self, nodal: NodalFlexibility, r: PETSc.Vec):
        """(C, w_free, du_free, response) of the Newton right-hand side ``r`` from the unit loads of the
        pairs' dofs (:mod:`~dolfinx_nnqem.solvers.nodal_flexibility`): the flexibility, the free
        response's w and du, and the map of a pair force change Δλ (3NC,) to its du. With
        :attr:`consistent`, of the outer linearisation with the obstacles' geometric terms."""
        p, model, condensation = self.problem, self.contact, self.solver.condensation
        condensation.refactorise(p.assemble_tangent, "the tangent stiffness K_t")
        positions = nodal.update()
        t0 = time.perf_counter()
        D = nodal.dofs[positions]
        B_D = rows_on_dofs(model, model.rows.values, D)
        Bc_D, update = B_D, None
        if self.consistent:
            terms = model.geometry.geometric_terms(p.u, p.load_factor, p.state.u_n, p.load_factor_n)
            Bc_D = rows_on_dofs(model, terms.rows_values(model.rows), D)
            update = nodal.geometric_update(terms, positions)
        C = nodal.flexibility(positions, B_D, Bc_D, update)
        condensation.timings.add("flexibility", t0)
        x_r = condensation.solve(r)
        du_free, x_D = nodal.free_response(x_r, positions, update)
        x_r.destroy()

        def response(dlam: np.ndarray) -> np.ndarray:
            return nodal.response(B_D.T @ dlam, positions, update)

        return C, Bc_D @ x_D, du_free, response

    def lm_direction(self, merit: Merit, globalisation: Globalisation) -> str | None:
        return "NNEQM1's outer iteration has no Levenberg–Marquardt step"

    def slope(self) -> float:
        return math.nan  # never asked: the outer iteration takes full steps

    def roundoff_note(self) -> str | None:
        """Round-off, when the pair laws have converged and |R|/F stopped at its floor: the rounding
        of u times K_t (as the monolithic solver's, :mod:`dolfinx_nnqem.numerics.roundoff`)."""
        condensation = self.solver.condensation
        if self.current is None or not condensation.factorised:
            return None
        _, _, _, scale, norm_R, norm_H = self.current
        opts = self.solver.options
        if norm_H > opts.rtol * scale + opts.atol:
            return None  # the contact rows stop it: not the equilibrium's round-off
        p = self.problem
        floor = residual_floor(condensation.K, p.u.x.petsc_vec, p.free_residual)
        return floor_note("|R|/F", norm_R / scale, floor / scale, opts.rtol)

    def move(self, step_length: float) -> Merit:
        p = self.problem
        assert self._step is not None  # newton_direction made it
        du, z_new = self._step
        n_u = du.shape[0]
        p.u.x.array[:n_u] += step_length * du
        p.u.x.scatter_forward()
        self.contact.z = z_new
        self.steps += 1
        return self.evaluate()

