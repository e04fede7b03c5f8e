"""The dual mortar pair's consistent linearisation (issues 41 and 43) against global finite differences.

A warped 2 × 2 slave patch of quadrilaterals (or of triangles) under a sheared, warped 3 × 3 master
patch, an open gap: the derivatives of a pair's coefficients a_i (the dual basis, the clip polygons,
M and m_j), its gap g̃_j / m_j and its averaged normal, and then its rows W and forces K
(``contact/mortar_linearisation.py``), each component compared with central differences of the
exact functions — :func:`~dolfinx_nnqem.contact.mortar_geometry.mortar_integrals` of the whole
moved surfaces at every perturbed configuration (the global difference the local couple
differences of the module stand in for).
"""

import numpy as np
import pytest

from dolfinx_nnqem.contact.mortar_geometry import mortar_integrals
from dolfinx_nnqem.contact.mortar_linearisation import (MortarPoints, _Incidence, interface_derivatives,
                                                        mortar_terms, newell_derivative, pair_geometry)
from dolfinx_nnqem.contact.projection import newell_area_vectors
from dolfinx_nnqem.contact.surfaces import Facets, GatheredSurfaces, local_frames

H = 1e-6  #: the global central differences' step


def _grid(n: int, lo: float, hi: float, first: int) -> tuple[np.ndarray, np.ndarray]:
    """(node ids (n+1)², coordinates) of an n × n grid on [lo, hi]² at z = 0."""
    t = np.linspace(lo, hi, n + 1)
    X, Y = np.meshgrid(t, t, indexing="ij")
    return first + np.arange((n + 1) ** 2), np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])


def _quads(n: int, ids: np.ndarray, up: bool, triangles: bool) -> np.ndarray:
    """Facets of the grid, counter-clockwise seen from +z if ``up`` (else clockwise)."""
    out = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = (ids[(i + di) * (n + 1) + j + dj] for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1)))
            out += [[a, b, c], [a, c, d]] if triangles else [[a, b, c, d]]
    facets = np.array(out)
    return facets if up else facets[:, ::-1]


def _setup(triangles: bool):
    rng = np.random.default_rng(3)
    s_ids, s_x = _grid(2, 0.0, 1.0, 0)
    m_ids, m_x = _grid(3, -0.23, 1.17, 100)
    s_x += 0.03 * rng.standard_normal(s_x.shape)  # warped, distorted
    m_x[:, 2] = 0.05 + 0.1 * m_x[:, 0] + 0.02 * rng.standard_normal(len(m_x))  # inclined, warped: an open gap
    m_x[:, :2] += 0.03 * rng.standard_normal((len(m_x), 2))
    ids = np.concatenate([s_ids, m_ids])
    x = np.vstack([s_x, m_x])
    slave, master = _quads(2, s_ids, True, triangles), _quads(3, m_ids, False, triangles)
    return ids, x, slave, master


def _surfaces(ids, x, slave, master) -> GatheredSurfaces:
    def facets(nodes, surface):
        xf = x[np.searchsorted(ids, nodes)]
        return Facets(np.full(len(nodes), surface), nodes, xf, newell_area_vectors(xf), np.ones(len(nodes)))

    return GatheredSurfaces((1, 2), Facets.concatenate([facets(master, 1), facets(slave, 2)]), [])


def _exact(ids, x, slave, master, block: int, cols: np.ndarray):
    """(a over ``cols``, g̃_j / m_j, pair normal) of slave node ``block`` at node positions ``x``."""
    s_take, m_take = np.searchsorted(ids, slave), np.searchsorted(ids, master)
    mi = mortar_integrals(slave, x[s_take], newell_area_vectors(x[s_take]), master, x[m_take],
                          newell_area_vectors(x[m_take]), search_distance=1.0)
    s = np.searchsorted(mi.slave_index, block)
    k, M = mi.master_nodes_of(s)
    a = np.zeros(len(cols))
    a[np.searchsorted(cols, k)] = -M / M.sum()
    a[np.searchsorted(cols, block)] = 1.0
    return a, mi.weighted_gap[s] / M.sum(), -mi.normal[s]


def _central(function, ids, x, cols):
    """(outputs, 3 c) central differences of ``function(x)`` over the coordinates of the nodes ``cols``."""
    out = []
    for node in np.searchsorted(ids, cols):
        for comp in range(3):
            e = np.zeros_like(x)
            e[node, comp] = H
            out.append((function(x + e) - function(x - e)) / (2 * H))
    return np.stack(out, axis=-1)


def _pair(triangles: bool, block: int):
    ids, x, slave, master = _setup(triangles)
    cd = interface_derivatives(_surfaces(ids, x, slave, master), 1.0)
    s = int(np.searchsorted(cd.integrals.slave_index, block))
    pg, gap = pair_geometry(cd, _Incidence(cd), s, -cd.integrals.normal[s], held_open=False)
    return ids, x, slave, master, pg, gap


