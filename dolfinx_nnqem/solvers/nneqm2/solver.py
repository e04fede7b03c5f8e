r"""NNEQM2: one nonsmooth system for the pair unknowns and every Gauss point's plastic flow (seed §4).

The displacement of an increment follows from the ELASTIC stiffness K_e, factorised once per run,
and the unknowns that load it: the pair forces, the Gauss points' plastic strains and, where
bodies float, the free rigid modes' amplitudes (:mod:`~dolfinx_nnqem.solvers.nneqm2.increment_start`):
equilibrium holds by construction, and the equations are the pair laws and the Gauss points'
yield conditions — one nonsmooth system. Only the Gauss points of a material that can yield
carry unknowns (an elastic body adds nothing).

Two variants (:class:`~dolfinx_nnqem.solvers.options.NNEQM2Options`, ``flow_directions``):

* "return-map" (default, :mod:`~dolfinx_nnqem.solvers.nneqm2.return_map`): each Gauss point's
  plastic strain increment, direction included, is an unknown, and its rows are the radial
  return's — the seed's yield complementarity with the normality of the flow. The answer is the
  backward-Euler state of the monolithic solver and NNEQM1, from any state, under any driver.
  A Newton step eliminates the Gauss points' rows locally through the consistent tangent, so it
  costs what an outer iteration of NNEQM1 costs.
* "frozen" (:mod:`~dolfinx_nnqem.solvers.nneqm2.frozen`): the seed's method, the flow directions
  frozen at the start of the increment and a dense system of order 3NC + NG in the plastic
  multipliers; first-order accurate in the increment where the stress turns.

Both return their own Gauss-point values (``SolveReport.gauss_point_values``: the stresses, Δp,
the plastic strain increments and the flow rule they follow), which the commit stores and the
independent check verifies (:mod:`~dolfinx_nnqem.solvers.checks`). Each increment also records
(``increment_info``) its own-stress equilibrium residual, the largest yield-function value and
the largest difference to the radial-return stress of the same displacement.

MPI: everything distributed is assembled and solved by PETSc; the dense contact systems are
gathered on every rank and solved redundantly, rank 0's solution broadcast where it decides.
"""

from __future__ import annotations

import math
import time

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.material.interface import GaussPointValues
from dolfinx_nnqem.material.kinematics import deviator_coordinates, deviator_tensors, elastic_stress
from dolfinx_nnqem.numerics.linalg import vec_norm
from dolfinx_nnqem.numerics.newton import solve
from dolfinx_nnqem.problem.contact_problem import ContactProblem
from dolfinx_nnqem.problem.kinematics_choice import kinematics_of
from dolfinx_nnqem.solvers.condensation import Condensation, check_dense_memory
from dolfinx_nnqem.solvers.contract import ReleasesPETSc
from dolfinx_nnqem.solvers.convergence import IterationRecord, SolveReport, logger
from dolfinx_nnqem.solvers.nneqm2.current_geometry import GeometryFollower, settled
from dolfinx_nnqem.solvers.nneqm2.gauss_points import GaussPointOperators
from dolfinx_nnqem.solvers.nneqm2.increment_start import IncrementStart, start_increment
from dolfinx_nnqem.solvers.nneqm2.frozen import FrozenDirections
from dolfinx_nnqem.solvers.nneqm2.return_map import ReturnMapIncrement
from dolfinx_nnqem.solvers.options import NNEQM2Options, SolverOptions
from dolfinx_nnqem.solvers.timings import Timings, summed

__all__ = ["NNEQM2Solver"]

_SQRT23 = math.sqrt(2.0 / 3.0)


def refuse_finite_strain(problem: ContactProblem) -> None:
    """NNEQM2 solves small-strain problems only; raise, before anything is built, for kinematics "finite"."""
    if kinematics_of(problem) != "finite":
        return
    raise ValueError(
        "nneqm2: the problem has kinematics = 'finite', which NNEQM2 cannot take: its Gauss-point unknowns and "
        "yield rows are the small-strain pointwise form (σ = σ_n + C (Δε − Δε_p) with Δε = sym grad Δu, the "
        "deviatoric plastic strain in ε), and its condensation uses the elastic stiffness K_e factorised once; at "
        "finite strain the stress is P(F) by the logarithmic strain and the tangent changes with F. Use the "
        "monolithic solver or NNEQM1, or kinematics = 'small'")


