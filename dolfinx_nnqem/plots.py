"""Pictures: pyvista (off-screen PNG) for fields, matplotlib for curves.

Collective functions gather what they draw on rank 0, which alone writes the file.
Off-screen pyvista needs no X server with the PyPI VTK; with Debian's VTK run under
``xvfb-run -a`` (see ``docs/install.md``).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from dolfinx_nnqem import results as res
from dolfinx_nnqem.output import von_mises

STATE_COLOURS = {0: "white", 1: "royalblue", 2: "crimson"}  # open, stick, slip


def _matplotlib():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_curve(x, y, path: str | os.PathLike, *, xlabel: str, ylabel: str, label: str = "FE",
               reference: dict[str, float] | None = None, title: str = "") -> None:
    """A curve with optional horizontal reference lines (e.g. an analytical limit load)."""
    plt = _matplotlib()
    fig, ax = plt.subplots(figsize=(6, 4))
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
    plt.close(fig)


def plot_convergence(histories: Sequence[Sequence[float]], path: str | os.PathLike,
                     labels: Sequence[str] | None = None, title: str = "") -> None:
    """Relative residual per iteration, one line per increment (log scale)."""
    plt = _matplotlib()
    fig, ax = plt.subplots(figsize=(6, 4))
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
    plt.close(fig)


def _gather_grid(problem, field: str):
    """Rank 0: (topology, cell_types, points, u, cell values) of the whole mesh; None elsewhere."""
    import dolfinx.plot

    topology, cell_types, x = dolfinx.plot.vtk_mesh(problem.V)
    u = problem.u.x.array.reshape(-1, 3)[: len(x)]
    state = problem.state
    ncells = len(cell_types)
    qdofs = state.W_scalar.dofmap.list[:ncells]
    if field == "von_mises":
        values = von_mises(state.sigma_n.x.array.reshape(-1, 3, 3)[qdofs]).mean(axis=1)
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


def plot_deformed(problem, path: str | os.PathLike, *, field: str = "von_mises", scale: float | None = None,
                  show_pairs: bool = True, title: str = "", camera: str | Sequence[float] | None = "iso",
                  focus: Sequence[float] | None = None, zoom: float = 1.0) -> None:
    """Deformed shape (displacements × ``scale``) coloured by a Gauss-point field (cell means).

    ``field``: ``"von_mises"`` (Pa) or ``"p"`` (equivalent plastic strain). Contact pairs are
    drawn at their slave nodes as spheres coloured by state (white open, blue stick, red slip).
    ``camera``: "iso", "xy", "xz", "yz", "front", a direction (x, y, z) from the focus to the
    camera, or None (VTK's default); ``focus``: the point looked at (default the mesh centre);
    ``zoom``: > 1 magnifies. Collective.
    """
    grid_data = _gather_grid(problem, field)
    table = res.pair_table(problem) if (show_pairs and problem.has_contact) else None
    if problem.comm.rank != 0:
        return
    import pyvista

    pyvista.OFF_SCREEN = True
    topology, cell_types, x, u, values = grid_data
    grid = pyvista.UnstructuredGrid(topology, cell_types, x)
    if scale is None:
        size = np.ptp(x, axis=0).max()
        umax = np.abs(u).max()
        scale = 0.1 * size / umax if umax > 0 else 1.0
    grid.points = x + scale * u
    grid.cell_data[field] = values
    plotter = pyvista.Plotter(off_screen=True, window_size=(1200, 700))
    plotter.add_mesh(grid, scalars=field, show_edges=True, cmap="viridis",
                     scalar_bar_args={"title": {"von_mises": "von Mises (Pa)", "p": "p"}[field]})
    if table is not None:
        centres = table["position_b"] + scale * table["u_body2"]  # the slave nodes: on the drawn mesh
        for state, colour in STATE_COLOURS.items():
            sel = table["state"] == state
            if np.any(sel):
                plotter.add_points(centres[sel], color=colour, point_size=14,
                                   render_points_as_spheres=True)
    plotter.add_text(f"{title}  (displacements x {scale:.3g})", font_size=10)
    views = {"iso": plotter.view_isometric, "xy": plotter.view_xy, "xz": plotter.view_xz,
             "yz": plotter.view_yz, "front": lambda: plotter.view_vector((0.4, 0.5, 1.0), viewup=(0, 1, 0))}
    if isinstance(camera, str):
        if camera not in views:
            raise ValueError(f"camera {camera!r}: expected one of {sorted(views)}, a direction, or None")
        views[camera]()
    elif camera is not None:
        plotter.view_vector(tuple(float(c) for c in camera), viewup=(0, 1, 0))
    if focus is not None:
        position = np.asarray(plotter.camera.position) - np.asarray(plotter.camera.focal_point)
        plotter.camera.focal_point = tuple(focus)
        plotter.camera.position = tuple(np.asarray(focus) + position)
    if zoom != 1.0:
        plotter.camera.zoom(zoom)
    plotter.screenshot(str(path))
    plotter.close()
