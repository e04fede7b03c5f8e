r"""NNEQM2: one nonsmooth system for the pair unknowns and every Gauss point's Δγ (seed §4).

For the load factor ℓ of an increment from the converged state (u_n, σ_n, p_n) the unknowns are
the pair unknowns z (3NC; the law's unknowns, force λ(z)) and the plastic multiplier increment
Δγ_j ≥ 0 at EVERY Gauss point j (NG): a dense nonsmooth system of order 3NC + NG
(``formulation.md`` §5), solved by :func:`dolfinx_nnqem.nonsmooth.solve_nonsmooth`.

Displacement. The ELASTIC stiffness K_e (Dirichlet rows and columns identity) is factorised once
per run. With the Gauss-point load matrix Q, Q_{:,j} = w_j B_jᵀ C N_j (the nodal load of the
plastic strain Δγ_j N_j; w_j the quadrature weight times det J),

    du(z, Δγ) = du_0 + K_e⁻¹ Bᵀ λ(z) + K_e⁻¹ Q Δγ,
    du_0 = K_e⁻¹ [F_ext(ℓ) − ∫ σ_n : ε(v) dx]   (free rows; prescribed increments by lifting),

so the stress σ_j = σ_n,j + C (ε_j(du) − Δγ_j N_j) satisfies ∫ σ : ε(v) dx = F_ext(ℓ) + Bᵀλ at
the free dofs for EVERY (z, Δγ): equilibrium holds by construction (up to the round-off of the
solves), with NNEQM2's own stresses. Writing the residual against ∫ σ_n : ε(v) rather than the
load increment ΔF_ext also removes any drift from the previous increments.

Equations. Pair rows H(w(z, Δγ), z) = 0 with w = B (u_n + du) (the law, as for NNEQM1), and per
Gauss point the yield complementarity, scaled to be dimensionless:

    H4_j = min(−f_j / σ_u,j, Δγ_j (3μ_j + H_j) / σ_u,j),
    f_j = q(σ_j) − σ_y0,j − H_j (p_n,j + Δγ_j).

Both arguments are stresses over σ_u,j = min(σ_y0,j, 10⁻² E_j) (the cap only matters for an
elastic body, stored with a huge σ_y0): −f/σ_u is the distance to the yield surface in units of
the yield stress and (3μ+H)Δγ is the stress a plastic strain Δγ relaxes, so both change by O(1)
per unit of the scaled unknown Δγ̃ = Δγ (3μ+H)/σ_u. At a tie the first argument (the yield
branch) is differentiated (``formulation.md`` §3). The pair rows are divided by the load scale F
and the pair unknowns too (:func:`dolfinx_nnqem.nneqm1._unknown_scale`), so the whole system and
its Jacobian are of order one and the Levenberg–Marquardt parameter is meaningful.

Jacobian (chain rule, dense): with W_BB = B K_e⁻¹ Bᵀ, W_BQ = B K_e⁻¹ Q and the deviatoric
Gauss-point strains S_B = dev ε(K_e⁻¹ Bᵀ), S_Q = dev ε(K_e⁻¹ Q),

    ∂H/∂z = ∂_wH W_BB ∂λ/∂z + ∂_zH,        ∂H/∂Δγ = ∂_wH W_BQ,
    ∂f_j/∂z = 2μ_j n_j · S_B,j ∂λ/∂z,     ∂f_j/∂Δγ_k = 2μ_j n_j · (S_Q,j,k − N_j δ_jk) − H_j δ_jk,

n_j = (3/2) s_j / q_j. Deviatoric tensors are stored in an orthonormal basis of the 5-dimensional
space of symmetric deviators (only the deviator enters q).

Flow directions. As in the seed, N_j = (3/2) s_n,j / q_n,j is computed from the converged
stress at the start of each increment and frozen within it (Q, K_e⁻¹Q, S_Q are built once per
increment: NG solves with the one factorisation). Where σ_n has no deviator (q_n ≤ 10⁻⁸ σ_u,
e.g. in the first increment) the direction of the elastic predictor's trial stress
σ_n + C ε(du_0 + K_e⁻¹Bᵀλ_n) is used; where that has none either, N_j = 0. With frozen N the
integration is an explicit-direction (forward) rule: exact for radial (proportional) stress
paths, first-order accurate in the increment otherwise. ``update_flow_directions=True``
recomputes N_j from the current iterate after each nonsmooth solve and solves the whole system
again with the new Q (a fixed point on N; each pass warm-started from the last solution) until
the plastic strain increments stop changing: max_j 2μ_j Δγ_j |N_new − N_old| / σ_u,j ≤
``flow_rtol``. By default (``flow_update="trial"``) N_new is the direction of the current trial
stress σ_n + C ε(du); ``flow_update="stress"`` takes the current stress σ_n + C (ε(du) − Δγ N).
Both have the same fixed point, the backward-Euler (radial return) update — for von Mises the
returned stress is parallel to the trial stress — i.e. the solution of the monolithic and NNEQM1
solvers; the trial direction removes the Gauss point's own Δγ N from the loop and needs about
half the passes or fewer (11 instead of 25–44 per increment on the tension-then-shear test).

State commit. :meth:`PlasticState.commit` would re-integrate with the radial return, which is
not NNEQM2's stress when N is frozen. The solver therefore hands the converged Gauss-point values
(σ_j, Δγ_j) to :attr:`ContactProblem.pending_gauss_values`; when :meth:`ContactProblem.commit`
commits exactly the displacement NNEQM2 produced it stores them with
:meth:`PlasticState.commit_values` (otherwise the radial return is used). After the commit the
package's own residual F_int(u_n) − F_ext − Bᵀλ evaluates ∫ σ_n : ε(v) with NNEQM2's stresses.
Each increment also records (``increment_info``) that residual computed before the commit, the
largest yield-function violation of the committed stresses, and their largest difference to the
radial-return stress of the same displacement.

MPI: everything distributed is assembled/solved by PETSc (K_e, Q, the strain operator); the dense
system (all pairs, all Gauss points) is gathered on every rank and solved redundantly, and rank
0's solution is broadcast, so every rank takes the same decisions.
"""

