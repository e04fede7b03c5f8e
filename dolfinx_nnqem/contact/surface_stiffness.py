r"""The consistent linearisation of node-to-surface pairs in the current geometry (issues 41 and 43).

With ``Contact(..., discretisation="node-to-surface", geometry="current")`` the monolithic solver
re-evaluates the pairs at every Newton iterate, as it does a rigid obstacle's
(:meth:`~dolfinx_nnqem.contact.geometry_tracking.ContactGeometry.refresh_surfaces`): every pair
keeps its slave node s, and its closest point is found again on the moved master surface,
ξ on master facet f (which may be another facet than before), with the master's outward unit
normal n there and the frame R = (n, t1, t2). With the pair's nodes j = s, k₁ … k_m and the
weights c_s = 1, c_k = −N_k(ξ) (degree-1 facets: triangles, bilinear quadrilaterals), the
residuals of the pair are

    gap   g = n · d,      d = x_s − Σ_k N_k(ξ) x_k,
    slip  s_α = t_α · a,  a = Σ_j c_j Δu_j   (Δu = u − u_n: w_n is measured with the current rows),
    force F_j = c_j Rᵀλ   on node j (Bᵀλ: the slave node and the master nodes).

B holds R c_j in node j's columns; the consistent Newton matrix adds what B leaves out, the
motion of ξ and of n with the nodes x_j = X_j + u_j:

* the closest point. Stationarity d · a_α = 0 (a_α = ∂x/∂ξ_α = Σ_k ∂N_k/∂ξ_α x_k) gives

      A δξ = Σ_j G_j δx_j,   A_αβ = a_α · a_β − d · x_,αβ,   G_αj = a_α c_j + d ∂N_j/∂ξ_α

  (∂N_s = 0; x_,12 = Σ_k ¼ s_k t_k x_k for a quadrilateral, zero for a triangle). A slave node
  whose closest point is clamped to an edge of its facet (beyond the master's boundary, or kept
  on its facet past a shared edge, within the edge allowance) moves along the edge:
  ξ = (1 − t) ξ_e + t ξ_f, t = (x_s − x_e) · e / e · e with e = x_f − x_e; at a corner ξ is held.
* the normal n = ν/|ν|, ν = a₁ × a₂:  δn = (I − n nᵀ)/|ν| (δa₁ × a₂ + a₁ × δa₂),
  δa_α = Σ_k ∂N_k/∂ξ_α δx_k + x_,αβ δξ_β; the frame follows, δr_i = ∂r_i/∂n δn
  (:func:`~dolfinx_nnqem.contact.surfaces.local_frames_derivative`).

Then, per pair, with columns the 3 (1 + m) dofs of its nodes,

    W_n = −n · a_β ∂ξ_β/∂x + dᵀ ∂n/∂x                    (zero at an interior closest point),
    W_α = aᵀ ∂t_α/∂x − (t_α · Σ_k ∂N_k/∂ξ_β Δu_k) ∂ξ_β/∂x,
    K_j = c_j Σ_i λ_i ∂r_i/∂x − Rᵀλ (∂N_j/∂ξ_β ∂ξ_β/∂x)  (the rows of node j),

∂(gap, slip)/∂u = R c + W (the H rows get ∂H/∂w (B + W)) and ∂(Bᵀλ)/∂u = K at fixed λ (the u rows
get K_t − K). The same terms for a rigid obstacle are in
:mod:`~dolfinx_nnqem.contact.geometric_stiffness`; unlike those, K couples the slave node with the
master nodes, which the tangent's pattern does not hold (:func:`stiffness_matrix`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from petsc4py import PETSc

from dolfinx_nnqem.contact.facet_layout import QUADRATIC
from dolfinx_nnqem.contact.pairset import PairRows
from dolfinx_nnqem.contact.projection import (Projection, cyclic_order, project_onto_facets, project_points,
                                             reference_vertices,
                                             shape_derivatives, shape_functions)
from dolfinx_nnqem.contact.surface_pairs import SurfacePairs
from dolfinx_nnqem.contact.surfaces import (Facets, GatheredSurfaces, local_frames, local_frames_derivative,
                                            symmetry_normals)
from dolfinx_nnqem.contact.symmetry_planes import symmetry_axes

__all__ = ["ClosestPoints", "SurfaceTerms", "closest_point_derivatives", "closest_points", "pair_terms",
           "Supports", "reprojected_pairs", "stiffness_matrix", "surface_terms"]

INTERIOR = 1e-8
"""A closest point whose tangential offset (:attr:`~dolfinx_nnqem.contact.projection.Projection.tangential_offset`)
is at most this times the master's facet size is the foot of the normal (stationary: ξ moves with the
nodes); a larger one is clamped to the facet's boundary (ξ held)."""


