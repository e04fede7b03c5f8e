"""Dual mortar integrals on quadratic facets (issue 28; ``contact/dual_quadratic.py``).

* The dual basis on the transformed basis: biorthogonal to N̂ (∫Φ_j N̂_k dA = δ_jk ∫N̂_k dA), a
  partition of unity, every weight positive — where the plain tri6 basis has zero vertex weights.
* Flat non-matching surfaces (tri6 and quad9 slaves and masters, the master rotated): every slave
  node covered has Σ_k M_jk = D_jj, and a quadratic field f, which both sides represent exactly,
  gives Σ_k M_jk f(X_k) = D_jj f̂_j (f̂ = T⁻ᵀ f its transformed nodal values) to round-off: M is
  exact, not only its row sums.
* Partial cover: the covered area and the coverage of covered and uncovered nodes.
* Curved facets: two non-matching meshes of one paraboloid (which quadratic facets represent
  exactly): the nodal gaps, zero exactly, come out at O(h³) (linear mortar on the vertices: O(h²)),
  and Σ_k M_jk = D_jj holds to the quadrature error.
"""

import numpy as np
import pytest

from dolfinx_nnqem.contact import quadratic_facets as qf
from dolfinx_nnqem.contact.dual_quadratic import quadratic_dual_coefficients, quadratic_mortar_integrals


