r"""NNEQM2 as the seed writes it: flow directions frozen at the start of the increment.

The unknowns are the pair unknowns z, the plastic multiplier increment Δγ_j of every Gauss point
j that can yield (NG of them) and, where bodies float, the free rigid modes' amplitudes α: a
dense nonsmooth system of order 3NC + NG (+ n_r). With the flow directions N_j frozen, the
displacement is linear in the unknowns (:mod:`~dolfinx_nnqem.solvers.nneqm2.increment_start`),

    du = du_0 + G Bᵀ λ(z) + G Q Δγ + N α,   Q_{:,j} = w_j B_jᵀ C N_j,

so the pairs see w = w_0 + W_BB λ + W_BQ Δγ + (BN) α (W_BB = B G Bᵀ, W_BQ = B G Q) and each
Gauss point the stress σ_j = σ_n,j + C (ε_j(du) − Δγ_j N_j). The rows: the pair laws and the
floating bodies' self-equilibrium (:class:`~dolfinx_nnqem.solvers.condensed.CondensedSystem`,
Δγ its further unknowns ξ), and per Gauss point the yield complementarity, dimensionless,

    H4_j = min(−f_j / σ_u,j, Δγ_j (3μ_j + H_j) / σ_u,j),   f_j = q(σ_j) − σ_y(p_n,j + Δγ_j),

(σ_y = σ_y0 + H p for linear hardening; H_j = σ_y'),

with the chain-rule Jacobian through S_B = dev ε(G Bᵀ) and S_Q = dev ε(G Q) (NG solves per
increment with the one factorisation). At a tie the yield branch is differentiated.

The directions. N_j = (3/2) s_n,j / q_n,j from the converged stress; where σ_n has no deviator
(the first increment) from the trial stress of the increment's ELASTIC contact solution (the pairs
solved with Δγ = 0), so that an obstacle's motion, which the elastic predictor du_0 does not see,
shapes the directions. A Gauss point with no direction even there cannot flow in this increment
(its row is H4 = Δγ); if its stress then leaves the yield surface the independent check refuses
the state, and load stepping cuts back. With frozen N the integration is exact for radial stress
paths and first-order accurate in the increment otherwise (``docs/theory.md`` measures it against
the backward-Euler answer of the default variant, :mod:`~dolfinx_nnqem.solvers.nneqm2.return_map`).
A large plastic increment where the stress turns may leave the yield rows without a solution:
the increment then fails, and load stepping cuts back.
"""

from __future__ import annotations

import time

import numpy as np
from petsc4py import PETSc

from dolfinx_nnqem.contact.pair_laws import PairLaws
from dolfinx_nnqem.material.interface import PointwiseMaterial
from dolfinx_nnqem.material.kinematics import DEVIATORIC_BASIS, equivalent_stress
from dolfinx_nnqem.material.kinematics import equivalent_stress_gradient as flow_direction
from dolfinx_nnqem.numerics.nonsmooth import NonsmoothResult, solve_dense
from dolfinx_nnqem.numerics.newton import Globalisation
from dolfinx_nnqem.problem.contact_problem import ContactProblem
from dolfinx_nnqem.solvers.condensation import Condensation
from dolfinx_nnqem.solvers.condensed import CondensedProblem, CondensedSystem, newton_step, rigid_start
from dolfinx_nnqem.solvers.contract import contact_model
from dolfinx_nnqem.solvers.convergence import IterationRecord, SolveReport, logger
from dolfinx_nnqem.solvers.nneqm2.gauss_points import GaussPointOperators
from dolfinx_nnqem.solvers.nneqm2.increment_start import IncrementStart
from dolfinx_nnqem.solvers.timings import Timings

__all__ = ["FrozenDirections", "FrozenSolution"]


class FrozenSolution:
    """A converged frozen-direction increment: the unknowns and the displacement they give."""

    def __init__(self, z: np.ndarray, dgamma: np.ndarray, N: np.ndarray, du: np.ndarray):
        self.z = z  #: (NC, 3) gathered pair unknowns
        self.dgamma = dgamma  #: (NG,) gathered Δγ of the points that can yield
        self.N = N  #: (NG, 5) their frozen directions
        self.du = du  #: owned rows of du


