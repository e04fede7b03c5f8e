"""The derivatives of the couple integrals of quadratic facets (``contact/quadratic_couple_differences.py``)
against central differences of the whole couple, the moved slave facet's dual coefficients computed again
(what ``quadratic_mortar_linearisation`` did before: every coordinate of both facets moved by ± h and
every pair of sub-facets integrated again).

The curved, distorted patches of ``test_quadratic_mortar_linearisation`` (quad9 and tri6, an inclined,
curved master above a curved slave), every candidate couple: overlapping ones, couples that only touch,
and couples whose facets do not face each other; and a flat, aligned patch whose master edges lie on
the slave's (the clip's coincident edges).
"""

import numpy as np
import pytest
from test_quadratic_mortar_linearisation import _area_vectors, _facets, _grid, _setup

from dolfinx_nnqem.contact.dual_quadratic import (integrate_quadratic_couples, quadratic_candidate_couples,
                                                  quadratic_dual_coefficients)
from dolfinx_nnqem.contact.quadratic_couple_differences import (dual_coefficient_derivatives,
                                                                quadratic_couple_derivatives)
from dolfinx_nnqem.contact.couple_complex_step import COMPLEX_STEP
from dolfinx_nnqem.contact.quadratic_facets import outward_signs, reference_nodes

STEP = 1e-6


def _moved_couples(xs, sign_s, xm, sign_m, ci, cj, step):
    """(M (c, 2, P, ks, km), g (c, 2, P, ks)): the couples with every coordinate of their two facets moved by
    + step, then by − step, integrated again whole (the slave facet's dual coefficients too)."""
    c, ks, km = len(ci), xs.shape[1], xm.shape[1]
    P, S = 3 * (ks + km), 3 * ks
    e = step * np.eye(P)[None]
    x = np.concatenate([xs[ci], xm[cj]], axis=1).reshape(c, 1, P)
    moved = np.concatenate([x + e, x - e], axis=1).reshape(-1, ks + km, 3)  # (c·2P): +h each, then −h each
    xs_p, xm_p = np.ascontiguousarray(moved[:, :ks]), np.ascontiguousarray(moved[:, ks:])
    A = np.broadcast_to(quadratic_dual_coefficients(xs[ci])[0][:, None, None], (c, 2, P, ks, ks)).copy()
    A[:, :, :S] = quadratic_dual_coefficients(xs_p.reshape(c, 2, P, ks, 3)[:, :, :S].reshape(-1, ks, 3))[0].reshape(
        c, 2, S, ks, ks)
    every = np.arange(len(moved), dtype=np.int64)
    M, g, _, _ = integrate_quadratic_couples(every, every, xs_p, np.repeat(sign_s[ci], 2 * P),
                                             np.ascontiguousarray(A.reshape(-1, ks, ks)), xm_p,
                                             np.repeat(sign_m[cj], 2 * P))
    return M.reshape(c, 2, P, ks, km), g.reshape(c, 2, P, ks)


def _whole_couple_differences(xs, sign_s, xm, sign_m, ci, cj, step):
    """(dM (c, ks, km, P), dg (c, ks, P)): central differences, every coordinate of a couple's two facets moved
    by ± step, the couple integrated again whole (its slave facet's dual coefficients too)."""
    M, g = _moved_couples(xs, sign_s, xm, sign_m, ci, cj, step)
    return ((M[:, 0] - M[:, 1]).transpose(0, 2, 3, 1) / (2.0 * step),
            (g[:, 0] - g[:, 1]).transpose(0, 2, 1) / (2.0 * step))


def _one_sided_columns(xs, sign_s, xm, sign_m, ci, cj, step):
    """(forward, backward) differences (c, ks·km + ks, P) of the couples' (M, g̃) whole."""
    M, g = _moved_couples(xs, sign_s, xm, sign_m, ci, cj, step)
    M0, g0, _, _ = integrate_quadratic_couples(ci, cj, xs, sign_s, quadratic_dual_coefficients(xs)[0], xm, sign_m)
    c, P = len(ci), M.shape[2]
    moved = np.concatenate([M.reshape(c, 2, P, -1), g], axis=3).transpose(1, 0, 3, 2)  # (2, c, outputs, P)
    at = np.concatenate([M0.reshape(c, -1), g0], axis=1)[:, :, None]
    return (moved[0] - at) / step, (at - moved[1]) / step


def _couples(ids, x, slave, master):
    xs, xm = x[np.searchsorted(ids, slave)], x[np.searchsorted(ids, master)]
    area_s, area_m = _area_vectors(xs, True), _area_vectors(xm, False)
    ci, cj = quadratic_candidate_couples(xs, area_s, xm, area_m, 1.0)
    return xs, outward_signs(xs, area_s), xm, outward_signs(xm, area_m), ci, cj


