"""The run's curves: ``pair_pressure.png``, ``load_curve.png`` and ``convergence.png`` (matplotlib).

What they show is described in :mod:`dolfinx_nnqem.io.run_pictures`. They need only
``summary.json`` and the last pair table, and this module imports nothing of the package (numpy
and matplotlib only), so that a fresh Python process can draw them, loading this file by its
path (:func:`start_drawing_curves`): that process imports matplotlib and draws while the run's
own process draws the pyvista pictures, on another core. Through the package it would load
DOLFINx first (a third of a second).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["CURVES", "draw_convergence", "draw_curves", "draw_load_curve", "draw_pair_pressure",
           "load_curve_series", "start_drawing_curves"]

CURVES = ("pair_pressure.png", "load_curve.png", "convergence.png")
MPI_LAUNCHER_PREFIXES = ("PMI_", "PMIX_", "HYDRA_", "MPIR_", "MPI_LOCAL", "OMPI_", "PRTE_")
"""Environment variables of an MPI launcher: a child of a rank must not see them (it would try
to join the parallel job, and fail to start)."""


def _matplotlib():
    import matplotlib

    matplotlib.use("Agg")  # off-screen: no display needed
    import matplotlib.pyplot as plt

    return plt


def _rows_by_interface(rows: list[dict]) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for row in rows:
        out.setdefault(row.get("interface", ""), []).append(row)
    return out


def draw_pair_pressure(rows: list[dict], path: Path, *, title: str = "") -> Path:
    """Pair pressure (Pa) over each contact surface, one panel per interface."""
    plt = _matplotlib()
    groups = _rows_by_interface(rows)
    fig, axes = plt.subplots(1, len(groups), figsize=(5.5 * len(groups), 4.5), squeeze=False)
    for ax, (name, group) in zip(axes[0], groups.items()):
        x = np.array([[float(r["slave_x"]), float(r["slave_y"]), float(r["slave_z"])] for r in group])
        pressure = np.array([float(r["pressure"]) for r in group])
        # the surface's two longest extents name the axes (a contact plane x-z shows x and z)
        a, b = sorted(np.argsort(np.ptp(x, axis=0))[-2:])
        closed = np.array([r["state"] != "open" for r in group])
        cloud = ax.scatter(x[:, a], x[:, b], c=pressure, cmap="viridis", s=60, edgecolors="k")
        ax.margins(0.15)  # room for the legend beside the edge pairs
        if np.any(~closed):
            ax.scatter(x[~closed, a], x[~closed, b], s=60, facecolors="white", edgecolors="grey",
                       label="open")
            ax.legend(loc="best", fontsize=8)
        fig.colorbar(cloud, ax=ax, label="pressure (Pa)")
        ax.set_xlabel(f"{'xyz'[a]} (m)")
        ax.set_ylabel(f"{'xyz'[b]} (m)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"interface {name}: max {pressure.max():.3g} Pa", fontsize=9)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _largest_component(history: list[list[float]]) -> tuple[int, np.ndarray]:
    """(k, values of component k) for the component with the largest last magnitude."""
    values = np.asarray(history, dtype=float).reshape(len(history), -1)
    k = int(np.argmax(np.abs(values[-1])))
    return k, values[:, k]


def load_curve_series(summary: dict) -> tuple[list[tuple[str, np.ndarray]], list[tuple[str, np.ndarray]]]:
    """The load curve's data: ([(label, force per increment, N)], [(label, displacement, m)])."""
    forces, displacements = [], []
    for key, what in (("reaction_history", "reaction of tag"), ("obstacle_force_history", "obstacle")):
        history = summary.get(key, [])
        for name in (history[-1] if history else {}):
            k, values = _largest_component([h.get(name, [math.nan] * 3) for h in history])
            forces.append((f"{what} {name}: F{'xyz'[k]}", values))
    probes = summary.get("probe_history", [])
    # the two-beam benchmark renames its probes "free_end_corners"
    names = [p["name"] for p in summary.get("probes") or summary.get("free_end_corners") or []]
    for i, name in enumerate(names if probes else []):
        k, values = _largest_component([h[i] for h in probes])
        displacements.append((f"{name}: u{'xyz'[k]}", values))
    return forces, displacements


def draw_load_curve(summary: dict, path: Path, *, title: str = "") -> Path:
    """Load factor against reactions (N) and probe displacements (mm)."""
    factors = np.asarray(summary.get("load_factors", []), dtype=float)
    forces, displacements = load_curve_series(summary)
    panels = [(s, "force (N)", 1.0) for s in [forces] if s] + [(s, "displacement (mm)", 1e3)
                                                               for s in [displacements] if s]
    if not panels:
        raise ValueError("summary.json has no reaction_history or probe_history")
    plt = _matplotlib()
    fig, axes = plt.subplots(1, len(panels), figsize=(6 * len(panels), 4.5), squeeze=False)
    for ax, (series, xlabel, unit) in zip(axes[0], panels):
        for label, values in series:
            n = min(len(values), len(factors))
            ax.plot(unit * values[:n], factors[:n], "o-", ms=4, label=label)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("load factor")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def draw_convergence(summary: dict, path: Path, *, title: str = "") -> Path:
    """‖R‖/F and ‖H‖/F per iteration, one line per increment (log scale)."""
    histories = [np.asarray(h, dtype=float).reshape(-1, 2) for h in summary.get("residual_histories", []) if h]
    if not histories:
        raise ValueError("summary.json has no residual_histories")
    with_contact = any(np.any(h[:, 1] > 0) for h in histories)
    names = ["equilibrium ‖R‖/F"] + (["contact ‖H‖/F"] if with_contact else [])
    plt = _matplotlib()
    from matplotlib import ticker

    fig, axes = plt.subplots(1, len(names), figsize=(6 * len(names), 4.5), squeeze=False)
    colours = plt.get_cmap("viridis")(np.linspace(0.0, 0.9, len(histories)))
    for column, (ax, name) in enumerate(zip(axes[0], names)):
        for k, (h, colour) in enumerate(zip(histories, colours)):
            ax.semilogy(np.arange(len(h)), np.maximum(h[:, column], 1e-17), "o-", ms=3, color=colour,
                        label=f"increment {k + 1}" if len(histories) <= 12 else None)
        # plain "1e−08" labels: the default ones are mathtext, whose parser cost this picture 0.5 s
        ax.yaxis.set_major_formatter(ticker.LogFormatter())
        ax.set_xlabel("iteration")
        ax.set_ylabel(name)
        ax.grid(True, which="both", alpha=0.3)
        if len(histories) <= 12:
            ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


