r"""NNEQM2's default increment: one nonsmooth system of the pairs and every Gauss point's return map.

The unknowns of an increment are the pair unknowns z (forces λ(z)), the plastic strain
increment Δε_p,j of every Gauss point j of a material that can yield (a deviator: 5
coordinates; Δε_p,j = Δγ_j N_j with its flow direction an unknown too, where the seed froze it)
and, where bodies float, the free rigid modes' amplitudes α. The displacement follows from the
ELASTIC stiffness K_e, factorised once per run (:mod:`~dolfinx_nnqem.solvers.nneqm2.increment_start`):

    du = G (b + Bᵀλ + q(Δε_p)) + N α,     q(Δε_p) = ∫ Bᵀ C Δε_p dx,

so equilibrium holds for every iterate, with the stress σ_j = σ_n,j + C (ε_j(du) − Δε_p,j).
The equations (all dimensionless):

    H(w, z) / F = 0                                        the pair laws, w = B(u_n + du) + m(ℓ)
    Nᵀ (b + Bᵀλ + q) / F = 0                                the floating bodies' self-equilibrium
    G_j = (Δε_p,j − P_j(t_j)) √(2/3) (3μ_j + H_j) / σ_u,j = 0   every Gauss point that can yield

with the trial deviator t_j = s_n,j + 2μ_j dev ε_j(du) and the material's return map P_j
(``PointwiseMaterial.plastic_strain``; H_j the hardening slope at p_n). For von Mises with linear
hardening the radial return's plastic strain

    P_j(t) = max(f_tr, 0) / (3μ + H) · (3/2) t / q(t),   f_tr = q(t) − σ_y0 − H p_n;

with a hardening law of any shape Δp solves q(t) − 3μ Δp = σ_y(p_n + Δp) and the direction is the same.

G_j = 0 is the seed's yield complementarity min(−f_j, Δγ_j (3μ + H)) = 0 (its component along t:
for von Mises the returned stress is parallel to the trial stress, so f_j = f_tr − (3μ + H) Δγ_j)
together with the normality of the flow (its components across t), which the seed froze at the
start of the increment. Its solution is the backward-Euler (radial return) state, the monolithic
solver's and NNEQM1's.

A Newton step eliminates the Gauss points' rows, which are local: with R'_j = ∂P_j/∂e (5 × 5,
``PointwiseMaterial.plastic_strain_tangent``) and the step's displacement y,

    dΔε_p,j = −G_j + R'_j dev ε_j(y),   K_t y = Bᵀ dλ − q(G),

K_t = K_e − ∫ Bᵀ C R' C B dx the consistent tangent at u_n + du (the problem's own
:meth:`~dolfinx_nnqem.problem.ContactProblem.assemble_tangent`). The pairs' step then solves the
condensed contact problem through K_t linearised where the iterate is — one frozen-branch step of
:class:`~dolfinx_nnqem.solvers.condensed.CondensedSystem` with C = B G_t Bᵀ and the free relative
displacement B G_t(−q(G)) — and the self-equilibrium rows become e + (BN)ᵀdλ = 0 with e = Nᵀ(b
+ Bᵀλ + q) − Nᵀ q(G). The step is the exact Newton step of the whole system; its cost is one
factorisation of K_t, 3 NC solves for C and one more, as in an outer iteration of NNEQM1. The
Newton driver (:func:`~dolfinx_nnqem.numerics.newton.solve`) damps it (Armijo, watchdog) on
Ψ = ½(|H/F|² + |Nᵀ…/F|² + Σ_j G_j²).
"""

from __future__ import annotations

import math
import time

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.contact.laws import LawEvaluation
from dolfinx_nnqem.material.kinematics import deviator_tensors
from dolfinx_nnqem.numerics.linalg import free_dropped_objects, global_norm
from dolfinx_nnqem.numerics.newton import Globalisation, Merit
from dolfinx_nnqem.problem.contact_problem import ContactProblem
from dolfinx_nnqem.solvers.condensation import Condensation
from dolfinx_nnqem.solvers.condensed import CondensedProblem, CondensedSystem
from dolfinx_nnqem.solvers.contract import contact_model
from dolfinx_nnqem.solvers.convergence import IterationRecord, SolveReport, count_states, logger
from dolfinx_nnqem.solvers.nneqm2.gauss_points import GaussPointOperators
from dolfinx_nnqem.solvers.nneqm2.increment_start import IncrementStart
from dolfinx_nnqem.solvers.prediction import newton_right_hand_side
from dolfinx_nnqem.solvers.timings import Timings

