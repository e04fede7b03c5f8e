"""The picture of the deformed shape (``deformed.png``, ``error_indicator.png``): the bodies on the
last increment's deformed mesh, coloured by a cell field, the plastic zone outlined, the contact
pairs by state and the rigid obstacles where they stand (:mod:`dolfinx_nnqem.io.obstacle_shapes`).

Drawn from a field step: the last increment of ``fields.xdmf`` read back, with the degree-2
displacement of ``fields_p2.pvd`` where the run wrote it, or the run's fields from memory
(:mod:`dolfinx_nnqem.io.live_fields`). Imports neither DOLFINx nor MPI (a picture worker draws it).
"""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from dolfinx_nnqem import pyvista_compat
from dolfinx_nnqem.io.live_fields import LINEAR_VTK_CELLS
from dolfinx_nnqem.io.obstacle_shapes import add_obstacles, view_box
from dolfinx_nnqem.io.offscreen import offscreen_plotter

__all__ = ["LABELS", "STATE_COLOURS", "VTK_CELLS", "DeformedScene", "deformed_plotter", "draw_deformed"]

STATE_COLOURS = {"open": "white", "stick": "royalblue", "slip": "crimson"}
_log = logging.getLogger("dolfinx_nnqem")


VTK_CELLS = {4: ("tetra", 4), 10: ("tetra", 4), 8: ("hexahedron", 8), 20: ("hexahedron", 8),
             27: ("hexahedron", 8)}
"""Nodes per cell in the XDMF topology → (pyvista cell type, corner nodes): a quadratic cell
is drawn by its corners (XDMF lists them first)."""


def _field_grid(step: dict, scale: float | None):
    """The pyvista grid of one field step, moved by ``scale`` × u; returns (grid, scale).

    A step with ``cell_type`` (from memory, :mod:`dolfinx_nnqem.io.live_fields`, or from
    ``fields_p2.pvd``) is drawn on those VTK cells whole, a quadratic one with its edge nodes;
    a step read from ``fields.xdmf`` by the corners of its cells (:data:`VTK_CELLS`).
    """
    pyvista = pyvista_compat.import_pyvista()

    topology = np.asarray(step["topology"], dtype=np.int64)
    if "cell_type" in step:
        cell_type, cells = int(step["cell_type"]), topology
    elif topology.shape[1] in VTK_CELLS:
        name, corners = VTK_CELLS[topology.shape[1]]
        cell_type = {"tetra": pyvista.CellType.TETRA, "hexahedron": pyvista.CellType.HEXAHEDRON}[name]
        cells = topology[:, :corners]
    else:
        raise ValueError(f"cells with {topology.shape[1]} nodes: expected one of {sorted(VTK_CELLS)}")
    x = np.asarray(step["geometry"], dtype=float).reshape(-1, 3)
    u = np.asarray(step.get("u", np.zeros_like(x)), dtype=float).reshape(len(x), -1)[:, :3]
    # the flat [n, i0, ..., i(n-1)] layout takes every VTK cell type (Lagrange cells too)
    flat = np.hstack([np.full((len(cells), 1), cells.shape[1]), cells]).reshape(-1)
    grid = pyvista.UnstructuredGrid(flat, np.full(len(cells), cell_type, dtype=np.uint8), x.copy())
    if scale is None:
        umax = np.abs(u).max()
        scale = 0.1 * np.ptp(x, axis=0).max() / umax if umax > 0 else 1.0
    grid.points = x + scale * u
    for key in ("von_mises", "p", "plastic", "error_indicator"):
        if key in step:
            grid.cell_data[key] = np.asarray(step[key], dtype=float).reshape(len(topology), -1)[:, 0]
    return grid, scale


