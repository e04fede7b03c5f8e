"""Anderson acceleration of a fixed-point iteration x ← G(x).

The plain iteration x_{k+1} = G(x_k) converges linearly, at the rate of G's contraction. Anderson
mixing (type II; Walker and Ni, SIAM J. Numer. Anal. 49 (2011)) keeps the last ``depth``
differences of the images g_k = G(x_k) and of the residuals f_k = g_k − x_k, and takes

    γ = argmin ‖f_k − ΔF γ‖₂,        x_{k+1} = g_k − ΔG γ,

the image of the combination of the last iterates whose linearised residual is smallest. With
``depth = 0`` it is the plain iteration. Used by NNEQM2's fixed point on the flow directions.
"""

from __future__ import annotations

import numpy as np

__all__ = ["AndersonMixing"]


class AndersonMixing:
    """The next iterate of x ← G(x) from the last ``depth`` + 1 pairs (x_k, G(x_k))."""

    def __init__(self, depth: int):
        if depth < 0:
            raise ValueError(f"AndersonMixing: depth = {depth}; expected an integer >= 0")
        self.depth = depth
        self._images: list[np.ndarray] = []
        self._residuals: list[np.ndarray] = []

    def next(self, x: np.ndarray, g: np.ndarray) -> np.ndarray:
        """x_{k+1} from the current iterate ``x`` and its image ``g`` = G(x) (same shape)."""
        g = np.asarray(g, dtype=np.float64)
        if self.depth == 0:
            return g.copy()
        self._images.append(g.reshape(-1).copy())
        self._residuals.append(g.reshape(-1) - np.asarray(x, dtype=np.float64).reshape(-1))
        del self._images[:-(self.depth + 1)], self._residuals[:-(self.depth + 1)]
        if len(self._images) < 2:
            return g.copy()
        dG = np.diff(np.array(self._images), axis=0).T
        dF = np.diff(np.array(self._residuals), axis=0).T
        gamma = np.linalg.lstsq(dF, self._residuals[-1], rcond=None)[0]
        return (self._images[-1] - dG @ gamma).reshape(g.shape)