__all__ = ["ReturnMapIncrement"]

_SQRT23 = math.sqrt(2.0 / 3.0)

_PairStep = tuple[CondensedSystem, np.ndarray, np.ndarray, object]
"""The contact step: the condensed system, its start x0, the step dx and its chart."""


class _Iterate:
    """The unknowns (z this rank's pairs, Δε_p the owned Gauss points', α) and what follows from them."""

    def __init__(self, z: np.ndarray, eps_p: np.ndarray, alpha: np.ndarray):
        self.z, self.eps_p, self.alpha = z, eps_p, alpha
        self.du: np.ndarray | None = None  #: owned rows of du
        self.t: np.ndarray | None = None  #: trial deviators (n_gp, 5)
        self.G: np.ndarray | None = None  #: Δε_p − P(t) (n_gp, 5)
        self.w: np.ndarray | None = None  #: (num_local, 3)
        self.law: LawEvaluation | None = None  #: the pair laws' evaluation at (w, z)
        self.E = np.zeros(0)  #: the self-equilibrium rows Nᵀ(b + Bᵀλ + q)
        self.norms = (0.0, 0.0, 0.0)  #: |H|/F, |E|/F, |G̃|

    def copy(self) -> _Iterate:
        out = _Iterate(self.z.copy(), self.eps_p.copy(), self.alpha.copy())
        out.__dict__.update({k: v for k, v in self.__dict__.items() if k not in ("z", "eps_p", "alpha")})
        return out


