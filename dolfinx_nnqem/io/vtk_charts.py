"""The run's curves drawn by VTK's 2D charts (``vtkChartXY``): ``load_curve.png``,
``convergence.png`` and ``pair_pressure.png`` (:mod:`dolfinx_nnqem.io.run_pictures`).

A picture is a row of panels (:class:`ChartPanels`), each a chart of lines with markers
(:func:`add_lines`) or of points coloured by a value with its colour legend (:func:`add_scatter`),
under the run's title. The look follows the matplotlib figures they replace: white background,
matplotlib's colour cycle (and viridis for the increments and the pressures), a light grid,
axis titles, a legend in the corner the data leave freest.

Why not matplotlib: a picture worker that draws the 3D pictures with VTK
(:mod:`dolfinx_nnqem.io.vtk_scene`) has most of VTK imported already; VTK's charts add a few of its
modules, where matplotlib's import cost the worker about as much as VTK's and its figures more than
the charts (``docs/performance.md``, issue 43).
"""

from __future__ import annotations

import os
import types
from collections.abc import Sequence
from typing import Any

import numpy as np

import dolfinx_nnqem.io.vtk_scene as vtk_scene
from dolfinx_nnqem.io.colour_maps import colour_table
from dolfinx_nnqem.pyvista_compat import set_plot_colour

__all__ = ["CYCLE", "ChartPanels", "add_lines", "add_scatter", "chart_modules", "sequential_colours"]

CYCLE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
         "#17becf")
"""The colours of successive lines (matplotlib's default cycle, "tab10")."""

DPI = 120
"""Pixels per inch of the pictures (their matplotlib figures were saved at 120 dpi)."""

TEXT = {"title": 17, "axis": 17, "labels": 15, "legend": 12}
"""Font sizes in pixels: a figure's title, the axes' titles, the tick labels, the legend's entries
(matplotlib's 10 pt titles and axis labels at 120 dpi, its tick labels and a small legend)."""

BORDERS = (95, 60, 25, 40)
"""Pixels (left, bottom, right, top) around a chart's plot area for the axes' tick labels and titles
and the chart's title (fixed, as the curves' margins were: the labels have a bounded width)."""

COLOUR_BAR_ROOM = 130
"""Pixels right of a scatter chart for its colour bar and the bar's labels."""

CHART_SAMPLES = 0
"""Multisampling of a chart's render window: none. The lines and markers look about the same as
with 8 samples, which cost a chart more than twice its CPU with Mesa's software OpenGL
(``docs/performance.md``)."""

_MODULES: dict[str, Any] = {}


def chart_modules() -> types.SimpleNamespace:
    """The VTK classes of :mod:`vtk_scene` and those of the charts (the charts, their 2D context
    and its OpenGL painter), imported once."""
    if not _MODULES:
        import vtkmodules.vtkRenderingContextOpenGL2  # noqa: F401  (the charts' OpenGL painter)
        from vtkmodules import vtkChartsCore, vtkRenderingContext2D

        _MODULES.update(vars(vtk_scene.vtk_modules()))
        for module in (vtkChartsCore, vtkRenderingContext2D):  # (not vtkViewsContext2D: its views import widgets)
            _MODULES.update({name: getattr(module, name) for name in dir(module) if name.startswith("vtk")})
    return types.SimpleNamespace(**_MODULES)


def sequential_colours(count: int) -> list[tuple[float, float, float]]:
    """``count`` colours of viridis from its low end to 0.9 of it (one line per increment)."""
    table = colour_table("viridis")
    rows = [table[int(round(f * 255))] / 255 for f in np.linspace(0.0, 0.9, count)]
    return [(float(red), float(green), float(blue)) for red, green, blue in rows]


