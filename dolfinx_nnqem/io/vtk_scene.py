"""An off-screen 3D scene drawn with VTK's own classes: the scene of the run's 3D pictures.

``deformed.png`` and ``error_indicator.png`` (:mod:`dolfinx_nnqem.io.deformed_picture`),
``contact_pressure.png`` (:func:`dolfinx_nnqem.io.plots.draw_contact_pressure`) and the rigid
obstacles in them (:mod:`dolfinx_nnqem.io.obstacle_shapes`) are made of a :class:`Scene`: meshes
coloured by a field or by one colour, a colour bar, a legend, a title, the axes, a camera, a PNG
file. It is styled as pyvista's default theme drew the same pictures before: a white background,
VTK's light kit, edges smoothed by FXAA, black Arial text, the colour bar at the bottom and the legend
in the lower left corner.

Why not pyvista: a picture worker imported pyvista and ``pyvista.plotting`` (which imports
``matplotlib.pyplot``) for these pictures, half of its CPU (issue 43, ``docs/performance.md``);
the VTK modules a scene needs import in a fraction of that. They are imported when the first
scene is made (:func:`_vtk`), not with this module.
"""

from __future__ import annotations

import os
import types
from collections.abc import Sequence
from typing import Any

import numpy as np

from dolfinx_nnqem.io.colour_maps import colour_table
from dolfinx_nnqem.pyvista_compat import legend_takes_images

__all__ = ["COLOURS", "Scene", "legend_disc", "line_data", "offscreen_window", "point_data", "release_window", "rgb", "surface_data",
           "unstructured_grid", "vtk_modules"]

COLOURS = {"white": "#ffffff", "black": "#000000", "royalblue": "#4169e1", "crimson": "#dc143c",
           "darkorange": "#ff8c00", "steelblue": "#4682b4", "lightgrey": "#d3d3d3", "grey": "#808080",
           "darkgray": "#a9a9a9", "tomato": "#ff6347", "seagreen": "#2e8b57", "mediumblue": "#0000cd"}
"""The named colours the pictures use (CSS names, as matplotlib and pyvista spell them)."""

WINDOW_SAMPLES = 0
"""Multisampling of a scene's render window: none. Its edges are smoothed by FXAA instead
(:data:`SMOOTHED_EDGES`): with Mesa's software OpenGL, the run's three 3D pictures took half as
much CPU again with 8 samples a pixel (``docs/performance.md``, "The pictures' CPU")."""

SMOOTHED_EDGES = True
"""A scene's renderer smooths its edges with VTK's fast approximate antialiasing (FXAA: one pass
over the rendered picture, before the text, the colour bar and the legend are drawn, which it
leaves untouched). Without multisampling or FXAA the plastic-zone outline and the mesh edges come
out jagged; FXAA draws them as 8 samples a pixel did to the eye."""

LEGEND_DISC_PIXELS = 16
"""Side of a legend disc's image (:func:`legend_disc`). About the size the legend draws it at (12
to 17 pixels in the run's pictures): scaled by linear interpolation, a much larger image's soft
edge, one of its pixels wide, would fall between the samples and the disc's edge come out jagged."""

PNG_COMPRESSION = 3
"""zlib's compression level of the PNG files (libpng's default is 6): the six pictures of a run
written in 0.7 of the CPU, the files a fifth larger (``docs/performance.md``)."""

FONT_SIZE = 18
"""Font size of the colour bar's title and labels (pyvista's default theme)."""


def rgb(colour: str | Sequence[float]) -> tuple[float, float, float]:
    """``colour`` (a name of :data:`COLOURS`, ``#rrggbb``, or RGB in 0–1) as RGB in 0–1."""
    if not isinstance(colour, str):
        red, green, blue = (float(c) for c in colour)
        return red, green, blue
    code = COLOURS.get(colour, colour)
    if not (code.startswith("#") and len(code) == 7):
        raise ValueError(f"colour {colour!r}: expected one of {sorted(COLOURS)} or #rrggbb")
    return int(code[1:3], 16) / 255, int(code[3:5], 16) / 255, int(code[5:7], 16) / 255


_MODULES: dict[str, Any] = {}