def _compare(xs, sign_s, xm, sign_m, ci, cj):
    """The largest differences of dM and dg from the whole couple's differences, relative to their largest
    entries, and the number of couples that count."""
    reference = _whole_couple_differences(xs, sign_s, xm, sign_m, ci, cj, STEP)
    derivatives = quadratic_couple_derivatives(xs, sign_s, xm, sign_m, ci, cj, COMPLEX_STEP)
    assert all(d.shape == r.shape for d, r in zip(derivatives, reference))
    return [float(np.abs(d - r).max() / np.abs(r).max()) for d, r in zip(derivatives, reference)]


@pytest.mark.parametrize("triangles", [False, True])
def test_curved_patches_give_the_whole_couples_differences(triangles):
    """Curved, distorted facets: every candidate couple (some only touching, some not overlapping at all),
    within 1e-7 of the largest entry (the whole couple's differences carry round-off ~1e-16 / STEP)."""
    xs, sign_s, xm, sign_m, ci, cj = _couples(*_setup(triangles))
    counted = integrate_quadratic_couples(ci, cj, xs, sign_s, quadratic_dual_coefficients(xs)[0], xm, sign_m)[2] > 0
    assert counted.any() and not counted.all()  # couples that count and couples that do not
    error_M, error_g = _compare(xs, sign_s, xm, sign_m, ci, cj)
    print(f"\n  {'tri6' if triangles else 'quad9'}: {len(ci)} couples, {int(counted.sum())} overlapping; "
          f"dM {error_M:.1e}, dg {error_g:.1e}")
    assert error_M < 1e-7 and error_g < 1e-7


def _flat_patches(triangles: bool, offset: float):
    """A flat master 0.05 above a flat slave, a 4 × 4 master patch over the 2 × 2 slave patch on the same
    square, moved by ``offset`` along x and 2 ``offset`` along y (not along the triangles' diagonals): its
    edges lie beside the slave's (couples touching along an edge or a corner); the couples."""
    s_ids, s_x = _grid(2, 0.0, 1.0, 0)
    m_ids, m_x = _grid(4, 0.0, 1.0, 100)
    m_x[:, 2] = 0.05
    m_x[:, :2] += [offset, 2.0 * offset]
    ids = np.concatenate([s_ids, m_ids])
    return _couples(ids, np.vstack([s_x, m_x]), _facets(2, s_ids, triangles), _facets(4, m_ids, triangles))


@pytest.mark.parametrize("triangles", [False, True])
def test_flat_patches_with_edges_beside_each_other(triangles):
    """The flat patches, the master moved by 1e-3: its edges and vertices 1e-3 beside the slave's."""
    error_M, error_g = _compare(*_flat_patches(triangles, 1e-3))
    print(f"\n  {'tri6' if triangles else 'quad9'}, offset 1e-3: dM {error_M:.1e}, dg {error_g:.1e}")
    assert error_M < 1e-7 and error_g < 1e-7


@pytest.mark.parametrize("triangles, neither", [(False, 0), (True, 96)])
def test_flat_patches_with_edges_on_each_other(triangles, neither):
    """The master's edges exactly on the slave's (offset 0): the integrals have kinks there (the clip's
    coincident edges and vertices) and no derivative. The complex step differentiates the branch the real
    evaluation takes at each clipped vertex: on quad9 every (couple, coordinate) column is a one-sided
    derivative (forward or backward differences, step 1e-8, to 1e-6 of the largest entry); on tri6, where
    vertices of the sub-triangles meet on the diagonals too, ``neither`` (96) of the 5760 columns is either
    one-sided derivative (measured; the central differences there were their mean, another choice)."""
    couples = _flat_patches(triangles, 0.0)
    dM, dg = quadratic_couple_derivatives(*couples, COMPLEX_STEP)
    columns = np.concatenate([dM.reshape(len(dM), -1, dM.shape[-1]), dg], axis=1)
    forward, backward = _one_sided_columns(*couples, 1e-8)
    scale = np.abs(columns).max()
    distance = np.minimum(np.abs(columns - forward).max(axis=1), np.abs(columns - backward).max(axis=1)) / scale
    one_sided = distance <= 1e-6
    print(f"\n  {'tri6' if triangles else 'quad9'}, offset 0: {len(dM)} couples; {int((~one_sided).sum())} of "
          f"{one_sided.size} columns neither one-sided derivative (the largest distance {distance.max():.1e}), the "
          f"others within {distance[one_sided].max():.1e}")
    assert int((~one_sided).sum()) == neither


