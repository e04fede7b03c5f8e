r"""Dual mortar contact pairs (``formulation.md`` §2b; Wohlmuth 2000, Popp et al. 2010).

The contact pressure is interpolated on the slave surface with dual shape functions Φ_j,
biorthogonal to the slave's N_j, so that the mortar matrix D is diagonal and each slave node j
keeps ONE node-wise complementarity condition on its weighted gap and weighted tangential
displacement (:mod:`~dolfinx_nnqem.contact.mortar_geometry` computes the integrals):

    D_jj = ∫ N_j dA,   M_jk = ∫ Φ_j (N_k ∘ π) dA,   g̃_j = ∫ Φ_j g0 dA.

Dividing the weighted quantities by m_j = Σ_k M_jk (= D_jj at a fully covered node) gives the pair
structure every law and solver already uses:

    w_j = R_j (u_j − Σ_k (M_jk / m_j) u_k),   g0_j = g̃_j / m_j,

with R_j built on n_j, minus the slave's averaged nodal normal. λ_j is the nodal force on slave
node j (pressure × D_jj); master node k receives −(M_jk / m_j) R_jᵀλ_j, so the forces balance exactly
and a rigid translation of both bodies leaves w unchanged. On a fully covered node m_j = D_jj
and this is the textbook dual mortar condition divided by D_jj.

Quadratic facets (degree-2 displacements, tri6 and quad9): the dual functions are built on the
transformed slave basis N̂ = T N and the integrals computed on the quadratic facets
(:mod:`~dolfinx_nnqem.contact.dual_quadratic`); D_jj = ∫ N̂_j dA, and pair j acts on the
transformed nodal displacement d̂_j = Σ_i t_ji u_i (:func:`~dolfinx_nnqem.contact.facet_layout.node_combination`)
instead of u_j, as node-to-surface does on tri6 slaves. Entries |M_jk| ≤ :data:`ROUND_OFF` × D_jj
are dropped there.

Documented choices:

* Small deformation: D, M, normals and gaps are computed once in the reference configuration
  (the seed's setting).
* Slave nodes at the edge of the master: a node keeps its pair if m_j ≥ :data:`MIN_COVERED` ×
  D_jj (at least half its support faces the master); the weights are then renormalised by m_j as
  above. Less covered nodes get no pair (their multiplier is zero: they cannot press on the
  master). On a slave surface whose boundary lies inside the master (the usual choice) every node
  is fully covered.
* Crosspoints and slave nodes on supported edges keep their pairs like any other node; a pair
  direction whose every dof is prescribed is pinned by the contact model (``ContactLaw.pin``).
  The averaged normal of a slave node on a symmetry plane of the interface (the master held on
  it too) is moved into the plane (the facets on the plane's other side are not modelled;
  :mod:`~dolfinx_nnqem.contact.symmetry_planes`), so that its frame holds the supported axis
  exactly and that friction direction is pinned; a support of the slave side alone changes
  neither.
* A master surface that overlaps itself in projection (coverage > 1, a folded or two-sided
  master) is refused.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from dolfinx_nnqem.contact.facet_layout import node_combination
from dolfinx_nnqem.contact.mortar_geometry import mortar_integrals
from dolfinx_nnqem.contact.surface_pairs import MAX_INTERFERENCE, SurfacePairs, facet_size, surface_pairs
from dolfinx_nnqem.contact.surfaces import ContactPairError, GatheredSurfaces, NoPairsError, first_by_position, format_point

if TYPE_CHECKING:
    import dolfinx

__all__ = ["MAX_COVERAGE", "MIN_COVERED", "ROUND_OFF", "mortar_pairs"]

MIN_COVERED = 0.5
"""A slave node keeps its pair if Σ_k M_jk ≥ this × D_jj."""

ROUND_OFF = 1e-12
"""Quadratic facets: entries |M_jk| ≤ this × D_jj are dropped (round-off of zero: the dual functions
change sign, so a master node whose functions barely meet slave node j's support gets M_jk ≈ 1e-17)."""

MAX_COVERAGE = 1.0 + 1e-6
"""Coverage above this means master facets overlap in projection (refused)."""


def mortar_pairs(V: dolfinx.fem.FunctionSpace, surfaces: GatheredSurfaces, *, tolerance: float, search_distance: float | None = None,
                 note: str = "", supported: np.ndarray | None = None,
                 max_interference: float = MAX_INTERFERENCE) -> SurfacePairs:
    """Dual mortar pairs of the second gathered surface (slave) against the first (master).

    Parameters
    ----------
    V
        The displacement space (vector P1).
    surfaces
        The master and slave surfaces, in that order.
    tolerance
        Gaps within it are zero.
    search_distance
        Largest normal distance between coupled slave and master facets; default: twice the
        larger facet size of the two surfaces.
    note
        Extra words for the pair set's ``describe``.
    supported
        Laid out like V's local dofs, non-zero at prescribed ones (None: no support is known): the
        normals of slave nodes on symmetry planes lie in the plane (:func:`surface_pairs`).
    max_interference
        How deep behind the master, in its facet size, a slave node may lie (:func:`surface_pairs`).

    Raises
    ------
    ContactPairError
        (on every rank) if no slave node is covered by the master, the master overlaps itself in
        projection, or a slave node lies deep behind the master.
    """
    tags = surfaces.tags[0], surfaces.tags[1]  # (master, slave): the two surfaces gathered
    master, slave = surfaces.facets_of(0), surfaces.facets_of(1)
    master_size = facet_size(master)
    if search_distance is None:
        search_distance = 2.0 * max(master_size, facet_size(slave))
    if slave.degree == 2:  # imported here: its numba kernels are compiled only where quadratic facets are
        from dolfinx_nnqem.contact.dual_quadratic import quadratic_mortar_integrals

        mi = quadratic_mortar_integrals(slave.nodes, slave.x, slave.area, master.nodes, master.x, master.area,
                                        search_distance=search_distance)
    else:
        mi = mortar_integrals(slave.nodes, slave.x, slave.area, master.nodes, master.x, master.area,
                              search_distance=search_distance)
    if mi.num_failed_points:
        raise ContactPairError(
            f"mortar integration between surfaces {tags[1]} (slave) and {tags[0]} (master) failed at "
            f"{mi.num_failed_points} quadrature points (an inverse map did not converge): are the facets distorted?")
    folded = mi.coverage > MAX_COVERAGE
    if np.any(folded):
        j = first_by_position(mi.x, folded)
        raise ContactPairError(
            f"the master surface {tags[0]} overlaps itself as seen from the slave node at {format_point(mi.x[j])} "
            f"(coverage {mi.coverage[j]:.6g} > 1): a folded or two-sided master surface")
    if slave.degree == 2:
        _drop_round_off(mi)
    m = np.asarray(mi.M.sum(axis=1)).ravel()
    keep = np.flatnonzero(m >= MIN_COVERED * mi.D)
    if len(keep) == 0:  # NoPairsError: in the current geometry the bodies slid apart (a failed solve, not bad input)
        raise NoPairsError(
            f"no node of the slave surface {tags[1]} is covered by the master surface {tags[0]} within the search "
            f"distance {search_distance:.6g}: do the surfaces face each other? (pass search_distance for larger "
            "initial gaps)")
    M = mi.M[keep]
    weights = M.data / np.repeat(m[keep], np.diff(M.indptr))
    master_x = np.zeros((len(mi.master_index), 3))
    master_x[np.searchsorted(mi.master_index, master.nodes.ravel())] = master.x.reshape(-1, 3)
    slave_rows = None
    if slave.degree == 2:  # quadratic: pair j acts on the transformed slave displacement d̂_j = Σ_i t_ji u_i
        rows = node_combination(slave.nodes, mi.slave_index).take(keep)
        if len(rows.columns) > len(keep):  # tri6 (quad9: the identity, the node alone)
            slave_rows = (rows.indptr, mi.slave_index[rows.columns], rows.coefficients)
    return surface_pairs(
        V, "mortar", tags, mi.slave_index[keep], mi.x[keep], mi.D[keep], -mi.normal[keep],
        mi.weighted_gap[keep] / m[keep], M.indptr, mi.master_index[M.indices], weights, master_x[M.indices],
        master_size=master_size, tolerance=tolerance, num_slave_nodes=len(mi.slave_index), note=note,
        supported=supported, slave_rows=slave_rows, max_interference=max_interference)


def _drop_round_off(mi) -> None:
    """Remove the entries |M_jk| ≤ :data:`ROUND_OFF` × D_jj of ``mi.M`` in place."""
    row = np.repeat(np.arange(mi.M.shape[0]), np.diff(mi.M.indptr))
    mi.M.data[np.abs(mi.M.data) <= ROUND_OFF * mi.D[row]] = 0.0
    mi.M.eliminate_zeros()
