"""Isotropic hardening laws σ_y(p): linear, Voce, and a piecewise-linear table.

Each law gives the yield stress σ_y(p) and its slope H'(p) = dσ_y/dp on arrays of equivalent
plastic strains p ≥ 0, and checks its parameters: a refusal names the parameter and the reason.
Softening (a falling yield stress) is refused: without a regularisation its answer depends on
the mesh (the plastic zone shrinks to one row of elements as the mesh is refined).

* :class:`LinearHardening` — σ_y0 + H p (H = 0: perfect plasticity, e.g. for limit loads);
* :class:`VoceHardening` — σ_0 + Q (1 − e^{−b p}) + H p;
* :class:`TabulatedHardening` — a table of (σ_y, p) rows in CalculiX's ``*PLASTIC`` order (stress
  first): the first row at p = 0 gives the initial yield stress, σ_y is linear between rows and
  CONSTANT beyond the last one (CalculiX's own rule, its ``ident`` lookup in the plasticity
  routines: past the last point the yield stress of the last point, slope 0). At a row's p
  exactly, the slope is the next segment's (the segment that holds p, as CalculiX's lookup
  finds it).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from dolfinx_nnqem.material.parameters import HIGH, LOW, check_parameters

__all__ = ["HardeningAtPoints", "IsotropicHardening", "LinearHardening", "TabulatedHardening", "VoceHardening"]


class IsotropicHardening:
    """The base of the hardening laws: σ_y(p) and H'(p) on arrays."""

    def yield_stress(self, p: np.ndarray) -> np.ndarray:  # pragma: no cover - every law defines it
        """σ_y(p), the shape of p."""
        raise NotImplementedError

    def slope(self, p: np.ndarray) -> np.ndarray:  # pragma: no cover - every law defines it
        """H'(p) = dσ_y/dp, the shape of p."""
        raise NotImplementedError

    @property
    def initial_yield_stress(self) -> float:
        """σ_y(0)."""
        return float(self.yield_stress(np.zeros(1))[0])


@dataclass(frozen=True)
class LinearHardening(IsotropicHardening):
    """σ_y = σ_y0 + H p (H = 0: perfect plasticity)."""

    sigma_y0: float
    H: float = 0.0

    def __post_init__(self):
        check_parameters("LinearHardening", [
            ("sigma_y0", self.sigma_y0, lambda v: LOW <= v <= HIGH, f"a value in [{LOW:g}, {HIGH:g}]"),
            ("H", self.H, lambda v: 0 <= v <= HIGH,
             f"a value in [0, {HIGH:g}] (H < 0, softening, makes the answer depend on the mesh)"),
        ])

    def yield_stress(self, p: np.ndarray) -> np.ndarray:
        """σ_y0 + H p."""
        return self.sigma_y0 + self.H * p

    def slope(self, p: np.ndarray) -> np.ndarray:
        """H, the shape of p."""
        return np.full(np.shape(p), float(self.H))


@dataclass(frozen=True)
class VoceHardening(IsotropicHardening):
    """σ_y = σ_0 + Q (1 − e^{−b p}) + H p: saturating hardening (Q ≥ 0 the saturation stress, b > 0
    its rate), with a linear term H ≥ 0."""

    sigma_0: float
    Q: float
    b: float
    H: float = 0.0

    def __post_init__(self):
        softening = "(a negative value is softening, which makes the answer depend on the mesh)"
        check_parameters("VoceHardening", [
            ("sigma_0", self.sigma_0, lambda v: LOW <= v <= HIGH, f"a value in [{LOW:g}, {HIGH:g}]"),
            ("Q", self.Q, lambda v: 0 <= v <= HIGH, f"a value in [0, {HIGH:g}] {softening}"),
            ("b", self.b, lambda v: 0 < v <= HIGH, f"a value in (0, {HIGH:g}]"),
            ("H", self.H, lambda v: 0 <= v <= HIGH, f"a value in [0, {HIGH:g}] {softening}"),
        ])

    def yield_stress(self, p: np.ndarray) -> np.ndarray:
        """σ_0 + Q (1 − e^{−b p}) + H p."""
        return self.sigma_0 + self.Q * (1.0 - np.exp(-self.b * p)) + self.H * p

    def slope(self, p: np.ndarray) -> np.ndarray:
        """Q b e^{−b p} + H."""
        return self.Q * self.b * np.exp(-self.b * p) + self.H