@pytest.mark.parametrize("k", [6, 9])
def test_dual_coefficient_derivatives_match_central_differences(k):
    """∂A_e of curved, distorted tri6 and quad9 facets against central differences of
    quadratic_dual_coefficients (measured 5e-10 and 3e-9 of the largest entry); A_e itself bit-identical."""
    rng = np.random.default_rng(1)
    x = np.column_stack([reference_nodes(k), 0.1 * rng.standard_normal(k)])[None]
    x = x + 0.03 * rng.standard_normal((3, k, 3))  # three curved, distorted facets
    A, dA = dual_coefficient_derivatives(x)
    differences = np.empty_like(dA)
    for p in range(3 * k):
        e = np.zeros((k, 3))
        e.flat[p] = STEP
        differences[:, p] = (quadratic_dual_coefficients(x + e)[0] - quadratic_dual_coefficients(x - e)[0]) / (2 * STEP)
    assert np.array_equal(A, quadratic_dual_coefficients(x)[0])
    assert np.abs(dA - differences).max() < 1e-7 * np.abs(differences).max()


H6 = 2e-4  #: the sixth-order differences' step (a kink of the tri6 couples lies within 3 × 1e-3 of a node)


def _one_couple(triangles: bool, tilt: float):
    """A curved, distorted slave facet (quad9, or tri6) and a curved master facet of the same kind over part
    of it, inclined by ``tilt`` along x; (xs, sign_s, xm, sign_m, ci, cj) of the one couple."""
    rng = np.random.default_rng(11)
    s_ids, s_x = _grid(1, 0.0, 1.0, 0)
    m_ids, m_x = _grid(1, 0.31, 1.27, 100)
    s_x += 0.02 * rng.standard_normal(s_x.shape)
    m_x[:, 2] = 0.05 + tilt * m_x[:, 0] + 0.015 * rng.standard_normal(len(m_x))
    m_x[:, :2] += 0.02 * rng.standard_normal((len(m_x), 2))
    ids = np.concatenate([s_ids, m_ids])
    xs, sign_s, xm, sign_m, _, _ = _couples(ids, np.vstack([s_x, m_x]), _facets(1, s_ids, triangles),
                                            _facets(1, m_ids, triangles))
    return xs, sign_s, xm, sign_m, np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64)


def _sixth_order(xs, sign_s, xm, sign_m):
    """(outputs, P) sixth-order central differences of the couple (0, 0)'s (M, g̃), whole (error ~ H6⁶ + 1e-16 /
    H6)."""
    ks = xs.shape[1]
    x = np.concatenate([xs[0], xm[0]])

    def integrals(y):
        M, g, area, _ = integrate_quadratic_couples(np.zeros(1, np.int64), np.zeros(1, np.int64), y[None, :ks],
                                                    sign_s[:1], quadratic_dual_coefficients(y[None, :ks])[0],
                                                    y[None, ks:], sign_m[:1])
        assert area[0] > 0.0
        return np.concatenate([M[0].ravel(), g[0]])

    columns = []
    for p in range(x.size):
        e = np.zeros(x.size)
        e[p] = H6
        f = {j: integrals(x + j * e.reshape(x.shape)) for j in (-3, -2, -1, 1, 2, 3)}
        columns.append((45 * (f[1] - f[-1]) - 9 * (f[2] - f[-2]) + (f[3] - f[-3])) / (60 * H6))
    return np.stack(columns, axis=-1)


@pytest.mark.parametrize("triangles", [False, True])
@pytest.mark.parametrize("tilt", [0.0, 0.3])
def test_complex_step_matches_sixth_order_differences(triangles, tilt):
    """One curved couple with a partial overlap (master nodes inside the slave facet, the slave's inside the
    master's), flat or inclined: the derivatives (the complex step of the in-plane points and the chain rule)
    within 1e-9 of sixth-order differences of the whole couple; the whole couple's central differences (step
    1e-6) printed next to them."""
    couple = _one_couple(triangles, tilt)
    reference = _sixth_order(*couple[:4])
    dM, dg = quadratic_couple_derivatives(*couple, COMPLEX_STEP)
    exact = np.concatenate([dM[0].reshape(-1, dM.shape[-1]), dg[0]])
    cM, cg = _whole_couple_differences(*couple, STEP)
    central = np.concatenate([cM[0].reshape(-1, cM.shape[-1]), cg[0]])
    scale = np.abs(reference).max()
    error, before = np.abs(exact - reference).max() / scale, np.abs(central - reference).max() / scale
    print(f"\n  {'tri6' if triangles else 'quad9'}, tilt {tilt}: |d − FD6|/|FD6| {error:.1e}; the whole couple's "
          f"central differences {before:.1e}")
    assert scale > 1e-2 and error <= 1e-9
