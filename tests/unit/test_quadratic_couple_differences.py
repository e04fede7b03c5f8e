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
from dolfinx_nnqem.contact.quadratic_facets import outward_signs, reference_nodes

STEP = 1e-6


def _whole_couple_differences(xs, sign_s, xm, sign_m, ci, cj, step):
    """(dM (c, ks, km, P), dg (c, ks, P)): every coordinate of a couple's two facets moved by ± step, the
    couple integrated again whole (its slave facet's dual coefficients too)."""
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
    M, g = M.reshape(c, 2, P, ks, km), g.reshape(c, 2, P, ks)
    return ((M[:, 0] - M[:, 1]).transpose(0, 2, 3, 1) / (2.0 * step),
            (g[:, 0] - g[:, 1]).transpose(0, 2, 1) / (2.0 * step))


def _couples(ids, x, slave, master):
    xs, xm = x[np.searchsorted(ids, slave)], x[np.searchsorted(ids, master)]
    area_s, area_m = _area_vectors(xs, True), _area_vectors(xm, False)
    ci, cj = quadratic_candidate_couples(xs, area_s, xm, area_m, 1.0)
    return xs, outward_signs(xs, area_s), xm, outward_signs(xm, area_m), ci, cj


def _compare(xs, sign_s, xm, sign_m, ci, cj):
    """The largest differences of dM and dg from the whole couple's differences, relative to their largest
    entries, and the number of couples that count."""
    reference = _whole_couple_differences(xs, sign_s, xm, sign_m, ci, cj, STEP)
    derivatives = quadratic_couple_derivatives(xs, sign_s, xm, sign_m, ci, cj, STEP)
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


@pytest.mark.parametrize("triangles", [False, True])
@pytest.mark.parametrize("offset, tolerance", [(1e-3, 1e-7), (0.0, 1e-4)])
def test_flat_patches_with_edges_on_each_other(triangles, offset, tolerance):
    """A flat master 0.05 above a flat slave, a 4 × 4 master patch over the 2 × 2 slave patch on the same
    square, moved by ``offset`` along x and 2 ``offset`` along y: its edges lie beside the slave's (couples
    touching along an edge or a corner). Exactly on them (offset 0) the integrals have kinks (the clip's coincident
    edges and vertices) and central differences there are exact only to O(step), whole couple or not
    (measured: the whole couple's differences with steps h/2, h, 2h differ by up to 1.3e-5 of the largest
    entry, and these from them by up to 9.6e-6)."""
    s_ids, s_x = _grid(2, 0.0, 1.0, 0)
    m_ids, m_x = _grid(4, 0.0, 1.0, 100)
    m_x[:, 2] = 0.05
    m_x[:, :2] += [offset, 2.0 * offset]  # not along the triangles' diagonals
    ids = np.concatenate([s_ids, m_ids])
    xs, sign_s, xm, sign_m, ci, cj = _couples(ids, np.vstack([s_x, m_x]), _facets(2, s_ids, triangles),
                                              _facets(4, m_ids, triangles))
    error_M, error_g = _compare(xs, sign_s, xm, sign_m, ci, cj)
    print(f"\n  {'tri6' if triangles else 'quad9'}, offset {offset}: {len(ci)} couples; "
          f"dM {error_M:.1e}, dg {error_g:.1e}")
    assert error_M < tolerance and error_g < tolerance


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
