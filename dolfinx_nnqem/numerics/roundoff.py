r"""The round-off floor of a residual: the level below which no iteration can push it.

The unknowns of a converged state are doubles: each u_j is the solution rounded to a relative
ε/2 (ε the machine epsilon), an error spread evenly over that interval, of root mean square
ε |u_j| / √12. A residual R(u) with Jacobian K therefore keeps, at the best representable u, a
part K δu of expected norm

    floor = ε / √12 · sqrt( Σ_i Σ_j K_ij² u_j² )

(i over the rows the residual measures). It is large where u is large against what the residual
balances: stiff bodies that slide far under a small strain carry displacements of the size of the
slide while their forces come from strains of 10⁻⁶ (``docs/robustness.md``, "The round-off
floor"). A tolerance below the floor is met, if at all, by chance: the Newton driver then stops as
stalled, and this module lets it say why, with the tolerance that can be reached.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from petsc4py import PETSc

__all__ = ["EPS", "ROUNDOFF_MARGIN", "dense_floor", "floor_note", "residual_floor"]

EPS = float(np.finfo(np.float64).eps)
ROUNDOFF_MARGIN = 10.0
"""A residual that stopped within this factor of its round-off floor stopped because of round-off
(the floor is an expected value: the measured residuals scatter about 0.7 to 1.7 times it)."""
REACHABLE_FACTOR = 3.0
"""The smallest tolerance worth asking for, in round-off floors: the scatter of the residual
around its floor then leaves it below the tolerance at most iterates."""


def residual_floor(K: PETSc.Mat, u: PETSc.Vec, restrict: Callable[[PETSc.Vec], PETSc.Vec]) -> float:
    """The expected norm of K δu, δu the rounding of ``u`` (module docstring), over the rows
    ``restrict`` keeps (it returns a vector with the others zeroed, e.g. the free dofs). Collective.

    K is an AIJ matrix (its entries are squared in a copy); called when an iteration has stopped,
    never in the loop.
    """
    K2 = K.duplicate(copy=True)
    indptr, indices, values = K2.getValuesCSR()
    K2.setValuesCSR(indptr, indices, values * values)
    K2.assemble()
    u2 = u.duplicate()  # u's layout (ghosted, for ``restrict``)
    u2.getArray()[:] = u.getArray(readonly=True) ** 2
    spread = u.duplicate()
    K2.mult(u2, spread)  # Σ_j K_ij² u_j² per row
    kept = restrict(spread)
    total = max(kept.sum(), 0.0)
    for obj in (K2, u2, spread, kept):
        obj.destroy()
    return EPS / math.sqrt(12.0) * math.sqrt(total)


def dense_floor(A: np.ndarray, x: np.ndarray) -> float:
    """The same floor for a dense system with Jacobian ``A`` at ``x``."""
    return EPS / math.sqrt(12.0) * math.sqrt(float(np.sum((A * A) @ (x * x))))


def floor_note(measure: str, value: float, floor: float, tolerance: float, name: str = "rtol") -> str | None:
    """Why an iteration stopped at ``value`` (the residual ``measure``, e.g. "|R|/F"), if round-off
    explains it: None unless ``value`` is within :data:`ROUNDOFF_MARGIN` of ``floor`` and the
    ``tolerance`` (the ``name`` the user set; all three in the same units) asks for less than
    :data:`REACHABLE_FACTOR` floors."""
    if not (math.isfinite(value) and floor > 0.0) or value > ROUNDOFF_MARGIN * floor \
            or tolerance >= REACHABLE_FACTOR * floor:
        return None
    reachable = float(f"{REACHABLE_FACTOR * floor:.0e}")  # one significant digit ...
    if reachable < REACHABLE_FACTOR * floor:
        reachable = float(f"{reachable + 10.0 ** math.floor(math.log10(reachable)):.0e}")  # ... rounded up
    return (f"round-off: {name} {tolerance:.1e} is at or below the round-off floor ~{floor:.1e} of this problem at "
            f"this load ({measure} = {value:.1e} at the last iterate: the unknowns' rounding to double precision, "
            f"times the Jacobian, is that large, and grows with them); the smallest reachable {name} here is about "
            f"{reachable:.0e}")
