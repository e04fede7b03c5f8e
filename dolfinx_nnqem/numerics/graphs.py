"""Connected components of an undirected graph, in NumPy.

:func:`scipy.sparse.csgraph.connected_components` gives the same partition, but importing
``scipy.sparse`` costs about 0.1 s of every run's start (measured, docs/performance.md), and
finding the bodies of a mesh is the only use a run has for it.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["connected_components"]


def connected_components(n: int, rows: npt.ArrayLike, cols: npt.ArrayLike) -> tuple[int, np.ndarray]:
    """The components of the undirected graph on vertices 0..n-1 with edges (rows[k], cols[k]).

    Returns the number of components and each vertex's component, numbered in the order of the
    components' smallest vertices (the numbering of scipy's ``connected_components``).

    Every vertex points at a root (``root[v] ≤ v``, a vertex of its component). Each round hooks
    the larger root of every edge whose ends have different roots onto the smaller one, then
    follows the pointers until every vertex points at a root. A component's root ends as its
    smallest vertex; the rounds are few (logarithmic in the component's diameter in practice).
    """
    rows = np.asarray(rows, dtype=np.int64)
    cols = np.asarray(cols, dtype=np.int64)
    root = np.arange(n, dtype=np.int64)
    while True:
        a, b = root[rows], root[cols]
        differ = a != b
        if not np.any(differ):
            break
        a, b = a[differ], b[differ]
        np.minimum.at(root, np.maximum(a, b), np.minimum(a, b))
        root = _compress(root)
    roots, label = np.unique(root, return_inverse=True)
    return len(roots), label.astype(np.int32)


def _compress(root: np.ndarray) -> np.ndarray:
    """Follow ``root`` until every vertex points at a vertex that points at itself."""
    while True:
        jumped = root[root]
        if np.array_equal(jumped, root):
            return root
        root = jumped