def _table(columns: Sequence[tuple[str, np.ndarray]]) -> Any:
    """A vtkTable of the named columns (floats)."""
    vtk = chart_modules()
    table = vtk.vtkTable()
    for name, values in columns:
        array = vtk.numpy_to_vtk(np.ascontiguousarray(np.asarray(values, dtype=float)), deep=True)
        array.SetName(name)
        table.AddColumn(array)
    return table


def _style(text: Any, size: int, *, bold: bool = False) -> None:
    text.SetColor(0.0, 0.0, 0.0)
    text.SetFontFamilyToArial()
    text.SetFontSize(size)
    text.SetBold(bold)
    text.ItalicOff()
    text.ShadowOff()


class ChartPanels:
    """A picture of ``panels`` charts side by side, each ``width`` × ``height`` inches (at
    :data:`DPI`), ``title`` above them all; drawn off-screen.

    Raises
    ------
    dolfinx_nnqem.io.offscreen.PictureUnavailable
        VTK cannot render in this process.
    """

    def __init__(self, panels: int, width: float, height: float, title: str = ""):
        vtk = chart_modules()
        panel_width, self.height = int(round(width * DPI)), int(round(height * DPI))
        self.window = vtk_scene.offscreen_window((panel_width * panels, self.height), CHART_SAMPLES)
        self.renderer = vtk.vtkRenderer()
        self.renderer.SetBackground(1.0, 1.0, 1.0)
        self.window.AddRenderer(self.renderer)
        self.context = vtk.vtkContextActor()  # the charts' 2D scene, drawn by the renderer
        self.renderer.AddViewProp(self.context)
        top = 2 * TEXT["title"] if title else TEXT["title"] // 2  # room for the title
        self.charts: list[Any] = []
        for k in range(panels):
            chart = vtk.vtkChartXY()
            chart.SetAutoSize(False)
            # the plot area's rectangle: the axes on its edges, their labels outside in BORDERS
            left, bottom, right, up = BORDERS
            chart.SetLayoutStrategy(vtk.vtkChart.AXES_TO_RECT)
            chart.SetSize(vtk.vtkRectf(k * panel_width + left, bottom, panel_width - left - right,
                                       self.height - top - bottom - up))
            _style(chart.GetTitleProperties(), TEXT["axis"])
            for axis in range(4):
                _style(chart.GetAxis(axis).GetTitleProperties(), TEXT["axis"])
                _style(chart.GetAxis(axis).GetLabelProperties(), TEXT["labels"])
                chart.GetAxis(axis).GetGridPen().SetColorF(0.85, 0.85, 0.85)
            self.context.GetScene().AddItem(chart)
            self.charts.append(chart)
        if title:
            text = vtk.vtkTextActor()
            text.SetInput(title)
            _style(text.GetTextProperty(), TEXT["title"])
            text.GetTextProperty().SetJustificationToCentered()
            text.GetTextProperty().SetVerticalJustificationToTop()
            text.SetPosition(panel_width * panels / 2, self.height - TEXT["title"] // 2)
            self.renderer.AddViewProp(text)

    def plot_size(self, index: int) -> tuple[float, float]:
        """The pixels (width, height) of the plot area of chart ``index``."""
        rect = self.charts[index].GetSize()
        return rect.GetWidth(), rect.GetHeight()

    def add_colour_bar(self, index: int, lookup: Any, title: str) -> None:
        """A vertical colour bar of ``lookup`` right of chart ``index``, titled ``title`` (the
        chart narrowed to leave it room)."""
        vtk = chart_modules()
        chart = self.charts[index]
        rect = chart.GetSize()
        room = COLOUR_BAR_ROOM
        chart.SetSize(vtk.vtkRectf(rect.GetX(), rect.GetY(), rect.GetWidth() - room, rect.GetHeight()))
        width, height = self.window.GetSize()
        bar = vtk.vtkScalarBarActor()
        bar.SetLookupTable(lookup)
        bar.SetMaximumNumberOfColors(256)
        bar.SetNumberOfLabels(5)
        bar.SetOrientationToVertical()
        bar.SetLabelFormat("%-#6.3g")
        bar.SetTitle(title)
        bar.UnconstrainedFontSizeOn()
        bar.SetAnnotationTextScaling(False)
        for text in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty()):
            _style(text, TEXT["labels"])
        # the bar beside the plot area, its title above it (in the room above the plot area)
        bar.SetPosition((rect.GetX() + rect.GetWidth() - room + BORDERS[2]) / width, rect.GetY() / height)
        bar.SetWidth((room - BORDERS[2]) / width)
        bar.SetHeight((rect.GetHeight() + BORDERS[3]) / height)
        self.renderer.AddViewProp(bar)

    def save(self, path: str | os.PathLike) -> None:
        """Render once and write the picture into the PNG file ``path``; the window is given back
        for the next picture (:func:`~dolfinx_nnqem.io.vtk_scene.release_window`)."""
        try:
            vtk_scene.write_png(self.window, path)
        finally:
            vtk_scene.release_window(self.window)