def refuse_material(gp: GaussPointOperators, frozen: bool) -> None:
    """NNEQM2's Gauss-point unknowns are deviatoric plastic strains (5 coordinates, Δp = √(2/3)|Δε_p|);
    the seed's frozen variant is written for von Mises yield (N = (3/2) s/q, isotropic hardening).
    Raise, before solving, for a material it cannot take."""
    material = gp.material
    criterion = gp.problem.comm.allgather(material.yield_criterion if np.any(material.yields) else "none")
    criteria = sorted(set(criterion) - {"none"})
    if not gp.problem.comm.allreduce(bool(material.deviatoric_flow), op=MPI.LAND):
        raise ValueError(
            f"nneqm2: a material of the problem ({', '.join(criteria) or 'its yield criterion'}) has a volumetric "
            "plastic strain; NNEQM2's Gauss-point unknowns are deviatoric plastic strains (5 coordinates): use the "
            "monolithic solver or NNEQM1")
    if frozen and criteria not in ([], ["von-mises"]):
        raise ValueError(
            f"nneqm2: flow_directions='frozen' is the seed's method for von Mises yield with isotropic hardening "
            f"(N = (3/2) s/q frozen in the increment); the problem's materials yield by {criteria}: use "
            "flow_directions='return-map' (the default), the monolithic solver or NNEQM1")