def _with_quadratic_displacement(folder: Path, step: dict) -> dict:
    """A step of ``fields.xdmf`` with the degree-2 displacement of ``fields_p2.pvd`` where the
    folder has it for the same increment: the grid of its Lagrange cells, u at every P2 node,
    and the cell fields of ``step`` carried over to those cells (matched by their centres).
    Otherwise (degree 1, an older folder, cells that do not match) ``step`` itself."""
    index = folder / "fields_p2.pvd"
    if not index.exists():
        return step
    try:
        datasets = list(ET.parse(index).iter("DataSet"))
        if not datasets or float(datasets[-1].attrib["timestep"]) != float(step["time"]):
            raise ValueError("its last increment is not the last of fields.xdmf")
        grid = pyvista_compat.import_pyvista().read(str(folder / datasets[-1].attrib["file"]))
        cell_type = int(grid.celltypes[0])
        if cell_type not in LINEAR_VTK_CELLS or np.any(grid.celltypes != cell_type):
            raise ValueError(f"cells of VTK types {sorted(set(grid.celltypes.tolist()))}")
        cells = np.asarray(grid.cells).reshape(grid.n_cells, -1)[:, 1:]
        order = _matching_cells(step, np.asarray(grid.points), cells, LINEAR_VTK_CELLS[cell_type][1])
    except (OSError, ValueError, KeyError, IndexError, ET.ParseError) as error:
        _log.warning(f"picture deformed.png: drawn from fields.xdmf, not {index.name} ({error})")
        return step
    quadratic = {"time": step["time"], "geometry": np.asarray(grid.points), "topology": cells,
                 "cell_type": cell_type, "u": np.asarray(grid.point_data["u"])}
    ncells = len(np.asarray(step["topology"]))
    for key, values in step.items():
        values = np.asarray(values)
        if key not in quadratic and values.ndim and len(values) == ncells:  # a cell field
            quadratic[key] = values.reshape(ncells, -1)[order]
    return quadratic


def _matching_cells(step: dict, points: np.ndarray, cells: np.ndarray, corners: int) -> np.ndarray:
    """For each of ``cells`` (rows of ``points``), the row of the same cell in ``step``'s topology,
    found by the centre of its corners (a ValueError where a cell has no match)."""
    from scipy.spatial import cKDTree

    x = np.asarray(step["geometry"], dtype=float).reshape(-1, 3)
    topology = np.asarray(step["topology"], dtype=np.int64)
    if len(topology) != len(cells):
        raise ValueError(f"{len(cells)} cells against {len(topology)} in fields.xdmf")
    # the corner nodes are the first ones in both files' orderings (XDMF's and VTK's Lagrange cells)
    centres = x[topology[:, :corners]].mean(axis=1)
    distance, order = cKDTree(centres).query(points[cells[:, :corners]].mean(axis=1))
    size = max(float(np.ptp(x, axis=0).max()), 1e-300)
    if np.any(distance > 1e-9 * size) or len(np.unique(order)) != len(order):
        raise ValueError("its cells are not those of fields.xdmf")
    return order


