"""The node-to-surface pair's consistent linearisation (issue 41) against finite differences.

A slave node above a master facet (a triangle, and a warped bilinear quadrilateral), off the
surface (g ≠ 0) so that every term counts: the closest point ξ, the normal n, the gap, the two
slips and the nodal forces Bᵀλ (slave and master nodes) as functions of the 3 (1 + m) node
coordinates, each derivative component compared with central differences of the exact
functions (the projection recomputed at every perturbed configuration).
"""

import numpy as np
import pytest

from dolfinx_nnqem.contact.projection import facet_normals, newell_area_vectors, project_points, shape_functions
from dolfinx_nnqem.contact.surface_stiffness import ClosestPoints, closest_point_derivatives, pair_terms
from dolfinx_nnqem.contact.surfaces import local_frames, symmetry_normals

TRIANGLE = np.array([[0.0, 0.0, 0.0], [1.0, 0.1, 0.05], [0.2, 0.9, -0.1]])
QUADRILATERAL = np.array([[0.0, 0.0, 0.0], [1.1, 0.05, 0.1], [1.0, 1.0, -0.15], [-0.1, 0.9, 0.05]])  # warped


def _state(facet: np.ndarray):
    """Node positions (slave first), their positions at u_n, and the pair force λ."""
    rng = np.random.default_rng(7)
    x = np.vstack([facet.mean(axis=0) + np.array([0.13, -0.07, 0.21]), facet])
    x_n = x - 0.05 * rng.standard_normal(x.shape)
    lam = np.array([-1.3, 0.4, -0.25])
    return x, x_n, lam


def _exact(x: np.ndarray, x_n: np.ndarray, lam: np.ndarray, axes: np.ndarray | None = None):
    """ξ, n, (gap, slip1, slip2) and the nodal forces (c_j Rᵀλ) at node positions ``x`` (slave, then the
    facet's cyclic vertices), the closest point found by the package's projection; ``axes``: the
    normal turned into the symmetry planes of these axes (the frame's, the gap stays n_f · d)."""
    x_s, x_m = x[0], x[1:]
    p = project_points(x_s[None], x_m[None], newell_area_vectors(x_m[None]))
    xi, N = p.xi[0], shape_functions(len(x_m), p.xi)[0]
    n_f = facet_normals(x_m[None], p.xi)[0]
    n = n_f if axes is None else symmetry_normals(n_f[None], axes[None])[0]
    R = local_frames(n[None])[0]
    d = x_s - N @ x_m
    du = x - x_n
    a = du[0] - N @ du[1:]
    residual = np.array([n_f @ d, R[1] @ a, R[2] @ a])
    c = np.concatenate([[1.0], -N])
    force = (c[:, None] * (R.T @ lam)[None, :]).ravel()
    return xi, n, residual, force, R, c


