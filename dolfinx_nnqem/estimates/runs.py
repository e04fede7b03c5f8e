"""The estimates inside a run that writes its results (the command line, ``run_two_beams``).

:class:`EstimateSettings` holds the ``[estimate]`` options; :func:`check_settings` refuses,
before anything is solved, what cannot be done (a degree-2 hexahedral run has no enrichment,
adaptivity needs tetrahedra); :func:`estimate_into_writer` makes the estimate after the run's
last increment and puts it into the run's ``summary.json`` (and so into ``error_estimates.png``,
drawn when the writer closes).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from dolfinx_nnqem.estimates.adaptive import check_target_error
from dolfinx_nnqem.estimates.enriched import ErrorEstimates, choose_enrichment, estimate_errors
from dolfinx_nnqem.estimates.quantities import probe_points
from dolfinx_nnqem.estimates.refinement import check_refinable
from dolfinx_nnqem.estimates.report import record_estimates
from dolfinx_nnqem.solvers.convergence import ConvergenceError

__all__ = ["EstimateSettings", "check_settings", "estimate_into_writer"]

_log = logging.getLogger("dolfinx_nnqem")


@dataclass(frozen=True)
class EstimateSettings:
    """The options of the estimates (problem file ``[estimate]``, ``run --estimate``/``--target-error``)."""

    enabled: bool = False  #: make the estimate (an enriched solve after the run: off by default, it costs)
    enrichment: str = "auto"  #: see :data:`~dolfinx_nnqem.estimates.enriched.ENRICHMENTS`
    target_error: float | None = None  #: adaptive refinement to this relative error (tetrahedra)
    max_cycles: int = 6  #: adaptive meshes at most
    refine_fraction: float = 0.5  #: Dörfler's θ
    quantities: tuple[str, ...] | None = None  #: the quantities the target applies to (default all)

    @classmethod
    def from_table(cls, table: Mapping, *, estimate: bool = False, target_error: float | None = None) -> EstimateSettings:
        """From a checked ``[estimate]`` table, with the command line's overrides."""
        target = target_error if target_error is not None else table.get("target_error")
        quantities = table.get("quantities")
        return cls(enabled=bool(estimate or table.get("enabled", False) or target is not None),
                   enrichment=table.get("enrichment", "auto"), target_error=target,
                   max_cycles=int(table.get("max_cycles", 6)), refine_fraction=float(table.get("refine_fraction", 0.5)),
                   quantities=None if quantities is None else tuple(quantities))


def check_settings(problem, settings: EstimateSettings) -> None:
    """Raise ValueError, before solving, for what the settings ask and the problem cannot give."""
    if not settings.enabled:
        return
    if settings.target_error is not None:
        check_target_error(settings.target_error)
        check_refinable(problem.mesh)
    choose_enrichment(problem, settings.enrichment)


def estimate_into_writer(writer, problem, method: str, settings: EstimateSettings, *,
                         probes: Mapping[str, Sequence] | None = None, options=None,
                         method_options: dict | None = None, check=None) -> ErrorEstimates | None:
    """The estimate of a finished run, recorded in its ``summary.json`` (collective).

    ``writer``: the run's :class:`~dolfinx_nnqem.io.output.ResultsWriter`, before it is closed
    (its summary gives the load factors and the run's wall time). None when the enriched solve
    did not converge (``summary.json`` says so in ``error_estimates.error``).
    """
    data = writer.summary.data
    try:
        estimates = estimate_errors(problem, method, data["load_factors"], probes=probe_points(probes),
                                    enrichment=settings.enrichment, options=options, method_options=method_options,
                                    run_time_s=float(data.get("wall_time_s") or 0.0) or None, check=check)
    except ConvergenceError as error:  # the run's results stand; the estimate says why it is missing
        _log.warning(f"no error estimate: the enriched solve did not converge ({error})")
        data["error_estimates"] = {"error": f"the enriched solve did not converge: {error}"}
        writer.summary.write()
        return None
    record_estimates(data, estimates)
    writer.summary.write()
    return estimates