def _pair_points(rows: list[dict], scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Slave points of the pairs on the drawn (scaled) deformed mesh, and their states."""
    if not rows:
        return np.zeros((0, 3)), np.array([], dtype=str)
    slave = np.array([[float(r["slave_x"]), float(r["slave_y"]), float(r["slave_z"])] for r in rows])
    u2 = np.array([[float(r["u2x"]), float(r["u2y"]), float(r["u2z"])] for r in rows])
    return slave + scale * u2, np.array([r["state"] for r in rows])


def deformed_plotter(step: dict, rows: list[dict], *, title: str = "", scale: float | None = None,
                     field: str = "von_mises", camera: str = "iso",
                     obstacles: Mapping[str, Mapping[str, Any]] | None = None):
    """The off-screen scene of :func:`draw_deformed`, not yet rendered: the deformed mesh coloured
    by ``field``, the plastic zone outlined, the pairs by state, and each rigid obstacle of
    ``obstacles`` (``summary.json``'s records, :func:`~dolfinx_nnqem.io.obstacle_shapes.obstacle_records`)
    moved by ``scale`` × its displacement (actor ``obstacle:NAME``)."""
    grid, scale = _field_grid(step, scale)
    if field not in grid.cell_data:
        raise ValueError(f"field {field!r}: the results hold {sorted(grid.cell_data)}")
    plotter = offscreen_plotter((1200, 800))
    _add_bodies(plotter, grid, field)
    plastic_zone = "p" in grid.cell_data and np.any(grid.cell_data["p"] > 0)
    if plastic_zone:
        plastic = grid.extract_cells(np.flatnonzero(grid.cell_data["p"] > 0))
        # the outline of the plastic zone (not its inner cell faces), drawn over the colours
        edges = pyvista_compat.extract_outer_surface(plastic).extract_feature_edges(
            boundary_edges=True, feature_edges=True, manifold_edges=False, non_manifold_edges=False)
        plotter.add_mesh(edges, color="darkorange", line_width=4, label="plastic zone (p > 0)")
    points, states = _pair_points(rows, scale)
    for state, colour in STATE_COLOURS.items():
        selected = states == state
        if np.any(selected):
            plotter.add_points(points[selected], color=colour, point_size=14, render_points_as_spheres=True,
                               label=f"{state} ({int(selected.sum())})")
    drawn = add_obstacles(plotter, obstacles, view_box(np.asarray(grid.points)), scale) if obstacles else []
    if plotter.legend is None and (len(points) or plastic_zone or drawn):
        plotter.add_legend(bcolor="lightgrey", face="circle", size=(0.2, 0.15), loc="lower left")
    plotter.add_text(f"{title}\ndisplacements x {scale:.3g}", font_size=10)
    # y up, as the problem files of this package have it (gravity along -y, stacks along y)
    views = {"iso": lambda: plotter.view_vector((1.0, 0.8, 1.4), viewup=(0, 1, 0)), "xy": plotter.view_xy,
             "xz": plotter.view_xz, "yz": plotter.view_yz}
    views[camera]()
    return plotter


LABELS = {"von_mises": "von Mises stress (Pa)", "p": "equivalent plastic strain p",
          "error_indicator": "error indicator eta_K (sqrt J)"}
"""The colour bar's title of each cell field (any other: its name)."""


def _add_bodies(plotter, grid, field: str) -> None:
    """The deformed bodies coloured by the cell field ``field`` (actor ``bodies``), its colour bar.

    Not rendered meanwhile (``render=False``): once a plotter has rendered, pyvista renders the
    whole scene again at every actor added or removed unless told not to, and only the
    screenshot's render is wanted (the scene recoloured for ``error_indicator.png`` rendered it
    three times)."""
    plotter.add_mesh(grid, scalars=field, show_edges=True, cmap="viridis", name="bodies",
                     scalar_bar_args={"title": LABELS.get(field, field)}, render=False)


class DeformedScene:
    """The scene of :func:`deformed_plotter`, made once and saved coloured by one cell field after
    another (``deformed.png``, then ``error_indicator.png``): only the bodies' colours and the
    colour bar change between them, not the mesh, the plastic zone, the pairs or the obstacles.

    Parameters are those of :func:`deformed_plotter` but ``field``, given to :meth:`draw`.
    """

    def __init__(self, step: dict, rows: list[dict], *, title: str = "", scale: float | None = None,
                 camera: str = "iso", obstacles: Mapping[str, Mapping[str, Any]] | None = None):
        self.step, self.rows = step, rows
        self.options: dict[str, Any] = {"title": title, "scale": scale, "camera": camera, "obstacles": obstacles}
        self.plotter: Any = None  #: the pyvista plotter, made at the first :meth:`draw`
        self.field: str | None = None  #: the field the bodies are coloured by

    def draw(self, field: str, path: Path) -> Path:
        """The scene coloured by ``field`` into the PNG file ``path``."""
        if self.plotter is None:
            self.plotter = deformed_plotter(self.step, self.rows, field=field, **self.options)
        elif field != self.field:
            grid = self.plotter.actors["bodies"].mapper.dataset
            if field not in grid.cell_data:
                raise ValueError(f"field {field!r}: the results hold {sorted(grid.cell_data)}")
            self.plotter.remove_scalar_bar(LABELS.get(self.field or "", self.field), render=False)
            _add_bodies(self.plotter, grid, field)  # (replaces the actor of that name)
        self.field = field
        self.plotter.screenshot(str(path))
        return path

    def close(self) -> None:
        """Free the plotter (its render window)."""
        if self.plotter is not None:
            self.plotter.close()
            self.plotter = None


def draw_deformed(step: dict, rows: list[dict], path: Path, *, title: str = "", scale: float | None = None,
                  field: str = "von_mises", camera: str = "iso",
                  obstacles: Mapping[str, Mapping[str, Any]] | None = None) -> Path:
    """The deformed shape coloured by ``field``, the plastic zone outlined, pairs by state, the
    rigid obstacles where they stand (:func:`deformed_plotter`), into the PNG file ``path``."""
    scene = DeformedScene(step, rows, title=title, scale=scale, camera=camera, obstacles=obstacles)
    try:
        return scene.draw(field, path)
    finally:
        scene.close()
