r"""The consistent linearisation of dual mortar pairs on quadratic facets (tri6, quad9) in the current
geometry (issue 41).

The degree-2 counterpart of :mod:`~dolfinx_nnqem.contact.mortar_linearisation`, whose chain rule
(the coefficients a_i, the gap g̃_j / m_j, the frame on the nodal normal, the blocks W and K) it
shares; what differs is where the pieces come from:

* the couple integrals M_c, g̃_c are those of :mod:`~dolfinx_nnqem.contact.dual_quadratic` (each
  facet split into four linear sub-facets, the quadratic maps evaluated at the Gauss points); their
  derivatives with respect to the 3 (k_e + k_f) coordinates of ALL the nodes of the two quadratic
  facets (vertices, edge nodes, quad9 centres) are those of
  :func:`~dolfinx_nnqem.contact.quadratic_couple_differences.quadratic_couple_derivatives`: the complex
  step (exact to round-off) in the nodes' projected in-plane points (each re-integrating the pairs of sub-facets
  that hold the node), the rest of the chain rule (the node's motion, the turn of the auxiliary
  plane, the integrands at fixed Gauss points, the dual coefficients A_e) exact;
* the nodal normal is n = −ν/|ν| with ν = Σ_e ∫_e N̂_j n dA, the moments of
  :func:`~dolfinx_nnqem.contact.quadratic_facets.nodal_integrals` summed over the slave facets e
  around node j. A moment is a quadrature of N̂_j(ξ_q) x_ξ × x_η, bilinear in the facet's nodes, so
  its derivative is analytic (:func:`moment_derivatives`):
  δ(x_ξ × x_η) = −[x_η]× Σ_b ∂_ξN_b δx_b + [x_ξ]× Σ_b ∂_ηN_b δx_b;
* the slave side of pair j is the transformed node d̂_j = Σ_i t_ji u_i
  (:func:`~dolfinx_nnqem.contact.facet_layout.node_combination`): on tri6 an edge node's pair acts on
  the node and its edge's two vertices with the constant coefficients t_ji (a_i = t_ji, ∂a_i = 0);
  on quad9 t = I, the node alone.

Pairs keep their slave nodes within a solve, as at degree 1; the re-evaluation between solves
(:class:`~dolfinx_nnqem.contact.current_geometry.MortarTracker`) gives pairs to newly covered
nodes and drops uncovered ones.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dolfinx_nnqem.contact.dual_quadratic import quadratic_candidate_couples, quadratic_mortar_integrals
from dolfinx_nnqem.contact.facet_layout import NodeCombination, node_combination
from dolfinx_nnqem.contact.mortar import _drop_round_off
from dolfinx_nnqem.contact.mortar_linearisation import STEP, CoupleDerivatives, _Incidence
from dolfinx_nnqem.contact.quadratic_couple_differences import quadratic_couple_derivatives
from dolfinx_nnqem.contact.quadratic_facets import (outward_signs, reference_rule, shape_derivatives,
                                                    transformed_shape_functions)
from dolfinx_nnqem.contact.surface_pairs import facet_size
from dolfinx_nnqem.contact.surfaces import GatheredSurfaces

__all__ = ["QuadraticCoupleDerivatives", "QuadraticIncidence", "moment_derivatives", "quadratic_couples",
           "quadratic_interface_derivatives"]


def _cross_matrices(v: np.ndarray) -> np.ndarray:
    """[v]× (…, 3, 3), with [v]× w = v × w."""
    out = np.zeros(v.shape + (3,))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def moment_derivatives(x: np.ndarray, sign: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The moments ∫_e N̂_a n dA (m, k, 3) of quadratic facets and their derivatives (m, k, 3, 3k) with
    respect to the facets' node coordinates (module docstring).

    The quadrature of :func:`~dolfinx_nnqem.contact.quadratic_facets.nodal_integrals` (which takes a
    planar facet's moments from its outward vector: the same values, to round-off).

    Parameters
    ----------
    x
        (m, k, 3) the facets' nodes; ``sign`` (m,) their outward signs.
    """
    m, k = x.shape[:2]
    xi, w = reference_rule(k)
    dN = shape_derivatives(k, xi)  # (q, k, 2)
    Nhat = transformed_shape_functions(k, xi)  # (q, k)
    J = np.einsum("qab,maj->mqbj", dN, x)  # rows x_ξ, x_η
    area = np.cross(J[:, :, 0], J[:, :, 1]) * sign[:, None, None]
    moments = np.einsum("q,qa,mqj->maj", w, Nhat, area)
    # ∂(x_ξ × x_η)/∂x_b = −∂_ξN_b [x_η]× + ∂_ηN_b [x_ξ]×  (m, q, b, 3, 3)
    D = (-dN[None, :, :, 0, None, None] * _cross_matrices(J[:, :, 1])[:, :, None]
         + dN[None, :, :, 1, None, None] * _cross_matrices(J[:, :, 0])[:, :, None])
    d = np.einsum("q,qa,mqbij->maibj", w, Nhat, D) * sign[:, None, None, None, None]
    return moments, d.reshape(m, k, 3, 3 * k)


