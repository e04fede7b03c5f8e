"""Checks of material parameters every material shares (elastic moduli, density): one place for
the supported ranges and for the wording of a refusal (the parameter, its value, what is expected)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from dolfinx_nnqem.numerics.ranges import MAX_MAGNITUDE as HIGH
from dolfinx_nnqem.numerics.ranges import MIN_MODULUS as LOW

__all__ = ["HIGH", "LOW", "NU_RANGE", "check_parameters", "elastic_checks", "lame"]

NU_RANGE = (-0.999, 0.4999)
"""Supported Poisson's ratios: κ/μ ≤ 5000 and μ/κ ≤ 4500. Every solver converged on the two-beam
benchmark up to ν = 0.49999 (κ/μ = 5e4) and down to −0.9999; at ν = 0.4999999 the monolithic
solver and NNEQM1 fail at the first increment (issue 31): one decade of margin."""

Check = tuple[str, object, Callable[[float], bool], str]
"""(parameter name, value, test, what is expected)."""


def elastic_checks(E: object, nu: object, density: object) -> list[Check]:
    """The checks of Young's modulus, Poisson's ratio and the density (any object: a value that is
    not a number is refused by :func:`check_parameters`)."""
    nu_low, nu_high = NU_RANGE
    return [
        ("E", E, lambda v: LOW <= v <= HIGH, f"a value in [{LOW:g}, {HIGH:g}] (the supported range)"),
        ("nu", nu, lambda v: nu_low <= v <= nu_high,
         f"a value in [{nu_low:g}, {nu_high:g}] (the supported range: beyond it the bulk and shear moduli "
         "differ by more than 5000 times and the solvers lose the digits they need)"),
        ("density", density, lambda v: 0 <= v <= HIGH, f"a value in [0, {HIGH:g}]"),
    ]


def check_parameters(owner: str, checks: Sequence[Check]) -> None:
    """Raise a ValueError naming ``owner`` and the first parameter that is not a number or fails its test."""
    for name, value, ok, expected in checks:
        try:
            number = float(value)  # type: ignore[arg-type]  # any object: a failure is the refusal below
        except (TypeError, ValueError):
            raise ValueError(f"{owner}: {name} = {value!r} is not a number") from None
        if math.isnan(number) or not ok(number):
            raise ValueError(f"{owner}: {name} = {value!r} is out of range; expected {expected}")


def lame(E: float, nu: float) -> tuple[float, float]:
    """(μ, λ) = (E / (2(1+ν)), Eν / ((1+ν)(1−2ν)))."""
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
