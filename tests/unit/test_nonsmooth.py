"""Tests of the dense nonsmooth Newton / Levenberg--Marquardt solver (formulation.md §4)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from dolfinx_nnqem.numerics.nonsmooth import NonsmoothResult, solve_nonsmooth


def _smooth_residual(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """H = (x0^2 + x1^2 - 5, x0 x1 - 2), roots (1, 2) and (2, 1)."""
    H = np.array([x[0] ** 2 + x[1] ** 2 - 5.0, x[0] * x[1] - 2.0])
    J = np.array([[2.0 * x[0], 2.0 * x[1]], [x[1], x[0]]])
    return H, J


def _convergence_orders(norms: list[float]) -> list[float]:
    """p_k = log(e_{k+1}/e_k) / log(e_k/e_{k-1}) from consecutive residual norms."""
    return [
        math.log(norms[k + 1] / norms[k]) / math.log(norms[k] / norms[k - 1])
        for k in range(1, len(norms) - 1)
    ]


def test_smooth_problem_converges_quadratically():
    kinds: list[str] = []
    result = solve_nonsmooth(
        _smooth_residual,
        np.array([1.3, 2.4]),
        tol=1e-14,
        log=lambda k, norm, t, kind: kinds.append(kind),
    )
    norms = result.residual_norms
    print("\n|H| per iteration:", " ".join(f"{v:.3e}" for v in norms))
    # orders from the iterates clearly above round-off (|H| > 1e-13)
    usable = [v for v in norms if v > 1e-13]
    orders = _convergence_orders(usable)
    print("observed orders p_k:", " ".join(f"{p:.3f}" for p in orders))
    assert result.converged, result.message
    np.testing.assert_allclose(result.x, [1.0, 2.0], rtol=0, atol=1e-14)
    assert result.lm_steps == 0 and result.line_search_steps == 0
    assert kinds == ["initial"] + ["newton"] * result.iterations
    assert len(norms) == result.iterations + 1
    assert len(orders) >= 2
    assert orders[-1] > 1.8, orders  # quadratic: p -> 2


def _lcp(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A random LCP with a symmetric positive definite (hence P-) matrix M."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    M = A @ A.T + 0.5 * np.eye(n)
    q = rng.normal(size=n) * 3.0
    return M, q


def _lcp_by_enumeration(M: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The unique solution of the P-matrix LCP by trying all 2^n active sets."""
    n = q.size
    for active in itertools.product((False, True), repeat=n):
        a = np.array(active)  # a_i: x_i > 0, (Mx + q)_i = 0
        x = np.zeros(n)
        if a.any():
            x[a] = np.linalg.solve(M[np.ix_(a, a)], -q[a])
        y = M @ x + q
        if (x >= -1e-12).all() and (y >= -1e-12).all():
            return x
    raise AssertionError("no solution found")


def test_piecewise_linear_complementarity_solved_exactly():
    M, q = _lcp(8, seed=4)

    def residual(x):
        y = M @ x + q
        take_x = x <= y  # min(a, b) with a = b takes a (formulation.md)
        H = np.where(take_x, x, y)
        J = np.where(take_x[:, None], np.eye(q.size), M)
        return H, J

    result = solve_nonsmooth(residual, np.ones(q.size), tol=1e-13 * np.linalg.norm(q))
    x_ref = _lcp_by_enumeration(M, q)
    y = M @ result.x + q
    print(
        f"\nLCP n = 8: {result.message}; |x - x_enum| = "
        f"{np.linalg.norm(result.x - x_ref):.2e}, x.y = {result.x @ y:.2e}, "
        f"min x = {result.x.min():.2e}, min y = {y.min():.2e}\n|H| per iteration: "
        + " ".join(f"{v:.2e}" for v in result.residual_norms)
    )
    assert result.converged, result.message
    assert 2 <= result.iterations <= 15  # the active set changes along the way
    # finite termination: once the active set is right, one Newton step solves it exactly
    assert result.residual_norms[-2] > 1e-3 * np.linalg.norm(q)
    np.testing.assert_allclose(result.x, x_ref, rtol=0, atol=1e-12 * np.abs(x_ref).max())
    # exact complementarity up to round-off
    assert np.abs(np.minimum(result.x, y)).max() <= 1e-13 * np.linalg.norm(q)


