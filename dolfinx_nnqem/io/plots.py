"""Pictures of a live problem: VTK (off-screen PNG, :mod:`dolfinx_nnqem.io.vtk_scene`) for fields,
matplotlib for the curves of :func:`plot_curve` and :func:`plot_convergence` (the demos' own; a
run's curves are VTK's charts, :mod:`dolfinx_nnqem.io.run_pictures`).

Collective functions gather what they draw on rank 0, which alone writes the file. The module
imports neither DOLFINx nor MPI until a function needs them: a process that only draws
(:mod:`dolfinx_nnqem.io.picture_worker`) uses :func:`draw_contact_pressure`.
Off-screen VTK needs no X server with the PyPI VTK; Debian's VTK needs one (run under
``xvfb-run -a``, see ``docs/install.md``): without it the VTK pictures are skipped with that
reason (:mod:`dolfinx_nnqem.io.offscreen`). The curves are matplotlib ``Figure`` objects saved by
the Agg canvas, without ``matplotlib.pyplot`` (its import costs, and it keeps figures open).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

import dolfinx_nnqem.io.vtk_scene as vtk_scene

if TYPE_CHECKING:
    from dolfinx_nnqem.problem.contact_problem import ContactProblem

STATE_COLOURS = {0: "white", 1: "royalblue", 2: "crimson"}  # open, stick, slip


def figure(width: float, height: float) -> Any:
    """A matplotlib ``Figure`` of ``width`` × ``height`` inches drawn by the Agg canvas (PNG, no
    display), without ``matplotlib.pyplot``: nothing to close, and pyplot's import is spared."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    return fig


def plot_curve(x: npt.ArrayLike, y: npt.ArrayLike, path: str | os.PathLike, *, xlabel: str, ylabel: str,
               label: str = "FE", reference: dict[str, float] | None = None, title: str = "") -> None:
    """A curve with optional horizontal reference lines (e.g. an analytical limit load)."""
    fig = figure(6, 4)
    ax = fig.subplots()
    ax.plot(x, y, "o-", label=label)
    for name, value in (reference or {}).items():
        ax.axhline(value, color="k", ls="--", lw=1)
        ax.text(ax.get_xlim()[0], value, f" {name}", va="bottom")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def plot_convergence(histories: Sequence[Sequence[float]], path: str | os.PathLike,
                     labels: Sequence[str] | None = None, title: str = "") -> None:
    """Relative residual per iteration, one line per increment (log scale)."""
    fig = figure(6, 4)
    ax = fig.subplots()
    for k, h in enumerate(histories):
        h = np.maximum(np.asarray(h, dtype=float), 1e-17)
        ax.semilogy(np.arange(len(h)), h, "o-", ms=3,
                    label=None if labels is None else labels[k])
    ax.set_xlabel("iteration")
    ax.set_ylabel("relative residual")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    if labels is not None and len(labels) <= 12:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def _gather_grid(problem, field: str):
    """Rank 0: (topology, cell_types, points, u, cell values) of the whole mesh; None elsewhere."""
    import dolfinx.plot

    from dolfinx_nnqem.material.kinematics import von_mises_stress

    topology, cell_types, x = dolfinx.plot.vtk_mesh(problem.V)
    u = problem.u.x.array.reshape(-1, 3)[: len(x)]
    state = problem.state
    ncells = len(cell_types)
    qdofs = state.W_scalar.dofmap.list[:ncells]
    if field == "von_mises":
        values = von_mises_stress(state.sigma_n.x.array.reshape(-1, 3, 3)[qdofs]).mean(axis=1)
    elif field == "p":
        values = state.p_n.x.array[qdofs].mean(axis=1)
    else:
        raise ValueError(f"field {field!r}: expected 'von_mises' or 'p'")
    comm = problem.comm
    parts = comm.gather((np.asarray(topology), np.asarray(cell_types), np.asarray(x), u, values), root=0)
    if comm.rank != 0:
        return None
    tops, types, xs, us, vals, offset = [], [], [], [], [], 0
    for top, ct, xx, uu, vv in parts:
        width = len(top) // max(len(ct), 1)  # one cell type per mesh: [n, i0..i(n-1)] rows
        top = top.reshape(-1, width).copy()
        top[:, 1:] += offset
        tops.append(top.reshape(-1))
        types.append(ct)
        xs.append(xx)
        us.append(uu)
        vals.append(vv)
        offset += len(xx)
    return (np.concatenate(tops), np.concatenate(types), np.concatenate(xs),
            np.concatenate(us), np.concatenate(vals))


