"""Piecewise-linear functions of the load factor: load amplitudes a(ℓ) and obstacle paths d(ℓ).

Problem files cannot hold Python functions, so a non-proportional load path is a table of
points (ℓ_k, value_k), linear between them and constant beyond the first and last point. Both
classes are plain callables: they work wherever an ``amplitude`` or ``motion`` function does.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dolfinx_nnqem.numerics.ranges import check_magnitude

__all__ = ["PiecewiseLinear", "PiecewiseLinearPath"]


def _table(points, width: int, what: str) -> np.ndarray:
    try:
        table = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{what} = {points!r}: expected a list of [ℓ, value] rows") from None
    if table.ndim != 2 or table.shape[1] != width or len(table) < 1:
        raise ValueError(f"{what}: expected rows of {width} numbers (ℓ then the value), got shape {table.shape}")
    if not np.all(np.isfinite(table)):
        raise ValueError(f"{what}: every entry must be finite")
    check_magnitude(what, table)
    if np.any(np.diff(table[:, 0]) <= 0.0):
        raise ValueError(f"{what}: the load factors ℓ of the rows must increase strictly, got {table[:, 0].tolist()}")
    return table


@dataclass(frozen=True)
class PiecewiseLinear:
    """a(ℓ) through the points ``[(ℓ_0, a_0), (ℓ_1, a_1), ...]`` (ℓ strictly increasing)."""

    points: Sequence[Sequence[float]]

    def __post_init__(self):
        _table(self.points, 2, "amplitude")

    def __call__(self, load_factor: float) -> float:
        table = np.asarray(self.points, dtype=np.float64)
        value = float(np.interp(load_factor, table[:, 0], table[:, 1]))
        if not math.isfinite(value):
            raise ValueError(f"amplitude: no finite value at load factor {load_factor}")
        return value


@dataclass(frozen=True)
class PiecewiseLinearPath:
    """d(ℓ) ∈ R³ through the points ``[(ℓ_0, dx_0, dy_0, dz_0), ...]`` (ℓ strictly increasing)."""

    points: Sequence[Sequence[float]]

    def __post_init__(self):
        _table(self.points, 4, "motion path")

    def __call__(self, load_factor: float) -> np.ndarray:
        table = np.asarray(self.points, dtype=np.float64)
        return np.array([np.interp(load_factor, table[:, 0], table[:, k]) for k in (1, 2, 3)])