def vtk_modules() -> types.SimpleNamespace:
    """The VTK classes a scene uses, imported once: rendering (OpenGL2, fonts for the text),
    annotation (colour bar, legend, title, axes), the filters and sources of the pictures, and the
    PNG writer. Only these VTK modules: ``import vtk`` would import all of VTK."""
    if not _MODULES:
        import vtkmodules.vtkRenderingFreeType  # noqa: F401  (text: without it no text is drawn)
        import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (the OpenGL render windows)
        from vtkmodules import (vtkCommonCore, vtkCommonDataModel, vtkFiltersCore, vtkFiltersGeometry,
                                vtkFiltersSources, vtkIOImage, vtkRenderingAnnotation, vtkRenderingCore)
        from vtkmodules.util import numpy_support

        for module in (vtkCommonCore, vtkCommonDataModel, vtkFiltersCore, vtkFiltersGeometry, vtkFiltersSources,
                       vtkIOImage, vtkRenderingAnnotation, vtkRenderingCore):
            _MODULES.update({name: getattr(module, name) for name in dir(module) if name.startswith(("vtk", "VTK_"))})
        _MODULES["numpy_to_vtk"] = numpy_support.numpy_to_vtk
        _MODULES["vtk_to_numpy"] = numpy_support.vtk_to_numpy
    return types.SimpleNamespace(**_MODULES)


_vtk = vtk_modules


# -- data ----------------------------------------------------------------------------------------
def _points(points: np.ndarray) -> Any:
    vtk = _vtk()
    result = vtk.vtkPoints()
    result.SetData(vtk.numpy_to_vtk(np.ascontiguousarray(np.asarray(points, dtype=float).reshape(-1, 3)), deep=True))
    return result


def _cells(rows: np.ndarray) -> Any:
    """A vtkCellArray of cells of equal size, one row of point indices each."""
    vtk = _vtk()
    rows = np.asarray(rows, dtype=np.int64).reshape(len(rows), -1)
    offsets = np.arange(0, rows.size + 1, rows.shape[1], dtype=np.int64)
    cells = vtk.vtkCellArray()
    cells.SetData(vtk.numpy_to_vtk(offsets, deep=True, array_type=vtk.VTK_ID_TYPE),
                  vtk.numpy_to_vtk(np.ascontiguousarray(rows.reshape(-1)), deep=True, array_type=vtk.VTK_ID_TYPE))
    return cells


def unstructured_grid(points: np.ndarray, cells: np.ndarray, cell_types: int | np.ndarray) -> Any:
    """A vtkUnstructuredGrid of ``points`` and ``cells``: rows of point indices (one VTK cell type,
    ``cell_types`` an int) or the flat ``[n, i0, ..., i(n-1), ...]`` layout of
    ``dolfinx.plot.vtk_mesh`` (``cell_types`` one VTK type per cell)."""
    vtk = _vtk()
    grid = vtk.vtkUnstructuredGrid()
    grid.SetPoints(_points(points))
    cells = np.asarray(cells, dtype=np.int64)
    if cells.ndim == 2:
        cell_array = _cells(cells)
        types_ = np.full(len(cells), int(np.asarray(cell_types).reshape(-1)[0]), dtype=np.uint8)
    else:  # the flat layout takes every VTK cell type (Lagrange cells too)
        cell_array = vtk.vtkCellArray()
        cell_array.ImportLegacyFormat(vtk.numpy_to_vtk(cells, deep=True, array_type=vtk.VTK_ID_TYPE))
        types_ = np.asarray(cell_types, dtype=np.uint8).reshape(-1)
    grid.SetCells(vtk.numpy_to_vtk(types_, deep=True, array_type=vtk.VTK_UNSIGNED_CHAR), cell_array)
    return grid


def surface_data(points: np.ndarray, triangles: np.ndarray) -> Any:
    """A vtkPolyData of triangles (rows of ``points``)."""
    data = _vtk().vtkPolyData()
    data.SetPoints(_points(points))
    data.SetPolys(_cells(triangles))
    return data


def point_data(points: np.ndarray) -> Any:
    """A vtkPolyData of ``points``, each a vertex (drawn as a sphere or a dot)."""
    data = _vtk().vtkPolyData()
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    data.SetPoints(_points(points))
    data.SetVerts(_cells(np.arange(len(points)).reshape(-1, 1)))
    return data