from __future__ import annotations

import math
import time

import dolfinx.fem as fem
import dolfinx.fem.petsc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.contact.laws import pin_constrained_directions
from dolfinx_nnqem.convergence import IterationRecord, SolveReport, logger
from dolfinx_nnqem.linalg import create_ksp, factorise, free_dropped_objects
from dolfinx_nnqem.material import strain
from dolfinx_nnqem.nneqm1 import _unknown_scale
from dolfinx_nnqem.nonsmooth import solve_nonsmooth
from dolfinx_nnqem.problem import ContactProblem, SolverOptions, assemble_vector

# Orthonormal basis of the symmetric deviatoric 3×3 tensors (rows: the 9 components, row-major).
_S2, _S6 = 1.0 / math.sqrt(2.0), 1.0 / math.sqrt(6.0)
DEVIATORIC_BASIS = np.array([
    [_S2, 0, 0, 0, -_S2, 0, 0, 0, 0],
    [_S6, 0, 0, 0, _S6, 0, 0, 0, -2 * _S6],
    [0, _S2, 0, _S2, 0, 0, 0, 0, 0],
    [0, 0, _S2, 0, 0, 0, _S2, 0, 0],
    [0, 0, 0, 0, 0, _S2, 0, _S2, 0],
])
"""D (5 × 9): T:D_a are the coordinates of dev T (|dev T|² = Σ_a (T:D_a)²)."""

_SQRT32 = math.sqrt(1.5)


