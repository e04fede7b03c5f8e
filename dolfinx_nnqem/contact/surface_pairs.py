r"""Pairs of slave nodes against a meshed master surface: node-to-surface and dual mortar.

Both discretisations of non-matching interfaces (``formulation.md`` §2b) give every slave node
j one pair whose relative displacement involves the slave node and some master nodes k with
weights c_jk (Σ_k c_jk = 1):

    w_j = R_j (u_j − Σ_k c_jk u_k),   g_j = g0_j + (w_j)_n,

so B's row block is R_j in the slave node's columns and −c_jk R_j in master node k's. The
nodal force λ_j acts on the slave node; Bᵀλ puts −c_jk R_jᵀλ_j on the master nodes, so the
two sides' forces balance exactly. Node-to-surface takes c_jk = N_k(ξ_j), the master facet's
shape functions at the slave node's closest point (:mod:`~dolfinx_nnqem.contact.node_to_surface`);
dual mortar takes c_jk = M_jk / Σ_k M_jk (:mod:`~dolfinx_nnqem.contact.mortar`). This module
holds what the two share: the pair set, its assembly and the checks of the geometry.

Like node-to-node pairs, everything is computed on every rank from the gathered surfaces
(:mod:`~dolfinx_nnqem.contact.surfaces`) in the slave nodes' coordinate order; a rank keeps the
pairs whose slave node it owns.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from dolfinx_nnqem import compat  # noqa: F401, I001  (first: loads MPI/PETSc for the PyPI wheel)

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.contact.pairs import owned_by_slave
from dolfinx_nnqem.contact.pairset import PairRows
from dolfinx_nnqem.contact.surfaces import (ContactPairError, Facets, GatheredSurfaces, first_by_position,
                                            format_point, local_frames)
from dolfinx_nnqem.contact.symmetry_planes import IN_PLANE, support_rules

if TYPE_CHECKING:
    import dolfinx

__all__ = ["MAX_INTERFERENCE", "RUN_INTERFERENCE", "InterferenceError", "SurfacePairs", "facet_size", "surface_pairs"]

MAX_INTERFERENCE = 0.1
"""A slave node may start up to this fraction of the master's mean facet size behind the master
surface (an initial interference, e.g. where a curved interface is faceted differently on its two
sides); a deeper one means overlapping bodies or swapped surfaces, and is refused."""

RUN_INTERFERENCE = 0.5
"""The same limit for the pairs re-evaluated during a run (``geometry = "current"``, between
solves): a solver that holds the geometry within a solve (NNEQM1) lets a slave node pass a curved
master surface by a fraction of a facet before the re-evaluation sees it (an edge of a die riding
up the bulge it pushes). The next solve pushes it out; beyond this limit the closest points may be
on the wrong facets, and load stepping cuts the increment back instead."""


class InterferenceError(ContactPairError):
    """A slave node lies deeper behind the master surface than the limit allows."""


@dataclass(eq=False)
class SurfacePairs:
    """Pairs of the slave surface's nodes against a meshed master surface, owned by this rank.

    A :class:`~dolfinx_nnqem.contact.pairset.PairSet`. Global order: by the rank owning the
    slave node, then by the slave node's coordinates (x, then y, then z).

    Attributes
    ----------
    kind
        ``"node-to-surface"`` or ``"mortar"``.
    master, slave
        Facet tags of the master and slave surfaces.
    slave_blocks
        (num_local,) global dof-block indices of the slave nodes.
    master_indptr, master_blocks, weights
        CSR: pair i involves the master nodes ``master_blocks[master_indptr[i]:master_indptr[i+1]]``
        with the weights c_ik (summing to 1).
    X_slave, X_master
        (num_local, 3) slave node positions and the facing master point Σ_k c_ik X_k.
    R, g0, area
        Frames (rows n, t1, t2; n points from the master to the slave side), initial gaps, and
        the slave nodes' tributary areas (D_jj for mortar).
    rows
        B's local rows.
    num_slave_nodes
        Nodes of the slave surface; those without a pair (beyond the master) are reported.
    note
        Extra words for :meth:`describe` (e.g. why this side is the slave).
    """

    comm: MPI.Comm
    kind: str
    master: int
    slave: int
    num_local: int
    num_global: int
    offset: int
    slave_blocks: np.ndarray
    master_indptr: np.ndarray
    master_blocks: np.ndarray
    weights: np.ndarray
    X_slave: np.ndarray
    X_master: np.ndarray
    R: np.ndarray
    g0: np.ndarray
    area: np.ndarray
    rows: PairRows
    num_slave_nodes: int
    note: str = ""
    pins_supported_slave_tangents: bool = True  #: see contact.constrained_directions.supported_slave_tangents
    master_facet: np.ndarray | None = None  #: node-to-surface: (num_local,) the gathered master facet of each pair
    support_pinned: np.ndarray | None = None
    """(num_local, 3) bool: pair directions a support holds, pinned by the contact model
    (:mod:`~dolfinx_nnqem.contact.symmetry_planes`); None: no support was known."""

    def motion(self, load_factor: float) -> np.ndarray:
        """Zero: both sides are deformable, their motion is in u."""
        return np.zeros((self.num_local, 3))

    def motion_amplitudes(self, load_factor: float) -> np.ndarray:
        """Empty: neither side moves besides u."""
        return np.zeros(0)

    def describe(self) -> str:
        """The kind, the number of pairs, the slave and master surfaces and the note, in one line."""
        without = self.num_slave_nodes - self.num_global
        beyond = f" ({without} slave nodes beyond the master surface have none)" if without else ""
        return (f"{self.kind}, {self.num_global} pairs{beyond}: slave surface {self.slave} against master "
                f"surface {self.master}{self.note}")


def facet_size(facets: Facets) -> float:
    """The square root of the mean facet area: a surface's element size."""
    return float(np.sqrt(np.mean(np.linalg.norm(facets.area, axis=1))))


