"""The run's curves drawn by VTK's charts (``io/vtk_charts.py``, issue 43): quiet where a series has
one point, and the same picture for residuals that differ by round-off."""

from __future__ import annotations

import numpy as np
import pytest

from dolfinx_nnqem.io import run_pictures, vtk_charts


def test_a_curve_of_one_point_is_drawn_without_vtk_errors(tmp_path, capfd):
    """An increment that converged at its first iteration (and a run of one increment) is a series
    of one point: VTK logged "Attempted to paint a line with <2 points" for it on the run's
    standard error (``-q`` must print nothing)."""
    summary = {"load_factors": [1.0], "reaction_history": [{"1": [0.0, -2.0, 0.0]}],
               "residual_histories": [[[1e-3, 0.0]], [[1.0, 0.5], [1e-9, 1e-12]]]}
    run_pictures.draw_convergence(summary, tmp_path / "convergence.png")
    run_pictures.draw_load_curve(summary, tmp_path / "load_curve.png")
    err = capfd.readouterr().err
    print(f"\n  standard error: {err!r}")
    assert "ERR" not in err and (tmp_path / "convergence.png").stat().st_size > 0


def test_a_log_axis_ends_on_whole_decades():
    """Residuals that differ by round-off between two runs (1.0e-16 or 1.3e-16 at the bottom)
    give the same axis, so the same picture."""
    first = vtk_charts._range(np.array([1.0, 1e-4, 1.0e-16]), log=True)
    second = vtk_charts._range(np.array([1.0, 1e-4, 1.3e-16]), log=True)
    assert first == second == (1e-16, 1.0)


def test_offscreen_plotter_is_still_public():
    """``dolfinx_nnqem.io.offscreen.offscreen_plotter`` (in docs/api.md) still gives a pyvista off-screen plotter."""
    from dolfinx_nnqem import pyvista_compat
    from dolfinx_nnqem.io.offscreen import PictureUnavailable, offscreen_plotter

    if pyvista_compat.vtk_render_problem() is not None:
        with pytest.raises(PictureUnavailable):
            offscreen_plotter((40, 30))
        return
    plotter = offscreen_plotter((40, 30))
    assert plotter.off_screen and tuple(plotter.window_size) == (40, 30)
    plotter.close()
