"""A pyvista plotter that draws off-screen, or the reason it cannot.

Every picture the package draws with pyvista starts here, so that a machine where VTK cannot
render (:func:`dolfinx_nnqem.pyvista_compat.vtk_render_problem`) skips the picture with that reason
instead of losing the process to VTK's abort.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from dolfinx_nnqem import pyvista_compat
from dolfinx_nnqem.chatter import apply_vtk_options

if TYPE_CHECKING:  # pyvista is imported where it is used (its import costs)
    import pyvista

__all__ = ["PictureUnavailable", "offscreen_plotter"]


class PictureUnavailable(RuntimeError):
    """VTK cannot render here (the message says why and what to do)."""


def offscreen_plotter(window_size: tuple[int, int]) -> pyvista.Plotter:
    """A ``pyvista.Plotter(off_screen=True)`` of ``window_size`` pixels.

    Raises
    ------
    PictureUnavailable
        VTK cannot render in this process.
    """
    pyvista = pyvista_compat.import_pyvista()

    apply_vtk_options()  # VTK's "bad X server connection" (it renders off-screen anyway): only with -v
    reason = pyvista_compat.vtk_render_problem()
    if reason is not None:
        raise PictureUnavailable(reason)
    pyvista.OFF_SCREEN = True
    return pyvista.Plotter(off_screen=True, window_size=window_size)