def quadratic_grid(n, k, lo=-0.5, hi=0.5, angle=0.0, offset=0, lift=lambda xy: np.zeros(len(xy)), up=True):
    """A structured surface of n × n squares (tri6: two triangles each) of [lo, hi]², rotated by
    ``angle`` about z, its nodes (vertices, edge midpoints, quad centres in the plane) lifted to
    z = lift(x, y): (nodes (m, k), x (m, k, 3), outward area vectors (m, 3), ±z by ``up``)."""
    h = (hi - lo) / (2 * n)  # the half step: every node is on the (2n + 1)² lattice
    def node(i, j):
        return offset + i * (2 * n + 1) + j

    rows = []
    for i in range(0, 2 * n, 2):
        for j in range(0, 2 * n, 2):
            if k == 9:
                v = [(i, j), (i + 2, j), (i, j + 2), (i + 2, j + 2)]
                rows.append(v + [((v[a][0] + v[b][0]) // 2, (v[a][1] + v[b][1]) // 2) for a, b in qf.EDGES[9]]
                            + [(i + 1, j + 1)])
            else:
                for v in ([(i, j), (i + 2, j), (i, j + 2)], [(i + 2, j + 2), (i, j + 2), (i + 2, j)]):
                    rows.append(v + [((v[a][0] + v[b][0]) // 2, (v[a][1] + v[b][1]) // 2) for a, b in qf.EDGES[6]])
    ij = np.array(rows)  # (m, k, 2)
    nodes = node(ij[..., 0], ij[..., 1])
    xy = lo + h * ij.astype(float)
    c, s = np.cos(angle), np.sin(angle)
    xy = xy @ np.array([[c, s], [-s, c]])
    x = np.concatenate([xy, lift(xy.reshape(-1, 2)).reshape(xy.shape[:2] + (1,))], axis=2)
    side = 1.0 if up else -1.0
    area = np.zeros((len(x), 3))
    area[:, 2] = side * (2 * h) ** 2 / (2 if k == 6 else 1)
    return nodes, x, area


def test_dual_basis_is_biorthogonal_to_the_transformed_basis():
    rng = np.random.default_rng(3)
    for k in (6, 9):
        nodes, x, area = quadratic_grid(1, k, lift=lambda xy: 0.3 * (xy ** 2).sum(axis=1))  # curved facets
        x = x + rng.normal(scale=0.02, size=x.shape)  # and distorted
        A, D = quadratic_dual_coefficients(x)
        err = {}
        for points in (qf.RULE_POINTS, 12):  # the rule A_e is built with, and a finer one
            xi, w = qf.reference_rule(k, points)
            dA = w * np.linalg.norm(qf.facet_geometry(x, xi)[1], axis=2)
            Nhat = qf.transformed_shape_functions(k, xi)
            phi = np.einsum("mjk,qk->mqj", A, Nhat)
            biorthogonal = np.einsum("mq,mqj,qk->mjk", dA, phi, Nhat)
            err[points] = np.abs(biorthogonal - D[:, :, None] * np.eye(k)).max() / D.max()
        print(f"\n  k = {k}: D_e / A = {np.round(D[0] / dA[0].sum(), 4).tolist()}; biorthogonality error {err}, "
              f"Σ_j Φ_j − 1: {np.abs(phi.sum(axis=2) - 1).max():.1e}")
        assert np.all(D > 0) and np.abs(phi.sum(axis=2) - 1).max() < 1e-11
        # exact for the rule it is built with; on these strongly curved, distorted facets the
        # rational area element costs that rule ~1e-7 against a finer one
        assert err[qf.RULE_POINTS] < 1e-12 and err[12] < 1e-5
    # the plain tri6 basis: the vertex weights vanish on a flat facet, no dual basis (why T is there)
    _, x, _ = quadratic_grid(1, 6)
    xi, w = qf.reference_rule(6)
    plain = np.einsum("q,qa->a", w, qf.shape_functions(6, xi))
    assert np.allclose(plain[:3], 0.0, atol=1e-15) and np.all(plain[3:] > 0)


def test_a_facet_too_distorted_for_a_dual_basis_is_refused():
    """A quad9 whose centre node is moved 0.33 of its side towards a corner: that corner's weight
    ∫N_j dA turns negative (−1.8e-4 of the area), the dual basis would be meaningless: refused, named."""
    from dolfinx_nnqem.contact.surfaces import ContactPairError

    _, x, _ = quadratic_grid(1, 9)
    x[0, 8, :2] += 0.30
    assert np.all(quadratic_dual_coefficients(x)[1] > 0)
    x[0, 8, :2] += 0.03
    with pytest.raises(ContactPairError, match=r"vertices \(-0.5, -0.5, 0\).*not positive: too distorted for dual mortar"):
        quadratic_dual_coefficients(x)


def quadratic_field(x):
    return 1.0 + 0.3 * x[..., 0] - 0.7 * x[..., 1] + 0.5 * x[..., 0] ** 2 - 0.4 * x[..., 0] * x[..., 1] \
        + 0.2 * x[..., 1] ** 2


@pytest.mark.parametrize("slave_k, master_k", [(6, 6), (9, 9), (6, 9), (9, 6)])
def test_flat_non_matching_surfaces_are_integrated_exactly(slave_k, master_k):
    """Slave 4 × 4 on [−½, ½]² at z = 0, master 3 × 3 on [−0.8, 0.8]² rotated 0.3 rad, at z = 0.05."""
    s_nodes, s_x, s_area = quadratic_grid(4, slave_k)
    m_nodes, m_x, m_area = quadratic_grid(3, master_k, -0.8, 0.8, angle=0.3, offset=10_000,
                                          lift=lambda xy: np.full(len(xy), 0.05), up=False)
    mi = quadratic_mortar_integrals(s_nodes, s_x, s_area, m_nodes, m_x, m_area, search_distance=0.5)
    assert mi.num_failed_points == 0
    m = np.asarray(mi.M.sum(axis=1)).ravel()
    rows = qf.node_combination(s_nodes, mi.slave_index)
    master_x = np.zeros((len(mi.master_index), 3))
    master_x[np.searchsorted(mi.master_index, m_nodes.ravel())] = m_x.reshape(-1, 3)
    f_hat = rows.apply(quadratic_field(mi.x))  # the transformed nodal values of f on the slave
    reproduction = np.abs(mi.M @ quadratic_field(master_x) - mi.D * f_hat).max() / mi.D.max()
    row_sums = np.abs(m / mi.D - 1).max()
    gap = np.abs(mi.weighted_gap / m - 0.05).max()
    print(f"\n  slave k = {slave_k}, master k = {master_k}: {mi.num_couples} couples; max |Σ_k M_jk / D_jj − 1| = "
          f"{row_sums:.1e}, max |Σ_k M_jk f_k − D_jj f̂_j| / max D = {reproduction:.1e}, gap error {gap:.1e}, "
          f"coverage in [{mi.coverage.min():.15f}, {mi.coverage.max():.15f}]")
    assert np.all(np.abs(mi.coverage - 1) < 1e-12)
    assert row_sums < 1e-12 and reproduction < 1e-13 and gap < 1e-14
    assert np.all(mi.D > 0) and np.allclose(mi.normal, [0.0, 0.0, 1.0], atol=1e-14)


@pytest.mark.parametrize("k", [6, 9])
def test_partial_cover(k):
    """The master covers x >= 0.3 of the slave [0, 1]² (4 × 4 facets): covered area 0.7 = Σ_jk M_jk
    (Σ_j Φ_j = 1); nodes whose facets lie in x >= 0.5 are covered fully (Σ_k M_jk = D_jj), those whose
    facets lie in x <= 0.25 not at all, and no partly covered node reports a coverage above 1 (the
    folded-master test: ∫_covered N̂_j dA / D_jj reaches 1.044 there, quad9 functions change sign)."""
    s_nodes, s_x, s_area = quadratic_grid(4, k, 0.0, 1.0)
    m_nodes, m_x, m_area = quadratic_grid(3, k, -0.1, 1.1, offset=10_000, lift=lambda xy: np.full(len(xy), 0.02),
                                          up=False)
    m_x[..., 0] += 0.4  # x in [0.3, 1.5]
    mi = quadratic_mortar_integrals(s_nodes, s_x, s_area, m_nodes, m_x, m_area, search_distance=0.5)
    m = np.asarray(mi.M.sum(axis=1)).ravel()
    covered = float(m.sum())
    full, none = mi.x[:, 0] > 0.5 + 1e-12, mi.x[:, 0] < 0.25 - 1e-12
    print(f"\n  k = {k}: covered area {covered:.15f} (0.7), coverage of the partly covered nodes "
          f"{np.round(np.sort(mi.coverage[~full & ~none]), 4).tolist()}")
    assert abs(covered - 0.7) < 1e-13 and mi.coverage.max() <= 1.0 + 1e-13
    assert np.allclose(mi.coverage[full], 1.0, atol=1e-13) and np.allclose(m[full], mi.D[full], rtol=1e-12)
    assert np.all(mi.coverage[none] == 0.0) and np.all(m[none] == 0.0)


def paraboloid_caps(n_slave, n_master, k, curvature=0.5):
    """Slave: z = c (x² + y²) over [−½, ½]²; master: the same paraboloid over [−0.7, 0.7]² rotated
    0.3 rad, meshed (n_master + ...) differently. Quadratic facets with their nodes on a paraboloid
    ARE the paraboloid (z is quadratic in x, y, which are linear in ξ): the two surfaces coincide
    exactly, so every gap the integration reports is its own error."""
    def lift(xy):
        return curvature * (xy ** 2).sum(axis=1)

    slave = quadratic_grid(n_slave, k, lift=lift)
    master = quadratic_grid(n_master, k, -0.7, 0.7, angle=0.3, offset=100_000, lift=lift, up=False)
    return slave, master


@pytest.mark.parametrize("k", [6, 9])
def test_curved_facets_gap_error_is_third_order(k):
    """Two non-matching meshes of the same curved surface (touching everywhere): the nodal gaps
    g̃_j / m_j vanish up to the correspondence error of the sub-facet segmentation, O(h³) (module
    docstring), where linear mortar on the facets' vertices has the O(h²) of its flat facets; and
    Σ_k M_jk = D_jj to the quadrature error on curved facets."""
    from dolfinx_nnqem.contact.mortar_geometry import mortar_integrals

    nv = qf.NUM_VERTICES[k]
    quadratic, linear, sums = [], [], []
    for n in (4, 8, 16):
        (s_nodes, s_x, s_area), (m_nodes, m_x, m_area) = paraboloid_caps(n, n + 1, k)
        mi = quadratic_mortar_integrals(s_nodes, s_x, s_area, m_nodes, m_x, m_area, search_distance=0.2)
        m = np.asarray(mi.M.sum(axis=1)).ravel()
        assert mi.num_failed_points == 0 and np.all(np.abs(mi.coverage - 1) < 1e-8)
        quadratic.append(np.abs(mi.weighted_gap / m).max())
        sums.append(np.abs(m / mi.D - 1).max())
        lin = mortar_integrals(s_nodes[:, :nv], s_x[:, :nv], s_area, m_nodes[:, :nv], m_x[:, :nv], m_area,
                               search_distance=0.2)
        linear.append(np.abs(lin.weighted_gap / np.asarray(lin.M.sum(axis=1)).ravel()).max())
    rate = np.log2(quadratic[1] / quadratic[2])
    print(f"\n  k = {k}, z = ½ (x² + y²), h = 1/4, 1/8, 1/16: max |g0_j| quadratic mortar "
          f"{[f'{e:.2e}' for e in quadratic]} (rate {rate:.2f}), linear mortar on the vertices "
          f"{[f'{e:.2e}' for e in linear]}; max |Σ_k M_jk / D_jj − 1| = {[f'{s:.1e}' for s in sums]}")
    assert rate > 2.3 and quadratic[-1] < 5e-6 and quadratic[-1] < 0.05 * linear[-1]
    assert max(sums) < 1e-9
