"""Adaptive refinement to a target error (tetrahedral meshes).

Each cycle solves the whole load path on the current mesh, estimates the error of the quantities
(:func:`~dolfinx_nnqem.estimates.enriched.estimate_errors`) and stops when the largest relative
estimate of the chosen quantities is at most the target; otherwise it refines the cells that
carry the bulk of the recovery indicator (:class:`~dolfinx_nnqem.estimates.indicators.RecoveryIndicator`,
:func:`~dolfinx_nnqem.estimates.refinement.mark_bulk`) with their tags and starts again.

The load path is solved again from the start on every mesh, as deal.II's step-42 does, rather
than transferring the Gauss-point state: the plastic strains, hardening and friction slips of a
cell have no consistent image on its children (the Gauss points move, and an interpolated state
is neither in equilibrium nor admissible), and the contact pairs themselves change with the
contact surfaces' facets. Solving again costs at most about the sum of a geometric series of the
cycles' sizes, dominated by the last.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from dolfinx_nnqem.estimates.enriched import ErrorEstimates, num_dofs, estimate_errors, rebuild_problem
from dolfinx_nnqem.estimates.indicators import RecoveryIndicator
from dolfinx_nnqem.estimates.quantities import Measure, ProbePoints
from dolfinx_nnqem.estimates.refinement import check_refinable, mark_bulk, refine_mesh_and_tags
from dolfinx_nnqem.problem.contact_problem import ContactProblem

__all__ = ["AdaptiveCycle", "AdaptiveResult", "check_target_error", "selected_relative", "solve_adaptively"]

RunCycle = Callable[[ContactProblem, int], Sequence[float]]
"""``run(problem, cycle)``: solve the load path of ``problem`` (with the caller's writers) and
return its converged load factors."""


@dataclass(frozen=True)
class AdaptiveCycle:
    """One mesh of the adaptive sequence."""

    index: int
    dofs: int
    cells: int
    estimates: ErrorEstimates
    relative_error: float  #: the largest relative estimate of the selected quantities
    indicator: tuple[float, float]  #: (η, η relative) of the recovery indicator
    run_time_s: float

    def as_dict(self) -> dict:
        return {"cycle": self.index, "dofs": self.dofs, "cells": self.cells,
                "relative_error": float(self.relative_error) if np.isfinite(self.relative_error) else None,
                "indicator": list(self.indicator), "run_time_s": self.run_time_s,
                "estimates": self.estimates.as_dict()}


@dataclass
class AdaptiveResult:
    """The adaptive sequence: the last cycle's problem (solved) and every cycle."""

    problem: ContactProblem
    cycles: list[AdaptiveCycle] = field(default_factory=list)
    reached: bool = False  #: the target was met

    def as_dict(self, target_error: float) -> dict:
        """The ``adaptivity`` entry of ``summary.json`` (``docs/outputs.md``)."""
        return {"target_error": target_error, "reached": self.reached, "method": "recovery indicator (ZZ), "
                "Dörfler marking; load path solved again on each mesh",
                "cycles": [c.as_dict() for c in self.cycles]}


def check_target_error(target_error: float) -> float:
    """The target as a float in (0, 1), or ValueError naming the value."""
    if isinstance(target_error, bool) or not isinstance(target_error, (int, float)) or not 0.0 < target_error < 1.0:
        raise ValueError(f"target_error = {target_error!r}; expected a relative error in (0, 1), e.g. 0.01 for 1 %")
    return float(target_error)


def selected_relative(estimates: ErrorEstimates, quantities: Sequence[str] | None) -> float:
    """The largest relative estimate among ``quantities`` (names, or kinds such as ``u`` or
    ``contact`` that select every quantity of that kind; None: all)."""
    chosen = [q for q in estimates.quantities
              if quantities is None or q.name in quantities or q.name.split(":")[0] in quantities]
    if quantities is not None and not chosen:
        raise ValueError(f"target quantities {list(quantities)}: none of the run's quantities "
                         f"{[q.name for q in estimates.quantities]}")
    return max((np.inf if q.relative is None else q.relative for q in chosen), default=0.0)


def solve_adaptively(problem: ContactProblem, run: RunCycle, method: str, target_error: float, *,
                     max_cycles: int = 6, fraction: float = 0.5, quantities: Sequence[str] | None = None,
                     probes: ProbePoints | None = None, options=None, method_options: dict | None = None,
                     on_cycle: Callable[[AdaptiveCycle], None] | None = None,
                     extra: Measure | None = None, enrichment: str = "auto", check=None) -> AdaptiveResult:
    """Refine ``problem``'s tetrahedral mesh until the estimated error is at most ``target_error``.

    Parameters
    ----------
    problem
        The problem on the initial mesh (unsolved); it is destroyed once refined.
    run
        Solves a cycle's problem (see :data:`RunCycle`).
    method
        The solver of the enriched solves.
    target_error
        The largest relative error estimate accepted (0.01: 1 %).
    max_cycles
        Meshes tried at most (the last one is returned whether it met the target or not).
    fraction
        Dörfler's bulk fraction θ: the cells holding θ of Σ η_K² are refined.
    quantities
        The quantities the target applies to (names or kinds; default all).
    on_cycle
        Called with each :class:`AdaptiveCycle` (progress lines).
    extra
        Further quantities of the caller's (:data:`~dolfinx_nnqem.estimates.quantities.Measure`).
    enrichment
        The enriched solve of each cycle (:data:`~dolfinx_nnqem.estimates.enriched.ENRICHMENTS`).
    check
        The :class:`~dolfinx_nnqem.solvers.checks.CheckOptions` of the enriched solves (the runs'
        are ``run``'s own).
    """
    target_error = check_target_error(target_error)
    check_refinable(problem.mesh)
    if isinstance(max_cycles, bool) or not isinstance(max_cycles, int) or max_cycles < 1:
        raise ValueError(f"max_cycles = {max_cycles!r}; expected an integer >= 1")
    result = AdaptiveResult(problem)
    for index in range(1, max_cycles + 1):
        t0 = time.perf_counter()
        load_factors = run(problem, index)
        elapsed = time.perf_counter() - t0
        estimates = estimate_errors(problem, method, load_factors, probes=probes, options=options,
                                    method_options=method_options, run_time_s=elapsed, extra=extra,
                                    enrichment=enrichment, check=check)
        indicator = RecoveryIndicator(problem)
        indicator.update()
        cells = problem.mesh.topology.index_map(3).size_global
        cycle = AdaptiveCycle(index, num_dofs(problem), cells, estimates, selected_relative(estimates, quantities),
                              indicator.global_estimate(), elapsed)
        result.cycles.append(cycle)
        if on_cycle is not None:
            on_cycle(cycle)
        result.problem = problem
        if cycle.relative_error <= target_error:
            result.reached = True
            break
        if index == max_cycles:
            break
        marked = mark_bulk(indicator.owned(), fraction, problem.comm)
        mesh, cell_tags, facet_tags = refine_mesh_and_tags(problem.mesh, problem.cell_tags, problem.facet_tags, marked)
        refined = rebuild_problem(problem, mesh, cell_tags, facet_tags, problem.definition.degree)
        problem.destroy()
        problem = refined
    return result