def line_data(points: np.ndarray) -> Any:
    """A vtkPolyData of one polyline through ``points`` in their order."""
    data = _vtk().vtkPolyData()
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    data.SetPoints(_points(points))
    data.SetLines(_cells(np.arange(len(points)).reshape(1, -1)))
    return data


def set_values(data: Any, name: str, values: np.ndarray, *, on: str = "cell") -> None:
    """Attach ``values`` (one a cell, or one a point with ``on="point"``) to ``data`` as ``name``."""
    array = _vtk().numpy_to_vtk(np.ascontiguousarray(np.asarray(values, dtype=float)), deep=True)
    array.SetName(name)
    (data.GetCellData() if on == "cell" else data.GetPointData()).AddArray(array)


def values_of(data: Any, name: str, *, on: str = "cell") -> np.ndarray | None:
    """The array ``name`` of ``data``'s cells (or points) as NumPy, None where it has none."""
    array = (data.GetCellData() if on == "cell" else data.GetPointData()).GetArray(name)
    return None if array is None else _vtk().vtk_to_numpy(array)


def _lookup_table(cmap: str, clim: tuple[float, float], nan_colour: str | Sequence[float]) -> Any:
    table = _vtk().vtkLookupTable()
    colours = colour_table(cmap)
    table.SetNumberOfTableValues(len(colours))
    for k, (red, green, blue) in enumerate(colours):
        table.SetTableValue(k, red / 255, green / 255, blue / 255, 1.0)
    table.SetNanColor(*rgb(nan_colour), 1.0)
    table.SetTableRange(*clim)
    return table


# -- the render window -------------------------------------------------------------------------
_SPARE: list[Any] = []  # the render window the last picture freed (release_window)


def offscreen_window(size: tuple[int, int], samples: int) -> Any:
    """An off-screen render window of ``size`` pixels and ``samples`` a pixel, without renderers:
    the one the last picture of this process freed (:func:`release_window`) where there is one,
    else a new one. Its making and its OpenGL context cost a picture more than its render with
    Mesa's software OpenGL (``docs/performance.md``); made once, the pictures of a run share it.

    Raises
    ------
    dolfinx_nnqem.io.offscreen.PictureUnavailable
        VTK cannot render in this process.
    """
    from dolfinx_nnqem.io.offscreen import check_rendering

    check_rendering()
    if _SPARE:
        window = _SPARE.pop()
    else:
        window = _vtk().vtkRenderWindow()
        window.SetOffScreenRendering(1)
    window.SetSize(*size)
    window.SetMultiSamples(samples)
    window.SetNumberOfLayers(1)
    return window


def write_png(window: Any, path: str | os.PathLike) -> None:
    """Render ``window`` once and write its pixels (RGB, the back buffer) into the PNG file ``path``:
    the last step of every picture, 3D scenes and charts alike."""
    vtk = _vtk()
    window.Render()
    image = vtk.vtkWindowToImageFilter()
    image.SetInput(window)
    image.SetInputBufferTypeToRGB()
    image.ReadFrontBufferOff()
    image.ShouldRerenderOff()
    image.Update()
    writer = vtk.vtkPNGWriter()
    writer.SetCompressionLevel(PNG_COMPRESSION)
    writer.SetFileName(str(path))
    writer.SetInputConnection(image.GetOutputPort())
    writer.Write()


def release_window(window: Any) -> None:
    """Give ``window`` back for the next picture (:func:`offscreen_window`): its renderers removed."""
    renderers = window.GetRenderers()
    for renderer in [renderers.GetItemAsObject(k) for k in range(renderers.GetNumberOfItems())]:
        window.RemoveRenderer(renderer)
    _SPARE[:] = [window]


