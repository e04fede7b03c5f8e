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

from dolfinx_nnqem.io.live_fields import LINEAR_VTK_CELLS
import dolfinx_nnqem.io.vtk_scene as vtk_scene
from dolfinx_nnqem.io.obstacle_shapes import add_obstacles, view_box

__all__ = ["CAMERAS", "LABELS", "STATE_COLOURS", "VTK_CELLS", "DeformedScene", "deformed_plotter", "deformed_scene",
           "draw_deformed"]

STATE_COLOURS = {"open": "white", "stick": "royalblue", "slip": "crimson"}
_log = logging.getLogger("dolfinx_nnqem")


VTK_CELLS = {4: ("tetra", 4), 10: ("tetra", 4), 8: ("hexahedron", 8), 20: ("hexahedron", 8),
             27: ("hexahedron", 8)}
"""Nodes per cell in the XDMF topology → (cell type, corner nodes): a quadratic cell is drawn by
its corners (XDMF lists them first)."""

_VTK_TYPES = {"tetra": 10, "hexahedron": 12}
"""VTK's cell type numbers (VTK_TETRA, VTK_HEXAHEDRON)."""

CELL_FIELDS = ("von_mises", "p", "plastic", "error_indicator")
"""The cell fields of a step the picture can be coloured by."""


def _field_grid(step: dict, scale: float | None) -> tuple[Any, float]:
    """The VTK grid of one field step, moved by ``scale`` × u; returns (grid, scale).

    A step with ``cell_type`` (from memory, :mod:`dolfinx_nnqem.io.live_fields`, or from
    ``fields_p2.pvd``) is drawn on those VTK cells whole, a quadratic one with its edge nodes;
    a step read from ``fields.xdmf`` by the corners of its cells (:data:`VTK_CELLS`).
    """
    topology = np.asarray(step["topology"], dtype=np.int64)
    if "cell_type" in step:
        cell_type, cells = int(step["cell_type"]), topology
    elif topology.shape[1] in VTK_CELLS:
        name, corners = VTK_CELLS[topology.shape[1]]
        cell_type, cells = _VTK_TYPES[name], topology[:, :corners]
    else:
        raise ValueError(f"cells with {topology.shape[1]} nodes: expected one of {sorted(VTK_CELLS)}")
    x = np.asarray(step["geometry"], dtype=float).reshape(-1, 3)
    u = np.asarray(step.get("u", np.zeros_like(x)), dtype=float).reshape(len(x), -1)[:, :3]
    if scale is None:
        umax = np.abs(u).max()
        scale = 0.1 * np.ptp(x, axis=0).max() / umax if umax > 0 else 1.0
    grid = vtk_scene.unstructured_grid(x + scale * u, cells, cell_type)
    for key in CELL_FIELDS:
        if key in step:
            vtk_scene.set_values(grid, key, np.asarray(step[key], dtype=float).reshape(len(topology), -1)[:, 0])
    return grid, scale


def _cell_fields(grid: Any) -> list[str]:
    """The names of the cell fields of ``grid`` (a VTK dataset)."""
    data = grid.GetCellData()
    return sorted(data.GetArrayName(k) for k in range(data.GetNumberOfArrays()))


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
        points, cells, cell_types, u = _read_lagrange_cells(folder / datasets[-1].attrib["file"])
        cell_type = int(cell_types[0]) if len(cell_types) else -1
        if cell_type not in LINEAR_VTK_CELLS or np.any(cell_types != cell_type):
            raise ValueError(f"cells of VTK types {sorted(set(cell_types.tolist()))}")
        cells = cells.reshape(len(cell_types), -1)
        order = _matching_cells(step, points, cells, LINEAR_VTK_CELLS[cell_type][1])
    except (OSError, ValueError, KeyError, IndexError, ET.ParseError) as error:
        _log.warning(f"picture deformed.png: drawn from fields.xdmf, not {index.name} ({error})")
        return step
    quadratic = {"time": step["time"], "geometry": points, "topology": cells, "cell_type": cell_type, "u": u}
    ncells = len(np.asarray(step["topology"]))
    for key, values in step.items():
        values = np.asarray(values)
        if key not in quadratic and values.ndim and len(values) == ncells:  # a cell field
            quadratic[key] = values.reshape(ncells, -1)[order]
    return quadratic


