"""Anderson mixing of a fixed-point iteration (NNEQM2's passes on the flow directions)."""

import numpy as np
import pytest

from dolfinx_nnqem.numerics.anderson import AndersonMixing


def _iterate(depth: int, G, x0: np.ndarray, tol: float = 1e-12, limit: int = 5000) -> tuple[np.ndarray, int]:
    mixing, x = AndersonMixing(depth), x0
    for k in range(1, limit + 1):
        g = G(x)
        if np.linalg.norm(g - x) <= tol:
            return g, k
        x = mixing.next(x, g)
    return x, limit


def test_anderson_mixing_converges_faster_to_the_same_fixed_point():
    """A linear contraction x ← A x + b with spectral radius 0.95 (plain iteration: hundreds of
    passes); Anderson of depth 5 reaches the same fixed point in fewer than half as many."""
    rng = np.random.default_rng(1)
    Q, _ = np.linalg.qr(rng.standard_normal((20, 20)))
    A = Q @ np.diag(np.linspace(-0.95, 0.95, 20)) @ Q.T
    b = rng.standard_normal(20)
    exact = np.linalg.solve(np.eye(20) - A, b)
    x_plain, n_plain = _iterate(0, lambda x: A @ x + b, np.zeros(20))
    x_aa, n_aa = _iterate(5, lambda x: A @ x + b, np.zeros(20))
    print(f"\n  passes to 1e-12: plain {n_plain}, Anderson(5) {n_aa}")
    assert np.allclose(x_plain, exact, atol=1e-10) and np.allclose(x_aa, exact, atol=1e-10)
    assert n_plain < 5000 and n_aa < n_plain / 2


def test_depth_zero_is_the_plain_iteration():
    mixing = AndersonMixing(0)
    x, g = np.array([1.0, 2.0]), np.array([0.5, 0.25])
    assert np.array_equal(mixing.next(x, g), g) and np.array_equal(mixing.next(g, x), x)
    with pytest.raises(ValueError, match="depth"):
        AndersonMixing(-1)