def test_levenberg_marquardt_fallback_when_jacobian_singular_at_x0():
    def residual(x):
        # J = [[1, 1], [2 x0, 4 x1]] is singular on x0 = 2 x1, e.g. at x0 = (2, 1)
        H = np.array([x[0] + x[1] - 3.0, x[0] ** 2 + 2.0 * x[1] ** 2 - 9.0])
        J = np.array([[1.0, 1.0], [2.0 * x[0], 4.0 * x[1]]])
        return H, J

    x0 = np.array([2.0, 1.0])
    assert np.linalg.matrix_rank(residual(x0)[1]) == 1
    steps: list[tuple[int, float, float, str]] = []
    result = solve_nonsmooth(
        residual, x0, tol=1e-13, log=lambda *entry: steps.append(entry)
    )
    print(f"\n{result.message}")
    for k, norm, t, kind in steps:
        print(f"  {k:2d} {kind:8s} t = {t:.3g} |H| = {norm:.3e}")
    assert result.converged, result.message
    assert steps[1][3] == "lm"
    assert result.lm_steps >= 1 and result.newton_steps >= 1
    assert np.abs(residual(result.x)[0]).max() <= 1e-13
    np.testing.assert_array_equal(x0, [2.0, 1.0])  # x0 not modified


def test_reports_max_iter_without_raising():
    result = solve_nonsmooth(_smooth_residual, np.array([3.0, 7.0]), tol=1e-14, max_iter=2)
    print(f"\n{result.message}")
    assert isinstance(result, NonsmoothResult)
    assert not result.converged
    assert result.iterations == 2 and len(result.residual_norms) == 3
    assert "max_iter = 2" in result.message


def test_reports_failure_when_there_is_no_root():
    def residual(x):  # H = x^2 + 1 > 0: Psi is minimal at x = 0 with |H| = 1
        return np.array([x[0] ** 2 + 1.0]), np.array([[2.0 * x[0]]])

    result = solve_nonsmooth(residual, np.array([0.5]), tol=1e-10, max_iter=200)
    print(f"\n{result.message}")
    assert not result.converged
    assert result.message.startswith(("stopped", "not converged"))
    assert result.residual_norms[-1] >= 1.0
    assert abs(result.x[0]) < 1e-3  # it did descend to the minimiser of Psi


def test_nan_residual_raises_floating_point_error_naming_the_iteration():
    def nan_at_start(x):
        return np.array([np.nan]), np.array([[1.0]])

    with pytest.raises(FloatingPointError, match="iteration 0"):
        solve_nonsmooth(nan_at_start, np.array([0.0]), tol=1e-10)

    def nan_beyond_two(x):  # root at 5, but H is NaN for x > 2: the first step hits it
        value = x[0] - 5.0 if x[0] <= 2.0 else np.nan
        return np.array([value]), np.array([[1.0]])

    with pytest.raises(FloatingPointError, match="iteration 1"):
        solve_nonsmooth(nan_beyond_two, np.array([0.0]), tol=1e-10)


def test_merit_scale_scales_the_reported_norms():
    def residual(x):  # one force-like row (1e6) and one length-like row
        H = np.array([1e6 * (x[0] - 1.0), x[1] - 2.0])
        return H, np.diag([1e6, 1.0])

    result = solve_nonsmooth(residual, np.zeros(2), tol=1e-12, merit_scale=[1e-6, 1.0])
    print(f"\n{result.message}; norms {result.residual_norms}")
    assert result.converged
    # D H(x0) = (1e-6 * -1e6, -2): |D H| = sqrt(5), not the unscaled 1e6
    assert result.residual_norms[0] == pytest.approx(math.sqrt(5.0), rel=1e-15)


