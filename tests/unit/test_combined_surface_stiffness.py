"""The consistent linearisation of node-to-surface pairs that combine slave nodes (P2 tetrahedra, issue 41)
against finite differences.

An edge node's pair acts on the node and its edge's two vertices (t = 1/(1 − 2α), −α/(1 − 2α) twice),
each projected onto its own curved 6-node triangle of the master: the edge node and one vertex onto
facet A, the other vertex onto facet B, which shares an edge (three nodes) with A. The gap
Σ_i t_i n_i · d_i, the two slips and the nodal forces Bᵀλ as functions of the 3 × 12 coordinates
(3 slave nodes, 9 master nodes), the closest points found again by the package's quadratic projection
at every perturbed configuration, against B + W and K of
:mod:`~dolfinx_nnqem.contact.combined_surface_stiffness`; also with the vertex on B beyond its curved
edge (its ξ slides along it).
"""

import numpy as np
import pytest

from dolfinx_nnqem.contact.combined_surface_stiffness import combined_pair_geometry, node_terms
from dolfinx_nnqem.contact.facet_layout import ALPHA
from dolfinx_nnqem.contact.mortar_linearisation import MortarPoints, mortar_terms
from dolfinx_nnqem.contact.quadratic_facets import facet_geometry, shape_functions
from dolfinx_nnqem.contact.quadratic_projection import project_points_quadratic
from dolfinx_nnqem.contact.surfaces import local_frames

UP = np.array([0.0, 0.0, 1.0])  # the facets' outward side
C = 1.0 - 2.0 * ALPHA[6]
T = np.array([1.0 / C, -ALPHA[6] / C, -ALPHA[6] / C])  # the edge node's row: the node, its edge's vertices
# the master's nodes in the parameter plane: P0, P1, P2, P3, then the edge nodes m12, m02, m01, m32, m13
PLANE = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [0.5, 0.5], [0, 0.5], [0.5, 0], [0.5, 1], [1, 0.5]], float)
FACETS = np.array([[0, 1, 2, 4, 5, 6], [1, 3, 2, 7, 4, 8]]) + 3  # tri6 order; positions in x (3 slave nodes first)
ON = np.array([0, 0, 1])  # each slave node's facet (A, A, B): the edge node first


def _master() -> np.ndarray:
    """The 9 master nodes on a warped, bent sheet (every second derivative of both facets non-zero)."""
    u, v = PLANE[:, 0], PLANE[:, 1]
    return np.column_stack([1.1 * u + 0.1 * v, 0.05 * u + 0.95 * v,
                            0.2 * u * (1 - u) - 0.15 * v * v + 0.1 * u * v + 0.02 * (v == 0.5)])


def _state(xi_b=(0.3, 0.45), offset_b=(0.02, 0.03, 0.12)):
    """All positions (3 slave nodes, 9 master nodes), the positions at u_n, λ."""
    master = _master()
    offsets = [(0.02, -0.03, 0.21), (-0.01, 0.02, 0.15), offset_b]
    points = [(0.35, 0.3), (0.15, 0.2), xi_b]
    slaves = [facet_geometry(master[FACETS[f] - 3][None], np.array([xi]))[0][0, 0] + np.array(o)
              for f, xi, o in zip(ON, points, offsets)]
    x = np.vstack([slaves, master])
    rng = np.random.default_rng(11)
    return x, x - 0.05 * rng.standard_normal(x.shape), np.array([-1.3, 0.4, -0.25])


def _projections(x: np.ndarray):
    return [project_points_quadratic(x[i][None], x[FACETS[f]][None], UP[None]) for i, f in enumerate(ON)]


def _coefficients(x: np.ndarray, projections) -> np.ndarray:
    """a_l over the 12 nodes: t_i at the slave nodes, −Σ_i t_i N_k(ξ_i) at the master nodes."""
    a = np.zeros(len(x))
    a[:3] = T
    for i, p in enumerate(projections):
        np.add.at(a, FACETS[ON[i]], -T[i] * shape_functions(6, p.xi)[0])
    return a


