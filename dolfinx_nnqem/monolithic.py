"""Monolithic semismooth Newton on (u, z): the scalable solver (``formulation.md`` §5).

Per iteration, with R = F_int(u) − F_ext(ℓ) − Bᵀλ(z) and H = H(Bu, z):

    [ K_t(u)     −Bᵀ Λ' ] [du]     [ R ]
    [ ∂_wH · B   ∂_zH   ] [dz] = − [ H ]

solved by PETSc (MUMPS LU by default; any KSP/PC through ``petsc_options``). Globalisation:
Armijo backtracking on Ψ = ½(‖R‖² + ‖H‖²) — both in force units, so no row scaling is
needed — with a watchdog that lets full Newton steps through when the pair states change, and a
Levenberg–Marquardt step (JᵀJ + ν I) d = −JᵀF when the Newton step fails the
line search or the factorisation (the polar law's (p_r, θ) parametrisation is singular at
p_r = 0). Without contact this is Newton–Raphson with the consistent tangent.
"""

from __future__ import annotations

import math
import time

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.block_system import AugmentedSystem, contact_jacobian_blocks, monolithic_matrix
from dolfinx_nnqem.convergence import IterationRecord, SolveReport, count_states, logger
from dolfinx_nnqem.linalg import (ITERATIVE_NO_CONTACT_OPTIONS, ITERATIVE_SOLVER_OPTIONS, create_ksp,
                                  free_dropped_objects, global_norm, rigid_body_modes, set_options)
from dolfinx_nnqem.problem import ContactProblem, SolverOptions


