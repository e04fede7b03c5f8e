r"""A small dense solver for nonsmooth equations H(x) = 0 (``formulation.md`` §4).

Damped generalized Newton with a Levenberg--Marquardt fallback, for dense systems of order up to
a few thousand (the contact systems of NNEQM1/NNEQM2):

* generalized Newton step J_k dx = -H(x_k), J_k in the B-subdifferential of H (LU
  factorisation; a singular or ill-conditioned J_k is detected from the LU pivots and the
  LAPACK condition estimate);
* Armijo backtracking (halving) on the merit function Psi(x) = 1/2 |D H(x)|^2;
* if J_k is singular or ill-conditioned, or the Newton direction fails the line search, a
  Levenberg--Marquardt step (A^T A + nu I) dx = -A^T D H, A = D J_k, nu = c |D H|^delta, again
  with Armijo backtracking on Psi.

D is the diagonal row scaling ``merit_scale`` (identity by default), used so that rows of
different units (forces, displacements, stresses) are comparable. Every norm the solver uses or
reports, the merit Psi, the LM matrix and the tolerance refer to the scaled residual D H. The
Newton direction itself does not depend on D.

Psi is only piecewise smooth for min/max/projection-type H (the contact laws), and the line search
uses the slope grad(Psi).dx = (D J)^T D H . dx of the chosen B-Jacobian. Near a kink that slope
can be the wrong one-sided derivative, and Psi can have local minima with H != 0 (for the contact
laws: folds of the law where friction jams a pair, or a badly chosen r). The solver then stops
and says so in ``NonsmoothResult.message``; it never returns a wrong "solution".
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import scipy.linalg
from scipy.linalg.lapack import dgecon

__all__ = ["NonsmoothResult", "solve_nonsmooth"]

ResidualFunction = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
"""``residual(x) -> (H, J)``: H (n,) and a dense J (n, n) in the B-subdifferential of H at x."""

LogFunction = Callable[[int, float, float, str], None]
"""``log(iteration, norm_H, step_length, kind)``, kind in {"initial", "newton", "lm"}."""

_BACKTRACK = 0.5
"""Factor of the step length at each Armijo rejection."""


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
        Total number of step-length reductions (rejected Armijo trials), both kinds of step.
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


def _evaluate(
    residual: ResidualFunction, x: np.ndarray, scale: np.ndarray, iteration: int
) -> tuple[np.ndarray, np.ndarray]:
    """Scaled residual D H(x) and scaled Jacobian D J(x); raise on NaN/inf or wrong shapes."""
    H, J = residual(x)
    H = np.asarray(H, dtype=np.float64)
    J = np.asarray(J, dtype=np.float64)
    n = x.size
    if H.shape != (n,):
        raise ValueError(f"residual returned H of shape {H.shape}, expected ({n},)")
    if J.shape != (n, n):
        raise ValueError(f"residual returned J of shape {J.shape}, expected ({n}, {n})")
    if not np.isfinite(H).all():
        raise FloatingPointError(
            f"H(x) is not finite at iteration {iteration} "
            f"({int(np.count_nonzero(~np.isfinite(H)))} NaN/inf entries)"
        )
    if not np.isfinite(J).all():
        raise FloatingPointError(
            f"the Jacobian J(x) is not finite at iteration {iteration} "
            f"({int(np.count_nonzero(~np.isfinite(J)))} NaN/inf entries)"
        )
    return scale * H, scale[:, None] * J


def _newton_direction(A: np.ndarray, F: np.ndarray, rcond_min: float) -> np.ndarray | None:
    """Solve A dx = -F by LU; None when A is singular or its reciprocal condition < rcond_min."""
    with warnings.catch_warnings():
        # lu_factor warns on an exactly zero pivot; the pivots are checked below instead.
        warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
        lu, piv = scipy.linalg.lu_factor(A, check_finite=False)
    if np.any(np.diag(lu) == 0.0):
        return None
    rcond, info = dgecon(lu, np.linalg.norm(A, 1), norm="1")
    if info != 0 or not rcond >= rcond_min:
        return None
    return scipy.linalg.lu_solve((lu, piv), -F, check_finite=False)


def _lm_direction(A: np.ndarray, gradient: np.ndarray, nu: float) -> np.ndarray:
    """Solve (A^T A + nu I) dx = -gradient by Cholesky (gradient = A^T D H).

    If rounding makes the matrix numerically indefinite (nu tiny against |A|^2), nu is raised
    tenfold until the factorisation succeeds: the direction then leans towards steepest descent,
    which is still a descent direction for Psi.
    """
    normal = A.T @ A
    size = max(float(np.abs(normal).max(initial=0.0)), 1.0)
    nu = max(nu, np.finfo(float).tiny)
    while True:
        try:
            factor = scipy.linalg.cho_factor(
                normal + nu * np.eye(normal.shape[0]), check_finite=False
            )
            return scipy.linalg.cho_solve(factor, -gradient, check_finite=False)
        except np.linalg.LinAlgError:
            if nu > 1e20 * size:  # cannot happen for finite A; guards an endless loop
                raise
            nu *= 10.0


def _line_search(
    residual: ResidualFunction,
    x: np.ndarray,
    F: np.ndarray,
    A: np.ndarray,
    dx: np.ndarray | None,
    scale: np.ndarray,
    iteration: int,
    armijo: float,
    min_step: float,
) -> tuple[tuple[float, np.ndarray, np.ndarray, np.ndarray] | None, int]:
    """Armijo backtracking on Psi = 1/2 |F|^2 from x along dx (F = D H(x), A = D J(x)).

    Returns ((t, x_new, F_new, A_new), rejections) for the first t in 1, 1/2, 1/4, ... with
    Psi(x + t dx) <= Psi(x) + armijo t grad(Psi).dx, or (None, rejections) when there is no
    direction, it is not a descent direction for the B-Jacobian's gradient A^T F, or t would
    fall below ``min_step``.
    """
    if dx is None:
        return None, 0
    slope = float((A.T @ F) @ dx)
    if not slope < 0.0:
        return None, 0
    psi = 0.5 * float(F @ F)
    t = 1.0
    rejections = 0
    while t >= min_step:
        x_new = x + t * dx
        F_new, A_new = _evaluate(residual, x_new, scale, iteration)
        if 0.5 * float(F_new @ F_new) <= psi + armijo * t * slope:
            return (t, x_new, F_new, A_new), rejections
        t *= _BACKTRACK
        rejections += 1
    return None, rejections


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
) -> NonsmoothResult:
    """Solve H(x) = 0 by damped generalized Newton with a Levenberg--Marquardt fallback.

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
        in Psi = 1/2 |D H|^2, in the LM matrix and in the tolerance. None: D = I.
    lm_c, lm_delta
        LM parameter nu = lm_c |D H|^lm_delta, lm_c > 0, lm_delta in [1, 2] (locally
        superlinear). nu is not scale-free: with ``merit_scale`` make D H and D J of order one.
    armijo
        Sufficient-decrease constant sigma in (0, 1/2):
        Psi(x + t dx) <= Psi(x) + sigma t grad(Psi).dx.
    min_step
        Smallest step length tried by the backtracking; below it the direction fails.
    rcond_min
        J is treated as singular (LM instead of Newton) when the LAPACK estimate of the
        reciprocal 1-norm condition number of D J is below this.
    log
        Optional ``log(iteration, norm_H, step_length, kind)``, called once for the initial
        iterate (kind "initial", step 0) and after every step (kind "newton" or "lm").
    watchdog
        Chamberlain's watchdog: up to this many full Newton steps in a row are accepted even
        when Psi does not decrease (each may grow Psi at most ``max_increase``-fold); after
        them, if no iterate improved on the best one, the iteration returns to the best
        iterate and continues with line-searched steps. A change of active branch (a pair
        opening or closing) makes Psi jump although the full step is the right one; 0 (the
        default) is the plain monotone method.

    Returns
    -------
    NonsmoothResult
        Failure (max_iter reached, line search failed, stationary point of Psi) is reported in
        ``converged``/``message``, not raised.

    Raises
    ------
    FloatingPointError
        If H (or J) is NaN/inf at an evaluated point; the message names the iteration.
    ValueError
        On invalid options or residual shapes.
    """
    tol = _check_positive("tol", tol)
    if int(max_iter) != max_iter or max_iter < 0:
        raise ValueError(f"max_iter must be a non-negative integer, got {max_iter!r}")
    max_iter = int(max_iter)
    lm_c = _check_positive("lm_c", lm_c)
    if not 1.0 <= lm_delta <= 2.0:
        raise ValueError(f"lm_delta must be in [1, 2], got {lm_delta!r}")
    if not 0.0 < armijo < 0.5:
        raise ValueError(f"armijo must be in (0, 1/2), got {armijo!r}")
    if not 0.0 < min_step < 1.0:
        raise ValueError(f"min_step must be in (0, 1), got {min_step!r}")
    rcond_min = _check_positive("rcond_min", rcond_min)

    x = np.array(x0, dtype=np.float64, copy=True)
    if x.ndim != 1:
        raise ValueError(f"x0 must be one-dimensional, got shape {x.shape}")
    n = x.size
    if merit_scale is None:
        scale = np.ones(n)
    else:
        scale = np.broadcast_to(np.asarray(merit_scale, dtype=np.float64), (n,)).copy()
        if not (np.isfinite(scale).all() and (scale > 0.0).all()):
            raise ValueError("merit_scale must be finite and > 0")

    F, A = _evaluate(residual, x, scale, 0)
    norm = float(np.linalg.norm(F))
    result = NonsmoothResult(x=x, converged=False, iterations=0, residual_norms=[norm])
    if log is not None:
        log(0, norm, 0.0, "initial")

    best = (norm, x, F, A)  # watchdog: best iterate so far
    free_steps = 0  # full steps accepted in a row without a new best
    for k in range(1, max_iter + 1):
        if norm <= tol:
            break
        if norm < (1.0 - armijo) * best[0]:
            best, free_steps = (norm, x, F, A), 0
        elif free_steps >= watchdog > 0:
            norm, x, F, A = best  # back to the best iterate; monotone steps from there
            free_steps = -1
        # 1. generalized Newton step, if J is regular enough
        dx = _newton_direction(A, F, rcond_min)
        step = None
        if dx is not None and watchdog > 0 and free_steps >= 0:
            x_full = x + dx
            F_full, A_full = _evaluate(residual, x_full, scale, k)
            if float(F_full @ F_full) <= max_increase * float(F @ F):
                step = (1.0, x_full, F_full, A_full)
                free_steps += 1
        if step is None:
            step, rejections = _line_search(residual, x, F, A, dx, scale, k, armijo, min_step)
            result.line_search_steps += rejections
            free_steps = max(free_steps, 0)
        kind = "newton"
        if step is None:
            # 2. Levenberg-Marquardt fallback
            if dx is None:
                newton_failure = "J singular or ill-conditioned"
            else:
                newton_failure = "the Newton direction failed the line search"
            kind = "lm"
            gradient = A.T @ F
            if not np.any(gradient):
                result.message = (
                    f"stopped at iteration {k}: {newton_failure} and the merit function is "
                    f"stationary (J^T H = 0) with |H| = {norm:.3e} > tol = {tol:.3e}"
                )
                return result
            dx = _lm_direction(A, gradient, lm_c * norm**lm_delta)
            step, rejections = _line_search(residual, x, F, A, dx, scale, k, armijo, min_step)
            result.line_search_steps += rejections
            if step is None:
                result.message = (
                    f"stopped at iteration {k}: the step became too small ({newton_failure}, "
                    f"and the LM direction failed it down to step length {min_step:.1e}: "
                    f"a local minimum or a kink of Psi); |H| = {norm:.3e} > tol = {tol:.3e}, "
                    f"|J^T H| = {float(np.linalg.norm(gradient)):.3e}"
                )
                return result

        t, x, F, A = step
        if kind == "newton":
            result.newton_steps += 1
        else:
            result.lm_steps += 1
        norm = float(np.linalg.norm(F))
        result.iterations = k
        result.residual_norms.append(norm)
        result.x = x
        if log is not None:
            log(k, norm, t, kind)

    result.x = x
    if norm <= tol:
        result.converged = True
        result.message = (
            f"converged in {result.iterations} iterations ({result.newton_steps} Newton, "
            f"{result.lm_steps} LM): |H| = {norm:.3e} <= tol = {tol:.3e}"
        )
    else:
        result.message = (
            f"not converged after max_iter = {max_iter} iterations: "
            f"|H| = {norm:.3e} > tol = {tol:.3e}"
        )
    return result
