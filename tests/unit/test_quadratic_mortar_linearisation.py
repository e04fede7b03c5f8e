"""The consistent linearisation of dual mortar pairs on quadratic facets (issue 41) against global finite
differences.

A curved 2 × 2 slave patch of 9-node quadrilaterals (or of 6-node triangles, 8 of them) under a sheared,
curved 3 × 3 master patch of the same kind, an open gap; every node (vertices, edge nodes, quad9
centres) moved at random, so the facets are curved and distorted. The derivatives of a pair's
coefficients a_i (the dual basis on the transformed basis, the segments, M and m_j), its gap g̃_j / m_j
and its averaged nodal normal (the moments ∫N̂_j n dA), and then its rows W and forces K
(``contact/quadratic_mortar_linearisation.py``), each compared with central differences of the exact
functions — :func:`~dolfinx_nnqem.contact.dual_quadratic.quadratic_mortar_integrals` of the whole moved
surfaces at every perturbed configuration. On tri6 an edge node's pair acts on d̂_j, the node and its
edge's vertices with the constant coefficients t_ji.
"""

import numpy as np
import pytest

from dolfinx_nnqem.contact.dual_quadratic import quadratic_mortar_integrals
from dolfinx_nnqem.contact.facet_layout import node_combination
from dolfinx_nnqem.contact.mortar import _drop_round_off
from dolfinx_nnqem.contact.mortar_linearisation import MortarPoints, mortar_terms, pair_geometry
from dolfinx_nnqem.contact.projection import newell_area_vectors
from dolfinx_nnqem.contact.quadratic_facets import nodal_integrals, outward_signs
from dolfinx_nnqem.contact.quadratic_mortar_linearisation import (QuadraticIncidence, moment_derivatives,
                                                                  quadratic_interface_derivatives)
from dolfinx_nnqem.contact.surfaces import Facets, GatheredSurfaces, local_frames

H = 1e-6  #: the global central differences' step
QUAD9 = ((0, 0), (2, 0), (0, 2), (2, 2), (1, 0), (0, 1), (2, 1), (1, 2), (1, 1))  #: node offsets on the 2n grid
TRI6 = (((0, 0), (2, 0), (2, 2), (2, 1), (1, 1), (1, 0)), ((0, 0), (2, 2), (0, 2), (1, 2), (0, 1), (1, 1)))


def _grid(n: int, lo: float, hi: float, first: int) -> tuple[np.ndarray, np.ndarray]:
    """(node ids (2n+1)², coordinates) of the nodes of an n × n grid of quadratic facets on [lo, hi]² at z = 0."""
    t = np.linspace(lo, hi, 2 * n + 1)
    X, Y = np.meshgrid(t, t, indexing="ij")
    return first + np.arange((2 * n + 1) ** 2), np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])


def _facets(n: int, ids: np.ndarray, triangles: bool) -> np.ndarray:
    """The grid's quad9 facets (or two tri6 per square), in quadratic_facets' node order."""
    out = []
    for i in range(n):
        for j in range(n):
            def node(di, dj):
                return ids[(2 * i + di) * (2 * n + 1) + 2 * j + dj]
            for layout in (TRI6 if triangles else (QUAD9,)):
                out.append([node(di, dj) for di, dj in layout])
    return np.array(out)


def _setup(triangles: bool):
    rng = np.random.default_rng(3)
    s_ids, s_x = _grid(2, 0.0, 1.0, 0)
    m_ids, m_x = _grid(3, -0.23, 1.17, 100)
    s_x += 0.02 * rng.standard_normal(s_x.shape)  # curved, distorted
    m_x[:, 2] = 0.05 + 0.1 * m_x[:, 0] + 0.015 * rng.standard_normal(len(m_x))  # inclined, curved: an open gap
    m_x[:, :2] += 0.02 * rng.standard_normal((len(m_x), 2))
    ids = np.concatenate([s_ids, m_ids])
    return ids, np.vstack([s_x, m_x]), _facets(2, s_ids, triangles), _facets(3, m_ids, triangles)


def _area_vectors(xf: np.ndarray, up: bool) -> np.ndarray:
    """The facets' vertex Newell vectors, along +z if ``up`` (the slave's outward side) else −z."""
    cyclic = [0, 1, 2] if xf.shape[1] == 6 else [0, 1, 3, 2]
    area = newell_area_vectors(xf[:, cyclic])
    return np.where((area[:, 2] > 0) == up, 1.0, -1.0)[:, None] * area


def _surfaces(ids, x, slave, master) -> GatheredSurfaces:
    def facets(nodes, surface, up):
        xf = x[np.searchsorted(ids, nodes)]
        return Facets(np.full(len(nodes), surface), nodes, xf, _area_vectors(xf, up), np.ones(len(nodes)))

    return GatheredSurfaces((1, 2), Facets.concatenate([facets(master, 1, False), facets(slave, 2, True)]), [])


