"""Geometry kernels of node-to-surface and dual mortar contact (no DOLFINx, no MPI).

Facets are built like ``surfaces.Facets``: quadrilaterals with their vertices in DOLFINx's
tensor-product order ((0,0), (1,0), (0,1), (1,1): not cyclic), outward area vectors given
separately. Every test prints the figure it checks (``pytest -s`` shows them).
"""

import time

import numpy as np
import pytest
from scipy.optimize import minimize

from dolfinx_nnqem.contact.mortar_geometry import couple_integrals, dual_coefficients, mortar_integrals, triangle_rule
from dolfinx_nnqem.contact.projection import (
    cyclic_order,
    facet_normals,
    newell_area_vectors,
    project_points,
    shape_derivatives,
    shape_functions,
)

TENSOR_TO_CYCLIC = [0, 1, 3, 2]


# --------------------------------------------------------------------------------------------
# Mesh helpers
# --------------------------------------------------------------------------------------------


def surface_grid(n, kind="quad", lo=(0.0, 0.0), hi=(1.0, 1.0), height=lambda x, y: 0.0 * x, up=True,
                 angle=0.0, offset=0):
    """A structured surface z = height(x, y) over a (rotated) rectangle, as (nodes, x, area).

    Quads come in tensor-product order; triangles split each cell along alternating diagonals.
    ``up``: outward normals along +z (else −z). ``angle`` rotates the rectangle about its centre.
    """
    nx, ny = (n, n) if np.isscalar(n) else n
    s, t = np.meshgrid(np.linspace(lo[0], hi[0], nx + 1), np.linspace(lo[1], hi[1], ny + 1), indexing="ij")
    c = 0.5 * (np.asarray(lo) + np.asarray(hi))
    X = c[0] + np.cos(angle) * (s - c[0]) - np.sin(angle) * (t - c[1])
    Y = c[1] + np.sin(angle) * (s - c[0]) + np.cos(angle) * (t - c[1])
    pts = np.column_stack([X.ravel(), Y.ravel(), height(X.ravel(), Y.ravel())])
    idx = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[:-1, 1:], idx[1:, 1:]], axis=-1)  # tensor order
    if kind == "quad":
        facets = quads.reshape(-1, 4)
    else:
        flip = (np.add.outer(np.arange(nx), np.arange(ny)) % 2).astype(bool)[..., None]
        a = np.where(flip, quads[..., [0, 1, 3]], quads[..., [0, 1, 2]])
        b = np.where(flip, quads[..., [0, 3, 2]], quads[..., [1, 3, 2]])
        facets = np.concatenate([a.reshape(-1, 3), b.reshape(-1, 3)])
    x = pts[facets]
    cyc = x[:, TENSOR_TO_CYCLIC] if kind == "quad" else x
    area = newell_area_vectors(cyc)
    area *= np.sign(area[:, 2])[:, None] * (1.0 if up else -1.0)
    return facets + offset, x, area


def nodal_values(nodes, x):
    """(unique node indices, their coordinates) of a facet array."""
    index, first = np.unique(nodes.ravel(), return_index=True)
    return index, x.reshape(-1, 3)[first]


# --------------------------------------------------------------------------------------------
# Shape functions, vertex order, dual functions
# --------------------------------------------------------------------------------------------


def test_cyclic_order_and_shape_functions():
    # a hexahedron's facet in DOLFINx order, seen from +z
    x = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]], dtype=float)
    perm_up = cyclic_order(x, [[0, 0, 1.0]])
    perm_down = cyclic_order(x, [[0, 0, -1.0]])
    print("cyclic order (outward +z):", perm_up[0], " (outward -z):", perm_down[0])
    assert perm_up[0].tolist() == [0, 1, 3, 2] and perm_down[0].tolist() == [0, 2, 3, 1]
    for k in (3, 4):
        xi = np.random.default_rng(k).uniform(-1, 1, (20, 2))
        N = shape_functions(k, xi)
        dN = shape_derivatives(k, xi)
        h = 1e-6
        fd = np.stack([(shape_functions(k, xi + h * e) - shape_functions(k, xi - h * e)) / (2 * h)
                       for e in np.eye(2)], axis=2)
        corners = shape_functions(k, [[0, 0], [1, 0], [0, 1]] if k == 3 else [[-1, -1], [1, -1], [1, 1], [-1, 1]])
        err = max(abs(N.sum(axis=1) - 1).max(), abs(dN - fd).max(), abs(corners - np.eye(k)).max())
        print(f"k = {k}: partition of unity, Kronecker property, derivatives vs FD: {err:.1e}")
        assert err < 1e-9
    # the normal follows the outward vector whatever the input order
    n = facet_normals(np.take_along_axis(x, perm_down[:, :, None], axis=1), [[0.2, 0.1]])
    assert np.allclose(n, [[0, 0, -1]])


