"""NNEQM1: a nonsmooth Newton on the contact unknowns nested in Newton–Raphson (seed §3).

For the load factor ℓ of an increment, outer iteration m (``formulation.md`` §5):

1. r_m = F_ext(ℓ) − F_int(u_m) + Bᵀλ_m (constrained rows zero);
2. one factorisation of the consistent tangent K_m; X = K_m⁻¹ Bᵀ (3NC right-hand sides
   solved together, KSPMatSolve), the contact flexibility C_m = B X (dense, 3NC × 3NC) and
   x_r = K_m⁻¹ r_m, w_free = B x_r;
3. inner: H(w(z), z) = 0 with w(z) = B u_m + w_free + C_m (λ(z) − λ_m), a dense nonsmooth system
   of order 3NC, by :func:`dolfinx_nnqem.nonsmooth.solve_nonsmooth` (Newton, Armijo, LM);
4. du = x_r + X (λ − λ_m); u ← u + du, then the return map at the Gauss points;
5. converged when ‖R‖ and ‖H‖ are below tolerance relative to the load scale.

``modified=True`` keeps K, X and C from the first iteration of the increment (modified
Newton): cheaper iterations, linear convergence.

The dense contact problem is small (3NC); every rank solves it redundantly with the same data,
so all ranks take the same decisions.
"""

from __future__ import annotations

import math
import time

import numpy as np
from petsc4py import PETSc

from dolfinx_nnqem.contact.laws import pin_constrained_directions
from dolfinx_nnqem.convergence import IterationRecord, SolveReport, count_states, logger
from dolfinx_nnqem.linalg import create_ksp, factorise, free_dropped_objects, global_norm
from dolfinx_nnqem.nonsmooth import solve_nonsmooth
from dolfinx_nnqem.problem import ContactProblem, SolverOptions