def plot_deformed(problem: ContactProblem, path: str | os.PathLike, *, field: str = "von_mises",
                  scale: float | None = None, show_pairs: bool = True, title: str = "",
                  camera: str | Sequence[float] | None = "iso",
                  focus: Sequence[float] | None = None, zoom: float = 1.0, show_obstacles: bool = True) -> None:
    """Deformed shape (displacements × ``scale``) coloured by a Gauss-point field (cell means).

    ``field``: ``"von_mises"`` (Pa) or ``"p"`` (equivalent plastic strain). Contact pairs are
    drawn at their slave nodes as spheres coloured by state (white open, blue stick, red slip).
    With ``show_obstacles``, each rigid obstacle is drawn translucent at its position at the last
    converged increment, moved by ``scale`` × its displacement like the bodies, and clipped to a
    box around them (:mod:`dolfinx_nnqem.io.obstacle_shapes`).
    ``camera``: "iso", "xy", "xz", "yz", "front", a direction (x, y, z) from the focus to the
    camera, or None (VTK's default); ``focus``: the point looked at (default the mesh centre);
    ``zoom``: > 1 magnifies. Collective.
    """
    from dolfinx_nnqem.io.obstacle_shapes import add_obstacles, obstacle_records, view_box
    from dolfinx_nnqem.io.results import pair_table

    grid_data = _gather_grid(problem, field)
    table = pair_table(problem) if (show_pairs and problem.has_contact) else None
    records = obstacle_records(problem, problem.load_factor_n) if show_obstacles else {}
    if problem.comm.rank != 0:
        return
    scene = vtk_scene.Scene((1200, 700))
    topology, cell_types, x, u, values = grid_data
    if scale is None:
        size = np.ptp(x, axis=0).max()
        umax = np.abs(u).max()
        scale = 0.1 * size / umax if umax > 0 else 1.0
    grid = vtk_scene.unstructured_grid(x + scale * u, topology, cell_types)
    vtk_scene.set_values(grid, field, values)
    bodies = scene.add_mesh("bodies", grid, scalars=field, cmap="viridis", show_edges=True)
    scene.add_scalar_bar({"von_mises": "von Mises (Pa)", "p": "p"}[field], bodies)
    if table is not None:
        centres = table["position_b"] + scale * table["u_body2"]  # the slave nodes: on the drawn mesh
        for state, colour in STATE_COLOURS.items():
            sel = table["state"] == state
            if np.any(sel):
                scene.add_mesh(f"pairs:{state}", vtk_scene.point_data(centres[sel]), colour=colour, point_size=14,
                               spheres=True)
    if records:
        add_obstacles(scene, records, view_box(x + scale * u), scale)
    scene.add_text(f"{title}  (displacements x {scale:.3g})", font_size=10)
    views = {"iso": ((1.0, 1.0, 1.0), (0.0, 0.0, 1.0)), "xy": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
             "xz": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)), "yz": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
             "front": ((0.4, 0.5, 1.0), (0.0, 1.0, 0.0))}
    if isinstance(camera, str):
        if camera not in views:
            raise ValueError(f"camera {camera!r}: expected one of {sorted(views)}, a direction, or None")
        scene.view_vector(*views[camera])
    elif camera is not None:
        scene.view_vector(tuple(float(c) for c in camera), viewup=(0, 1, 0))
    else:
        scene.renderer.ResetCamera()
    view = scene.camera()
    if focus is not None:
        position = np.asarray(view.GetPosition()) - np.asarray(view.GetFocalPoint())
        view.SetFocalPoint(*focus)
        view.SetPosition(*(np.asarray(focus) + position))
    if zoom != 1.0:
        view.Zoom(zoom)
    try:
        scene.screenshot(path)
    finally:
        scene.close()