def _central(function, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """(outputs, 3 (1 + m)) central differences of ``function`` at ``x`` (n nodes × 3)."""
    columns = []
    for i in range(x.size):
        e = np.zeros(x.size)
        e[i] = h
        columns.append((function(x + e.reshape(x.shape)) - function(x - e.reshape(x.shape))) / (2 * h))
    return np.stack(columns, axis=-1)


def _points(x, x_n):
    p = project_points(x[0][None], x[1:][None], newell_area_vectors(x[1:][None]))
    du = x - x_n
    return ClosestPoints(x[0][None], x[1:][None], p.xi, np.array([True]), p.normal, du[0][None], du[1:][None],
                         np.arange(len(x))[None])


@pytest.mark.parametrize("facet", [TRIANGLE, QUADRILATERAL], ids=["tri3", "quad4"])
def test_closest_point_and_normal_derivatives_match_finite_differences(facet):
    x, x_n, lam = _state(facet)
    p = project_points(x[0][None], x[1:][None], newell_area_vectors(x[1:][None]))
    assert p.tangential_offset[0] < 1e-12 and abs(p.g0[0]) > 0.1  # an interior foot, off the surface
    dxi, dn, n = closest_point_derivatives(x[0][None], x[1:][None], p.xi, np.array([True]))
    fd_xi = _central(lambda y: _exact(y, x_n, lam)[0], x)
    fd_n = _central(lambda y: _exact(y, x_n, lam)[1], x)
    print(f"\n  {len(facet)} vertices: |∂ξ/∂x − FD| = {np.abs(dxi[0] - fd_xi).max():.1e}, "
          f"|∂n/∂x − FD| = {np.abs(dn[0] - fd_n).max():.1e}")
    np.testing.assert_allclose(n[0], _exact(x, x_n, lam)[1], atol=1e-14)
    np.testing.assert_allclose(dxi[0], fd_xi, atol=1e-8)
    np.testing.assert_allclose(dn[0], fd_n, atol=1e-8)


@pytest.mark.parametrize("facet", [TRIANGLE, QUADRILATERAL], ids=["tri3", "quad4"])
def test_gap_slip_and_force_derivatives_match_finite_differences(facet):
    """∂(gap, slip)/∂x = R c + W and ∂(c_j Rᵀλ)/∂x = K, component by component."""
    x, x_n, lam = _state(facet)
    K, W = pair_terms(_points(x, x_n), lam[None])
    _, _, _, _, R, c = _exact(x, x_n, lam)
    B = np.einsum("ik,j->ijk", R, c).reshape(3, -1)  # R c_j in node j's columns
    fd_residual = _central(lambda y: _exact(y, x_n, lam)[2], x)
    fd_force = _central(lambda y: _exact(y, x_n, lam)[3], x)
    print(f"\n  {len(facet)} vertices: |W| = {np.abs(W).max():.2f}, |K| = {np.abs(K).max():.2f}; "
          f"|B + W − FD| = {np.abs(B + W[0] - fd_residual).max():.1e}, |K − FD| = {np.abs(K[0] - fd_force).max():.1e}")
    for row, name in enumerate(("gap", "slip t1", "slip t2")):
        np.testing.assert_allclose(B[row] + W[0, row], fd_residual[row], atol=1e-8, err_msg=name)
    np.testing.assert_allclose(K[0], fd_force, atol=1e-8)
    assert np.abs(W[0, 0]).max() < 1e-12  # an interior closest point: the gap's derivative is B's row alone
    assert np.abs(W[0, 1:]).max() > 1e-2 and np.abs(K).max() > 1e-2  # the terms are there


@pytest.mark.parametrize("facet", [TRIANGLE, QUADRILATERAL], ids=["tri3", "quad4"])
def test_closest_point_clamped_to_an_edge_matches_finite_differences(facet):
    """A slave node beyond the facet's edge (kept on its facet, as past a shared edge within the edge
    allowance): ξ slides along the edge, and the gap (d no longer along n), slips and forces follow."""
    x, x_n, lam = _state(facet)
    x[0] = 0.5 * (x[2] + x[3]) + np.array([0.15, 0.1, 0.3])  # beyond the edge from vertex 1 to vertex 2
    p = project_points(x[0][None], x[1:][None], newell_area_vectors(x[1:][None]))
    assert p.tangential_offset[0] > 0.05
    points = _points(x, x_n)
    points = ClosestPoints(points.x_s, points.x_m, points.xi, np.array([False]), points.normal, points.du_s,
                           points.du_m, points.blocks)
    dxi, dn, _ = closest_point_derivatives(points.x_s, points.x_m, points.xi, points.interior)
    np.testing.assert_allclose(dxi[0], _central(lambda y: _exact(y, x_n, lam)[0], x), atol=1e-8)
    np.testing.assert_allclose(dn[0], _central(lambda y: _exact(y, x_n, lam)[1], x), atol=1e-8)
    K, W = pair_terms(points, lam[None])
    _, _, _, _, R, c = _exact(x, x_n, lam)
    B = np.einsum("ik,j->ijk", R, c).reshape(3, -1)
    np.testing.assert_allclose(B + W[0], _central(lambda y: _exact(y, x_n, lam)[2], x), atol=1e-8)
    np.testing.assert_allclose(K[0], _central(lambda y: _exact(y, x_n, lam)[3], x), atol=1e-8)
    assert np.abs(W[0, 0]).max() > 1e-3  # the gap's derivative is not B's row alone here


def test_closest_point_at_a_corner_holds_xi():
    """A slave node beyond a corner: ξ stays at the corner (δξ = 0), the normal still turns."""
    x, x_n, lam = _state(TRIANGLE)
    x[0] = x[2] + np.array([0.3, -0.2, 0.2])  # beyond vertex 1 (1, 0.1, 0.05)
    p = project_points(x[0][None], x[1:][None], newell_area_vectors(x[1:][None]))
    assert p.tangential_offset[0] > 0.1
    dxi, dn, _ = closest_point_derivatives(x[0][None], x[1:][None], p.xi, np.array([False]))
    np.testing.assert_allclose(p.xi[0], [1.0, 0.0], atol=1e-14)
    assert np.all(dxi == 0.0) and np.abs(dn).max() > 0.1


def test_normal_turned_into_a_symmetry_plane_matches_finite_differences():
    """A slave node on a symmetry plane y = const (its frame's normal has the y component removed,
    as :func:`~dolfinx_nnqem.contact.surfaces.symmetry_normals` does; the gap stays n_f · d): the
    frame, slips and forces turn with the projected normal."""
    x, x_n, lam = _state(QUADRILATERAL)
    axes = np.array([False, True, False])
    points = _points(x, x_n)
    turned = symmetry_normals(points.normal, axes[None])
    assert np.linalg.norm(turned - points.normal) > 1e-2  # the facet's normal has a y component
    points = ClosestPoints(points.x_s, points.x_m, points.xi, points.interior, turned, points.du_s, points.du_m,
                           points.blocks, None, axes[None])
    K, W = pair_terms(points, lam[None])
    _, _, _, _, R, c = _exact(x, x_n, lam, axes)
    B = np.einsum("ik,j->ijk", R, c).reshape(3, -1)
    np.testing.assert_allclose(B + W[0], _central(lambda y: _exact(y, x_n, lam, axes)[2], x), atol=1e-8)
    np.testing.assert_allclose(K[0], _central(lambda y: _exact(y, x_n, lam, axes)[3], x), atol=1e-8)


@pytest.mark.parametrize("facet", [TRIANGLE, QUADRILATERAL], ids=["tri3", "quad4"])
def test_projection_onto_given_facets_is_the_single_facet_projection(facet):
    """project_onto_facets (all points at once, each on its own facet) gives, bit for bit, what
    project_points gives on that facet alone (keep_preferred's per-node projection)."""
    from dolfinx_nnqem.contact.projection import project_onto_facets

    rng = np.random.default_rng(3)
    facets = np.stack([facet + 0.3 * rng.standard_normal(3) for _ in range(4)])
    outward = newell_area_vectors(facets)
    points = facet.mean(axis=0) + 0.8 * rng.standard_normal((12, 3))
    which = rng.integers(0, 4, 12)
    q = project_onto_facets(points, facets, outward, which)
    for i, f in enumerate(which):
        one = project_points(points[i:i + 1], facets[f:f + 1], outward[f:f + 1])
        for name in ("xi", "N", "point", "normal", "g0", "distance", "tangential_offset"):
            assert np.array_equal(getattr(q, name)[i], getattr(one, name)[0]), name
    assert np.array_equal(q.facet, which)


def test_a_rank_without_pairs_gets_empty_terms():
    """On 3 ranks a rank may own no slave node of the interface: its terms are empty (the matrices they
    go into are assembled collectively, so it must still take part), not a failed reshape."""
    from dolfinx_nnqem.contact.surface_stiffness import surface_terms

    x, x_n, _ = _state(QUADRILATERAL)
    one = _points(x, x_n)
    none = ClosestPoints(*(getattr(one, f)[:0] for f in ("x_s", "x_m", "xi", "interior", "normal", "du_s", "du_m",
                                                         "blocks")))
    terms = surface_terms(none, np.zeros((0, 3)), np.zeros(0, dtype=np.int64))
    assert len(terms) == 0 and terms.columns.shape == (0, 15) and terms.K.shape == (0, 15, 15)
    assert terms.W.shape == (0, 3, 15)