def _high_order_integral(x_cyclic, f):
    """∫_e f(ξ) dA with a 6 × 6 Gauss rule (quads) or the degree-5 rule (triangles)."""
    k = x_cyclic.shape[0]
    if k == 4:
        g, w = np.polynomial.legendre.leggauss(6)
        xi = np.array([[a, b] for a in g for b in g])
        w = np.outer(w, w).ravel()
    else:
        bary, w = triangle_rule()
        xi, w = bary[:, 1:], 0.5 * w
    dN = shape_derivatives(k, xi)
    J = np.einsum("qka,kj->qaj", dN, x_cyclic)
    dA = w * np.linalg.norm(np.cross(J[:, 0], J[:, 1]), axis=1)
    return np.einsum("q,q...->...", dA, f(xi))


@pytest.mark.parametrize("k", [3, 4])
def test_biorthogonality(k):
    if k == 4:  # a strongly distorted planar quadrilateral, tilted in space
        x = np.array([[0.0, 0.0, 0.0], [2.0, 0.3, 0.0], [1.6, 1.9, 0.0], [-0.4, 1.1, 0.0]])
    else:
        x = np.array([[0.0, 0.0, 0.0], [1.7, 0.2, 0.0], [0.4, 1.3, 0.0]])
    rot = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    x = x @ rot.T + [0.3, -1.0, 2.0]
    A, D = dual_coefficients(x[None])
    A, D = A[0], D[0]

    def phi_n(xi):
        N = shape_functions(k, xi)
        return np.einsum("jl,ql,qk->qjk", A, N, N)

    integral = _high_order_integral(x, phi_n)
    ref = np.diag(_high_order_integral(x, lambda xi: shape_functions(k, xi)))
    err = abs(integral - ref).max() / D.max()
    print(f"k = {k}: max |∫ Φ_j N_k − δ_jk ∫ N_k| / max D = {err:.1e}")
    assert err < 1e-12
    if k == 3:  # Φ_j = 3 N_j − N_{j+1} − N_{j+2}
        assert np.allclose(A, 4 * np.eye(3) - 1, atol=1e-12)
    assert abs(D.sum() - _high_order_integral(x, lambda xi: np.ones(len(xi)))) < 1e-12


# --------------------------------------------------------------------------------------------
# Node-to-surface projection
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["quad", "tri"])
def test_projection_flat_plane(kind):
    _, x, area = surface_grid(7, kind, lo=(-1, -1), hi=(1, 2), height=lambda x, y: 0 * x + 0.25)
    rng = np.random.default_rng(1)
    p = np.column_stack([rng.uniform(-1, 1, 300), rng.uniform(-1, 2, 300), rng.uniform(-0.5, 1.0, 300)])
    P = project_points(p, x, area)
    recon = np.einsum("nk,nkj->nj", P.N, x[P.facet])  # N in the caller's vertex order
    err = max(abs(P.point - np.column_stack([p[:, :2], np.full(len(p), 0.25)])).max(),
              abs(P.g0 - (p[:, 2] - 0.25)).max(), abs(P.normal - [0, 0, 1]).max(),
              abs(recon - P.point).max(), P.tangential_offset.max())
    print(f"{kind}: flat plane, max error of closest point / g0 / normal / Σ N_k X_k: {err:.1e}")
    assert err < 1e-13
    # the facet found contains the point's foot
    assert np.all(P.N >= -1e-14)


