"""Discretisation-error estimates on the quantities users read, per-cell indicators, adaptivity.

- :mod:`~dolfinx_nnqem.estimates.quantities`: the quantities (contact resultants, reactions, probe
  displacements, the largest equivalent plastic strain) of a solved problem;
- :mod:`~dolfinx_nnqem.estimates.enriched`: their error estimates from an enriched solve (degree 2,
  or the uniformly refined mesh) along the run's load path;
- :mod:`~dolfinx_nnqem.estimates.indicators`: per-cell indicators by stress recovery (ZZ);
- :mod:`~dolfinx_nnqem.estimates.refinement`: refinement of tetrahedral meshes with their tags;
- :mod:`~dolfinx_nnqem.estimates.adaptive`: adaptive refinement to a target error.

``docs/error-estimates.md`` gives the method, its cost and the measured effectivities.
"""

from dolfinx_nnqem.estimates.adaptive import AdaptiveCycle, AdaptiveResult, solve_adaptively
from dolfinx_nnqem.estimates.enriched import (ENRICHMENTS, ErrorEstimates, QuantityEstimate, choose_enrichment,
                                              enriched_problem, estimate_errors, rebuild_problem)
from dolfinx_nnqem.estimates.indicators import INDICATOR_NAME, RecoveryIndicator
from dolfinx_nnqem.estimates.quantities import ProbePoints, probe_points, read_quantities
from dolfinx_nnqem.estimates.refinement import check_refinable, mark_bulk, refine_mesh_and_tags

__all__ = ["ENRICHMENTS", "INDICATOR_NAME", "AdaptiveCycle", "AdaptiveResult", "ErrorEstimates", "ProbePoints",
           "QuantityEstimate", "RecoveryIndicator",
           "check_refinable", "choose_enrichment", "enriched_problem", "estimate_errors", "mark_bulk", "probe_points",
           "read_quantities", "rebuild_problem", "refine_mesh_and_tags", "solve_adaptively"]