def _twist(k: int) -> np.ndarray:
    """∂²N_a/∂ξ₁∂ξ₂ of the cyclic vertices: ¼ s_a t_a for a quadrilateral, 0 for a triangle."""
    if k == 3:
        return np.zeros(3)
    return 0.25 * np.array([1.0, -1.0, 1.0, -1.0])  # corners (−1,−1), (1,−1), (1,1), (−1,1)


def _cross_matrix(a: np.ndarray) -> np.ndarray:
    """[a]× (p, 3, 3): [a]× b = a × b."""
    out = np.zeros(a.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -a[..., 2], a[..., 1]
    out[..., 1, 0], out[..., 1, 2] = a[..., 2], -a[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -a[..., 1], a[..., 0]
    return out


def _node_weights(N: np.ndarray, dN: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(c_j (p, 1 + m), ∂N_j/∂ξ (p, 1 + m, 2)) over the pair's nodes: the slave node, then the master's."""
    p = len(N)
    c = np.concatenate([np.ones((p, 1)), -N], axis=1)
    dNj = np.concatenate([np.zeros((p, 1, 2)), dN], axis=1)
    return c, dNj


def _edge_derivative(x_s: np.ndarray, x_m: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """∂ξ/∂x (p, 2, c) of closest points clamped to the boundary of their facets.

    On an edge from vertex e to vertex f (straight, for either facet), ξ = (1 − t) ξ_e + t ξ_f with
    t = p · e / e · e, p = x_s − x_e, e = x_f − x_e, so δt e · e = e · (δx_s − δx_e) + (p − 2 t e) · (δx_f − δx_e);
    at a corner (t = 0 or 1) ξ is held.
    """
    q, m = x_m.shape[:2]
    corners = reference_vertices(m)
    start, end = corners, np.roll(corners, -1, axis=0)
    along = end - start  # (m, 2)
    t = np.einsum("pma,ma->pm", xi[:, None, :] - start[None], along) / np.sum(along ** 2, axis=1)
    off = np.linalg.norm(xi[:, None, :] - start[None] - np.clip(t, 0.0, 1.0)[:, :, None] * along[None], axis=2)
    edge = np.argmin(off, axis=1)
    rows = np.arange(q)
    t_e = np.clip(t[rows, edge], 0.0, 1.0)
    corner = (t_e < 1e-12) | (t_e > 1.0 - 1e-12)
    e_vertex, f_vertex = edge, (edge + 1) % m
    x_e, x_f = x_m[rows, e_vertex], x_m[rows, f_vertex]
    e = x_f - x_e
    r = x_s - x_e - 2.0 * t_e[:, None] * e
    dt = np.zeros((q, 1 + m, 3))
    dt[rows, 0] = e
    dt[rows, 1 + e_vertex] = -e - r
    dt[rows, 1 + f_vertex] += r
    dt /= np.sum(e * e, axis=1)[:, None, None]
    dt[corner] = 0.0
    return (along[edge][:, :, None, None] * dt[:, None]).reshape(q, 2, 3 * (1 + m))


def closest_point_derivatives(x_s: np.ndarray, x_m: np.ndarray, xi: np.ndarray, interior: np.ndarray
                              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """∂ξ/∂x and ∂n/∂x of closest points on degree-1 facets (module docstring).

    Parameters
    ----------
    x_s
        (p, 3) the slave nodes.
    x_m
        (p, m, 3) their master facets' vertices in cyclic order
        (:func:`~dolfinx_nnqem.contact.projection.cyclic_order`), m = 3 or 4.
    xi
        (p, 2) the closest points' local coordinates on those facets (cyclic order).
    interior
        (p,) True where ξ is the foot of the normal; elsewhere it is clamped to the facet's boundary.

    Returns
    -------
    (dxi (p, 2, c), dn (p, 3, c), n (p, 3)): the derivatives with respect to the c = 3 (1 + m) node
    coordinates (the slave node's, then the master vertices', each x, y, z), and n = a₁ × a₂ / |a₁ × a₂|.
    """
    p, m = x_m.shape[:2]
    N, dN = shape_functions(m, xi), shape_derivatives(m, xi)
    a = np.einsum("pka,pkj->paj", dN, x_m)  # a_α
    x12 = np.einsum("k,pkj->pj", _twist(m), x_m)  # x_,12
    d = x_s - np.einsum("pk,pkj->pj", N, x_m)
    c, dNj = _node_weights(N, dN)
    G = (a[:, :, None, :] * c[:, None, :, None]
         + d[:, None, None, :] * np.transpose(dNj, (0, 2, 1))[:, :, :, None]).reshape(p, 2, -1)
    A = np.einsum("paj,pbj->pab", a, a)
    twist = np.einsum("pj,pj->p", d, x12)
    A[:, 0, 1] -= twist
    A[:, 1, 0] -= twist
    dxi = np.linalg.solve(A, G) if p else np.zeros((0, 2, G.shape[2]))
    dxi[~interior] = _edge_derivative(x_s[~interior], x_m[~interior], xi[~interior])
    # δa_α = Σ_k ∂N_k/∂ξ_α δx_k + x_,12 δξ_(other)
    da = np.einsum("pja,il->paijl", dNj, np.eye(3)).reshape(p, 2, 3, -1)
    da[:, 0] += x12[:, :, None] * dxi[:, 1][:, None, :]
    da[:, 1] += x12[:, :, None] * dxi[:, 0][:, None, :]
    nu = np.cross(a[:, 0], a[:, 1])
    length = np.linalg.norm(nu, axis=1)
    n = nu / length[:, None]
    dnu = -_cross_matrix(a[:, 1]) @ da[:, 0] + _cross_matrix(a[:, 0]) @ da[:, 1]
    projector = (np.eye(3) - n[:, :, None] * n[:, None, :]) / length[:, None, None]
    return dxi, projector @ dnu, n


@dataclass(frozen=True)
class ClosestPoints:
    """Where the pairs of an interface project at the iterate (what :func:`pair_terms` needs).

    Attributes
    ----------
    x_s
        (p, 3) slave nodes.
    x_m
        (p, m, 3) their master facets' vertices, cyclic order.
    xi, interior
        (p, 2) the closest points (cyclic local coordinates); (p,) True where ξ is the foot of the normal.
    normal
        (p, 3) the pairs' normals (the master's outward normal at ξ).
    du_s, du_m
        (p, 3) and (p, m, 3): u − u_n at the slave node and the master vertices (cyclic order).
    blocks
        (p, 1 + m) global dof blocks of the slave node and the master vertices (cyclic order).
    beyond
        (p,) True where the slave node lies beyond the master's boundary by more than the edge
        allowance: the pair is held open (its gap a constant, :func:`reprojected_pairs`), None: none.
    turned
        (p, 3) True at the axes of a symmetry plane the pair's normal was turned into
        (:func:`~dolfinx_nnqem.contact.surfaces.symmetry_normals`: ``normal`` is then the turned one,
        the gap still n_f · d with the facet's normal n_f), None: no normal turned.
    """

    x_s: np.ndarray
    x_m: np.ndarray
    xi: np.ndarray
    interior: np.ndarray
    normal: np.ndarray
    du_s: np.ndarray
    du_m: np.ndarray
    blocks: np.ndarray
    beyond: np.ndarray | None = None
    turned: np.ndarray | None = None


def _turned_derivative(n_facet: np.ndarray, dn_facet: np.ndarray, turned: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """∂n/∂x of normals turned into symmetry planes: n = P n_f / |P n_f| (P drops the components of
    ``axes``) moves by (I − n nᵀ) P δn_f / |P n_f| where it was turned, by δn_f elsewhere."""
    P = (~axes).astype(float)
    projected = P * n_facet
    moved = np.linalg.norm(turned - n_facet, axis=1) > 0.0
    out = dn_facet.copy()
    length = np.linalg.norm(projected[moved], axis=1)
    projector = np.eye(3) - turned[moved][:, :, None] * turned[moved][:, None, :]
    out[moved] = projector @ (P[moved][:, :, None] * dn_facet[moved]) / length[:, None, None]
    return out


def pair_terms(points: ClosestPoints, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K (p, c, c), W (p, 3, c)) of the pairs at ``points`` with local forces ``lam`` (p, 3) (module
    docstring), columns as in :func:`closest_point_derivatives` (the slave node, then the master
    vertices in cyclic order)."""
    q = points
    m = q.x_m.shape[1]
    dxi, dn_facet, n_facet = _derivatives(m)(q.x_s, q.x_m, q.xi, q.interior)
    sign = np.sign(np.einsum("pj,pj->p", q.normal, n_facet))  # the pair's orientation
    n_facet, dn_facet = sign[:, None] * n_facet, sign[:, None, None] * dn_facet
    dn = dn_facet if q.turned is None else _turned_derivative(n_facet, dn_facet, q.normal, q.turned)
    R = local_frames(q.normal)
    dR = np.einsum("pikl,plc->pikc", local_frames_derivative(q.normal), dn)
    N, dN = _shapes(m, q.xi)
    a_facet = np.einsum("pka,pkj->paj", dN, q.x_m)
    d = q.x_s - np.einsum("pk,pkj->pj", N, q.x_m)
    c, dNj = _node_weights(N, dN)
    W = np.empty((len(N), 3, dxi.shape[2]))
    # g = n_f · d; B's normal row is n c_j (n = n_f unless turned into a symmetry plane)
    W[:, 0] = (-np.einsum("pj,paj,pac->pc", n_facet, a_facet, dxi) + np.einsum("pj,pjc->pc", d, dn_facet)
               + np.einsum("pj,pl->pjl", c, n_facet - q.normal).reshape(len(N), -1))
    if q.beyond is not None:  # a constant gap: W cancels B's normal row
        W[q.beyond, 0] = -np.einsum("pj,pl->pjl", c, q.normal)[q.beyond].reshape(-1, dxi.shape[2])
    a = q.du_s - np.einsum("pk,pkj->pj", N, q.du_m)
    s = np.einsum("pij,pbj->pib", R[:, 1:], np.einsum("pkb,pkj->pbj", dN, q.du_m))
    W[:, 1:] = np.einsum("pk,pikc->pic", a, dR[:, 1:]) - np.einsum("pib,pbc->pic", s, dxi)
    v = np.einsum("pi,pij->pj", lam, R)
    dv = np.einsum("pi,pijc->pjc", lam, dR)
    K = (np.einsum("pj,pic->pjic", c, dv)
         - np.einsum("pi,pjb,pbc->pjic", v, dNj, dxi)).reshape(len(N), -1, dxi.shape[2])
    return K, W


def _derivatives(m: int):
    """The closest point's and normal's derivatives for facets of m nodes: linear (3, 4) or quadratic
    (6, 9: :mod:`~dolfinx_nnqem.contact.quadratic_surface_stiffness`)."""
    if m in QUADRATIC:
        from dolfinx_nnqem.contact.quadratic_surface_stiffness import quadratic_closest_point_derivatives

        return quadratic_closest_point_derivatives
    return closest_point_derivatives


def _shapes(m: int, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N (p, m), ∂N/∂ξ (p, m, 2)) of facets of m nodes at ``xi``, in the facets' node order (linear
    facets: cyclic; quadratic ones: :mod:`~dolfinx_nnqem.contact.quadratic_facets`')."""
    if m in QUADRATIC:
        from dolfinx_nnqem.contact.quadratic_surface_stiffness import quadratic_shapes

        N, dN, _ = quadratic_shapes(m, xi)
        return N, dN
    return shape_functions(m, xi), shape_derivatives(m, xi)


@dataclass(frozen=True)
class SurfaceTerms:
    """The geometric blocks of node-to-surface pairs, in the columns of their rows of B.

    Attributes
    ----------
    pairs
        (k,) local pair indices (into the model's pairs).
    columns
        (k, c) the pairs' global columns, ascending (B's order for the pair).
    K
        (k, c, c) ∂(Bᵀλ)/∂u at fixed λ, rows and columns ``columns``.
    W
        (k, 3, c) ∂(gap, slip)/∂u − B.
    """

    pairs: np.ndarray
    columns: np.ndarray
    K: np.ndarray
    W: np.ndarray

    def __len__(self) -> int:
        return len(self.pairs)

    def add_rows(self, values: np.ndarray, rows: PairRows) -> np.ndarray:
        """``values`` in B's layout ``rows`` with W added on these pairs' rows (in place; returned)."""
        if len(self):
            c = self.columns.shape[1]
            start = rows.indptr[3 * self.pairs]
            if np.any(rows.indptr[3 * self.pairs + 3] - start != 3 * c):
                raise ValueError("SurfaceTerms: a pair's rows of B have other columns than its nodes'")
            values[start[:, None] + np.arange(3 * c)] += self.W.reshape(len(self), -1)
        return values


def stiffness_matrix(terms: Sequence[SurfaceTerms], free: Sequence[np.ndarray], template: PETSc.Mat) -> PETSc.Mat:
    """The blocks K of every pair of ``terms`` as a new matrix laid out like ``template`` (the tangent),
    rows and columns of constrained dofs left out (``free``: per terms, (k, c) 1 at free columns, 0 at
    constrained ones).

    Made as Sᵀ blockdiag(K_p) S, S picking each pair's columns (one 1 per row): PETSc's product sums
    the pairs' shares and sends the rows of master nodes owned by another rank there (collective).
    """
    comm = template.getComm()
    blocks = [mask[:, :, None] * part.K * mask[:, None, :] for part, mask in zip(terms, free)]
    columns = np.concatenate([np.zeros(0, dtype=np.int64)] + [part.columns.ravel() for part in terms])
    n = len(columns)
    offset = comm.tompi4py().exscan(n) or 0
    total = comm.tompi4py().allreduce(n)
    S = PETSc.Mat().createAIJWithArrays(
        size=((n, total), template.getSizes()[1]),
        csr=(np.arange(n + 1, dtype=PETSc.IntType), columns.astype(PETSc.IntType), np.ones(n)), comm=comm)
    indptr, index, values = [np.zeros(1, dtype=np.int64)], [np.zeros(0, dtype=np.int64)], [np.zeros(0)]
    start = offset
    for block in blocks:  # row r of pair p's block: the c columns of the pair
        k, c = block.shape[:2]
        first = start + c * np.arange(k)
        index.append(np.repeat(first, c * c) + np.tile(np.arange(c), k * c))
        indptr.append(indptr[-1][-1] + c * np.arange(1, k * c + 1))
        values.append(block.ravel())
        start += k * c
    K_pairs = PETSc.Mat().createAIJWithArrays(
        size=((n, total), (n, total)),
        csr=(np.concatenate(indptr).astype(PETSc.IntType), np.concatenate(index).astype(PETSc.IntType),
             np.concatenate(values)), comm=comm)
    G = K_pairs.PtAP(S)
    for m in (S, K_pairs):
        m.destroy()
    return G


def surface_terms(points: ClosestPoints, lam: np.ndarray, pairs: np.ndarray) -> SurfaceTerms:
    """The :class:`SurfaceTerms` of the local pairs ``pairs`` at ``points`` with forces ``lam``, their
    columns put in B's (ascending) order. A rank without pairs (on 3 ranks, the slave surface may lie on
    two of them) gets empty terms with the pair's c = 3 (1 + m) columns."""
    if len(points.blocks) == 0:
        c = 3 * points.blocks.shape[1]
        return SurfaceTerms(np.zeros(0, dtype=np.int64), np.zeros((0, c), dtype=np.int64), np.zeros((0, c, c)),
                            np.zeros((0, 3, c)))
    K, W = pair_terms(points, lam)
    order = np.argsort(points.blocks, axis=1, kind="stable")
    take = (3 * order[:, :, None] + np.arange(3)).reshape(len(order), -1)
    K = np.take_along_axis(np.take_along_axis(K, take[:, :, None], axis=1), take[:, None, :], axis=2)
    W = np.take_along_axis(W, take[:, None, :], axis=2)
    blocks = np.take_along_axis(points.blocks, order, axis=1)
    columns = (3 * blocks[:, :, None] + np.arange(3)).reshape(len(order), -1)
    return SurfaceTerms(np.asarray(pairs, dtype=np.int64), columns.astype(np.int64), K, W)


def closest_points(x_s: np.ndarray, master: Facets, preferred: np.ndarray, allowance: float,
                   size: float) -> tuple[Projection, np.ndarray, np.ndarray]:
    """The slave nodes ``x_s`` projected onto the ``master`` facets (at their current positions), a node
    kept on its ``preferred`` facet where its closest point there is within ``allowance`` of the facet
    and of the best distance (the rule of :func:`~dolfinx_nnqem.contact.node_to_surface.keep_preferred`,
    for all nodes at once); (projection, cyclic vertex order of each node's facet, interior flags: the
    foot of the normal, within :data:`INTERIOR` × ``size``)."""
    p = project_points(x_s, master.x, master.area)
    changed = np.flatnonzero((preferred >= 0) & (p.facet != preferred))
    if len(changed):
        q = project_onto_facets(x_s[changed], master.x, master.area, preferred[changed])
        best = np.where(p.facet[changed] >= 0, p.distance[changed], np.inf)
        keep = (q.tangential_offset <= allowance) & (q.distance <= best + allowance)
        p = Projection(*(np.array(a, copy=True) for a in (p.facet, p.xi, p.N, p.point, p.normal, p.g0, p.distance,
                                                            p.tangential_offset)))
        for name in ("facet", "xi", "N", "point", "normal", "g0", "distance", "tangential_offset"):
            getattr(p, name)[changed[keep]] = getattr(q, name)[keep]
    order = cyclic_order(master.x[p.facet], master.area[p.facet])
    return p, order, p.tangential_offset <= INTERIOR * size


def reprojected_pairs(pairs: SurfacePairs, reference: GatheredSurfaces, moved: GatheredSurfaces, u_n_slave: np.ndarray,
                      u_n_master: np.ndarray, gap_rounding: float, allowance: float, size: float,
                      supports: Supports | None = None) -> tuple[SurfacePairs, ClosestPoints]:
    """The node-to-surface ``pairs`` (the same slave nodes, in the same order) projected again onto the
    moved master surface, and their :class:`ClosestPoints`.

    Parameters
    ----------
    pairs
        The interface's :class:`~dolfinx_nnqem.contact.surface_pairs.SurfacePairs`.
    reference, moved
        The gathered surfaces (master, slave) at rest and at X + u.
    u_n_slave, u_n_master
        (p, 3) u_n at the pairs' slave nodes; (m, k, 3) at the master facets' vertices (gathered order).
    gap_rounding, allowance, size
        Gaps within ``gap_rounding`` are zero; the edge allowance of a preferred facet; the master's
        facet size.
    supports
        The prescribed components of the pairs' slave nodes and of the master's vertices: the
        normals of slave nodes on a symmetry plane of the interface are turned into it, as the
        re-evaluation between solves does (:mod:`~dolfinx_nnqem.contact.symmetry_planes`). None: no
        support is known.

    Returns
    -------
    (SurfacePairs, ClosestPoints): the pairs with their facets, weights N_k(ξ), frames, rows and
    gaps g0 = g − (B u)_n of the iterate (so that g0 + (B u)_n is the current gap g), and where they
    project. A slave node now beyond the master's boundary by more than ``allowance`` keeps its pair
    within the solve (the pair unknowns' layout is fixed) with the gap g = ``size``: the pair opens, as
    if dropped, which the re-evaluation between solves then does
    (:func:`~dolfinx_nnqem.contact.node_to_surface.node_to_surface_pairs`), so that the next solve
    starts converged.
    """
    master, master_ref = moved.facets_of(0), reference.facets_of(0)
    slaves = np.searchsorted(moved.nodes[1].index, pairs.slave_blocks)
    x_s = moved.nodes[1].x[slaves]
    u_s = x_s - reference.nodes[1].x[slaves]
    assert pairs.master_facet is not None  # node-to-surface pairs carry it
    if master.degree == 2:  # the facets' own node order (quadratic_facets), curved or not
        from dolfinx_nnqem.contact.quadratic_surface_stiffness import quadratic_closest_points

        p, order, interior = quadratic_closest_points(x_s, master, pairs.master_facet, allowance, size, INTERIOR)
    else:
        p, order, interior = closest_points(x_s, master, pairs.master_facet, allowance, size)
    f, k = p.facet, master.x.shape[1]
    u_m = master.x[f] - master_ref.x[f]  # caller's vertex order, like N
    g = np.where(np.abs(p.g0) <= gap_rounding, 0.0, p.g0)
    beyond = p.tangential_offset > allowance
    g[beyond] = size  # held open: the next re-evaluation between solves drops the pair
    normal, turned = _pair_normals(p, x_s, master, supports)
    g0 = g - np.einsum("pj,pj->p", normal, u_s - np.einsum("pk,pkj->pj", p.N, u_m))
    R = local_frames(normal) if len(f) else np.zeros((0, 3, 3))
    nodes = np.concatenate([pairs.slave_blocks[:, None], master.nodes[f]], axis=1)
    coefficients = np.concatenate([np.ones((len(f), 1)), -p.N], axis=1)
    rows = PairRows.from_weighted_nodes(R, np.arange(0, (k + 1) * len(f) + 1, k + 1), nodes.ravel(),
                                        coefficients.ravel())
    new = replace(pairs, master_blocks=master.nodes[f].ravel(), weights=p.N.ravel(), X_master=p.point, R=R,
                  g0=g0, rows=rows, master_facet=f.copy())
    cyclic = order[:, :, None]
    du_m = np.take_along_axis(u_m - u_n_master[f], cyclic, axis=1)
    points = ClosestPoints(x_s, np.take_along_axis(master.x[f], cyclic, axis=1), p.xi, interior, normal,
                           u_s - u_n_slave, du_m,
                           np.concatenate([pairs.slave_blocks[:, None], np.take_along_axis(master.nodes[f], order,
                                                                                           axis=1)], axis=1),
                           beyond, turned)
    return new, points


@dataclass(frozen=True)
class Supports:
    """The prescribed components of an interface's nodes (for its symmetry planes).

    Attributes
    ----------
    slave
        (p, 3) bool: of the pairs' slave nodes.
    master
        (m, k, 3) bool: of the gathered master facets' vertices.
    in_plane
        The distance within which a master node lies in a slave node's plane
        (:data:`~dolfinx_nnqem.contact.symmetry_planes.IN_PLANE` × the master's facet size).
    """

    slave: np.ndarray
    master: np.ndarray
    in_plane: float


def _pair_normals(p: Projection, x_s: np.ndarray, master: Facets, supports: Supports | None
                  ) -> tuple[np.ndarray, np.ndarray | None]:
    """(the pairs' normals, the symmetry axes they were turned into or None): the facet normals, turned
    into the symmetry planes of the interface where a slave node lies on one
    (:func:`~dolfinx_nnqem.contact.symmetry_planes.symmetry_axes`)."""
    if supports is None or not supports.slave.any():
        return p.normal, None
    f, k = p.facet, master.x.shape[1]
    axes = symmetry_axes(supports.slave, x_s, np.arange(0, k * len(f) + 1, k), master.x[f].reshape(-1, 3),
                         supports.master[f].reshape(-1, 3), supports.in_plane)
    return symmetry_normals(p.normal, axes), axes