def _reference_closest(x_cyclic, p):
    """Dense sampling of the warped quad's bilinear map, refined by a bounded optimiser."""
    g = np.linspace(-1, 1, 161)
    xi = np.array(np.meshgrid(g, g, indexing="ij")).reshape(2, -1).T
    X = shape_functions(4, xi) @ x_cyclic
    d2 = ((p[:, None, :] - X[None]) ** 2).sum(axis=2)
    out = []
    for i, start in enumerate(xi[d2.argmin(axis=1)]):
        f = lambda s, i=i: ((shape_functions(4, s) @ x_cyclic - p[i]) ** 2).sum()
        r = minimize(f, start, method="L-BFGS-B", bounds=[(-1, 1), (-1, 1)], options={"ftol": 1e-15, "gtol": 1e-12})
        out.append(np.sqrt(min(r.fun, d2[i].min())))
    return np.array(out)


def test_projection_warped_quad_against_dense_search():
    xc = np.array([[0.0, 0.0, 0.0], [1.0, 0.1, 0.12], [1.1, 0.9, -0.05], [-0.1, 1.2, 0.15]])
    x = xc[TENSOR_TO_CYCLIC][None]  # given in DOLFINx order; reordered by project_points
    outward = newell_area_vectors(xc[None])
    rng = np.random.default_rng(2)
    # half of the points above the facet (interior feet), half around it (edges, corners)
    p = np.vstack([np.column_stack([rng.uniform(0.1, 0.9, 100), rng.uniform(0.1, 1.0, 100), rng.uniform(-0.3, 0.3, 100)]),
                   np.column_stack([rng.uniform(-0.6, 1.6, 100), rng.uniform(-0.6, 1.8, 100), rng.uniform(-0.6, 0.6, 100)])])
    P = project_points(p, x, outward)
    ref = _reference_closest(xc, p)
    diff = P.distance - ref
    print(f"warped quad: distance − dense-search distance in [{diff.min():.1e}, {diff.max():.1e}]")
    assert diff.max() < 1e-12 and diff.min() > -1e-9  # never worse, never better than the true minimum
    interior = np.all(np.abs(P.xi) < 1 - 1e-9, axis=1)
    # at an interior closest point X_s − x(ξ) is normal to the surface: orthogonal to x_ξ, x_η
    dN = shape_derivatives(4, P.xi[interior])
    J = np.einsum("nka,kj->naj", dN, xc)
    r = p[interior] - P.point[interior]
    ortho = np.abs(np.einsum("naj,nj->na", J, r)).max()
    print(f"  {interior.sum()} interior feet: max |(X_s − x)·∂x/∂ξ| = {ortho:.1e}, "
          f"max tangential offset {P.tangential_offset[interior].max():.1e}; "
          f"{(~interior).sum()} on edges/corners")
    assert ortho < 1e-12 and P.tangential_offset[interior].max() < 1e-12
    assert np.all(np.einsum("nj,j->n", P.normal, outward[0]) > 0)
    assert np.allclose(P.N.sum(axis=1), 1.0)