class MonolithicSolver:
    """Semismooth Newton on the displacement and the pair unknowns together.

    Parameters
    ----------
    problem
        The problem to solve.
    options
        Tolerances and ``petsc_options`` (merged over MUMPS LU,
        :data:`dolfinx_nnqem.linalg.DIRECT_SOLVER_OPTIONS`).
    armijo
        Sufficient-decrease constant of the line search.
    min_step
        Smallest line-search step before switching to Levenberg–Marquardt.
    lm_c, lm_delta
        ν = lm_c · min(ε, 1)^lm_delta · mean diag(JᵀJ), ε the relative residual.
    watchdog
        Full Newton steps accepted in a row although Ψ grows (Chamberlain's watchdog). A
        change of pair state makes Ψ jump — an open pair's trial penetration enters H as
        r·g — although the step is exactly the one semismooth Newton needs; after
        ``watchdog`` such steps without a new best Ψ the solver returns to the best iterate
        and takes monotone (line-searched) steps from there.
    max_increase
        A full step is let through by the watchdog only if Ψ grows by at most this factor
        (|H| by its square root): a penetration of a few element sizes' worth of r·g, not the
        near-infinite step of a nearly singular Jacobian (the polar law at p_r = 0).
    augmentation
        Iterative solver only: the penalty added to the u block on closed pair directions, in
        units of r (:class:`dolfinx_nnqem.block_system.AugmentedSystem`). It changes the
        preconditioner, not the Newton step.
    lag_preconditioner
        Iterative solver with contact: keep the u block's AMG hierarchy while it works
        (rebuilt when 5 % of the pairs changed state, or a solve converges poorly).
    """

    name = "monolithic"

    def __init__(self, problem: ContactProblem, options: SolverOptions | None = None, *,
                 armijo: float = 1e-4, min_step: float = 1.0 / 64, lm_c: float = 1.0,
                 lm_delta: float = 1.0, watchdog: int = 6, max_increase: float = 1e8,
                 augmentation: float = 1.0, lag_preconditioner: bool = True):
        self.problem = problem
        self.options = options or SolverOptions()
        self.armijo, self.min_step, self.lm_c, self.lm_delta = armijo, min_step, lm_c, lm_delta
        self.watchdog = watchdog
        self.max_increase = max_increase
        if not (math.isfinite(augmentation) and augmentation > 0):
            raise ValueError(f"MonolithicSolver: augmentation = {augmentation!r}; expected a finite value > 0 "
                             "(the u block's penalty on closed pair directions, in units of r)")
        self.prefix = f"nnqem_monolithic_{id(self)}_"
        self.iterative = self._use_iterative()
        if self.iterative:
            defaults = ITERATIVE_SOLVER_OPTIONS if problem.has_contact else ITERATIVE_NO_CONTACT_OPTIONS
            set_options(self.prefix, defaults)
        self.ksp = create_ksp(problem.comm, self.prefix, self.options.petsc_options,
                              defaults=not self.iterative)
        self._ksp_rtol_floor, _, _, self._ksp_max_it = self.ksp.getTolerances()
        self._fieldsplit_ready = False
        self._K = None
        self._augmented = None
        self._lagging = self.iterative and problem.has_contact and lag_preconditioner
        self.refresh_fraction = 0.05
        self.amg_setups = 0  # AMG hierarchies built (iterative solver with contact)
        self._refresh_u_pc = True
        self._lag_state = None
        self._fresh_rate = None  # Krylov convergence rate right after the last AMG set-up
        self._last_forcing = None  # (ε, η) of the last inexact Newton step (iterative solver)
        if self.iterative and problem.has_contact:
            self._augmented = AugmentedSystem(problem.pairs, problem.constrained_rows(), problem.r,
                                              augmentation)
        self.timings: dict[str, float] = {}
        self.linear_iterations = 0  # Krylov iterations over all Newton steps (iterative solver)

    def _use_iterative(self) -> bool:
        choice = self.options.linear_solver
        if choice not in ("direct", "iterative", "auto"):
            raise ValueError(f"linear_solver = {choice!r}: expected 'direct', 'iterative' or 'auto'")
        if choice == "auto":
            return self.problem.V.dofmap.index_map.size_global * 3 >= self.options.auto_iterative_dofs
        return choice == "iterative"

    def _configure_iterative(self, J: PETSc.Mat) -> None:
        """Field split (u, z) and the rigid-body near-nullspace for GAMG, once."""
        p = self.problem
        if self._fieldsplit_ready:
            return
        nullspace = rigid_body_modes(p.V)
        if not p.has_contact:
            J.setNearNullSpace(nullspace)
            self._fieldsplit_ready = True  # K is assembled into the same matrix every iteration
            self._keep = (nullspace,)
            return
        (is_u, is_z), _ = J.getNestISs()
        is_u.compose("nearnullspace", nullspace)  # PCFIELDSPLIT passes it to the u block's GAMG
        pc = self.ksp.getPC()
        pc.setFieldSplitIS(("u", is_u), ("z", is_z))
        self._fieldsplit_ready = True
        self._keep = (is_u, is_z, nullspace)

    # -- residual and merit ----------------------------------------------------------------------
    def _evaluate(self):
        """R (full), free part, H, law evaluation, and the load scale at the current iterate."""
        p = self.problem
        t0 = time.perf_counter()
        F_int = p.assemble_internal_force()
        self._tick("assembly", t0)
        R = p.residual(F_int=F_int)
        R_free = p.free_residual(R)
        ev = None
        H = np.zeros((0, 3))
        if p.has_contact:
            t0 = time.perf_counter()
            w = p.relative_displacement()
            ev = p.evaluate_law(w, p.z)
            H = ev.H
            self._tick("contact", t0)
        scale = self._load_scale(F_int)
        return R, R_free, H, ev, scale

    def _load_scale(self, F_int: PETSc.Vec) -> float:
        p = self.problem
        s = max(p.external_force().norm(), F_int.norm())
        if p.has_contact:
            s = max(s, p.pairs.global_force(p.contact_force()).norm())
        return s

    def _norm_H(self, H: np.ndarray) -> float:
        return global_norm(H, self.problem.comm)

    # -- one increment --------------------------------------------------------------------------
    def solve_increment(self, load_factor: float) -> SolveReport:
        """Solve for the load factor ``load_factor`` from the last converged state."""
        p = self.problem
        opts = self.options
        report = SolveReport(converged=False, iterations=0,
                             system_order=p.V.dofmap.index_map.size_global * 3 + 3 * p.num_pairs)
        self._last_forcing = None  # (ε, η) of the last Newton step of this increment
        lifted = self._predict(load_factor)
        step_length, kind = (1.0, "lifted") if lifted else (float("nan"), "")
        first = 1 if lifted else 0
        R, R_free, H, ev, scale = self._evaluate()
        best = None  # (Ψ, u, z) of the best iterate so far (watchdog)
        nonmonotone = 0  # full steps accepted in a row without decreasing Ψ below the best
        for it in range(first, opts.max_iterations + 1):
            free_dropped_objects(p.petsc_comms)
            normR, normH = R_free.norm(), self._norm_H(H)
            if not (math.isfinite(normR) and math.isfinite(normH)):
                report.message = f"NaN/inf residual at iteration {it} (|R| = {normR}, |H| = {normH})"
                return report
            ref = max(scale, opts.atol)
            states = count_states(ev.state, p.comm) if ev is not None else (0, 0, 0)
            record = IterationRecord(it, normR / ref, normH / ref, step_length, kind, states,
                                     p.state.count_trial_plastic_points(p.u))
            report.history.append(record)
            logger.info(record.line(self.name))
            report.iterations = it
            if normR <= opts.rtol * scale + opts.atol and normH <= opts.rtol * scale + opts.atol:
                report.converged = True
                report.message = "converged"
                return report
            if it == opts.max_iterations:
                break
            psi = 0.5 * (normR ** 2 + normH ** 2)
            if best is None or psi < (1.0 - 2.0 * self.armijo) * best[0]:
                best = (psi, p.u.x.array.copy(), p.z.copy() if p.has_contact else None)
                nonmonotone = 0
            elif nonmonotone >= self.watchdog:
                # the watchdog ran out: back to the best iterate, monotone steps from there
                self._restore_snapshot(best)
                R, R_free, H, ev, scale = self._evaluate()
                normR, normH = R_free.norm(), self._norm_H(H)
                nonmonotone = -1  # one monotone step before full steps are allowed again
            self._u0 = p.u.x.array[:R_free.getLocalSize()].copy()  # the iterate the step starts from
            self._z0 = p.z.copy() if p.has_contact else None
            if self.iterative:
                self._set_forcing(math.sqrt(normR ** 2 + normH ** 2) / ref)
            du, dz = self._newton_direction(R_free, H, ev)
            kind = "newton"
            alpha = None
            if du is not None:
                alpha = self._line_search(du, dz, normR, normH, allow_increase=nonmonotone >= 0)
            if alpha is None:
                kind = "lm"
                self._restore_iterate()
                du, dz = self._lm_direction(R_free, H, ev, ref)
                alpha = self._line_search(du, dz, normR, normH, accept_any=True)
            elif alpha < 0:  # a full step accepted without decrease
                kind, alpha = "full", 1.0
            nonmonotone += 1
            step_length = alpha
            R, R_free, H, ev, scale = self._accepted or self._evaluate()
        report.message = (f"no convergence in {opts.max_iterations} iterations "
                          f"(|R|/F = {report.final.equilibrium:.3e}, |H|/F = {report.final.contact:.3e})")
        return report

    def _predict(self, load_factor: float) -> bool:
        """The increment's starting point; True if it was reached by a lifted Newton step.

        The secant predictor when the load path goes on in the same direction; otherwise, if
        prescribed displacements move, a Newton step from the converged state with their jump
        lifted (:meth:`_lifted_step`); otherwise the converged state.
        """
        p = self.problem
        extrapolated = self.options.extrapolate and p.extrapolate(load_factor)
        u_bc = p.u.x.array[p.bc_dofs].copy()
        p.apply_prescribed_displacements(load_factor)
        p.predict_contact()
        delta_bc = p.u.x.array[p.bc_dofs] - u_bc
        if extrapolated or not p.comm.allreduce(bool(np.any(delta_bc != 0.0)), op=MPI.LOR):
            return False
        p.u.x.array[p.bc_dofs] = u_bc
        _, R_free, H, ev, _ = self._evaluate()
        if self._lifted_step(R_free, H, ev, delta_bc):
            return True
        p.apply_prescribed_displacements(load_factor)  # the solve failed: plain Newton from here
        return False

    def _lifted_step(self, R_free, H, ev, delta_bc: np.ndarray) -> bool:
        """Newton step from the converged state that moves the constrained dofs by ``delta_bc``.

        J du = −F − J_c Δu_D with du = Δu_D at the constrained dofs: the tangent (and the pair
        laws) evaluated where the solution is, not at a state whose boundary layer alone has been
        moved (which, in a plastic body, yields spuriously and misleads the first step). The
        step is taken in full, without line search (its start is not an admissible state).
        Returns False if the linear solve failed.
        """
        p = self.problem
        delta = np.zeros_like(p.u.x.array)
        delta[p.bc_dofs] = delta_bc
        K_delta = p.tangent_action(delta)
        R_lifted = self._free(R_free, K_delta)
        H_lifted = H
        if p.has_contact:
            dw = p.pairs.relative_displacement(self._as_vec(delta))
            H_lifted = H + np.einsum("nij,nj->ni", ev.dH_dw, dw)
        if self.iterative:
            self._set_forcing(1.0, record=False)  # the lifted system's residual is not the iterate's
        self._u0 = p.u.x.array[:R_free.getLocalSize()].copy()
        self._z0 = p.z.copy() if p.has_contact else None
        du, dz = self._newton_direction(R_lifted, H_lifted, ev)
        if du is None:
            return False
        self._set_iterate(self._u0, self._z0, du, dz, 1.0)
        p.u.x.array[p.bc_dofs] += delta_bc
        return True

    def _free(self, R_free: PETSc.Vec, K_delta: PETSc.Vec) -> PETSc.Vec:
        """R_free + K_δ with the constrained rows zeroed."""
        out = self.problem.free_residual(K_delta)
        out.axpy(1.0, R_free)
        return out

    def _as_vec(self, array: np.ndarray) -> PETSc.Vec:
        p = self.problem
        v = p.u.x.petsc_vec.duplicate()
        with v.localForm() as local:
            local.array[:] = array
        return v

    def _restore_snapshot(self, snapshot) -> None:
        p = self.problem
        p.u.x.array[:] = snapshot[1]
        if p.has_contact:
            p.z = snapshot[2].copy()

    # -- directions ---------------------------------------------------------------------------------
    def _jacobian(self, ev) -> PETSc.Mat:
        p = self.problem
        t0 = time.perf_counter()
        self._K = p.assemble_tangent(self._K)
        self._tick("assembly", t0)
        if not p.has_contact:
            return self._K
        t0 = time.perf_counter()
        _, dlam_dz = p.law.force(p.z)
        rows = p.constrained_rows()
        blocks = contact_jacobian_blocks(p.pairs, ev.dH_dw, ev.dH_dz, dlam_dz, rows)
        J = monolithic_matrix(self._K, blocks)
        self._tick("block_matrix", t0)
        return J

    def _rhs(self, J: PETSc.Mat, R_free: PETSc.Vec, H: np.ndarray) -> PETSc.Vec:
        b = J.createVecRight()
        n_u = R_free.getLocalSize()
        arr = b.getArray()
        arr[:n_u] = -R_free.getArray()
        arr[n_u:] = -H.reshape(-1)
        return b

    def _split(self, x: PETSc.Vec, n_u: int):
        """(du, dz) from the solution vector, du = 0 exactly at the constrained dofs.

        The matrix has identity rows there and the right-hand side zeros, but a Krylov solve
        (and an inexact one above all) returns them only to its tolerance; left alone, the
        prescribed values would drift, unseen by the free residual.
        """
        arr = x.getArray(readonly=True)
        du = arr[:n_u].copy()
        du[self.problem.owned_bc_dofs()] = 0.0
        return du, arr[n_u:].reshape(-1, 3).copy()

    def _lag_u_preconditioner(self) -> None:
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
        state = self._pair_state
        if self._lag_state is None or self._lag_state.shape != state.shape or self._fresh_rate is None:
            self._refresh_u_pc = True
        else:
            changed = self.problem.comm.allreduce(int(np.count_nonzero(state != self._lag_state)), op=MPI.SUM)
            if changed > self.refresh_fraction * self.problem.num_pairs:
                self._refresh_u_pc = True
        ksp_u = self.ksp.getPC().getFieldSplitSubKSP()[0]
        ksp_u.getPC().setReusePreconditioner(not self._refresh_u_pc)
        if self._refresh_u_pc:
            self._lag_state = state.copy()
            self.amg_setups += 1
            self.ksp.setTolerances(max_it=self._ksp_max_it)
        else:
            rtol = self.ksp.getTolerances()[0]
            expected = math.log(rtol) / math.log(self._fresh_rate)
            self.ksp.setTolerances(max_it=int(2 * expected) + 5)
        self._lag_refreshed = self._refresh_u_pc
        self._refresh_u_pc = False

    def _lagged_solve_is_poor(self, b: PETSc.Vec) -> bool:
        """True if this solve used a lagged hierarchy and did not converge within its budget."""
        if self._lag_refreshed:
            its = max(self.ksp.getIterationNumber(), 1)
            reduction = self.ksp.getResidualNorm() / max(b.norm(), 1e-300)
            self._fresh_rate = min(max(reduction ** (1.0 / its), 1e-3), 0.95)
            return False
        return self.ksp.getConvergedReason() <= 0

    def _set_forcing(self, eps: float, record: bool = True) -> None:
        """Inexact Newton: Krylov tolerance η = min(max(ε², 0.1·rtol/ε), 1e-2), ε the relative residual.

        η = O(ε) keeps Newton's local order (Dembo–Eisenstat–Steihaug); ε² leaves the step as
        good as an exact one where the quadratic term dominates, and 0.1·rtol/ε is just the
        accuracy that lets the step reach the tolerance. Early iterations, far from the
        solution, are not solved to full accuracy. Never below ``ksp_rtol`` of the options.

        If the last step (``record``-ed, in this increment) cut the residual by no less than its
        Krylov tolerance allowed (ε ≤ 2 η_prev ε_prev), the problem behaves linearly here (an
        elastic increment, no pair changing state): η = 0.1·rtol/ε, so that this step finishes
        the increment instead of taking ε² and one more Newton iteration for the same Krylov work.
        """
        rtol = self.options.rtol
        eta = min(max(eps * eps, 0.1 * rtol / max(eps, 1e-300)), 1e-2)
        if self._last_forcing is not None:
            eps_prev, eta_prev = self._last_forcing
            if eps <= 2.0 * eta_prev * eps_prev:
                eta = min(eta, 0.1 * rtol / max(eps, 1e-300))
        eta = max(eta, self._ksp_rtol_floor)
        self._last_forcing = (eps, eta) if record else None
        self.ksp.setTolerances(rtol=eta)

    def _augmented_system(self, R_free, H, ev):
        """The augmented Newton system (iterative solver with contact): (MatNest, rhs)."""
        p = self.problem
        self._pair_state = ev.state
        t0 = time.perf_counter()
        self._K = p.assemble_tangent(self._K)
        self._tick("assembly", t0)
        t0 = time.perf_counter()
        _, dlam_dz = p.law.force(p.z)
        J = self._augmented.matrix(self._K, ev.dH_dw, ev.dH_dz, dlam_dz)
        b = self._augmented.rhs(R_free, H, ev.dH_dw)
        self._tick("block_matrix", t0)
        return J, b

    def _newton_direction(self, R_free, H, ev):
        """Solve J d = −F; returns (du, dz) as arrays, or (None, None) if the solve failed."""
        if self._augmented is not None:
            J, b = self._augmented_system(R_free, H, ev)
        else:
            J = self._jacobian(ev)
            b = self._rhs(J, R_free, H)
        x = b.duplicate()
        self.ksp.setOperators(J)
        if self.iterative:
            self._configure_iterative(J)
        if not self._krylov_solve(b, x):
            return None, None
        if self._lagging and self._lagged_solve_is_poor(b):
            # the lagged AMG hierarchy no longer fits K + BᵀPB: rebuild it, solve the same system again
            self._refresh_u_pc = True
            if not self._krylov_solve(b, x):
                return None, None
            self._lagged_solve_is_poor(b)  # records the fresh hierarchy's convergence rate
        if self.ksp.getConvergedReason() <= 0 or not np.all(np.isfinite(x.getArray(readonly=True))):
            logger.info(f"{self.name}: linear solve failed, KSP reason {self.ksp.getConvergedReason()}")
            return None, None
        return self._split(x, R_free.getLocalSize())

    def _krylov_solve(self, b: PETSc.Vec, x: PETSc.Vec) -> bool:
        """Set up (lagging the u block's AMG where it may) and solve; False on a PETSc error."""
        t0 = time.perf_counter()
        try:
            self.ksp.setUp()
            self._lag_u_preconditioner()
            self._tick("setup", t0)
            t0 = time.perf_counter()
            self.ksp.solve(b, x)
        except PETSc.Error:
            self._refresh_u_pc = True  # whatever failed, do not lag from it
            return False
        finally:
            self._tick("solve", t0)
        self.linear_iterations += self.ksp.getIterationNumber()
        return True

    def _lm_direction(self, R_free, H, ev, ref: float):
        """Levenberg–Marquardt: (JᵀJ + ν I) d = −JᵀF, ν = lm_c · min(ε, 1)^lm_delta · mean diag(JᵀJ)."""
        J = self._jacobian(ev)
        F = self._rhs(J, R_free, H)  # = −F
        JtJ = J.transposeMatMult(J)
        diag = JtJ.getDiagonal()
        mean_diag = diag.sum() / max(diag.getSize(), 1)
        eps = math.sqrt(R_free.norm() ** 2 + self._norm_H(H) ** 2) / ref
        JtJ.shift(self.lm_c * min(eps, 1.0) ** self.lm_delta * mean_diag)
        rhs = JtJ.createVecRight()
        J.multTranspose(F, rhs)
        x = rhs.duplicate()
        # LM solves JᵀJ directly (MUMPS) whatever the Newton solver: it is the rare fallback
        ksp = create_ksp(self.problem.comm, self.prefix + "lm_", {})
        ksp.setOperators(JtJ)
        ksp.solve(rhs, x)
        ksp.destroy()
        return self._split(x, R_free.getLocalSize())

    # -- line search -----------------------------------------------------------------------------
    def _set_iterate(self, u0, z0, du, dz, alpha):
        p = self.problem
        n_u = du.shape[0]
        p.u.x.array[:n_u] = u0 + alpha * du
        p.u.x.scatter_forward()
        if p.has_contact:
            p.z = z0 + alpha * dz

    def _restore_iterate(self):
        p = self.problem
        n_u = self._u0.shape[0]
        p.u.x.array[:n_u] = self._u0
        p.u.x.scatter_forward()
        if p.has_contact:
            p.z = self._z0.copy()

    def _line_search(self, du, dz, normR, normH, accept_any: bool = False,
                     allow_increase: bool = False) -> float | None:
        """Armijo backtracking on Ψ; returns α, or None when α fell below ``min_step``.

        With ``allow_increase`` a finite full step that fails the Armijo test is accepted
        anyway and −1 is returned (the watchdog decides later whether to keep it).
        """
        psi0 = 0.5 * (normR ** 2 + normH ** 2)
        alpha = 1.0
        self._accepted = None  # the evaluation at the accepted iterate, reused by the caller
        while True:
            self._set_iterate(self._u0, self._z0, du, dz, alpha)
            evaluation = self._evaluate()
            _, R_free, H, _, _ = evaluation
            psi = 0.5 * (R_free.norm() ** 2 + self._norm_H(H) ** 2)
            if math.isfinite(psi) and psi <= (1.0 - 2.0 * self.armijo * alpha) * psi0:
                self._accepted = evaluation
                return alpha
            if allow_increase and alpha == 1.0 and psi <= self.max_increase * psi0:
                self._accepted = evaluation
                return -1.0
            alpha *= 0.5
            if alpha < self.min_step:
                if accept_any:
                    # LM direction is a descent direction; take the smallest tried step
                    self._set_iterate(self._u0, self._z0, du, dz, alpha * 2)
                    return alpha * 2
                return None

    def _tick(self, key: str, t0: float) -> None:
        self.timings[key] = self.timings.get(key, 0.0) + time.perf_counter() - t0