class NNEQM1Solver:
    """Nested NNEQM: contact flexibility + dense nonsmooth Newton inside Newton–Raphson.

    Parameters
    ----------
    problem
        A :class:`~dolfinx_nnqem.problem.ContactProblem` with contact.
    options
        Tolerances, outer iteration limit, ``petsc_options`` for the tangent solves.
    modified
        Keep K and C from the start of the increment (modified Newton).
    inner_max_iterations
        Iteration limit of the dense nonsmooth solve.
    """

    name = "nneqm1"

    def __init__(self, problem: ContactProblem, options: SolverOptions | None = None, *,
                 modified: bool = False, inner_max_iterations: int = 100):
        if not problem.has_contact:
            raise ValueError("NNEQM1 solves contact problems: the problem has no Contact")
        self.problem = problem
        self.options = options or SolverOptions()
        self.modified = modified
        self.inner_max_iterations = inner_max_iterations
        self.ksp = create_ksp(problem.comm, f"nnqem_nneqm1_{id(self)}_", self.options.petsc_options)
        self._K = None
        self.timings: dict[str, float] = {}
        self.last_condensed = None  # (C, w_free, w_m, lam_m, ...) of the latest outer iteration

    # -- gathered pair data (global order, every rank) ----------------------------------------------
    def _gather_pairs(self):
        p = self.problem
        pairs = p.pairs
        g = pairs.gather(np.hstack([p.w_n, p.pairs.g0[:, None], p.mu_f[:, None], p.z,
                                    p.constrained_directions.astype(float)]))
        self._constrained = g[:, 8:11] > 0.5
        return g[:, 0:3], g[:, 3], g[:, 4], g[:, 5:8]

    def _local_rows(self, array_global: np.ndarray) -> np.ndarray:
        pairs = self.problem.pairs
        return array_global[pairs.offset:pairs.offset + pairs.num_local]

    # -- flexibility ---------------------------------------------------------------------------------
    def _factorise_and_condense(self):
        """Factor K_m; X = K⁻¹Bᵀ (dense, local rows), C = B X gathered to every rank."""
        p = self.problem
        t0 = time.perf_counter()
        self._K = p.assemble_tangent(self._K)
        self._tick("assembly", t0)
        t0 = time.perf_counter()
        factorise(self.ksp, self._K, "NNEQM1", "the stiffness K")
        self._tick("factorisation", t0)
        t0 = time.perf_counter()
        Bt = p.transposed_B()
        Bt_dense = Bt.convert("dense")
        X = Bt_dense.duplicate()
        self.ksp.matSolve(Bt_dense, X)
        C_local_rows = p.pairs.B.matMult(X)
        nc = p.num_pairs
        # (3 rows per owned pair) × 3NC, regrouped per pair for the gather (a rank may own none)
        C_rows = C_local_rows.getDenseArray().reshape(p.pairs.num_local, 9 * nc)
        C = p.pairs.gather(C_rows).reshape(3 * nc, 3 * nc)
        self._X = X.getDenseArray().copy()  # (owned u rows, 3NC)
        self._C = C
        self._tick("flexibility", t0)
        for m in (Bt, Bt_dense, X, C_local_rows):
            m.destroy()

    def _solve_K(self, rhs: PETSc.Vec) -> PETSc.Vec:
        x = rhs.duplicate()
        t0 = time.perf_counter()
        self.ksp.solve(rhs, x)
        self._tick("solve", t0)
        return x

    # -- one increment --------------------------------------------------------------------------------
    def solve_increment(self, load_factor: float) -> SolveReport:
        p = self.problem
        opts = self.options
        law = p.law
        p.apply_prescribed_displacements(load_factor)
        p.predict_contact()
        nc = p.num_pairs
        report = SolveReport(converged=False, iterations=0, system_order=3 * nc)
        w_prev, g0, mu_f, _ = self._gather_pairs()
        step_length, inner_its = float("nan"), 0
        for it in range(opts.max_iterations + 1):
            free_dropped_objects(p.petsc_comms)
            # residuals at the current iterate
            t0 = time.perf_counter()
            F_int = p.assemble_internal_force()
            self._tick("assembly", t0)
            R = p.residual(F_int=F_int)
            R_free = p.free_residual(R)
            w_local = p.relative_displacement()
            ev = p.evaluate_law(w_local, p.z)
            scale = max(p.external_force().norm(), F_int.norm(),
                        p.pairs.global_force(p.contact_force()).norm())
            normR, normH = R_free.norm(), global_norm(ev.H, p.comm)
            if not (math.isfinite(normR) and math.isfinite(normH)):
                report.message = f"NaN/inf residual at iteration {it} (|R| = {normR}, |H| = {normH})"
                return report
            ref = max(scale, opts.atol)
            record = IterationRecord(it, normR / ref, normH / ref, step_length, "newton" if it else "",
                                     count_states(ev.state, p.comm),
                                     p.state.count_trial_plastic_points(p.u), inner_its)
            report.history.append(record)
            logger.info(record.line(self.name))
            report.iterations = it
            tol = opts.rtol * scale + opts.atol
            if normR <= tol and normH <= tol:
                report.converged, report.message = True, "converged"
                return report
            if it == opts.max_iterations:
                break

            # 1.–2. out-of-balance force, factorisation, flexibility
            if not (self.modified and it > 0):
                self._factorise_and_condense()
            r = R_free.copy()
            r.scale(-1.0)
            x_r = self._solve_K(r)
            w_free = p.pairs.gather(p.pairs.relative_displacement(x_r)).reshape(-1)
            w_m = p.pairs.gather(w_local).reshape(-1)
            z_m = p.pairs.gather(p.z)
            lam_m, _ = law.force(z_m)
            lam_m = lam_m.reshape(-1)
            self.last_condensed = {"C": self._C, "w_free": w_free, "w_m": w_m, "lam_m": lam_m,
                                   "mu_f": mu_f, "g0": g0, "w_prev": w_prev, "r": p.r}

            # 3. inner dense nonsmooth solve for z
            result = self._inner_solve(z_m, w_m, w_free, lam_m, w_prev, g0, mu_f, tol)
            inner_its = result.iterations
            if not result.converged:
                report.message = f"inner nonsmooth solve failed at outer iteration {it}: {result.message}"
                return report
            z_new = result.x.reshape(nc, 3)
            lam_new, _ = law.force(z_new)

            # 4. du = x_r + X (λ − λ_m)
            n_u = R_free.getLocalSize()
            du = x_r.getArray(readonly=True) + self._X @ (lam_new.reshape(-1) - lam_m)
            p.u.x.array[:n_u] += du
            p.u.x.scatter_forward()
            p.z = self._local_rows(z_new).copy()
            step_length = 1.0
        report.message = (f"no convergence in {opts.max_iterations} outer iterations "
                          f"(|R|/F = {report.final.equilibrium:.3e}, |H|/F = {report.final.contact:.3e})")
        return report

    def _inner_solve(self, z_m, w_m, w_free, lam_m, w_prev, g0, mu_f, tol):
        """Dense nonsmooth Newton/LM on z with w(z) = w_m + w_free + C (λ(z) − λ_m).

        Unknowns and rows are scaled by the load scale F so that the LM parameter
        ν = c |H̃| sees a residual and a Jacobian of order one (angles, for the polar law,
        are not scaled).
        """
        law, r, C = self.problem.law, self.problem.r, self._C
        force_unit = r * self.problem.characteristic_length()
        nc = z_m.shape[0]
        F = max(tol / max(self.options.rtol, 1e-300), 1e-300)  # the load scale
        z_scale = np.tile(_unknown_scale(law, F), nc)

        def residual(x):
            z = (x * z_scale).reshape(nc, 3)
            lam, dlam_dz = law.force(z)
            w = (w_m + w_free + C @ (lam.reshape(-1) - lam_m)).reshape(nc, 3)
            ev = pin_constrained_directions(law, law.evaluate(w, w_prev, z, g0, mu_f, r), z,
                                            self._constrained, force_unit)
            # J = blockdiag(∂H/∂w) · C · blockdiag(∂λ/∂z) + blockdiag(∂H/∂z)
            DwC = np.einsum("nij,njk->nik", ev.dH_dw, C.reshape(nc, 3, 3 * nc))
            J = np.einsum("anj,njk->ank", DwC.reshape(3 * nc, nc, 3), dlam_dz)
            idx = np.arange(nc)
            Jb = J.reshape(nc, 3, nc, 3)
            Jb[idx, :, idx, :] += ev.dH_dz
            J = J.reshape(3 * nc, 3 * nc) * z_scale[None, :] / F
            return ev.H.reshape(-1) / F, J

        t0 = time.perf_counter()
        result = solve_nonsmooth(residual, z_m.reshape(-1) / z_scale, tol=tol / F,
                                 max_iter=self.inner_max_iterations, watchdog=6)
        result.x = result.x * z_scale
        self._tick("contact", t0)
        return result

    def _tick(self, key: str, t0: float) -> None:
        self.timings[key] = self.timings.get(key, 0.0) + time.perf_counter() - t0


def _unknown_scale(law, force_scale: float) -> np.ndarray:
    """Scale of each pair unknown: forces scale with the load; the polar angle θ does not."""
    if law.name == "polar":
        return np.array([force_scale, force_scale, 1.0])
    return np.full(3, force_scale)
