"""The estimates as users read them: text lines (the command line), ``summary.json`` entries.

Every quantity is printed as value ± estimate with the method, e.g.::

    error estimates (enriched solve: degree 2 on the same mesh; 594 -> 3150 dofs, 6.6 × the run's time)
      u:tip               [-9.9e-05, -1.176e-03, 4.09e-04] ± 2.3e-04  (15.7 %)
"""

from __future__ import annotations

import numpy as np

from dolfinx_nnqem.estimates.enriched import ErrorEstimates

__all__ = ["format_estimates", "record_estimates"]

UNITS = {"contact": "N", "reaction": "N", "u": "m", "max_p": ""}


def _vector(values: np.ndarray) -> str:
    if values.size == 1:
        return f"{values[0]:.6g}"
    return "[" + ", ".join(f"{v:.6g}" for v in values) + "]"


def format_estimates(estimates: ErrorEstimates) -> str:
    """One header line (method, sizes, cost) and one line per quantity: value ± estimate (relative)."""
    cost = estimates.cost()
    cost_text = f", {cost:.1f} × the run's time" if cost is not None else ""
    lines = [f"error estimates ({estimates.method}; {estimates.dofs} -> {estimates.enriched_dofs} dofs, "
             f"{estimates.enriched_time_s:.1f} s{cost_text})"]
    if estimates.note:
        lines.append(f"  note: {estimates.note}")
    width = max((len(q.name) for q in estimates.quantities), default=0)
    for q in estimates.quantities:
        unit = UNITS.get(q.name.split(":")[0], "")
        relative = "n/a" if q.relative is None else f"{100 * q.relative:.3g} %"
        lines.append(f"  {q.name:<{width}}  {_vector(q.value)} ± {q.estimate:.3g} {unit}  ({relative})".rstrip())
    return "\n".join(lines)


def record_estimates(summary_data: dict, estimates: ErrorEstimates) -> None:
    """Put the estimates into a summary's data (``error_estimates``, ``docs/outputs.md``)."""
    summary_data["error_estimates"] = estimates.as_dict()