# -- the three curves, in this process or in a child ---------------------------------------------
def draw_curves(summary: dict, rows: list[dict], out: str | os.PathLike, title: str) -> dict[str, str]:
    """Draw :data:`CURVES` into the folder ``out``.

    Returns
    -------
    dict
        Per picture name, the path written (a string), or ``"not drawn: ..."`` with the reason.
    """
    out = Path(out)
    done: dict[str, str] = {}
    draws: dict[str, Callable[..., Path]] = {"pair_pressure.png": draw_pair_pressure,
                                             "load_curve.png": draw_load_curve,
                                             "convergence.png": draw_convergence}
    for name, draw in draws.items():
        if name == "pair_pressure.png" and not rows:
            done[name] = "not drawn: no contact pairs"
            continue
        try:
            done[name] = str(draw(rows if name == "pair_pressure.png" else summary, out / name, title=title))
        except (ValueError, KeyError, OSError, IndexError) as error:  # the data is missing
            done[name] = f"not drawn: {error}"
    return done


class CurveDrawing:
    """The curves being drawn by a child process (:func:`start_drawing_curves`), or drawn already."""

    def __init__(self, child: subprocess.Popen | None, fallback: Callable[[], dict[str, str]],
                 drawn: dict[str, str] | None = None):
        self._child = child
        self._fallback = fallback
        self._drawn = drawn

    @classmethod
    def finished(cls, drawn: dict[str, str]) -> CurveDrawing:
        """Curves drawn in this process: :meth:`result` gives ``drawn``."""
        return cls(None, lambda: drawn, drawn)

    def result(self) -> dict[str, str]:
        """Wait for the child: per picture its path or ``"not drawn: ..."`` (:func:`draw_curves`).
        Where the child failed (or took over 600 s), the curves are drawn here instead."""
        if self._drawn is None:
            child, self._child = self._child, None
            try:
                assert child is not None and child.stdout is not None
                stdout, _ = child.communicate(timeout=600)
                self._drawn = json.loads(stdout) if child.returncode == 0 else None
            except (subprocess.TimeoutExpired, OSError, ValueError, AssertionError):
                self._drawn = None
                _end(child)
            if self._drawn is None:
                self._drawn = self._fallback()
        return self._drawn

    def cancel(self) -> None:
        """Stop the child, if it still runs (the run stopped drawing: an error, an interrupt)."""
        child, self._child = self._child, None
        _end(child)


def _end(child: subprocess.Popen | None) -> None:
    if child is not None and child.poll() is None:
        child.kill()
        child.communicate()


def start_drawing_curves(summary: dict, rows: list[dict], out: str | os.PathLike, title: str) -> CurveDrawing:
    """Start :func:`draw_curves` in a fresh Python process, which this one waits for with
    :meth:`CurveDrawing.result`.

    The run's process meanwhile draws its pyvista pictures: the two take about as long, and
    each imports its own library (matplotlib there; pyvista and VTK here), so on a machine with
    a free core the curves cost the run next to no time. Where the child cannot start or fails,
    the curves are drawn in this process instead (the same pictures).
    """
    job = json.dumps({"summary": summary, "rows": rows, "out": str(out), "title": title})
    # a child of an MPI rank must not join the parallel job (MPICH: "PMI_Init returned -1")
    env = {k: v for k, v in os.environ.items() if not k.startswith(MPI_LAUNCHER_PREFIXES)}
    code = ("import importlib.util, json, sys\n"
            "spec = importlib.util.spec_from_file_location('_nnqem_curves', sys.argv[1])\n"
            "module = importlib.util.module_from_spec(spec)\n"
            "spec.loader.exec_module(module)\n"
            "job = json.load(sys.stdin)\n"
            "done = module.draw_curves(job['summary'], job['rows'], job['out'], job['title'])\n"
            "sys.stdout.write(json.dumps(done))\n")

    def here() -> dict[str, str]:
        return draw_curves(summary, rows, out, title)

    try:
        child = subprocess.Popen([sys.executable, "-c", code, str(Path(__file__).resolve())], stdin=subprocess.PIPE,
                                 stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env)
    except OSError:
        return CurveDrawing.finished(here())
    try:  # the job goes now: the child reads it once it has loaded numpy, then imports matplotlib
        assert child.stdin is not None
        child.stdin.write(job)
        child.stdin.close()
    except OSError:  # the child died at once: drawn here when asked
        pass
    child.stdin = None  # closed: communicate() must not flush it
    return CurveDrawing(child, here)