def _check_gaps(g0: np.ndarray, x: np.ndarray, master_size: float, tags: tuple[int, int],
                max_interference: float) -> None:
    """Refuse slave nodes deeper behind the master than ``max_interference`` × its facet size
    (:class:`InterferenceError`)."""
    deep = g0 < -max_interference * master_size
    if np.any(deep):
        i = first_by_position(x, deep)
        why = (": are the bodies overlapping, or are the surfaces swapped?" if max_interference == MAX_INTERFERENCE
               else "")
        raise InterferenceError(
            f"the node at {format_point(x[i])} of the slave surface {tags[1]} lies {-g0[i]:.6g} behind the master "
            f"surface {tags[0]} (more than {max_interference:g} × its facet size {master_size:.4g}){why}")


def _joined_rows(slave_rows: tuple[np.ndarray, np.ndarray, np.ndarray], local: np.ndarray, indptr: np.ndarray,
                 masters: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each kept pair's nodes: its slave nodes (``slave_rows`` of the rows ``local``), then its
    master nodes (CSR ``indptr``, ``masters``, weights ``c``) with −c, as one CSR."""
    s_indptr, s_nodes, s_coefficients = slave_rows
    s_counts = np.diff(s_indptr)[local]
    m_counts = np.diff(indptr)
    nodes_indptr = np.concatenate([[0], np.cumsum(s_counts + m_counts)]).astype(np.int64)
    pair_s = np.repeat(np.arange(len(local)), s_counts)
    pair_m = np.repeat(np.arange(len(local)), m_counts)
    s_take = np.repeat(s_indptr[local] - np.concatenate([[0], np.cumsum(s_counts)])[:-1], s_counts) \
        + np.arange(int(s_counts.sum()))
    at_s = nodes_indptr[pair_s] + (np.arange(len(pair_s)) - np.concatenate([[0], np.cumsum(s_counts)])[pair_s])
    at_m = nodes_indptr[pair_m] + s_counts[pair_m] + (np.arange(len(pair_m)) - indptr[pair_m])
    nodes = np.empty(int(nodes_indptr[-1]), dtype=np.int64)
    coefficients = np.empty(len(nodes))
    nodes[at_s], coefficients[at_s] = s_nodes[s_take], s_coefficients[s_take]
    nodes[at_m], coefficients[at_m] = masters, -c
    return nodes_indptr, nodes, coefficients


def surface_pairs(V: dolfinx.fem.FunctionSpace, kind: str, tags: tuple[int, int], slave_index: np.ndarray, X_slave: np.ndarray,
                  area: np.ndarray, normal: np.ndarray, g0: np.ndarray, master_indptr: np.ndarray,
                  master_index: np.ndarray, weights: np.ndarray, X_master_nodes: np.ndarray, *,
                  master_size: float, tolerance: float, num_slave_nodes: int, note: str = "",
                  supported: np.ndarray | None = None,
                  slave_rows: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                  facet: np.ndarray | None = None, max_interference: float = MAX_INTERFERENCE) -> SurfacePairs:
    """Assemble the pair set from per-slave-node data given identically on every rank (collective).

    Parameters
    ----------
    V
        The displacement space.
    kind
        ``"node-to-surface"`` or ``"mortar"``.
    tags
        (master tag, slave tag).
    slave_index, X_slave, area
        (p,) global dof blocks, (p, 3) positions and (p,) tributary areas of the slave nodes that
        have a pair.
    normal
        (p, 3) unit pair normals, pointing from the master side to the slave side.
    g0
        (p,) initial gaps (positive: open).
    master_indptr, master_index, weights, X_master_nodes
        CSR over the slave nodes: master nodes' global dof blocks, their weights c_jk (summing to
        1 per slave node) and coordinates.
    master_size, tolerance
        The master's facet size (for the interference check) and the length below which a gap
        is zero.
    num_slave_nodes, note
        See :class:`SurfacePairs`.
    supported
        Laid out like V's local dofs, non-zero at prescribed ones: the normals of slave nodes on
        symmetry planes of the interface are moved into the plane
        (:mod:`~dolfinx_nnqem.contact.symmetry_planes`, :func:`~dolfinx_nnqem.contact.surfaces.symmetry_normals`).
        None: the normals as given.
    slave_rows
        The slave side of each pair's row as CSR over the p slave nodes (indptr, global dof blocks,
        coefficients summing to 1): d̂_j = Σ_i t_ji u_i of a quadratic slave surface
        (:func:`~dolfinx_nnqem.contact.quadratic_facets.node_combination`). None: u_j alone.
    facet
        (p,) node-to-surface: the master facet of each slave node (kept as ``master_facet``).
    max_interference
        How deep behind the master, in its facet size, a slave node may lie
        (:data:`MAX_INTERFERENCE` where a run starts, :data:`RUN_INTERFERENCE` during a run);
        deeper: :class:`InterferenceError`.
    """
    _check_gaps(g0, X_slave, master_size, tags, max_interference)
    g0 = np.where(np.abs(g0) <= tolerance, 0.0, g0)  # touching within the tolerance: no gap (round-off)
    # deterministic global order for any number of ranks: the slave nodes' coordinates
    order = np.lexsort((X_slave[:, 2], X_slave[:, 1], X_slave[:, 0]))
    mine, offset, num_global = owned_by_slave(V.mesh.comm, V.dofmap.index_map, slave_index[order])
    local = order[mine]
    indptr, take, (nodes_indptr, nodes, coefficients) = _pair_nodes(local, slave_index, slave_rows, master_indptr,
                                                                     master_index, weights)
    masters, c = master_index[take], weights[take]
    pair = np.repeat(np.arange(len(local)), np.diff(indptr))
    X_master = np.zeros((len(local), 3))
    np.add.at(X_master, pair, c[:, None] * X_master_nodes[take])
    pinned = None
    if supported is not None:  # every pair, on every rank: the rules look at supported edges as a whole
        every = np.arange(len(slave_index))
        rules = support_rules(V, supported, slave_index, X_slave, normal, master_indptr, master_index,
                              X_master_nodes, _pair_nodes(every, slave_index, slave_rows, master_indptr, master_index,
                                                          weights)[2], IN_PLANE * master_size)
        normal, pinned = rules.normal, rules.pinned[local]
        note += rules.note
    normal = normal[local]
    R = local_frames(normal) if len(local) else np.zeros((0, 3, 3))
    return SurfacePairs(
        comm=V.mesh.comm, kind=kind, master=int(tags[0]), slave=int(tags[1]), num_local=len(local),
        num_global=num_global, offset=offset, slave_blocks=slave_index[local], master_indptr=indptr,
        master_blocks=masters, weights=c, X_slave=X_slave[local], X_master=X_master, R=R, g0=g0[local],
        area=area[local], rows=PairRows.from_weighted_nodes(R, nodes_indptr, nodes, coefficients),
        num_slave_nodes=int(num_slave_nodes), note=note, master_facet=None if facet is None else facet[local],
        support_pinned=pinned,
    )


def _pair_nodes(selection: np.ndarray, slave_index: np.ndarray,
                slave_rows: tuple[np.ndarray, np.ndarray, np.ndarray] | None, master_indptr: np.ndarray,
                master_index: np.ndarray, weights: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The pairs ``selection`` (indices of the slave nodes with a pair), in that order: the CSR
    pointer of their master entries, those entries' positions in ``master_index`` (``take``), and
    each pair's nodes as CSR (global dof blocks and coefficients: the slave side, then the master
    nodes with −c_jk)."""
    counts = np.diff(master_indptr)[selection]
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    take = np.repeat(master_indptr[selection] - indptr[:-1], counts) + np.arange(indptr[-1])
    masters, c = master_index[take], weights[take]
    if slave_rows is not None:
        return indptr, take, _joined_rows(slave_rows, selection, indptr, masters, c)
    # the slave node with coefficient 1, then the master nodes with −c_jk
    nodes_indptr = indptr + np.arange(len(selection) + 1)
    nodes = np.empty(len(take) + len(selection), dtype=np.int64)
    coefficients = np.empty(len(nodes))
    slave_at = nodes_indptr[:-1]
    nodes[slave_at], coefficients[slave_at] = slave_index[selection], 1.0
    rest = np.setdiff1d(np.arange(len(nodes)), slave_at)
    nodes[rest], coefficients[rest] = masters, -c
    return indptr, take, (nodes_indptr, nodes, coefficients)