@pytest.mark.parametrize("triangles", [False, True])
@pytest.mark.parametrize("block", [4, 0])  # the patch's centre node, a corner node (partly covered facets)
def test_coefficients_gap_and_normal_derivatives_match_global_differences(triangles, block):
    ids, x, slave, master, pg, gap = _pair(triangles, block)
    a, g, n = _exact(ids, x, slave, master, block, pg.blocks)
    assert np.allclose(pg.a, a, rtol=0, atol=1e-13) and abs(gap - g) < 1e-13 and abs(gap) > 1e-2
    c = len(pg.blocks)
    fd = _central(lambda y: np.concatenate([np.atleast_1d(v) for v in _exact(ids, y, slave, master, block, pg.blocks)]),
                  ids, x, pg.blocks)
    fd_a, fd_g, fd_n = fd[:c], fd[c], fd[c + 1:]
    errors = [np.abs(d - fd).max() / np.abs(fd).max() for d, fd in ((pg.da, fd_a), (pg.dg, fd_g), (pg.dn, fd_n))]
    print(f"\n  {'triangles' if triangles else 'quadrilaterals'}, node {block}: {len(pg.blocks)} nodes; "
          f"|d − FD|/|FD| of a: {errors[0]:.1e}, g: {errors[1]:.1e}, n: {errors[2]:.1e}")
    assert max(errors) < 1e-6
    assert np.abs(fd_a).max() > 1e-2 and np.abs(fd_g).max() > 1e-2  # the coefficients and the gap do move


def test_newell_derivative_matches_finite_differences():
    rng = np.random.default_rng(1)
    x = rng.standard_normal((1, 4, 3))
    fd = np.stack([(newell_area_vectors(x + e) - newell_area_vectors(x - e))[0] / (2 * H)
                   for e in (H * np.eye(12).reshape(12, 1, 4, 3))], axis=-1)
    assert np.abs(newell_derivative(x)[0] - fd).max() < 1e-8


@pytest.mark.parametrize("triangles", [False, True])
def test_rows_and_forces_match_global_differences(triangles):
    """W (∂(gap, slip)/∂u − B) and K (∂(Bᵀλ)/∂u) of the centre node's pair against central differences
    of the gap, the slips t_α · Σ a_i (x_i − x_n,i) and the nodal forces a_i Rᵀλ."""
    block = 4
    ids, x, slave, master, pg, _ = _pair(triangles, block)
    at = np.searchsorted(ids, pg.blocks)
    x_n = x - 0.05 * np.random.default_rng(5).standard_normal(x.shape)
    lam = np.array([-1.3, 0.4, -0.25])

    def exact(y):
        a, g, n = _exact(ids, y, slave, master, block, pg.blocks)
        R = local_frames(n[None])[0]
        slip = a @ (y - x_n)[at]
        return np.concatenate([[g, R[1] @ slip, R[2] @ slip], (a[:, None] * (R.T @ lam)[None]).ravel()])

    points = MortarPoints([pg], _exact(ids, x, slave, master, block, pg.blocks)[2][None], [(x - x_n)[at]])
    terms = mortar_terms(points, lam[None], np.array([0]))[0]
    R = local_frames(points.normal)[0]
    B = (R[:, None, :] * pg.a[None, :, None]).reshape(3, -1)
    fd = _central(exact, ids, x, pg.blocks)
    error_W = np.abs(B + terms.W[0] - fd[:3]).max() / np.abs(fd[:3]).max()
    error_K = np.abs(terms.K[0] - fd[3:]).max() / np.abs(fd[3:]).max()
    print(f"\n  |B + W − FD|/|FD| = {error_W:.1e}, |K − FD|/|FD| = {error_K:.1e}")
    assert error_W < 1e-6 and error_K < 1e-6


def test_normal_turned_into_a_symmetry_plane_matches_global_differences():
    """A slave node on a symmetry plane x = const: its normal with the x component removed
    (:func:`~dolfinx_nnqem.contact.surfaces.symmetry_normals`) turns by (I − n nᵀ) P δn_f / |P n_f|."""
    from dolfinx_nnqem.contact.mortar_linearisation import _normal_derivative
    from dolfinx_nnqem.contact.surfaces import symmetry_normals

    block = 3  # on the patch's edge x ≈ 0
    ids, x, slave, master = _setup(False)
    axes = np.array([[True, False, False]])
    cd = interface_derivatives(_surfaces(ids, x, slave, master), 1.0)
    s = int(np.searchsorted(cd.integrals.slave_index, block))
    given = -cd.integrals.normal[s]
    turned = symmetry_normals(given[None], axes)[0]
    incidence = _Incidence(cd)
    pg, _ = pair_geometry(cd, incidence, s, turned, held_open=False)
    dn = _normal_derivative(cd, incidence, incidence.facets(block), pg.blocks, turned, given)
    fd = _central(lambda y: symmetry_normals(_exact(ids, y, slave, master, block, pg.blocks)[2][None], axes)[0],
                  ids, x, pg.blocks)
    error = np.abs(dn - fd).max() / np.abs(fd).max()
    print(f"\n  turned normal: |dn − FD|/|FD| = {error:.1e} (turned by {np.degrees(np.arccos(given @ turned)):.2f}°)")
    assert turned[0] == 0.0 and given[0] != 0.0 and np.abs(pg.dn - dn).max() == 0.0
    assert error < 1e-6