def _slave_triangles(problem, table: dict) -> np.ndarray | None:
    """Rank 0: the slave surface's triangles as rows of the pair table (None elsewhere).

    The facets' vertex coordinates are gathered and matched to the pairs' slave nodes
    (``position_b``); facets with a vertex that carries no pair (beyond the master) are left
    out. None as well for a surface of quadrilaterals or pairs without slave facets (node-to-node,
    obstacles): then the points alone are drawn.
    """
    from dolfinx_nnqem import compat
    from dolfinx_nnqem.contact.nearest import nearest

    slave = getattr(problem.contact.interfaces[0].pairs, "slave", None)
    if slave is None:  # node-to-node pairs and obstacles name no slave facets: points are drawn
        return None  # (the same answer on every rank: no collective call is skipped by one)
    mesh = problem.mesh
    fdim = mesh.topology.dim - 1
    facets = problem.facet_tags.find(int(slave))
    facets = facets[facets < mesh.topology.index_map(fdim).size_local]  # owned: each facet once
    nodes = compat.entities_to_geometry(mesh, fdim, facets)
    # (corners, vertices per facet): a rank without slave facets sends an empty block
    parts = problem.comm.gather((mesh.geometry.x[nodes.reshape(-1)], nodes.shape[1]), root=0)
    if problem.comm.rank != 0:
        return None
    widths = {width for corners, width in parts if len(corners)}
    if widths != {3} or len(table["position_b"]) == 0:  # quadrilaterals, or nothing to draw
        return None
    corners = np.concatenate([corners for corners, _ in parts])
    distance, row = nearest(table["position_b"], corners)
    size = max(np.ptp(table["position_b"], axis=0).max(), 1e-300)
    row = np.where(distance <= 1e-9 * size, row, -1).reshape(-1, 3)
    return row[np.all(row >= 0, axis=1)]


def contact_pressure_data(problem: ContactProblem) -> dict | None:
    """What :func:`draw_contact_pressure` draws of ``problem``, gathered on rank 0 (None elsewhere).

    Collective. A dict of ``points`` (the pairs' slave nodes, ``position_b`` of the pair table),
    ``pressure`` (Pa, per pair), ``interface`` (each pair's index into the problem's interfaces) and
    ``triangles`` (:func:`_slave_triangles`: the slave facets as rows of the table, or None where
    the points alone are drawn): NumPy arrays only, so that another process can draw them.
    """
    from dolfinx_nnqem.io.results import pair_table

    table = pair_table(problem)
    assert problem.contact is not None  # pair_table reads the contact model: it has raised without one
    triangles = _slave_triangles(problem, table) if len(problem.contact.interfaces) == 1 else None
    if problem.comm.rank != 0:
        return None
    return {"points": table["position_b"], "pressure": table["pressure"], "interface": table["interface"],
            "triangles": triangles}


def plot_contact_pressure(problem_or_table: ContactProblem | dict, path: str | os.PathLike, *,
                          problem: ContactProblem | None = None, title: str = "",
                          unit: str = "MPa", camera: str | Sequence[float] = "bottom", point_size: float = 12.0,
                          interface: int | None = None, circle: float | None = None) -> None:
    """The contact pressure on the slave surface: its facets interpolated, with a scalar bar.

    ``problem_or_table``: a problem (collective: call on every rank; its pair table is gathered
    and its slave facets are drawn as triangles coloured by the nodal pressures interpolated),
    or a pair table (:func:`dolfinx_nnqem.io.results.pair_table`; the slave nodes are drawn as
    points coloured by pressure). ``interface`` restricts to one interface of the table.
    ``camera``: "bottom" (looking up the y axis onto the contact face), "top", "iso", or a
    direction from the centre to the camera. ``circle``: the radius of a reference contact
    circle about the y axis (e.g. Hertz's a), drawn just below the surface. Rank 0 writes the PNG.
    """
    data: dict | None
    if isinstance(problem_or_table, dict):
        table = problem_or_table
        data = {"points": table["position_b"], "pressure": table["pressure"], "interface": table.get("interface"),
                "triangles": None}
        if problem is not None and problem.comm.rank != 0:
            data = None
    else:
        data = contact_pressure_data(problem_or_table)
    if data is None:  # not rank 0
        return
    select = None if interface is None else np.asarray(data["interface"]) == interface
    draw_contact_pressure(data, path, title=title, unit=unit, camera=camera, point_size=point_size,
                          select=select, circle=circle)