class FrozenDirections:
    """The seed's NNEQM2 increment (module docstring), solved by the dense nonsmooth Newton driver.

    Parameters
    ----------
    problem, gp, elastic
        The problem, its Gauss-point operators and the factorisation of K_e.
    globalisations, max_iterations
        The dense solves' damping rules in turn and their iteration limit.
    """

    def __init__(self, problem: ContactProblem, gp: GaussPointOperators, elastic: Condensation,
                 globalisations: tuple[Globalisation, ...], max_iterations: int):
        self.p, self.gp, self.elastic = problem, gp, elastic
        self.material: PointwiseMaterial = gp.material  # von Mises yield (NNEQM2Solver refuses others)
        self.globalisations, self.max_iterations = globalisations, max_iterations
        self.timings = Timings()
        slope = self.material.hardening({"p": problem.state.p_n.x.array[:gp.n_gp]})
        self.gscale = gp.gather_yielding(gp.stress_unit / (3.0 * gp.mu + slope))  # Δγ = Δγ̃ · gscale
        self._pairs = None  # G Bᵀ (owned rows), its strains (NG, 5, 3NC) and B G Bᵀ: built once per geometry

    def pairs_changed(self) -> None:
        """Forget G Bᵀ, its strains and B G Bᵀ (the contact geometry changed): made again from the same
        factorisation of K_e at the next increment."""
        self._pairs = None

    # -- influence of loads -----------------------------------------------------------------------------
    def _influence(self, loads: PETSc.Mat):
        """Y = G loads (owned rows), S = dev ε(Y) gathered (NG, 5, m), B Y gathered (3NC, m)."""
        p, gp = self.p, self.gp
        if loads.getSize()[1] == 0:  # no Gauss point can yield (MUMPS refuses zero right-hand sides)
            WB = np.zeros((3 * p.contact.num_global, 0)) if p.contact is not None else None
            return np.zeros((loads.getLocalSize()[0], 0)), np.zeros((gp.num_yield_points, 5, 0)), WB
        Y = self.elastic.solve_columns(loads)
        S = gp.dev_strains_of_columns(Y)
        WB = None
        if p.contact is not None:
            model = p.contact
            BY = model.B.matMult(Y)
            m = Y.getSize()[1]
            WB = model.gather(BY.getDenseArray().reshape(model.num_local, 3, m)).reshape(3 * model.num_global, m)
            BY.destroy()
        Y_local = Y.getDenseArray().copy()
        Y.destroy()
        return Y_local, S, WB

    def _pair_influence(self):
        if self._pairs is None:
            t0 = time.perf_counter()
            Bt = self.elastic.transposed_B()
            self._pairs = self._influence(Bt)
            Bt.destroy()
            self.timings.add("flexibility", t0)
        return self._pairs

    def _flow_matrix(self, N: np.ndarray) -> PETSc.Mat:
        """Q (AIJ, V rows × NG): column j is the load w_j B_jᵀ (2μ_j N_j) of Δγ_j = 1 (``N``: the
        gathered directions (NG, 5))."""
        gp, p = self.gp, self.p
        n, NG = gp.n_yield, gp.num_yield_points
        vals = (2.0 * gp.mu[gp.yields, None] * (gp.local_yielding(N) @ DEVIATORIC_BASIS)).reshape(-1)
        row_counts = np.repeat(gp.yields.astype(PETSc.IntType), 9)
        indptr = np.concatenate([[0], np.cumsum(row_counts)]).astype(PETSc.IntType)
        G = PETSc.Mat().createAIJ(
            size=((9 * gp.n_gp, 9 * p.state.num_gauss_points()), (n, NG)),
            csr=(indptr, np.repeat(gp.offset + np.arange(n), 9).astype(PETSc.IntType), vals), comm=p.comm)
        G.assemble()
        Q = gp.A.transposeMatMult(G)
        G.destroy()
        Q.zeroRows(p.constrained_rows(), diag=0.0)
        return Q

    def _mode_loads_of(self, Q: PETSc.Mat) -> np.ndarray:
        """Nᵀ Q (n_r, NG), gathered: the self-equilibrium rows' dependence on Δγ."""
        rows = []
        for v in self.elastic.modes.vectors:
            out = Q.createVecRight()
            Q.multTranspose(v, out)
            rows.append(self.gp.gather(out.getArray(readonly=True).copy()))
            out.destroy()
        return np.array(rows).reshape(len(rows), self.gp.num_yield_points)

    # -- one increment -------------------------------------------------------------------------------
    def solve(self, start: IncrementStart, tol: float, report: SolveReport) -> FrozenSolution | None:
        """The increment from ``start``; None (and ``report.message``) when the dense solve fails."""
        p, gp = self.p, self.gp
        F = start.force_scale
        YB = SB = WBB = None
        nc = p.num_pairs
        if nc:
            YB, SB, WBB = self._pair_influence()
        du0 = self._vector(start.du0)
        e0 = gp.gather_yielding(gp.deviatoric_strains(du0))
        s_n = gp.gather_yielding(start.s_n)
        mu = gp.gather_yielding(gp.mu)
        su = gp.gather_yielding(gp.stress_unit)
        z, alpha = np.zeros((0, 3)), np.zeros(0)  # with contact: the elastic contact solution's, below
        lam = np.zeros(0)
        elastic_iterations = 0
        if nc:
            assert start.laws is not None  # the start has the pairs' data with contact
            z, alpha, elastic_iterations = self._elastic_contact(start, du0, WBB, F, tol)
            lam = start.laws.force(z)[0].reshape(-1)
        # -- the directions, frozen: from σ_n, else from the elastic contact solution's trial stress
        s_dir = s_n.copy()
        flat = equivalent_stress(s_n) <= 1e-8 * su
        s_dir[flat] = s_n[flat] + 2.0 * mu[flat, None] * (e0[flat] + (SB[flat] @ lam if SB is not None else 0.0))
        N = flow_direction(s_dir, su)
        t0 = time.perf_counter()
        Q = self._flow_matrix(N)
        NtQ = self._mode_loads_of(Q)
        YQ, SQ, WBQ = self._influence(Q)
        Q.destroy()
        self.timings.add("plastic_matrix", t0)
        system = self._system(start, du0, WBB, WBQ, NtQ, F, nc)
        rows = _YieldRows(system, gp, self.material, start, e0, SB, SQ, N, self.gscale)
        x0 = system.scaled(z, np.zeros(gp.num_yield_points), alpha)
        result, records = self._dense_solve(system, rows, x0, tol, start)
        du0.destroy()
        report.history.extend(records)
        report.iterations = elastic_iterations + result.iterations
        if not result.converged:
            report.message = f"dense nonsmooth solve failed: {result.message}"
            return None
        x = result.x
        dgt = x[system.n3:system.n3 + system.m]
        a = rows.values(x)[0]
        dgt[(dgt < a) | (dgt < 0.0)] = 0.0  # Δγ exactly 0 on the elastic branch, never negative
        z, dg = system.pair_unknowns(x), system.xi(x)
        du = start.du0 + YQ @ dg
        if nc:
            assert YB is not None and start.laws is not None  # made, given with contact
            du += YB @ start.laws.force(z)[0].reshape(-1)
        if system.n_r:
            du += self.elastic.mode_array() @ system.modes(x)
        return FrozenSolution(z, dg, N, du)

    def _vector(self, owned: np.ndarray) -> PETSc.Vec:
        """A vector laid out like V with the given owned entries."""
        vec = self.elastic.K.createVecRight()
        vec.getArray()[:] = owned
        return vec

    def _system(self, start: IncrementStart, du0: PETSc.Vec, WBB, WBQ, NtQ, F: float, nc: int) -> CondensedSystem:
        """The condensed system with Δγ as its further unknowns: w = w_0 + W_BB λ + W_BQ Δγ + (BN) α,
        w_0 = B (u_n + du_0) + m(ℓ)."""
        p = self.p
        n_r = self.elastic.num_modes
        if nc:
            assert start.laws is not None and start.w_prev is not None  # given with contact
            u = p.state.u_n.x.petsc_vec.copy()
            u.axpy(1.0, du0)
            w0 = contact_model(p).gather(p.relative_displacement(u))
            u.destroy()
            laws, w_prev, r = start.laws, start.w_prev, start.laws.r_max
            BN = self.elastic.mode_coupling()
        else:
            w0, WBB, WBQ = np.zeros((0, 3)), np.zeros((0, 0)), np.zeros((0, self.gp.num_yield_points))
            laws, w_prev, r = PairLaws((), np.zeros(0), np.zeros(0), np.zeros((0, 3), dtype=bool)), np.zeros((0, 3)), 1.0
            BN = np.zeros((0, n_r))
        cond = CondensedProblem(C=WBB, w_free=w0.reshape(-1), w_m=np.zeros(w0.size), lam_m=np.zeros(w0.size),
                                mu_f=laws.mu_f, g0=laws.g0, w_prev=w_prev, r=r, BN=BN,
                                e=self.elastic.mode_loads(start.b))
        xi_scale = self.gscale if WBQ.shape[1] else None  # no Δγ in the elastic contact solve
        return CondensedSystem(laws, cond, F, W_xi=WBQ, E_xi=NtQ, xi_scale=xi_scale)

    def _elastic_contact(self, start: IncrementStart, du0: PETSc.Vec, WBB, F: float, tol: float
                         ) -> tuple[np.ndarray, np.ndarray, int]:
        """(z, α) of the increment's elastic contact solution (Δγ = 0), or the start where the
        dense solve fails (then the directions come from what the predictor says), and the
        iterations it took."""
        p = self.p
        assert start.z is not None and start.w_prev is not None and start.w_start is not None  # called with contact
        system = self._system(start, du0, WBB, np.zeros((3 * p.num_pairs, 0)), np.zeros((self.elastic.num_modes, 0)),
                              F, p.num_pairs)
        x0 = system.scaled(start.z, alpha=rigid_start(system.cond.BN, system.cond.w_free - start.w_prev.reshape(-1)))
        if system.n_r:
            x0 = newton_step(system.residual(x0, frozen=system.at(start.w_start, start.z)), x0, system.advance)
        result = solve_dense(system.residual, x0, tol=tol, max_iter=self.max_iterations,
                             globalisations=self.globalisations, advance=system.advance)
        x = result.x if result.converged else x0
        return system.pair_unknowns(x), system.modes(x), result.iterations

    def _dense_solve(self, system: CondensedSystem, rows: _YieldRows, x0: np.ndarray, tol: float,
                     start: IncrementStart) -> tuple[NonsmoothResult, list]:
        records = []
        last: dict = {}

        def residual(x, frozen=None, yield_branch=None):
            """[pairs; yield; self-equilibrium] rows, matching the unknowns [z; Δγ; α]."""
            pair = system.pair_rows(x, frozen)
            H4, J4, plastic = rows.rows(x, pair, yield_branch)
            last.update(states=pair.state, plastic=plastic)
            n3 = system.n3
            H = np.concatenate([pair.H[:n3], H4, pair.H[n3:]])
            J = np.concatenate([pair.J[:n3], J4, pair.J[n3:]])
            return H, J, pair.lin.cartesian

        def log(k, norm, t, kind):
            counts = np.bincount(np.asarray(last.get("states", []), dtype=np.int64), minlength=3)[:3]
            records.append(IterationRecord(k, 0.0, norm, t if k else float("nan"), kind if k else "",
                                           (int(counts[0]), int(counts[1]), int(counts[2])), last.get("plastic", 0)))
            logger.debug(f"[nneqm2] it {k}: |H̃| = {norm:.3e} {kind} t={t:.2e}")

        t0 = time.perf_counter()
        if system.n_r:
            # a floating body's predictor strains come from a load not yet balanced by contact:
            # one Newton step with the pairs' branches frozen where the increment starts and each
            # Gauss point on the branch it ended the last increment on
            assert start.w_start is not None  # free modes: bodies held by contact
            frozen = system.at(start.w_start, system.pair_unknowns(x0))
            x0 = newton_step(residual(x0, frozen=frozen, yield_branch=rows.last_yielded), x0, system.advance)
        step_rule = system.advance
        if system.nc and system.laws.slip_following:
            # the polar angle of a pair without friction force follows the slip at every step, as
            # in the monolithic solver (theory page, "The polar law's Newton step")
            x0, step_rule = system.on_the_slip(x0), system.advance_on_the_slip
        result = solve_dense(residual, x0, tol=tol, max_iter=self.max_iterations, log=log,
                             globalisations=self.globalisations, advance=step_rule)
        self.timings.add("dense_solve", t0)
        comm = self.p.comm
        if comm.size > 1:  # every rank takes rank 0's decision and solution
            result.converged, result.message, result.x = comm.bcast((result.converged, result.message, result.x),
                                                                    root=0)
        return result, records