def legend_disc(colour: str | Sequence[float], pixels: int = LEGEND_DISC_PIXELS) -> Any:
    """A legend's symbol: a disc of ``colour`` as an RGBA image of ``pixels`` × ``pixels``, its
    edge's pixels as opaque as the disc covers them.

    An image rather than a polygon: the legend is drawn after the scene's FXAA pass
    (:data:`SMOOTHED_EDGES`), so a polygon's edge would stay jagged; the image is scaled to the
    legend's symbol box with linear interpolation, which keeps its edge soft.
    """
    vtk = _vtk()
    centre = 0.5 * pixels
    y, x = np.mgrid[0:pixels, 0:pixels] + 0.5
    coverage = np.clip(centre - np.hypot(x - centre, y - centre), 0.0, 1.0)
    rgba = np.empty((pixels, pixels, 4), dtype=np.uint8)
    rgba[..., :3] = np.round(255 * np.asarray(rgb(colour)))
    rgba[..., 3] = np.round(255 * coverage)
    image = vtk.vtkImageData()
    image.SetDimensions(pixels, pixels, 1)
    image.GetPointData().SetScalars(vtk.numpy_to_vtk(rgba.reshape(-1, 4), deep=True,
                                                     array_type=vtk.VTK_UNSIGNED_CHAR))
    return image


def _legend_polygon_disc() -> Any:
    """A legend's symbol where images cannot be (:func:`~dolfinx_nnqem.pyvista_compat.legend_takes_images`):
    a polygon disc of diameter 1 raised by 0.6 (the symbol beside its text)."""
    angle = np.linspace(0.0, 2.0 * np.pi, 100, endpoint=False)
    ring = np.column_stack([0.5 * np.cos(angle), 0.5 * np.sin(angle) + 0.6, np.zeros_like(angle)])
    disc = _vtk().vtkPolyData()
    disc.SetPoints(_points(ring))
    disc.SetPolys(_cells(np.arange(len(ring)).reshape(1, -1)))
    return disc