@pytest.mark.parametrize(
    "options, name",
    [
        ({"tol": 0.0}, "tol"),
        ({"tol": 1e-8, "lm_delta": 3.0}, "lm_delta"),
        ({"tol": 1e-8, "armijo": 0.7}, "armijo"),
        ({"tol": 1e-8, "max_iter": -1}, "max_iter"),
        ({"tol": 1e-8, "merit_scale": [1.0, -1.0]}, "merit_scale"),
    ],
)
def test_invalid_options_raise(options, name):
    with pytest.raises(ValueError, match=name):
        solve_nonsmooth(_smooth_residual, np.array([1.3, 2.4]), **options)


def test_wrong_residual_shape_raises():
    with pytest.raises(ValueError, match="shape"):
        solve_nonsmooth(lambda x: (np.zeros(3), np.eye(3)), np.zeros(2), tol=1e-8)


def _arctan(x):
    """H(x) = arctan(x): full Newton steps from |x0| > 1.39 diverge, damped ones converge."""
    return np.arctan(x), np.diag(1.0 / (1.0 + x * x))


def test_solve_dense_retries_from_the_start_with_the_next_globalisation():
    from dolfinx_nnqem.numerics.newton import Globalisation
    from dolfinx_nnqem.numerics.nonsmooth import solve_dense

    full, monotone = Globalisation(min_step=1e-10, watchdog=6), Globalisation(min_step=1e-10, watchdog=0)
    x0 = np.array([3.0])
    alone = solve_dense(_arctan, x0, tol=1e-10, max_iter=6, globalisations=(full,))
    retried = solve_dense(_arctan, x0, tol=1e-10, max_iter=6, globalisations=(full, monotone))
    direct = solve_nonsmooth(_arctan, x0, tol=1e-10, max_iter=6, watchdog=0)
    print(f"\n  watchdog alone: {alone.message}\n  then monotone: {retried.message}")
    assert not alone.converged and "not converged" in alone.message
    assert retried.converged and abs(retried.x[0]) < 1e-10
    assert retried.iterations == alone.iterations + direct.iterations  # the retry starts again from x0
    assert len(retried.residual_norms) == len(alone.residual_norms) + len(direct.residual_norms)
    np.testing.assert_array_equal(retried.x, direct.x)
    # a first globalisation that converges is the only one run
    first = solve_dense(_arctan, x0, tol=1e-10, max_iter=6, globalisations=(monotone, full))
    assert first.converged and first.iterations == direct.iterations
    both_fail = solve_dense(_arctan, x0, tol=1e-10, max_iter=2, globalisations=(full, monotone))
    assert not both_fail.converged
    assert both_fail.message.startswith("watchdog 6: ") and "; then monotone: " in both_fail.message
    with pytest.raises(ValueError, match="at least one globalisation"):
        solve_dense(_arctan, x0, tol=1e-10, max_iter=6, globalisations=())


def test_solve_dense_falls_back_to_another_start_and_step_rule():
    """Every globalisation fails from x0; the fallback's start (inside the basin) and step rule
    are then tried with each in turn; a first attempt that converges leaves the fallback unused."""
    from dolfinx_nnqem.numerics.newton import Globalisation
    from dolfinx_nnqem.numerics.nonsmooth import Fallback, solve_dense

    full, monotone = Globalisation(min_step=1e-10, watchdog=6), Globalisation(min_step=1e-10, watchdog=0)
    x0 = np.array([3.0])
    calls = []

    def recorded(x, dx, alpha, chart):  # the plain step, recorded
        calls.append(alpha)
        return x + alpha * dx

    plain = solve_dense(_arctan, x0, tol=1e-10, max_iter=3, globalisations=(full, monotone))
    out = solve_dense(_arctan, x0, tol=1e-10, max_iter=6, globalisations=(full,),
                      fallback=Fallback("near", np.array([0.5]), recorded))
    print(f"\n  {out.message}")
    assert not plain.converged
    assert out.converged and abs(out.x[0]) < 1e-10 and calls
    assert out.message.startswith("watchdog 6 near after watchdog 6: not converged")
    calls.clear()
    unused = solve_dense(_arctan, x0, tol=1e-10, max_iter=6, globalisations=(monotone,),
                         fallback=Fallback("near", np.array([0.5]), recorded))
    assert unused.converged and not calls
    failed = solve_dense(_arctan, x0, tol=1e-10, max_iter=2, globalisations=(full, monotone),
                         fallback=Fallback("near", np.array([0.5]), recorded))
    assert not failed.converged and failed.message.count("; then ") == 3
    assert "; then watchdog 6 near: " in failed.message and "; then monotone near: " in failed.message



