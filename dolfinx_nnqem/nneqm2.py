r"""NNEQM2: one nonsmooth system for the pair unknowns and every Gauss point's Δγ (seed §4).

For the load factor ℓ of an increment from the converged state (u_n, σ_n, p_n) the unknowns are
the pair unknowns z (3NC; the law's unknowns, force λ(z)) and the plastic multiplier increment
Δγ_j ≥ 0 at EVERY Gauss point j (NG): a dense nonsmooth system of order 3NC + NG
(``formulation.md`` §5), solved by the package's Newton driver on dense arrays
(:func:`dolfinx_nnqem.nonsmooth.solve_nonsmooth`). "Every Gauss point" means every Gauss point of
a material that can yield: at a point of an elastic material (σ_y0 = inf) Δγ_j = 0 always, so it
carries no unknown and no row (the solution is the same; an elastic body adds nothing to the
order). NG below counts the Gauss points that can yield.

Displacement. The ELASTIC stiffness K_e (Dirichlet rows and columns identity) is factorised once
per run (:class:`~dolfinx_nnqem.condensation.Condensation`). With the Gauss-point load matrix Q, Q_{:,j} = w_j B_jᵀ C N_j (the nodal load of the
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
and the pair unknowns too (each law's ``unknown_scale``), so the whole system and
its Jacobian are of order one and the Levenberg–Marquardt parameter is meaningful.

Floating bodies. Where a body has free rigid modes N (held only by contact), K_e⁻¹ is the
generalised inverse G of :mod:`dolfinx_nnqem.condensation`, du gains N α, w gains (B N) α (the
stresses do not: ε(N) = 0), and the self-equilibrium rows Nᵀ(b + Bᵀλ + QΔγ) = 0 (divided by F)
join the system: order 3NC + NG + n_r.

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
the plastic strain increments stop changing and the stress lies in the yield surface:
max_j 2μ_j Δγ_j |N_new − N_old| / σ_u,j ≤ ``flow_rtol`` and max_j f_j(q) / σ_u,j ≤ ``flow_rtol``.
By default (``flow_update="trial"``) N_new is the direction of the current trial
stress σ_n + C ε(du); ``flow_update="stress"`` takes the current stress σ_n + C (ε(du) − Δγ N).
Both have the same fixed point, the backward-Euler (radial return) update — for von Mises the
returned stress is parallel to the trial stress — i.e. the solution of the monolithic and NNEQM1
solvers; the trial direction removes the Gauss point's own Δγ N from the loop and needs about
half the passes or fewer (11 instead of 25–44 per increment on the tension-then-shear test).
The passes solve the yield rows projected on their N, q_N = N : s instead of q(s): affine in Δγ,
so a pass always has a solution, and equal to q where N ∥ s, i.e. at the fixed point. The fixed
point is accelerated by Anderson mixing (``flow_acceleration``). With frozen N the yield rows may
have no solution (the stress turns in a large plastic increment); then, before the load stepping
cuts back, the increment is solved again with updated directions from the elastic predictor's
trial directions (``retry_updating_directions``; ``increment_info[k]["directions"]``).

State commit. :meth:`PlasticState.commit` would re-integrate with the radial return, which is
not NNEQM2's stress when N is frozen. The solver therefore returns the converged Gauss-point
values (σ_j, Δγ_j) in ``SolveReport.gauss_point_values``; when :meth:`ContactProblem.commit`
is given them for exactly the displacement NNEQM2 produced it stores them with
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

import time
from dataclasses import dataclass

import dolfinx.fem as fem
import dolfinx.fem.petsc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.anderson import AndersonMixing
from dolfinx_nnqem.condensation import Condensation
from dolfinx_nnqem.contact.model import PairLaws
from dolfinx_nnqem.convergence import IterationRecord, SolveReport, logger
from dolfinx_nnqem.linalg import free_dropped_objects
from dolfinx_nnqem.material import (DEVIATORIC_BASIS, GaussPointValues, can_yield, deviator_coordinates,
                                    deviator_tensors, elastic_stress, equivalent_stress, flow_direction, strain,
                                    yield_function, yield_stress_unit)
from dolfinx_nnqem.nneqm1 import rigid_start
from dolfinx_nnqem.nonsmooth import NonsmoothResult, solve_dense
from dolfinx_nnqem.problem import ContactProblem, assemble_vector
from dolfinx_nnqem.solver import NNEQM2Options, SolverOptions

SLIDING_WINDOW = 10
"""Iterates in a row at which no pair holding a motion that only friction holds sticks (the body
slides along it: past the friction limit no equilibrium exists) after which a dense solve stops
instead of creeping: the Levenberg–Marquardt steps still lower |H| by a tenth per ten iterations
(the stall test's measure) towards a least-squares point, up to 100 iterations of the
order-924 system per attempt on the sliding three-block case (issue 31: 87 s to fail, 23 s
with this stop; a window of 5 gained only 3 s more)."""


class _Sliding(Exception):
    """Raised inside a dense solve when a body only friction holds slides (see SLIDING_WINDOW)."""

__all__ = ["NNEQM2Solver"]


@dataclass
class _Increment:
    """Everything the dense system of one increment needs, gathered in global order.

    Pairs: ``laws`` (their laws, gaps, μ_f), ``w_prev`` (NC, 3), ``w0`` = B(u_n + du_0) + m(ℓ)
    (3NC,), the flexibilities W_BB = B G Bᵀ (3NC, 3NC) and W_BQ = B G Q (3NC, NG), the free
    rigid modes B N (3NC, n_r), with their loads e = Nᵀ b (n_r,) and Nᵀ Q (n_r, NG).
    Gauss points that can yield (NG): the converged deviators ``s_n`` (NG, 5) and p_n, the
    material values μ, σ_y0, H, the stress unit σ_u and the scale of Δγ, the deviatoric strains of
    du_0 (``e0``, (NG, 5)), of G Bᵀ (``SB``, (NG, 5, 3NC)) and of G Q (``SQ``, (NG, 5, NG)), and
    the frozen flow directions N (NG, 5).
    """

    nc: int
    NG: int
    F: float  #: the force scale
    laws: PairLaws | None
    w_prev: np.ndarray | None
    w0: np.ndarray | None
    WBB: np.ndarray | None
    BN: np.ndarray
    e: np.ndarray
    s_n: np.ndarray
    p_n: np.ndarray
    mu: np.ndarray
    sy: np.ndarray
    Hh: np.ndarray
    su: np.ndarray
    gscale: np.ndarray
    e0: np.ndarray
    SB: np.ndarray
    r: float
    w_start: np.ndarray | None = None  #: w where the increment starts (B u + m(ℓ), prescribed values applied)
    dp_n: np.ndarray | None = None  #: (NG,) Δp of the last increment (which Gauss points yielded)
    N: np.ndarray | None = None
    SQ: np.ndarray | None = None
    WBQ: np.ndarray | None = None
    NtQ: np.ndarray | None = None
    projected: bool = False  #: the yield rows take q_N = N : s (the flow directions' pass) instead of q(s)

    @property
    def n_r(self) -> int:
        return self.BN.shape[1]


class NNEQM2Solver:
    """One dense nonsmooth system in the pair unknowns and the Δγ of all Gauss points that can yield.

    Parameters
    ----------
    problem
        A :class:`~dolfinx_nnqem.problem.ContactProblem`, with or without contact (without:
        the system is the NG yield complementarities only).
    options
        Tolerances (``rtol`` applies to the scaled system, see the module docstring),
        ``petsc_options`` for the K_e solves (MUMPS LU by default).
    nneqm2
        This solver's own options (:class:`~dolfinx_nnqem.solver.NNEQM2Options`).

    Notes
    -----
    Reporting: ``SolveReport.system_order`` = 3NC + NG (+ n_r); ``iterations`` counts the dense
    nonsmooth iterations (all passes and attempts); in ``history`` the
    ``contact`` field holds the norm of the whole scaled system [H/F; H4] and ``equilibrium``
    is 0 for the intermediate iterates (equilibrium holds by construction for every iterate) and,
    in the last record, the measured own-stress residual. ``increment_info`` (one dict per
    converged increment) adds the checks (own-stress equilibrium, yield violation, difference to
    the radial-return stress), the number of flow-direction passes and the wall time;
    ``timings`` accumulates seconds per phase (``flexibility``: G Bᵀ once; ``plastic_matrix``:
    Q, G Q and its strains, once per increment or pass; ``dense_solve``; ``solve``: the
    predictor solves).
    """

    name = "nneqm2"

    def __init__(self, problem: ContactProblem, options: SolverOptions | None = None,
                 nneqm2: NNEQM2Options | None = None):
        self.problem = problem
        self.options = options or SolverOptions()
        self.settings = nneqm2 or NNEQM2Options()
        self.flow_rtol = 100.0 * self.options.rtol if self.settings.flow_rtol is None else self.settings.flow_rtol
        self._timings: dict[str, float] = {}
        self.increment_info: list[dict] = []  #: per converged solve: checks and counts
        self._last_pair_states = None  #: pair states of the last dense solve's best iterate (gathered order)
        self._sliding = False  #: the last dense solve stopped because a body only friction holds slides
        self._factorised = False
        self._YB = None
        self._setup_gauss_point_operators()
        order = 3 * problem.num_pairs + self.num_yield_points
        if order > self.settings.max_dense_order:
            raise ValueError(
                f"nneqm2: the dense system would have order 3 NC + NG = {order} ({problem.num_pairs} pairs, "
                f"{self.num_yield_points} Gauss points that can yield), {8e-9 * order**2:.2g} GB per matrix, above "
                f"NNEQM2Options.max_dense_order = {self.settings.max_dense_order}; use the monolithic solver or NNEQM1 "
                "(their size grows with the mesh, not its square), or raise max_dense_order")
        self.condensation = Condensation(problem, self.name, self.options.petsc_options)

    @property
    def timings(self) -> dict[str, float]:
        out = dict(self.condensation.timings)
        for key, value in self._timings.items():
            out[key] = out.get(key, 0.0) + value
        return out

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
        self._w = wv.getArray(readonly=True)[:self.n_gp].copy()
        wv.destroy()
        if self._A.getLocalSize()[0] != 9 * self.n_gp:
            raise RuntimeError("NNEQM2: the strain operator's rows do not match the Gauss points")
        at_points = st.values_at_points
        self._mu = at_points(st.mu)
        self._lmbda = at_points(st.lmbda)
        self._sy = at_points(st.sigma_y0)
        self._Hh = at_points(st.H)
        # Only the Gauss points of a material that can yield carry an unknown Δγ: at an elastic
        # one (σ_y0 = inf) Δγ = 0 always, and its row would only add to the dense system's order
        self._yields = can_yield(self._sy)
        self.n_yp = int(np.count_nonzero(self._yields))
        counts = p.comm.allgather(self.n_yp)
        self.yp_offset = int(sum(counts[:p.comm.rank]))
        self.num_yield_points = int(sum(counts))
        self._su = yield_stress_unit(self._sy, at_points(st.E))  # stress unit of the yield rows
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
        self.condensation.factorise(p.assemble_elastic_stiffness, "the elastic stiffness K_e")
        if p.has_contact:
            t0 = time.perf_counter()
            Bt = self.condensation.transposed_B()
            self._YB, self._SB, self._WBB = self._influence(Bt)
            Bt.destroy()
            self._tick("flexibility", t0)
        self._factorised = True

    def _influence(self, loads: PETSc.Mat):
        """Y = G loads (owned rows), S = dev ε(Y) gathered (NG, 5, m), B Y gathered (3NC, m)."""
        p = self.problem
        if loads.getSize()[1] == 0:  # no Gauss point can yield (MUMPS refuses zero right-hand sides)
            n_u = loads.getLocalSize()[0]
            WB = np.zeros((3 * p.contact.num_global, 0)) if p.has_contact else None
            return np.zeros((n_u, 0)), np.zeros((self.num_yield_points, 5, 0)), WB
        Y = self.condensation.solve_columns(loads)
        S = self._dev_strains_of(Y)
        WB = None
        if p.has_contact:
            model = p.contact
            BY = model.B.matMult(Y)
            ncols = Y.getSize()[1]
            WB = model.gather(BY.getDenseArray().reshape(model.num_local, 3, ncols)).reshape(3 * model.num_global, ncols)
            BY.destroy()
        Y_local = Y.getDenseArray().copy()
        Y.destroy()
        return Y_local, S, WB

    def _dev_strains_of(self, Y: PETSc.Mat) -> np.ndarray:
        """dev ε_j of every column of the dense matrix Y at the Gauss points that can yield,
        gathered: (NG, 5, ncols)."""
        AY = self._A.matMult(Y)
        ncols = Y.getSize()[1]
        e9 = AY.getDenseArray().reshape(self.n_gp, 9, ncols)
        e5 = (DEVIATORIC_BASIS @ e9.transpose(1, 0, 2).reshape(9, -1)).reshape(5, self.n_gp, ncols)
        e5 = e5.transpose(1, 0, 2) / self._w[:, None, None]
        AY.destroy()
        return self._gather_yielding(e5)

    # -- small helpers -------------------------------------------------------------------------
    def _gather_gp(self, local: np.ndarray) -> np.ndarray:
        """Owned Gauss-point rows of every rank, in global Gauss-point order, on every rank."""
        comm = self.problem.comm
        if comm.size == 1:
            return np.asarray(local)
        return np.concatenate(comm.allgather(np.ascontiguousarray(local)), axis=0)

    def _gather_yielding(self, local: np.ndarray) -> np.ndarray:
        """The rows of the owned Gauss points that can yield, gathered (global order, every rank)."""
        return self._gather_gp(np.asarray(local)[self._yields])

    def _local_yielding(self, array_global: np.ndarray) -> np.ndarray:
        """This rank's rows of a gathered array over the Gauss points that can yield."""
        return array_global[self.yp_offset:self.yp_offset + self.n_yp]

    def _owned(self, array_global: np.ndarray) -> np.ndarray:
        """A gathered array over the Gauss points that can yield, at every owned Gauss point (0 at
        the elastic ones)."""
        local = self._local_yielding(array_global)
        out = np.zeros((self.n_gp,) + local.shape[1:])
        out[self._yields] = local
        return out

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
        return assemble_vector(self._Fsig_form, self.problem.V)

    def _flow_matrix(self, N5_local: np.ndarray) -> PETSc.Mat:
        """Q = Aᵀ G (AIJ, V rows × NG): column j is the load w_j B_jᵀ (2μ_j N_j) of Δγ_j = 1, for
        the owned Gauss points that can yield (``N5_local``: their directions, (n, 5))."""
        n, NG = self.n_yp, self.num_yield_points
        vals = (2.0 * self._mu[self._yields, None] * (N5_local @ DEVIATORIC_BASIS)).reshape(-1)
        # rows: the 9 strain components of every owned Gauss point; one entry where it can yield
        row_counts = np.repeat(self._yields.astype(PETSc.IntType), 9)
        indptr = np.concatenate([[0], np.cumsum(row_counts)]).astype(PETSc.IntType)
        G = PETSc.Mat().createAIJ(
            size=((9 * self.n_gp, 9 * self.problem.state.num_gauss_points()), (n, NG)),
            csr=(indptr, np.repeat(self.yp_offset + np.arange(n), 9).astype(PETSc.IntType), vals),
            comm=self.problem.comm)
        G.assemble()
        Q = self._A.transposeMatMult(G)
        G.destroy()
        Q.zeroRows(self.problem.constrained_rows(), diag=0.0)
        return Q

    def _mode_loads_of(self, Q: PETSc.Mat) -> np.ndarray:
        """Nᵀ Q (n_r, NG), gathered: the self-equilibrium rows' dependence on Δγ."""
        rows = []
        for v in self.condensation.modes.vectors:
            out = Q.createVecRight()
            Q.multTranspose(v, out)
            rows.append(self._gather_gp(out.getArray(readonly=True).copy()))
            out.destroy()
        return np.array(rows).reshape(len(rows), self.num_yield_points)

    def _z_scale(self, d: _Increment, laws: PairLaws | None) -> np.ndarray:
        """Scale of the pair unknowns (forces with the load scale F, the polar angle 1)."""
        return laws.unknown_scale(d.F).reshape(-1) if d.nc else np.zeros(0)

    def _tick(self, key: str, t0: float) -> None:
        self._timings[key] = self._timings.get(key, 0.0) + time.perf_counter() - t0

    # -- one increment ---------------------------------------------------------------------------
    def solve_increment(self, load_factor: float) -> SolveReport:
        p, st, opts = self.problem, self.problem.state, self.options
        if not self._factorised:
            self._factorise()
        t_start = time.perf_counter()
        if self.settings.extrapolate:
            # the pair unknowns start from the secant extrapolation of the last two increments; so
            # does u, where w_start (the pair branches a floating body's start freezes) is read;
            # the displacement increment itself comes from the elastic predictor below
            p.extrapolate(load_factor)
        p.apply_prescribed_displacements(load_factor)
        p.predict_contact()
        nc = p.num_pairs
        NG = self.num_yield_points
        n_r = self.condensation.num_modes
        report = SolveReport(converged=False, iterations=0, system_order=3 * nc + NG + n_r)
        n_u = p.V.dofmap.index_map.size_local * 3

        # -- the elastic predictor du_0 = G [F_ext − ∫σ_n:ε(v)], prescribed increments lifted
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
        du0 = self.condensation.solve(b)
        du0_arr = du0.getArray(readonly=True).copy()
        e0 = self._gather_yielding(deviator_coordinates(self._strains9(du0)))
        # F_n and F_ext, the lifted prescribed increments and an obstacle's motion (not yet in F_n)
        scale = max(F_ext.norm(), F_n.norm(), lift.norm())

        # -- gathered pair data (global order, every rank)
        laws = w_prev = w0 = w_start = None
        z_start = np.zeros((0, 3))
        lam_start = np.zeros((0, 3))
        if nc:
            model = p.contact
            laws = model.gathered_laws()
            w_prev = model.gather(model.w_n)
            z_start = model.gather(model.z)
            un_plus = st.u_n.x.petsc_vec.copy()
            un_plus.axpy(1.0, du0)
            w0 = model.gather(p.relative_displacement(un_plus)).reshape(-1)
            un_plus.destroy()
            w_start = model.gather(p.relative_displacement()).reshape(-1)
            lam_start, _ = laws.force(z_start)
            scale = max(scale, model.global_force(model.force()).norm(),
                        model.motion_force_scale(p.load_factor, p.load_factor_n))
        F = max(scale, p.force_floor)  # not atol: |R|/F must be the check's (issue 31)
        tol = opts.rtol + opts.atol / F

        # -- Gauss-point data (global order)
        s_n = self._gather_yielding(deviator_coordinates(sigma_n))
        mu, sy, Hh, su, gscale = (self._gather_yielding(a) for a in (self._mu, self._sy, self._Hh, self._su,
                                                                      self._gscale))
        d = _Increment(
            nc=nc, NG=NG, F=F, laws=laws, w_prev=w_prev, w0=w0, WBB=self._WBB if nc else None,
            BN=self.condensation.mode_coupling() if nc else np.zeros((0, n_r)),
            e=self.condensation.mode_loads(b), s_n=s_n, p_n=self._gather_yielding(st.p_n.x.array[:self.n_gp]),
            mu=mu, sy=sy, Hh=Hh, su=su, gscale=gscale, e0=e0, SB=self._SB if nc else np.zeros((NG, 5, 0)),
            r=max(group.r for group in laws.groups) if nc else 1.0, w_start=w_start,
            dp_n=self._gather_yielding(st.dp_n.x.array[:self.n_gp]))

        alpha_0 = rigid_start(d.BN, w0 - w_prev.reshape(-1)) if n_r else np.zeros(0)
        if n_r and nc:  # a floating body: the pair forces from an equilibrated elastic prediction
            z_start, alpha_0 = self._elastic_pair_prediction(d, laws, z_start, alpha_0)
            lam_start, _ = laws.force(z_start)

        # -- flow directions at the start of the increment
        s_tr = s_n + 2.0 * mu[:, None] * (e0 + d.SB @ lam_start.reshape(-1))  # the elastic predictor's trial
        s_dir = s_n.copy()
        flat = equivalent_stress(s_n) <= 1e-8 * su
        s_dir[flat] = s_tr[flat]
        N = flow_direction(s_dir, su)

        x_start = np.concatenate([z_start.reshape(-1) / self._z_scale(d, laws), np.zeros(NG),
                                  alpha_0 / (F / d.r)])
        x = x_start
        flow_updates, change = 0, float("nan")
        total_its = 0
        updating, retried = self.settings.update_flow_directions, False
        mixing = AndersonMixing(self.settings.flow_acceleration)
        while True:
            free_dropped_objects(p.petsc_comms)
            # -- Q, G Q and its strains/relative displacements for the current N
            t0 = time.perf_counter()
            Q = self._flow_matrix(self._local_yielding(N))
            d.NtQ = self._mode_loads_of(Q)
            YQ, SQ, WBQ = self._influence(Q)
            Q.destroy()
            self._tick("plastic_matrix", t0)
            d.N, d.SQ, d.WBQ = N, SQ, WBQ
            d.projected = updating
            result, records = self._dense_solve(x, d, tol, total_its)
            report.history.extend(records)
            total_its += result.iterations
            report.iterations = total_its
            if not result.converged and (self._sliding or p.friction_held.saturated(self._last_pair_states)):
                # a body only friction holds slides (no pair holding it sticks): no flow
                # direction can hold it, so no retry (it cost minutes per cutback, issue 31)
                report.message = (f"dense nonsmooth solve failed (flow-direction pass {flow_updates}): "
                                  f"{result.message}; no pair holding a motion that only friction holds "
                                  "sticks")
                return report
            if not result.converged and not updating and self.settings.retry_updating_directions:
                # With N frozen at σ_n the yield rows may have no solution: where the stress turns
                # within a large plastic increment, q(σ_tr − 2μ Δγ N) stays above the yield stress
                # for every Δγ. The radial return's directions always admit one; start their fixed
                # point from the elastic predictor's trial directions, from the increment's start.
                logger.info(f"[{self.name}] ℓ = {load_factor:.6g}: no solution with the flow directions frozen "
                            f"at the start ({result.message}); solving with updated directions")
                updating, retried = True, True
                x = x_start
                N = flow_direction(s_tr, su, fallback=N)
                continue
            if not result.converged:
                report.message = (f"dense nonsmooth solve failed (flow-direction pass {flow_updates}): "
                                  f"{result.message}")
                return report
            x = result.x
            # clean Δγ: exactly 0 on the elastic branch, never negative
            dgt = x[3 * nc:3 * nc + NG]
            a, _ = self._yield_rows(x, d, laws)[:2]
            dgt[(dgt < a) | (dgt < 0.0)] = 0.0
            z = (x[:3 * nc] * self._z_scale(d, laws)).reshape(nc, 3)
            dg = dgt * gscale
            alpha = x[3 * nc + NG:] * (F / d.r)
            lam = laws.force(z)[0].reshape(-1) if nc else np.zeros(0)
            if not updating:
                break
            s_end = self._yield_rows(x, d, laws)[2]  # stress deviators at the end of this pass (cleaned Δγ)
            s_new = s_end if self.settings.flow_update == "stress" else s_end + 2.0 * mu[:, None] * N * dg[:, None]
            N_new = flow_direction(s_new, su, fallback=N)
            # settled when the plastic strains stop turning AND the stress lies in the yield surface
            # with q itself: a point the pass's q_N = N : s left elastic (N ⟂ s, or N = 0 before
            # any stress) has Δγ = 0, so only q can show it should yield
            turn = float(np.max(2.0 * mu * dg * np.linalg.norm(N_new - N, axis=1) / su, initial=0.0))
            outside = float(np.max(yield_function(equivalent_stress(s_end), d.sy, d.Hh, d.p_n + dg) / su, initial=0.0))
            change = max(turn, outside)
            logger.info(f"[{self.name}] flow-direction pass {flow_updates}: max 2μ Δγ |ΔN| / σ_y = {turn:.3e}, "
                        f"max f/σ_y = {outside:.3e}")
            if change <= self.flow_rtol:
                break
            flow_updates += 1
            if flow_updates > self.settings.max_flow_updates:
                report.message = (f"flow directions did not settle in {self.settings.max_flow_updates} passes "
                                  f"(last change {change:.3e} > {self.flow_rtol:.1e})")
                return report
            N = flow_direction(mixing.next(N, N_new), su, fallback=N_new)

        # -- displacement, stress, the proposed Gauss-point state
        t0 = time.perf_counter()
        dg_local = self._owned(dg)
        du = du0_arr + YQ @ dg
        if nc:
            du += self._YB @ lam
        if n_r:
            du += self.condensation.mode_array() @ alpha
        u_bc = p.u.x.array[p.bc_dofs].copy()  # the prescribed values, kept exactly
        p.u.x.array[:n_u] = st.u_n.x.array[:n_u] + du
        p.u.x.scatter_forward()
        p.u.x.array[p.bc_dofs] = u_bc
        if nc:
            p.contact.z = p.contact.local_rows(z).copy()
        du_vec = compat.create_vector(p.V)
        du_vec.getArray()[:] = du
        eps = self._strains9(du_vec)
        du_vec.destroy()
        N9 = deviator_tensors(self._owned(N))
        eps_e = eps - dg_local[:, None, None] * N9
        sigma = sigma_n + elastic_stress(eps_e, self._lmbda, self._mu)
        report.gauss_point_values = GaussPointValues(p.u.x.array.copy(), sigma, dg_local.copy())
        info = self._checks(sigma, dg_local, F_ext, load_factor, total_its, flow_updates, change)
        info["directions"] = "frozen" if not updating else "updated after frozen failed" if retried else "updated"
        self._tick("stress_update", t0)
        info["wall_time_s"] = time.perf_counter() - t_start
        self.increment_info.append(info)
        last = report.history[-1]
        report.history[-1] = IterationRecord(last.iteration, info["equilibrium_residual"], last.contact,
                                             last.step_length, "", last.states, info["plastic_points"])
        logger.info(f"[{self.name}] ℓ = {load_factor:.6g}: order {3 * nc + NG + n_r}, {total_its} iterations, "
                    f"{flow_updates} flow updates, own-stress |R|/F = {info['equilibrium_residual']:.2e}, "
                    f"max f/σ_y = {info['max_yield_violation']:.2e}, "
                    f"max |σ − σ_return map|/σ_y = {info['return_map_difference']:.2e}")
        report.converged, report.message = True, "converged"
        return report

    # -- the dense nonsmooth system -------------------------------------------------------------
    def _yield_rows(self, x, d: _Increment, laws):
        """a = −f/σ_u, b = Δγ̃, the stress deviators s and q at the scaled unknowns ``x``
        (q_N = N : s in place of q when ``d.projected``)."""
        nc, NG = d.nc, d.NG
        dgt = x[3 * nc:3 * nc + NG]
        dg = dgt * d.gscale
        if nc:
            z = (x[:3 * nc] * self._z_scale(d, laws)).reshape(nc, 3)
            lam = laws.force(z)[0].reshape(-1)
            e = d.e0 + d.SB @ lam
        else:
            e = d.e0
        e = e + np.einsum("jak,k->ja", d.SQ, dg)
        s = d.s_n + 2.0 * d.mu[:, None] * (e - d.N * dg[:, None])
        q = np.einsum("ja,ja->j", d.N, s) if d.projected else equivalent_stress(s)
        return -yield_function(q, d.sy, d.Hh, d.p_n + dg) / d.su, dgt, s, q

    def _dense_solve(self, x0, d: _Increment, tol, it_offset):
        """The driver on the scaled [pair rows / F; H4; self-equilibrium / F] with the chain-rule Jacobian."""
        nc, NG, F, n_r, laws = d.nc, d.NG, d.F, d.n_r, d.laws
        z_scale = self._z_scale(d, laws)
        gscale, mu, su, Hh, N, SQ, SB = d.gscale, d.mu, d.su, d.Hh, d.N, d.SQ, d.SB
        a_scale = F / d.r  # α = α̃ · F / r
        n3 = 3 * nc
        m = n3 + NG + n_r
        last = {}

        def residual(x, frozen=None, yield_branch=None):
            """[pair rows / F; H4; self-equilibrium / F] and its Jacobian at ``x``; with ``frozen``
            = (law evaluation, w) the pair rows are that evaluation linearised at x instead, and
            with ``yield_branch`` (NG,) bool the Gauss points take that branch of their min."""
            dgt = x[n3:n3 + NG]
            dg = dgt * gscale
            Hs = np.empty(m)
            J = np.zeros((m, m))
            chart = None
            if nc:
                z = (x[:n3] * z_scale).reshape(nc, 3)
                lam, _ = laws.force(z)
                w = d.w0 + d.WBB @ lam.reshape(-1) + d.WBQ @ dg
                if n_r:
                    w = w + d.BN @ (x[n3 + NG:] * a_scale)
                if frozen is None:
                    ev = laws.evaluate(w.reshape(nc, 3), d.w_prev, z)
                else:
                    ev, w_f = frozen
                    ev = ev._replace(H=ev.H + np.einsum("nij,nj->ni", ev.dH_dw, w.reshape(nc, 3) - w_f))
                lin = laws.linearise(z, ev)  # the laws' step coordinates y
                dlam_dz = lin.dlam_dy
                chart = lin.cartesian
                y_scale = laws.step_scale(F, chart).reshape(-1)  # of the step coordinates
                Hs[:n3] = ev.H.reshape(-1) / F
                # pair rows: blockdiag(∂H/∂w) [W_BB Λ', W_BQ, B N] + [blockdiag(∂H/∂y), 0, 0]
                DwW = np.einsum("nij,njk->nik", ev.dH_dw, d.WBB.reshape(nc, 3, n3))
                Jz = np.einsum("anj,njk->ank", DwW.reshape(n3, nc, 3), dlam_dz).reshape(n3, nc, 3)
                idx = np.arange(nc)
                Jzb = Jz.reshape(nc, 3, nc, 3)
                Jzb[idx, :, idx, :] += lin.dH_dy
                J[:n3, :n3] = Jz.reshape(n3, n3) * y_scale[None, :] / F
                DwQ = np.einsum("nij,njk->nik", ev.dH_dw, d.WBQ.reshape(nc, 3, NG))
                J[:n3, n3:n3 + NG] = DwQ.reshape(n3, NG) * gscale[None, :] / F
                if n_r:
                    DwN = np.einsum("nij,njk->nik", ev.dH_dw, d.BN.reshape(nc, 3, n_r))
                    J[:n3, n3 + NG:] = DwN.reshape(n3, n_r) * a_scale / F
                    # self-equilibrium of the floating bodies: Nᵀ(b + Bᵀλ + QΔγ) = 0
                    Hs[n3 + NG:] = (d.e + d.BN.T @ lam.reshape(-1) + d.NtQ @ dg) / F
                    JE = np.einsum("anj,njk->ank", d.BN.T.reshape(n_r, nc, 3), dlam_dz).reshape(n_r, n3)
                    J[n3 + NG:, :n3] = JE * y_scale[None, :] / F
                    J[n3 + NG:, n3:n3 + NG] = d.NtQ * gscale[None, :] / F
                last["states"] = ev.state
            a, b, s, q = self._yield_rows(x, d, laws)
            use_a = a <= b if yield_branch is None else yield_branch  # tie: the first argument (yield branch)
            Hs[n3:n3 + NG] = np.where(use_a, a, b)
            # ∂(−f/σ_u): g_j = 2μ_j (3/2) s_j / q_j, or 2μ_j N_j for the projected q_N = N_j : s_j
            if d.projected:
                gvec = N * (2.0 * mu)[:, None]
            else:
                qs = np.where(q > 0.0, q, 1.0)
                gvec = np.where((q > 0.0)[:, None], 1.5 * s / qs[:, None], 0.0) * (2.0 * mu)[:, None]
            rows = np.flatnonzero(use_a)
            if rows.size:
                gr = gvec[rows]
                Jgg = np.einsum("ja,jak->jk", gr, SQ[rows])
                Jgg[np.arange(rows.size), rows] -= np.einsum("ja,ja->j", gr, N[rows]) + Hh[rows]
                J[n3 + rows, n3:n3 + NG] = -(Jgg * gscale[None, :]) / su[rows, None]
                if nc:
                    JgB = np.einsum("ja,jak->jk", gr, SB[rows])  # (r, 3nc) w.r.t. λ
                    JgZ = np.einsum("rnj,njk->rnk", JgB.reshape(rows.size, nc, 3), dlam_dz)
                    J[n3 + rows, :n3] = -(JgZ.reshape(rows.size, n3) * y_scale[None, :]) / su[rows, None]
            other = np.flatnonzero(~use_a)
            J[n3 + other, n3 + other] = 1.0
            last["Hc"] = float(np.linalg.norm(Hs[:n3]))
            last["H4"] = float(np.linalg.norm(Hs[n3:n3 + NG]))
            last["plastic"] = int(np.count_nonzero(use_a & (b > 0.0)))
            return Hs, J, chart

        def advance(x, dx, alpha, cartesian):
            """The pair unknowns step in the laws' coordinates; Δγ and the mode amplitudes linearly."""
            out = x + alpha * dx
            if nc:
                dy = dx[:n3] * laws.step_scale(F, cartesian).reshape(-1)
                z = laws.advance((x[:n3] * z_scale).reshape(nc, 3), dy.reshape(nc, 3), alpha, cartesian)
                out[:n3] = z.reshape(-1) / z_scale
            return out

        records = []

        def log(k, norm, t, kind):
            states = (0, 0, 0)
            if nc:
                counts = np.bincount(np.asarray(last["states"], dtype=np.int64), minlength=3)[:3]
                states = tuple(int(c) for c in counts)
                if norm < last.get("best", np.inf):  # the pair states of the best iterate, for a failure
                    last["best"], last["best_states"] = norm, np.array(last["states"])
                sliding = norm > tol and self.problem.friction_held.saturated(last["states"])
                last["sliding"] = last.get("sliding", 0) + 1 if sliding else 0
            records.append(IterationRecord(it_offset + k, 0.0, norm, t if k else float("nan"),
                                           kind if k else "", states, last["plastic"]))
            logger.debug(f"[{self.name}] it {it_offset + k}: |H̃| = {norm:.3e} (pairs {last['Hc']:.3e}, "
                         f"yield {last['H4']:.3e}) {kind} t={t:.2e}")
            if last.get("sliding", 0) >= SLIDING_WINDOW:
                raise _Sliding(f"stopped at iteration {it_offset + k}: for {SLIDING_WINDOW} iterations no pair "
                               "holding a motion that only friction holds has stuck: the body slides, past the "
                               "friction limit no equilibrium exists")

        def on_the_slip(x):
            """x with the unknowns no force depends on (the polar angle of pairs without friction
            force) set on the slip there (:meth:`PairLaws.follow_slip`)."""
            z = (x[:n3] * z_scale).reshape(nc, 3)
            lam, _ = laws.force(z)
            w = d.w0 + d.WBB @ lam.reshape(-1) + d.WBQ @ (x[n3:n3 + NG] * gscale)
            if n_r:
                w = w + d.BN @ (x[n3 + NG:] * a_scale)
            out = x.copy()
            out[:n3] = laws.follow_slip(z, w.reshape(nc, 3), d.w_prev).reshape(-1) / z_scale
            return out

        def advance_following(x, dx, alpha, cartesian):
            return on_the_slip(advance(x, dx, alpha, cartesian))

        t0 = time.perf_counter()
        self._sliding = False
        if n_r and d.w_start is not None:
            x0 = self._frozen_branch_start(x0, d, laws, z_scale, residual, advance)
        step_rule = advance
        if nc and laws.slip_following:
            # The polar angle of a pair without friction force follows the slip at every step, as
            # in the monolithic solver: its H3 row then holds no meaningless residual and its H2
            # branch is the Cartesian law's (theory page, "The polar law's Newton step")
            x0, step_rule = on_the_slip(x0), advance_following
        try:
            result = solve_dense(residual, x0, tol=tol, max_iter=self.settings.inner_max_iterations, log=log,
                                 globalisations=self.settings.inner_globalisations, advance=step_rule)
        except _Sliding as sliding:  # no other globalisation can hold a sliding body either
            result = NonsmoothResult(x=x0, converged=False, iterations=len(records), residual_norms=[],
                                     message=str(sliding))
            self._sliding = True
        self._tick("dense_solve", t0)
        # every rank takes rank 0's decision and solution
        comm = self.problem.comm
        self._last_pair_states = last.get("best_states")  # of the best iterate (gathered order)
        if comm.size > 1:
            converged, message, xs, states, sliding = comm.bcast((result.converged, result.message, result.x,
                                                                  self._last_pair_states, self._sliding), root=0)
            result.converged, result.message, result.x = converged, message, xs
            self._last_pair_states, self._sliding = states, sliding
        return result, records

    @staticmethod
    def _elastic_pair_prediction(d: _Increment, laws, z: np.ndarray, alpha: np.ndarray):
        """(z, α) of one elastic Newton step of the pairs and the self-equilibrium rows alone,
        the pair branches frozen where the increment starts (no plastic flow).

        A floating body's predictor strains e0 come from a load not yet balanced by contact;
        with the pair forces of this prediction, e0 + S_B λ is the strain of an equilibrated
        elastic state, from which the flow directions of Gauss points without stress are taken.
        """
        nc, n_r, F = d.nc, d.n_r, d.F
        n3 = 3 * nc
        lam, _ = laws.force(z)
        w_start = d.w_start.reshape(nc, 3)
        ev = laws.evaluate(w_start, d.w_prev, z)
        lin = laws.linearise(z, ev)
        dlam_dz = lin.dlam_dy
        w = (d.w0 + d.WBB @ lam.reshape(-1) + d.BN @ alpha).reshape(nc, 3)
        H = np.concatenate([(ev.H + np.einsum("nij,nj->ni", ev.dH_dw, w - w_start)).reshape(-1),
                            d.e + d.BN.T @ lam.reshape(-1)]) / F
        J = np.zeros((n3 + n_r, n3 + n_r))
        DwW = np.einsum("nij,njk->nik", ev.dH_dw, d.WBB.reshape(nc, 3, n3))
        Jz = np.einsum("anj,njk->ank", DwW.reshape(n3, nc, 3), dlam_dz).reshape(nc, 3, nc, 3)
        Jz[np.arange(nc), :, np.arange(nc), :] += lin.dH_dy
        J[:n3, :n3] = Jz.reshape(n3, n3)
        J[:n3, n3:] = np.einsum("nij,njk->nik", ev.dH_dw, d.BN.reshape(nc, 3, n_r)).reshape(n3, n_r)
        J[n3:, :n3] = np.einsum("anj,njk->ank", d.BN.T.reshape(n_r, nc, 3), dlam_dz).reshape(n_r, n3)
        try:
            step = np.linalg.solve(J / F, -H)
        except np.linalg.LinAlgError:
            return z, alpha
        if not np.all(np.isfinite(step)):
            return z, alpha
        return laws.advance(z, step[:n3].reshape(nc, 3), 1.0, lin.cartesian), alpha + step[n3:]

    @staticmethod
    def _frozen_branch_start(x0, d: _Increment, laws, z_scale, residual, advance):
        """One Newton step with every branch frozen where the increment starts.

        As in NNEQM1 (:meth:`NNEQM1Solver._frozen_branch_start`): a floating body's elastic
        predictor du_0 = G b is the response to a load not yet balanced by contact, fixed at the
        fixing dofs; pairs and Gauss points evaluated there start on meaningless branches. The
        pair laws are evaluated where the increment starts (u_n with the new prescribed values)
        and linearised at x0, each Gauss point takes the branch it ended the last increment on
        (plastic if it yielded), and the whole system is solved once; the iteration starts from
        there (or from x0 if that system is singular).
        """
        nc = d.nc
        z = (x0[:3 * nc] * z_scale).reshape(nc, 3)
        w_start = d.w_start.reshape(nc, 3)
        ev = laws.evaluate(w_start, d.w_prev, z)
        H, J, chart = residual(x0, frozen=(ev, w_start), yield_branch=d.dp_n > 0.0)
        try:
            step = np.linalg.solve(J, -H)
        except np.linalg.LinAlgError:
            return x0
        return advance(x0, step, 1.0, chart) if np.all(np.isfinite(step)) else x0

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
            Bl = p.contact.global_force(p.contact.force())
            scale = max(scale, Bl.norm())
            R.axpy(-1.0, Bl)
        R_free = p.free_residual(R)
        eq = R_free.norm() / max(scale, self.problem.force_floor)
        # the radial-return stress of the same displacement, from the same converged state
        rm = fem.Function(st.W_tensor)
        rm.interpolate(self._rm_expr)
        sig_rm = rm.x.array[:9 * self.n_gp].reshape(self.n_gp, 3, 3)
        diff = np.linalg.norm((sigma - sig_rm).reshape(self.n_gp, 9), axis=1) / self._su
        f = (yield_function(equivalent_stress(deviator_coordinates(sigma)), self._sy, self._Hh,
                            st.p_n.x.array[:self.n_gp] + dg_local) / self._su)[self._yields]
        return {
            "load_factor": float(load_factor),
            "system_order": 3 * p.num_pairs + self.num_yield_points + self.condensation.num_modes,
            "iterations": int(iterations),
            "flow_updates": int(flow_updates),
            "flow_change": change,
            "equilibrium_residual": float(eq),
            "return_map_difference": comm.allreduce(float(np.max(diff, initial=0.0)), op=MPI.MAX),
            "max_yield_violation": comm.allreduce(float(np.max(f, initial=-np.inf)), op=MPI.MAX),
            "plastic_points": comm.allreduce(int(np.count_nonzero(dg_local > 0.0)), op=MPI.SUM),
        }

    def destroy(self) -> None:
        self.condensation.destroy()
        self._A.destroy()
