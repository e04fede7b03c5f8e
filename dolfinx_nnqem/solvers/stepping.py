"""Load stepping with cutback (``formulation.md`` §6).

The load factor ℓ rises from 0 to 1 in N equal increments. An increment that does not converge
is halved and retried, at most ``max_cutbacks`` times in a row; then :class:`ConvergenceError`
names the increment, the residuals and the pair states. Every converged increment is committed
and handed to the callbacks (the writers) before the next one starts, so a run that dies later
loses no converged increment.

A solver's "converged" is not taken on trust: before the commit the state is checked
independently (:func:`dolfinx_nnqem.solvers.checks.check_state`: equilibrium at the free dofs, every
pair's complementarity, finite values, the small-strain setting); a failed check makes the
increment a non-converged one with the check's reason. A ``checkpoint``
(:class:`dolfinx_nnqem.io.checkpoint.Checkpointer`) saves what the next increment needs after the
writers ran; ``resume`` (from :func:`dolfinx_nnqem.io.checkpoint.restore`) continues such a run.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.contact.geometry_tracking import GeometryStepError
from dolfinx_nnqem.contact.slip_check import stale_message, switch_message
from dolfinx_nnqem.material.interface import GaussPointValues
from dolfinx_nnqem.solvers.checks import CheckOptions, StateCheck, check_state, failure_details, values_to_commit
from dolfinx_nnqem.solvers.contract import SolvableProblem, Solver
from dolfinx_nnqem.solvers.convergence import ConvergenceError, SolveReport, logger
from dolfinx_nnqem.numerics.heap import release_free_heap
from dolfinx_nnqem.numerics.linalg import free_dropped_objects
from dolfinx_nnqem.solvers.step_control import AutomaticIncrements, as_step_control
from dolfinx_nnqem.problem.validation import check_load_factors, check_stepping_arguments


@dataclass
class IncrementResult:
    """A converged increment, as handed to the writers."""

    index: int  #: 1-based count of converged increments
    load_factor: float
    report: SolveReport
    plastic_points: int  #: Gauss points that yielded in this increment
    wall_time_s: float
    cutbacks: int  #: halvings needed before this increment converged
    commit_time_s: float = 0.0  #: state update (Gauss-point stresses) after convergence
    output_time_s: float = 0.0  #: time spent in the callbacks (writers)
    check: StateCheck | None = None  #: the independent check of the converged state

    @property
    def iterations(self) -> int:
        """The solver's iterations in this increment (the converged attempt's)."""
        return self.report.iterations


@dataclass
class StepperState:
    """Where load stepping stands after a converged increment (what a restart needs)."""

    start: float  #: the load factor the run started from
    step: float  #: the next increment's size (after a cutback: the reduced one)
    cutbacks: int  #: halvings still in force
    index: int  #: converged increments so far


Checkpoint = Callable[[Any, StepperState, "IncrementResult"], object]
"""``checkpoint(problem, stepper_state, result)``, called after every converged increment
(:class:`dolfinx_nnqem.io.checkpoint.Checkpointer`, whose problem is the concrete
:class:`~dolfinx_nnqem.problem.contact_problem.ContactProblem`: hence ``Any`` for it here)."""


def _free_dropped_memory(problem: SolvableProblem) -> None:
    """Before an increment (collective): the PETSc objects dropped since the last one destroyed, and
    the C heap's free pages, what the last increment's check and commit freed, given back."""
    free_dropped_objects(problem.petsc_comms)
    release_free_heap()


def solve_load_steps(
    problem: SolvableProblem,
    solver: Solver,
    increments: int | str | AutomaticIncrements = 15,
    *,
    max_cutbacks: int = 5,
    callbacks: Sequence[Callable[[IncrementResult], None]] = (),
    final_load_factor: float = 1.0,
    max_displacement: float | None = None,
    check: CheckOptions | None = None,
    checkpoint: Checkpoint | None = None,
    resume: StepperState | None = None,
) -> list[IncrementResult]:
    """Drive ``solver`` from the last converged load factor to ``final_load_factor``.

    Parameters
    ----------
    problem
        The :class:`~dolfinx_nnqem.problem.contact_problem.ContactProblem`.
    solver
        A :class:`~dolfinx_nnqem.solvers.contract.Solver`.
    increments
        Number of equal increments N (the seed: 15), or ``"auto"`` / an
        :class:`~dolfinx_nnqem.solvers.step_control.AutomaticIncrements` for automatic incrementation
        (the increment grows when Newton converges easily and shrinks when it struggles).
    max_cutbacks
        Halvings allowed in a row before giving up.
    callbacks
        Called with every converged :class:`IncrementResult`, in order.
    max_displacement
        Reject (and cut back) an increment whose largest displacement component exceeds this:
        past a limit load a small-displacement model keeps finding equilibria with ever larger
        displacements, so collapse is declared when the displacement leaves the small range.
    check
        :class:`~dolfinx_nnqem.solvers.checks.CheckOptions` of the independent check of every converged
        state (default: tolerances derived from the solver's ``options``).
    checkpoint
        Called as ``checkpoint(problem, stepper_state, result)`` after the callbacks of every
        converged increment (:class:`dolfinx_nnqem.io.checkpoint.Checkpointer`).
    resume
        The :class:`StepperState` of a restored checkpoint: continue that run (same
        ``increments`` and ``final_load_factor``).

    Raises
    ------
    ConvergenceError
        An increment did not converge after ``max_cutbacks`` halvings. Its ``failure``
        attribute (a dict: increment, load factor, reason, the worst nodes and pairs) is also
        handed to every callback that has a ``failed`` method before it is raised.
    """
    equal, control = as_step_control(increments)  # equal: N equal increments, None: automatic
    equal, max_cutbacks, final_load_factor, max_displacement = check_stepping_arguments(
        equal, max_cutbacks, final_load_factor, max_displacement)
    check = check or CheckOptions()
    schedule = _Schedule.of_run(problem.load_factor_n, final_load_factor, equal, control, resume)
    index0 = 0 if resume is None else resume.index
    results: list[IncrementResult] = []
    ell = problem.load_factor_n
    while not schedule.reached(ell):
        target = schedule.target(ell)
        _free_dropped_memory(problem)
        t0 = time.perf_counter()
        report, verdict, values = _solve_and_check(problem, solver, target, check, max_displacement)
        if report.converged and _moved_to_current_geometry(problem, solver, report, target, index0 + len(results) + 1,
                                                           schedule.cutbacks, callbacks, ell):
            problem.restore()  # the same increment again, the slid interfaces in the current geometry
            continue
        if not report.converged:
            _cut_back_or_fail(problem, solver, report, schedule, max_cutbacks, target, index0 + len(results) + 1,
                              callbacks, ell)
            continue
        result = _commit(problem, solver, report, values, target, index=index0 + len(results) + 1,
                         cutbacks=schedule.cutbacks, verdict=verdict, t0=t0, callbacks=callbacks)
        values = None  # committed: not held through the next increment's solve (σ and Δε_p at every point)
        results.append(result)
        ell = target
        schedule.accepted(report.iterations)
        if checkpoint is not None:
            checkpoint(problem, schedule.state(result.index), result)
    return results


def _cut_back_or_fail(problem: SolvableProblem, solver: Solver, report: SolveReport, schedule: _Schedule,
                      max_cutbacks: int, target: float, increment: int,
                      callbacks: Sequence[Callable[[IncrementResult], None]], last_converged: float) -> None:
    """After an increment that did not converge: back to the converged state with the step halved,
    or, after ``max_cutbacks`` halvings, the run's failure (:func:`_fail` raises)."""
    if not schedule.can_cut_back(max_cutbacks):
        _fail(problem, solver, report, target, increment=increment, cutbacks=schedule.cutbacks,
              callbacks=callbacks, last_converged=last_converged)
    problem.restore()
    schedule.cut_back()
    logger.warning(f"[{solver.name}] increment to load factor {target:.6g} failed "
                   f"({report.message}); cutback {schedule.cutbacks}, new step {schedule.step:.6g}")


@dataclass
class _Schedule:
    """The load factors to aim at: equal increments (or automatic ones), halved after a failure.

    ``step`` is signed for equal increments (unloading paths run downwards) and a size for
    automatic ones, whose ``control`` turns it into a target.
    """

    start: float  #: the load factor the run started from
    final: float
    step: float
    cutbacks: int  #: halvings in force
    increments: int | None  #: N equal increments, or None (automatic)
    control: AutomaticIncrements | None

    @classmethod
    def starting(cls, start: float, final: float, increments: int | None,
                 control: AutomaticIncrements | None) -> _Schedule:
        if control is None:
            assert increments is not None  # as_step_control gives one of the two
            step = (final - start) / increments
        else:
            step = control.first_step(final - start)
        return cls(start, final, step, 0, increments, control)

    @classmethod
    def of_run(cls, load_factor_n: float, final: float, increments: int | None,
               control: AutomaticIncrements | None, resume: StepperState | None) -> _Schedule:
        """The schedule of a run from the converged load factor ``load_factor_n``, or of the run a
        checkpoint's ``resume`` continues; an automatic one's prescribed load factors checked."""
        if resume is None:
            schedule = cls.starting(load_factor_n, final, increments, control)
        else:
            schedule = cls(resume.start, final, resume.step, resume.cutbacks, increments, control)
        if control is not None:
            check_load_factors(control.load_factors, schedule.start, final)
        return schedule

    @property
    def direction(self) -> float:
        return 1.0 if self.final >= self.start else -1.0

    @property
    def span(self) -> float:
        return abs(self.final - self.start)

    def reached(self, ell: float) -> bool:
        """ℓ is the final load factor (to rounding)."""
        return self.direction * (self.final - ell) <= 1e-12 * self.span

    def target(self, ell: float) -> float:
        """The next increment's end, not past the final load factor."""
        if self.control is not None:
            return self.control.target(ell, abs(self.step), self.final, self.direction, self.span)
        target = ell + self.step
        return self.final if self.direction * (target - self.final) > 0 else target

    def can_cut_back(self, max_cutbacks: int) -> bool:
        """Another halving is allowed (not past ``max_cutbacks`` in a row, nor below the
        automatic control's smallest step)."""
        if self.cutbacks >= max_cutbacks:
            return False
        return self.control is None or not self.control.too_small(abs(self.step) / 2.0, self.span)

    def cut_back(self) -> None:
        self.cutbacks += 1
        self.step /= 2.0

    def accepted(self, iterations: int) -> None:
        """After a converged increment: the automatic size follows the Newton iterations; after a
        successful cut step, the equal step is tried again, doubling back."""
        if self.control is not None:
            self.step = self.direction * self.control.next_step(abs(self.step), iterations, self.span)
            self.cutbacks = 0
        elif self.cutbacks:
            assert self.increments is not None  # equal increments (no control)
            self.step = self.direction * min(abs(2.0 * self.step), self.span / self.increments)
            self.cutbacks = max(self.cutbacks - 1, 0)

    def state(self, index: int) -> StepperState:
        return StepperState(self.start, self.step, self.cutbacks, index)


def _solve_and_check(problem, solver, target: float, check: CheckOptions | None,
                     max_displacement: float | None = None
                     ) -> tuple[SolveReport, StateCheck | None, GaussPointValues | None]:
    """Solve the increment to ``target``; a solver's "converged" stands only if the independent
    check confirms it and the displacement stays below ``max_displacement``. Returns the report,
    the check and the Gauss-point values to commit (None if the solve did not converge)."""
    report = _solve(problem, solver, float(target))
    verdict, values = None, None
    if report.converged:
        # the Gauss-point values to commit, computed once: the check verifies them, the commit stores them
        values = values_to_commit(problem, report)
        verdict = check_state(problem, report, getattr(solver, "options", None), check, values)
        if not verdict.ok:
            report.converged = False
            report.message = f"the solver reported convergence, but the independent check failed: {verdict.reason}"
    if report.converged and max_displacement is not None:
        u_max = _max_displacement(problem)
        if u_max > max_displacement:
            report.converged = False
            report.message = (f"largest displacement {u_max:.4g} exceeds max_displacement = "
                              f"{max_displacement:.4g} (collapse)")
    return report, verdict, values


GEOMETRY_PASSES = 30
"""Solves of one increment at most, each in the contact geometry of the last one's solution, unless
they are still converging (:data:`CONVERGING_PASSES`)."""

CONVERGING_PASSES = 100
"""Solves of one increment at most while each moves u less than :data:`SETTLING_FACTOR` times the
one before on average over the last three: a slow but steady fixed point (a solver that holds the
geometry within a solve, at large deformation) is given the solves it needs."""

SETTLING_FACTOR = 0.8


def _solve(problem, solver, target: float) -> SolveReport:
    """Solve the increment; with current-geometry contact, until the geometry settles.

    The geometry is evaluated where the increment starts (u_n, the obstacles at ℓ) and the
    increment solved with it frozen; then it is evaluated again at the solution and the increment
    solved again from there, until a solve starts converged (the first solve's start is the
    predictor, not u_n, so it always gets a second): the solution then satisfies the equations in
    the geometry of its own configuration (``docs/theory.md``, "Large sliding"). A solver that
    re-evaluates the geometry at every iterate (``report.geometry_consistent``) needs one solve.
    The report counts the Newton iterations of every pass.
    """
    model = problem.contact
    if model is None or not model.geometry.follows_bodies:
        return solver.solve_increment(target)
    lost = _update_geometry(problem, target)
    if lost is not None:
        return lost
    report = solver.solve_increment(target)
    iterations, passes = report.iterations, 1
    moves: list[float] = []  # how far each repeated solve moved u (max norm)
    # The first solve starts from the predictor (the secant extrapolation), not from where the geometry
    # was evaluated (u_n): even with no Newton iteration its solution is not yet in its own geometry.
    while report.converged and (report.iterations > 0 or passes == 1) and not report.geometry_consistent:
        if passes >= GEOMETRY_PASSES and (passes == CONVERGING_PASSES or _settling_factor(moves) > SETTLING_FACTOR):
            report.converged = False
            report.message = _unsettled_message(moves, passes)
            break
        lost = _update_geometry(problem, target)
        if lost is not None:
            lost.iterations += iterations
            return lost
        problem.warm_start = True
        before = problem.u.x.array.copy()
        try:
            report = solver.solve_increment(target)
        finally:
            problem.warm_start = False
        moved = np.abs(problem.u.x.array - before).max(initial=0.0)
        moves.append(float(problem.comm.allreduce(moved, op=MPI.MAX)))
        iterations, passes = iterations + report.iterations, passes + 1
    report.iterations, report.geometry_passes = iterations, passes
    return report


def _settling_factor(moves: list[float]) -> float:
    """The mean factor by which each of the last three repeated solves moved u less than the one
    before (inf if there are fewer than four)."""
    if len(moves) < 4 or moves[-4] <= 0.0:
        return float("inf")
    return (moves[-1] / moves[-4]) ** (1.0 / 3.0)


def _unsettled_message(moves: list[float], passes: int) -> str:
    """Why the repeated solves of an increment stopped: the geometry did not settle. Says how far
    the last solve still moved u and by what factor the solves were converging, and what settles
    it: the monolithic solver linearises the geometry within its Newton steps."""
    text = f"the contact geometry did not settle in {passes} solves of the increment (each re-evaluated at the last solution)"
    factor = _settling_factor(moves)
    if factor < float("inf") and moves[0] > 0.0:
        text += (f"; the last solve moved u by {moves[-1]:.3g} ({moves[-1] / moves[0]:.2g} of the second), "
                 f"by a factor {factor:.2f} a solve over the last three: the solves in a geometry held within each "
                 "converge too slowly or not at all here; the monolithic solver linearises the geometry")
    return text


def _update_geometry(problem, target: float) -> SolveReport | None:
    """Re-evaluate the current contact geometry; a failed solve's report if an interface lost all its
    pairs or a slave node lies too deep behind its master (:class:`GeometryStepError`: load stepping
    then cuts the increment back, and names the interface if it gives up)."""
    try:
        problem.update_contact_geometry(target)
    except GeometryStepError as error:
        return SolveReport(converged=False, iterations=0, message=str(error))
    return None


def _moved_to_current_geometry(problem, solver, report: SolveReport, target: float, increment: int, cutbacks: int,
                               callbacks, last_converged: float | None) -> bool:
    """The slip check before a converged state is committed (collective): no state is committed in a
    contact geometry known to be stale (``docs/reliability.md``, "Which contact geometry").

    Reference-geometry interfaces whose surfaces slid past
    :data:`~dolfinx_nnqem.contact.slip_check.SLIP_LIMIT` × their facet size are moved to the current
    geometry where they can be (``geometry = "auto"``, node-to-surface, mortar or a rigid obstacle,
    degree 1, a solver that follows the geometry); True then: the caller solves the increment again.
    Where one cannot, the run stops here (:class:`ConvergenceError`, no cutback: a smaller increment
    slides as far the next time), naming the interface and why.
    """
    model = problem.contact
    if model is None:
        return False
    slips = model.geometry.slipped(problem.relative_displacement())
    if not slips:
        return False
    stale = []
    for slip in slips:
        why_not = model.geometry.why_not_current(slip.index)
        if why_not is None and not solver.follows_contact_geometry:
            why_not = (f"{solver.name} solves contact in the reference geometry only (use the monolithic solver or "
                       "NNEQM1 for large sliding)")
        if why_not is not None:
            stale.append(stale_message(slip, target, why_not))
    if stale:
        failure: dict[str, object] = {"increment": increment, "load_factor": float(target)}
        if last_converged is not None:
            failure["last_converged_load_factor"] = float(last_converged)
        failure.update({"cutbacks": cutbacks, "reason": "; ".join(stale), **failure_details(problem),
                        "stale_geometry": [slip.label for slip in slips]})
        problem.restore()
        message = "\n".join([f"{solver.name}: the increment to load factor {target:.6g} converged, but is not "
                             "committed: the contact geometry is stale"] + [f"  {line}" for line in stale])
        _give_up(message, failure, callbacks)
    for slip in slips:
        model.geometry.start_following(slip.index)
        message = switch_message(slip, target)
        problem.slip_warnings.append(message)
        logger.warning(f"[{solver.name}] {message}")
    return True


def _commit(problem, solver, report: SolveReport, values: GaussPointValues | None, target: float, *,
            index: int, cutbacks: int, verdict: StateCheck | None, t0: float, callbacks) -> IncrementResult:
    """Commit a converged increment with the Gauss-point ``values`` (the radial return's at u if None)
    and hand it to the callbacks (the writers)."""
    t_commit = time.perf_counter()
    problem.commit(values)
    result = IncrementResult(
        index=index, load_factor=float(target), report=report,
        plastic_points=problem.state.count_plastic_points(),
        wall_time_s=time.perf_counter() - t0, cutbacks=cutbacks,
        commit_time_s=time.perf_counter() - t_commit, check=verdict,
    )
    solves = f" ({report.geometry_passes} solves in the current contact geometry)" if report.geometry_passes > 1 else ""
    logger.info(f"[{solver.name}] increment {index}: load factor {target:.6g} converged in "
                f"{report.iterations} iterations{solves}, {result.plastic_points} plastic Gauss points")
    t_out = time.perf_counter()
    for callback in callbacks:
        callback(result)
    result.output_time_s = time.perf_counter() - t_out
    return result


def _fail(problem, solver, report: SolveReport, target: float, *, increment: int, cutbacks: int, callbacks,
          last_converged: float | None = None) -> None:
    """Restore the last converged state and raise ConvergenceError with the failure record."""
    failure: dict[str, object] = {"increment": increment, "load_factor": float(target)}
    if last_converged is not None:
        failure["last_converged_load_factor"] = float(last_converged)
    failure.update({"cutbacks": cutbacks, "reason": report.message, **failure_details(problem)})
    if _sliding_bodies(problem, report):
        failure["friction_held"] = list(problem.friction_held.motions)
    last = report.final
    if last is not None and last.plastic_points is None:  # not counted without the iteration log
        last.plastic_points = problem.state.count_trial_plastic_points(problem.u)  # the iterate the solver left
    problem.restore()
    _give_up(_failure_message(solver, float(target), report, cutbacks, problem), failure, callbacks)


def _give_up(message: str, failure: dict, callbacks) -> None:
    """Raise ConvergenceError with ``failure``, after handing it to the callbacks that take it."""
    error = ConvergenceError(message)
    error.failure = failure
    for callback in callbacks:
        if hasattr(callback, "failed"):
            callback.failed(failure)
    raise error


def _max_displacement(problem) -> float:
    n_owned = problem.V.dofmap.index_map.size_local * 3
    local = float(abs(problem.u.x.array[:n_owned]).max(initial=0.0))
    return problem.comm.allreduce(local, op=MPI.MAX)


def _failure_message(solver, target: float, report: SolveReport, cutbacks: int, problem=None) -> str:
    last = report.final
    lines = [f"{solver.name}: the increment to load factor {target:.6g} did not converge after "
             f"{cutbacks} cutbacks: {report.message}"]
    if last is not None:
        lines.append(f"  last iterate: |R|/F = {last.equilibrium:.3e}, |H|/F = {last.contact:.3e}, "
                     f"open/stick/slip = {last.states}, plastic Gauss points = {last.plastic_points}")
    if report.inner_states is not None:
        lines.append(f"  the failed inner contact solve's last iterate: open/stick/slip = {report.inner_states}")
    lines += _sliding_bodies(problem, report)
    lines += _stale_geometry(problem)
    return "\n".join(lines)


def _stale_geometry(problem) -> list[str]:
    """The likely cause when a reference-geometry interface slid past the slip limit at the failed
    iterate: its pairs no longer describe the surfaces (collective)."""
    model = getattr(problem, "contact", None)
    if model is None:
        return []
    return [f"  likely cause: {slip.describe()} at the last iterate: the pairs, normals and gaps found in the "
            "reference configuration no longer describe the surfaces"
            for slip in model.geometry.slipped(problem.relative_displacement())]


def _sliding_bodies(problem, report: SolveReport) -> list[str]:
    """The likely cause when the failed iterate slips and some rigid motion only friction holds:
    past the friction limit that body slides without resistance, and no equilibrium exists."""
    held = getattr(problem, "friction_held", None)
    if held is None or not held.motions or not _slipping(report):
        return []
    return (["  likely cause: friction alone holds "
             + ("this rigid motion" if len(held.motions) == 1 else "these rigid motions")
             + " (no support, no contact normal faces it):"]
            + [f"    - {motion}" for motion in held.motions]
            + ["  pairs slip at the last iterate: once the load along such a motion exceeds what friction can "
               "carry (mu_f times the contact pressure), the body slides freely and no equilibrium exists; "
               "add a support against that motion, or reduce the load along it"])


def _slipping(report: SolveReport) -> bool:
    """Pairs slip at the failed solve's last iterate: the outer one, or that of a failed nested
    contact solve (NNEQM1's, whose outer iterate keeps the states it started from)."""
    last = report.final
    inner = report.inner_states
    return (last is not None and last.states[2] > 0) or (inner is not None and inner[2] > 0)


def solve_load_path(problem: SolvableProblem, solver: Solver, load_factors: Sequence[float], *,
                    callbacks: Sequence[Callable[[IncrementResult], None]] = (),
                    check: CheckOptions | None = None) -> list[IncrementResult]:
    """Solve the increments ending at the given load factors, in order, without cutback.

    For an explicit load path (e.g. to repeat the path another run took after cutbacks, since
    friction makes the solution path dependent). Raises :class:`ConvergenceError` at the first
    increment that does not converge.
    """
    results: list[IncrementResult] = []
    for target in load_factors:
        t0 = time.perf_counter()
        report, verdict, values = _solve_and_check(problem, solver, target, check)
        while report.converged and _moved_to_current_geometry(problem, solver, report, target, len(results) + 1, 0,
                                                              callbacks, problem.load_factor_n):
            problem.restore()
            report, verdict, values = _solve_and_check(problem, solver, target, check)
        if not report.converged:
            _fail(problem, solver, report, target, increment=len(results) + 1, cutbacks=0, callbacks=callbacks)
        results.append(_commit(problem, solver, report, values, target, index=len(results) + 1, cutbacks=0,
                               verdict=verdict, t0=t0, callbacks=callbacks))
        values = None  # as in solve_load_steps
    return results
