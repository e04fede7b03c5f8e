"""The compiled per-point algebra of the logarithmic-strain route (``material/finite_strain/point_kernels.py``)
against numpy's batched forms: the Jacobi eigen-decomposition (also at repeated and nearly repeated
eigenvalues), the elastic trial state, the eigenvalues of a coaxial tensor and the exponential map."""

import numpy as np
import pytest

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
from dolfinx_nnqem.material.finite_strain.point_kernels import (coaxial_eigenvalues, elastic_trial, exponential_map,
                                                                 symmetric_eigen)


def _random_rotation(rng) -> np.ndarray:
    Q, R = np.linalg.qr(rng.standard_normal((3, 3)))
    return Q * np.sign(np.diag(R))


def _eigen_of(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lam, Q, work = np.empty(3), np.empty((3, 3)), np.empty((3, 3))
    symmetric_eigen(S, lam, Q, work)
    return lam, Q


@pytest.mark.parametrize("eigenvalues", [(0.3, 1.0, 2.5), (1.0, 1.0, 2.0), (2.0, 2.0, 2.0), (1.0, 1.0 + 1e-12, 1.0 + 3e-9),
                                         (1e-6, 1.0, 1e6), (-2.0, 0.0, 5.0)])
def test_symmetric_eigen_reproduces_the_tensor_and_numpys_eigenvalues(eigenvalues):
    rng = np.random.default_rng(3)
    for _ in range(20):
        R = _random_rotation(rng)
        S = R @ np.diag(eigenvalues) @ R.T
        lam, Q = _eigen_of(S)
        scale = np.abs(S).max()
        assert np.all(np.diff(lam) >= 0.0), "ascending, as numpy.linalg.eigh"
        assert np.abs(lam - np.linalg.eigvalsh(0.5 * (S + S.T))).max() <= 1e-14 * scale
        assert np.abs(Q.T @ Q - np.eye(3)).max() <= 1e-14, "orthonormal, also where eigenvalues repeat"
        assert np.abs(Q @ np.diag(lam) @ Q.T - 0.5 * (S + S.T)).max() <= 1e-14 * scale


def test_symmetric_eigen_of_a_diagonal_tensor_needs_no_rotation():
    lam, Q = _eigen_of(np.diag([3.0, 1.0, 2.0]))
    assert lam.tolist() == [1.0, 2.0, 3.0]
    assert np.array_equal(np.abs(Q), np.eye(3)[:, [1, 2, 0]])


def _random_deformations(rng, n: int) -> np.ndarray:
    F = np.eye(3) + 0.2 * rng.standard_normal((n, 3, 3))
    F[np.linalg.det(F) < 0, :, 0] *= -1.0
    return F


def test_elastic_trial_matches_the_numpy_formulas():
    rng = np.random.default_rng(7)
    n = 200
    F, F_n = _random_deformations(rng, n), _random_deformations(rng, n)
    A = _random_deformations(rng, n)
    b_n = A @ np.swapaxes(A, 1, 2)  # symmetric positive definite
    F_n_inv, f, left, Q, eps_tr = (np.empty((n, 3, 3)) for _ in range(5))
    lam = np.empty((n, 3))
    elastic_trial(F, F_n, b_n, F_n_inv, f, left, lam, Q, eps_tr)
    f_ref = F @ np.linalg.inv(F_n)
    b_tr = f_ref @ b_n @ np.swapaxes(f_ref, 1, 2)
    lam_ref, Q_ref = np.linalg.eigh(b_tr)
    eps_ref = (Q_ref * (0.5 * np.log(lam_ref))[:, None, :]) @ np.swapaxes(Q_ref, 1, 2)
    assert np.abs(f - f_ref).max() <= 1e-12 * np.abs(f_ref).max()
    assert np.abs(left - f_ref @ b_n).max() <= 1e-12 * np.abs(f_ref @ b_n).max()
    assert np.abs(lam - lam_ref).max() <= 1e-13 * lam_ref.max()
    assert np.abs(eps_tr - eps_ref).max() <= 1e-12


def test_elastic_trial_marks_a_state_that_is_not_positive_definite():
    F = np.eye(3)[None].copy()
    b_n = np.diag([1.0, -1.0, 1.0])[None].copy()
    out = [np.empty((1, 3, 3)) for _ in range(3)]
    lam, Q, eps_tr = np.empty((1, 3)), np.empty((1, 3, 3)), np.empty((1, 3, 3))
    elastic_trial(F, F.copy(), b_n, *out, lam, Q, eps_tr)
    assert lam.min() == -1.0 and np.isnan(eps_tr).any()


def test_exponential_map_matches_the_numpy_formulas():
    rng = np.random.default_rng(11)
    n = 100
    F = _random_deformations(rng, n)
    J = np.linalg.det(F)
    tau = rng.standard_normal((n, 3, 3))
    tau = tau + np.swapaxes(tau, 1, 2)
    Q_e = np.stack([_random_rotation(rng) for _ in range(n)])
    lam_e = 0.3 * rng.standard_normal((n, 3))
    b_e, F_inv, P, sigma = (np.empty((n, 3, 3)) for _ in range(4))
    exponential_map(F, J, tau, Q_e, lam_e, b_e, F_inv, P, sigma)
    b_ref = (Q_e * np.exp(2.0 * lam_e)[:, None, :]) @ np.swapaxes(Q_e, 1, 2)
    F_inv_ref = np.linalg.inv(F)
    assert np.abs(b_e - b_ref).max() <= 1e-13 * np.abs(b_ref).max()
    assert np.abs(F_inv - F_inv_ref).max() <= 1e-11 * np.abs(F_inv_ref).max()
    assert np.abs(P - tau @ np.swapaxes(F_inv_ref, 1, 2)).max() <= 1e-11 * np.abs(P).max()
    assert np.array_equal(sigma, tau / J[:, None, None])


def _half_log_series(X: np.ndarray) -> np.ndarray:
    """½ ln(I + X) by its series to the fourth power: exact to rounding where |X| ≤ 1e-5."""
    X2 = X @ X
    return 0.5 * (X - X2 / 2.0 + X2 @ X / 3.0 - X2 @ X2 / 4.0)


@pytest.mark.parametrize("size", [1e-5, 1e-7, 1e-9])
def test_elastic_trial_keeps_the_digits_of_a_small_strain(size):
    """Strains of 1e-5 to 1e-9 from F = I + H (H a multiple of 2⁻⁵², so F holds it exactly) after a
    converged state with a small elastic strain (b_e,n = I + β, β exact too): ε^tr to 1e-12 of its
    size. Formed as b_e^tr near I and decomposed, it kept about 1e-16 / size (1e-7 at 1e-9)."""
    rng = np.random.default_rng(5)
    n = 50
    unit = 2.0 ** -52  # the spacing of the doubles at 1
    H = np.round(size * rng.standard_normal((n, 3, 3)) / unit) * unit
    beta = np.round(size * rng.standard_normal((n, 3, 3)) / unit) * unit
    beta = beta + np.swapaxes(beta, 1, 2)
    F, F_n, b_n = np.eye(3) + H, np.broadcast_to(np.eye(3), (n, 3, 3)).copy(), np.eye(3) + beta
    assert np.array_equal(F - np.eye(3), H) and np.array_equal(b_n - np.eye(3), beta)
    F_n_inv, f, left, Q, eps_tr = (np.empty((n, 3, 3)) for _ in range(5))
    lam = np.empty((n, 3))
    elastic_trial(F, F_n, b_n, F_n_inv, f, left, lam, Q, eps_tr)
    X = H + np.swapaxes(H, 1, 2) + H @ np.swapaxes(H, 1, 2) + (np.eye(3) + H) @ beta @ (np.eye(3) + np.swapaxes(H, 1, 2))
    eps_ref = _half_log_series(X)
    assert np.abs(eps_tr - eps_ref).max() <= 1e-12 * np.abs(eps_ref).max()


def test_exponential_map_keeps_the_digits_of_a_small_strain():
    """The off-diagonal entries of b_e for an elastic strain of 1e-9, to 1e-11 of their size (formed as
    Σ exp(2λ) q ⊗ q they carried a few ulps of 1: 1e-7 of their size); its diagonal 1 + x holds one ulp."""
    rng = np.random.default_rng(13)
    n = 50
    Q_e = np.stack([_random_rotation(rng) for _ in range(n)])
    lam_e = 1e-9 * rng.standard_normal((n, 3))
    F = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    b_e, F_inv, P, sigma = (np.empty((n, 3, 3)) for _ in range(4))
    exponential_map(F, np.ones(n), np.zeros((n, 3, 3)), Q_e, lam_e, b_e, F_inv, P, sigma)
    X = (Q_e * np.expm1(2.0 * lam_e)[:, None, :]) @ np.swapaxes(Q_e, 1, 2)
    off = ~np.eye(3, dtype=bool)
    assert np.abs(b_e[:, off] - X[:, off]).max() <= 1e-11 * np.abs(X[:, off]).max()
    assert np.abs(b_e[:, ~off] - (1.0 + X[:, ~off])).max() <= 2.3e-16


def test_coaxial_eigenvalues_are_numpys_in_the_given_eigenvectors():
    """q_aᵀ A q_a (compiled) against numpy's batched form, and the eigenvalues themselves where Q are
    A's eigenvectors (also repeated ones), to a few ulps of |A|."""
    rng = np.random.default_rng(5)
    n = 40
    Q = np.stack([_random_rotation(rng) for _ in range(n)])
    values = rng.standard_normal((n, 3))
    values[:10, 1] = values[:10, 0]  # repeated eigenvalues
    A = (Q * values[:, None, :]) @ np.swapaxes(Q, 1, 2)
    A[20:] += 1e-3 * rng.standard_normal((n - 20, 3, 3))  # not coaxial: q_aᵀ A q_a all the same
    A = 0.5 * (A + np.swapaxes(A, 1, 2))
    lam = np.empty((n, 3))
    coaxial_eigenvalues(A, Q, lam)
    scale = np.abs(A).max(axis=(1, 2))[:, None]
    assert (np.abs(lam - np.sum(Q * (A @ Q), axis=1)) / scale).max() <= 4e-15
    assert (np.abs(lam - values) / scale)[:20].max() <= 4e-15