def _legend_corner(chart: Any, lines: Sequence[np.ndarray], box: tuple[float, float, float, float],
                   labels: Sequence[str]) -> tuple[int, int]:
    """The place in the plot area where the legend of ``labels`` covers the least of ``lines``
    (each an (n, 2) array of its points in the axes' units, ``box`` = (x0, x1, y0, y1) the axes'
    ranges, in logarithms on a log axis): (horizontal, vertical) alignment of vtkChartLegend
    (LEFT/CENTER/RIGHT, TOP/CENTER/BOTTOM), the first of matplotlib's order among the equally
    free (its "best", as far as the legend's size is known beforehand)."""
    vtk = chart_modules()
    legend = vtk.vtkChartLegend
    x0, x1, y0, y1 = box
    rect = chart.GetSize()
    # the legend's box as fractions of the plot area: a symbol and the longest label per entry line
    width = (40 + 0.6 * TEXT["legend"] * max(len(label) for label in labels)) / max(rect.GetWidth(), 1.0)
    height = (10 + 1.3 * TEXT["legend"] * len(labels)) / max(rect.GetHeight(), 1.0)
    samples = []
    for line in lines:  # each line sampled along its segments (a line crossing a corner covers it)
        u = (line[:, 0] - x0) / max(x1 - x0, 1e-300)
        v = (line[:, 1] - y0) / max(y1 - y0, 1e-300)
        t = np.linspace(0.0, 1.0, 20)[:, None]
        if len(u) > 1:
            u = (u[:-1] + t * np.diff(u)).reshape(-1)
            v = (v[:-1] + t * np.diff(v)).reshape(-1)
        samples.append(np.column_stack([u, v]))
    uv = np.concatenate(samples) if samples else np.zeros((0, 2))
    # matplotlib's order of the places "best" tries: the corners, then the middles of the sides
    places = [(legend.RIGHT, legend.TOP), (legend.LEFT, legend.TOP), (legend.LEFT, legend.BOTTOM),
              (legend.RIGHT, legend.BOTTOM), (legend.LEFT, legend.CENTER), (legend.RIGHT, legend.CENTER),
              (legend.CENTER, legend.BOTTOM), (legend.CENTER, legend.TOP), (legend.CENTER, legend.CENTER)]
    start = {legend.LEFT: 0.0, legend.RIGHT: 1.0 - width, legend.BOTTOM: 0.0, legend.TOP: 1.0 - height}
    counts = []
    for horizontal, vertical in places:
        u0 = start.get(horizontal, 0.5 - width / 2) if horizontal != legend.CENTER else 0.5 - width / 2
        v0 = start.get(vertical, 0.5 - height / 2) if vertical != legend.CENTER else 0.5 - height / 2
        covered = (uv[:, 0] >= u0) & (uv[:, 0] <= u0 + width) & (uv[:, 1] >= v0) & (uv[:, 1] <= v0 + height)
        counts.append(int(np.count_nonzero(covered)))
    return places[int(np.argmin(counts))]