class _YieldRows:
    """The Gauss points' yield complementarity rows H4 and their Jacobian (module docstring)."""

    def __init__(self, system: CondensedSystem, gp: GaussPointOperators, material: PointwiseMaterial,
                 start: IncrementStart, e0, SB, SQ, N, gscale):
        self.system = system
        self.e0, self.SB, self.SQ, self.N, self.gscale = e0, SB, SQ, N, gscale
        self.s_n = gp.gather_yielding(start.s_n)
        self.p_n = gp.gather_yielding(start.p_n)
        self.mu = gp.gather_yielding(gp.mu)
        self.material = material.subset(gp.yields).gathered(gp.gather)  # the points that can yield, gathered
        self.su = gp.gather_yielding(gp.stress_unit)
        self.can_flow = np.linalg.norm(N, axis=1) > 0.0  # a point with no direction cannot flow
        dp_n = gp.gather_yielding(gp.problem.state.dp_n.x.array[:gp.n_gp])
        self.last_yielded = dp_n > 0.0  # the branch each point ended the last increment on

    def values(self, x: np.ndarray, lam: np.ndarray | None = None):
        """a = −f/σ_u, b = Δγ̃, the stress deviators s and q at x."""
        system = self.system
        dgt = x[system.n3:system.n3 + system.m]
        dg = dgt * self.gscale
        e = self.e0
        if system.nc:
            if lam is None:
                lam = system.laws.force(system.pair_unknowns(x))[0]
            e = e + self.SB @ lam.reshape(-1)
        e = e + np.einsum("jak,k->ja", self.SQ, dg)
        s = self.s_n + 2.0 * self.mu[:, None] * (e - self.N * dg[:, None])
        q = equivalent_stress(s)
        return -self.material.yield_value(s, {"p": self.p_n + dg}) / self.su, dgt, s, q

    def rows(self, x: np.ndarray, pair, yield_branch=None) -> tuple[np.ndarray, np.ndarray, int]:
        """H4 (NG,), its Jacobian rows (NG, n) and the number of points on the plastic branch."""
        system = self.system
        n3, NG = system.n3, system.m
        a, b, s, q = self.values(x, pair.lam)
        use_a = (a <= b) if yield_branch is None else np.asarray(yield_branch, dtype=bool)  # tie: the yield branch
        use_a = use_a & self.can_flow
        H4 = np.where(use_a, a, b)
        J = np.zeros((NG, system.n))
        qs = np.where(q > 0.0, q, 1.0)
        gvec = np.where((q > 0.0)[:, None], 1.5 * s / qs[:, None], 0.0) * (2.0 * self.mu)[:, None]  # ∂q/∂e
        rows = np.flatnonzero(use_a)
        if rows.size:
            Hh = self.material.hardening({"p": self.p_n + b * self.gscale})  # dσ_y/dp where the points are
            gr = gvec[rows]
            Jgg = np.einsum("ja,jak->jk", gr, self.SQ[rows])
            Jgg[np.arange(rows.size), rows] -= np.einsum("ja,ja->j", gr, self.N[rows]) + Hh[rows]
            J[rows, n3:n3 + NG] = -(Jgg * self.gscale[None, :]) / self.su[rows, None]
            if system.nc:
                JgB = np.einsum("ja,jak->jk", gr, self.SB[rows])  # w.r.t. λ
                JgZ = np.einsum("rnj,njk->rnk", JgB.reshape(rows.size, system.nc, 3), pair.lin.dlam_dy)
                J[rows, :n3] = -(JgZ.reshape(rows.size, n3) * pair.y_scale[None, :]) / self.su[rows, None]
        other = np.flatnonzero(~use_a)
        J[other, n3 + other] = 1.0
        return H4, J, int(np.count_nonzero(use_a & (b > 0.0)))