class NNEQM2Solver(ReleasesPETSc):
    """One nonsmooth system in the pair unknowns and the plastic flow of all Gauss points that can yield.

    Parameters
    ----------
    problem
        A :class:`~dolfinx_nnqem.problem.ContactProblem`, with or without contact.
    options
        Tolerances (relative to the system's scales: the force scale F for the pair rows, σ_u
        for the yield rows), the iteration limit, ``petsc_options`` for the stiffness solves.
    nneqm2
        This solver's own options (:class:`~dolfinx_nnqem.solvers.options.NNEQM2Options`).

    Notes
    -----
    ``SolveReport.system_order`` is the number of unknowns (3NC + 5NG + n_r for "return-map",
    3NC + NG + n_r for "frozen"); ``iterations`` counts Newton iterations ("return-map") or the
    dense nonsmooth iterations ("frozen"); ``increment_info`` holds one dict of checks per
    converged increment; ``timings`` accumulates seconds per phase.
    """

    name = "nneqm2"
    follows_contact_geometry = True  # K_e once per run; what is built on B follows the pairs (.current_geometry)

    def __init__(self, problem: ContactProblem, options: SolverOptions | None = None,
                 nneqm2: NNEQM2Options | None = None):
        refuse_finite_strain(problem)
        self.problem = problem
        self.options = options or SolverOptions()
        self.settings = nneqm2 or NNEQM2Options()
        self.increment_info: list[dict] = []  #: per converged increment: checks and counts
        t0 = time.perf_counter()
        self.gp = GaussPointOperators(problem)
        self._parameters_version = problem.state.parameters_version  # the materials gp and K_e are built of
        self.frozen = self.settings.flow_directions == "frozen"
        refuse_material(self.gp, self.frozen)
        n_r = problem.rigid_modes.count
        self.system_order = 3 * problem.num_pairs + (1 if self.frozen else 5) * self.gp.num_yield_points + n_r
        if self.frozen and self.system_order > self.settings.max_dense_order:
            raise ValueError(
                f"nneqm2: the dense system would have order 3 NC + NG = {self.system_order} ({problem.num_pairs} "
                f"pairs, {self.gp.num_yield_points} Gauss points that can yield), {8e-9 * self.system_order**2:.2g} "
                f"GB per matrix, above NNEQM2Options.max_dense_order = {self.settings.max_dense_order}; use "
                "flow_directions='return-map' (no dense matrix over the Gauss points), the monolithic solver or "
                "NNEQM1, or raise max_dense_order")
        if not self.frozen and problem.has_contact:
            check_dense_memory(problem, self.name, self.settings.max_memory_gb)
        self.elastic = Condensation(problem, self.name, self.options.petsc_options)
        self.tangent = None if self.frozen else Condensation(problem, f"{self.name}_tangent",
                                                             self.options.petsc_options)
        self._frozen = (FrozenDirections(problem, self.gp, self.elastic, self.settings.inner_globalisations,
                                         self.settings.inner_max_iterations) if self.frozen else None)
        self._factorised = False
        self.geometry = GeometryFollower(problem, self._pairs_changed)
        self._timings = Timings(setup=time.perf_counter() - t0)
        self._phases: list[dict[str, float]] = []

    @property
    def timings(self) -> dict[str, float]:
        """Seconds per phase: setup, assembly, factorisation, flexibility, solve, and the variant's own."""
        parts = [self._timings, self.elastic.timings, *self._phases]
        if self.tangent is not None:
            parts.append({f"tangent_{k}": v for k, v in self.tangent.timings.items()})
        if self._frozen is not None:
            parts.append(self._frozen.timings)
        return summed(*parts)

    # -- one increment -------------------------------------------------------------------------------
    def solve_increment(self, load_factor: float) -> SolveReport:
        """Solve for the load factor ``load_factor`` from the last converged state (the elastic
        stiffness K_e factorised once, on the first call)."""
        p = self.problem
        if p.state.parameters_version != self._parameters_version:  # the same on every rank (update is collective)
            raise ValueError("nneqm2: the problem's material parameters changed (ContactProblem.update) after this "
                             "solver was built; its Gauss-point operators and factorised elastic stiffness are those "
                             "of the old parameters: build the solver again (make_solver)")
        if not self._factorised:
            self.elastic.factorise(p.assemble_elastic_stiffness, "the elastic stiffness K_e")
            self._factorised = True
        t_start = time.perf_counter()
        self.geometry.follow()  # current geometry: B changed since the last solve
        repeats = self.geometry.repeated(load_factor)  # the last solve's values, if this one repeats it
        start = start_increment(p, self.gp, self.elastic, load_factor, self.settings.extrapolate)
        self.system_order = (3 * p.num_pairs + (1 if self.frozen else 5) * self.gp.num_yield_points
                             + p.rigid_modes.count)  # pairs come and go in the current geometry
        report = SolveReport(converged=False, iterations=0, system_order=self.system_order)
        tol = self.options.rtol + self.options.atol / start.force_scale
        try:
            values = self._settled(repeats, start, tol, report) if repeats is not None else None
            if values is None:
                values = self._frozen_increment(start, tol, report) if self.frozen else \
                    self._return_map_increment(start, tol, report, repeated=repeats is not None)
        finally:
            start.destroy()
        if values is None:
            return report
        if repeats is not None and values is not repeats:
            report.iterations = self.geometry.moved(report.iterations, repeats)
        self.geometry.remember(load_factor, values)
        report.gauss_point_values = values
        info = self._checks(values, load_factor, report.iterations)
        info["wall_time_s"] = time.perf_counter() - t_start
        info["solves"] = 1
        if repeats is not None and self.increment_info and self.increment_info[-1]["load_factor"] == info["load_factor"]:
            # one entry per increment: the last solve's checks, in the geometry it ended in
            previous = self.increment_info.pop()
            info["solves"] += previous["solves"]
            info["iterations"] += previous["iterations"]
            info["wall_time_s"] += previous["wall_time_s"]
        self.increment_info.append(info)
        last = report.history[-1]
        report.history[-1] = IterationRecord(last.iteration, info["equilibrium_residual"], last.contact,
                                             last.step_length, "", last.states, info["plastic_points"],
                                             yield_residual=last.yield_residual)
        logger.info(f"[{self.name}] ℓ = {load_factor:.6g}: {self.settings.flow_directions} directions, "
                    f"{report.iterations} iterations, own-stress |R|/F = {info['equilibrium_residual']:.2e}, "
                    f"max f/σ_y = {info['max_yield_violation']:.2e}, "
                    f"max |σ − σ_return map|/σ_y = {info['return_map_difference']:.2e}")
        report.converged, report.message = True, "converged"
        return report

    def _settled(self, last: GaussPointValues, start: IncrementStart, tol: float, report: SolveReport
                 ) -> GaussPointValues | None:
        """``last`` if the last solve's state satisfies the equations in the geometry re-evaluated at it
        (:func:`~dolfinx_nnqem.solvers.nneqm2.current_geometry.settled`): the increment then takes no
        iteration. Else None (and the solve starts there)."""
        ok, record = settled(self.problem, self.gp, last, start, tol)
        report.history.append(record)
        logger.info(record.line(self.name) + ("  (the last solve, in the geometry re-evaluated at it)"))
        if not ok:
            report.history.clear()
            return None
        return last

    def _return_map_increment(self, start: IncrementStart, tol: float, report: SolveReport, repeated: bool = False
                              ) -> GaussPointValues | None:
        """The default variant's Newton iteration; its Gauss-point values, or None.

        With the polar law, an increment that fails is tried once more with the angle of sliding
        pairs on their slip after every step, as in the monolithic solver. ``repeated``: the solve
        repeats the last one in a re-evaluated contact geometry, from its solution (no lift).
        """
        p = self.problem
        backend, outcome = self._newton(start, tol, report, align_sliding=False, repeated=repeated)
        report.iterations = outcome.iterations
        if outcome.converged:
            return self._own_values(start, backend.x)
        if p.contact is not None and p.contact.slip_following and outcome.iterations > 0:
            logger.info(f"[{self.name}] increment to load factor {start.load_factor:.6g}: {outcome.message}; "
                        "trying again with the angle of sliding pairs on their slip after every step")
            tried = outcome.iterations
            p.restore()
            again = start_increment(p, self.gp, self.elastic, start.load_factor, self.settings.extrapolate)
            try:
                backend, outcome = self._newton(again, tol, report, align_sliding=True, repeated=False)
                outcome.iterations += tried
                report.iterations = outcome.iterations
                if outcome.converged:
                    return self._own_values(again, backend.x)
            finally:
                again.destroy()
        report.message = outcome.message
        return None

    def _newton(self, start: IncrementStart, tol: float, report: SolveReport, align_sliding: bool,
                repeated: bool):
        """One attempt: the predictor step, then the Newton driver. (backend, outcome)."""
        p = self.problem
        assert self.tangent is not None  # the return-map variant factorises K_t
        backend = ReturnMapIncrement(p, self.gp, self.elastic, self.tangent, start, tol, report, align_sliding)
        # the first step linearises where the increment starts, as the other solvers' first
        # iteration does; where prescribed values jump and nothing is extrapolated, at u_n with
        # the jump lifted (a boundary layer moved alone would yield spuriously); a repeated solve
        # (current geometry) at the last solution, which holds the prescribed values already
        jump = not repeated and start.extrapolation is None and p.comm.allreduce(
            bool(np.any(p.u.x.array[p.bc_dofs] != p.state.u_n.x.array[p.bc_dofs])), op=MPI.LOR)
        why_not = backend.predictor_step(lift=jump)
        first = (0, "", math.nan) if why_not else (1, "predictor", 1.0)
        outcome = solve(backend, self.settings.globalisation, self.options.max_iterations,
                        first_iteration=first[0], first_kind=first[1], first_step_length=first[2])
        self._phases.append(backend.timings)
        return backend, outcome

    def _own_values(self, start: IncrementStart, x) -> GaussPointValues:
        """The converged iterate into the problem (z) and its Gauss-point values."""
        p, gp = self.problem, self.gp
        if p.contact is not None:
            p.contact.z = x.z.copy()
        du = self.elastic.K.createVecRight()
        du.getArray()[:] = x.du
        eps = gp.strains(du)
        du.destroy()
        deps_p = deviator_tensors(x.eps_p)
        sigma = start.sigma_n + elastic_stress(eps, gp.lmbda, gp.mu) - 2.0 * gp.mu[:, None, None] * deps_p
        dp = _SQRT23 * np.linalg.norm(x.eps_p, axis=1)
        return GaussPointValues(p.u.x.array.copy(), sigma, dp, deps_p, "backward-euler")

    def _frozen_increment(self, start: IncrementStart, tol: float, report: SolveReport) -> GaussPointValues | None:
        """The seed's variant; its Gauss-point values, or None."""
        p, gp, st = self.problem, self.gp, self.problem.state
        assert self._frozen is not None  # the frozen variant's
        solution = self._frozen.solve(start, tol, report)
        if solution is None:
            return None
        n_u = solution.du.shape[0]
        u_bc = p.u.x.array[p.bc_dofs].copy()  # the prescribed values, kept exactly
        p.u.x.array[:n_u] = st.u_n.x.array[:n_u] + solution.du
        p.u.x.scatter_forward()
        p.u.x.array[p.bc_dofs] = u_bc
        if p.contact is not None:
            p.contact.z = p.contact.local_rows(solution.z).copy()
        du = self.elastic.K.createVecRight()
        du.getArray()[:] = solution.du
        eps = gp.strains(du)
        du.destroy()
        dg = gp.owned(solution.dgamma)
        deps_p = dg[:, None, None] * deviator_tensors(gp.owned(solution.N))
        sigma = start.sigma_n + elastic_stress(eps - deps_p, gp.lmbda, gp.mu)
        return GaussPointValues(p.u.x.array.copy(), sigma, dg, deps_p, "frozen-directions")

    # -- what each increment reports about itself -----------------------------------------------------
    def _checks(self, values: GaussPointValues, load_factor: float, iterations: int) -> dict:
        p, gp, st = self.problem, self.gp, self.problem.state
        comm = p.comm
        F_int = gp.force(values.sigma)  # equilibrium with NNEQM2's own stresses (before the commit)
        F_ext = p.external_force()
        scale = p.force_scale(F_int, F_ext)
        R = p.residual(F_int=F_int)
        R_free = p.free_residual(R)
        eq = vec_norm(R_free) / scale  # F, as the independent check has it (atol is no scale: issue 31)
        # the return map's stress of the same displacement, from the same converged state
        sigma_rm = st.return_map_values(p.u).sigma
        diff = np.linalg.norm((values.sigma - sigma_rm).reshape(gp.n_gp, 9), axis=1) / gp.stress_unit
        f = (gp.material.yield_value(deviator_coordinates(values.sigma), st.internal_at_points(values))
             / gp.stress_unit)[gp.yields]
        for vec in (F_int, F_ext, R, R_free):
            vec.destroy()
        return {
            "load_factor": float(load_factor),
            "system_order": self.system_order,
            "iterations": int(iterations),
            "directions": self.settings.flow_directions,
            "equilibrium_residual": float(eq),
            "return_map_difference": comm.allreduce(float(np.max(diff, initial=0.0)), op=MPI.MAX),
            "max_yield_violation": comm.allreduce(float(np.max(f, initial=-np.inf)), op=MPI.MAX),
            "plastic_points": comm.allreduce(int(np.count_nonzero(values.dp > 0.0)), op=MPI.SUM),
        }

    def _pairs_changed(self) -> None:
        """The contact geometry changed: forget what was built on B (the factorisations of K_e and
        K_t stay: at small strain they do not depend on the pairs)."""
        for part in (self.elastic, self.tangent, self._frozen):
            if part is not None:
                part.pairs_changed()

    def destroy(self) -> None:
        """Free the condensations' and the Gauss-point operators' PETSc objects (collective)."""
        for part in (self.elastic, self.tangent, self.gp):
            if part is not None:
                part.destroy()