class ReturnMapIncrement:
    """One increment of NNEQM2's default variant, as a backend of the Newton driver.

    Parameters
    ----------
    problem, gp, elastic, tangent
        The problem, its Gauss-point operators and the factorisations of K_e (once per run) and of
        K_t (every step).
    start
        The increment's start (:func:`~dolfinx_nnqem.solvers.nneqm2.increment_start.start_increment`).
    tol
        Converged when |H|/F, |Nᵀ…|/F and |G̃| are all at most ``tol``.
    report
        Where the iterations are recorded.
    align_sliding
        The polar law: after every step, put the angle of sliding pairs on their slip too, not only
        that of the pairs without friction force (:meth:`PairLaws.follow_slip`; the monolithic
        solver's second attempt).
    """

    def __init__(self, problem: ContactProblem, gp: GaussPointOperators, elastic: Condensation,
                 tangent: Condensation, start: IncrementStart, tol: float, report: SolveReport,
                 align_sliding: bool = False):
        self.p, self.gp, self.elastic, self.tangent = problem, gp, elastic, tangent
        self.start, self.tol, self.report = start, tol, report
        self.align_sliding = align_sliding
        self.F = start.force_scale
        self.row_scale = np.where(gp.yields, _SQRT23 * (3.0 * gp.mu + gp.material.hardening(start.internal_n))
                                  / gp.stress_unit, 0.0)
        self.timings = Timings()
        z = problem.contact.z.copy() if problem.contact is not None else np.zeros((0, 3))
        self.x = _Iterate(z, np.zeros((gp.n_gp, 5)), np.zeros(elastic.num_modes))
        self._direction: tuple[_PairStep | None, np.ndarray, np.ndarray] | None = None  #: (pairs, dΔε_p, dα)
        self._x0: _Iterate | None = None
        self._psi0 = math.nan

    # -- the residual -------------------------------------------------------------------------------
    def _loads(self, x: _Iterate) -> PETSc.Vec:
        """Bᵀλ(z) + q(Δε_p), constrained rows zeroed (a new vector laid out like V)."""
        p = self.p
        f = self._plastic_force(x.eps_p)
        if p.contact is not None:
            contact_force = p.contact.global_force(p.contact.force(x.z))
            f.axpy(1.0, contact_force)
            contact_force.destroy()
            with f.localForm() as local:  # a pair on a support loads its constrained dof too
                local.array[p.bc_dofs] = 0.0
        return f

    def _plastic_force(self, eps_p: np.ndarray) -> PETSc.Vec:
        """q(Δε_p) = ∫ Bᵀ C Δε_p dx (C Δε_p = 2μ Δε_p for a deviator), constrained rows zeroed."""
        gp, p = self.gp, self.p
        f = gp.force(2.0 * gp.mu[:, None, None] * deviator_tensors(eps_p))
        with f.localForm() as local:
            local.array[p.bc_dofs] = 0.0
        return f

    def _trial(self, du: PETSc.Vec) -> np.ndarray:
        """The trial deviators s_n + 2μ dev ε(du) at the owned Gauss points (n_gp, 5)."""
        return self.start.s_n + 2.0 * self.gp.mu[:, None] * self.gp.deviatoric_strains(du)

    def _return_map(self, t: np.ndarray) -> np.ndarray:
        """The return map's plastic strains for trial deviators t, 0 where nothing yields."""
        plastic_strain, _ = self.gp.material.plastic_strain(t, self.start.internal_n)
        return np.where(self.gp.yields[:, None], plastic_strain, 0.0)

    def _return_map_tangent(self, t: np.ndarray) -> np.ndarray:
        return self.gp.material.plastic_strain_tangent(t, self.start.internal_n)

    def _displace(self, x: _Iterate) -> None:
        """du = G (b + Bᵀλ + q) + N α, the problem's u = u_n + du, and the rows that follow."""
        f = self._loads(x)
        x.E = self.elastic.mode_loads(f) + self.elastic.mode_loads(self.start.b)
        f.axpy(1.0, self.start.b)
        du = self.elastic.solve(f)
        if self.elastic.num_modes:
            du.getArray()[:] += self.elastic.mode_array() @ x.alpha
        x.du = du.getArray(readonly=True).copy()
        self._set_displacement(x.du)
        x.t = self._trial(du)
        x.G = np.where(self.gp.yields[:, None], x.eps_p - self._return_map(x.t), 0.0)
        for vec in (f, du):
            vec.destroy()

    def _set_displacement(self, du: np.ndarray) -> None:
        """The problem's u = u_n + du (owned rows), the prescribed values kept exactly."""
        p, st = self.p, self.p.state
        n_u = du.shape[0]
        u_bc = p.u.x.array[p.bc_dofs].copy()
        p.u.x.array[:n_u] = st.u_n.x.array[:n_u] + du
        p.u.x.scatter_forward()
        p.u.x.array[p.bc_dofs] = u_bc

    def evaluate(self) -> Merit:
        """u at the current iterate, and its merit Ψ = ½ (|H|² + |E|² + |G̃|²) of the pair rows H and
        the self-equilibrium rows E (relative to the load scale F) and the scaled yield rows G̃."""
        x, p = self.x, self.p
        t0 = time.perf_counter()
        self._displace(x)
        norm_H = 0.0
        if p.contact is not None:
            x.w = p.relative_displacement()
            x.law = p.contact.evaluate(x.w, x.z)
            norm_H = global_norm(x.law.H, p.comm) / self.F
        norm_E = float(np.linalg.norm(x.E)) / self.F
        norm_G = global_norm(self.row_scale[:, None] * x.G, p.comm)
        x.norms = (norm_H, norm_E, norm_G)
        self.timings.add("residual", t0)
        psi = 0.5 * (norm_H ** 2 + norm_E ** 2 + norm_G ** 2)
        return Merit(psi, max(x.norms) <= self.tol)

    # -- steps ---------------------------------------------------------------------------------------
    def _contact_step(self, r: PETSc.Vec, e: np.ndarray, z: np.ndarray, w_lin: np.ndarray | None):
        """The step through the factorised K_t for the out-of-balance load ``r`` (free rows; the
        constrained rows carry the step's prescribed values), the floating bodies' residual ``e``
        and the pair laws linearised at (``w_lin``, ``z``) (this rank's pairs; no ``w_lin`` without
        contact): the pairs' new
        unknowns by one frozen-branch step of the condensed contact problem
        (:class:`~dolfinx_nnqem.solvers.condensed.CondensedSystem`), and the displacement step
        y = G_t r + X dλ + N dα (owned rows).

        Returns ((system, x0, dx, chart) or None without contact, dα, y), or a reason string.
        """
        p, tangent = self.p, self.tangent
        x_r = tangent.solve(r)
        y = x_r.getArray(readonly=True).copy()
        pairs, dalpha = None, np.zeros(tangent.num_modes)
        if p.contact is not None:
            X, C = tangent.pair_flexibility()
            model, laws, w_prev = p.contact, self.start.laws, self.start.w_prev
            assert laws is not None and w_prev is not None and w_lin is not None  # all given with contact
            z_all, w_all = model.gather(z), model.gather(w_lin)
            lam_m, _ = laws.force(z_all)
            cond = CondensedProblem(C=C, w_free=model.gather(model.B_times(x_r)).reshape(-1), w_m=w_all.reshape(-1),
                                    lam_m=lam_m.reshape(-1), mu_f=laws.mu_f, g0=laws.g0, w_prev=w_prev,
                                    r=laws.r_max, BN=tangent.mode_coupling(), e=e)
            system = CondensedSystem(laws, cond, self.F)
            x0 = system.scaled(z_all)
            H, J, chart = system.residual(x0, frozen=system.at(w_all, z_all))
            try:
                dx = np.linalg.solve(J, -H)
            except np.linalg.LinAlgError:
                x_r.destroy()
                return "the linearised contact problem is singular"
            if not np.all(np.isfinite(dx)):
                x_r.destroy()
                return "the linearised contact problem gave a step that is not finite"
            z_full = system.pair_unknowns(system.advance(x0, dx, 1.0, chart))
            dalpha = system.modes(dx)
            y += X @ (laws.force(z_full)[0] - lam_m).reshape(-1)
            pairs = (system, x0, dx, chart)
        elif tangent.num_modes:
            x_r.destroy()
            return "a floating body without contact"  # refused before solving by the rigid-mode check
        if tangent.num_modes:
            y += tangent.mode_array() @ dalpha
        x_r.destroy()
        return pairs, dalpha, y

    def _stepped_pairs(self, pairs: _PairStep, step_length: float) -> np.ndarray:
        """This rank's pair unknowns after ``step_length`` of the contact step ``pairs``; with the
        polar law the angles no force depends on (and, with ``align_sliding``, those of sliding
        pairs) put on the slip the step predicts, as the monolithic solver does after every step
        (theory page, "The polar law's Newton step")."""
        system, x0, dx, chart = pairs
        x = system.advance(x0, dx, step_length, chart)
        z_all = system.pair_unknowns(x)
        laws = system.laws
        if laws.slip_following:
            assert self.start.w_prev is not None  # a contact step: the start has the pairs' data
            w = system.relative_displacement(x, laws.force(z_all)[0]).reshape(system.nc, 3)
            z_all = laws.follow_slip(z_all, w, self.start.w_prev, sliding_too=self.align_sliding)
        return contact_model(self.p).local_rows(z_all).copy()

    def _owned_vector(self, owned: np.ndarray) -> PETSc.Vec:
        vec = self.elastic.K.createVecRight()
        vec.getArray()[:] = owned
        return vec

    def predictor_step(self, lift: bool) -> str | None:
        """The first step, as the monolithic solver's and NNEQM1's first iteration: everything
        linearised where the increment starts — the problem's u (the secant extrapolation, or
        u_n with the new prescribed values) or, with ``lift``, u_n with the prescribed jump lifted
        into the right-hand side — and the plastic strains from the radial return's
        linearisation there, Δε_p = P(t_s) + R'(t_s) (e(du) − e_s).

        Linearising at the iterate instead would start from the elastic predictor du_0 = G b:
        where a body floats, a response to a load contact does not balance yet (pairs on
        meaningless branches, Gauss points yielding spuriously); elsewhere an elastic overshoot.
        Returns None, or why there is no step (the increment then starts from the predictor).
        """
        p, st, gp, start, tangent = self.p, self.p.state, self.gp, self.start, self.tangent
        t0 = time.perf_counter()
        delta = np.zeros_like(p.u.x.array)
        if lift:
            delta[p.bc_dofs] = p.u.x.array[p.bc_dofs] - st.u_n.x.array[p.bc_dofs]
            p.u.x.array[p.bc_dofs] -= delta[p.bc_dofs]
        n_u = self.elastic.K.getLocalSize()[0]
        du_lin = self._owned_vector(p.u.x.array[:n_u] - st.u_n.x.array[:n_u])
        tangent.factorise(p.assemble_tangent, "the tangent stiffness K_t")
        R = p.residual(z=self.x.z)
        R_free = p.free_residual(R)
        r = newton_right_hand_side(p, R_free, delta if lift else None)
        for vec in (R, R_free):
            vec.destroy()
        w_lin = p.relative_displacement() if p.has_contact else None
        t_lin = self._trial(du_lin)
        e_lin = (t_lin - start.s_n) / (2.0 * gp.mu[:, None])
        step = self._contact_step(r, tangent.mode_loads(r), self.x.z, w_lin)
        r.destroy()
        if lift:
            p.u.x.array[p.bc_dofs] += delta[p.bc_dofs]
        if isinstance(step, str):
            du_lin.destroy()
            return step
        pairs, _, y = step
        du = du_lin.getArray(readonly=True) + y
        du_vec = self._owned_vector(du)
        e_new = (self._trial(du_vec) - start.s_n) / (2.0 * gp.mu[:, None])
        x = self.x.copy()
        x.eps_p = np.where(gp.yields[:, None], self._return_map(t_lin) + np.einsum(
            "jab,jb->ja", self._return_map_tangent(t_lin), e_new - e_lin), 0.0)
        if pairs is not None:
            x.z = self._stepped_pairs(pairs, 1.0)
        x.alpha = self.elastic.mode_amplitudes(du)
        for vec in (du_lin, du_vec):
            vec.destroy()
        self.x = x
        self.timings.add("newton_step", t0)
        return None

    def newton_direction(self, merit: Merit) -> str | None:
        """The exact Newton step (module docstring): K_t at the iterate, the condensed contact
        step, the Gauss points' plastic strain corrections dΔε_p = −G + R' dev ε(y)."""
        p, gp, x, tangent = self.p, self.gp, self._x0, self.tangent
        assert x is not None and x.G is not None and x.t is not None  # start_step copied the evaluated iterate
        t0 = time.perf_counter()
        tangent.factorise(p.assemble_tangent, "the tangent stiffness K_t")
        g = self._plastic_force(x.G)
        g.scale(-1.0)
        step = self._contact_step(g, x.E + tangent.mode_loads(g), x.z, x.w)
        g.destroy()
        if isinstance(step, str):
            return step
        pairs, dalpha, y = step
        y_vec = self._owned_vector(y)
        d_eps = np.where(gp.yields[:, None], -x.G + np.einsum(
            "jab,jb->ja", self._return_map_tangent(x.t), gp.deviatoric_strains(y_vec)), 0.0)
        y_vec.destroy()
        self._direction = (pairs, d_eps, dalpha)
        self.timings.add("newton_step", t0)
        return None

    def lm_direction(self, merit: Merit, globalisation: Globalisation) -> str | None:
        """Why there is none: NNEQM2's step has no Levenberg–Marquardt variant."""
        return "NNEQM2's Newton step has no Levenberg–Marquardt variant"

    def slope(self) -> float:
        """∇Ψ · d = −2Ψ: the step is the exact Newton step of the whole system."""
        return -2.0 * self._psi0

    def roundoff_note(self) -> None:
        """None: NNEQM2 iterates on the pair and yield rows (its equilibrium holds by construction),
        whose rounding :mod:`~dolfinx_nnqem.numerics.roundoff` does not estimate; a stop is put down
        to the merit function."""
        return None

    def move(self, step_length: float) -> Merit:
        """x = x_0 + step_length · d (the pair unknowns in the laws' step coordinates), evaluated."""
        assert self._x0 is not None and self._direction is not None  # set by start_step and newton_direction
        x0, (pairs, d_eps, dalpha) = self._x0, self._direction
        x = x0.copy()
        if pairs is not None:
            x.z = self._stepped_pairs(pairs, step_length)
        x.eps_p = x0.eps_p + step_length * d_eps
        x.alpha = x0.alpha + step_length * dalpha
        self.x = x
        return self.evaluate()

    # -- the driver's bookkeeping -------------------------------------------------------------------
    def start_step(self) -> None:
        """The current iterate becomes the start x_0 of the next step (and Ψ(x_0) is kept)."""
        self._x0 = self.x.copy()
        norm_H, norm_E, norm_G = self.x.norms
        self._psi0 = 0.5 * (norm_H ** 2 + norm_E ** 2 + norm_G ** 2)

    def snapshot(self) -> _Iterate:
        """A copy of the current iterate."""
        return self.x.copy()

    def restore(self, snapshot) -> Merit:
        """Return to a copy of ``snapshot`` (from :meth:`snapshot`); its merit."""
        self.x = snapshot.copy()
        return self.evaluate()

    def record(self, iteration: int, step_length: float, kind: str) -> None:
        """Append the current iterate's record to the report and log it."""
        p, x = self.p, self.x
        free_dropped_objects(p.petsc_comms)
        norm_H, norm_E, norm_G = x.norms
        states = count_states(x.law.state, p.comm) if x.law is not None else (0, 0, 0)  # x.law: with contact
        plastic = p.comm.allreduce(int(np.count_nonzero(np.linalg.norm(x.eps_p, axis=1) > 0.0)), op=MPI.SUM)
        record = IterationRecord(iteration, norm_E, norm_H, step_length, kind if iteration else "", states,
                                 plastic, yield_residual=norm_G)
        self.report.history.append(record)
        logger.info(record.line("nneqm2"))