def test_projection_edges_corners_and_ties():
    _, x, area = surface_grid(2, "quad", lo=(0, 0), hi=(2, 2))  # 4 unit quads, z = 0
    p = np.array([
        [1.0, 0.5, 0.3],   # above the edge x = 1 shared by facets 0 and 2
        [1.0, 1.0, -0.4],  # below the vertex shared by all four facets
        [2.5, 0.5, 0.2],   # beyond the surface's edge x = 2
        [2.5, 2.5, 0.0],   # beyond its corner (2, 2)
        [0.5, 0.5, 0.0],   # on the surface
    ])
    P = project_points(p, x, area)
    print("facets:", P.facet, " g0:", np.round(P.g0, 12), " tangential offsets:", np.round(P.tangential_offset, 12))
    assert P.facet[0] == 0 and P.facet[1] == 0  # ties: the lowest facet index
    assert np.allclose(P.point, [[1, 0.5, 0], [1, 1, 0], [2, 0.5, 0], [2, 2, 0], [0.5, 0.5, 0]], atol=1e-14)
    assert np.allclose(P.g0, [0.3, -0.4, 0.2, 0.0, 0.0]) and np.allclose(P.distance[2:4], [np.hypot(0.5, 0.2), np.sqrt(0.5)])
    assert np.allclose(P.tangential_offset, [0, 0, 0.5, np.sqrt(0.5), 0], atol=1e-14)
    # the tie is decided by the caller's order: reversed facet order gives the new lowest index
    rev = project_points(p[:2], x[::-1], area[::-1])
    print("reversed order:", rev.facet)
    assert rev.facet.tolist() == [1, 0] and np.allclose(rev.point, P.point[:2])
    # a ridge (convex edge between two inclined facets): outside it, the ridge, with a tie
    ridge = np.array([[[0, 0, 0], [1, 0, 0.5], [0, 1, 0], [1, 1, 0.5]],
                      [[1, 0, 0.5], [2, 0, 0], [1, 1, 0.5], [2, 1, 0]]], dtype=float)
    ridge_area = newell_area_vectors(ridge[:, TENSOR_TO_CYCLIC])
    R = project_points([[1.0, 0.5, 1.0], [0.0, 0.5, 10.0]], ridge, ridge_area)
    print("ridge: facets", R.facet, "points", R.point.tolist())
    assert R.facet.tolist() == [0, 0] and np.allclose(R.point[0], [1, 0.5, 0.5])
    # max_distance: far points get no facet
    far = project_points([[0.5, 0.5, 50.0], [0.5, 0.5, 0.1]], x, area, max_distance=1.0)
    assert far.facet.tolist() == [-1, 0] and np.isnan(far.g0[0])


# --------------------------------------------------------------------------------------------
# Dual mortar: single couples
# --------------------------------------------------------------------------------------------


def test_couple_coincident_and_mixed():
    sq = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)  # cyclic, outward +z
    A, D = dual_coefficients(sq[None])
    # a coincident master facet (outward −z): every edge coincides with a clip line
    M, g, cov, area = couple_integrals(sq, A[0], sq[::-1])
    err = abs(M - np.diag(D[0])[:, ::-1]).max()
    print(f"coincident quads: overlap area {area:.15f}, max |M − D δ| = {err:.1e}")
    assert abs(area - 1) < 1e-14 and err < 1e-15 and np.allclose(cov, D[0]) and abs(g).max() < 1e-15
    # a master facet that only touches along an edge, and one facing the same way: no couple
    assert couple_integrals(sq, A[0], (sq + [1, 0, 0])[::-1])[3] == 0.0
    assert couple_integrals(sq, A[0], sq + [0, 0, 0.1])[3] == 0.0
    # mixed sides: a quad slave under a tilted triangle (cyclic about its outward normal ≈ −z),
    # a triangle slave (outward +z) under a quad facing down
    tri_master = np.array([[0.2, -0.3, 0.1], [0.4, 1.5, 0.3], [1.4, 0.4, 0.2]])
    M, _, cov, area = couple_integrals(sq, A[0], tri_master)
    tri_slave = np.array([[0.2, -0.3, 0.0], [1.4, 0.4, 0.0], [0.4, 1.5, 0.0]])
    At, Dt = dual_coefficients(tri_slave[None])
    Mt, gt, _, area_t = couple_integrals(tri_slave, At[0], sq[::-1] + [0, 0, 0.5])
    print(f"quad slave / tri master: overlap {area:.6f}, Σ M = {M.sum():.6f}; "
          f"tri slave / quad master: overlap {area_t:.6f}, Σ M = {Mt.sum():.6f}, gaps {gt / Dt[0]}")
    assert area > 0 and abs(M.sum() - area) < 1e-13 and abs(cov.sum() - area) < 1e-13
    assert area_t > 0 and abs(Mt.sum() - area_t) < 1e-13 and abs(gt.sum() - 0.5 * area_t) < 1e-13


# --------------------------------------------------------------------------------------------
# Dual mortar: patch property, linear reproduction, gaps
# --------------------------------------------------------------------------------------------

