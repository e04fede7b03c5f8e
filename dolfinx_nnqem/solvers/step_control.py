"""Automatic incrementation: the next increment's size from how hard Newton worked on the last one.

Fixed increments (``solve_load_steps(..., increments=N)``) cut an increment in half when it
fails and return to the nominal size after successes. :class:`AutomaticIncrements` also grows
the increment when Newton converges easily and shrinks it when it struggles, as CalculiX and
Abaqus do:

* an increment that converged in at most ``easy_iterations`` Newton iterations makes the next
  one ``grow`` times larger, one that needed ``hard_iterations`` or more makes it ``shrink``
  times smaller; in between the size is kept;
* a failed increment is halved and retried (``max_cutbacks`` failures in a row end the run);
* the size stays in [``min_step``, ``max_step``] (fractions of the load path's length), and an
  increment never steps over a load factor listed in ``load_factors``: those are hit exactly,
  so that results exist where the user asked for them.

The rule looks only at the last increment, so a restart needs nothing but the current size
(:class:`~dolfinx_nnqem.solvers.stepping.StepperState.step`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from dolfinx_nnqem.problem.validation import check_integer, check_real

__all__ = ["AutomaticIncrements", "as_step_control"]


@dataclass(frozen=True)
class AutomaticIncrements:
    """Settings of automatic incrementation (see the module docstring).

    Parameters
    ----------
    initial_step
        First increment, as a fraction of the load path (final − start load factor).
    max_step, min_step
        Bounds of an increment, fractions of the load path. A cutback below ``min_step`` ends
        the run as not converged.
    easy_iterations, hard_iterations
        Newton iterations at or below which the next increment grows, at or above which it
        shrinks.
    grow, shrink
        Factors applied to the increment in those two cases (grow > 1 > shrink > 0).
    load_factors
        Load factors every run must stop at (output points), in the direction of the path.
    """

    initial_step: float = 0.1
    max_step: float = 1.0
    min_step: float = 1e-4
    easy_iterations: int = 4
    hard_iterations: int = 8
    grow: float = 1.5
    shrink: float = 0.5
    load_factors: Sequence[float] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        for name in ("initial_step", "max_step", "min_step"):
            check_real(f"automatic increments: {name}", getattr(self, name), low=0.0, high=1.0)
        if not self.min_step <= self.initial_step <= self.max_step:
            raise ValueError(f"automatic increments: need min_step <= initial_step <= max_step, got "
                             f"{self.min_step:g}, {self.initial_step:g}, {self.max_step:g}")
        check_integer("automatic increments: easy_iterations", self.easy_iterations, low=1, high=1000)
        check_integer("automatic increments: hard_iterations", self.hard_iterations,
                      low=int(self.easy_iterations) + 1, high=1000)
        check_real("automatic increments: grow", self.grow, low=1.0, high=10.0)
        if check_real("automatic increments: shrink", self.shrink, low=0.0, high=1.0) == 1.0:
            raise ValueError("automatic increments: shrink = 1 would never shrink; expected a value in (0, 1)")
        object.__setattr__(self, "load_factors",
                           tuple(check_real("load_factors", x) for x in np.ravel(self.load_factors)))

    def first_step(self, span: float) -> float:
        """The first increment's size (load-factor units) on a path of length ``span``."""
        return self.initial_step * span

    def next_step(self, step: float, iterations: int, span: float) -> float:
        """The size after an increment of size ``step`` converged in ``iterations`` Newton iterations."""
        if iterations <= self.easy_iterations:
            step *= self.grow
        elif iterations >= self.hard_iterations:
            step *= self.shrink
        return float(np.clip(step, self.min_step * span, self.max_step * span))

    def too_small(self, step: float, span: float) -> bool:
        """A cutback went below ``min_step``."""
        return step < self.min_step * span * (1.0 - 1e-12)

    def target(self, ell: float, step: float, final: float, direction: float, span: float) -> float:
        """The next increment's end: ℓ + step, not past ``final`` nor past a requested load factor.

        A stop less than a quarter of a step beyond ℓ + step is taken at once (within the
        ``max_step`` bound) rather than leaving a sliver of an increment for later.
        """
        stops = [x for x in self.load_factors if direction * (x - ell) > 1e-12 * abs(step)] + [final]
        nearest = min(stops, key=lambda x: direction * (x - ell))
        distance = direction * (nearest - ell)
        if distance <= max(step, min(1.25 * step, self.max_step * span)):
            return nearest
        return ell + direction * step


def as_step_control(increments: int | str | AutomaticIncrements) -> tuple[int | None, AutomaticIncrements | None]:
    """``increments`` of :func:`~dolfinx_nnqem.solvers.stepping.solve_load_steps` as (N, None) or (None, settings).

    ``"auto"`` means :class:`AutomaticIncrements` with its defaults.
    """
    if isinstance(increments, AutomaticIncrements):
        return None, increments
    if isinstance(increments, str):
        if increments.strip().lower() != "auto":
            raise ValueError(f"increments = {increments!r}; expected a positive integer or 'auto'")
        return None, AutomaticIncrements()
    return increments, None
