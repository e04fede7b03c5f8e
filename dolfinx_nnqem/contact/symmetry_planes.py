"""Which supports of a slave node are symmetry planes of its interface (node-to-surface and mortar).

A quarter or half model cuts both bodies with a plane and prescribes, on both, the displacement
component normal to it. A slave node on such a plane has its surface normal in the plane; the
nodal normal averaged from the facets on one side of it tilts out, so the normal is moved back
(:func:`~dolfinx_nnqem.contact.surfaces.symmetry_normals`) and the friction along the plane's
normal is pinned: the supports carry it. Left free, the friction forces of several such slave
nodes, each coupled to several master nodes, can combine into forces on the supports alone (a
null space of the multipliers, a singular Newton matrix; ``docs/theory.md``).

A support of the slave side alone is no such plane. A block resting on an incline and held or
driven at its side face has its side's slave nodes supported along x, yet its contact normal is
the incline's, and the master under those nodes is free along x. Moving that normal into the
plane x = const turned the incline's normal into the vertical and made the statically
determinate reaction G tan α low; pinning the friction along x there made the sliding limit of a
block pushed at its side low (``docs/theory.md`` has the figures). So a supported axis k of slave
node j counts as a symmetry plane only where the pair's master side is held on the same plane:

* at least one master node of the pair lies in the plane x_k = X_j,k (within :data:`IN_PLANE` ×
  the master's facet size), and
* every master node of the pair in that plane has its component k prescribed as well.

A node supported in all three components is held in all three, as before this rule (its normal
is kept, its friction pinned). Elsewhere the normal is the one the geometry gives, and a friction
direction lying in the span of the slave's supports is pinned only where it must be: where the
rows of such directions, restricted to the free dofs (the master's), are linearly dependent —
more such slave nodes along a supported edge than master dofs under them, which would make a
sticking edge's multipliers undetermined. The pair set's description says how many nodes each
rule touched: no normal changes, and no friction is dropped, silently.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.contact.surfaces import local_frames, owned_supports, symmetry_normals
from dolfinx_nnqem.numerics.graphs import connected_components

if TYPE_CHECKING:
    import dolfinx

__all__ = ["DEPENDENT", "IN_PLANE", "SupportRules", "overconstraining", "support_rules", "supports_of",
           "symmetry_axes", "tangents_in_span"]

IN_PLANE = 1e-6
"""A master node lies in a slave node's support plane when their coordinates along the plane's
normal differ by at most this × the master's facet size (meshers write a plane's nodes with the
same coordinate, or within round-off; a millionth of a facet is far above round-off and far below
any geometric feature)."""

DEPENDENT = 1e-8
"""Rows of supported friction directions are dependent when their smallest singular value is
below this × their largest (a Newton matrix conditioned worse than 10⁸ by them alone)."""

ROUND_OFF = 1e-12
"""A turned unit normal that moved less than this is reported as unchanged (its out-of-plane
component was round-off)."""


@dataclass
class SupportRules:
    """What the supports of the slave nodes do to their pairs (one row per pair)."""

    normal: np.ndarray  #: (p, 3) the pair normals, moved into the symmetry planes
    pinned: np.ndarray  #: (p, 3) bool: pair directions a support holds (column 0, the normal, never)
    note: str  #: words for the pair set's description ("" when no rule changed anything)


def supports_of(V: dolfinx.fem.FunctionSpace, supported: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """(m, 3) bool: the prescribed components of the dof blocks ``blocks`` (collective).

    ``blocks`` (global indices) must be the same on every rank; each rank fills in the blocks it
    owns and the flags are combined, so every rank gets every block's flags.
    """
    start, end = V.dofmap.index_map.local_range
    blocks = np.asarray(blocks, dtype=np.int64).reshape(-1)
    owned = (blocks >= start) & (blocks < end)
    flags = np.zeros((len(blocks), 3), dtype=np.int8)
    flags[owned] = owned_supports(V, supported, blocks[owned])
    V.mesh.comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)
    return flags.astype(bool)


def symmetry_axes(slave_flags: np.ndarray, X_slave: np.ndarray, indptr: np.ndarray, X_master: np.ndarray,
                  master_flags: np.ndarray, in_plane: float) -> np.ndarray:
    """(n, 3) bool: the supported axes of each pair's slave node that are symmetry planes of the interface.

    Parameters
    ----------
    slave_flags
        (n, 3) the slave nodes' prescribed components.
    X_slave
        (n, 3) the slave nodes' positions.
    indptr, X_master, master_flags
        CSR over the n pairs: each entry a master node of the pair, its position (entries, 3) and
        prescribed components (entries, 3).
    in_plane
        The distance along an axis within which a master node lies in the slave node's plane.
    """
    n = len(slave_flags)
    pair = np.repeat(np.arange(n), np.diff(indptr))
    on_plane = np.abs(X_master - X_slave[pair]) <= in_plane  # (entries, 3): in the plane x_k = X_j,k
    any_on_plane = np.zeros((n, 3), dtype=bool)
    np.logical_or.at(any_on_plane, pair, on_plane)
    free_on_plane = np.zeros((n, 3), dtype=bool)
    np.logical_or.at(free_on_plane, pair, on_plane & ~master_flags)
    axes = slave_flags & any_on_plane & ~free_on_plane
    axes[slave_flags.all(axis=1)] = True  # fully supported: held in all three, as before this rule
    return axes


def tangents_in_span(R: np.ndarray, flags: np.ndarray) -> np.ndarray:
    """(n, 3) bool: the tangents t1, t2 of the frames R (n, 3, 3) lying in the span of the axes
    ``flags`` (n, 3) (their other components vanish); column 0 (the normal) False."""
    free_part = np.abs(R[:, 1:, :]) * ~flags[:, None, :]
    out = np.zeros((len(R), 3), dtype=bool)
    out[:, 1:] = np.all(free_part <= 1e-12, axis=2) & np.any(flags, axis=1)[:, None]
    return out


def overconstraining(R: np.ndarray, candidates: np.ndarray, rows: tuple[np.ndarray, np.ndarray, np.ndarray],
                     free: np.ndarray) -> np.ndarray:
    """(n, 3) bool: the ``candidates`` directions whose rows, on the free dofs, are dependent.

    Each connected group of candidate rows (rows sharing a free dof) whose matrix has rank below
    its number of rows (:data:`DEPENDENT`) is returned whole.

    Parameters
    ----------
    R
        (n, 3, 3) the pair frames.
    candidates
        (n, 3) bool: directions to examine.
    rows
        Each pair's nodes as CSR (indptr, node indices into ``free``, coefficients): the row of
        direction d of pair j is Σ_i coefficient_i R[j, d] ⊗ e_node_i.
    free
        (nodes, 3) bool: the free dofs of every node ``rows`` names.
    """
    pair, direction = np.nonzero(candidates)
    out = np.zeros_like(candidates)
    if len(pair) == 0:
        return out
    indptr, nodes, coefficients = rows
    counts = np.diff(indptr)[pair]
    row = np.repeat(np.arange(len(pair)), counts)
    entry = np.repeat(indptr[pair] - np.concatenate([[0], np.cumsum(counts)])[:-1], counts) + np.arange(counts.sum())
    values = coefficients[entry][:, None] * R[pair, direction][row]  # (entries, 3)
    at, component = np.nonzero(free[nodes[entry]] & (values != 0.0))
    columns, column = np.unique(3 * nodes[entry][at] + component, return_inverse=True)
    _, group = connected_components(len(pair) + len(columns), row[at], len(pair) + column.reshape(-1))
    for g in np.unique(group[:len(pair)]):
        members = np.flatnonzero(group[:len(pair)] == g)
        mine = np.isin(row[at], members)
        cols = np.unique(column.reshape(-1)[mine])
        A = np.zeros((len(members), len(cols)))
        np.add.at(A, (np.searchsorted(members, row[at][mine]), np.searchsorted(cols, column.reshape(-1)[mine])),
                  values[at[mine], component[mine]])
        s = np.linalg.svd(A, compute_uv=False) if A.size else np.zeros(0)
        if len(s) < len(members) or s.min(initial=np.inf) <= DEPENDENT * s.max(initial=0.0):
            out[pair[members], direction[members]] = True
    return out


def support_rules(V: dolfinx.fem.FunctionSpace, supported: np.ndarray, slave_index: np.ndarray, X_slave: np.ndarray,
                  normal: np.ndarray,
                  master_indptr: np.ndarray, master_index: np.ndarray, X_master: np.ndarray,
                  rows: tuple[np.ndarray, np.ndarray, np.ndarray], in_plane: float) -> SupportRules:
    """The normals and pinned directions of every pair (module docstring; collective).

    Every argument describes all pairs, the same on every rank: the slave nodes (global dof
    blocks, positions, unit normals), the master nodes of each pair (CSR: global dof blocks and
    positions), each pair's nodes (``rows``: CSR of global dof blocks and coefficients, slave and
    master side), and ``in_plane`` (:data:`IN_PLANE` × the master's facet size).
    """
    indptr, row_blocks, coefficients = rows
    blocks = np.unique(np.concatenate([slave_index, master_index, row_blocks]))
    flags = supports_of(V, supported, blocks)
    slave_flags = flags[np.searchsorted(blocks, slave_index)]
    axes = symmetry_axes(slave_flags, X_slave, master_indptr, X_master,
                         flags[np.searchsorted(blocks, master_index)], in_plane)
    turned = symmetry_normals(normal, axes)
    R = local_frames(turned) if len(turned) else np.zeros((0, 3, 3))
    symmetric = tangents_in_span(R, axes)
    candidates = tangents_in_span(R, slave_flags) & ~symmetric
    dependent = overconstraining(R, candidates, (indptr, np.searchsorted(blocks, row_blocks), coefficients), ~flags)
    return SupportRules(turned, symmetric | dependent, _note(normal, turned, slave_flags, axes, dependent))


def _note(given: np.ndarray, turned: np.ndarray, slave_flags: np.ndarray, axes: np.ndarray,
          dependent: np.ndarray) -> str:
    """How many slave normals were turned (and by how much at most), how many supported slave
    nodes are on no symmetry plane, and at how many of them friction is pinned."""
    moved = np.linalg.norm(turned - given, axis=1) > ROUND_OFF
    angle = np.degrees(np.arccos(np.clip(np.sum(turned * given, axis=1), -1.0, 1.0)))
    partly = slave_flags.any(axis=1) & ~slave_flags.all(axis=1)
    alone = np.count_nonzero(partly & np.any(slave_flags & ~axes, axis=1))
    pinned = np.count_nonzero(dependent.any(axis=1))
    words = ""
    if moved.any():
        words += (f"; normals of {np.count_nonzero(moved)} slave nodes on symmetry planes turned into the plane "
                  f"(by at most {angle[moved].max():.3g}°)")
    if alone:
        words += (f"; {alone} slave nodes supported on their side alone (no symmetry plane: the master is free "
                  "there) keep their normals")
    if pinned:
        words += (f"; friction along the support pinned at {pinned} of them: their rows would over-constrain "
                  "the master (more slave nodes along a supported edge than master nodes under it; the coarser "
                  "side as slave keeps it)")
    return words
