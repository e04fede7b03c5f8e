r"""Dense nonsmooth systems H(x) = 0: the dense backend of the Newton driver.

For systems of order up to a few thousand (the contact systems of NNEQM1 and NNEQM2), given as
a function ``residual(x) -> (H, J)`` with a dense J in the B-subdifferential of H. The
globalisation (Armijo, watchdog, Levenberg–Marquardt fallback) is the driver's,
:func:`dolfinx_nnqem.numerics.newton.solve`; this module supplies the linear algebra:

* Newton direction: J d = −H by LU; a singular or ill-conditioned J (LU pivots, LAPACK's
  condition estimate below ``rcond_min``) has no direction and LM takes over;
* LM direction: (AᵀA + ν I) d = −Aᵀ D H, A = D J, by Cholesky, with ν = lm_c |D H|^lm_delta;
* the slope ∇Ψ·d = (Aᵀ D H)·d of the chosen B-Jacobian.

D is the diagonal row scaling ``merit_scale`` (identity by default), so that rows of different
units (forces, displacements, stresses) are comparable. Every norm the solver uses or reports,
the merit Ψ = ½|D H|², the LM matrix and the tolerance refer to D H. The Newton direction itself
does not depend on D.

Ψ is only piecewise smooth for min/max/projection-type H (the contact laws); near a kink the
slope can be the wrong one-sided derivative, and Ψ can have local minima with H ≠ 0. The solver
then stops and says so in ``NonsmoothResult.message``; it never returns a wrong "solution".
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from dolfinx_nnqem.numerics.newton import Globalisation, Merit, solve
from dolfinx_nnqem.numerics.roundoff import dense_floor, floor_note

__all__ = ["DenseSystem", "Fallback", "NonsmoothResult", "solve_dense", "solve_nonsmooth"]

ResidualFunction = Callable[[np.ndarray], tuple]
"""``residual(x) -> (H, J)``: H (n,) and a dense J (n, n) in the B-subdifferential of H at x; with
an ``advance`` function, ``(H, J, chart)``: J is then taken in the step coordinates ``chart``
describes (e.g. the pair laws' :class:`~dolfinx_nnqem.contact.laws.Linearisation`)."""

AdvanceFunction = Callable[[np.ndarray, np.ndarray, float, object], np.ndarray]
"""``advance(x, dx, alpha, chart) -> x_new``: the point the step α dx from x reaches, dx in the step
coordinates ``chart`` (returned by the residual at x). Default: x + α dx."""

LogFunction = Callable[[int, float, float, str], None]
"""``log(iteration, norm_H, step_length, kind)``, kind in {"initial", "newton", "lm"}."""


@dataclass
class NonsmoothResult:
    """Outcome of :func:`solve_nonsmooth`.

    Attributes
    ----------
    x
        Last iterate (the solution if ``converged``).
    converged
        True when |D H(x)| <= tol.
    iterations
        Number of steps taken (Newton plus LM).
    residual_norms
        |D H| at every iterate, the initial one included (length ``iterations + 1``).
    newton_steps, lm_steps
        Accepted generalized Newton and Levenberg--Marquardt steps.
    line_search_steps
        Total number of step-length reductions (rejected trial steps), both kinds of step.
    message
        What happened, in words (the reason when not converged).
    """

    x: np.ndarray
    converged: bool
    iterations: int
    residual_norms: list[float] = field(default_factory=list)
    newton_steps: int = 0
    lm_steps: int = 0
    line_search_steps: int = 0
    message: str = ""


class DenseSystem:
    """A dense system H(x) = 0 as a :class:`~dolfinx_nnqem.numerics.newton.NewtonSystem`.

    Parameters
    ----------
    residual
        ``residual(x) -> (H, J)``.
    x0
        The starting point (copied).
    tol
        Converged when |D H| <= tol.
    scale
        The row scaling D, (n,).
    rcond_min
        J is treated as singular below this reciprocal condition number of D J.
    log
        Optional ``log(iteration, norm, step_length, kind)`` called for every recorded iterate.
    advance
        Optional ``advance(x, dx, alpha, chart)``: steps in other coordinates than x (the
        residual then returns ``(H, J, chart)``).
    """

    def __init__(self, residual: ResidualFunction, x0: np.ndarray, tol: float, scale: np.ndarray,
                 rcond_min: float, log: LogFunction | None = None, advance: AdvanceFunction | None = None):
        self.residual = residual
        self.advance = advance
        self.x = np.array(x0, dtype=np.float64, copy=True)
        self.tol, self.scale, self.rcond_min, self.log = tol, scale, rcond_min, log
        self.norms: list[float] = []
        self._iteration = 0  # the iterate being evaluated (errors name it)
        # The evaluation D H, D J (and chart) at x, the step's start and its direction: set by
        # evaluate(), start_step() and the directions, which the driver calls before any reads them
        self.F: np.ndarray
        self.A: np.ndarray
        self.chart: object = None
        self._x0: np.ndarray
        self._F0: np.ndarray
        self._A0: np.ndarray
        self._chart0: object = None
        self.dx: np.ndarray

    # -- evaluation ---------------------------------------------------------------------------
    def _evaluate_at(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """D H(x) and D J(x) (and the step chart in ``self.chart``); raise on NaN/inf or wrong shapes."""
        out = self.residual(x)
        H, J = out[0], out[1]
        self.chart = out[2] if len(out) > 2 else None
        H = np.asarray(H, dtype=np.float64)
        J = np.asarray(J, dtype=np.float64)
        n = x.size
        if H.shape != (n,):
            raise ValueError(f"residual returned H of shape {H.shape}, expected ({n},)")
        if J.shape != (n, n):
            raise ValueError(f"residual returned J of shape {J.shape}, expected ({n}, {n})")
        if not np.isfinite(H).all():
            raise FloatingPointError(f"H(x) is not finite at iteration {self._iteration} "
                                     f"({int(np.count_nonzero(~np.isfinite(H)))} NaN/inf entries)")
        if not np.isfinite(J).all():
            raise FloatingPointError(f"the Jacobian J(x) is not finite at iteration {self._iteration} "
                                     f"({int(np.count_nonzero(~np.isfinite(J)))} NaN/inf entries)")
        return self.scale * H, self.scale[:, None] * J

    def _merit(self) -> Merit:
        norm = float(np.linalg.norm(self.F))
        return Merit(0.5 * norm * norm, norm <= self.tol)

    def evaluate(self) -> Merit:
        self.F, self.A = self._evaluate_at(self.x)
        return self._merit()

    def record(self, iteration: int, step_length: float, kind: str) -> None:
        norm = float(np.linalg.norm(self.F))
        self.norms.append(norm)
        self._iteration = iteration + 1
        if self.log is not None:
            if iteration == 0 and not kind:
                self.log(0, norm, 0.0, "initial")
            else:
                self.log(iteration, norm, step_length, "lm" if kind == "lm" else "newton")

    def snapshot(self) -> tuple:
        return self.x, self.F, self.A, self.chart

    def restore(self, snapshot) -> Merit:
        self.x, self.F, self.A, self.chart = snapshot
        return self._merit()

    # -- steps ------------------------------------------------------------------------------------
    def start_step(self) -> None:
        self._x0, self._F0, self._A0, self._chart0 = self.x, self.F, self.A, self.chart

    def newton_direction(self, merit: Merit) -> str | None:
        """Solve A d = −F by LU; no direction when A is singular or too ill-conditioned."""
        import scipy.linalg  # by the dense methods only: a monolithic run does not pay its import (0.1 s)
        from scipy.linalg.lapack import dgecon

        A, F = self._A0, self._F0
        with warnings.catch_warnings():
            # lu_factor warns on an exactly zero pivot; the pivots are checked below instead.
            warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
            lu, piv = scipy.linalg.lu_factor(A, check_finite=False)
        if np.any(np.diag(lu) == 0.0):
            return "J singular or ill-conditioned"
        rcond, info = dgecon(lu, np.linalg.norm(A, 1), norm="1")
        if info != 0 or not rcond >= self.rcond_min:
            return "J singular or ill-conditioned"
        self.dx = scipy.linalg.lu_solve((lu, piv), -F, check_finite=False)
        return None

    def lm_direction(self, merit: Merit, globalisation: Globalisation) -> str | None:
        """Solve (AᵀA + ν I) d = −AᵀF by Cholesky, ν = lm_c |F|^lm_delta.

        If rounding makes the matrix numerically indefinite (ν tiny against |A|²), ν is raised
        tenfold until the factorisation succeeds: the direction then leans towards steepest
        descent, which is still a descent direction for Ψ.
        """
        import scipy.linalg  # as in newton_direction

        A, F = self._A0, self._F0
        gradient = A.T @ F
        if not np.any(gradient):
            return (f"the merit function is stationary (J^T H = 0) with |H| = {np.linalg.norm(F):.3e} "
                    f"> tol = {self.tol:.3e}")
        normal = A.T @ A
        size = max(float(np.abs(normal).max(initial=0.0)), 1.0)
        nu = max(globalisation.lm_c * float(np.linalg.norm(F)) ** globalisation.lm_delta, np.finfo(float).tiny)
        while True:
            try:
                factor = scipy.linalg.cho_factor(normal + nu * np.eye(normal.shape[0]), check_finite=False)
                self.dx = scipy.linalg.cho_solve(factor, -gradient, check_finite=False)
                return None
            except np.linalg.LinAlgError:
                if nu > 1e20 * size:  # cannot happen for finite A; guards an endless loop
                    raise
                nu *= 10.0

    def slope(self) -> float:
        return float((self._A0.T @ self._F0) @ self.dx)

    def move(self, step_length: float) -> Merit:
        if self.advance is None:
            self.x = self._x0 + step_length * self.dx
        else:
            self.x = self.advance(self._x0, self.dx, step_length, self._chart0)
        self.F, self.A = self._evaluate_at(self.x)
        return self._merit()

    def roundoff_note(self) -> str | None:
        """Round-off, when |D H| stopped at the floor that rounding x to double precision gives it
        (:func:`~dolfinx_nnqem.numerics.roundoff.dense_floor`; the caller's other inputs round too,
        so this floor is a lower estimate and round-off is named only where it suffices)."""
        return floor_note("|H|", float(np.linalg.norm(self.F)), dense_floor(self.A, self.x), self.tol,
                          name="tol")


def _check_positive(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be finite and > 0, got {name} = {value!r}")
    return value


def solve_nonsmooth(
    residual: ResidualFunction,
    x0: npt.ArrayLike,
    *,
    tol: float,
    max_iter: int = 50,
    merit_scale: float | npt.ArrayLike | None = None,
    lm_c: float = 1.0,
    lm_delta: float = 1.0,
    armijo: float = 1e-4,
    min_step: float = 1e-10,
    rcond_min: float = 1e-12,
    log: LogFunction | None = None,
    watchdog: int = 0,
    max_increase: float = 1e8,
    advance: AdvanceFunction | None = None,
) -> NonsmoothResult:
    """Solve H(x) = 0 by the globalised semismooth Newton driver on dense arrays.

    Parameters
    ----------
    residual
        ``residual(x) -> (H, J)`` with H (n,) and a dense J (n, n) in the B-subdifferential of
        H at x.
    x0
        Initial guess, shape (n,). Not modified.
    tol
        Converged when |D H(x)| <= tol (2-norm of the scaled residual).
    max_iter
        Maximum number of steps.
    merit_scale
        Row scaling D (scalar or (n,), positive), making rows of different units comparable
        in Ψ = 1/2 |D H|^2, in the LM matrix and in the tolerance. None: D = I.
    lm_c, lm_delta
        LM parameter ν = lm_c |D H|^lm_delta, lm_c > 0, lm_delta in [1, 2] (locally
        superlinear). ν is not scale-free: with ``merit_scale`` make D H and D J of order one.
    armijo
        Sufficient-decrease constant σ in (0, 1/2).
    min_step
        Smallest step length tried by the backtracking; below it the direction fails.
    rcond_min
        J is treated as singular (LM instead of Newton) when the LAPACK estimate of the
        reciprocal 1-norm condition number of D J is below this.
    log
        Optional ``log(iteration, norm_H, step_length, kind)``, called once for the initial
        iterate (kind "initial", step 0) and after every step (kind "newton" or "lm").
    watchdog, max_increase
        The driver's watchdog (:class:`~dolfinx_nnqem.numerics.newton.Globalisation`); 0 (the default)
        is the plain monotone method.
    advance
        ``advance(x, dx, alpha, chart)`` when steps are taken in other coordinates than x (see
        :data:`AdvanceFunction`); the residual then returns ``(H, J, chart)``.

    Returns
    -------
    NonsmoothResult
        Failure (max_iter reached, line search failed, stationary point of Ψ) is reported in
        ``converged``/``message``, not raised.

    Raises
    ------
    FloatingPointError
        If H (or J) is NaN/inf at an evaluated point; the message names the iteration.
    ValueError
        On invalid options or residual shapes.
    """
    globalisation = Globalisation(armijo=armijo, min_step=min_step, watchdog=int(watchdog),
                                  max_increase=max_increase, lm_c=_check_positive("lm_c", lm_c),
                                  lm_delta=lm_delta)
    return _solve_with(residual, x0, tol, max_iter, globalisation, merit_scale=merit_scale, rcond_min=rcond_min,
                       log=log, advance=advance)


def _solve_with(residual: ResidualFunction, x0: npt.ArrayLike, tol: float, max_iter: int,
                globalisation: Globalisation, *, merit_scale: float | npt.ArrayLike | None = None,
                rcond_min: float = 1e-12, log: LogFunction | None = None,
                advance: AdvanceFunction | None = None) -> NonsmoothResult:
    """:func:`solve_nonsmooth` with its damping given as a :class:`Globalisation`."""
    tol = _check_positive("tol", tol)
    if int(max_iter) != max_iter or max_iter < 0:
        raise ValueError(f"max_iter must be a non-negative integer, got {max_iter!r}")
    rcond_min = _check_positive("rcond_min", rcond_min)
    x0 = np.array(x0, dtype=np.float64, copy=True)
    if x0.ndim != 1:
        raise ValueError(f"x0 must be one-dimensional, got shape {x0.shape}")
    n = x0.size
    if merit_scale is None:
        scale = np.ones(n)
    else:
        scale = np.broadcast_to(np.asarray(merit_scale, dtype=np.float64), (n,)).copy()
        if not (np.isfinite(scale).all() and (scale > 0.0).all()):
            raise ValueError("merit_scale must be finite and > 0")

    system = DenseSystem(residual, x0, tol, scale, rcond_min, log, advance)
    outcome = solve(system, globalisation, int(max_iter))
    norm = system.norms[-1]
    result = NonsmoothResult(x=system.x, converged=outcome.converged, iterations=outcome.iterations,
                             residual_norms=system.norms, newton_steps=outcome.newton_steps,
                             lm_steps=outcome.lm_steps, line_search_steps=outcome.line_search_steps)
    if outcome.converged:
        result.message = (f"converged in {result.iterations} iterations ({result.newton_steps} Newton, "
                          f"{result.lm_steps} LM): |H| = {norm:.3e} <= tol = {tol:.3e}")
    elif outcome.message.startswith("stopped"):
        result.message = f"{outcome.message}; |H| = {norm:.3e} > tol = {tol:.3e}"
    else:
        result.message = f"not converged after max_iter = {max_iter} iterations: |H| = {norm:.3e} > tol = {tol:.3e}"
    return result


def _describe(globalisation: Globalisation) -> str:
    return "monotone" if globalisation.watchdog == 0 else f"watchdog {globalisation.watchdog}"


class Fallback(NamedTuple):
    """Another way through a dense system, tried with every globalisation when the ways before it
    failed: a start and a step rule (``label`` names it in messages). ``x0`` may be a function
    of no argument returning the start: it is then computed only if the attempt is made."""

    label: str
    x0: np.ndarray | Callable[[], np.ndarray]
    advance: AdvanceFunction | None


def solve_dense(residual: ResidualFunction, x0: npt.ArrayLike, *, tol: float, max_iter: int,
                globalisations: Sequence[Globalisation], advance: AdvanceFunction | None = None,
                log: LogFunction | None = None, fallback: Fallback | Sequence[Fallback] | None = None
                ) -> NonsmoothResult:
    """:func:`solve_nonsmooth` from ``x0`` with each globalisation in turn, until one converges.

    The contact systems of NNEQM1 and NNEQM2 meet two kinds of trouble that no single damping
    rule handles: full semismooth Newton steps can cycle between pair states (stick ↔ slip, Ψ
    alternating between two values: a monotone line search breaks the cycle, a watchdog lets it
    run), and Ψ can have narrow curved valleys and kinks (the polar law's angle) where monotone
    steps shrink to nothing while a few non-monotone full steps cross them. The first
    globalisation is tried; if it stops without converging, the next starts again from ``x0``.

    Parameters
    ----------
    residual, x0, tol, max_iter, advance
        As for :func:`solve_nonsmooth` (``max_iter`` per attempt).
    globalisations
        The damping rules, in the order they are tried (at least one).
    log
        As for :func:`solve_nonsmooth`; later attempts continue the iteration numbers.
    fallback
        If no globalisation converges from ``x0`` with ``advance``, each is tried again from
        ``fallback.x0`` with ``fallback.advance``; a sequence of fallbacks is tried in its order,
        each one only if every attempt before it failed.

    Returns
    -------
    NonsmoothResult
        The first converged attempt's result, or the last attempt's; ``iterations``,
        ``residual_norms`` and the step counts cover every attempt; a failure's message names
        each attempt and why it stopped.
    """
    if not globalisations:
        raise ValueError("solve_dense needs at least one globalisation")
    fallbacks = () if fallback is None else (fallback,) if isinstance(fallback, Fallback) else tuple(fallback)
    attempts: list[tuple[Globalisation, npt.ArrayLike | Fallback, AdvanceFunction | None, str]] = [
        (g, x0, advance, _describe(g)) for g in globalisations]
    for way in fallbacks:
        attempts += [(g, way, way.advance, f"{_describe(g)} {way.label}") for g in globalisations]
    starts: dict[int, np.ndarray] = {}  # each fallback's start, computed once, when first needed
    iterations, norms, counts, failures = 0, [], [0, 0, 0], []
    for g, start, step_rule, label in attempts:
        if isinstance(start, Fallback):
            if id(start) not in starts:
                starts[id(start)] = start.x0() if callable(start.x0) else start.x0
            start = starts[id(start)]
        offset = iterations
        attempt_log = None if log is None else (lambda k, norm, step, kind, o=offset: log(o + k, norm, step, kind))
        result = _solve_with(residual, start, tol, max_iter, g, log=attempt_log, advance=step_rule)
        iterations += result.iterations
        norms += result.residual_norms
        counts = [counts[0] + result.newton_steps, counts[1] + result.lm_steps,
                  counts[2] + result.line_search_steps]
        if result.converged:
            break
        failures.append(f"{label}: {result.message}")
    result.iterations, result.residual_norms = iterations, norms
    result.newton_steps, result.lm_steps, result.line_search_steps = counts
    if result.converged and failures:
        result.message = f"{label} after {'; '.join(failures)}: {result.message}"
    elif len(failures) > 1:
        result.message = "; then ".join(failures)
    return result