@dataclass(frozen=True)
class QuadraticCoupleDerivatives(CoupleDerivatives):
    """:class:`~dolfinx_nnqem.contact.mortar_linearisation.CoupleDerivatives` of quadratic facets (the
    facets' nodes in :mod:`~dolfinx_nnqem.contact.quadratic_facets`' order, not cyclic), with

    Attributes
    ----------
    combination
        The rows d̂_j = Σ_i t_ji u_i over the rows of ``integrals`` (columns: rows of it too).
    moments, d_moments
        :func:`moment_derivatives` of the slave facets.
    """

    combination: NodeCombination
    moments: np.ndarray
    d_moments: np.ndarray


def quadratic_interface_derivatives(moved: GatheredSurfaces, search_distance: float | None,
                                    slave_blocks: np.ndarray | None = None) -> QuadraticCoupleDerivatives:
    """The quadratic mortar integrals of the moved surfaces (master, slave) and their couples'
    derivatives (the same candidate couples, search distance and dropped round-off as
    :func:`~dolfinx_nnqem.contact.mortar.mortar_pairs`); only the couples whose slave facet holds one
    of the nodes ``slave_blocks`` (a rank's pairs) are differenced and kept (None: every couple)."""
    master, slave = moved.facets_of(0), moved.facets_of(1)
    if search_distance is None:
        search_distance = 2.0 * max(facet_size(master), facet_size(slave))
    mi = quadratic_mortar_integrals(slave.nodes, slave.x, slave.area, master.nodes, master.x, master.area,
                                    search_distance=search_distance)
    _drop_round_off(mi)
    xs, xm = np.ascontiguousarray(slave.x, dtype=np.float64), np.ascontiguousarray(master.x, dtype=np.float64)
    sign_s, sign_m = outward_signs(xs, slave.area), outward_signs(xm, master.area)
    ci, cj = quadratic_candidate_couples(xs, slave.area, xm, master.area, float(search_distance))
    if slave_blocks is not None:
        wanted = np.isin(slave.nodes[ci], slave_blocks).any(axis=1)
        ci, cj = ci[wanted], cj[wanted]
    dM, dg = quadratic_couple_derivatives(xs, sign_s, xm, sign_m, ci, cj, STEP * facet_size(slave))
    moments, d_moments = moment_derivatives(xs, sign_s)
    return QuadraticCoupleDerivatives(mi, slave.nodes, master.nodes, xs, np.column_stack([ci, cj]), dM, dg,
                                      node_combination(slave.nodes, mi.slave_index), moments, d_moments)


class QuadraticIncidence(_Incidence):
    """:class:`~dolfinx_nnqem.contact.mortar_linearisation._Incidence` of quadratic facets: a node's
    area vectors are its moments on its facets, its pair's slave side the transformed node."""

    def __init__(self, cd: QuadraticCoupleDerivatives):
        self._index(cd)
        self._cd = cd

    def nodal_areas(self, facets: np.ndarray, block: int | None) -> tuple[np.ndarray, np.ndarray]:
        """The moments ∫_e N̂_j n dA (f, 3) of node ``block`` on its slave facets ``facets`` and their
        derivatives (f, 3, 3 ks) with respect to those facets' nodes."""
        position = np.argmax(self._cd.slave_nodes[facets] == block, axis=1)
        return self._cd.moments[facets, position], self._cd.d_moments[facets, position]

    def slave_row(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        """The global dof blocks and coefficients t_ji of d̂_j, pair ``s``'s slave side (row s of the integrals)."""
        columns, coefficients = self._cd.combination.row(s)
        return self._cd.integrals.slave_index[columns], coefficients

    def slave_rows(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The slave sides of the rows ``rows`` of the integrals as CSR (indptr, global dof blocks,
        coefficients); None where every row is its node alone (quad9)."""
        taken = self._cd.combination.take(rows)
        if len(taken.columns) == len(rows):
            return None
        return taken.indptr, self._cd.integrals.slave_index[taken.columns], taken.coefficients


def quadratic_couples(moved: GatheredSurfaces, search_distance: float | None, slave_blocks: np.ndarray
                      ) -> tuple[QuadraticCoupleDerivatives, QuadraticIncidence]:
    """The couple derivatives of the moved quadratic surfaces and their incidence, as
    :func:`~dolfinx_nnqem.contact.mortar_linearisation.remortared_pairs` takes them (``couples``)."""
    quadratic = quadratic_interface_derivatives(moved, search_distance, slave_blocks)
    return quadratic, QuadraticIncidence(quadratic)