@dataclass(frozen=True)
class TabulatedHardening(IsotropicHardening):
    """A piecewise-linear σ_y(p) from rows (σ_y, p), CalculiX ``*PLASTIC`` order (stress first).

    The first row must be at p = 0 (the initial yield stress); p rises strictly from row to row;
    σ_y does not fall (softening is refused); at least two rows. Beyond the last row σ_y stays
    at the last value (perfect plasticity), as in CalculiX.
    """

    table: tuple[tuple[float, float], ...]

    def __init__(self, table: Sequence[Sequence[float]]):
        rows = _checked_table(table)
        object.__setattr__(self, "table", tuple((float(s), float(p)) for s, p in rows))

    @property
    def stresses(self) -> np.ndarray:
        """The table's σ_y column."""
        return np.array([s for s, _ in self.table])

    @property
    def strains(self) -> np.ndarray:
        """The table's p column."""
        return np.array([p for _, p in self.table])

    def _segment(self, p: np.ndarray) -> np.ndarray:
        """The segment that holds p: k with p_k ≤ p < p_{k+1}; the last row's index beyond it."""
        return np.searchsorted(self.strains, p, side="right") - 1

    def yield_stress(self, p: np.ndarray) -> np.ndarray:
        """σ_y(p), linear between the rows and the last row's beyond it."""
        p = np.asarray(p, dtype=float)
        k = np.clip(self._segment(p), 0, len(self.table) - 1)
        slope = self.slope(p)
        return self.stresses[k] + slope * (p - self.strains[k])

    def slope(self, p: np.ndarray) -> np.ndarray:
        """The slope of the segment that holds p (the next segment's at a row), 0 beyond the last row."""
        p = np.asarray(p, dtype=float)
        k = self._segment(p)
        s, e = self.stresses, self.strains
        inside = (k >= 0) & (k < len(self.table) - 1)
        kk = np.clip(k, 0, len(self.table) - 2)
        return np.where(inside, (s[kk + 1] - s[kk]) / (e[kk + 1] - e[kk]), 0.0)


def _checked_table(table) -> list[tuple[float, float]]:
    """The rows of a hardening table, or a ValueError naming what is wrong."""
    try:
        rows = [tuple(row) for row in table]
    except TypeError:
        raise ValueError(f"TabulatedHardening: table = {table!r}: expected rows [sigma_y, p]") from None
    if len(rows) < 2:
        raise ValueError(f"TabulatedHardening: table has {len(rows)} row(s); expected at least two rows "
                         "[sigma_y, p] (one row is a constant yield stress: use LinearHardening)")
    out = []
    for i, row in enumerate(rows):
        if len(row) != 2:
            raise ValueError(f"TabulatedHardening: table[{i}] = {list(row)!r}: expected [sigma_y, p]")
        check_parameters(f"TabulatedHardening: table[{i}]", [
            ("sigma_y", row[0], lambda v: LOW <= v <= HIGH, f"a yield stress in [{LOW:g}, {HIGH:g}]"),
            ("p", row[1], lambda v: 0 <= v <= HIGH, "an equivalent plastic strain >= 0"),
        ])
        out.append((float(row[0]), float(row[1])))
    if out[0][1] != 0.0:
        raise ValueError(f"TabulatedHardening: table[0] has p = {out[0][1]!r}; the first row must be at p = 0 "
                         "(its sigma_y is the initial yield stress, as in CalculiX's *PLASTIC)")
    for i in range(1, len(out)):
        if not out[i][1] > out[i - 1][1]:
            raise ValueError(f"TabulatedHardening: table is not increasing in p: table[{i}] has p = {out[i][1]!r} "
                             f"after p = {out[i - 1][1]!r}; p must rise strictly from row to row")
        if out[i][0] < out[i - 1][0]:
            raise ValueError(f"TabulatedHardening: table[{i}] has sigma_y = {out[i][0]!r} below the previous row's "
                             f"{out[i - 1][0]!r}: softening (a falling yield stress) makes the answer depend on the "
                             "mesh without a regularisation, and is refused")
    return out


class HardeningAtPoints:
    """The hardening laws of a set of Gauss points: point j follows ``laws[law_index[j]]``."""

    def __init__(self, law_index: np.ndarray, laws: Sequence[IsotropicHardening]):
        self.law_index = np.asarray(law_index, dtype=np.int64)
        self.laws = tuple(laws)

    def _each(self, p: np.ndarray, rule: Callable[[IsotropicHardening, np.ndarray], np.ndarray]) -> np.ndarray:
        p = np.asarray(p, dtype=float)
        out = np.empty_like(p)
        for k, law in enumerate(self.laws):
            mask = self.law_index == k
            if np.any(mask):
                out[mask] = rule(law, p[mask])
        return out

    def yield_stress(self, p: np.ndarray) -> np.ndarray:
        """σ_y(p) (n,)."""
        return self._each(p, lambda law, q: law.yield_stress(q))

    def slope(self, p: np.ndarray) -> np.ndarray:
        """H'(p) = dσ_y/dp (n,)."""
        return self._each(p, lambda law, q: law.slope(q))

    def subset(self, index: slice | np.ndarray) -> HardeningAtPoints:
        """The laws of the points ``index`` selects (a slice, a boolean mask or indices)."""
        return HardeningAtPoints(self.law_index[index], self.laws)

    def gathered(self, gather: Callable[[np.ndarray], np.ndarray]) -> HardeningAtPoints:
        """The laws with ``law_index`` passed through ``gather``."""
        return HardeningAtPoints(gather(self.law_index), self.laws)

