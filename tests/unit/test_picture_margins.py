"""The curve pictures' fixed margins (``vtk_charts.BORDERS``: the charts' plot areas placed in fixed
rectangles, their labels around them) hold every label: no text of ``pair_pressure.png``,
``load_curve.png`` or ``convergence.png`` is cut by the picture's edge or runs into the next panel,
also with the widest tick labels (coordinates of seven characters, pressures of six digits or with
a power of ten, forces of eight digits, residuals down to 1e-16).

Checked on the pixels: the picture's outer frame and the columns where one panel meets the next
are blank (white), while each panel has ink (the labels and curves are drawn)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dolfinx_nnqem.io import run_pictures
from dolfinx_nnqem.io.vtk_charts import TEXT


def _rows(interface: str, x: np.ndarray, z: np.ndarray, pressure: np.ndarray) -> list[dict]:
    """Pair-table rows (as read from the pair CSV) on the plane y = 0; the first pair open."""
    return [{"interface": interface, "slave_x": str(a), "slave_y": "0.0", "slave_z": str(b), "pressure": str(p),
             "state": "open" if k == 0 else "stick"} for k, (a, b, p) in enumerate(zip(x, z, pressure))]


def _assert_fits(path: Path, panels: int) -> None:
    """Nothing drawn on the picture's outer frame (2 pixels) nor, below the title, on the column
    where a panel meets the next; ink in every panel."""
    from matplotlib.image import imread

    image = imread(path)[..., :3]
    ink = np.any(image < 0.9, axis=2)
    height, width = ink.shape
    frame = {"left": ink[:, :2], "right": ink[:, -2:], "top": ink[:2, :], "bottom": ink[-2:, :]}
    cut = [side for side, pixels in frame.items() if pixels.any()]
    assert not cut, f"{path.name}: drawn up to the picture's edge: {cut}"
    panel = width // panels
    below_title = ink[2 * TEXT["title"]:]  # (the figure's title spans the panels)
    crossing = [k for k in range(1, panels) if below_title[:, k * panel - 1:k * panel + 1].any()]
    assert not crossing, f"{path.name}: drawn across the border of panels {crossing} and the next"
    assert all(ink[:, k * panel:(k + 1) * panel].mean() > 0.01 for k in range(panels)), f"{path.name}: a blank panel"


@pytest.mark.parametrize("panels", [1, 3])
def test_the_pair_pressure_labels_fit(tmp_path, panels):
    grid = np.linspace(0.0, 1.0, 5)
    x, z = (a.ravel() for a in np.meshgrid(grid, grid))
    rows = _rows("narrow", -3.75e-4 + 5e-4 * x, -3.75e-4 + 5e-4 * z, 987654.0 * x)  # "-0.0003", "800000"
    rows += _rows("wide", 1234.5 + 4444.0 * x, -9876.5 + 3000.0 * z, 4.5e9 * z)  # km-sized, 1e9 pressures
    rows += _rows("tiny", 0.1 * x, 0.1 * z, 1e-3 + 2e-4 * x)  # mPa: "0.00110"
    rows = [row for row in rows if row["interface"] in ("narrow", "wide", "tiny")[:panels]]
    path = run_pictures.draw_pair_pressure(rows, tmp_path / "pair_pressure.png", title="a title as long as a run's "
                                           "title (monolithic: load factor 1, increment 15 of 15)")
    _assert_fits(path, panels)


def test_the_curve_labels_fit(tmp_path):
    factors = np.linspace(0.1, 1.0, 10)
    summary = {"load_factors": factors.tolist(),
               "reaction_history": [{"1": [0.0, -1.2345e7 * f, 0.0], "2": [3.3e-3 * f, 0.0, 0.0]} for f in factors],
               "probes": [{"name": "free end"}], "probe_history": [[[0.0, -2.5e-4 * f, 0.0]] for f in factors],
               "residual_histories": [[[1.0, 0.5], [1e-4, 1e-3], [1e-12, 1e-16]] for _ in factors]}
    _assert_fits(run_pictures.draw_load_curve(summary, tmp_path / "load_curve.png", title="load"), 2)
    _assert_fits(run_pictures.draw_convergence(summary, tmp_path / "convergence.png", title="convergence"), 2)
