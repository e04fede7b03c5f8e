"""Whether VTK can draw off-screen here, or the reason it cannot.

Every 3D picture the package draws starts here (:class:`dolfinx_nnqem.io.vtk_scene.Scene`), so
that a machine where VTK cannot render (:func:`dolfinx_nnqem.pyvista_compat.vtk_render_problem`)
skips the picture with that reason instead of losing the process to VTK's abort.
"""

from __future__ import annotations

from typing import Any

from dolfinx_nnqem import pyvista_compat
from dolfinx_nnqem.chatter import apply_vtk_options

__all__ = ["PictureUnavailable", "check_rendering", "offscreen_plotter"]


class PictureUnavailable(RuntimeError):
    """VTK cannot render here (the message says why and what to do)."""


def check_rendering() -> None:
    """Return where VTK can render off-screen in this process.

    Raises
    ------
    PictureUnavailable
        VTK cannot render in this process.
    """
    apply_vtk_options()  # VTK's "bad X server connection" (it renders off-screen anyway): only with -v
    reason = pyvista_compat.vtk_render_problem()
    if reason is not None:
        raise PictureUnavailable(reason)


def offscreen_plotter(window_size: tuple[int, int]) -> Any:  # a pyvista.Plotter
    """A ``pyvista.Plotter(off_screen=True)`` of ``window_size`` pixels, for a user's own pictures
    (the package's pictures no longer use pyvista; this public function stays as it was).

    Raises
    ------
    PictureUnavailable
        VTK cannot render in this process.
    """
    pyvista = pyvista_compat.import_pyvista()
    check_rendering()
    pyvista.OFF_SCREEN = True
    return pyvista.Plotter(off_screen=True, window_size=window_size)