def draw_contact_pressure(data: dict, path: str | os.PathLike, *, title: str = "", unit: str = "MPa",
                          camera: str | Sequence[float] = "bottom", point_size: float = 12.0,
                          select: np.ndarray | None = None, circle: float | None = None) -> None:
    """Draw the contact pressure of :func:`contact_pressure_data` into ``path`` (not collective).

    Parameters
    ----------
    data
        ``points`` (n, 3), ``pressure`` (n,) and ``triangles`` (rows of ``points``, or None: the
        points are drawn as spheres coloured by pressure).
    select
        The pairs drawn (a boolean mask; default all).
    title, unit, camera, point_size, circle
        As :func:`plot_contact_pressure`.
    """
    points, triangles = np.asarray(data["points"]), data["triangles"]
    if select is None:
        select = np.ones(len(data["pressure"]), dtype=bool)
    scene = vtk_scene.Scene((1000, 800))
    try:
        _contact_pressure_scene(scene, points, triangles, np.asarray(data["pressure"], dtype=float), select,
                                title=title, unit=unit, camera=camera, point_size=point_size, circle=circle)
        scene.screenshot(path)
    finally:
        scene.close()


def _contact_pressure_scene(scene: vtk_scene.Scene, points: np.ndarray, triangles: np.ndarray | None,
                            pressure: np.ndarray, select: np.ndarray, *, title: str, unit: str,
                            camera: str | Sequence[float], point_size: float, circle: float | None) -> None:
    """The scene of :func:`draw_contact_pressure`: the surface or the points coloured by the
    pressure (the pairs not selected grey), its colour bar, the reference circle, the axes."""
    pressure = np.where(select, pressure, np.nan)
    finite = pressure[np.isfinite(pressure)]
    clim = (0.0, float(finite.max()) if len(finite) and finite.max() > 0 else 1.0)
    if triangles is not None and len(triangles):
        surface = vtk_scene.surface_data(points, np.asarray(triangles))
        vtk_scene.set_values(surface, "pressure", pressure, on="point")
        shown = scene.add_mesh("pressure", surface, scalars="pressure", on="point", cmap="plasma", clim=clim,
                               nan_colour="lightgrey", show_edges=True, edge_colour="grey")
    else:
        cloud = vtk_scene.point_data(points[select])
        vtk_scene.set_values(cloud, "pressure", pressure[select], on="point")
        shown = scene.add_mesh("pressure", cloud, scalars="pressure", on="point", cmap="plasma", clim=clim,
                               point_size=point_size, spheres=True)
    scene.add_scalar_bar(f"contact pressure ({unit})", shown)
    if circle is not None:
        # only the sector the surface covers (a quarter for a quarter model), so that the camera
        # frames the surface
        covered = np.arctan2(points[:, 2], points[:, 0])
        angle = np.linspace(covered.min(), covered.max(), 91)
        y = points[:, 1].min() - 1e-3 * max(float(np.ptp(points, axis=0).max()), 1e-300)
        ring = np.column_stack([circle * np.cos(angle), np.full_like(angle, y), circle * np.sin(angle)])
        scene.add_mesh("circle", vtk_scene.line_data(ring), colour="white", line_width=3)
    scene.add_text(title or "contact pressure on the slave surface", font_size=11)
    scene.add_axes()
    if isinstance(camera, str):
        views = {"bottom": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)), "top": ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
                 "iso": ((1.0, 1.0, 1.0), (0.0, 0.0, 1.0))}
        if camera not in views:
            raise ValueError(f"camera {camera!r}: expected one of {sorted(views)} or a direction")
        scene.view_vector(*views[camera])
    else:
        scene.view_vector(tuple(float(c) for c in camera), viewup=(0, 1, 0))