def _nice_ticks(axis: Any, limits: tuple[float, float], most: int) -> str:
    """Ticks of a linear axis at round values (steps of 1, 2, 2.5 or 5 × a power of ten), at most
    ``most``, labelled with the digits their step needs; beyond 1e5 or below 1e-3 the labels are
    of a common power of ten, returned as the suffix of the axis's title (" [x 1e6]"), else "".
    (VTK's own labels of large values ran into one another: "-200000-100000".)"""
    vtk = chart_modules()
    low, high = limits
    raw = max(high - low, 1e-300) / most
    magnitude = 10.0 ** np.floor(np.log10(raw))
    step = next(f * magnitude for f in (1.0, 2.0, 2.5, 5.0, 10.0) if f * magnitude >= raw * (1 - 1e-9))
    ticks = np.arange(np.ceil(low / step - 1e-9), np.floor(high / step + 1e-9) + 1) * step
    biggest = float(np.abs(ticks).max()) if len(ticks) else 0.0
    exponent = int(np.floor(np.log10(biggest))) if biggest > 0 and not 1e-3 <= biggest < 1e5 else 0
    scaled_step = step / 10.0 ** exponent
    decimals = max(0, -int(np.floor(np.log10(scaled_step) + 1e-9)))
    if decimals and abs(scaled_step * 10 ** decimals - round(scaled_step * 10 ** decimals)) > 1e-6:
        decimals += 1  # a step of 2.5 × 10^k
    positions, labels = vtk.vtkDoubleArray(), vtk.vtkStringArray()
    for tick in ticks:
        text = f"{tick / 10.0 ** exponent:.{decimals}f}"
        positions.InsertNextValue(float(tick))
        labels.InsertNextValue("0" if float(text) == 0 else text)
    axis.SetCustomTickPositions(positions, labels)
    return f" [x 1e{exponent}]" if exponent else ""


def _equal_ranges(xlim: tuple[float, float], ylim: tuple[float, float],
                  pixels: tuple[float, float]) -> tuple[tuple[float, float], tuple[float, float]]:
    """``xlim`` or ``ylim`` widened about its middle so that a unit is as many pixels along x as
    along y in a plot area of ``pixels`` (width, height)."""
    width, height = max(pixels[0], 1.0), max(pixels[1], 1.0)
    per_pixel = max((xlim[1] - xlim[0]) / width, (ylim[1] - ylim[0]) / height)
    centre_x, centre_y = 0.5 * (xlim[0] + xlim[1]), 0.5 * (ylim[0] + ylim[1])
    return ((centre_x - 0.5 * per_pixel * width, centre_x + 0.5 * per_pixel * width),
            (centre_y - 0.5 * per_pixel * height, centre_y + 0.5 * per_pixel * height))


def _range(values: np.ndarray, *, log: bool = False, pad: float = 0.05) -> tuple[float, float]:
    """The axis range of ``values``: on a linear axis with a margin of ``pad`` × their span each
    side; on a log axis the whole decades around them (as matplotlib's: residuals that differ by
    round-off between two runs give the same picture)."""
    finite = values[np.isfinite(values)]
    if log:
        finite = np.log10(finite[finite > 0])
        low, high = (float(np.floor(finite.min())), float(np.ceil(finite.max()))) if len(finite) else (0.0, 1.0)
        return 10.0 ** low, 10.0 ** max(high, low + 1.0)
    low, high = (float(finite.min()), float(finite.max())) if len(finite) else (0.0, 1.0)
    margin = pad * (high - low) if high > low else max(abs(high), 1.0) * pad
    return low - margin, high + margin


def _fixed_axis(axis: Any, limits: tuple[float, float]) -> None:
    """``axis`` fixed to ``limits`` in data units (before a log axis takes their logarithms)."""
    vtk = chart_modules()
    axis.SetBehavior(vtk.vtkAxis.FIXED)
    axis.SetUnscaledRange(*limits)


