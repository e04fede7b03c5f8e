"""Writers: what a converged increment leaves on disk.

Each writer is a callable taking an :class:`~dolfinx_nnqem.stepping.IncrementResult`; pass them
as ``callbacks`` to :func:`~dolfinx_nnqem.stepping.solve_load_steps`. Files are (re)written
after every increment, so a run that dies at increment k leaves increments 1..k readable.

- ``fields.xdmf`` (+ ``.h5``): one time series (time = load factor) with the displacement
  ``u`` (P1), and per cell the von Mises stress ``von_mises``, the equivalent plastic strain
  ``p`` and the fraction of Gauss points that yielded in the increment ``plastic`` (cell means
  of the Gauss-point values).
- ``pairs.pvd`` + ``pairs/pairs_XXXX.vtp``: the contact pairs as a point cloud with p_n,
  friction force, state, gap and slip (ParaView).
- ``pairs/pairs_XXXX.csv``: the pair table of each increment.
- ``summary.json``: the run summary (schema in ``docs/outputs.md``).
"""

from __future__ import annotations

import csv
import json
import math
import os
import time
from pathlib import Path

import dolfinx.fem as fem
import numpy as np
from dolfinx.io import XDMFFile

from dolfinx_nnqem import results as res
from dolfinx_nnqem.convergence import STATE_NAMES


def von_mises(sigma: np.ndarray) -> np.ndarray:
    """q = sqrt(3/2 s:s) for stresses of shape (..., 3, 3)."""
    s = sigma - np.trace(sigma, axis1=-2, axis2=-1)[..., None, None] * np.eye(3) / 3.0
    return np.sqrt(1.5 * np.einsum("...ij,...ij->...", s, s))


class FieldWriter:
    """XDMF time series of the displacement and cell means of the Gauss-point state."""

    def __init__(self, problem, path: str | os.PathLike):
        self.problem = problem
        mesh = problem.mesh
        self.Q0 = fem.functionspace(mesh, ("DG", 0))
        self.q = fem.Function(self.Q0, name="von_mises")
        self.p = fem.Function(self.Q0, name="p")
        self.plastic = fem.Function(self.Q0, name="plastic")
        # XDMF stores fields of the mesh's degree: a quadratic displacement is written at the
        # vertices (interpolated to P1)
        if problem.V.ufl_element().embedded_superdegree > 1:
            self.u_out = fem.Function(fem.functionspace(mesh, ("Lagrange", 1, (3,))), name="u")
        else:
            self.u_out = None
        self.file = XDMFFile(mesh.comm, str(path), "w")
        self.file.write_mesh(mesh)

    def _cell_means(self) -> None:
        state = self.problem.state
        tdim = self.problem.mesh.topology.dim
        imap = self.problem.mesh.topology.index_map(tdim)
        cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
        qdofs = state.W_scalar.dofmap.list[cells]  # (ncells, points per cell)
        dg = self.Q0.dofmap.list[cells, 0]
        sigma = state.sigma_n.x.array.reshape(-1, 3, 3)
        self.q.x.array[dg] = von_mises(sigma[qdofs]).mean(axis=1)
        self.p.x.array[dg] = state.p_n.x.array[qdofs].mean(axis=1)
        self.plastic.x.array[dg] = (state.dp_n.x.array[qdofs] > 0).mean(axis=1)

    def __call__(self, result) -> None:
        self._cell_means()
        t = float(result.load_factor)
        u = self.problem.u
        if self.u_out is not None:
            self.u_out.interpolate(u)
            u = self.u_out
        for f in (u, self.q, self.p, self.plastic):
            self.file.write_function(f, t)

    def close(self) -> None:
        self.file.close()


class PairWriter:
    """Pair point cloud (VTK .vtp per increment + .pvd collection) and a CSV table per increment."""

    def __init__(self, problem, folder: str | os.PathLike):
        self.problem = problem
        self.folder = Path(folder)
        self.rank = problem.comm.rank
        self.entries: list[tuple[float, str]] = []
        if self.rank == 0:
            (self.folder / "pairs").mkdir(parents=True, exist_ok=True)

    def __call__(self, result) -> None:
        table = res.pair_table(self.problem)  # collective
        if self.rank != 0:
            return
        name = f"pairs_{result.index:04d}"
        self._write_csv(self.folder / "pairs" / f"{name}.csv", table)
        self._write_vtp(self.folder / "pairs" / f"{name}.vtp", table)
        self.entries.append((float(result.load_factor), f"pairs/{name}.vtp"))
        self._write_pvd(self.folder / "pairs.pvd")

    @staticmethod
    def _write_csv(path: Path, t: dict) -> None:
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["pair", "interface", "x", "y", "z", "state", "p_n_on_body1", "t1_on_body1", "t2_on_body1",
                        "Fx_on_body1", "Fy_on_body1", "Fz_on_body1", "gap", "slip1", "slip2",
                        "u1x", "u1y", "u1z", "u2x", "u2y", "u2z"])
            for i in range(len(t["state"])):
                w.writerow([i, t["interface_name"][i], *t["position"][i], STATE_NAMES[t["state"][i]],
                            *t["force_local_body1"][i], *t["force_on_body1"][i], t["gap"][i], *t["slip"][i],
                            *t["u_body1"][i], *t["u_body2"][i]])

    @staticmethod
    def _write_vtp(path: Path, t: dict) -> None:
        import pyvista

        cloud = pyvista.PolyData(np.asarray(t["position"], dtype=float))
        local = t["force_local_body1"]
        cloud["p_n"] = -local[:, 0]  # compression on body 2, N
        cloud["friction_on_body2"] = -t["force_on_body1"] - (-local[:, 0])[:, None] * t["frame"][:, 0, :]
        cloud["force_on_body1"] = t["force_on_body1"]
        cloud["state"] = t["state"].astype(np.int32)
        cloud["interface"] = t["interface"].astype(np.int32)
        cloud["gap"] = t["gap"]
        cloud["slip"] = np.linalg.norm(t["slip"], axis=1)
        cloud["u_body1"] = t["u_body1"]
        cloud["u_body2"] = t["u_body2"]
        cloud.save(str(path))

    def _write_pvd(self, path: Path) -> None:
        lines = ['<?xml version="1.0"?>',
                 '<VTKFile type="Collection" version="0.1">', "  <Collection>"]
        lines += [f'    <DataSet timestep="{t:.12g}" file="{f}"/>' for t, f in self.entries]
        lines += ["  </Collection>", "</VTKFile>"]
        path.write_text("\n".join(lines) + "\n")