SIDES = [("quad", "quad"), ("quad", "tri"), ("tri", "quad"), ("tri", "tri")]


@pytest.mark.parametrize("slave, master", SIDES)
def test_patch_full_cover(slave, master):
    """Flat interface, slave 4 × 4 on the unit square, master 3 × 3 rotated by 0.3 rad covering it."""
    d = 0.05
    sn, sx, sa = surface_grid(4, slave)
    mn, mx, ma = surface_grid(3, master, lo=(-0.2, -0.2), hi=(1.2, 1.2), angle=0.3,
                              height=lambda x, y: 0 * x + d, up=False, offset=1000)
    R = mortar_integrals(sn, sx, sa, mn, mx, ma)
    Msum = np.asarray(R.M.sum(axis=1)).ravel()
    # a linear master field u_k = a · x_k + b is reproduced at the slave nodes
    a, b = np.array([0.7, -1.3, 0.4]), 0.25
    mi, mxn = nodal_values(mn, mx)
    assert np.array_equal(mi, R.master_index)
    u = mxn @ a + b
    repro = abs(R.M @ u / R.D - (R.x @ a + b + a[2] * d)).max()  # the master lies at z = d
    figures = {
        "max |Σ_k M_jk − D_jj|": abs(Msum - R.D).max(),
        "|Σ D − area|": abs(R.D.sum() - 1.0),
        "|Σ M − covered area|": abs(R.M.sum() - 1.0),
        "linear reproduction": repro,
        "max |g0_j − d|": abs(R.g0 - d).max(),
        "max |coverage − 1|": abs(R.coverage - 1).max(),
    }
    print(f"{slave} slave / {master} master, {R.num_couples} couples: "
          + ", ".join(f"{k} = {v:.1e}" for k, v in figures.items()))
    assert max(figures.values()) < 1e-12
    assert R.num_failed_points == 0
    assert np.allclose(R.normal, [0, 0, 1])
    k, mjk = R.master_nodes_of(0)
    assert np.all(np.isin(k, mi)) and abs(mjk.sum() - R.D[0]) < 1e-12


@pytest.mark.parametrize("slave, master", [("quad", "quad"), ("tri", "tri")])
def test_patch_partial_cover(slave, master):
    """The master covers x >= 0.3 of the slave: covered area 0.7; nodes at x <= 0.5 partially or not covered."""
    d = -0.02  # slight initial penetration
    sn, sx, sa = surface_grid(4, slave)
    mn, mx, ma = surface_grid(3, master, lo=(0.3, -0.2), hi=(1.5, 1.2), height=lambda x, y: 0 * x + d,
                              up=False, offset=1000)
    R = mortar_integrals(sn, sx, sa, mn, mx, ma)
    fully = R.coverage > 1 - 1e-12
    partial = (R.coverage > 1e-12) & ~fully
    Msum = np.asarray(R.M.sum(axis=1)).ravel()
    a, b = np.array([0.7, -1.3, 0.4]), 0.25
    u = nodal_values(mn, mx)[1] @ a + b
    repro = abs((R.M @ u / R.D - (R.x @ a + b + a[2] * d))[fully]).max()
    figures = {
        "max |Σ_k M_jk − D_jj| (fully covered)": abs(Msum - R.D)[fully].max(),
        "|Σ M − 0.7|": abs(R.M.sum() - 0.7),
        "linear reproduction (fully covered)": repro,
        "max |g0_j − d| (fully covered)": abs(R.g0 - d)[fully].max(),
    }
    print(f"{slave}/{master}: {fully.sum()} fully, {partial.sum()} partially covered nodes "
          f"(coverage {np.unique(np.round(R.coverage[partial], 6))}), "
          + ", ".join(f"{k} = {v:.1e}" for k, v in figures.items()))
    assert max(figures.values()) < 1e-12
    assert np.all(R.coverage[R.x[:, 0] < 1e-12] == 0) and np.all(fully[R.x[:, 0] > 0.7])