class NNEQM2Solver:
    """One dense nonsmooth system in the pair unknowns and all Gauss points' Δγ.

    Parameters
    ----------
    problem
        A :class:`~dolfinx_nnqem.problem.ContactProblem`, with or without contact (without:
        the system is the NG yield complementarities only).
    options
        Tolerances (``rtol`` applies to the scaled system, see the module docstring),
        ``petsc_options`` for the K_e solves (MUMPS LU by default).
    update_flow_directions
        False (the seed's method): N frozen at its value from the start of the increment.
        True: N recomputed from the current stress after each solve until it stops changing.
    inner_max_iterations
        Iteration limit of each dense nonsmooth solve.
    max_flow_updates
        Limit of the N fixed-point passes (``update_flow_directions=True``).
    flow_rtol
        Convergence of the N fixed point (stress units over σ_u); default ``100 · rtol``.
    flow_update
        How ``update_flow_directions`` recomputes N_j: from the current iterate's trial stress
        σ_n + C ε(du) (``"trial"``, default) or from its stress σ_n + C (ε(du) − Δγ N)
        (``"stress"``). Both have the same fixed point (von Mises: the returned stress is
        parallel to the trial stress); ``"trial"`` needs fewer passes (see the module docstring).
    polar_start
        With the polar law: ``"cartesian"`` (default) solves the system with the Cartesian law
        first and starts the polar solve from that solution; ``"direct"`` starts the polar
        solve from the previous increment's unknowns (the seed's procedure; slow and often cut
        back on the two-beam benchmark).

    Notes
    -----
    Reporting: ``SolveReport.system_order`` = 3NC + NG; ``iterations`` counts the dense
    nonsmooth iterations (all passes, Cartesian warm starts included); in ``history`` the
    ``contact`` field holds the norm of the whole scaled system [H/F; H4] and ``equilibrium``
    is 0 for the intermediate iterates (equilibrium holds by construction for every iterate) and,
    in the last record, the measured own-stress residual. ``increment_info`` (one dict per
    converged increment) adds the checks (own-stress equilibrium, yield violation, difference to
    the radial-return stress), the number of flow-direction passes and the wall time;
    ``timings`` accumulates seconds per phase (``flexibility``: K_e⁻¹Bᵀ once; ``plastic_matrix``:
    Q, K_e⁻¹Q and its strains, once per increment or pass; ``dense_solve``; ``solve``: the
    predictor solves).
    """

    name = "nneqm2"

    def __init__(self, problem: ContactProblem, options: SolverOptions | None = None, *,
                 update_flow_directions: bool = False, inner_max_iterations: int = 100,
                 max_flow_updates: int = 50, flow_rtol: float | None = None,
                 polar_start: str = "cartesian", flow_update: str = "trial"):
        self.problem = problem
        self.options = options or SolverOptions()
        self.update_flow_directions = bool(update_flow_directions)
        if polar_start not in ("cartesian", "direct"):
            raise ValueError(f"polar_start = {polar_start!r}; expected 'cartesian' or 'direct'")
        self.polar_start = polar_start
        if flow_update not in ("trial", "stress"):
            raise ValueError(f"flow_update = {flow_update!r}; expected 'trial' or 'stress'")
        self.flow_update = flow_update
        self.warm_start_iterations = 0  #: iterations spent in Cartesian warm starts (polar law)
        self.inner_max_iterations = inner_max_iterations
        self.max_flow_updates = max_flow_updates
        self.flow_rtol = 100.0 * self.options.rtol if flow_rtol is None else float(flow_rtol)
        self.ksp = create_ksp(problem.comm, f"nnqem_nneqm2_{id(self)}_", self.options.petsc_options)
        self.timings: dict[str, float] = {}
        self.increment_info: list[dict] = []  #: per converged solve: checks and counts
        self._Ke = None
        self._YB = None
        self._setup_gauss_point_operators()

    # -- set-up ------------------------------------------------------------------------------
    def _setup_gauss_point_operators(self) -> None:
        """Strain operator, quadrature weights, Gauss-point material values, helper forms."""
        t0 = time.perf_counter()
        p, st = self.problem, self.problem.state
        V, Wt, Ws = p.V, st.W_tensor, st.W_scalar
        # A: rows (j, kl) of the owned Gauss points, A u = w_j ε_j(u)_kl
        du, tau = ufl.TrialFunction(V), ufl.TestFunction(Wt)
        self._A = dolfinx.fem.petsc.assemble_matrix(jit.form(ufl.inner(strain(du), tau) * st.dx))
        self._A.assemble()
        phi = ufl.TestFunction(Ws)
        wv = assemble_vector(jit.form(phi * st.dx), Ws)
        imap = Ws.dofmap.index_map
        self.n_gp = imap.size_local
        self.gp_offset = imap.local_range[0]
        self.num_gauss_points = imap.size_global
        self._w = wv.getArray(readonly=True)[:self.n_gp].copy()
        wv.destroy()
        if self._A.getLocalSize()[0] != 9 * self.n_gp:
            raise RuntimeError("NNEQM2: the strain operator's rows do not match the Gauss points")
        points = compat.interpolation_points(Ws)

        def at_points(expr):
            f = fem.Function(Ws)
            f.interpolate(jit.expression(expr, points))
            return f.x.array[:self.n_gp].copy()

        self._mu = at_points(st.mu)
        self._lmbda = at_points(st.lmbda)
        self._sy = at_points(st.sigma_y0)
        self._Hh = at_points(st.H)
        E = at_points(st.E)
        self._su = np.minimum(self._sy, 1e-2 * E)  # stress unit of the yield rows
        self._gscale = self._su / (3.0 * self._mu + self._Hh)  # Δγ = Δγ̃ · gscale
        # ∫ σ : ε(v) for a quadrature stress (NNEQM2's own internal force)
        v = ufl.TestFunction(V)
        self._sig_fn = fem.Function(Wt)
        self._Fsig_form = jit.form(ufl.inner(self._sig_fn, strain(v)) * st.dx)
        # lifting: K_e g (all rows) for a displacement g carrying the prescribed increments
        self._lift_fn = fem.Function(V)
        self._lift_form = jit.form(ufl.inner(st.elastic_stress(strain(self._lift_fn)), strain(v)) * st.dx)
        # radial return of the current u from the converged state (for the report only)
        self._rm_expr = jit.expression(st.return_map(p.u).sigma, compat.interpolation_points(Wt))
        self._tick("setup", t0)

    def _factorise(self) -> None:
        p = self.problem
        t0 = time.perf_counter()
        self._Ke = p.assemble_elastic_stiffness()
        self._tick("assembly", t0)
        t0 = time.perf_counter()
        factorise(self.ksp, self._Ke, "NNEQM2", "the elastic stiffness K_e")
        self._tick("factorisation", t0)
        if p.has_contact:
            t0 = time.perf_counter()
            Bt = p.transposed_B()
            self._YB, self._SB, self._WBB = self._influence(Bt)
            Bt.destroy()
            self._tick("flexibility", t0)

    def _influence(self, rhs_aij: PETSc.Mat):
        """Y = K_e⁻¹ R (owned rows), S = dev ε(Y) gathered (NG, 5, m), B Y gathered (3NC, m)."""
        p = self.problem
        R_dense = rhs_aij.convert("dense")
        Y = R_dense.duplicate()
        self.ksp.matSolve(R_dense, Y)
        S = self._dev_strains_of(Y)
        WB = None
        if p.has_contact:
            BY = p.pairs.B.matMult(Y)
            ncols = Y.getSize()[1]
            WB = p.pairs.gather(BY.getDenseArray().reshape(p.pairs.num_local, 3, ncols)).reshape(
                3 * p.num_pairs, ncols)
            BY.destroy()
        Y_local = Y.getDenseArray().copy()
        for m in (R_dense, Y):
            m.destroy()
        return Y_local, S, WB

    def _dev_strains_of(self, Y: PETSc.Mat) -> np.ndarray:
        """dev ε_j of every column of the dense matrix Y, gathered: (NG, 5, ncols)."""
        AY = self._A.matMult(Y)
        ncols = Y.getSize()[1]
        e9 = AY.getDenseArray().reshape(self.n_gp, 9, ncols)
        e5 = (DEVIATORIC_BASIS @ e9.transpose(1, 0, 2).reshape(9, -1)).reshape(5, self.n_gp, ncols)
        e5 = e5.transpose(1, 0, 2) / self._w[:, None, None]
        AY.destroy()
        return self._gather_gp(e5)

    # -- small helpers -------------------------------------------------------------------------
    def _gather_gp(self, local: np.ndarray) -> np.ndarray:
        """Owned Gauss-point rows of every rank, in global Gauss-point order, on every rank."""
        comm = self.problem.comm
        if comm.size == 1:
            return np.asarray(local)
        return np.concatenate(comm.allgather(np.ascontiguousarray(local)), axis=0)

    def _local_gp(self, array_global: np.ndarray) -> np.ndarray:
        return array_global[self.gp_offset:self.gp_offset + self.n_gp]

    def _strains9(self, vec: PETSc.Vec) -> np.ndarray:
        """ε_j(u) at the owned Gauss points, (n_gp, 3, 3), for a vector laid out like V."""
        e = self._A.createVecLeft()
        self._A.mult(vec, e)
        out = e.getArray(readonly=True).reshape(self.n_gp, 3, 3) / self._w[:, None, None]
        e.destroy()
        return out

    def _quadrature_force(self, sigma_local: np.ndarray) -> PETSc.Vec:
        """∫ σ : ε(v) dx for owned Gauss-point stresses (n_gp, 3, 3)."""
        f = self._sig_fn
        f.x.array[:9 * self.n_gp] = np.asarray(sigma_local).reshape(-1)
        f.x.scatter_forward()
        F = compat.create_vector(self.problem.V)
        with F.localForm() as local:
            local.set(0.0)
        dolfinx.fem.petsc.assemble_vector(F, self._Fsig_form)
        F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        return F

    def _flow_matrix(self, N5_local: np.ndarray) -> PETSc.Mat:
        """Q = Aᵀ G (AIJ, V rows × NG): column j is the load w_j B_jᵀ (2μ_j N_j) of Δγ_j = 1."""
        n, off, NG = self.n_gp, self.gp_offset, self.num_gauss_points
        vals = (2.0 * self._mu[:, None] * (N5_local @ DEVIATORIC_BASIS)).reshape(-1)
        G = PETSc.Mat().createAIJ(
            size=((9 * n, 9 * NG), (n, NG)),
            csr=(np.arange(9 * n + 1, dtype=PETSc.IntType),
                 np.repeat(off + np.arange(n), 9).astype(PETSc.IntType), vals),
            comm=self.problem.comm)
        G.assemble()
        Q = self._A.transposeMatMult(G)
        G.destroy()
        Q.zeroRows(self.problem.constrained_rows(), diag=0.0)
        return Q

    def _z_scale(self, F: float, law=None) -> np.ndarray:
        """Scale of the pair unknowns (forces with the load scale F, the polar angle 1)."""
        p = self.problem
        law = p.law if law is None else law
        return np.tile(_unknown_scale(law, F), p.num_pairs) if p.has_contact else np.zeros(0)

    def _tick(self, key: str, t0: float) -> None:
        self.timings[key] = self.timings.get(key, 0.0) + time.perf_counter() - t0

    # -- one increment ---------------------------------------------------------------------------
    def solve_increment(self, load_factor: float) -> SolveReport:
        p, st, opts = self.problem, self.problem.state, self.options
        p.pending_gauss_values = None
        if self._Ke is None:
            self._factorise()
        t_start = time.perf_counter()
        p.apply_prescribed_displacements(load_factor)
        p.predict_contact()
        nc = p.num_pairs
        NG = self.num_gauss_points
        report = SolveReport(converged=False, iterations=0, system_order=3 * nc + NG)
        n_u = p.V.dofmap.index_map.size_local * 3

        # -- the elastic predictor du_0 = K_e⁻¹ [F_ext − ∫σ_n:ε(v)], prescribed increments lifted
        t0 = time.perf_counter()
        sigma_n = st.sigma_n.x.array[:9 * self.n_gp].reshape(self.n_gp, 3, 3).copy()
        F_n = self._quadrature_force(sigma_n)
        F_ext = p.external_force()
        du_D = np.zeros_like(p.u.x.array)
        du_D[p.bc_dofs] = p.u.x.array[p.bc_dofs] - st.u_n.x.array[p.bc_dofs]
        self._lift_fn.x.array[:] = du_D
        lift = assemble_vector(self._lift_form, p.V)
        b = F_ext.copy()
        b.axpy(-1.0, F_n)
        b.axpy(-1.0, lift)
        owned_bc = p.owned_bc_dofs()
        b_arr = b.getArray()
        b_arr[owned_bc] = du_D[owned_bc]
        del b_arr
        self._tick("assembly", t0)
        du0 = b.duplicate()
        t0 = time.perf_counter()
        self.ksp.solve(b, du0)
        self._tick("solve", t0)
        du0_arr = du0.getArray(readonly=True).copy()
        e0 = self._gather_gp(np.einsum("ak,jk->ja", DEVIATORIC_BASIS,
                                       self._strains9(du0).reshape(self.n_gp, 9)))
        scale = max(F_ext.norm(), F_n.norm())

        # -- gathered pair data (global order, every rank)
        if nc:
            pairs = p.pairs
            g = pairs.gather(np.hstack([p.w_n, pairs.g0[:, None], p.mu_f[:, None], p.z,
                                        p.constrained_directions.astype(float)]))
            w_prev, g0, mu_f, z_start = g[:, 0:3], g[:, 3], g[:, 4], g[:, 5:8]
            constrained = g[:, 8:11] > 0.5
            un_plus = st.u_n.x.petsc_vec.copy()
            un_plus.axpy(1.0, du0)
            w0 = pairs.gather(pairs.relative_displacement(un_plus)).reshape(-1)
            un_plus.destroy()
            lam_start, _ = p.law.force(z_start)
            scale = max(scale, pairs.global_force(p.contact_force()).norm())
        else:
            w_prev = g0 = mu_f = constrained = w0 = None
            z_start = np.zeros((0, 3))
            lam_start = np.zeros((0, 3))
        F = max(scale, opts.atol)
        tol = opts.rtol + opts.atol / F

        # -- Gauss-point data (global order)
        s_n = self._gather_gp(np.einsum("ak,jk->ja", DEVIATORIC_BASIS, sigma_n.reshape(self.n_gp, 9)))
        mu, sy, Hh, su, gscale = (self._gather_gp(a) for a in (self._mu, self._sy, self._Hh, self._su,
                                                                self._gscale))
        p_n = self._gather_gp(st.p_n.x.array[:self.n_gp])
        SB = self._SB if nc else np.zeros((NG, 5, 0))
        WBB = self._WBB if nc else None

        # -- flow directions at the start of the increment
        q_n = _SQRT32 * np.linalg.norm(s_n, axis=1)
        s_dir = s_n.copy()
        flat = q_n <= 1e-8 * su
        if np.any(flat):
            s_tr = s_n + 2.0 * mu[:, None] * (e0 + SB @ lam_start.reshape(-1))
            s_dir[flat] = s_tr[flat]
        N = _flow_direction(s_dir, su)

        x = np.concatenate([z_start.reshape(-1) / self._z_scale(F), np.zeros(NG)])
        data = dict(nc=nc, NG=NG, F=F, e0=e0, s_n=s_n, mu=mu, sy=sy, Hh=Hh, su=su, gscale=gscale,
                    p_n=p_n, SB=SB, WBB=WBB, w0=w0, w_prev=w_prev, g0=g0, mu_f=mu_f,
                    constrained=constrained)
        flow_updates, change = 0, float("nan")
        total_its = 0
        while True:
            free_dropped_objects(self.problem.petsc_comms)
            # -- Q, K_e⁻¹Q and its strains/relative displacements for the current N
            t0 = time.perf_counter()
            Q = self._flow_matrix(self._local_gp(N))
            YQ, SQ, WBQ = self._influence(Q)
            Q.destroy()
            self._tick("plastic_matrix", t0)
            data.update(N=N, SQ=SQ, WBQ=WBQ)
            result, records = self._solve_system(x, data, tol, total_its)
            report.history.extend(records)
            total_its += result.iterations
            report.iterations = total_its
            if not result.converged:
                report.message = (f"dense nonsmooth solve failed (flow-direction pass {flow_updates}): "
                                  f"{result.message}")
                return report
            x = result.x
            # clean Δγ: exactly 0 on the elastic branch, never negative
            dgt = x[3 * nc:]
            a, _ = self._yield_rows(x, data, p.law)[:2]
            dgt[(dgt < a) | (dgt < 0.0)] = 0.0
            z = (x[:3 * nc] * self._z_scale(F)).reshape(nc, 3)
            dg = dgt * gscale
            lam = p.law.force(z)[0].reshape(-1) if nc else np.zeros(0)
            # stresses at the end of this pass
            s_end = s_n + 2.0 * mu[:, None] * (e0 + SB @ lam + np.einsum("jak,k->ja", SQ, dg)
                                               - N * dg[:, None])
            if not self.update_flow_directions:
                break
            s_new = s_end if self.flow_update == "stress" else s_end + 2.0 * mu[:, None] * N * dg[:, None]
            N_new = _flow_direction(s_new, su, fallback=N)
            change = float(np.max(2.0 * mu * dg * np.linalg.norm(N_new - N, axis=1) / su, initial=0.0))
            logger.info(f"[{self.name}] flow-direction pass {flow_updates}: "
                        f"max 2μ Δγ |ΔN| / σ_y = {change:.3e}")
            if change <= self.flow_rtol:
                break
            flow_updates += 1
            if flow_updates > self.max_flow_updates:
                report.message = (f"flow directions did not settle in {self.max_flow_updates} passes "
                                  f"(last change {change:.3e} > {self.flow_rtol:.1e})")
                return report
            N = N_new

        # -- displacement, stress, pending state
        t0 = time.perf_counter()
        dg_local = self._local_gp(dg)
        du = du0_arr + YQ @ dg
        if nc:
            du += self._YB @ lam
        u_bc = p.u.x.array[p.bc_dofs].copy()  # the prescribed values, kept exactly
        p.u.x.array[:n_u] = st.u_n.x.array[:n_u] + du
        p.u.x.scatter_forward()
        p.u.x.array[p.bc_dofs] = u_bc
        if nc:
            p.z = z[p.pairs.offset:p.pairs.offset + p.pairs.num_local].copy()
        du_vec = compat.create_vector(p.V)
        du_vec.getArray()[:] = du
        eps = self._strains9(du_vec)
        du_vec.destroy()
        N9 = (self._local_gp(N) @ DEVIATORIC_BASIS).reshape(self.n_gp, 3, 3)
        eps_e = eps - dg_local[:, None, None] * N9
        sigma = sigma_n + (self._lmbda[:, None, None] * np.trace(eps_e, axis1=1, axis2=2)[:, None, None]
                           * np.eye(3) + 2.0 * self._mu[:, None, None] * eps_e)
        p.pending_gauss_values = (p.u.x.array.copy(), sigma, dg_local.copy())
        info = self._checks(sigma, dg_local, F_ext, load_factor, total_its, flow_updates, change)
        self._tick("stress_update", t0)
        info["wall_time_s"] = time.perf_counter() - t_start
        self.increment_info.append(info)
        last = report.history[-1]
        report.history[-1] = IterationRecord(last.iteration, info["equilibrium_residual"], last.contact,
                                             last.step_length, "", last.states, info["plastic_points"])
        logger.info(f"[{self.name}] ℓ = {load_factor:.6g}: order {3 * nc + NG}, {total_its} iterations, "
                    f"{flow_updates} flow updates, own-stress |R|/F = {info['equilibrium_residual']:.2e}, "
                    f"max f/σ_y = {info['max_yield_violation']:.2e}, "
                    f"max |σ − σ_return map|/σ_y = {info['return_map_difference']:.2e}")
        report.converged, report.message = True, "converged"
        return report

    # -- the dense nonsmooth system -------------------------------------------------------------
    def _yield_rows(self, x, d, law):
        """a = −f/σ_u, b = Δγ̃, the stress deviators s and q at the scaled unknowns ``x``."""
        nc = d["nc"]
        dgt = x[3 * nc:]
        dg = dgt * d["gscale"]
        if nc:
            z = (x[:3 * nc] * self._z_scale(d["F"], law)).reshape(nc, 3)
            lam = law.force(z)[0].reshape(-1)
            e = d["e0"] + d["SB"] @ lam
        else:
            e = d["e0"]
        e = e + np.einsum("jak,k->ja", d["SQ"], dg)
        s = d["s_n"] + 2.0 * d["mu"][:, None] * (e - d["N"] * dg[:, None])
        q = _SQRT32 * np.linalg.norm(s, axis=1)
        f = q - d["sy"] - d["Hh"] * (d["p_n"] + dg)
        return -f / d["su"], dgt, s, q

    def _solve_system(self, x0, d, tol, it_offset):
        """The dense system with the problem's law; for the polar law optionally warm-started.

        ``polar_start="cartesian"``: the same system is first solved with the Cartesian
        (Alart–Curnier) law, whose solution is the polar law's too; the polar unknowns
        (p_n, |q|, θ) are read off it (θ of a pair without friction force from its slip
        direction, which H3 needs) and the polar system is then solved from there, usually
        in one or two Newton steps. The damped Newton/LM iteration on the polar form from the
        previous increment's unknowns crawls with tiny line-search steps on this benchmark.
        """
        p = self.problem
        law = p.law
        if not (d["nc"] and law.name == "polar" and self.polar_start == "cartesian"):
            return self._dense_solve(x0, d, tol, it_offset, law)
        from dolfinx_nnqem.contact.laws import get_law

        nc, F = d["nc"], d["F"]
        cart = get_law("alart-curnier")
        z0 = (x0[:3 * nc] * self._z_scale(F, law)).reshape(nc, 3)
        lam0 = law.force(z0)[0]
        xc = np.concatenate([lam0.reshape(-1) / self._z_scale(F, cart), x0[3 * nc:]])
        first, records = self._dense_solve(xc, d, tol, it_offset, cart)
        if not first.converged:
            first.message = f"Cartesian warm start: {first.message}"
            return first, records
        lam = first.x[:3 * nc].reshape(nc, 3) * F
        dg = first.x[3 * nc:] * d["gscale"]
        w = (d["w0"] + d["WBB"] @ lam.reshape(-1) + d["WBQ"] @ dg).reshape(nc, 3)
        z = law.unknowns(lam)
        slip = w[:, 1:3] - d["w_prev"][:, 1:3]
        no_force = z[:, 1] <= 1e-12 * F
        z[no_force, 2] = np.arctan2(slip[no_force, 1], slip[no_force, 0])
        xp = np.concatenate([z.reshape(-1) / self._z_scale(F, law), first.x[3 * nc:]])
        second, more = self._dense_solve(xp, d, tol, it_offset + first.iterations, law)
        second.iterations += first.iterations
        self.warm_start_iterations += first.iterations
        return second, records + more[1:]

    def _dense_solve(self, x0, d, tol, it_offset, law):
        """solve_nonsmooth on the scaled [pair rows / F; H4] with the chain-rule Jacobian."""
        p = self.problem
        nc, NG, F = d["nc"], d["NG"], d["F"]
        z_scale = self._z_scale(F, law)
        gscale, mu, su, Hh, N, SQ, SB = d["gscale"], d["mu"], d["su"], d["Hh"], d["N"], d["SQ"], d["SB"]
        force_unit = p.r * p.characteristic_length() if nc else 1.0
        n3 = 3 * nc
        last = {}

        def residual(x):
            dgt = x[n3:]
            dg = dgt * gscale
            Hs = np.empty(n3 + NG)
            J = np.zeros((n3 + NG, n3 + NG))
            if nc:
                z = (x[:n3] * z_scale).reshape(nc, 3)
                lam, dlam_dz = law.force(z)
                w = (d["w0"] + d["WBB"] @ lam.reshape(-1) + d["WBQ"] @ dg).reshape(nc, 3)
                ev = pin_constrained_directions(
                    law, law.evaluate(w, d["w_prev"], z, d["g0"], d["mu_f"], p.r), z, d["constrained"],
                    force_unit)
                Hs[:n3] = ev.H.reshape(-1) / F
                # pair rows: blockdiag(∂H/∂w) [W_BB Λ', W_BQ] + [blockdiag(∂H/∂z), 0]
                DwW = np.einsum("nij,njk->nik", ev.dH_dw, d["WBB"].reshape(nc, 3, n3))
                Jz = np.einsum("anj,njk->ank", DwW.reshape(n3, nc, 3), dlam_dz).reshape(n3, nc, 3)
                idx = np.arange(nc)
                Jzb = Jz.reshape(nc, 3, nc, 3)
                Jzb[idx, :, idx, :] += ev.dH_dz
                J[:n3, :n3] = Jz.reshape(n3, n3) * z_scale[None, :] / F
                DwQ = np.einsum("nij,njk->nik", ev.dH_dw, d["WBQ"].reshape(nc, 3, NG))
                J[:n3, n3:] = DwQ.reshape(n3, NG) * gscale[None, :] / F
                last["states"] = ev.state
            a, b, s, q = self._yield_rows(x, d, law)
            use_a = a <= b  # tie: the first argument (yield branch)
            Hs[n3:] = np.where(use_a, a, b)
            # ∂(−f/σ_u): g_j = 2μ_j (3/2) s_j / q_j
            qs = np.where(q > 0.0, q, 1.0)
            gvec = np.where((q > 0.0)[:, None], 1.5 * s / qs[:, None], 0.0) * (2.0 * mu)[:, None]
            rows = np.flatnonzero(use_a)
            if rows.size:
                gr = gvec[rows]
                Jgg = np.einsum("ja,jak->jk", gr, SQ[rows])
                Jgg[np.arange(rows.size), rows] -= np.einsum("ja,ja->j", gr, N[rows]) + Hh[rows]
                J[n3 + rows, n3:] = -(Jgg * gscale[None, :]) / su[rows, None]
                if nc:
                    JgB = np.einsum("ja,jak->jk", gr, SB[rows])  # (r, 3nc) w.r.t. λ
                    JgZ = np.einsum("rnj,njk->rnk", JgB.reshape(rows.size, nc, 3), dlam_dz)
                    J[n3 + rows, :n3] = -(JgZ.reshape(rows.size, n3) * z_scale[None, :]) / su[rows, None]
            other = np.flatnonzero(~use_a)
            J[n3 + other, n3 + other] = 1.0
            last["Hc"] = float(np.linalg.norm(Hs[:n3]))
            last["H4"] = float(np.linalg.norm(Hs[n3:]))
            last["plastic"] = int(np.count_nonzero(use_a & (b > 0.0)))
            return Hs, J

        records = []

        def log(k, norm, t, kind):
            states = (0, 0, 0)
            if nc:
                counts = np.bincount(np.asarray(last["states"], dtype=np.int64), minlength=3)[:3]
                states = tuple(int(c) for c in counts)
            records.append(IterationRecord(it_offset + k, 0.0, norm, t if k else float("nan"),
                                           kind if k else "", states, last["plastic"]))
            logger.debug(f"[{self.name}] it {it_offset + k}: |H̃| = {norm:.3e} (pairs {last['Hc']:.3e}, "
                         f"yield {last['H4']:.3e}) {kind} t={t:.2e}")

        t0 = time.perf_counter()
        result = solve_nonsmooth(residual, x0, tol=tol, max_iter=self.inner_max_iterations, log=log)
        self._tick("dense_solve", t0)
        # every rank takes rank 0's decision and solution
        comm = p.comm
        if comm.size > 1:
            converged, message, xs = comm.bcast((result.converged, result.message, result.x), root=0)
            result.converged, result.message, result.x = converged, message, xs
        return result, records

    # -- checks of the converged increment ----------------------------------------------------
    def _checks(self, sigma, dg_local, F_ext, load_factor, iterations, flow_updates, change) -> dict:
        p, st = self.problem, self.problem.state
        comm = p.comm
        # equilibrium with NNEQM2's own stresses (before the commit)
        R = self._quadrature_force(sigma)
        F_int_norm = R.norm()
        R.axpy(-1.0, F_ext)
        scale = max(F_ext.norm(), F_int_norm)
        if p.has_contact:
            Bl = p.pairs.global_force(p.contact_force())
            scale = max(scale, Bl.norm())
            R.axpy(-1.0, Bl)
        R_free = p.free_residual(R)
        eq = R_free.norm() / max(scale, self.options.atol)
        # the radial-return stress of the same displacement, from the same converged state
        rm = fem.Function(st.W_tensor)
        rm.interpolate(self._rm_expr)
        sig_rm = rm.x.array[:9 * self.n_gp].reshape(self.n_gp, 3, 3)
        diff = np.linalg.norm((sigma - sig_rm).reshape(self.n_gp, 9), axis=1) / self._su
        s = np.einsum("ak,jk->ja", DEVIATORIC_BASIS, sigma.reshape(self.n_gp, 9))
        f = (_SQRT32 * np.linalg.norm(s, axis=1) - self._sy
             - self._Hh * (st.p_n.x.array[:self.n_gp] + dg_local)) / self._su
        return {
            "load_factor": float(load_factor),
            "system_order": 3 * p.num_pairs + self.num_gauss_points,
            "iterations": int(iterations),
            "flow_updates": int(flow_updates),
            "flow_change": change,
            "equilibrium_residual": float(eq),
            "return_map_difference": comm.allreduce(float(np.max(diff, initial=0.0)), op=MPI.MAX),
            "max_yield_violation": comm.allreduce(float(np.max(f, initial=-np.inf)), op=MPI.MAX),
            "plastic_points": comm.allreduce(int(np.count_nonzero(dg_local > 0.0)), op=MPI.SUM),
        }


def _flow_direction(s: np.ndarray, su: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray:
    """N = (3/2) s / q in the deviatoric basis; 0 (or ``fallback``) where q ≤ 10⁻⁸ σ_u."""
    q = _SQRT32 * np.linalg.norm(s, axis=1)
    ok = q > 1e-8 * su
    N = np.zeros_like(s) if fallback is None else fallback.copy()
    N[ok] = 1.5 * s[ok] / q[ok, None]
    return N


__all__ = ["NNEQM2Solver", "DEVIATORIC_BASIS"]