def test_solve_dense_tries_fallbacks_in_order_and_computes_a_lazy_start_only_when_needed():
    """A sequence of fallbacks: each is tried (with every globalisation) only after all the
    attempts before it failed; a start given as a function is computed once, when its attempt
    comes, and never if an earlier attempt converged."""
    from dolfinx_nnqem.numerics.newton import Globalisation
    from dolfinx_nnqem.numerics.nonsmooth import Fallback, solve_dense

    full, monotone = Globalisation(min_step=1e-10, watchdog=6), Globalisation(min_step=1e-10, watchdog=0)
    x0 = np.array([3.0])
    computed = []

    def lazy_start():
        computed.append(True)
        return np.array([0.5])

    ways = [Fallback("far", np.array([5.0]), None), Fallback("near", lazy_start, None)]
    out = solve_dense(_arctan, x0, tol=1e-10, max_iter=6, globalisations=(full,), fallback=ways)
    print(f"\n  {out.message}")
    assert out.converged and abs(out.x[0]) < 1e-10 and computed == [True]
    assert out.message.startswith("watchdog 6 near after watchdog 6: ") and "; watchdog 6 far: " in out.message
    computed.clear()
    early = solve_dense(_arctan, np.array([0.5]), tol=1e-10, max_iter=6, globalisations=(full,), fallback=ways)
    assert early.converged and not computed
    failed = solve_dense(_arctan, x0, tol=1e-10, max_iter=2, globalisations=(full, monotone),
                         fallback=[Fallback("far", np.array([5.0]), None), Fallback("farther", lambda: np.array([9.0]),
                                                                                     None)])
    assert not failed.converged and failed.message.count("; then ") == 5

class _CreepingCycle:
    """A Newton backend whose full steps cycle A → B → A' → ... with Ψ(A) creeping down by 0.1 %
    a cycle (Ψ(B) = 2); a damped step from A lands on the solution. The pattern of the monolithic
    solver on a gap closed with slip inside one increment (stick ↔ slip between two pair sets)."""

    def __init__(self):
        self.x, self._x0 = ("A", 0), None

    def _merit(self, x=None):
        from dolfinx_nnqem.numerics.newton import Merit

        kind, k = x or self.x
        psi = {"A": 0.999 ** k, "B": 2.0, "solution": 0.0}[kind]
        return Merit(psi, psi == 0.0)

    def evaluate(self):
        return self._merit()

    def record(self, iteration, step_length, kind):
        pass

    def snapshot(self):
        return self.x

    def restore(self, snapshot):
        self.x = snapshot
        return self._merit()

    def start_step(self):
        self._x0 = self.x

    def newton_direction(self, merit):
        return None

    def lm_direction(self, merit, globalisation):
        return "none here"

    def slope(self):
        return -2.0 * self._merit(self._x0).psi

    def roundoff_note(self):
        return None

    def move(self, step_length):
        kind, k = self._x0
        if step_length < 1.0:
            self.x = ("solution", 0)
        else:
            self.x = ("B", k) if kind == "A" else ("A", k + 1)
        return self._merit()


