"""The node-to-surface pair's consistent linearisation on quadratic master facets (issue 41) against finite
differences.

A slave node above a curved 9-node quadrilateral and a curved 6-node triangle (edge and centre nodes
off the straight facet, so that every second derivative x_,αβ counts), off the surface (g ≠ 0): the
closest point ξ, the normal n, the gap, the two slips and the nodal forces Bᵀλ as functions of the
3 (1 + k) node coordinates, each derivative component compared with central differences of the exact
functions (the quadratic projection recomputed at every perturbed configuration); also a node beyond a
curved edge (ξ slides along it) and beyond a corner (ξ held).
"""

import numpy as np
import pytest

from dolfinx_nnqem.contact.quadratic_facets import facet_geometry, reference_nodes, shape_functions
from dolfinx_nnqem.contact.quadratic_projection import project_points_quadratic
from dolfinx_nnqem.contact.quadratic_surface_stiffness import quadratic_closest_point_derivatives
from dolfinx_nnqem.contact.surface_stiffness import ClosestPoints, pair_terms
from dolfinx_nnqem.contact.surfaces import local_frames


def _curved(k: int) -> np.ndarray:
    """A curved facet of k nodes: its reference nodes mapped to a warped, bent sheet."""
    r = reference_nodes(k)
    x = np.column_stack([1.1 * r[:, 0] + 0.1 * r[:, 1], 0.05 * r[:, 0] + 0.95 * r[:, 1],
                         0.2 * r[:, 0] * (1 - r[:, 0]) - 0.15 * r[:, 1] * r[:, 1] + 0.1 * r[:, 0] * r[:, 1]])
    return x


QUAD9, TRI6 = _curved(9), _curved(6)
UP = np.array([0.0, 0.0, 1.0])  # the facets' outward side


def _state(facet: np.ndarray, xi=(0.35, 0.3), offset=(0.02, -0.03, 0.21)):
    """Node positions (slave first, above the point ``xi`` of the facet), their positions at u_n, λ."""
    rng = np.random.default_rng(7)
    above = facet_geometry(facet[None], np.array([xi]))[0][0, 0]
    x = np.vstack([above + np.array(offset), facet])
    x_n = x - 0.05 * rng.standard_normal(x.shape)
    return x, x_n, np.array([-1.3, 0.4, -0.25])


def _project(x: np.ndarray):
    return project_points_quadratic(x[0][None], x[1:][None], UP[None])


def _exact(x: np.ndarray, x_n: np.ndarray, lam: np.ndarray):
    """ξ, n, (gap, slip1, slip2) and the nodal forces (c_j Rᵀλ) at node positions ``x`` (slave, then the
    facet's nodes), the closest point found by the package's quadratic projection."""
    p = _project(x)
    N = shape_functions(len(x) - 1, p.xi)[0]
    n = p.normal[0]
    R = local_frames(n[None])[0]
    d = x[0] - N @ x[1:]
    du = x - x_n
    a = du[0] - N @ du[1:]
    c = np.concatenate([[1.0], -N])
    force = (c[:, None] * (R.T @ lam)[None, :]).ravel()
    return p.xi[0], n, np.array([n @ d, R[1] @ a, R[2] @ a]), force, R, c


def _central(function, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    columns = []
    for i in range(x.size):
        e = np.zeros(x.size)
        e[i] = h
        columns.append((function(x + e.reshape(x.shape)) - function(x - e.reshape(x.shape))) / (2 * h))
    return np.stack(columns, axis=-1)


def _points(x, x_n, interior: bool):
    p = _project(x)
    du = x - x_n
    return ClosestPoints(x[0][None], x[1:][None], p.xi, np.array([interior]), p.normal, du[0][None], du[1:][None],
                         np.arange(len(x))[None])


def _check(x, x_n, lam, interior: bool) -> tuple[float, float, float, float]:
    """Compare ∂ξ, ∂n, B + W and K with central differences; the largest differences."""
    p = _project(x)
    dxi, dn, n = quadratic_closest_point_derivatives(x[0][None], x[1:][None], p.xi, np.array([interior]))
    K, W = pair_terms(_points(x, x_n, interior), lam[None])
    _, n_exact, _, _, R, c = _exact(x, x_n, lam)
    B = np.einsum("ik,j->ijk", R, c).reshape(3, -1)
    fd = [_central(lambda y, i=i: _exact(y, x_n, lam)[i], x) for i in range(4)]
    np.testing.assert_allclose(np.abs(n[0] @ n_exact), 1.0, atol=1e-14)
    errors = (np.abs(dxi[0] - fd[0]).max(), np.abs(np.sign(n[0] @ n_exact) * dn[0] - fd[1]).max(),
              np.abs(B + W[0] - fd[2]).max(), np.abs(K[0] - fd[3]).max())
    print(f"\n  {len(x) - 1} nodes: |∂ξ − FD| {errors[0]:.1e}, |∂n − FD| {errors[1]:.1e}, |B + W − FD| {errors[2]:.1e}, "
          f"|K − FD| {errors[3]:.1e}; |W| {np.abs(W).max():.2f}, |K| {np.abs(K).max():.2f}")
    assert np.abs(W[0, 1:]).max() > 1e-2 and np.abs(K).max() > 1e-2  # the terms are there
    return errors


@pytest.mark.parametrize("facet", [QUAD9, TRI6], ids=["quad9", "tri6"])
def test_quadratic_closest_point_terms_match_finite_differences(facet):
    """An interior foot of the normal on a curved facet: every derivative within 1e-8 of central differences."""
    x, x_n, lam = _state(facet)
    p = _project(x)
    assert p.tangential_offset[0] < 1e-12 and abs(p.g0[0]) > 0.1
    assert max(_check(x, x_n, lam, True)) < 1e-8


@pytest.mark.parametrize("facet", [QUAD9, TRI6], ids=["quad9", "tri6"])
def test_quadratic_closest_point_on_a_curved_edge_matches_finite_differences(facet):
    """A slave node beyond the facet's curved edge η = 0: ξ slides along the edge (its quadratic curve)."""
    x, x_n, lam = _state(facet, xi=(0.4, 0.0), offset=(0.03, -0.2, 0.15))
    p = _project(x)
    assert p.tangential_offset[0] > 0.05 and abs(p.xi[0, 1]) < 1e-14 and 0.05 < p.xi[0, 0] < 0.95
    errors = _check(x, x_n, lam, False)
    assert max(errors) < 1e-8
    assert np.abs(pair_terms(_points(x, x_n, False), lam[None])[1][0, 0]).max() > 1e-3  # not B's row alone


def test_quadratic_closest_point_at_a_corner_holds_xi():
    """A slave node beyond a corner: ξ stays there (δξ = 0), the normal still turns, and the terms match."""
    x, x_n, lam = _state(QUAD9, xi=(0.0, 0.0), offset=(-0.2, -0.15, 0.1))
    p = _project(x)
    np.testing.assert_allclose(p.xi[0], [0.0, 0.0], atol=1e-14)
    dxi, dn, _ = quadratic_closest_point_derivatives(x[0][None], x[1:][None], p.xi, np.array([False]))
    assert np.all(dxi == 0.0) and np.abs(dn).max() > 0.1
    assert max(_check(x, x_n, lam, False)) < 1e-8
