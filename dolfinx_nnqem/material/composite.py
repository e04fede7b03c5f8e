"""The pointwise material of Gauss points that belong to bodies of different material kinds.

Each point belongs to one part (``owner``); every method asks each part's pointwise material for
its own points and puts the answers back in the points' order. A mesh of one material kind
never meets this class: its part's pointwise material is used as it is.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from dolfinx_nnqem.material.interface import PointwiseMaterial

__all__ = ["CompositeAtPoints"]


class CompositeAtPoints:
    """:class:`~dolfinx_nnqem.material.interface.PointwiseMaterial` of points of several parts.

    Parameters
    ----------
    owner
        (n,) the part of every point.
    parts
        Part k's pointwise material at the points ``np.flatnonzero(owner == k)``, in that order.
    """

    def __init__(self, owner: np.ndarray, parts: list[PointwiseMaterial]):
        self.owner = np.asarray(owner)
        self.parts = list(parts)
        self._masks = [self.owner == k for k in range(len(self.parts))]

    # -- per-point arrays ----------------------------------------------------------------------------------
    def _scattered(self, values: list[np.ndarray]) -> np.ndarray:
        """Per-part arrays (each over the part's points) as one array over every point."""
        first = next((np.asarray(v) for v in values if np.asarray(v).shape[0]), np.asarray(values[0]))
        out = np.zeros((self.owner.size, *first.shape[1:]), dtype=first.dtype)
        for mask, v in zip(self._masks, values):
            out[mask] = v
        return out

    def _each(self, method: str, *arrays: np.ndarray, internal: Mapping[str, np.ndarray] | None = None):
        """``method`` of every part at its points (``arrays`` and ``internal`` split accordingly)."""
        out = []
        for mask, part in zip(self._masks, self.parts):
            args: list[object] = [np.asarray(a)[mask] for a in arrays]
            if internal is not None:
                args.append({name: np.asarray(v)[mask] for name, v in internal.items()})
            out.append(getattr(part, method)(*args))
        return out

    @property
    def mu(self) -> np.ndarray:
        """Shear modulus (n,), each point's from its part."""
        return self._scattered([p.mu for p in self.parts])

    @property
    def lmbda(self) -> np.ndarray:
        """Lamé's λ (n,), each point's from its part."""
        return self._scattered([p.lmbda for p in self.parts])

    @property
    def stress_unit(self) -> np.ndarray:
        """σ_u (n,), each point's from its part."""
        return self._scattered([p.stress_unit for p in self.parts])

    @property
    def yields(self) -> np.ndarray:
        """(n,) bool: the points whose part's material can yield."""
        return self._scattered([p.yields for p in self.parts])

    @property
    def yield_criterion(self) -> str:
        """The criterion shared by every part with yielding points here ("none" if there is none);
        "mixed" where they differ."""
        criteria = {p.yield_criterion for p, mask in zip(self.parts, self._masks)
                    if np.any(p.yields) and np.any(mask)} or {"none"}
        return criteria.pop() if len(criteria) == 1 else "mixed"

    @property
    def deviatoric_flow(self) -> bool:
        """Every part's plastic strain is deviatoric."""
        return all(p.deviatoric_flow for p in self.parts)

    # -- the return map -------------------------------------------------------------------------------------
    def plastic_strain(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(Δε_p (n, 5), Δp (n,)) of each part's return map at its points."""
        pairs = self._each("plastic_strain", t, internal=internal)
        return self._scattered([e for e, _ in pairs]), self._scattered([dp for _, dp in pairs])

    def plastic_strain_tangent(self, t: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """∂Δε_p/∂e (n, 5, 5), each part's at its points."""
        return self._scattered(self._each("plastic_strain_tangent", t, internal=internal))

    def yield_value(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """f (n,), each part's at its points."""
        return self._scattered(self._each("yield_value", s, internal=internal))

    def flow_direction(self, s: np.ndarray, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """N (the shape of s), each part's at its points."""
        return self._scattered(self._each("flow_direction", s, internal=internal))

    def flow_direction_of(self, s: np.ndarray, deps_p: np.ndarray, dp: np.ndarray,
                          internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """The flow direction that Δε_p is checked against, each part's at its points."""
        return self._scattered(self._each("flow_direction_of", s, deps_p, dp, internal=internal))

    def hardening(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """dσ_y/dp (n,), each part's at its points."""
        return self._scattered(self._each("hardening", internal=internal))

    def yield_stress(self, internal: Mapping[str, np.ndarray]) -> np.ndarray:
        """The size of the elastic domain (n,), each part's at its points."""
        return self._scattered(self._each("yield_stress", internal=internal))

    # -- selections ------------------------------------------------------------------------------------------
    def subset(self, index: slice | np.ndarray) -> CompositeAtPoints:
        """The composite at the points ``index`` selects (a slice, a boolean mask or indices), each part
        at its own of them."""
        owner = self.owner[index]
        parts = []
        for k, (mask, part) in enumerate(zip(self._masks, self.parts)):
            position = np.cumsum(mask) - 1  # each point's place among the part's points
            parts.append(part.subset(np.asarray(position[index])[owner == k]))
        return CompositeAtPoints(owner, parts)

    def gathered(self, gather: Callable[[np.ndarray], np.ndarray]) -> CompositeAtPoints:
        """The composite with the owners and every part's arrays passed through ``gather``."""
        return CompositeAtPoints(gather(self.owner), [part.gathered(gather) for part in self.parts])
