"""pyvista and VTK differences between the software stacks, importable without DOLFINx.

The part of :mod:`dolfinx_nnqem.compat` that the pictures need (``compat`` re-exports it): it
imports neither DOLFINx nor PETSc nor MPI, so that a process that only draws pictures
(:mod:`dolfinx_nnqem.io.picture_worker`) can use it. Told apart by capability, as in ``compat``.
"""

from __future__ import annotations

import os
import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pyvista is imported where it is used (its import costs)
    import pyvista

__all__ = ["extract_outer_surface", "import_pyvista", "legend_takes_images", "set_plot_colour", "vtk_render_problem"]


def extract_outer_surface(dataset: pyvista.DataSet) -> pyvista.PolyData:
    """The outer surface of a pyvista dataset as PolyData, by VTK's dataset surface filter.

    pyvista 0.49 asks which algorithm to use (``algorithm="dataset_surface"``, the filter older
    versions always used, and it warns when the keyword is left out); pyvista 0.44 (Debian 13)
    has no such keyword.
    """
    import inspect

    if "algorithm" in inspect.signature(type(dataset).extract_surface).parameters:
        return dataset.extract_surface(algorithm="dataset_surface")
    return dataset.extract_surface()


def legend_takes_images(vtk_version: str) -> bool:
    """Whether ``vtkLegendBoxActor`` draws an entry given an image alone without printing.

    VTK 9.3 (Debian 13) prints "Symbol is not defined: " to standard output for every such entry,
    and an empty polygon set given beside the image makes its transform filter log an error; VTK
    9.7 (the PyPI wheel) does neither. Where it prints, the legend's symbols are polygons.
    """
    major, minor = (int(part) for part in vtk_version.split(".")[:2])
    return (major, minor) >= (9, 4)


def set_plot_colour(plot: Any, red: float, green: float, blue: float) -> None:
    """The colour of a VTK chart's plot (``vtkPlot``), RGB in 0–1.

    Recent VTK (9.7 here) names the call with floats ``SetColorF`` (its ``SetColor`` takes bytes);
    older ones (Debian 13's 9.3, as far as known) took the floats in ``SetColor``. Told apart by
    capability.
    """
    if hasattr(plot, "SetColorF"):
        plot.SetColorF(red, green, blue)
    else:
        plot.SetColor(red, green, blue)


def import_pyvista() -> Any:  # the pyvista module (pyvista is typed as Any here: pyproject.toml)
    """``import pyvista``, without the mypy plugin pyvista loads where mypy is installed.

    Recent pyvista (0.49 here) imports ``mypy.nodes`` for its typing plugin whenever it finds
    mypy (a development environment, such as this package's ``[test]`` extra): time of the run's
    pictures (``docs/performance.md``) for a plugin only mypy itself uses. pyvista asks
    ``importlib.util.find_spec("mypy")``, which answers None for a module set to None in
    ``sys.modules``; that is done for the import only, and only where mypy is not loaded
    already. A pyvista without the plugin (Debian 13's 0.44, as far as known) imports as ever.
    """
    if "pyvista" in sys.modules or "mypy" in sys.modules:
        import pyvista

        return pyvista
    sys.modules["mypy"] = None  # type: ignore[assignment]  # None: find_spec answers None, importing it raises ImportError
    try:
        import pyvista
    finally:
        if sys.modules.get("mypy", 0) is None:
            del sys.modules["mypy"]
    return pyvista


_RENDER_PROBLEM: list[str | None] = []  # the answer of vtk_render_problem, once known


def vtk_render_problem() -> str | None:
    """Why VTK cannot draw a picture in this process, or None if it can.

    Without a display, VTK ≥ 9.4 (the PyPI wheels) falls back to EGL or OSMesa and renders
    off-screen; Debian 13's VTK 9.3 renders through X only, and aborts the whole process
    (SIGABRT) when no X server answers. Told apart by capability: the render window class VTK
    picks here. Call ``chatter.apply_vtk_options()`` first (VTK logs the failed X connection
    while it picks).
    """
    if not sys.platform.startswith("linux") or os.environ.get("DISPLAY"):
        return None
    if not _RENDER_PROBLEM:  # a process draws two pictures: the render window is made once to ask
        import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (registers the OpenGL render windows)
        from vtkmodules.vtkRenderingCore import vtkRenderWindow

        window = vtkRenderWindow()
        name = window.GetClassName()
        _RENDER_PROBLEM.append(
            "this VTK renders through X only and no display is set (DISPLAY is empty): run under "
            "`xvfb-run -a`, or install a VTK that renders off-screen (pip's vtk >= 9.4)"
            if name == "vtkXOpenGLRenderWindow" else None)
    return _RENDER_PROBLEM[0]