def _exact(ids, x, slave, master, block: int, cols: np.ndarray):
    """(a over ``cols``, g̃_j / m_j, pair normal) of slave node ``block`` at node positions ``x``: the
    integrals of the slave facets around it (its dual function's support, where its normal's moments are)
    against the whole master patch."""
    slave = slave[(slave == block).any(axis=1)]
    xs, xm = x[np.searchsorted(ids, slave)], x[np.searchsorted(ids, master)]
    mi = quadratic_mortar_integrals(slave, xs, _area_vectors(xs, True), master, xm, _area_vectors(xm, False),
                                    search_distance=1.0)
    _drop_round_off(mi)
    s = np.searchsorted(mi.slave_index, block)
    k, M = mi.master_nodes_of(s)
    a = np.zeros(len(cols))
    a[np.searchsorted(cols, k)] = -M / M.sum()
    columns, t = node_combination(slave, mi.slave_index).row(s)
    a[np.searchsorted(cols, mi.slave_index[columns])] = t
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
    cd = quadratic_interface_derivatives(_surfaces(ids, x, slave, master), 1.0, np.array([block]))
    s = int(np.searchsorted(cd.integrals.slave_index, block))
    pg, gap = pair_geometry(cd, QuadraticIncidence(cd), s, -cd.integrals.normal[s], held_open=False)
    return ids, x, slave, master, pg, gap


# the patch's centre vertex (12), an edge node inside (7), a corner (0), an edge node on the patch's edge (1)
@pytest.mark.parametrize("triangles", [False, True])
@pytest.mark.parametrize("block", [12, 7, 0, 1])
def test_coefficients_gap_and_normal_derivatives_match_global_differences(triangles, block):
    ids, x, slave, master, pg, gap = _pair(triangles, block)
    a, g, n = _exact(ids, x, slave, master, block, pg.blocks)
    assert np.allclose(pg.a, a, rtol=0, atol=1e-13) and abs(gap - g) < 1e-13 and abs(gap) > 1e-2
    c = len(pg.blocks)
    fd = _central(lambda y: np.concatenate([np.atleast_1d(v) for v in _exact(ids, y, slave, master, block, pg.blocks)]),
                  ids, x, pg.blocks)
    fd_a, fd_g, fd_n = fd[:c], fd[c], fd[c + 1:]
    errors = [np.abs(d - fd).max() / np.abs(fd).max() for d, fd in ((pg.da, fd_a), (pg.dg, fd_g), (pg.dn, fd_n))]
    combined = np.count_nonzero((pg.a != 0.0) & (pg.blocks < 100))
    print(f"\n  {'tri6' if triangles else 'quad9'}, node {block}: {c} nodes, slave side on {combined}; "
          f"|d − FD|/|FD| of a: {errors[0]:.1e}, g: {errors[1]:.1e}, n: {errors[2]:.1e}")
    assert max(errors) < 1e-6
    assert np.abs(fd_a).max() > 1e-2 and np.abs(fd_g).max() > 1e-2 and np.abs(fd_n).max() > 1e-2


def test_tri6_edge_node_pair_acts_on_the_transformed_node():
    """On tri6 an edge node's pair acts on d̂_j = (u_j − α (u_a + u_b)) / (1 − 2α), α = 1/5."""
    ids, x, slave, master, pg, _ = _pair(True, 7)
    slave = (pg.blocks < 100) & (pg.a != 0.0)  # the slave patch's nodes are 0-24, the master's from 100
    assert np.array_equal(pg.blocks[slave], [2, 7, 12])  # the edge node 7 and its edge's vertices
    assert np.allclose(pg.a[slave], [-0.2 / 0.6, 1.0 / 0.6, -0.2 / 0.6], rtol=1e-15) and pg.a[slave].sum() == 1.0
    assert not pg.da[slave].any()


@pytest.mark.parametrize("k", [6, 9])
def test_moment_derivatives_match_finite_differences(k):
    """∂(∫N̂_a n dA)/∂x of a curved facet: analytic against central differences of nodal_integrals."""
    rng = np.random.default_rng(2)
    ids, x, slave, _ = _setup(k == 6)
    xf = x[np.searchsorted(ids, slave[:1])] + 0.03 * rng.standard_normal((1, k, 3))
    up = _area_vectors(xf, True)
    moments, d = moment_derivatives(xf, outward_signs(xf, up))
    assert np.abs(moments - nodal_integrals(xf, up)[1]).max() < 1e-15
    fd = np.stack([(nodal_integrals(xf + e, up)[1] - nodal_integrals(xf - e, up)[1])[0] / (2 * H)
                   for e in (H * np.eye(3 * k).reshape(3 * k, 1, k, 3))], axis=-1)
    assert np.abs(d[0] - fd).max() < 1e-8 * np.abs(fd).max()


@pytest.mark.parametrize("triangles", [False, True])
@pytest.mark.parametrize("block", [12, 1])
def test_rows_and_forces_match_global_differences(triangles, block):
    """W (∂(gap, slip)/∂u − B) and K (∂(Bᵀλ)/∂u) of a pair against central differences of the gap, the
    slips t_α · Σ a_i (x_i − x_n,i) and the nodal forces a_i Rᵀλ."""
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
    print(f"\n  {'tri6' if triangles else 'quad9'}, node {block}: |B + W − FD|/|FD| = {error_W:.1e}, "
          f"|K − FD|/|FD| = {error_K:.1e}")
    assert error_W < 1e-6 and error_K < 1e-6
