"""The node layout of contact facets, linear and quadratic, and the transformed basis's node rows.

Numbers and tables only (no numba): every pair set needs them, while the shape-function kernels
of :mod:`dolfinx_nnqem.contact.quadratic_facets` are compiled only where a quadratic facet is met
(numba's import and start cost a small linear run a third of its time). The node order, the
transformed basis N̂ = T N and its rows d̂ = T⁻ᵀ d are explained in that module's docstring.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["ALPHA", "EDGES", "NUM_VERTICES", "QUADRATIC", "NodeCombination", "is_quadratic", "node_combination"]

QUADRATIC = (6, 9)
"""Nodes per quadratic facet: tri6, quad9."""

NUM_VERTICES = {3: 3, 4: 4, 6: 3, 9: 4}
"""Vertices of a facet with k nodes."""

EDGES = {6: ((1, 2), (0, 2), (0, 1)), 9: ((0, 1), (0, 2), (1, 3), (2, 3))}
"""The vertices (positions in the facet) of the edge of each edge node, in node order."""

ALPHA = {6: 0.2, 9: 0.0}
"""The fraction α of each adjacent edge function a vertex function takes (module docstring)."""


def is_quadratic(k: int) -> bool:
    """Whether facets of k nodes are quadratic (tri6, quad9)."""
    return k in QUADRATIC


@dataclass(frozen=True)
class NodeCombination:
    """The rows d̂_j = Σ_i t_ji d_i over a surface's nodes (CSR; columns are row positions too).

    The identity for linear facets and quad9; for tri6, the edge nodes' rows involve their edge's
    vertices (module docstring). Every row sums to 1, so a rigid translation moves d̂ like d.
    """

    indptr: np.ndarray
    columns: np.ndarray
    coefficients: np.ndarray

    @classmethod
    def identity(cls, p: int) -> NodeCombination:
        """The identity on ``p`` nodes: row j is node j alone, with coefficient 1."""
        return cls(np.arange(p + 1, dtype=np.int64), np.arange(p, dtype=np.int64), np.ones(p))

    def row(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """The columns and coefficients of row j."""
        span = slice(self.indptr[j], self.indptr[j + 1])
        return self.columns[span], self.coefficients[span]

    def take(self, rows: np.ndarray) -> NodeCombination:
        """The given rows, in that order (columns unchanged)."""
        rows = np.asarray(rows, dtype=np.int64)
        counts = self.indptr[rows + 1] - self.indptr[rows]
        indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        entries = np.repeat(self.indptr[rows] - indptr[:-1], counts) + np.arange(indptr[-1])
        return NodeCombination(indptr, self.columns[entries], self.coefficients[entries])

    def apply(self, values: np.ndarray) -> np.ndarray:
        """Σ_i t_ji values_i for every row j (``values`` indexed by the column positions)."""
        rows = np.repeat(np.arange(len(self.indptr) - 1), np.diff(self.indptr))
        terms = self.coefficients.reshape((-1,) + (1,) * (np.ndim(values) - 1)) * np.asarray(values)[self.columns]
        out = np.zeros((len(self.indptr) - 1,) + np.shape(values)[1:])
        np.add.at(out, rows, terms)
        return out


def node_combination(facet_nodes: npt.ArrayLike, index: npt.ArrayLike) -> NodeCombination:
    """The rows of d̂ = T⁻ᵀ d over the nodes ``index`` (sorted) of a surface of facets ``facet_nodes``.

    Parameters
    ----------
    facet_nodes
        (m, k) the facets' nodes (any labels present in ``index``), in this module's order.
    index
        (p,) the surface's nodes, sorted: row j is node ``index[j]``, columns are positions in it.
    """
    facet_nodes = np.asarray(facet_nodes, dtype=np.int64)
    index = np.asarray(index, dtype=np.int64)
    p, k = len(index), facet_nodes.shape[1]
    alpha = ALPHA.get(k, 0.0)
    if alpha == 0.0:
        return NodeCombination.identity(p)
    nv = NUM_VERTICES[k]
    position = np.searchsorted(index, facet_nodes)
    edge = position[:, nv:].ravel()
    ends = np.stack([position[:, list(pair)] for pair in EDGES[k]], axis=1).reshape(-1, 2)
    edge, first = np.unique(edge, return_index=True)
    ends = ends[first]
    c = 1.0 - 2.0 * alpha
    counts = np.ones(p, dtype=np.int64)
    counts[edge] = 3
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    columns = np.empty(indptr[-1], dtype=np.int64)
    coefficients = np.empty(indptr[-1])
    columns[indptr[:-1]] = np.arange(p)
    coefficients[indptr[:-1]] = 1.0
    coefficients[indptr[edge]] = 1.0 / c
    columns[indptr[edge] + 1], columns[indptr[edge] + 2] = ends[:, 0], ends[:, 1]
    coefficients[indptr[edge] + 1] = coefficients[indptr[edge] + 2] = -alpha / c
    return NodeCombination(indptr, columns, coefficients)