def test_watchdog_breaks_a_creeping_cycle_of_full_steps():
    """Chamberlain's rule counts every sufficient decrease as progress and follows the cycle to the
    iteration limit; with progress measured as halving Ψ the watchdog returns to the best iterate
    and its monotone step converges (the monolithic solver's default)."""
    from dolfinx_nnqem.numerics.newton import Globalisation, solve
    from dolfinx_nnqem.solvers import MonolithicOptions

    classic = solve(_CreepingCycle(), Globalisation(watchdog=6), 40)
    default = MonolithicOptions().globalisation
    broken = solve(_CreepingCycle(), default, 40)
    print(f"\n  Chamberlain's rule: {classic.message}; progress = halving Ψ: {broken.message}, "
          f"{broken.watchdog_restarts} return(s) to the best iterate")
    assert not classic.converged and classic.iterations == 40 and classic.watchdog_restarts == 0
    assert broken.converged and broken.watchdog_restarts == 1 and broken.iterations <= default.watchdog + 2


def _no_root(x):
    """H = x² + 1 > 0: Ψ is least at x = 0, |H| = 1; full Newton steps x ← (x − 1/x)/2 are chaotic."""
    return np.array([x[0] ** 2 + 1.0]), np.array([[2.0 * x[0]]])


def test_stall_test_stops_an_attempt_that_cannot_converge():
    """Without a root the watchdog's full steps wander to the iteration limit; with the stall test
    the attempt stops once the lowest |H| has not fallen by a tenth in ``stall_window`` iterations
    and says so, so that the caller's next attempt starts early."""
    from dolfinx_nnqem.numerics.newton import Globalisation
    from dolfinx_nnqem.numerics.nonsmooth import solve_dense

    x0 = np.array([0.3])
    wander = solve_dense(_no_root, x0, tol=1e-10, max_iter=100, globalisations=(Globalisation(watchdog=6),))
    stall = solve_dense(_no_root, x0, tol=1e-10, max_iter=100,
                        globalisations=(Globalisation(watchdog=6, stall_window=10),))
    print(f"\n  without the stall test: {wander.message}\n  with it: {stall.message}")
    assert not wander.converged and wander.iterations == 100
    assert not stall.converged and "stalled" in stall.message and "10 iterations" in stall.message
    assert stall.iterations < 30
    assert min(stall.residual_norms) >= 1.0  # nothing was given up: |H| >= 1 everywhere


@pytest.mark.parametrize("residual, x0", [(_smooth_residual, [3.0, 7.0]), (_arctan, [1.2]),
                                          (lambda x: (x ** 3, np.diag(3.0 * x ** 2)), [1.0])])
def test_stall_test_leaves_converging_solves_alone(residual, x0):
    """A solve that converges, however slowly (H = x³: |H| falls by 8/27 a step), takes the
    same iterates with and without the stall test."""
    from dolfinx_nnqem.numerics.newton import Globalisation
    from dolfinx_nnqem.numerics.nonsmooth import solve_dense

    plain, tested = (solve_dense(residual, np.array(x0), tol=1e-12, max_iter=100,
                                 globalisations=(Globalisation(min_step=1e-10, watchdog=0, stall_window=w),))
                     for w in (None, 3))
    print(f"\n  {tested.message}")
    assert plain.converged and tested.converged
    assert tested.iterations == plain.iterations
    np.testing.assert_array_equal(tested.x, plain.x)


@pytest.mark.parametrize("options, name", [({"watchdog_progress": 1.0}, "watchdog_progress"),
                                           ({"watchdog_progress": 0.0}, "watchdog_progress"),
                                           ({"watchdog_restarts": 0}, "watchdog_restarts"),
                                           ({"stall_window": 0}, "stall_window"),
                                           ({"stall_progress": 1.0}, "stall_progress")])
def test_invalid_watchdog_options_raise(options, name):
    from dolfinx_nnqem.numerics.newton import Globalisation

    with pytest.raises(ValueError, match=name):
        Globalisation(**options)