def _exact(x: np.ndarray, x_n: np.ndarray, lam: np.ndarray):
    """(gap, slip1, slip2) and the nodal forces a_l Rᵀλ at positions ``x``, and R, a."""
    projections = _projections(x)
    gap = sum(t * p.g0[0] for t, p in zip(T, projections))
    R = local_frames(projections[0].normal)[0]  # the edge node's own normal
    a = _coefficients(x, projections)
    slip = R[1:] @ (a @ (x - x_n))
    return np.concatenate([[gap], slip]), (a[:, None] * (R.T @ lam)[None, :]).ravel(), R, a


def _central(function, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    columns = []
    for i in range(x.size):
        e = np.zeros(x.size)
        e[i] = h
        columns.append((function(x + e.reshape(x.shape)) - function(x - e.reshape(x.shape))) / (2 * h))
    return np.stack(columns, axis=-1)


def _terms(x: np.ndarray, x_n: np.ndarray, lam: np.ndarray, interior: np.ndarray):
    projections = _projections(x)
    xi = np.vstack([p.xi for p in projections])
    normal = np.vstack([p.normal for p in projections])
    terms = node_terms(x[:3], x[FACETS[ON]], xi, interior, normal)
    blocks = np.column_stack([np.arange(3), FACETS[ON]])
    geometry = combined_pair_geometry(blocks, T, terms, terms.dn[0], held_open=False)
    assert np.array_equal(geometry.blocks, np.arange(12))  # the shared edge's nodes once
    (part,) = mortar_terms(MortarPoints([geometry], normal[:1], [x - x_n]), lam[None], np.array([0]))
    return part, geometry, projections


@pytest.mark.parametrize("beyond", [False, True], ids=["interior", "beyond-an-edge"])
def test_combined_pair_terms_match_finite_differences(beyond):
    """B + W and K of the combined pair within 1e-8 of central differences (interior feet of the normal,
    or the vertex on B beyond its curved edge P3–P2)."""
    x, x_n, lam = _state(*(((0.5, 0.5), (0.1, 0.15, 0.1)) if beyond else ()))
    interior = np.array([True, True, not beyond])
    part, geometry, projections = _terms(x, x_n, lam, interior)
    offsets = np.array([p.tangential_offset[0] for p in projections])
    assert np.all(offsets[:2] < 1e-12) and (offsets[2] > 0.05 if beyond else offsets[2] < 1e-12)
    _, _, R, a = _exact(x, x_n, lam)
    np.testing.assert_allclose(geometry.a, a, atol=1e-14)
    B = np.einsum("ik,j->ijk", R, a).reshape(3, -1)
    fd_rows = _central(lambda y: _exact(y, x_n, lam)[0], x)
    fd_forces = _central(lambda y: _exact(y, x_n, lam)[1], x)
    errors = np.abs(B + part.W[0] - fd_rows).max(), np.abs(part.K[0] - fd_forces).max()
    normals = [p.normal[0] for p in projections]
    print(f"\n  |B + W − FD| {errors[0]:.1e}, |K − FD| {errors[1]:.1e}; |W| {np.abs(part.W).max():.2f}, "
          f"|K| {np.abs(part.K).max():.2f}; the nodes' normals {np.degrees(np.arccos(normals[0] @ normals[2])):.1f}° "
          "apart")
    assert np.abs(part.W[0, 0]).max() > 1e-2 and np.abs(part.K).max() > 1e-2  # the terms are there
    assert max(errors) < 1e-8


def test_the_gap_takes_each_node_s_own_normal():
    """The gap's derivative is Σ_i t_i ∂(n_i · d_i): with one normal for all (the pair's, node j's) the
    differences disagree (the nodes' normals differ on the bent sheet)."""
    x, x_n, lam = _state()
    part, geometry, projections = _terms(x, x_n, lam, np.ones(3, dtype=bool))
    n = projections[0].normal[0]
    one_normal = lambda y: sum(t * n @ (y[i] - shape_functions(6, p.xi)[0] @ y[FACETS[ON[i]]])  # noqa: E731
                               for i, (t, p) in enumerate(zip(T, _projections(y))))
    fd = _central(lambda y: np.array([one_normal(y)]), x)[0]
    exact = _central(lambda y: _exact(y, x_n, lam)[0], x)[0]
    assert np.abs(fd - exact).max() > 1e-3
    assert np.abs(geometry.dg - exact).max() < 1e-8
