r"""NNEQM1: a nonsmooth Newton on the contact unknowns nested in Newton–Raphson (seed §3).

For the load factor ℓ of an increment, outer iteration m (``formulation.md`` §5):

1. r_m = F_ext(ℓ) − F_int(u_m) + Bᵀλ_m (constrained rows zero);
2. one factorisation of the consistent tangent K_m (:class:`~dolfinx_nnqem.condensation.Condensation`);
   X = G Bᵀ (3NC right-hand sides solved together), the contact flexibility C_m = B X (dense,
   3NC × 3NC) and x_r = G r_m, w_free = B x_r;
3. inner: H(w(z), z) = 0 with w(z) = w_m + w_free + C_m (λ(z) − λ_m), a dense nonsmooth system
   of order 3NC, by the package's Newton driver (:func:`dolfinx_nnqem.nonsmooth.solve_nonsmooth`);
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
from dataclasses import asdict, dataclass

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.condensation import Condensation
from dolfinx_nnqem.contact.model import PairLaws
from dolfinx_nnqem.convergence import IterationRecord, SolveReport, count_states, logger
from dolfinx_nnqem.linalg import free_dropped_objects, global_norm
from dolfinx_nnqem.newton import Globalisation, Merit, solve
from dolfinx_nnqem.nonsmooth import Fallback, solve_dense
from dolfinx_nnqem.problem import ContactProblem
from dolfinx_nnqem.solver import NNEQM1Options, SolverOptions

__all__ = ["CondensedProblem", "NNEQM1Solver"]

FULL_STEPS = Globalisation(line_search=False, levenberg_marquardt=False)
"""NNEQM1's outer Newton–Raphson: every step is a solved condensed problem, taken in full."""


@dataclass
class CondensedProblem:
    """One outer iteration's dense contact problem (all pairs, global order).

    Attributes
    ----------
    C
        (3NC, 3NC) contact flexibility B G Bᵀ.
    w_free, w_m, lam_m
        (3NC,) relative displacement of the out-of-balance load, at the iterate, and its forces.
    mu_f, g0
        (NC,) friction coefficients and initial gaps.
    w_prev
        (NC, 3) w at the start of the increment.
    r
        The laws' scaling (the largest over the interfaces).
    BN, e
        (3NC, n_r) the free rigid modes seen by the pairs, (n_r,) Nᵀ r_m (empty without them).
    """

    C: np.ndarray
    w_free: np.ndarray
    w_m: np.ndarray
    lam_m: np.ndarray
    mu_f: np.ndarray
    g0: np.ndarray
    w_prev: np.ndarray
    r: float
    BN: np.ndarray
    e: np.ndarray

    def as_dict(self) -> dict:
        return asdict(self)


def rigid_start(BN: np.ndarray, w_change: np.ndarray) -> np.ndarray:
    """Starting mode amplitudes α_0 = −(B N)⁺ Δw: the rigid motion that undoes the change ``w_change``
    of the pairs' relative displacements, in the least-squares sense.

    The generalised inverse fixes a floating body at its fixing dofs, so the elastic predictor
    moves it rigidly by an arbitrary amount; started from α = 0, its pairs would open or
    penetrate for no physical reason (and an interface whose pairs all open leaves the body's
    modes without a Jacobian column). Started from α_0, the pairs keep their relative position.
    """
    if BN.shape[1] == 0:
        return np.zeros(0)
    return -np.linalg.lstsq(BN, w_change, rcond=None)[0]


