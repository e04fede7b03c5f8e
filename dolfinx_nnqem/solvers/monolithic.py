r"""Monolithic semismooth Newton on (u, z): the scalable solver (``formulation.md`` §5).

Per iteration, with R = F_int(u) − F_ext(ℓ) − Bᵀλ(z) and H = H(Bu + m(ℓ), z):

    [ K_t(u)     −Bᵀ Λ' ] [du]     [ R ]
    [ ∂_wH · B   ∂_zH   ] [dz] = − [ H ]

solved by the linear-solver strategy (:mod:`dolfinx_nnqem.solvers.linear_solver`: MUMPS LU by
default, or FGMRES + fieldsplit + GAMG for large meshes) and globalised by the package's Newton
driver (:func:`dolfinx_nnqem.numerics.newton.solve`) on Ψ = ½(‖R‖² + ‖H‖²) — both in force units, so no
row scaling is needed. The Levenberg–Marquardt fallback solves (JᵀJ + ν I) d = −JᵀF with
ν = lm_c · min(ε, 1)^lm_delta · mean diag(JᵀJ), ε the relative residual. Without contact this
is Newton–Raphson with the consistent tangent.

Each increment starts from a predictor: the secant extrapolation of the last two increments
where the load path goes on in the same direction, else — where prescribed displacements jump —
a Newton step from the converged state with the jump lifted into the right-hand side. With the
polar law, an increment that fails is tried once more from the same prediction with the angle of
sliding pairs put on their slip after every step (``docs/theory.md``, the polar law).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem import compat
from dolfinx_nnqem.contact.geometric_stiffness import GeometricTerms
from dolfinx_nnqem.contact.laws import LawEvaluation, Linearisation
from dolfinx_nnqem.contact.surface_stiffness import SurfaceTerms
from dolfinx_nnqem.solvers.block_system import AugmentedSystem, MonolithicMatrix, free_mask
from dolfinx_nnqem.solvers.contract import ReleasesPETSc
from dolfinx_nnqem.solvers.convergence import IterationRecord, SolveReport, count_states, iteration_log_on, logger
from dolfinx_nnqem.numerics.linalg import (clear_options, create_ksp, direct_options, free_dropped_objects, global_norm,
                                           vec_norm)
from dolfinx_nnqem.solvers.linear_solver import DirectSolver, IterativeSolver
from dolfinx_nnqem.numerics.newton import Globalisation, Merit, NewtonResult, solve
from dolfinx_nnqem.numerics.roundoff import floor_note, residual_floor
from dolfinx_nnqem.problem.contact_problem import ContactProblem
from dolfinx_nnqem.solvers.options import MonolithicOptions, SolverOptions
from dolfinx_nnqem.solvers.prediction import lifted_residual, predict_increment
from dolfinx_nnqem.solvers.surface_tangent import SurfaceTangent
from dolfinx_nnqem.solvers.timings import Timings

__all__ = ["MonolithicSolver"]


@dataclass
class _Evaluation:
    """The residuals at an iterate."""

    R_free: PETSc.Vec  #: equilibrium residual, constrained rows zeroed
    H: np.ndarray  #: (num_local_pairs, 3) pair laws
    law: LawEvaluation | None  #: the LawEvaluation (Jacobian blocks, states), or None without contact
    scale: float  #: the force scale F
    norm_R: float
    norm_H: float
    lin: Linearisation | None = None  #: the laws' Linearisation (Newton step coordinates), or None without contact
    geometric: GeometricTerms | None = None  #: the obstacle pairs' geometric blocks at the iterate (consistent geometry)
    surface: list[SurfaceTerms] | None = None  #: the node-to-surface pairs' geometric blocks (consistent geometry)


class MonolithicSolver(ReleasesPETSc):
    """Semismooth Newton on the displacement and the pair unknowns together.

    Parameters
    ----------
    problem
        The problem to solve.
    options
        Tolerances, iteration limit and ``petsc_options`` (merged over MUMPS LU,
        :data:`dolfinx_nnqem.numerics.linalg.DIRECT_SOLVER_OPTIONS`, or over the iterative defaults).
    monolithic
        This solver's own options (:class:`~dolfinx_nnqem.solvers.options.MonolithicOptions`).
    """

    name = "monolithic"
    follows_contact_geometry = True

    def __init__(self, problem: ContactProblem, options: SolverOptions | None = None,
                 monolithic: MonolithicOptions | None = None):
        self.problem = problem
        self.options = options or SolverOptions()
        self.settings = monolithic or MonolithicOptions()
        self.prefix = f"nnqem_monolithic_{id(self)}_"
        self.iterative = self._use_iterative()
        self.linear: IterativeSolver | DirectSolver = self._linear_solver()
        self._K: PETSc.Mat | None = None
        self._surface_tangent = SurfaceTangent()  # K_t − K of the node-to-surface pairs (consistent geometry)
        self._mask = free_mask(problem) if problem.has_contact else None
        self._matrix: MonolithicMatrix | None = None  # the direct Newton matrix (also the LM fallback's)
        self._augmented: AugmentedSystem | None = self._augmented_system_of_pairs()
        self._geometry_version = problem.contact.geometry.version if problem.contact is not None else 0
        self._timings = Timings()
        # the vectors of every iteration, created once and refilled (as DOLFINx's NonlinearProblem
        # does); only the free residual of an evaluation is new, since the watchdog keeps evaluations
        self._work: dict[str, PETSc.Vec] = {}

    @property
    def consistent_geometry(self) -> bool:
        """True if current-geometry obstacles are re-evaluated at every iterate, their geometric terms in
        J (asked anew at every use: ``geometry = "auto"`` moves an obstacle to the current geometry
        during a run)."""
        model = self.problem.contact
        return self.settings.consistent_geometry and model is not None and model.geometry.obstacles_follow

    @property
    def consistent_surfaces(self) -> bool:
        """True if current-geometry node-to-surface and mortar pairs are re-evaluated at every iterate, their
        geometric terms in J (:mod:`~dolfinx_nnqem.contact.surface_stiffness`,
        :mod:`~dolfinx_nnqem.contact.mortar_linearisation`; with the iterative solver in the augmented
        system's u block, :class:`~dolfinx_nnqem.solvers.block_system.AugmentedSystem`)."""
        model = self.problem.contact
        return self.settings.consistent_geometry and model is not None and any(model.geometry.reprojecting)

    @property
    def timings(self) -> dict[str, float]:
        """Seconds per phase: assembly, contact, block_matrix, and the linear solver's setup and solve."""
        return {**self._timings, **self.linear.timings}

    @property
    def linear_iterations(self) -> int:
        """Krylov iterations over all Newton steps (iterative solver)."""
        return self.linear.linear_iterations

    @property
    def amg_setups(self) -> int:
        """AMG hierarchies built (iterative solver with contact)."""
        return self.linear.amg_setups

    def _linear_solver(self) -> IterativeSolver | DirectSolver:
        p = self.problem
        if self.iterative:
            return IterativeSolver(p.V, self.prefix, self.options.petsc_options, self.options.rtol, p.num_pairs,
                                   self.settings.lag_preconditioner, p.state.symmetric_tangent,
                                   self.settings.forcing, self.settings.max_forcing)
        return DirectSolver(p.comm, self.prefix, self.options.petsc_options)

    def _augmented_system_of_pairs(self) -> AugmentedSystem | None:
        """The iterative solver's augmented system (None for the direct one, or without contact)."""
        model = self.problem.contact
        if not self.iterative or model is None or self._mask is None:  # the mask: with contact
            return None
        return AugmentedSystem(model, self._mask, model.r_max, self.settings.augmentation)

    def _follow_geometry(self) -> None:
        """After the contact geometry changed (B's rows, the number of pairs): the pieces built on
        B made again (the Newton matrix's pattern, the linear solver's operator layout)."""
        model = self.problem.contact
        if model is None or model.geometry.version == self._geometry_version:
            return
        self._geometry_version = model.geometry.version
        for old in (self._matrix, self._augmented, self.linear):
            if old is not None:
                old.destroy()
        for vector in self._work.values():  # some have J's layout (3 rows per pair)
            vector.destroy()
        self._work.clear()
        self._matrix = None
        self.linear = self._linear_solver()
        self._augmented = self._augmented_system_of_pairs()

    def _refresh_geometry(self) -> None:
        """The current-geometry obstacles', node-to-surface and mortar pairs re-evaluated at the iterate (u, ℓ)
        (collective; nothing to do unless :attr:`consistent_geometry` or :attr:`consistent_surfaces`,
        or if the iterate has not moved)."""
        p = self.problem
        if self.consistent_geometry:
            assert p.contact is not None  # consistent_geometry: with contact
            p.contact.geometry.refresh_obstacles(p.u, p.load_factor, p.state.u_n, p.load_factor_n)
        if self.consistent_surfaces:
            assert p.contact is not None  # consistent_surfaces: with contact
            p.contact.geometry.refresh_surfaces(p.u, p.state.u_n, p.load_factor_n)

    def _geometric_terms(self) -> GeometricTerms | None:
        """The obstacle pairs' geometric blocks at the iterate, or None (:attr:`consistent_geometry` off)."""
        if not self.consistent_geometry:
            return None
        p = self.problem
        assert p.contact is not None  # consistent_geometry: with contact
        return p.contact.geometry.geometric_terms(p.u, p.load_factor, p.state.u_n, p.load_factor_n)

    def _use_iterative(self) -> bool:
        choice = self.settings.linear_solver
        if choice == "auto":
            return self.problem.V.dofmap.index_map.size_global * 3 >= self.settings.auto_iterative_dofs
        return choice == "iterative"

    # -- one increment ------------------------------------------------------------------------------
    def solve_increment(self, load_factor: float) -> SolveReport:
        """Solve for the load factor ``load_factor`` from the last converged state."""
        p = self.problem
        self._follow_geometry()
        report = SolveReport(converged=False, iterations=0,
                             system_order=p.V.dofmap.index_map.size_global * 3 + 3 * p.num_pairs)
        outcome = self._attempt(load_factor, report, align_sliding=False)
        if not outcome.converged and p.contact is not None and p.contact.slip_following and outcome.iterations > 0:
            # The polar law's H3 = r |s| sin(θ − θ_s) is a sine that a Newton step can follow only
            # within a quarter turn; where slips are small and turn between iterates, steps clipped
            # to that turn can stall. Put θ of sliding pairs on the slip after every step instead
            # (PolarLaw.follow_slip). Only as a second attempt: measured always on, it cost
            # iterations on other cases of the robustness suite (docs/robustness.md).
            logger.info(f"[{self.name}] increment to load factor {load_factor:.6g}: {outcome.message}; "
                        "trying again with the angle of sliding pairs on their slip after every step")
            tried = outcome.iterations
            p.restore()
            outcome = self._attempt(load_factor, report, align_sliding=True)
            outcome.iterations += tried
        report.iterations = outcome.iterations
        report.converged = outcome.converged
        # every iterate was evaluated in its own geometry, and no pair can have changed: no second solve
        report.geometry_consistent = self.consistent_geometry and not (p.contact is not None
                                                                       and p.contact.geometry.surfaces_follow)
        final = report.final
        if outcome.converged:
            report.message = "converged"
        elif final is not None:
            report.message = f"{outcome.message} (|R|/F = {final.equilibrium:.3e}, |H|/F = {final.contact:.3e})"
        else:
            report.message = outcome.message
        return report

    def _attempt(self, load_factor: float, report: SolveReport, align_sliding: bool) -> NewtonResult:
        """Newton from the increment's prediction; ``align_sliding``: see :meth:`set_iterate`."""
        self.linear.begin_increment()
        lifted = self._predict(load_factor)
        system = _NewtonSystem(self, report, align_sliding)
        return solve(system, self.settings.globalisation, self.options.max_iterations,
                     first_iteration=1 if lifted else 0, first_kind="lifted" if lifted else "",
                     first_step_length=1.0 if lifted else math.nan)

    def _predict(self, load_factor: float) -> bool:
        """The increment's starting point; True if it was reached by a lifted Newton step.

        The secant predictor when the load path goes on in the same direction; otherwise, if
        prescribed displacements move, a Newton step from the converged state with their jump
        lifted (:meth:`_lifted_step`); otherwise the converged state.
        """
        p = self.problem
        # the starting active set sees the predicted configuration's gaps
        start = predict_increment(p, load_factor, self.settings.extrapolate, self._refresh_geometry)
        if not start.lift:
            return False
        p.u.x.array[p.bc_dofs] = start.u_bc
        if self._lifted_step(self.evaluate(), start.delta_bc):
            return True
        p.apply_prescribed_displacements(load_factor)  # the solve failed: plain Newton from here
        return False

    def _lifted_step(self, ev: _Evaluation, delta_bc: np.ndarray) -> bool:
        """Newton step from the converged state that moves the constrained dofs by ``delta_bc``.

        J du = −F − J_c Δu_D with du = Δu_D at the constrained dofs: the tangent (and the pair
        laws) evaluated where the solution is, not at a state whose boundary layer alone has been
        moved (which, in a plastic body, yields spuriously and misleads the first step). The
        step is taken in full, without line search (its start is not an admissible state).
        Returns False if the linear solve failed. The geometric terms of current-geometry obstacles
        are left out of the lifted right-hand side (they act on prescribed slave dofs only, rarely
        moved): the step is a predictor, the Newton iterations that follow use them.
        """
        p = self.problem
        delta = np.zeros_like(p.u.x.array)
        delta[p.bc_dofs] = delta_bc
        R_lifted = lifted_residual(p, ev.R_free, delta)
        H_lifted = ev.H
        if p.contact is not None and ev.law is not None:  # the law: with contact
            delta_vec = p.u.x.petsc_vec.duplicate()
            with delta_vec.localForm() as local:
                local.array[:] = delta
            H_lifted = ev.H + np.einsum("nij,nj->ni", ev.law.dH_dw, p.contact.B_times(delta_vec))
        # the lifted system's residual is not the iterate's; the step sets the pairs' starting states
        self.linear.set_forcing(1.0, record=False, cap=self.settings.lift_forcing)
        u0 = p.u.x.array[:ev.R_free.getLocalSize()].copy()
        z0 = p.contact.z.copy() if p.contact is not None else None
        lifted = _Evaluation(R_lifted, H_lifted, ev.law, ev.scale, math.nan, math.nan, ev.lin)
        direction = self.newton_direction(lifted)
        if direction is None:
            return False
        self.set_iterate(u0, z0, direction, 1.0, ev.lin)
        p.u.x.array[p.bc_dofs] += delta_bc
        return True

    # -- the pieces the Newton system uses ------------------------------------------------------
    def _vector(self, name: str, create) -> PETSc.Vec:
        """The work vector ``name``, created by ``create()`` the first time."""
        vector = self._work.get(name)
        if vector is None:
            vector = self._work[name] = create()
        return vector

    def evaluate(self) -> _Evaluation:
        """R (free part), H, the law evaluation and the force scale at the current iterate."""
        p = self.problem
        self._refresh_geometry()
        t0 = time.perf_counter()
        F_int = p.assemble_internal_force(self._vector("F_int", lambda: compat.create_vector(p.V)))
        self._timings.add("assembly", t0)
        F_ext = p.external_force(out=self._vector("F_ext", lambda: compat.create_vector(p.V)))
        contact_force = None
        if p.contact is not None:
            contact = p.contact
            contact_force = contact.global_force(contact.force(),
                                                 out=self._vector("contact_force", contact.B.createVecRight))
        R = p.residual(F_int=F_int, F_ext=F_ext, contact_force=contact_force,
                       out=self._vector("R", lambda: compat.create_vector(p.V)))
        R_free = p.free_residual(R)
        law, lin, H, geometric, surface = None, None, np.zeros((0, 3)), None, None
        if p.contact is not None:
            t0 = time.perf_counter()
            law = p.contact.evaluate(p.relative_displacement())
            lin = p.contact.linearise(law)
            H = law.H
            geometric = self._geometric_terms()
            surface = p.contact.geometry.surface_terms() if self.consistent_surfaces else None
            self._timings.add("contact", t0)
        return _Evaluation(R_free, H, law, p.force_scale(F_int, F_ext, contact_force), vec_norm(R_free),
                           global_norm(H, p.comm), lin, geometric, surface)

    def _newton_matrix(self, ev: _Evaluation) -> PETSc.Mat:
        """J as one AIJ matrix (the direct system, and the LM fallback's)."""
        p = self.problem
        t0 = time.perf_counter()
        self._K = p.assemble_tangent(self._K)
        self._timings.add("assembly", t0)
        if p.contact is None:
            return self._K
        assert self._mask is not None and ev.law is not None and ev.lin is not None  # all made with contact
        t0 = time.perf_counter()
        self._follow_geometry()  # a node-to-surface pair may have changed its master facet at this iterate
        if self._matrix is None:
            self._matrix = MonolithicMatrix(p.contact, self._mask)
        B_values = None
        if ev.geometric is not None:  # on every rank, pairs or none: K's assembly in it is collective
            ev.geometric.add_to_tangent(self._K, self._matrix.slave_free(ev.geometric),
                                        combined=self._matrix.combined_blocks(ev.geometric))
            B_values = ev.geometric.rows_values(p.contact.rows)
        K, new_pattern = self._K, False
        if ev.surface is not None:  # on every rank, pairs or none: the matrices are collective
            K, B_values, new_pattern = self._surface_tangent.with_terms(self._K, ev.surface, self._matrix, p.contact.rows,
                                                                        B_values, p.comm)
        J = self._matrix.assemble(K, ev.law.dH_dw, ev.lin.dH_dy, ev.lin.dlam_dy, B_values, new_pattern=new_pattern)
        self._timings.add("block_matrix", t0)
        return J

    def _augmented_system(self, ev: _Evaluation):
        """The augmented Newton system (iterative solver with contact): (MatNest, rhs)."""
        p = self.problem
        t0 = time.perf_counter()
        self._K = p.assemble_tangent(self._K)
        self._timings.add("assembly", t0)
        t0 = time.perf_counter()
        self._follow_geometry()  # a node-to-surface or mortar pair may have changed its columns at this iterate
        assert p.contact is not None and self._augmented is not None and ev.law is not None and ev.lin is not None
        weights = ev.lin.augmentation  # the pair rows' weights in the augmentation (the polar law's)
        B_values = None
        if ev.geometric is not None:  # on every rank, pairs or none: K's assembly in it is collective
            terms = ev.geometric
            terms.add_to_tangent(self._K, self._augmented.slave_free(terms),
                                 self._augmented.augmented_geometric_blocks(terms, ev.law.dH_dw, weights),
                                 combined=self._augmented.combined_blocks(terms, ev.law.dH_dw, weights))
            B_values = terms.rows_values(p.contact.rows)
        surface = None
        if ev.surface is not None:  # on every rank, pairs or none: the matrices are collective
            B_values, G, W_free = self._augmented.surface_blocks(ev.surface, self._K, B_values)
            surface = (G, W_free)
        J = self._augmented.matrix(self._K, ev.law.dH_dw, ev.lin.dH_dy, ev.lin.dlam_dy, B_values, surface, weights)
        if surface is not None:
            surface[0].destroy()
        b = self._augmented.rhs(ev.R_free, ev.H, ev.law.dH_dw, weights)
        self._timings.add("block_matrix", t0)
        return J, b

    def _rhs(self, J: PETSc.Mat, ev: _Evaluation, b: PETSc.Vec | None = None) -> PETSc.Vec:
        """−(R_free, H) in J's layout (a new vector, or ``b`` overwritten)."""
        b = J.createVecRight() if b is None else b
        n_u = ev.R_free.getLocalSize()
        arr = b.getArray()
        arr[:n_u] = -ev.R_free.getArray()
        arr[n_u:] = -ev.H.reshape(-1)
        return b

    def _split(self, x: PETSc.Vec, n_u: int) -> tuple[np.ndarray, np.ndarray]:
        """(du, dz) from the solution vector, du = 0 exactly at the constrained dofs.

        The matrix has identity rows there and the right-hand side zeros, but a Krylov solve
        (and an inexact one above all) returns them only to its tolerance; left alone, the
        prescribed values would drift, unseen by the free residual.
        """
        arr = x.getArray(readonly=True)
        du = arr[:n_u].copy()
        du[self.problem.owned_bc_dofs()] = 0.0
        return du, arr[n_u:].reshape(-1, 3).copy()

    def newton_direction(self, ev: _Evaluation) -> tuple[np.ndarray, np.ndarray] | None:
        """Solve J d = −F at the current iterate; (du, dz), or None if the solve failed."""
        if self._augmented is not None:
            J, b = self._augmented_system(ev)
        else:
            J = self._newton_matrix(ev)
            b = self._rhs(J, ev, self._vector("b", J.createVecRight))
        x = self._vector("x", b.duplicate)
        why_not = self.linear.solve(J, b, x, None if ev.law is None else ev.law.state)
        if why_not is not None:
            logger.info(f"{self.name}: {why_not}")
            return None
        return self._split(x, ev.R_free.getLocalSize())

    def lm_direction(self, ev: _Evaluation, g: Globalisation) -> tuple[np.ndarray, np.ndarray, float]:
        """Levenberg–Marquardt: (JᵀJ + ν I) d = −JᵀF, ν = lm_c · min(ε, 1)^lm_delta · mean diag(JᵀJ).

        Returns (du, dz, ∇Ψ·d). JᵀJ is factorised with MUMPS whatever the Newton solver: it is
        the rare fallback.
        """
        J = self._newton_matrix(ev)
        minus_F = self._rhs(J, ev)
        JtJ = J.transposeMatMult(J)
        diag = JtJ.getDiagonal()
        mean_diag = diag.sum() / max(diag.getSize(), 1)
        eps = math.sqrt(ev.norm_R ** 2 + ev.norm_H ** 2) / ev.scale  # F > 0: it has a floor
        JtJ.shift(g.lm_c * min(eps, 1.0) ** g.lm_delta * mean_diag)
        rhs = JtJ.createVecRight()
        J.multTranspose(minus_F, rhs)
        x = rhs.duplicate()
        options = direct_options({})
        ksp = create_ksp(self.problem.comm, self.prefix + "lm_", options)
        ksp.setOperators(JtJ)
        ksp.solve(rhs, x)
        clear_options(self.prefix + "lm_", options)
        ksp.destroy()
        slope = -rhs.dot(x)  # ∇Ψ·d = (JᵀF)·d
        du, dz = self._split(x, ev.R_free.getLocalSize())
        return du, dz, slope

    def set_iterate(self, u0: np.ndarray, z0: np.ndarray | None, direction, alpha: float, lin=None,
                    align_sliding: bool = False) -> None:
        """u = u0 + α du, z advanced by α dz in the step coordinates of ``lin`` (owned entries; ghosts
        updated); then the unknowns no force depends on follow the slip, with ``align_sliding`` also
        the direction of the friction force of sliding pairs (:meth:`ContactModel.follow_slip`)."""
        p = self.problem
        du, dz = direction[0], direction[1]
        p.u.x.array[:du.shape[0]] = u0 + alpha * du
        p.u.x.scatter_forward()
        self._refresh_geometry()  # before the slip is followed: w in the iterate's own frames
        if p.contact is not None:
            assert z0 is not None  # the pair unknowns of the start, with contact
            p.contact.z = p.contact.advance(z0, dz, alpha, None if lin is None else lin.cartesian)
            p.contact.follow_slip(p.relative_displacement(), sliding_too=align_sliding)


    def destroy(self) -> None:
        """Free the PETSc objects (linear solver, matrices, work vectors)."""
        self.linear.destroy()
        for vector in self._work.values():
            vector.destroy()
        self._work.clear()
        for obj in (self._matrix, self._augmented):
            if obj is not None:
                obj.destroy()
        self._surface_tangent.destroy()
        for petsc_object in (self._K, self._mask):
            if petsc_object is not None:
                petsc_object.destroy()


class _NewtonSystem:
    """The monolithic system as a backend of the Newton driver (one per increment)."""

    def __init__(self, solver: MonolithicSolver, report: SolveReport, align_sliding: bool = False):
        self.solver = solver
        self.problem = solver.problem
        self.report = report
        self.align_sliding = align_sliding  #: see MonolithicSolver.set_iterate
        self.current: _Evaluation | None = None
        self._count_plastic = iteration_log_on(self.problem.comm)  # trial plastic points, for the log only
        self._start: tuple[np.ndarray, np.ndarray | None, _Evaluation] | None = None  # (u0, z0, evaluation) of the step being taken
        self._direction: tuple[np.ndarray, np.ndarray] | None = None
        self._slope = math.nan

    def _merit(self, ev: _Evaluation) -> Merit:
        opts = self.solver.options
        tol = opts.rtol * ev.scale + opts.atol
        converged = ev.norm_R <= tol and ev.norm_H <= tol
        return Merit(0.5 * (ev.norm_R ** 2 + ev.norm_H ** 2), converged)

    def evaluate(self) -> Merit:
        self.current = self.solver.evaluate()
        return self._merit(self.current)

    def record(self, iteration: int, step_length: float, kind: str) -> None:
        p, ev = self.problem, self.current
        assert ev is not None  # the driver evaluates before it records
        free_dropped_objects(p.petsc_comms)  # once per iteration, on every rank
        ref = ev.scale  # F, as the independent check has it (atol is no scale: issue 31)
        states = count_states(ev.law.state, p.comm) if ev.law is not None else (0, 0, 0)
        plastic = p.state.count_trial_plastic_points(p.u) if self._count_plastic else None
        record = IterationRecord(iteration, ev.norm_R / ref, ev.norm_H / ref, step_length, kind, states, plastic)
        self.report.history.append(record)
        logger.info(record.line(self.solver.name))

    def snapshot(self):
        p = self.problem
        return p.u.x.array.copy(), (p.contact.z.copy() if p.contact is not None else None), self.current

    def restore(self, snapshot) -> Merit:
        p = self.problem
        u, z, ev = snapshot
        p.u.x.array[:] = u
        if p.contact is not None:
            p.contact.z = z.copy()
        self.solver._refresh_geometry()  # B and the frames of the restored iterate, as ev has them
        self.current = ev
        return self._merit(ev)

    def start_step(self) -> None:
        p = self.problem
        assert self.current is not None  # the driver evaluates before a step
        u0 = p.u.x.array[:self.current.R_free.getLocalSize()].copy()
        self._start = (u0, p.contact.z.copy() if p.contact is not None else None, self.current)

    def newton_direction(self, merit: Merit) -> str | None:
        assert self._start is not None  # start_step came first
        ev = self._start[2]
        ref = ev.scale
        self.solver.linear.set_forcing(math.sqrt(ev.norm_R ** 2 + ev.norm_H ** 2) / ref)
        self._direction = self.solver.newton_direction(ev)
        if self._direction is None:
            return "the linear solve of the Newton step failed"
        self._slope = -2.0 * merit.psi  # J d = −F exactly: ∇Ψ·d = −|F|²
        return None

    def lm_direction(self, merit: Merit, globalisation: Globalisation) -> str | None:
        assert self._start is not None  # start_step came first
        u0, z0, ev = self._start
        self.solver.set_iterate(u0, z0, (np.zeros_like(u0), None if z0 is None else np.zeros_like(z0)), 0.0)
        du, dz, self._slope = self.solver.lm_direction(ev, globalisation)
        self._direction = (du, dz)
        return None

    def slope(self) -> float:
        return self._slope

    def move(self, step_length: float) -> Merit:
        assert self._start is not None and self._direction is not None  # start_step and a direction came first
        u0, z0, ev = self._start
        self.solver.set_iterate(u0, z0, self._direction, step_length, ev.lin, self.align_sliding)
        return self.evaluate()

    def roundoff_note(self) -> str | None:
        """Round-off, when the pair laws have converged and |R|/F stopped at its floor: the rounding
        of u times K_t (stiff bodies that moved far under small strains, docs/robustness.md)."""
        ev, K = self.current, self.solver._K
        if ev is None or K is None:  # no Newton matrix yet
            return None
        opts = self.solver.options
        if ev.norm_H > opts.rtol * ev.scale + opts.atol:
            return None  # the contact rows stop it: not the equilibrium's round-off
        p = self.problem
        floor = residual_floor(K, p.u.x.petsc_vec, p.free_residual)
        return floor_note("|R|/F", ev.norm_R / ev.scale, floor / ev.scale, opts.rtol)