def test_weighted_gap_sphere_cap_converges():
    """Flat slave under a sphere (radius 2) at distance 0.1: g0_j → the exact vertical gap, O(h²)."""
    Rs, d = 2.0, 0.1

    def cap(x, y):
        return d + Rs - np.sqrt(Rs**2 - x**2 - y**2)

    errors = []
    for n in (4, 8, 16, 32):
        sn, sx, sa = surface_grid(n, "quad", lo=(-0.5, -0.5), hi=(0.5, 0.5))
        m = 3 * n // 4  # non-matching, warped quads; a fixed ratio H / h keeps the rate clean
        mn, mx, ma = surface_grid(m, "quad", lo=(-0.6, -0.6), hi=(0.6, 0.6), height=cap, up=False, offset=10**6)
        R = mortar_integrals(sn, sx, sa, mn, mx, ma, search_distance=0.5)  # the default (a facet size) is too short
        assert np.all(R.coverage > 1 - 1e-12) and R.num_failed_points == 0
        exact = cap(R.x[:, 0], R.x[:, 1]) - R.x[:, 2]
        errors.append(abs(R.g0 - exact).max())
    rates = np.log2(np.array(errors[:-1]) / errors[1:])
    print("sphere cap: max |g0_j − exact| for n = 4, 8, 16, 32:", ", ".join(f"{e:.2e}" for e in errors),
          "; rates", np.round(rates, 2))
    assert np.all(rates > 1.7) and errors[-1] < 5e-4


def test_curved_interface_balance():
    """A curved (cylindrical) quad slave under a triangulated master offset by 0.01 vertically."""
    def cyl(x, y):
        return 0.3 * x**2

    sn, sx, sa = surface_grid(8, "quad", height=cyl)
    mn, mx, ma = surface_grid(13, "tri", lo=(-0.2, -0.2), hi=(1.2, 1.2), height=lambda x, y: cyl(x, y) + 0.01,
                              up=False, offset=1000)
    R = mortar_integrals(sn, sx, sa, mn, mx, ma)
    Msum = np.asarray(R.M.sum(axis=1)).ravel()
    rel = abs(Msum - R.D).max() / R.D.max()
    # exact distance along the nodal normal n from X to the master z = 0.3 x² + 0.01 (Newton in t)
    X, n = R.x, R.normal
    t = np.full(len(X), 0.01)
    for _ in range(20):
        xx = X[:, 0] + t * n[:, 0]
        t -= (X[:, 2] + t * n[:, 2] - cyl(xx, 0) - 0.01) / (n[:, 2] - 0.6 * xx * n[:, 0])
    err = abs(R.g0 - t).max()
    print(f"curved quad slave / tri master: max |Σ_k M_jk − D_jj| / max D = {rel:.1e}, coverage in "
          f"[{R.coverage.min():.6f}, {R.coverage.max():.6f}], max |g0_j − exact normal gap| = {err:.1e} "
          f"(gap {t.min():.5f} .. {t.max():.5f})")
    # every slave facet is planar and fully covered, so the patch property holds facet by facet
    assert rel < 1e-12 and abs(R.coverage - 1).max() < 1e-12 and err < 1e-3


def test_warped_slave_balance_converges():
    """Warped slave quads (a saddle z = 2 (x − ½)(y − ½)): Σ_k M_jk = D_jj up to the quadrature
    error of the plane-to-facet area ratio, which vanishes under refinement."""
    def saddle(x, y):
        return 2.0 * (x - 0.5) * (y - 0.5)

    errors = []
    for n in (4, 8, 16):
        sn, sx, sa = surface_grid(n, "quad", height=saddle)
        mn, mx, ma = surface_grid(n + 1, "quad", lo=(-0.2, -0.2), hi=(1.2, 1.2),
                                  height=lambda x, y: saddle(x, y) + 0.01, up=False, offset=10**5)
        R = mortar_integrals(sn, sx, sa, mn, mx, ma)
        errors.append((abs(np.asarray(R.M.sum(axis=1)).ravel() - R.D).max() / R.D.max(), abs(R.coverage - 1).max()))
    errors = np.array(errors)
    print("warped slave, n = 4, 8, 16: max |Σ_k M_jk − D_jj| / max D:", ", ".join(f"{e:.1e}" for e in errors[:, 0]),
          "; max |coverage − 1|:", ", ".join(f"{e:.1e}" for e in errors[:, 1]))
    assert np.all(errors[0] < 1e-4) and np.all(errors[1] < errors[0] / 10) and np.all(errors[2] < errors[1] / 10)


