"""The secant predictor: an increment starts from the linear extrapolation of the last two converged ones.

u ← u_n + β (u_n − u_{n−1}), the pair forces likewise (:meth:`ContactModel.extrapolate
<dolfinx_nnqem.contact.model.ContactModel.extrapolate>`), with β the ratio of this increment's
change of the load amplitudes to the last one's: Δℓ / Δℓ_previous when every load follows ℓ.
Where the load path turns (the changes of the amplitudes are not parallel: e.g. a pressure stops
rising and a drag starts) the last increment's response says little about this one's, and no
prediction is made.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from dolfinx_nnqem.contact.model import ContactModel
    from dolfinx_nnqem.contact.geometry_tracking import Remap

__all__ = ["History", "SecantPredictor"]

History = tuple[float, np.ndarray, "np.ndarray | None"]
"""``(ℓ, u, z)`` of the increment before the last converged one."""

TURN_TOLERANCE = 1e-3
"""The load path turns where the new change of the amplitudes leaves the last one's line by more
than this fraction of its length."""


class SecantPredictor:
    """The history the secant predictor needs, and the prediction.

    Attributes
    ----------
    history
        ``(ℓ, u, z)`` of the increment before the last converged one (None before two increments
        exist): u the local array (ghosts included), z this rank's pair unknowns (None without
        contact).
    """

    def __init__(self) -> None:
        self.history: History | None = None

    def factor(self, amplitudes: Callable[[float], np.ndarray], load_factor_n: float,
               load_factor: float) -> float | None:
        """β to ``load_factor`` from the last converged ``load_factor_n``; None before two increments
        exist or where the load path turns.

        Parameters
        ----------
        amplitudes
            The amplitudes of every load, support and obstacle motion at a load factor.
        load_factor_n, load_factor
            The last converged load factor and the one of the increment to predict.
        """
        if self.history is None:
            return None
        ell_prev = self.history[0]
        a_n = amplitudes(load_factor_n)
        d_prev = a_n - amplitudes(ell_prev)
        d_new = amplitudes(load_factor) - a_n
        norm_prev = float(d_prev @ d_prev)
        if norm_prev == 0.0:
            return None
        beta = float(d_new @ d_prev) / norm_prev
        if np.linalg.norm(d_new - beta * d_prev) > TURN_TOLERANCE * np.linalg.norm(d_new):
            return None  # the load path turns here
        return beta

    def extrapolate(self, u: np.ndarray, u_n: np.ndarray, contact: ContactModel | None, beta: float) -> None:
        """u ← u_n + β (u_n − u_{n−1}) in place, the contact model's unknowns likewise."""
        assert self.history is not None  # beta needs it
        _, u_prev, z_prev = self.history
        u[:] = u_n + beta * (u_n - u_prev)
        if contact is not None:
            assert z_prev is not None  # committed with contact
            contact.extrapolate(z_prev, beta)

    def record(self, load_factor_n: float, u_n: np.ndarray, z_n: np.ndarray | None) -> None:
        """Keep the converged increment about to be superseded (copies of u_n and z_n)."""
        self.history = (load_factor_n, u_n.copy(), None if z_n is None else z_n.copy())

    def restore(self, history: tuple | None, u_shape: tuple[int, ...], num_pairs: int | None) -> None:
        """Set :attr:`history` from a checkpoint of the same problem and partition (``num_pairs``:
        this rank's pairs, None without contact).

        Raises
        ------
        ValueError
            If u has another shape than ``u_shape``.
        """
        if history is not None:
            ell, u, z = history
            u = np.array(u, dtype=float)
            if u.shape != u_shape:
                raise ValueError(f"predictor history: u has shape {u.shape}, expected {u_shape}")
            z = np.array(z, dtype=float).reshape(num_pairs, 3) if num_pairs is not None else None
            history = (float(ell), u, z)
        self.history = history

    def follow_pairs(self, remap: Remap, z_n: np.ndarray) -> None:
        """The history's pair unknowns after the pairs changed (a new pair: no change to extrapolate)."""
        if self.history is not None:
            ell, u_prev, z_prev = self.history
            if z_prev is not None:
                self.history = (ell, u_prev, remap(z_prev, z_n))

    def clear(self) -> None:
        """Forget the history (a run starting again from the initial state)."""
        self.history = None
