r"""The consistent linearisation of dual mortar pairs in the current geometry (issues 41 and 43).

With ``Contact(..., discretisation="mortar", geometry="current")`` the monolithic solver (direct
linear solver) re-evaluates the mortar integrals at every Newton iterate, as it does node-to-surface
pairs (:mod:`~dolfinx_nnqem.contact.surface_stiffness`): the pairs of the solve keep their slave
nodes j, and the segments, the dual basis, M and g̃ are integrated again on the moved facets
(:mod:`~dolfinx_nnqem.contact.mortar_geometry`). Pair j's residuals (:mod:`~dolfinx_nnqem.contact.mortar`)
are, with its nodes i and the coefficients a_j = 1 (the slave node), a_k = −c_jk = −M_jk / m_j
(master nodes), m_j = Σ_k M_jk, and a_i = 0 at the other nodes its geometry depends on (the
vertices of the slave facets around j and of the master facets they couple with),

    gap   g = g̃_j / m_j,
    slip  s_α = t_α · Σ_i a_i Δu_i     (Δu = u − u_n),
    force F_i = a_i Rᵀλ                (Bᵀλ),

with the frame R = (n, t1, t2) on the averaged nodal normal n = −ν/|ν|, ν = Σ_e a_e (the Newell area
vectors of the slave facets e around j, pointing to the master). B holds R a_i in node i's columns;
the consistent Newton matrix adds the motion of a_i, g and n with the nodes x = X + u:

    W_n = ∂g/∂x − n a,   W_α = (Σ_i a_i Δu_i)ᵀ ∂t_α/∂x + Σ_i (t_α · Δu_i) ∂a_i/∂x,
    K_i = a_i Σ_r λ_r ∂r_r/∂x + Rᵀλ ⊗ ∂a_i/∂x           (the rows of node i),

∂(gap, slip)/∂u = B + W and ∂(Bᵀλ)/∂u = K at fixed λ (the same blocks as node-to-surface:
:class:`~dolfinx_nnqem.contact.surface_stiffness.SurfaceTerms`, the u rows get K_t − K), with

    ∂g/∂x = (∂g̃_j − g ∂m_j) / m_j,   ∂c_jk/∂x = (∂M_jk − c_jk ∂m_j) / m_j,   ∂m_j = Σ_k ∂M_jk.

Which parts are analytic and which are complex steps:

* analytic: the chain rule above (the coefficients, the gap, the rows, the forces, the frame on n),
  and the nodal normal: δa_e = ½ Σ_i δx_i × (x_{i+1} − x_{i−1}) over the cyclic vertices of facet e,
  δn = −(I − n nᵀ) δν / |ν|; turned into a symmetry plane (the master held on it too,
  :mod:`~dolfinx_nnqem.contact.symmetry_planes`), n = P n_f / |P n_f| moves by
  (I − n nᵀ) P δn_f / |P n_f|;
* the complex step of the LOCAL couple integrals: ∂M_c and ∂g̃_c of every candidate couple c (slave
  facet e, master facet f) with respect to the 3 (k_e + k_f) coordinates of its vertices, each
  coordinate moved by i :data:`STEP` × the slave surface's facet size and the couple integrated
  again in complex arithmetic, its dual coefficients A_e included
  (:func:`~dolfinx_nnqem.contact.couple_complex_step.couple_derivatives`): exact to round-off, where
  Popp, Gee and Wall (2009) differentiate the clip polygon's vertices, the Gauss points' inverse maps
  and the dual coefficients by hand. A couple that does not count at x has zero derivatives (the
  branch the real evaluation takes; at an edge of the master exactly on one of the slave the
  derivative is that branch's, one-sided). Before, central differences (:func:`couple_differences`,
  ± :data:`DIFFERENCE_STEP` × the facet size) stood in for them, to ~1e-10 relative.

A pair whose node is covered less than :data:`~dolfinx_nnqem.contact.mortar.MIN_COVERED` at an
iterate keeps its pair within the solve (the pair unknowns' layout is fixed) with the gap g = the
master's facet size: the pair opens, as node-to-surface pairs beyond the master do, and the
re-evaluation between solves then drops it. Nodes newly covered get their pair there too.

Quadratic facets (degree 2: quad9, tri6) take the same chain rule with their own couple integrals,
nodal normals and slave sides (:mod:`~dolfinx_nnqem.contact.quadratic_mortar_linearisation`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from dolfinx_nnqem.contact.couple_complex_step import COMPLEX_STEP, couple_derivatives
from dolfinx_nnqem.contact.mortar import MIN_COVERED
from dolfinx_nnqem.contact.mortar_geometry import (MIN_FACING_COSINE, RELATIVE_TOLERANCE, MortarIntegrals,
                                                   _integrate_couples, candidate_couples, dual_coefficients,
                                                   mortar_integrals, triangle_rule)
from dolfinx_nnqem.contact.pairset import PairRows
from dolfinx_nnqem.contact.projection import _cyclic
from dolfinx_nnqem.contact.surface_pairs import SurfacePairs, facet_size
from dolfinx_nnqem.contact.surface_stiffness import SurfaceTerms
from dolfinx_nnqem.contact.surfaces import GatheredSurfaces, local_frames, local_frames_derivative

if TYPE_CHECKING:
    import dolfinx

__all__ = ["DIFFERENCE_STEP", "STEP", "CoupleDerivatives", "MortarPoints", "couple_derivatives", "couple_differences",
           "interface_derivatives", "mortar_terms", "newell_derivative", "remortared_pairs"]

STEP = COMPLEX_STEP
"""The couple derivatives' imaginary step, relative to the slave surface's facet size: a vertex coordinate
(:func:`couple_derivatives`) or, on quadratic facets, an in-plane point
(:mod:`~dolfinx_nnqem.contact.quadratic_mortar_linearisation`) moved by i × this × the facet size."""

DIFFERENCE_STEP = 1e-6
"""The step of :func:`couple_differences` (relative to the facet size) the linearisation took before the
complex step: its truncation error ~ DIFFERENCE_STEP², its round-off ~ 1e-16 / DIFFERENCE_STEP, relative."""


def couple_differences(xs: np.ndarray, xm: np.ndarray, ci: np.ndarray, cj: np.ndarray, step: float,
                       relative_tolerance: float = RELATIVE_TOLERANCE,
                       min_facing_cosine: float = MIN_FACING_COSINE) -> tuple[np.ndarray, np.ndarray]:
    """Central differences of the integrals of couples (slave facet ``ci``, master facet ``cj``): what the
    linearisation took before the complex step (:func:`couple_derivatives`); kept as the reference its
    test and ``benchmarks/mortar_derivatives.py`` measure it against.

    Parameters
    ----------
    xs, xm
        (ms, ks, 3) and (mm, km, 3): the slave and master facets' vertices, cyclic
        (:func:`~dolfinx_nnqem.contact.mortar_geometry.couple_integrals`).
    ci, cj
        (c,) the couples.
    step
        The length a coordinate is moved by, each way.

    Returns
    -------
    (dM (c, ks, km, P), dg (c, ks, P)): ∂M_c and ∂g̃_c with respect to the P = 3 (ks + km) vertex
    coordinates (the slave facet's vertices, then the master's, each x, y, z); the dual coefficients
    of a moved slave facet are computed again (once per slave facet and coordinate).
    """
    c, ks, km = len(ci), xs.shape[1], xm.shape[1]
    P, S = 3 * (ks + km), 3 * ks
    e = step * np.eye(P)[None]
    x = np.concatenate([xs[ci], xm[cj]], axis=1).reshape(c, 1, P)
    moved = np.concatenate([x + e, x - e], axis=1).reshape(-1, ks + km, 3)  # (c·2P): +h each, then −h each
    xs_p, xm_p = np.ascontiguousarray(moved[:, :ks]), np.ascontiguousarray(moved[:, ks:])
    A0 = dual_coefficients(xs)[0]  # (ms, ks, ks); moved slave facets: (ms, 2, S, ks, ks)
    facets = xs.reshape(-1, 1, S)
    A_moved = dual_coefficients(np.concatenate([facets + e[:, :S, :S], facets - e[:, :S, :S]], axis=1)
                                .reshape(-1, ks, 3))[0].reshape(len(xs), 2, S, ks, ks)
    A = np.broadcast_to(A0[ci][:, None, None], (c, 2, P, ks, ks)).copy()
    A[:, :, :S] = A_moved[ci]
    A = np.ascontiguousarray(A.reshape(-1, ks, ks))
    qb, qw = triangle_rule()
    every = np.arange(len(moved), dtype=np.int64)
    M, g, _, _, _ = _integrate_couples(every, every, xs_p, A, xm_p, qb, qw, relative_tolerance, min_facing_cosine)
    M, g = M.reshape(c, 2, P, ks, km), g.reshape(c, 2, P, ks)
    dM = (M[:, 0] - M[:, 1]).transpose(0, 2, 3, 1) / (2.0 * step)
    dg = (g[:, 0] - g[:, 1]).transpose(0, 2, 1) / (2.0 * step)
    return dM, dg


def newell_derivative(x_cyclic: np.ndarray) -> np.ndarray:
    """∂a/∂x (m, 3, 3k) of the Newell area vectors a = ½ Σ_i x_i × x_{i+1} of facets (m, k, 3) (cyclic):
    δa = ½ Σ_i δx_i × (x_{i+1} − x_{i−1}) = −½ Σ_i [x_{i+1} − x_{i−1}]× δx_i."""
    m, k = x_cyclic.shape[:2]
    v = np.roll(x_cyclic, -1, axis=1) - np.roll(x_cyclic, 1, axis=1)  # (m, k, 3)
    cross = np.zeros((m, k, 3, 3))
    cross[..., 0, 1], cross[..., 0, 2] = -v[..., 2], v[..., 1]
    cross[..., 1, 0], cross[..., 1, 2] = v[..., 2], -v[..., 0]
    cross[..., 2, 0], cross[..., 2, 1] = -v[..., 1], v[..., 0]
    return (-0.5 * cross).transpose(0, 2, 1, 3).reshape(m, 3, 3 * k)


@dataclass(frozen=True)
class CoupleDerivatives:
    """The mortar integrals of an interface at x and the derivatives of its couples' integrals.

    Attributes
    ----------
    integrals
        :func:`~dolfinx_nnqem.contact.mortar_geometry.mortar_integrals` at x.
    slave_nodes, master_nodes
        (ms, ks), (mm, km) global dof blocks of the facets' vertices, cyclic.
    slave_x
        (ms, ks, 3) the slave facets' vertices, cyclic.
    couples
        (c, 2) the candidate couples (slave facet, master facet).
    dM, dg
        :func:`couple_derivatives` of the couples.
    """

    integrals: MortarIntegrals
    slave_nodes: np.ndarray
    master_nodes: np.ndarray
    slave_x: np.ndarray
    couples: np.ndarray
    dM: np.ndarray
    dg: np.ndarray


def interface_derivatives(moved: GatheredSurfaces, search_distance: float | None,
                          slave_blocks: np.ndarray | None = None) -> CoupleDerivatives:
    """The mortar integrals of the moved surfaces (master, slave) and their couples' derivatives (the
    same candidate couples and search distance as :func:`~dolfinx_nnqem.contact.mortar.mortar_pairs`);
    only the couples whose slave facet holds one of the nodes ``slave_blocks`` (a rank's pairs) are
    differentiated and kept (None: every couple)."""
    master, slave = moved.facets_of(0), moved.facets_of(1)
    if search_distance is None:
        search_distance = 2.0 * max(facet_size(master), facet_size(slave))
    mi = mortar_integrals(slave.nodes, slave.x, slave.area, master.nodes, master.x, master.area,
                          search_distance=search_distance)
    xs, perm_s = _cyclic(slave.x, slave.area)
    xm, perm_m = _cyclic(master.x, master.area)
    ci, cj = candidate_couples(xs, xm, float(search_distance))
    nodes_s = np.take_along_axis(slave.nodes, perm_s, axis=1)
    if slave_blocks is not None:
        wanted = np.isin(nodes_s[ci], slave_blocks).any(axis=1)
        ci, cj = ci[wanted], cj[wanted]
    dM, dg = couple_derivatives(xs, xm, ci, cj, STEP * facet_size(slave))
    return CoupleDerivatives(mi, nodes_s, np.take_along_axis(master.nodes, perm_m, axis=1), xs,
                             np.column_stack([ci, cj]), dM, dg)


@dataclass(frozen=True)
class PairGeometry:
    """One mortar pair's nodes and the derivatives of its coefficients, gap and normal.

    ``blocks`` (c,) ascending global dof blocks; ``a`` (c,) the coefficients a_i; ``da`` (c, 3c),
    ``dg`` (3c,) and ``dn`` (3, 3c) their, the gap's and the normal's derivatives."""

    blocks: np.ndarray
    a: np.ndarray
    da: np.ndarray
    dg: np.ndarray
    dn: np.ndarray


class _Incidence:
    """Which (couple, slave vertex) entries and which slave facets hold each slave node."""

    def __init__(self, cd: CoupleDerivatives):
        self._index(cd)
        d = cd.slave_x - cd.slave_x[:, :1]
        self.area = 0.5 * np.cross(d, np.roll(d, -1, axis=1)).sum(axis=1)  #: (ms, 3) the slave facets' Newell vectors
        self.d_area = newell_derivative(cd.slave_x)  #: (ms, 3, 3 ks) their derivatives

    def _index(self, cd: CoupleDerivatives) -> None:
        """Sort the (couple, slave vertex) entries and the slave facets' nodes by node."""
        ks = cd.slave_nodes.shape[1]
        at = cd.slave_nodes[cd.couples[:, 0]].ravel()  # (c·ks,) the node of entry (couple, vertex)
        self._entry_order = np.argsort(at, kind="stable")
        self._entry_nodes = at[self._entry_order]
        self._ks = ks
        facets = cd.slave_nodes.ravel()
        self._facet_order = np.argsort(facets, kind="stable")
        self._facet_nodes = facets[self._facet_order]
        self._slave_index = cd.integrals.slave_index

    def entries(self, block: int) -> tuple[np.ndarray, np.ndarray]:
        """(couples, slave vertices) whose slave vertex is node ``block``."""
        lo, hi = np.searchsorted(self._entry_nodes, [block, block + 1])
        flat = self._entry_order[lo:hi]
        return flat // self._ks, flat % self._ks

    def facets(self, block: int) -> np.ndarray:
        """The slave facets around node ``block``."""
        lo, hi = np.searchsorted(self._facet_nodes, [block, block + 1])
        return self._facet_order[lo:hi] // self._ks

    def nodal_areas(self, facets: np.ndarray, block: int | None) -> tuple[np.ndarray, np.ndarray]:
        """The area vectors (f, 3) whose sum is node ``block``'s ν on its slave facets ``facets`` (linear
        facets: the facets' Newell vectors) and their derivatives (f, 3, 3 ks)."""
        return self.area[facets], self.d_area[facets]

    def slave_row(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        """The global dof blocks and coefficients of pair ``s``'s slave side (row s of the integrals):
        linear facets, its node alone."""
        return np.array([self._slave_index[s]]), np.ones(1)

    def slave_rows(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The slave sides of the rows ``rows`` as CSR; None: every row is its node alone."""
        return None


def _normal_derivative(cd: CoupleDerivatives, incidence: _Incidence, facets: np.ndarray, cols: np.ndarray,
                       normal: np.ndarray, given: np.ndarray, block: int | None = None) -> np.ndarray:
    """∂n/∂x (3, 3c) over ``cols`` of the pair normal ``normal``: n_f = −ν/|ν| (``given``) of the Newell
    vectors ν of the slave facets ``facets`` (module docstring), or ``given`` turned into symmetry planes
    (:func:`~dolfinx_nnqem.contact.surfaces.symmetry_normals` removed its components along them); ν of
    node ``block`` on quadratic facets: the sum of its moments (:meth:`_Incidence.nodal_areas`)."""
    areas, d_areas = incidence.nodal_areas(facets, block)
    dnu = np.zeros((3, 3 * len(cols)))
    at = (3 * np.searchsorted(cols, cd.slave_nodes[facets])[:, :, None] + np.arange(3)).reshape(len(facets), -1)
    np.add.at(dnu, (np.arange(3)[None, :, None], at[:, None, :]), d_areas)
    length = np.linalg.norm(areas.sum(axis=0))
    dn = -(np.eye(3) - np.outer(given, given)) @ dnu / length
    if np.array_equal(normal, given):
        return dn
    axes = (normal == 0.0) & (given != 0.0)  # the components the symmetry planes removed
    P = (~axes).astype(float)
    return (np.eye(3) - np.outer(normal, normal)) @ (P[:, None] * dn) / np.linalg.norm(P * given)


def pair_geometry(cd: CoupleDerivatives, incidence: _Incidence, s: int, normal: np.ndarray, held_open: bool
                  ) -> tuple[PairGeometry, float]:
    """The geometry of the pair of slave node ``s`` (its row in ``cd.integrals``) with the unit pair
    normal ``normal``, and its gap g̃_j / m_j (nan if ``held_open``: its gap is then held)."""
    mi = cd.integrals
    block = int(mi.slave_index[s])
    couples, vertices = incidence.entries(block)
    facets = incidence.facets(block)
    active = np.any(cd.dM[couples, vertices] != 0.0, axis=(1, 2)) | np.any(cd.dg[couples, vertices] != 0.0, axis=1)
    row = slice(mi.M.indptr[s], mi.M.indptr[s + 1])
    masters = mi.master_index[mi.M.indices[row]]
    couple_nodes = np.concatenate([cd.slave_nodes[cd.couples[couples, 0]], cd.master_nodes[cd.couples[couples, 1]]],
                                  axis=1)
    row_blocks, row_coefficients = incidence.slave_row(s)  # the slave side: node j, or d̂_j on tri6
    cols = np.unique(np.concatenate([row_blocks, masters, couple_nodes[active].ravel(), cd.slave_nodes[facets].ravel()]))
    c = len(cols)
    M = np.zeros(c)
    M[np.searchsorted(cols, masters)] = mi.M.data[row]
    dM = np.zeros((c, 3 * c))
    dgt = np.zeros(3 * c)
    at = (3 * np.searchsorted(cols, couple_nodes[active])[:, :, None] + np.arange(3)).reshape(
        int(active.sum()), 3 * couple_nodes.shape[1])  # (entries, P): each couple coordinate's column
    master_rows = np.searchsorted(cols, cd.master_nodes[cd.couples[couples[active], 1]])  # (entries, km)
    np.add.at(dM, (master_rows[:, :, None], at[:, None, :]), cd.dM[couples[active], vertices[active]])
    np.add.at(dgt, at, cd.dg[couples[active], vertices[active]])
    m = M.sum()
    if m > 0.0:
        dm = dM.sum(axis=0)
        coefficient, dc = M / m, (dM - np.outer(M / m, dm)) / m
    else:  # not covered at all: held open
        dm, coefficient, dc = np.zeros(3 * c), np.zeros(c), np.zeros_like(dM)
    gap = float(mi.weighted_gap[s] / m) if not held_open else np.nan
    dg = np.zeros(3 * c) if held_open else (dgt - gap * dm) / m
    slave = np.searchsorted(cols, row_blocks)
    a, da = -coefficient, -dc
    a[slave], da[slave] = row_coefficients, 0.0
    return PairGeometry(cols, a, da, dg, _normal_derivative(cd, incidence, facets, cols, normal, -mi.normal[s],
                                                            block)), gap


@dataclass(frozen=True)
class MortarPoints:
    """The mortar pairs of an interface at the iterate, as :func:`mortar_terms` needs them.

    Attributes
    ----------
    geometry
        Per local pair, its :class:`PairGeometry`.
    normal
        (p, 3) the pairs' unit normals.
    du
        Per local pair, (c, 3): u − u_n at its nodes.
    """

    geometry: list[PairGeometry]
    normal: np.ndarray
    du: list[np.ndarray]


def _group_terms(geometry: Sequence[PairGeometry], normal: np.ndarray, du: np.ndarray, lam: np.ndarray,
                 pairs: np.ndarray) -> SurfaceTerms:
    """The :class:`SurfaceTerms` of pairs with the same number c of nodes (module docstring)."""
    k, c = len(geometry), len(geometry[0].blocks)
    a = np.stack([g.a for g in geometry])
    da = np.stack([g.da for g in geometry])  # (k, c, 3c)
    dg = np.stack([g.dg for g in geometry])
    dn = np.stack([g.dn for g in geometry])  # (k, 3, 3c)
    R = local_frames(normal)
    dR = np.einsum("pikl,plc->pikc", local_frames_derivative(normal), dn)
    W = np.empty((k, 3, 3 * c))
    W[:, 0] = dg - (a[:, :, None] * normal[:, None, :]).reshape(k, -1)
    slip = np.einsum("pi,pil->pl", a, du)
    W[:, 1:] = (np.einsum("pl,pilc->pic", slip, dR[:, 1:])
                + np.einsum("pil,pjl,pjc->pic", R[:, 1:], du, da))
    v = np.einsum("pr,prl->pl", lam, R)
    dv = np.einsum("pr,prlc->plc", lam, dR)
    K = (a[:, :, None, None] * dv[:, None] + v[:, None, :, None] * da[:, :, None, :]).reshape(k, 3 * c, 3 * c)
    blocks = np.stack([g.blocks for g in geometry])
    columns = (3 * blocks[:, :, None] + np.arange(3)).reshape(k, -1)
    return SurfaceTerms(np.asarray(pairs, dtype=np.int64), columns.astype(np.int64), K, W)


def mortar_terms(points: MortarPoints, lam: np.ndarray, pairs: np.ndarray) -> list[SurfaceTerms]:
    """The geometric blocks of the local mortar pairs ``pairs`` at ``points`` with forces ``lam`` (p, 3):
    one :class:`~dolfinx_nnqem.contact.surface_stiffness.SurfaceTerms` per number of nodes of a pair."""
    sizes = np.array([len(g.blocks) for g in points.geometry], dtype=np.int64)
    out = []
    for c in np.unique(sizes):
        group = np.flatnonzero(sizes == c)
        out.append(_group_terms([points.geometry[i] for i in group], points.normal[group],
                                np.stack([points.du[i] for i in group]), lam[group], np.asarray(pairs)[group]))
    return out


def _all_normals(mi: MortarIntegrals, every: np.ndarray, moved: GatheredSurfaces,
                 V: dolfinx.fem.FunctionSpace | None, supported: np.ndarray | None,
                 slave_rows: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                 ) -> tuple[np.ndarray, np.ndarray | None]:
    """(the unit normals of every pair of the interface (rows ``every`` of ``mi``), their pinned
    directions or None): the averaged normals, turned into the interface's symmetry planes as
    :func:`~dolfinx_nnqem.contact.surface_pairs.surface_pairs` does (collective); ``slave_rows``: the
    pairs' slave sides where they combine nodes (tri6; :meth:`_Incidence.slave_rows`)."""
    from dolfinx_nnqem.contact.surface_pairs import _pair_nodes
    from dolfinx_nnqem.contact.symmetry_planes import IN_PLANE, support_rules

    given = -mi.normal[every]
    if supported is None or V is None:
        return given, None
    M = mi.M[every]
    m = np.asarray(M.sum(axis=1)).ravel()
    weights = M.data / np.repeat(np.where(m > 0.0, m, 1.0), np.diff(M.indptr))
    masters = mi.master_index[M.indices]
    master = moved.nodes[0]
    rows = _pair_nodes(np.arange(len(every)), mi.slave_index[every], slave_rows, M.indptr, masters, weights)[2]
    rules = support_rules(V, supported, mi.slave_index[every], mi.x[every], given, M.indptr, masters,
                          master.x[np.searchsorted(master.index, masters)], rows,
                          IN_PLANE * facet_size(moved.facets_of(0)))
    return rules.normal, rules.pinned


def _nodal(reference: GatheredSurfaces, moved: GatheredSurfaces, u_n: tuple[np.ndarray, np.ndarray]
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(global dof blocks (sorted), x, u, u − u_n) of every node of the interface."""
    blocks = np.concatenate([n.index for n in reference.nodes])
    x = np.concatenate([n.x for n in moved.nodes])
    u = x - np.concatenate([n.x for n in reference.nodes])
    order = np.argsort(blocks)
    return blocks[order], x[order], u[order], (u - np.concatenate(u_n))[order]


def remortared_pairs(pairs: SurfacePairs, reference: GatheredSurfaces, moved: GatheredSurfaces,
                     u_n: tuple[np.ndarray, np.ndarray], gap_rounding: float, search_distance: float | None,
                     V: dolfinx.fem.FunctionSpace | None = None, supported: np.ndarray | None = None, *,
                     couples: tuple[CoupleDerivatives, _Incidence] | None = None) -> tuple[SurfacePairs, MortarPoints]:
    """The mortar ``pairs`` (the same slave nodes, in the same order) integrated again on the moved
    surfaces, and their :class:`MortarPoints` (collective).

    Parameters
    ----------
    pairs
        The interface's mortar :class:`~dolfinx_nnqem.contact.surface_pairs.SurfacePairs`.
    reference, moved
        The gathered surfaces (master, slave) at rest and at X + u (their area vectors the moved ones:
        :func:`~dolfinx_nnqem.contact.current_geometry.with_moved_normals`).
    u_n
        u_n at the master's and the slave's nodes (``reference.nodes[0].index``, ``[1].index``).
    gap_rounding, search_distance
        Gaps within ``gap_rounding`` are zero; the mortar search distance (None: its default).
    V, supported
        The displacement space and its prescribed dofs (None: no support known): the normals of slave
        nodes on the interface's symmetry planes are turned into them.
    couples
        The couple derivatives of the moved surfaces and their incidence, where the caller made them
        (quadratic facets: :func:`~dolfinx_nnqem.contact.quadratic_mortar_linearisation.quadratic_couples`);
        None: those of linear facets, made here.

    Returns
    -------
    The pairs with their weights c_jk = M_jk / m_j, frames, gaps g0 = g − (B u)_n and rows (B holds a
    pair's every node whose position its geometry depends on, with coefficient 0 where it is not
    the slave node or in M's row), and their :class:`MortarPoints`. A pair whose node is covered
    less than :data:`~dolfinx_nnqem.contact.mortar.MIN_COVERED` is held open (module docstring).
    """
    if couples is None:
        cd = interface_derivatives(moved, search_distance, pairs.slave_blocks)
        couples = (cd, _Incidence(cd))
    cd, incidence = couples
    mi = cd.integrals
    gathered = pairs.comm.allgather(pairs.slave_blocks)  # every pair of the interface, in the global order
    every = np.searchsorted(mi.slave_index, np.concatenate(gathered))
    normals, pinned = _all_normals(mi, every, moved, V, supported, incidence.slave_rows(every))
    start = sum(len(blocks) for blocks in gathered[:pairs.comm.rank])
    local = every[start:start + pairs.num_local]
    normal = normals[start:start + pairs.num_local]
    m = np.asarray(mi.M[local].sum(axis=1)).ravel()
    held = m < MIN_COVERED * mi.D[local]
    blocks, x, u, du = _nodal(reference, moved, u_n)
    size = facet_size(moved.facets_of(0))
    geometry, du_pairs, g0 = [], [], np.empty(len(local))
    masters: list[np.ndarray] = []
    weights: list[np.ndarray] = []
    for i, (s, h) in enumerate(zip(local, held)):
        pg, gap = pair_geometry(cd, incidence, int(s), normal[i], bool(h))
        gap = size if h else (0.0 if abs(gap) <= gap_rounding else gap)
        at = np.searchsorted(blocks, pg.blocks)
        g0[i] = gap - normal[i] @ (pg.a @ u[at])
        geometry.append(pg)
        du_pairs.append(du[at])
        master = np.isin(pg.blocks, mi.master_index) & (pg.a != 0.0)
        masters.append(pg.blocks[master])
        weights.append(-pg.a[master])
    R = local_frames(normal) if len(local) else np.zeros((0, 3, 3))
    counts = np.array([len(g.blocks) for g in geometry], dtype=np.int64)
    nodes = np.concatenate([np.zeros(0, dtype=np.int64)] + [g.blocks for g in geometry])
    a = np.concatenate([np.zeros(0)] + [g.a for g in geometry])
    rows = PairRows.from_weighted_nodes(R, np.concatenate([[0], np.cumsum(counts)]), nodes, a)
    indptr = np.concatenate([[0], np.cumsum([len(k) for k in masters])]).astype(np.int64)
    master_blocks = np.concatenate([np.zeros(0, dtype=np.int64)] + masters)
    c = np.concatenate([np.zeros(0)] + weights)
    X_master = np.zeros((len(local), 3))
    np.add.at(X_master, np.repeat(np.arange(len(local)), np.diff(indptr)),
              c[:, None] * x[np.searchsorted(blocks, master_blocks)])
    new = replace(pairs, master_indptr=indptr, master_blocks=master_blocks, weights=c, X_master=X_master, R=R,
                  g0=g0, rows=rows,
                  support_pinned=pairs.support_pinned if pinned is None else pinned[start:start + pairs.num_local])
    return new, MortarPoints(geometry, normal, du_pairs)