def _permute_vertices(nodes, x, seed):
    """The same facets with each facet's vertices in a random order."""
    perm = np.argsort(np.random.default_rng(seed).random(nodes.shape), axis=1)
    return np.take_along_axis(nodes, perm, axis=1), np.take_along_axis(x, perm[:, :, None], axis=1)


@pytest.mark.parametrize("slave, master", [("quad", "quad"), ("tri", "quad")])
def test_vertex_order_does_not_matter(slave, master):
    sn, sx, sa = surface_grid(5, slave, height=lambda x, y: 0.1 * x * y)
    mn, mx, ma = surface_grid(4, master, lo=(-0.1, -0.1), hi=(1.1, 1.1), angle=0.2,
                              height=lambda x, y: 0.1 * x * y + 0.02, up=False, offset=1000)
    R = mortar_integrals(sn, sx, sa, mn, mx, ma)
    Q = mortar_integrals(*_permute_vertices(sn, sx, 1), sa, *_permute_vertices(mn, mx, 2), ma)
    diff = max(abs(R.D - Q.D).max(), abs((R.M - Q.M).toarray()).max(), abs(R.weighted_gap - Q.weighted_gap).max(),
               abs(R.normal - Q.normal).max(), abs(R.coverage - Q.coverage).max())
    pts = R.x + [0.0, 0.0, 0.05]
    P = project_points(pts, mx, ma)
    _, px = _permute_vertices(mn, mx, 3)
    P2 = project_points(pts, px, ma)
    # N pairs with the caller's vertex order: Σ_k N_k X_k is the closest point in both orders
    recon = abs(np.einsum("nk,nkj->nj", P2.N, px[P2.facet]) - P.point).max()
    pdiff = max(abs(P.point - P2.point).max(), abs(P.g0 - P2.g0).max(), abs(P.normal - P2.normal).max())
    print(f"{slave}/{master}: mortar data differ by {diff:.1e}, projections by {pdiff:.1e} "
          f"(Σ N_k X_k in the permuted order: {recon:.1e}) after permuting every facet's vertices")
    assert diff < 1e-14 and pdiff < 1e-14 and recon < 1e-14


def test_input_validation():
    nodes, x, area = surface_grid(2, "quad")
    with pytest.raises(ValueError, match="3 or 4"):
        project_points([[0, 0, 1.0]], np.zeros((2, 5, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="do not match"):
        mortar_integrals(nodes[:, :3], x, area, nodes, x, -area)


# --------------------------------------------------------------------------------------------
# Performance
# --------------------------------------------------------------------------------------------


def test_performance_10k_facets():
    sn, sx, sa = surface_grid(100, "quad")
    mn, mx, ma = surface_grid(87, "quad", lo=(-0.01, -0.01), hi=(1.01, 1.01), angle=0.05, up=False, offset=10**6)
    mortar_integrals(*surface_grid(2, "quad"), *surface_grid(2, "quad", up=False, offset=100))  # compiled
    t0 = time.perf_counter()
    R = mortar_integrals(sn, sx, sa, mn, mx, ma)
    t1 = time.perf_counter()
    P = project_points(R.x, mx, ma)
    t2 = time.perf_counter()
    fully = R.coverage > 1 - 1e-12
    print(f"dual mortar: {len(sx)} slave quads x {len(mx)} master quads, {R.num_couples} couples: {t1 - t0:.2f} s; "
          f"projection of {len(R.x)} nodes: {t2 - t1:.2f} s; "
          f"max |Σ_k M_jk − D_jj| on {fully.sum()} fully covered nodes {abs(np.asarray(R.M.sum(axis=1)).ravel() - R.D)[fully].max():.1e}")
    assert np.all(P.facet >= 0)
