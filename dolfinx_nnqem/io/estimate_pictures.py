"""The picture of a run's error estimates, ``error_estimates.png``, from ``summary.json``.

Left: every quantity's relative error estimate (%, log scale), labelled with value ± estimate;
right, after an adaptive run: the largest relative estimate of each cycle against its dofs,
with the target. A matplotlib ``Figure`` without pyplot (no DOLFINx, no MPI): a picture worker draws it too.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["ESTIMATE_PICTURE", "draw_error_estimates"]

ESTIMATE_PICTURE = "error_estimates.png"


def _label(q: dict) -> str:
    value = np.asarray(q["value"], dtype=float)
    magnitude = float(np.linalg.norm(value))
    return f"{q['name']}: |Q| = {magnitude:.4g} ± {q['estimate']:.2g}"


def _draw_quantities(ax, estimates: dict) -> None:
    items = [q for q in estimates["quantities"] if q.get("relative") is not None]
    if not items:
        raise ValueError("no quantity has a relative estimate")
    relative = np.array([max(100 * q["relative"], 1e-14) for q in items])
    y = np.arange(len(items))
    ax.barh(y, relative, color="tab:orange")
    ax.set_yticks(y, [_label(q) for q in items], fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("relative error estimate (%)")
    cost = estimates.get("cost")
    cost_text = f", {cost:.1f} × the run's time" if cost is not None else ""
    ax.set_title(f"{estimates['method']}\n{estimates['dofs']} → {estimates['enriched_dofs']} dofs{cost_text}",
                 fontsize=8)
    ax.grid(True, axis="x", alpha=0.3)


def _draw_cycles(ax, adaptivity: dict) -> None:
    cycles = [c for c in adaptivity["cycles"] if c.get("relative_error") is not None]
    dofs = [c["dofs"] for c in cycles]
    errors = [100 * c["relative_error"] for c in cycles]
    ax.loglog(dofs, errors, "o-", label="adaptive cycles")
    ax.axhline(100 * adaptivity["target_error"], color="k", ls="--", lw=1, label="target")
    ax.set_xlabel("displacement dofs")
    ax.set_ylabel("largest relative estimate (%)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


def draw_error_estimates(summary: dict, path: Path, *, title: str = "") -> Path:
    """The estimates of ``summary`` (``error_estimates``, and ``adaptivity`` when present)."""
    estimates = summary.get("error_estimates")
    if not estimates:
        raise ValueError("the run made no error estimate (run --estimate, [estimate] enabled = true)")
    from dolfinx_nnqem.io.plots import figure

    adaptivity = summary.get("adaptivity")
    panels = 2 if adaptivity else 1
    fig = figure(9 * panels, 0.35 * len(estimates["quantities"]) + 2.5)
    axes = fig.subplots(1, panels, squeeze=False)
    _draw_quantities(axes[0][0], estimates)
    if adaptivity:
        _draw_cycles(axes[0][1], adaptivity)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return path
