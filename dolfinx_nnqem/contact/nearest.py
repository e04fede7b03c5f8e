"""Nearest-point queries of contact search, without importing SciPy for small surfaces.

A KD-tree (:class:`scipy.spatial.cKDTree`) answers a nearest-point query in O(log n), but
importing ``scipy.spatial`` costs about 0.18 s of CPU at every run's start (it pulls in
``scipy.sparse`` and ``scipy.linalg``; measured, docs/performance.md), more than a direct
comparison of every query with every point costs below :data:`DIRECT_PAIRS` pairs. Larger
searches build the tree (importing SciPy once then).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["DIRECT_PAIRS", "nearest"]

DIRECT_PAIRS = 2_000_000
"""Largest number of (query, point) pairs compared directly; above it a KD-tree is built."""

_CHUNK = 200_000
"""(query, point) pairs per block of the direct comparison (bounds its memory to a few MB)."""


def nearest(points: npt.ArrayLike, queries: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """For every query point, the distance to the nearest of ``points`` and its index.

    Parameters
    ----------
    points
        (n, 3) points searched (n ≥ 1).
    queries
        (m, 3) query points.

    Returns
    -------
    distance, index
        (m,) Euclidean distances and (m,) indices into ``points``; among equally near points
        the direct comparison returns the first, the KD-tree any one of them.
    """
    points = np.asarray(points, dtype=np.float64)
    queries = np.asarray(queries, dtype=np.float64)
    if len(points) == 0:
        raise ValueError("nearest: no points to search")
    if len(points) * len(queries) > DIRECT_PAIRS:
        from scipy.spatial import cKDTree  # only for large searches: the import costs more than small ones

        distance, index = cKDTree(points).query(queries)
        return np.asarray(distance), np.asarray(index, dtype=np.int64)
    distance = np.empty(len(queries))
    index = np.empty(len(queries), dtype=np.int64)
    rows = max(1, _CHUNK // len(points))
    for start in range(0, len(queries), rows):
        block = queries[start:start + rows]
        squared = ((block[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
        best = np.argmin(squared, axis=1)
        index[start:start + rows] = best
        distance[start:start + rows] = np.sqrt(squared[np.arange(len(block)), best])
    return distance, index