def _decade_ticks(axis: Any, limits: tuple[float, float], most: int = 9) -> None:
    """Ticks of a log axis at whole decades within ``limits``, every decade or every few so that
    at most ``most`` are labelled, as "1e-08" (VTK's own: every decade, with minor grid lines)."""
    vtk = chart_modules()
    first, last = int(np.ceil(np.log10(limits[0]) - 1e-9)), int(np.floor(np.log10(limits[1]) + 1e-9))
    step = max(1, int(np.ceil((last - first + 1) / most)))
    positions, labels = vtk.vtkDoubleArray(), vtk.vtkStringArray()
    for exponent in range(last - (last - first) // step * step, last + 1, step):
        positions.InsertNextValue(float(exponent))  # (a log axis places its ticks by the exponent)
        labels.InsertNextValue("1" if exponent == 0 else f"1e{exponent:+03d}".replace("+", ""))
    axis.SetCustomTickPositions(positions, labels)


def add_lines(chart: Any, series: Sequence[tuple[str | None, np.ndarray, np.ndarray, Any]], *, xlabel: str,
              ylabel: str, log_y: bool = False, marker_size: float = 8.0, legend: bool = True,
              title: str = "") -> None:
    """Lines with circle markers, one per (label, x, y, colour) of ``series`` (a label None: left
    out of the legend), on a grid; ``log_y``: a logarithmic y axis."""
    vtk = chart_modules()
    bottom, left = chart.GetAxis(vtk.vtkAxis.BOTTOM), chart.GetAxis(vtk.vtkAxis.LEFT)
    points = []
    for k, (label, x, y, colour) in enumerate(series):
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        # a series of one point is its marker (VTK logs an error for a line of fewer than 2 points)
        line = chart.AddPlot(vtk.vtkChart.LINE if len(x) > 1 else vtk.vtkChart.POINTS)
        line.SetInputData(_table([("x", x), (label or f"series {k}", y)]), 0, 1)
        set_plot_colour(line, *vtk_scene.rgb(colour))
        line.SetWidth(1.5)
        line.SetMarkerStyle(vtk.vtkPlotPoints.CIRCLE)
        line.SetMarkerSize(marker_size)
        if label is None and hasattr(line, "SetLegendVisibility"):
            line.SetLegendVisibility(False)
        points.append(np.column_stack([x, y]))
    data = np.concatenate(points) if points else np.zeros((0, 2))
    xlim, ylim = _range(data[:, 0]), _range(data[:, 1], log=log_y)
    _fixed_axis(bottom, xlim)
    _fixed_axis(left, ylim)
    if log_y:
        left.SetLogScale(True)
        _decade_ticks(left, ylim)
    else:
        ylabel += _nice_ticks(left, ylim, 8)
    bottom.SetTitle(xlabel + _nice_ticks(bottom, xlim, 7))
    left.SetTitle(ylabel)
    chart.SetTitle(title)
    if legend and any(label is not None for label, *_ in series):
        chart.SetShowLegend(True)
        low, high = (float(np.log10(ylim[0])), float(np.log10(ylim[1]))) if log_y else ylim
        shown = [np.column_stack([line[:, 0], np.log10(np.maximum(line[:, 1], 1e-300)) if log_y else line[:, 1]])
                 for line in points]
        labels = [label for label, *_ in series if label is not None]
        horizontal, vertical = _legend_corner(chart, shown, (xlim[0], xlim[1], low, high), labels)
        chart.GetLegend().SetHorizontalAlignment(horizontal)
        chart.GetLegend().SetVerticalAlignment(vertical)
        _style(chart.GetLegend().GetLabelProperties(), TEXT["legend"])
        chart.GetLegend().SetLabelSize(TEXT["legend"])


def _points_plot(chart: Any, x: np.ndarray, y: np.ndarray, label: str | None, size: float, *,
                 colour: str = "black") -> Any:
    """A plot of circle markers at (x, y) in ``chart``, of ``colour``; named ``label`` in the
    legend (None: left out of it, where this VTK can)."""
    vtk = chart_modules()
    dots = chart.AddPlot(vtk.vtkChart.POINTS)
    dots.SetInputData(_table([("x", x), (label or "points", y)]), 0, 1)
    dots.SetMarkerStyle(vtk.vtkPlotPoints.CIRCLE)
    dots.SetMarkerSize(size)
    set_plot_colour(dots, *vtk_scene.rgb(colour))
    if label is None and hasattr(dots, "SetLegendVisibility"):
        dots.SetLegendVisibility(False)
    return dots


def add_scatter(panels: ChartPanels, index: int, x: np.ndarray, y: np.ndarray, values: np.ndarray, *, cmap: str = "viridis",
                value_label: str, xlabel: str, ylabel: str, title: str = "", grey: np.ndarray | None = None,
                grey_label: str = "", marker_size: float = 9.0, equal: bool = True) -> None:
    """Into the chart ``index`` of ``panels``: points (x, y) coloured by ``values`` (the map ``cmap``
    over their range) with a colour bar titled ``value_label`` on the chart's right; the points of
    ``grey`` (a mask) drawn white with a grey edge on top, named ``grey_label`` in a legend; ``equal``: the
    same length per pixel along both axes (the ranges widened)."""
    vtk = chart_modules()
    chart = panels.charts[index]
    x, y, values = (np.asarray(a, dtype=float) for a in (x, y, values))
    low, high = float(values.min()), float(values.max())
    if high <= low:
        high = low + (abs(low) if low else 1.0)
    table = colour_table(cmap)
    lookup = vtk.vtkLookupTable()
    lookup.SetNumberOfTableValues(len(table))
    for k, (red, green, blue) in enumerate(table):
        lookup.SetTableValue(k, red / 255, green / 255, blue / 255, 1.0)
    lookup.SetTableRange(low, high)
    # a marker is a disc without an edge: each is drawn on a larger one of the edge's colour (black,
    # grey for the grey points), so that touching markers stay apart
    edges = grey if grey is not None else np.zeros(len(x), dtype=bool)
    for mask, colour, label in ((~edges, "black", None), (edges, "grey", grey_label)):
        if np.any(mask):
            _points_plot(chart, x[mask], y[mask], label, marker_size + 2.0, colour=colour)
    dots = _points_plot(chart, x, y, None, marker_size)
    dots.SetInputData(_table([("x", x), ("y", y), ("value", values)]), 0, 1)
    dots.SetLookupTable(lookup)
    dots.SelectColorArray("value")
    dots.ScalarVisibilityOn()
    if np.any(edges):
        _points_plot(chart, x[edges], y[edges], None, marker_size, colour="white")
        chart.SetShowLegend(True)
        _style(chart.GetLegend().GetLabelProperties(), TEXT["legend"])
        chart.GetLegend().SetLabelSize(TEXT["legend"])
    panels.add_colour_bar(index, lookup, value_label)
    xlim, ylim = _range(x, pad=0.15), _range(y, pad=0.15)  # room for the legend beside the edge pairs
    if equal:
        xlim, ylim = _equal_ranges(xlim, ylim, panels.plot_size(index))
    _fixed_axis(chart.GetAxis(vtk.vtkAxis.BOTTOM), xlim)
    _fixed_axis(chart.GetAxis(vtk.vtkAxis.LEFT), ylim)
    chart.GetAxis(vtk.vtkAxis.BOTTOM).SetTitle(xlabel + _nice_ticks(chart.GetAxis(vtk.vtkAxis.BOTTOM), xlim, 6))
    chart.GetAxis(vtk.vtkAxis.LEFT).SetTitle(ylabel + _nice_ticks(chart.GetAxis(vtk.vtkAxis.LEFT), ylim, 8))
    chart.SetTitle(title)
