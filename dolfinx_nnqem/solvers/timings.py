"""Wall time per phase of a solver: the one timing helper of the solvers."""

from __future__ import annotations

import time
from collections.abc import Mapping

__all__ = ["Timings", "summed"]


class Timings(dict[str, float]):
    """Wall time (s) per phase of a solver (``"assembly"``, ``"solve"``, ...), summed over calls.

    A plain dict to its readers (the solver's ``timings``, the run's summary); :meth:`add` is how
    a phase is counted.
    """

    def add(self, key: str, t0: float) -> None:
        """Add the time since ``t0`` (a :func:`time.perf_counter` reading) to the phase ``key``."""
        self[key] = self.get(key, 0.0) + time.perf_counter() - t0


def summed(*parts: Mapping[str, float]) -> Timings:
    """The phases of ``parts`` (a solver's and those of the pieces it composes), times of the same
    phase added."""
    out = Timings()
    for part in parts:
        for key, value in part.items():
            out[key] = out.get(key, 0.0) + value
    return out
