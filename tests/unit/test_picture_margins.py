"""The curve pictures' fixed margins (``run_pictures._curve_margins``, not ``tight_layout``: issue 43)
hold every label: no text of ``pair_pressure.png``, ``load_curve.png`` or ``convergence.png`` is
cut by the picture's edge or drawn over another, also with the widest tick labels matplotlib writes
(coordinates of seven characters, pressures of six digits or with a power of ten)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dolfinx_nnqem.io import run_pictures


def _rows(interface: str, x: np.ndarray, z: np.ndarray, pressure: np.ndarray) -> list[dict]:
    """Pair-table rows (as read from the pair CSV) on the plane y = 0; the first pair open."""
    return [{"interface": interface, "slave_x": str(a), "slave_y": "0.0", "slave_z": str(b), "pressure": str(p),
             "state": "open" if k == 0 else "stick"} for k, (a, b, p) in enumerate(zip(x, z, pressure))]


def _texts_checked(monkeypatch) -> list[dict]:
    """Each figure saved: its labelled parts (each axis with its tick labels and label, each title,
    the legend), their boxes in pixels taken when ``savefig`` is called, and the figure's."""
    import matplotlib.figure

    seen: list[dict] = []
    save = matplotlib.figure.Figure.savefig

    def checked(fig, path, **kwargs):
        renderer = fig.canvas.get_renderer()
        fig.draw(renderer)  # (the ticks drawn, and their labels, are chosen at a draw)
        parts = [("figure", "title", fig._suptitle.get_window_extent(renderer))] if fig._suptitle else []
        for k, ax in enumerate(fig.axes):
            for name, part in (("x axis", ax.xaxis), ("y axis", ax.yaxis), ("title", ax.title),
                               ("legend", ax.get_legend())):
                box = part.get_tightbbox(renderer) if part is not None and part.get_visible() else None
                if box is not None and box.width > 0 and box.height > 0 and (name != "title" or ax.get_title()):
                    parts.append((f"axes {k}", name, box))
        seen.append({"path": Path(path), "canvas": fig.bbox, "parts": parts})
        return save(fig, path, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", checked)
    return seen


def _assert_fits(figure: dict) -> None:
    """Every part inside the picture, and no two parts of different panels (a colour bar is a
    panel of its own) or of the figure drawn over one another."""
    canvas, parts = figure["canvas"], figure["parts"]
    outside = [(owner, name) for owner, name, box in parts if box.x0 < canvas.x0 - 0.5 or box.x1 > canvas.x1 + 0.5
               or box.y0 < canvas.y0 - 0.5 or box.y1 > canvas.y1 + 0.5]
    assert not outside, f"{figure['path'].name}: cut by the picture's edge: {outside}"
    overlapping = []
    for i, (owner, name, box) in enumerate(parts):
        for other_owner, other_name, other in parts[i + 1:]:
            if owner != other_owner and box.overlaps(other):
                common = box.intersection(box, other)
                if common is not None and common.width > 1 and common.height > 1:
                    overlapping.append((f"{owner} {name}", f"{other_owner} {other_name}"))
    assert not overlapping, f"{figure['path'].name}: drawn over one another: {overlapping}"


@pytest.mark.parametrize("panels", [1, 3])
def test_the_pair_pressure_labels_fit(tmp_path, monkeypatch, panels):
    seen = _texts_checked(monkeypatch)
    grid = np.linspace(0.0, 1.0, 5)
    x, z = (a.ravel() for a in np.meshgrid(grid, grid))
    rows = _rows("narrow", -3.75e-4 + 5e-4 * x, -3.75e-4 + 5e-4 * z, 987654.0 * x)  # "−0.0003", "800000"
    rows += _rows("wide", 1234.5 + 4444.0 * x, -9876.5 + 3000.0 * z, 4.5e9 * z)  # km-sized, 1e9 offset
    rows += _rows("tiny", 0.1 * x, 0.1 * z, 1e-3 + 2e-4 * x)  # mPa: "0.00110"
    rows = [row for row in rows if row["interface"] in ("narrow", "wide", "tiny")[:panels]]
    run_pictures.draw_pair_pressure(rows, tmp_path / "pair_pressure.png", title="a title as long as a run's title "
                                    "(monolithic: load factor 1, increment 15 of 15)")
    assert len(seen) == 1
    print(f"\n  {panels} panel(s): {[(owner, name) for owner, name, _ in seen[0]['parts']]}", end="")
    _assert_fits(seen[0])


def test_the_curve_labels_fit(tmp_path, monkeypatch):
    seen = _texts_checked(monkeypatch)
    factors = np.linspace(0.1, 1.0, 10)
    summary = {"load_factors": factors.tolist(),
               "reaction_history": [{"1": [0.0, -1.2345e7 * f, 0.0], "2": [3.3e-3 * f, 0.0, 0.0]} for f in factors],
               "probes": [{"name": "free end"}], "probe_history": [[[0.0, -2.5e-4 * f, 0.0]] for f in factors],
               "residual_histories": [[[1.0, 0.5], [1e-4, 1e-3], [1e-12, 1e-16]] for _ in factors]}
    run_pictures.draw_load_curve(summary, tmp_path / "load_curve.png", title="load")
    run_pictures.draw_convergence(summary, tmp_path / "convergence.png", title="convergence")
    assert [figure["path"].name for figure in seen] == ["load_curve.png", "convergence.png"]
    for figure in seen:
        _assert_fits(figure)