class NNEQM1Solver:
    """Nested NNEQM: contact flexibility + dense nonsmooth Newton inside Newton–Raphson.

    Parameters
    ----------
    problem
        A :class:`~dolfinx_nnqem.problem.ContactProblem` with contact.
    options
        Tolerances, outer iteration limit, ``petsc_options`` for the tangent solves.
    nneqm1
        This solver's own options (:class:`~dolfinx_nnqem.solver.NNEQM1Options`).
    """

    name = "nneqm1"

    def __init__(self, problem: ContactProblem, options: SolverOptions | None = None,
                 nneqm1: NNEQM1Options | None = None):
        if not problem.has_contact:
            raise ValueError("NNEQM1 solves contact problems: the problem has no Contact")
        self.problem = problem
        self.options = options or SolverOptions()
        self.settings = nneqm1 or NNEQM1Options()
        self.condensation = Condensation(problem, self.name, self.options.petsc_options)
        self._timings: dict[str, float] = {}
        self.last_condensed: CondensedProblem | None = None  #: the latest outer iteration's dense problem

    @property
    def timings(self) -> dict[str, float]:
        """Seconds per phase: assembly, factorisation, flexibility, solve, contact."""
        out = dict(self.condensation.timings)
        for key, value in self._timings.items():
            out[key] = out.get(key, 0.0) + value
        return out

    def solve_increment(self, load_factor: float) -> SolveReport:
        p = self.problem
        # the outer iteration starts where the monolithic solver's Newton does: from the secant
        # extrapolation of the last two increments (u and the pair unknowns) while the load path
        # goes on in the same direction, else with the jump of the prescribed values lifted
        extrapolated = self.settings.extrapolate and p.extrapolate(load_factor)
        u_bc = p.u.x.array[p.bc_dofs].copy()
        p.apply_prescribed_displacements(load_factor)
        p.predict_contact()
        delta_bc = p.u.x.array[p.bc_dofs] - u_bc
        report = SolveReport(converged=False, iterations=0,
                             system_order=3 * p.num_pairs + self.condensation.num_modes)
        system = _OuterSystem(self, report)
        lifted = False
        if not extrapolated and p.comm.allreduce(bool(np.any(delta_bc != 0.0)), op=MPI.LOR):
            p.u.x.array[p.bc_dofs] = u_bc
            lifted = system.lifted_step(delta_bc)
            if not lifted:  # its contact solve failed: the plain start, from the moved boundary
                p.apply_prescribed_displacements(load_factor)
                system.inner_failure = None
        outcome = solve(system, FULL_STEPS, self.options.max_iterations, first_iteration=1 if lifted else 0,
                        first_kind="lifted" if lifted else "", first_step_length=1.0 if lifted else math.nan)
        report.iterations, report.converged = outcome.iterations, outcome.converged
        final = report.final
        if outcome.converged:
            report.message = "converged"
        elif system.inner_failure is not None:
            report.message = system.inner_failure
        else:
            report.message = (f"no convergence in {self.options.max_iterations} outer iterations "
                              f"(|R|/F = {final.equilibrium:.3e}, |H|/F = {final.contact:.3e})")
        return report

    def inner_solve(self, cond: CondensedProblem, laws: PairLaws, z_m: np.ndarray, tol: float, scale: float):
        """Dense nonsmooth Newton/LM on x = (z, α) with w(z, α) = w_m + w_free + C (λ(z) − λ_m) + B N α.

        Unknowns and rows are scaled by the load scale F so that the LM parameter ν = c |H̃|
        sees a residual and a Jacobian of order one (the polar angle is not scaled; the mode
        amplitudes α scale as F / r).
        """
        C, n_r = cond.C, cond.BN.shape[1]
        nc = z_m.shape[0]
        n3 = 3 * nc
        F = scale
        z_scale = laws.unknown_scale(F).reshape(-1)
        x_scale = np.concatenate([z_scale, np.full(n_r, F / cond.r)])

        def w_of(xs, lam):
            w = cond.w_m + cond.w_free + C @ (lam.reshape(-1) - cond.lam_m)
            return w + cond.BN @ xs[n3:] if n_r else w

        def step_scale(cartesian):
            """x_scale of the step coordinates (friction forces of pairs in the Cartesian chart)."""
            if cartesian is None:
                return x_scale
            return np.concatenate([laws.step_scale(F, cartesian).reshape(-1), x_scale[n3:]])

        def system(xs, lam, lin, ev):
            """The scaled rows and Jacobian for the law evaluation ``ev`` in the laws' step coordinates ``lin``."""
            y_scale = step_scale(lin.cartesian)
            # J = blockdiag(∂H/∂w) · C · blockdiag(∂λ/∂y) + blockdiag(∂H/∂y)
            DwC = np.einsum("nij,njk->nik", ev.dH_dw, C.reshape(nc, 3, n3))
            Jz = np.einsum("anj,njk->ank", DwC.reshape(n3, nc, 3), lin.dlam_dy)
            idx = np.arange(nc)
            Jb = Jz.reshape(nc, 3, nc, 3)
            Jb[idx, :, idx, :] += lin.dH_dy
            if not n_r:
                return ev.H.reshape(-1) / F, Jz.reshape(n3, n3) * y_scale[None, :n3] / F, lin.cartesian
            # the free rigid modes: w depends on α, and Nᵀ(r + Bᵀ(λ − λ_m)) = 0
            H = np.concatenate([ev.H.reshape(-1), cond.e + cond.BN.T @ (lam.reshape(-1) - cond.lam_m)])
            J = np.zeros((n3 + n_r, n3 + n_r))
            J[:n3, :n3] = Jz.reshape(n3, n3)
            J[:n3, n3:] = np.einsum("nij,njk->nik", ev.dH_dw, cond.BN.reshape(nc, 3, n_r)).reshape(n3, n_r)
            J[n3:, :n3] = np.einsum("anj,njk->ank", cond.BN.T.reshape(n_r, nc, 3), lin.dlam_dy).reshape(n_r, n3)
            return H / F, J * y_scale[None, :] / F, lin.cartesian

        def residual(x):
            xs = x * x_scale
            z = xs[:n3].reshape(nc, 3)
            lam, _ = laws.force(z)
            ev = laws.evaluate(w_of(xs, lam).reshape(nc, 3), cond.w_prev, z)
            return system(xs, lam, laws.linearise(z, ev), ev)

        def advance(x, dx, alpha, cartesian):
            """The pair unknowns step in the laws' coordinates; the mode amplitudes linearly."""
            xs, dxs = x * x_scale, dx * step_scale(cartesian)
            z = laws.advance(xs[:n3].reshape(nc, 3), dxs[:n3].reshape(nc, 3), alpha, cartesian)
            return np.concatenate([z.reshape(-1), xs[n3:] + alpha * dxs[n3:]]) / x_scale

        def on_the_slip(x):
            """x with the unknowns no force depends on (the polar angle of pairs without friction
            force) set on the slip there (:meth:`PairLaws.follow_slip`)."""
            xs = x * x_scale
            z = xs[:n3].reshape(nc, 3)
            lam, _ = laws.force(z)
            z = laws.follow_slip(z, w_of(xs, lam).reshape(nc, 3), cond.w_prev)
            return np.concatenate([z.reshape(-1), xs[n3:]]) / x_scale

        def advance_following(x, dx, alpha, cartesian):
            return on_the_slip(advance(x, dx, alpha, cartesian))

        x0 = np.concatenate([z_m.reshape(-1), rigid_start(cond.BN, cond.w_free)]) / x_scale
        if n_r:  # only a floating body's predictor is out of balance (see _frozen_branch_start)
            x0 = self._frozen_branch_start(x0, x_scale, laws, cond, z_m, w_of, system, advance)
        # The polar angles follow the slip only if the plain iteration fails: measured on the
        # robustness suite, following always costs cutbacks elsewhere (docs/robustness.md)
        fallback = None
        if laws.slip_following:
            fallback = Fallback("with the polar angles on the slip", on_the_slip(x0), advance_following)
        result = solve_dense(residual, x0, tol=tol / F, max_iter=self.settings.inner_max_iterations,
                             globalisations=self.settings.inner_globalisations, advance=advance, fallback=fallback)
        result.x = result.x * x_scale
        return result

    @staticmethod
    def _frozen_branch_start(x0, x_scale, laws, cond, z_m, w_of, system, advance):
        """The inner start: one Newton step with every pair's branch frozen at the outer iterate.

        The elastic predictor w_free is the response to the out-of-balance load before the pair
        forces change; where that load is not in balance (a body held only by contact, whose
        generalised inverse fixes it at its fixing dofs) it deforms the contact surfaces
        meaninglessly, and pairs evaluated there start on the wrong branch (opening although
        they will be pressed). The monolithic solver linearises the laws where the iterate is;
        this step does the same here: the laws' values and B-Jacobians at (w_m, z_m), their
        linearisation at x0, one solve. The iteration then starts from its solution (or from x0
        if that system is singular). Used when there are free rigid modes: where every body is
        supported, the predictor is the physical response to the out-of-balance load and the
        seed's start from it is kept.
        """
        nc = z_m.shape[0]
        xs = x0 * x_scale
        lam, _ = laws.force(z_m)
        ev = laws.evaluate(cond.w_m.reshape(nc, 3), cond.w_prev, z_m)
        w = w_of(xs, lam).reshape(nc, 3)
        H_lin = ev.H + np.einsum("nij,nj->ni", ev.dH_dw, w - cond.w_m.reshape(nc, 3))
        H, J, cartesian = system(xs, lam, laws.linearise(z_m, ev), ev._replace(H=H_lin))
        try:
            step = np.linalg.solve(J, -H)
        except np.linalg.LinAlgError:
            return x0
        return advance(x0, step, 1.0, cartesian) if np.all(np.isfinite(step)) else x0

    def destroy(self) -> None:
        self.condensation.destroy()


