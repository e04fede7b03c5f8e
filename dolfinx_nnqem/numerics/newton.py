r"""One globalised semismooth Newton driver for every nonsmooth system of the package.

``formulation.md`` §4: for H(x) = 0 with the merit Ψ(x) = ½|H(x)|² (rows scaled by the
backend so that they are comparable),

* a generalized Newton step J_k d = −H(x_k), J_k ∈ ∂_B H(x_k);
* Armijo backtracking on Ψ: Ψ(x + α d) ≤ Ψ(x) + σ α ∇Ψ·d, α = 1, ½, ¼, ... ≥ ``min_step``;
* Chamberlain's watchdog: a full step that increases Ψ (by at most ``max_increase``) is
  accepted, up to ``watchdog`` steps in a row without progress (Ψ below ``watchdog_progress``
  times its value at the last progress); then the iteration returns to the best iterate (the
  lowest Ψ) and takes one line-searched step from there. After ``watchdog_restarts`` such
  returns the rest of the solve is monotone. A change of pair state makes Ψ jump (an open
  pair's trial penetration enters H as r·g) although the full step is the one semismooth
  Newton needs; but full steps can also cycle between pair states (stick ↔ slip) with Ψ
  creeping down by a fraction of a percent per cycle, which a watchdog that counted every
  decrease as progress would follow to the iteration limit;
* Levenberg–Marquardt (JᵀJ + ν I) d = −JᵀH when there is no Newton direction (a singular J,
  a failed linear solve) or it fails the line search; if the LM direction fails the line search
  too, Ψ is (numerically) stationary and the driver stops and says so;
* optionally, a stall test: when the lowest Ψ reached has not fallen below ``stall_progress``
  times its value ``stall_window`` iterations earlier, the driver stops and says so. A system
  with no solution near the start (a local minimum of Ψ with Ψ > 0, where damped steps crawl
  along a plateau and watchdog steps cycle) otherwise runs to the iteration limit before the
  caller can try something else;
* when it stops without converging, the backend is asked whether round-off explains it (a
  tolerance below the residual's round-off floor, :mod:`dolfinx_nnqem.numerics.roundoff`): the
  message then says so, with the tolerance that can be reached, instead of blaming the merit
  function.

The driver makes every one of these decisions; what a system *is* lives in a backend
(:class:`NewtonSystem`): the dense arrays of NNEQM1's and NNEQM2's contact systems
(:class:`dolfinx_nnqem.numerics.nonsmooth.DenseSystem`), the PETSc block system of the monolithic solver,
or NNEQM1's outer Newton–Raphson iteration, whose step is a whole condensed contact solve and
which takes full steps (``Globalisation(line_search=False, levenberg_marquardt=False)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

__all__ = ["Globalisation", "Merit", "NewtonResult", "NewtonSystem", "solve"]


@dataclass(frozen=True)
class Globalisation:
    """How the driver damps and safeguards the Newton steps.

    Attributes
    ----------
    line_search
        Armijo backtracking (and the watchdog); False: every step is taken in full.
    levenberg_marquardt
        Fall back to an LM step when the Newton direction is missing or fails the line search.
    armijo
        Sufficient-decrease constant σ in (0, ½).
    min_step
        Smallest step length tried by the backtracking.
    watchdog
        Full steps accepted in a row without a new best Ψ (0: a monotone method).
    max_increase
        The watchdog accepts a full step only if Ψ grows by at most this factor.
    watchdog_progress
        Progress, for the watchdog, is Ψ below this fraction of its value at the last progress;
        None: 1 − 2·armijo, any sufficient decrease (Chamberlain's rule).
    watchdog_restarts
        Returns to the best iterate after which the solve continues with monotone steps only;
        None: no limit.
    lm_c, lm_delta
        The LM parameter ν = lm_c · (residual size)^lm_delta, in the backend's units (see the
        backends); lm_delta in [1, 2] keeps LM locally superlinear.
    stall_window, stall_progress
        Stop as stalled when the lowest Ψ reached is above ``stall_progress`` times the lowest
        Ψ reached ``stall_window`` iterations earlier; None: no stall test. The default
        fraction, 0.81 of Ψ, asks |H| to fall by a tenth in the window. Stricter fractions cut
        damped attempts that crawl (a few per cent a step) before they find the right pair
        states and converge quadratically.
    stagnation
        The watchdog takes a full step that fails the Armijo test only if it changes Ψ by more
        than this fraction (a pair changing state makes Ψ jump); a full step that leaves Ψ
        where it was (a two-point cycle: one pair between stick and slip, the rest converged)
        is backtracked like any other. None: every full step within ``max_increase``.
    """

    line_search: bool = True
    levenberg_marquardt: bool = True
    armijo: float = 1e-4
    min_step: float = 1.0 / 64
    watchdog: int = 6
    max_increase: float = 1e8
    watchdog_progress: float | None = None
    watchdog_restarts: int | None = None
    lm_c: float = 1.0
    lm_delta: float = 1.0
    stall_window: int | None = None
    stall_progress: float = 0.81
    stagnation: float | None = None

    def __post_init__(self):
        if not 0.0 < self.armijo < 0.5:
            raise ValueError(f"armijo must be in (0, 1/2), got {self.armijo!r}")
        if not 0.0 < self.min_step < 1.0:
            raise ValueError(f"min_step must be in (0, 1), got {self.min_step!r}")
        if not (isinstance(self.watchdog, int) and self.watchdog >= 0):
            raise ValueError(f"watchdog must be an integer >= 0, got {self.watchdog!r}")
        if not (math.isfinite(self.max_increase) and self.max_increase >= 1.0):
            raise ValueError(f"max_increase must be finite and >= 1, got {self.max_increase!r}")
        if self.watchdog_progress is not None and not 0.0 < self.watchdog_progress < 1.0:
            raise ValueError(f"watchdog_progress must be in (0, 1) or None, got {self.watchdog_progress!r}")
        if self.watchdog_restarts is not None and not (isinstance(self.watchdog_restarts, int)
                                                       and self.watchdog_restarts >= 1):
            raise ValueError(f"watchdog_restarts must be an integer >= 1 or None, got {self.watchdog_restarts!r}")
        if not (math.isfinite(self.lm_c) and self.lm_c > 0.0):
            raise ValueError(f"lm_c must be finite and > 0, got lm_c = {self.lm_c!r}")
        if not 1.0 <= self.lm_delta <= 2.0:
            raise ValueError(f"lm_delta must be in [1, 2], got {self.lm_delta!r}")
        if self.stall_window is not None and not (isinstance(self.stall_window, int) and self.stall_window >= 1):
            raise ValueError(f"stall_window must be an integer >= 1 or None, got {self.stall_window!r}")
        if not 0.0 < self.stall_progress < 1.0:
            raise ValueError(f"stall_progress must be in (0, 1), got {self.stall_progress!r}")
        if self.stagnation is not None and not 0.0 < self.stagnation < 1.0:
            raise ValueError(f"stagnation must be in (0, 1) or None, got {self.stagnation!r}")


@dataclass(frozen=True)
class Merit:
    """The merit of an iterate, as the backend measures it.

    Attributes
    ----------
    psi
        Ψ = ½|H|² (scaled rows).
    converged
        The backend's convergence test holds at this iterate.
    """

    psi: float
    converged: bool

    @property
    def finite(self) -> bool:
        """Ψ is finite (no overflow in the residual)."""
        return math.isfinite(self.psi)


class NewtonSystem(Protocol):
    """What the driver needs from a system H(x) = 0 (a backend).

    The backend keeps the iterate x and the evaluation at it. ``start_step`` freezes the
    current iterate as the start x_0 of a step; directions are computed at x_0; ``move(α)``
    sets x = x_0 + α d and evaluates there.
    """

    def evaluate(self) -> Merit:
        """Evaluate at the current iterate."""

    def record(self, iteration: int, step_length: float, kind: str) -> None:
        """Log the current iterate (``kind``: "", "newton", "full", "lm", or the backend's own)."""

    def snapshot(self) -> object:
        """Something :meth:`restore` can return to (the current iterate and its evaluation)."""

    def restore(self, snapshot: object) -> Merit:
        """Return to a snapshot; its merit."""

    def start_step(self) -> None:
        """The current iterate becomes the start x_0 of the next step."""

    def newton_direction(self, merit: Merit) -> str | None:
        """Compute d with J(x_0) d = −H(x_0); None on success, else why there is none."""

    def lm_direction(self, merit: Merit, globalisation: Globalisation) -> str | None:
        """Compute the LM direction at x_0; None on success, else why there is none."""

    def slope(self) -> float:
        """∇Ψ(x_0) · d for the current direction."""

    def move(self, step_length: float) -> Merit:
        """x = x_0 + step_length · d, evaluated."""

    def roundoff_note(self) -> str | None:
        """Why the residual cannot fall further at the current iterate when round-off sets its
        floor there (:func:`dolfinx_nnqem.numerics.roundoff.floor_note`), else None. Asked only when
        the iteration stops without converging; the failure message then gives it instead of "a
        local minimum, a plateau or a cycle of the merit function"."""


@dataclass
class NewtonResult:
    """Outcome of :func:`solve`.

    Attributes
    ----------
    converged
        The backend's convergence test held at the last iterate.
    iterations
        Steps taken.
    newton_steps, lm_steps
        Accepted Newton (full or damped) and Levenberg–Marquardt steps.
    line_search_steps
        Step-length reductions (rejected trial steps) over all steps.
    watchdog_restarts
        Returns to the best iterate.
    message
        What happened, in words (the reason when not converged).
    """

    converged: bool = False
    iterations: int = 0
    newton_steps: int = 0
    lm_steps: int = 0
    line_search_steps: int = 0
    watchdog_restarts: int = 0
    message: str = ""


def solve(system: NewtonSystem, globalisation: Globalisation, max_iterations: int, *,
          first_iteration: int = 0, first_kind: str = "", first_step_length: float = math.nan) -> NewtonResult:
    """Drive ``system`` to H = 0 from its current iterate.

    Parameters
    ----------
    system
        The backend.
    globalisation
        The damping rules.
    max_iterations
        The iteration number not to exceed (iterations are numbered from ``first_iteration``).
    first_iteration, first_kind, first_step_length
        How the starting iterate is recorded (a predictor step the caller already took counts
        as iteration 1 of kind "lifted", say).

    Returns
    -------
    NewtonResult
        Failure (iteration limit, non-finite residual, stationary merit, no direction) is
        reported, not raised; exceptions of the backend pass through.
    """
    g = globalisation
    result = NewtonResult(iterations=first_iteration)
    merit = system.evaluate()
    step_length, kind = first_step_length, first_kind
    watchdog = _Watchdog.start(g)
    lowest: list[float] = []  # the lowest Ψ reached, after each iteration (the stall test)
    for iteration in range(first_iteration, max_iterations + 1):
        result.iterations = iteration
        system.record(iteration, step_length, kind)
        if _finished(merit, iteration, result):
            return result
        if iteration == max_iterations:
            break
        lowest.append(min(merit.psi, lowest[-1]) if lowest else merit.psi)
        if _stalled(lowest, g):
            result.message = _stall_message(system, g, iteration)
            return result
        if g.line_search and watchdog.steps > 0:
            merit = watchdog.check(system, merit, result)
        step = _next_step(system, merit, g, watchdog.allows_increase(), iteration, result)
        if step is None:  # no step: result.message says why
            return result
        step_length, merit, kind = step
        watchdog.nonmonotone += 1
    note = system.roundoff_note()
    result.message = f"no convergence in {max_iterations} iterations" + ("" if note is None else f" ({note})")
    return result


def _finished(merit: Merit, iteration: int, result: NewtonResult) -> bool:
    """Whether the iterate ends the solve: Ψ is not finite (a failure) or the backend's
    convergence test holds; ``result`` then says so."""
    if not merit.finite:
        result.message = f"the residual is not finite (NaN/inf) at iteration {iteration}"
        return True
    if merit.converged:
        result.converged = True
        result.message = f"converged in {iteration} iterations"
        return True
    return False


def _stall_message(system: NewtonSystem, g: Globalisation, iteration: int) -> str:
    """Why the solve stops when :func:`_stalled` holds at ``iteration``."""
    why = _why_stuck(system, "a local minimum, a plateau or a cycle of the merit function")
    return (f"stopped at iteration {iteration}: stalled, the lowest |H| fell by less than "
            f"{1.0 - math.sqrt(g.stall_progress):.0%} in the last {g.stall_window} iterations "
            f"({why})")


@dataclass
class _Watchdog:
    """Chamberlain's watchdog over the iterates of one solve (see :class:`Globalisation`).

    Attributes
    ----------
    steps
        Full steps accepted in a row without progress before a return to the best iterate;
        0 once the watchdog has returned ``watchdog_restarts`` times (monotone steps only).
    restarts
        ``Globalisation.watchdog_restarts``.
    progress
        Progress is Ψ below this fraction of ``progress_psi``.
    track_lowest
        The best iterate is the lowest Ψ (progress measured by its own fraction), not the last
        progress (Chamberlain).
    best
        The best iterate's merit and snapshot; None before the first iterate is checked.
    progress_psi
        Ψ at the last progress.
    nonmonotone
        Steps taken since the last progress; −1 right after a return to the best iterate, so
        that the next step is line-searched.
    """

    steps: int
    restarts: int | None
    progress: float
    track_lowest: bool
    best: tuple[Merit, object] | None = None
    progress_psi: float = math.inf
    nonmonotone: int = 0

    @classmethod
    def start(cls, g: Globalisation) -> _Watchdog:
        """The watchdog of a new solve."""
        progress = 1.0 - 2.0 * g.armijo if g.watchdog_progress is None else g.watchdog_progress
        return cls(steps=g.watchdog, restarts=g.watchdog_restarts, progress=progress,
                   track_lowest=g.watchdog_progress is not None)

    def allows_increase(self) -> bool:
        """Whether the next step may be a full step that increases Ψ (not right after a return)."""
        return self.steps > 0 and self.nonmonotone >= 0

    def check(self, system: NewtonSystem, merit: Merit, result: NewtonResult) -> Merit:
        """Record progress at the current iterate, or, when the watchdog has run out, return to
        the best iterate; the merit of the iterate the next step starts from."""
        if self.best is None or merit.psi < self.progress * self.progress_psi:
            self.best, self.progress_psi, self.nonmonotone = (merit, system.snapshot()), merit.psi, 0
            return merit
        if self.track_lowest and merit.psi < self.best[0].psi:
            self.best = (merit, system.snapshot())
        if self.nonmonotone >= self.steps:  # the watchdog ran out: a monotone step from the best
            # (with track_lowest, the current iterate may be the best one already: no return)
            if not self.track_lowest or self.best[0].psi < merit.psi:
                merit = system.restore(self.best[1])
            self.progress_psi, self.nonmonotone = self.best[0].psi, -1
            result.watchdog_restarts += 1
            if self.restarts is not None and result.watchdog_restarts >= self.restarts:
                self.steps = 0
        return merit


def _next_step(system: NewtonSystem, merit: Merit, g: Globalisation, allow_increase: bool, iteration: int,
               result: NewtonResult) -> tuple[float, Merit, str] | None:
    """The step from the current iterate: (α, merit at the new iterate, kind), the Newton step
    if it passes the line search, else the Levenberg–Marquardt step; counted in ``result``.
    None when there is none (``result.message`` says why)."""
    system.start_step()
    why_not = system.newton_direction(merit)
    if why_not is None:
        step, rejected = _take_step(system, merit, g, allow_increase=allow_increase)
        result.line_search_steps += rejected
        if step is not None:
            result.newton_steps += 1
            return step[0], step[1], "newton" if step[2] else "full"  # "full": a watchdog step without decrease
        why_not = "the Newton direction failed the line search"
    if not g.levenberg_marquardt:
        result.message = f"stopped at iteration {iteration + 1}: {why_not}"
        return None
    return _lm_step(system, merit, g, why_not, iteration, result)


def _lm_step(system: NewtonSystem, merit: Merit, g: Globalisation, why_not: str, iteration: int,
             result: NewtonResult) -> tuple[float, Merit, str] | None:
    """The Levenberg–Marquardt step, taken because of ``why_not`` (no Newton step), always
    line-searched; None when there is none (``result.message`` says why)."""
    why_lm = system.lm_direction(merit, g)
    if why_lm is not None:
        result.message = f"stopped at iteration {iteration + 1}: {why_not}, and {why_lm}"
        return None
    step, rejected = _take_step(system, merit, g, allow_increase=False)
    result.line_search_steps += rejected
    if step is None:
        why = _why_stuck(system, "a local minimum or a kink of the merit function")
        result.message = (f"stopped at iteration {iteration + 1}: {why_not}, and the Levenberg–Marquardt "
                          f"direction failed it down to step length {g.min_step:.1e} ({why})")
        return None
    result.lm_steps += 1
    return step[0], step[1], "lm"


def _why_stuck(system: NewtonSystem, otherwise: str) -> str:
    """Why the iteration stopped short: round-off, where the backend finds that it sets the
    residual's floor at the current iterate, ``otherwise`` the shape of the merit function."""
    note = system.roundoff_note()
    return otherwise if note is None else note


def _stalled(lowest: list[float], g: Globalisation) -> bool:
    """The stall test on the lowest Ψ after each iteration (see :class:`Globalisation`)."""
    w = g.stall_window
    return w is not None and len(lowest) > w and lowest[-1] > g.stall_progress * lowest[-1 - w]


def _take_step(system: NewtonSystem, merit: Merit, g: Globalisation,
               allow_increase: bool) -> tuple[tuple[float, Merit, bool] | None, int]:
    """The step along the current direction: (α, merit at x_0 + α d, sufficient decrease?) and
    the number of rejected trials; None when no step length down to ``min_step`` is acceptable.

    Without line search the full step is taken. With it, α = 1, ½, ... until Armijo holds; a
    full step that fails Armijo is still taken when ``allow_increase`` (the watchdog) and Ψ
    grows by at most ``max_increase``.
    """
    if not g.line_search:
        return (1.0, system.move(1.0), True), 0
    slope = system.slope()
    descent = slope < 0.0
    alpha, rejected = 1.0, 0
    while alpha >= g.min_step:
        if not descent and not (allow_increase and alpha == 1.0):
            return None, rejected
        trial = system.move(alpha)
        if trial.finite and descent and trial.psi <= merit.psi + g.armijo * alpha * slope:
            return (alpha, trial, True), rejected
        if allow_increase and alpha == 1.0 and trial.finite and trial.psi <= g.max_increase * merit.psi \
                and (g.stagnation is None or abs(trial.psi - merit.psi) > g.stagnation * merit.psi):
            return (alpha, trial, False), rejected
        alpha *= 0.5
        rejected += 1
    return None, rejected