class SummaryWriter:
    """``summary.json``: run summary, rewritten after every increment.

    Parameters
    ----------
    problem, method
        The problem and the solver's name.
    path
        The JSON file.
    increments
        Number of increments asked for.
    probes
        Named mesh nodes whose displacement is reported, e.g. free-end corners:
        ``{name: (x, y, z)}`` or ``{name: ((x, y, z), cell_tag)}`` to pick one body's node
        where bodies have coincident nodes.
    extra
        Further JSON-serialisable data to include (e.g. the benchmark's parameters).
    """

    def __init__(self, problem, method: str, path: str | os.PathLike, increments: int,
                 probes: dict[str, np.ndarray] | None = None, extra: dict | None = None):
        self.problem = problem
        self.path = Path(path)
        self.t0 = time.perf_counter()
        self.data = {
            "method": method, "increments": int(increments), "converged": False,
            "load_factors": [], "iterations": [], "residual_histories": [],
            "plastic_gauss_points": [], "num_gauss_points": problem.state.num_gauss_points(),
            "num_pairs": problem.num_pairs, "wall_time_s": 0.0, "mpi_ranks": problem.comm.size,
        }
        if extra:
            self.data.update(extra)
        self.probe_names = list(probes or {})
        points, blocks = [], []
        for name in self.probe_names:
            spec = probes[name]
            point, tag = (spec, None) if np.ndim(spec[0]) == 0 else spec
            points.append(np.asarray(point, dtype=float))
            blocks.append(res.node_blocks_at_points(problem, points[-1], cell_tag=tag)[0])
        self.probe_points = np.array(points).reshape(-1, 3)
        self.probe_blocks = np.array(blocks, dtype=np.int64)

    def __call__(self, result) -> None:
        p = self.problem
        d = self.data
        d["load_factors"].append(float(result.load_factor))
        d["iterations"].append(int(result.iterations))
        d["residual_histories"].append(
            [[h.equilibrium, h.contact] for h in result.report.history])
        d["plastic_gauss_points"].append(int(result.plastic_points))
        d["system_order"] = int(result.report.system_order)
        d["wall_time_s"] = time.perf_counter() - self.t0
        d["converged"] = bool(math.isclose(result.load_factor, 1.0))
        eq = res.equilibrium_check(p)
        d["applied_load"] = eq["applied_load"].tolist()
        d["reactions"] = {str(k): v.tolist() for k, v in eq["reactions"].items()}
        if eq["obstacle_forces"]:
            d["obstacle_forces"] = {k: v.tolist() for k, v in eq["obstacle_forces"].items()}
        d["reaction_sum"] = eq["reaction_sum"].tolist()
        d["equilibrium_residual"] = eq["global_imbalance"]
        d["free_dof_residual"] = eq["residual_norm"]
        if len(self.probe_blocks):
            u = res.values_at_blocks(p, self.probe_blocks)
            d["probes"] = [{"name": n, "position": x.tolist(), "u": ui.tolist()}
                           for n, x, ui in zip(self.probe_names, self.probe_points, u)]
        if p.has_contact:
            t = res.pair_table(p)
            d["pairs"] = [
                {"position": t["position"][i].tolist(), "state": str(t["state_name"][i]),
                 "force_on_body1": t["force_on_body1"][i].tolist(),
                 "force_local_body1": t["force_local_body1"][i].tolist(),
                 "u_body1": t["u_body1"][i].tolist(), "u_body2": t["u_body2"][i].tolist(),
                 "gap": float(t["gap"][i]), "interface": str(t["interface_name"][i])}
                for i in range(len(t["state"]))]
        if p.comm.rank == 0:
            tmp = self.path.with_suffix(".json.tmp")
            tmp.write_text(json.dumps(d, indent=1))
            os.replace(tmp, self.path)  # atomic: a crash never leaves half a file


class ResultsWriter:
    """All writers of a run in one folder: fields.xdmf, pairs (when there is contact), summary.json."""

    def __init__(self, problem, method: str, folder: str | os.PathLike, increments: int,
                 probes: dict[str, np.ndarray] | None = None, extra: dict | None = None,
                 fields: bool = True):
        self.folder = Path(folder)
        if problem.comm.rank == 0:
            self.folder.mkdir(parents=True, exist_ok=True)
        problem.comm.Barrier()
        self.writers = []
        if fields:
            self.writers.append(FieldWriter(problem, self.folder / "fields.xdmf"))
        if problem.has_contact:
            self.writers.append(PairWriter(problem, self.folder))
        self.summary = SummaryWriter(problem, method, self.folder / "summary.json", increments, probes, extra)
        self.writers.append(self.summary)

    def __call__(self, result) -> None:
        for w in self.writers:
            w(result)

    def close(self) -> None:
        for w in self.writers:
            if hasattr(w, "close"):
                w.close()