class _OuterSystem:
    """NNEQM1's outer Newton–Raphson as a backend of the Newton driver (full steps only)."""

    def __init__(self, solver: NNEQM1Solver, report: SolveReport):
        self.solver = solver
        self.problem = solver.problem
        self.report = report
        self.laws = self.problem.contact.gathered_laws()
        self.w_prev = self.problem.contact.gather(self.problem.contact.w_n)
        self.steps = 0
        self.inner_iterations = 0
        self.inner_failure: str | None = None
        self.current = None
        self._step = None

    def evaluate(self) -> Merit:
        p, s = self.problem, self.solver
        t0 = time.perf_counter()
        F_int = p.assemble_internal_force()
        s._timings["assembly"] = s._timings.get("assembly", 0.0) + time.perf_counter() - t0
        R_free = p.free_residual(p.residual(F_int=F_int))
        w = p.relative_displacement()
        law = p.contact.evaluate(w)
        scale = p.force_scale(F_int)
        norm_R, norm_H = R_free.norm(), global_norm(law.H, p.comm)
        self.current = (R_free, w, law, scale, norm_R, norm_H)
        opts = s.options
        tol = opts.rtol * scale + opts.atol
        return Merit(0.5 * (norm_R ** 2 + norm_H ** 2), norm_R <= tol and norm_H <= tol)

    def record(self, iteration: int, step_length: float, kind: str) -> None:
        p = self.problem
        free_dropped_objects(p.petsc_comms)  # once per iteration, on every rank
        _, _, law, scale, norm_R, norm_H = self.current
        ref = scale  # F, as the independent check has it (atol is no scale: issue 31)
        record = IterationRecord(iteration, norm_R / ref, norm_H / ref, step_length, "newton" if iteration else "",
                                 count_states(law.state, p.comm), p.state.count_trial_plastic_points(p.u),
                                 self.inner_iterations)
        self.report.history.append(record)
        logger.info(record.line(self.solver.name))

    def snapshot(self):
        return self.problem.u.x.array.copy(), self.problem.contact.z.copy(), self.current

    def restore(self, snapshot) -> Merit:
        u, z, self.current = snapshot
        self.problem.u.x.array[:] = u
        self.problem.contact.z = z.copy()
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
        model = p.contact
        R_free, w, _, scale, _, _ = self.current
        if not (s.settings.modified and self.steps > 0):
            cond_solver.factorise(p.assemble_tangent, "the tangent stiffness K_t")
            self._X, self._C = cond_solver.pair_flexibility()
        r = R_free.copy()
        if lift is not None:
            K_delta = p.tangent_action(lift)
            K_delta_free = p.free_residual(K_delta)
            r.axpy(1.0, K_delta_free)
            for vec in (K_delta, K_delta_free):
                vec.destroy()
        r.scale(-1.0)
        if lift is not None:  # the constrained rows of the right-hand side are du there (identity rows)
            owned = p.owned_bc_dofs()
            r.getArray()[owned] = lift[owned]
        x_r = cond_solver.solve(r)
        z_m = model.gather(model.z)
        lam_m, _ = self.laws.force(z_m)
        cond = CondensedProblem(
            C=self._C, w_free=model.gather(model.B_times(x_r)).reshape(-1), w_m=model.gather(w).reshape(-1),
            lam_m=lam_m.reshape(-1), mu_f=self.laws.mu_f, g0=self.laws.g0, w_prev=self.w_prev,
            r=max(group.r for group in self.laws.groups), BN=cond_solver.mode_coupling(),
            e=cond_solver.mode_loads(r))
        s.last_condensed = cond
        opts = s.options
        tol = opts.rtol * scale + opts.atol
        t0 = time.perf_counter()
        result = s.inner_solve(cond, self.laws, z_m, tol, max(tol / max(opts.rtol, 1e-300), 1e-300))
        s._timings["contact"] = s._timings.get("contact", 0.0) + time.perf_counter() - t0
        self.inner_iterations = result.iterations
        if not result.converged:
            self.inner_failure = f"inner nonsmooth solve failed at outer iteration {self.steps}: {result.message}"
            return self.inner_failure
        nc = model.num_global
        z_new = result.x[:3 * nc].reshape(nc, 3)
        lam_new, _ = self.laws.force(z_new)
        du = x_r.getArray(readonly=True) + self._X @ (lam_new.reshape(-1) - cond.lam_m)
        if cond_solver.num_modes:
            du += cond_solver.mode_array() @ result.x[3 * nc:]
        self._step = (du, model.local_rows(z_new).copy())
        x_r.destroy()
        return None

    def lm_direction(self, merit: Merit, globalisation: Globalisation) -> str | None:
        return "NNEQM1's outer iteration has no Levenberg–Marquardt step"

    def slope(self) -> float:
        return math.nan  # never asked: the outer iteration takes full steps

    def move(self, step_length: float) -> Merit:
        p = self.problem
        du, z_new = self._step
        n_u = du.shape[0]
        p.u.x.array[:n_u] += step_length * du
        p.u.x.scatter_forward()
        p.contact.z = z_new
        self.steps += 1
        return self.evaluate()

