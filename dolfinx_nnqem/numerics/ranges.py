"""Range checks of single numbers, shared by every layer that takes a user's value.

Each raises :class:`ValueError` (or :class:`TypeError`) naming the value; numpy scalars are
accepted wherever Python numbers are. The ranges are documented in docs/reliability.md
("Supported ranges").
"""

from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["MAX_MAGNITUDE", "MIN_MODULUS", "check_integer", "check_magnitude", "check_real", "shown"]

MAX_MAGNITUDE = 1e20
"""Largest magnitude of a dimensional input: moduli, yield stress, density, loads, prescribed
displacements and motions, obstacle geometry, r, μ_f. Within it (and with the moduli not below
:data:`MIN_MODULUS`) the products and squares the solvers form (stiffness × displacement,
r × gap, the sums of squares of norms) stay far inside double precision (±1.8e308); E, a
traction, a density, r or a prescribed value of 1e300 overflowed to NaN in the first iteration
(issue 31). Any consistent unit system fits: Pa and m, MPa and mm, GPa."""
MIN_MODULUS = 1e-20
"""Smallest Young's modulus and yield stress: E = 1e-300 made the displacements overflow."""


def shown(value) -> str:
    """A user's value as a message shows it: numpy scalars as the Python numbers they hold, numpy
    arrays as lists, in lists and tuples too (numpy 2 writes ``repr(np.float64(nan))`` as
    "np.float64(nan)", which is no input anyone typed)."""
    return repr(_plain(value))


def _plain(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return type(value)(_plain(v) for v in value)
    return value


def check_magnitude(name: str, values, limit: float = MAX_MAGNITUDE) -> None:
    """Raise ValueError naming ``name`` when a component of ``values`` exceeds ``limit`` in
    magnitude (the values are finite numbers already)."""
    array = np.abs(np.atleast_1d(np.asarray(values, dtype=float)))
    if array.size and float(array.max()) > limit:
        raise ValueError(f"{name} = {shown(values)}: beyond the supported magnitude {limit:g} (a value this large "
                         "overflows double precision in the solvers' products; docs/reliability.md, "
                         "'Supported ranges')")


def check_real(name: str, value, *, low: float = -math.inf, high: float = math.inf,
               low_inclusive: bool = False) -> float:
    """``value`` as a float: a finite real (not a bool) in (low, high] (or [low, high])."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} = {shown(value)}: expected a number")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"{name} = {shown(value)}: expected a finite number")
    if (x < low if low_inclusive else x <= low) or x > high:
        bracket = "[" if low_inclusive else "("
        raise ValueError(f"{name} = {shown(value)}: expected a value in {bracket}{low:g}, {high:g}]")
    return x


def check_integer(name: str, value, *, low: int, high: int) -> int:
    """``value`` as an int: an integer (Python or numpy, not a bool) in [low, high]."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} = {shown(value)}: expected an integer")
    n = int(value)
    if not low <= n <= high:
        raise ValueError(f"{name} = {shown(value)}: expected an integer in [{low}, {high}]")
    return n