def _read_lagrange_cells(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(points, connectivity, cell types, u at the points) of the VTK XML unstructured grid ``path``
    (a dataset of ``fields_p2.pvd``: a ``.pvtu`` and its pieces, or a ``.vtu``), read by VTK's
    reader; a ValueError where it has no ``u``."""
    if not path.is_file():
        raise OSError(f"{path.name} is missing")
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLPUnstructuredGridReader, vtkXMLUnstructuredGridReader

    reader = vtkXMLPUnstructuredGridReader() if path.suffix == ".pvtu" else vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    grid = reader.GetOutput()
    u = grid.GetPointData().GetArray("u")
    if grid.GetPoints() is None or u is None:
        raise ValueError(f"{path.name} holds no grid with u")
    return (vtk_to_numpy(grid.GetPoints().GetData()).astype(float), vtk_to_numpy(grid.GetCells().GetConnectivityArray()).astype(np.int64),
            vtk_to_numpy(grid.GetCellTypesArray()).astype(np.int64), vtk_to_numpy(u).astype(float))


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


def deformed_scene(step: dict, rows: list[dict], *, title: str = "", scale: float | None = None,
                   field: str = "von_mises", camera: str = "iso",
                   obstacles: Mapping[str, Mapping[str, Any]] | None = None) -> vtk_scene.Scene:
    """The off-screen scene of :func:`draw_deformed`, not yet rendered: the deformed mesh coloured
    by ``field`` (actor ``bodies``), the plastic zone outlined, the pairs by state, and each rigid
    obstacle of ``obstacles`` (``summary.json``'s records,
    :func:`~dolfinx_nnqem.io.obstacle_shapes.obstacle_records`) moved by ``scale`` × its
    displacement (actor ``obstacle:NAME``)."""
    grid, scale = _field_grid(step, scale)
    if field not in _cell_fields(grid):
        raise ValueError(f"field {field!r}: the results hold {_cell_fields(grid)}")
    scene = vtk_scene.Scene((1200, 800))
    _add_bodies(scene, grid, field)
    plastic_zone = _add_plastic_zone(scene, grid)
    points, states = _pair_points(rows, scale)
    for state, colour in STATE_COLOURS.items():
        selected = states == state
        if np.any(selected):
            scene.add_mesh(f"pairs:{state}", vtk_scene.point_data(points[selected]), colour=colour, point_size=14,
                           spheres=True, label=f"{state} ({int(selected.sum())})")
    box = view_box(vtk_scene.vtk_modules().vtk_to_numpy(grid.GetPoints().GetData()))
    drawn = add_obstacles(scene, obstacles, box, scale) if obstacles else []
    if len(points) or plastic_zone or drawn:
        scene.add_legend(size=(0.2, 0.15), background="lightgrey")
    scene.add_text(f"{title}\ndisplacements x {scale:.3g}", font_size=10)
    # y up, as the problem files of this package have it (gravity along -y, stacks along y)
    scene.view_vector(CAMERAS[camera][0], viewup=CAMERAS[camera][1])
    return scene


deformed_plotter = deformed_scene  # (its name when it returned a pyvista plotter)

CAMERAS = {"iso": ((1.0, 0.8, 1.4), (0.0, 1.0, 0.0)), "xy": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
           "xz": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)), "yz": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0))}
"""Camera name → (direction from the bodies to the camera, the direction up in the picture)."""


def _add_plastic_zone(scene: vtk_scene.Scene, grid: Any) -> bool:
    """The outline of the cells where p > 0 (their outer surface's boundary and feature edges, not
    the inner cell faces), drawn over the colours; False where no cell is plastic."""
    p = vtk_scene.values_of(grid, "p")
    if p is None or not np.any(p > 0):
        return False
    vtk = vtk_scene.vtk_modules()
    # the plastic cells as a grid of their own (one cell type: rows of the connectivity)
    cells = vtk.vtk_to_numpy(grid.GetCells().GetConnectivityArray()).reshape(grid.GetNumberOfCells(), -1)
    points = vtk.vtk_to_numpy(grid.GetPoints().GetData())
    plastic = vtk_scene.unstructured_grid(points, cells[p > 0], grid.GetCellType(0))
    surface = vtk.vtkDataSetSurfaceFilter()
    surface.SetInputData(plastic)
    edges = vtk.vtkFeatureEdges()
    edges.SetInputConnection(surface.GetOutputPort())
    edges.BoundaryEdgesOn()
    edges.FeatureEdgesOn()
    edges.ManifoldEdgesOff()
    edges.NonManifoldEdgesOff()
    edges.ColoringOff()
    edges.Update()
    scene.add_mesh("plastic zone", edges.GetOutput(), colour="darkorange", line_width=4,
                   label="plastic zone (p > 0)")
    return True


LABELS = {"von_mises": "von Mises stress (Pa)", "p": "equivalent plastic strain p",
          "error_indicator": "error indicator eta_K (sqrt J)"}
"""The colour bar's title of each cell field (any other: its name)."""


def _add_bodies(scene: vtk_scene.Scene, grid: Any, field: str) -> None:
    """The deformed bodies coloured by the cell field ``field`` (actor ``bodies``), edges shown, and
    its colour bar (replacing those of another field)."""
    bodies = scene.add_mesh("bodies", grid, scalars=field, cmap="viridis", show_edges=True)
    scene.add_scalar_bar(LABELS.get(field, field), bodies)


class DeformedScene:
    """The scene of :func:`deformed_scene`, made once and saved coloured by one cell field after
    another (``deformed.png``, then ``error_indicator.png``): only the bodies' colours and the
    colour bar change between them, not the mesh, the plastic zone, the pairs or the obstacles.

    Parameters are those of :func:`deformed_scene` but ``field``, given to :meth:`draw`.
    """

    def __init__(self, step: dict, rows: list[dict], *, title: str = "", scale: float | None = None,
                 camera: str = "iso", obstacles: Mapping[str, Mapping[str, Any]] | None = None):
        self.step, self.rows = step, rows
        self.options: dict[str, Any] = {"title": title, "scale": scale, "camera": camera, "obstacles": obstacles}
        self.scene: vtk_scene.Scene | None = None  #: the VTK scene, made at the first :meth:`draw`
        self.field: str | None = None  #: the field the bodies are coloured by

    def draw(self, field: str, path: Path) -> Path:
        """The scene coloured by ``field`` into the PNG file ``path``."""
        if self.scene is None:
            self.scene = deformed_scene(self.step, self.rows, field=field, **self.options)
        elif field != self.field:
            grid = self.scene.actors["bodies"].GetMapper().GetInput()
            if field not in _cell_fields(grid):
                raise ValueError(f"field {field!r}: the results hold {_cell_fields(grid)}")
            _add_bodies(self.scene, grid, field)  # (replaces the actor and the colour bar)
        self.field = field
        self.scene.screenshot(path)
        return path

    def close(self) -> None:
        """Free the scene (its render window)."""
        if self.scene is not None:
            self.scene.close()
            self.scene = None


def draw_deformed(step: dict, rows: list[dict], path: Path, *, title: str = "", scale: float | None = None,
                  field: str = "von_mises", camera: str = "iso",
                  obstacles: Mapping[str, Mapping[str, Any]] | None = None) -> Path:
    """The deformed shape coloured by ``field``, the plastic zone outlined, pairs by state, the
    rigid obstacles where they stand (:func:`deformed_scene`), into the PNG file ``path``."""
    scene = DeformedScene(step, rows, title=title, scale=scale, camera=camera, obstacles=obstacles)
    try:
        return scene.draw(field, path)
    finally:
        scene.close()
