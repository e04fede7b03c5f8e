"""Draw ``docs/figures/large_sliding_forces.png`` (issue 27): forces of the large-sliding cases.

Left: the issue's sphere (R = 0.6, pressed 0.01 into a unit cube of 8³ hexahedra at x = 0.3, then
moved to x = 0.7, frictionless), its vertical force against its position, with the current
geometry, with the reference geometry (until the run stops) and pressed in place at five
positions. Right: the upper block slid 0.4 (1.6 master facets) over the lower one, node-to-surface,
current geometry: normal and tangential force against the slide, frictionless and μ_f = 0.3.

    python scripts/large_sliding_figure.py
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from dolfinx_nnqem.cases.large_sliding import (PRESSED_AT, obstacle_force, slave_force, sliding_blocks,  # noqa: E402
                                               sliding_sphere)
from dolfinx_nnqem.solvers import ConvergenceError, SolverOptions, make_solver, solve_load_steps  # noqa: E402

FIGURE = Path(__file__).resolve().parents[1] / "docs" / "figures" / "large_sliding_forces.png"
OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)


def history(problem, increments: int, force) -> np.ndarray:
    """(ℓ, F_x, F_y) of every converged increment (until the run stops)."""
    rows: list[list[float]] = []
    try:
        with make_solver("monolithic", problem, OPTIONS) as solver:
            solve_load_steps(problem, solver, increments,
                             callbacks=[lambda r: rows.append([r.load_factor, *force(problem)[:2]])])
    except ConvergenceError:
        pass
    return np.array(rows)


def sphere_position(load_factor: np.ndarray) -> np.ndarray:
    return 0.3 + 0.4 * np.clip((load_factor - PRESSED_AT) / (1.0 - PRESSED_AT), 0.0, 1.0)


def main() -> None:
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    for geometry, style in (("current", "-o"), ("reference", "--s")):
        h = history(sliding_sphere(8, geometry=geometry), 20, obstacle_force)
        slid = h[:, 0] >= PRESSED_AT
        left.plot(sphere_position(h[slid, 0]), -h[slid, 2], style, ms=3, label=f"slid, {geometry} geometry")
    places = np.linspace(0.3, 0.7, 5)
    in_place = [-history(sliding_sphere(8, start=x, end=x), 4, obstacle_force)[-1, 2] for x in places]
    left.plot(places, in_place, "k*", ms=10, label="pressed in place (current geometry)")
    left.set(xlabel="sphere position x", ylabel="vertical force on the block", title="sphere R = 0.6 on 8³, frictionless")
    left.legend(fontsize=8)
    for mu_f, style in ((0.0, "-o"), (0.3, "-s")):
        h = history(sliding_blocks(slide=0.4, mu_f=mu_f), 12, slave_force)
        s = 0.4 * np.clip((h[:, 0] - PRESSED_AT) / (1.0 - PRESSED_AT), 0.0, 1.0)
        right.plot(s, h[:, 2], style, ms=3, label=f"normal, μ_f = {mu_f:g}")
        right.plot(s, -h[:, 1], style.replace("-", ":"), ms=3, label=f"−tangential, μ_f = {mu_f:g}")
    right.axvline(0.25, color="0.7", lw=0.8)
    right.set(xlabel="slide (master facet size 0.25)", ylabel="force on the upper block",
              title="block slid 1.6 facets, node-to-surface")
    right.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(FIGURE, dpi=110)
    print(f"wrote {FIGURE}")


if __name__ == "__main__":
    main()
