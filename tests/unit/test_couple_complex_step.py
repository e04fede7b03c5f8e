"""Complex-step derivatives of the dual mortar couple integrals (issue 41) against high-order differences.

:func:`~dolfinx_nnqem.contact.couple_complex_step.couple_derivatives` (one complex evaluation of the
couple kernel per vertex coordinate) against sixth-order central differences of the exact function
— :func:`~dolfinx_nnqem.contact.mortar_geometry.couple_integrals` with the dual coefficients of the
moved slave facet — on couples with a partial overlap, a vertex of one facet inside the other,
tilted and warped facets, triangles, quadrilaterals and a triangle against a quadrilateral. The
central differences the linearisation took before (``couple_differences``, step 1e-6 × the facet
size) are measured against the same reference and printed next to them (``pytest -s``).
"""

import numpy as np
import pytest

from dolfinx_nnqem.contact.couple_complex_step import COMPLEX_STEP, couple_derivatives
from dolfinx_nnqem.contact.mortar_geometry import couple_integrals, dual_coefficients
from dolfinx_nnqem.contact.mortar_linearisation import DIFFERENCE_STEP, couple_differences

H = 1e-3  #: the sixth-order differences' step (no vertex comes within 3 H of the other facet's edges)


def _rotation(axis: int, degrees: float) -> np.ndarray:
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    i, j = [a for a in range(3) if a != axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _polygon(k: int, centre, size: float, turn: float) -> np.ndarray:
    """A square (k = 4) or triangle (k = 3) in the plane z = centre_z, counter-clockwise seen from +z."""
    angles = np.radians(turn) + 2 * np.pi * np.arange(k) / k
    return np.asarray(centre) + size * np.column_stack([np.cos(angles), np.sin(angles), np.zeros(k)])


def _master(points: np.ndarray) -> np.ndarray:
    """Master vertices counter-clockwise about the master's outward normal (−z: it faces the slave)."""
    return points[::-1].copy()


def _couples() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """(slave (ks, 3), master (km, 3)) couples, cyclic."""
    rng = np.random.default_rng(7)
    square = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    warped = square + 0.04 * rng.standard_normal((4, 3))
    tilt = _rotation(0, 20.0) @ _rotation(1, -12.0)
    tilt_m = _rotation(1, 9.0) @ tilt
    master_over_warped = square + [0.31, -0.27, 0.12] + 0.04 * rng.standard_normal((4, 3))
    triangle = _polygon(3, [0.0, 0.0, 0.0], 0.6, 5.0)
    return {
        "quads, partial overlap": (square.copy(), _master(square + [0.37, 0.21, 0.1])),
        "quads, master vertices inside the slave": (square.copy(),
                                                    _master(_polygon(4, [0.83, 0.71, 0.08], 0.45, 17.0))),
        "quads, slave inside the master": (_polygon(4, [0.5, 0.5, 0.0], 0.4, 9.0),
                                           _master(_polygon(4, [0.46, 0.53, 0.07], 0.9, 31.0))),
        "quads, tilted and warped": (warped @ tilt.T, _master(master_over_warped @ tilt_m.T)),
        "triangles, partial overlap": (triangle, _master(_polygon(3, [0.23, 0.17, 0.09], 0.55, 41.0))),
        "triangles, tilted, a vertex inside": (triangle @ tilt.T, _master(_polygon(3, [0.13, -0.08, 0.1], 0.4, 77.0)
                                                                          @ (_rotation(0, -7.0) @ tilt).T)),
        "triangle against a quadrilateral": (triangle + 0.02 * rng.standard_normal((3, 3)),
                                             _master(_polygon(4, [0.31, 0.12, 0.1], 0.5, 22.0))),
    }


def _integrals(x: np.ndarray, ks: int) -> np.ndarray:
    """(M, g̃) of the couple with vertices x (ks + km, 3), the dual coefficients of its slave facet at x."""
    xs, xm = x[:ks], x[ks:]
    M, g, _, area = couple_integrals(xs, dual_coefficients(xs[None])[0][0], xm)
    assert area > 0.0
    return np.concatenate([M.ravel(), g])


def _sixth_order(x: np.ndarray, ks: int) -> np.ndarray:
    """(outputs, P) sixth-order central differences of :func:`_integrals` (error ~ H⁶ + 1e-16 / H)."""
    columns = []
    for p in range(x.size):
        e = np.zeros(x.size)
        e[p] = H
        f = {j: _integrals(x + j * e.reshape(x.shape), ks) for j in (-3, -2, -1, 1, 2, 3)}
        columns.append((45 * (f[1] - f[-1]) - 9 * (f[2] - f[-2]) + (f[3] - f[-3])) / (60 * H))
    return np.stack(columns, axis=-1)


def _as_rows(dM: np.ndarray, dg: np.ndarray) -> np.ndarray:
    """(outputs, P) of one couple's (dM (ks, km, P), dg (ks, P))."""
    return np.concatenate([dM.reshape(-1, dM.shape[-1]), dg])


@pytest.mark.parametrize("name", list(_couples()))
def test_complex_step_couple_derivatives_match_sixth_order_differences(name):
    xs, xm = _couples()[name]
    ks = len(xs)
    x = np.vstack([xs, xm])
    reference = _sixth_order(x, ks)
    one = np.zeros(1, dtype=np.int64)
    size = 1.0  # the facets' size: the steps are relative to it
    exact = _as_rows(*(d[0] for d in couple_derivatives(xs[None], xm[None], one, one, COMPLEX_STEP * size)))
    central = _as_rows(*(d[0] for d in couple_differences(xs[None], xm[None], one, one, DIFFERENCE_STEP * size)))
    scale = np.abs(reference).max()
    error, before = np.abs(exact - reference).max() / scale, np.abs(central - reference).max() / scale
    print(f"\n  {name}: |d − FD6|/|FD6| complex step {error:.1e}, central differences (before) {before:.1e}")
    assert scale > 1e-2  # the integrals do move
    assert error <= 1e-9


def test_a_real_evaluation_in_complex_arithmetic_is_the_real_one():
    """The complex specialisation of the couple kernel with a zero imaginary part: the real integrals
    (to round-off) and no imaginary part."""
    for xs, xm in _couples().values():
        A = dual_coefficients(xs[None])[0][0]
        real = couple_integrals(xs, A, xm)
        as_complex = couple_integrals(xs.astype(complex), A.astype(complex), xm.astype(complex))
        for r, c in zip(real[:3], as_complex[:3]):
            assert np.abs(c.real - r).max() <= 1e-15 * np.abs(r).max() and not np.any(c.imag)
        assert as_complex[3] == pytest.approx(real[3], rel=1e-15)


def test_a_couple_without_overlap_has_zero_derivatives():
    square = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    xs, xm = square[None], _master(square + [1.5, 0.0, 0.1])[None]
    one = np.zeros(1, dtype=np.int64)
    dM, dg = couple_derivatives(xs, xm, one, one, COMPLEX_STEP)
    assert dM.shape == (1, 4, 4, 24) and dg.shape == (1, 4, 24) and not dM.any() and not dg.any()