# -- the scene -----------------------------------------------------------------------------------
class Scene:
    """An off-screen render window of ``size`` pixels with one renderer: meshes, a colour bar, a
    legend, a title, a camera, then :meth:`screenshot`. ``actors`` holds what was added by name.

    Raises
    ------
    dolfinx_nnqem.io.offscreen.PictureUnavailable
        VTK cannot render in this process (:func:`dolfinx_nnqem.pyvista_compat.vtk_render_problem`).
    """

    def __init__(self, size: tuple[int, int]):
        vtk = _vtk()
        self.window: Any = offscreen_window(size, WINDOW_SAMPLES)
        self.renderer = vtk.vtkRenderer()
        self.renderer.SetBackground(1.0, 1.0, 1.0)
        self.renderer.SetUseFXAA(SMOOTHED_EDGES)
        self.window.AddRenderer(self.renderer)
        vtk.vtkLightKit().AddLightsToRenderer(self.renderer)
        self.actors: dict[str, Any] = {}  #: name → the VTK prop added under it
        self.legend: list[tuple[str, tuple[float, float, float]]] = []  #: (label, colour) of the meshes
        self._axes: Any = None  # the renderer of the axes in the lower left corner, if shown

    # -- props -----------------------------------------------------------------------------------
    def add(self, name: str, prop: Any) -> Any:
        """Add the VTK ``prop`` as ``name`` (replacing the prop of that name)."""
        self.remove(name)
        self.renderer.AddViewProp(prop)
        self.actors[name] = prop
        return prop

    def remove(self, name: str) -> None:
        """Remove the prop ``name`` if there is one."""
        prop = self.actors.pop(name, None)
        if prop is not None:
            self.renderer.RemoveViewProp(prop)

    def add_mesh(self, name: str, data: Any, *, colour: str | Sequence[float] = "white", scalars: str | None = None,
                 on: str = "cell", cmap: str = "viridis", clim: tuple[float, float] | None = None,
                 nan_colour: str = "darkgray", show_edges: bool = False, edge_colour: str = "black",
                 line_width: float = 1.0, point_size: float = 5.0, spheres: bool = False, opacity: float = 1.0,
                 smooth: bool = False, label: str | None = None) -> Any:
        """Add ``data`` (a VTK dataset) as ``name``: coloured by its array ``scalars`` (on cells or
        points, the map ``cmap`` over ``clim``, default the array's range) or by ``colour``;
        ``smooth``: shaded by point normals; ``label``: an entry of the legend."""
        vtk = _vtk()
        if smooth:
            normals = vtk.vtkPolyDataNormals()
            normals.SetInputData(data)
            normals.ComputeCellNormalsOff()
            normals.SplittingOff()
            normals.Update()
            data = normals.GetOutput()
        mapper = vtk.vtkDataSetMapper()
        mapper.SetInputData(data)
        if scalars is None:
            mapper.ScalarVisibilityOff()
        else:
            values = values_of(data, scalars, on=on)
            if values is None:
                raise ValueError(f"no {on} field {scalars!r} to colour by")
            if clim is None:
                finite = values[np.isfinite(values)]
                clim = (float(finite.min()), float(finite.max())) if len(finite) else (0.0, 1.0)
            mapper.SetLookupTable(_lookup_table(cmap, clim, nan_colour))
            mapper.SetScalarRange(*clim)
            mapper.SetScalarModeToUseCellFieldData() if on == "cell" else mapper.SetScalarModeToUsePointFieldData()
            mapper.SelectColorArray(scalars)
            mapper.ScalarVisibilityOn()
            mapper.InterpolateScalarsBeforeMappingOn()
        actor = vtk.vtkActor()
        actor.SetMapper(mapper)
        style = actor.GetProperty()
        style.SetColor(*rgb(colour))
        style.SetOpacity(opacity)
        style.SetLineWidth(line_width)
        style.SetPointSize(point_size)
        style.SetAmbient(0.0)
        style.SetDiffuse(1.0)
        style.SetSpecular(0.0)
        if spheres:
            style.RenderPointsAsSpheresOn()
        if show_edges:
            style.EdgeVisibilityOn()
            style.SetEdgeColor(*rgb(edge_colour))
        if smooth:
            style.SetInterpolationToPhong()
        else:
            style.SetInterpolationToFlat()
        if label is not None:
            self.legend.append((label, rgb(colour)))
        return self.add(name, actor)

    def add_scalar_bar(self, title: str, actor: Any, name: str = "scalar bar") -> Any:
        """A horizontal colour bar of ``actor``'s colours at the bottom, titled ``title``, five
        labels of three significant digits."""
        vtk = _vtk()
        bar = vtk.vtkScalarBarActor()
        bar.SetLookupTable(actor.GetMapper().GetLookupTable())
        bar.SetMaximumNumberOfColors(256)
        bar.SetNumberOfLabels(5)
        bar.SetOrientationToHorizontal()
        bar.SetPosition(0.35, 0.05)
        bar.SetWidth(0.6)
        bar.SetHeight(0.08)
        bar.SetLabelFormat("%-#6.3g")
        bar.UnconstrainedFontSizeOn()
        bar.SetAnnotationTextScaling(False)
        bar.SetTitle(title)
        for text in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty(), bar.GetAnnotationTextProperty()):
            text.SetColor(0.0, 0.0, 0.0)
            text.SetFontFamilyToArial()
            text.SetFontSize(FONT_SIZE)
            text.ItalicOff()
            text.BoldOff()
            text.ShadowOff()
        bar.GetTitleTextProperty().SetJustificationToCentered()
        return self.add(name, bar)

    def add_legend(self, *, size: tuple[float, float] = (0.2, 0.15), background: str = "lightgrey") -> Any:
        """The legend of the meshes added with a ``label``, in the lower left corner: a disc of
        each one's colour and its label, on a ``background`` box of ``size`` (of the window)."""
        vtk = _vtk()
        legend = vtk.vtkLegendBoxActor()
        legend.SetNumberOfEntries(len(self.legend))
        images = legend_takes_images(vtk.vtkVersion.GetVTKVersion())
        for k, (label, colour) in enumerate(self.legend):
            if images:  # the disc's box ends where the label begins: the space keeps them apart
                legend.SetEntry(k, legend_disc(colour), f" {label}", colour)
            else:  # a polygon: drawn after the FXAA pass, its edge stays jagged
                legend.SetEntry(k, _legend_polygon_disc(), label, colour)
        legend.SetPosition(0.05, 0.05)
        legend.SetPosition2(*size)
        legend.UseBackgroundOn()
        legend.SetBackgroundColor(*rgb(background))
        legend.SetBackgroundOpacity(1.0)
        legend.BorderOff()
        legend.GetEntryTextProperty().SetFontFamilyToArial()
        return self.add("legend", legend)

    def add_text(self, text: str, font_size: int = 10) -> Any:
        """``text`` in the upper left corner, black, its size following the window's as pyvista's
        ``add_text(font_size=...)`` does."""
        vtk = _vtk()
        corner = vtk.vtkCornerAnnotation()
        corner.SetText(2, text)  # 2: the upper left corner
        corner.SetLinearFontScaleFactor(font_size // 2)
        corner.SetNonlinearFontScaleFactor(0.35)
        corner.SetMaximumFontSize(200)
        corner.SetMinimumFontSize(6)
        style = corner.GetTextProperty()
        style.SetColor(0.0, 0.0, 0.0)
        style.SetFontFamilyToArial()
        style.ShadowOff()
        return self.add("title", corner)

    def add_axes(self) -> Any:
        """The x, y, z axes in the lower left corner, turned as the scene is (an orientation marker)."""
        vtk = _vtk()
        axes = vtk.vtkAxesActor()
        axes.SetShaftTypeToLine()
        for name, colour in (("X", "tomato"), ("Y", "seagreen"), ("Z", "mediumblue")):
            for style in (getattr(axes, f"Get{name}AxisShaftProperty")(), getattr(axes, f"Get{name}AxisTipProperty")()):
                style.SetColor(*rgb(colour))
                style.SetLineWidth(2.0)
                style.SetAmbient(0.5)
            caption = getattr(axes, f"Get{name}AxisCaptionActor2D")()
            caption.SetWidth(0.25)
            caption.SetHeight(0.1)
            text = caption.GetCaptionTextProperty()
            text.SetColor(0.0, 0.0, 0.0)
            text.ShadowOff()
        corner = vtk.vtkRenderer()
        corner.SetViewport(0.0, 0.0, 0.2, 0.2)
        corner.SetLayer(1)
        corner.InteractiveOff()
        corner.SetUseFXAA(SMOOTHED_EDGES)
        corner.AddViewProp(axes)
        self.window.SetNumberOfLayers(2)
        self.window.AddRenderer(corner)
        self._axes = corner
        self.actors["axes"] = axes
        return axes

    # -- camera and picture ------------------------------------------------------------------------
    def view_vector(self, vector: Sequence[float], viewup: Sequence[float] = (0.0, 0.0, 1.0)) -> None:
        """Look at the centre of the scene from the direction ``vector``, ``viewup`` up, the
        whole scene in view (pyvista's ``view_vector``)."""
        bounds = np.array(self.renderer.ComputeVisiblePropBounds(), dtype=float)
        centre = 0.5 * (bounds[::2] + bounds[1::2])
        camera = self.renderer.GetActiveCamera()
        camera.SetFocalPoint(*centre)
        camera.SetPosition(*(centre + np.asarray(vector, dtype=float)))
        camera.SetViewUp(*(float(v) for v in viewup))
        self.renderer.ResetCamera()

    def camera(self) -> Any:
        """The renderer's vtkCamera (to move, zoom or read)."""
        return self.renderer.GetActiveCamera()

    def _turn_axes(self) -> None:
        """The axes' camera looking along the scene's (the orientation marker's rule)."""
        if self._axes is None:
            return
        camera = self.renderer.GetActiveCamera()
        direction = np.asarray(camera.GetPosition()) - np.asarray(camera.GetFocalPoint())
        marker = self._axes.GetActiveCamera()
        marker.SetFocalPoint(0.0, 0.0, 0.0)
        marker.SetPosition(*(direction / np.linalg.norm(direction)))
        marker.SetViewUp(*camera.GetViewUp())
        self._axes.ResetCamera()

    def screenshot(self, path: str | os.PathLike) -> None:
        """Render once and write the window into the PNG file ``path``."""
        self._turn_axes()
        self.renderer.ResetCameraClippingRange()
        write_png(self.window, path)

    def close(self) -> None:
        """Give the render window back for the next picture (:func:`release_window`)."""
        if self.window is not None:
            release_window(self.window)
            self.window = None
