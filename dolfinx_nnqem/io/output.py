"""Writers: what a converged increment leaves on disk.

Each writer is a callable taking an :class:`~dolfinx_nnqem.solvers.stepping.IncrementResult`; pass them
as ``callbacks`` to :func:`~dolfinx_nnqem.solvers.stepping.solve_load_steps`. Files are (re)written
after every increment, so a run that dies at increment k leaves increments 1..k readable.

- ``fields.xdmf`` + ``fields/fields_XXXX.xdmf|h5``: one time series (time = load factor) with
  the displacement ``u`` (P1), and per cell the von Mises stress ``von_mises``, the equivalent
  plastic strain ``p``, the fraction of Gauss points that yielded in the increment
  ``plastic`` and f/σ_y ``yield_function`` (cell means of the Gauss-point values); one closed file per increment and an
  atomically replaced index (:mod:`dolfinx_nnqem.io.field_series`: survives a kill).
- ``fields_p2.pvd`` + ``fields/u_p2_XXXX*.pvtu``/``.vtu`` (degree 2): the quadratic displacement at
  its own nodes, on VTK Lagrange cells (:mod:`dolfinx_nnqem.io.quadratic_fields`).
- ``pairs.pvd`` + ``pairs/pairs_XXXX.vtp``: the contact pairs as a point cloud with p_n,
  friction force, state, gap and slip (ParaView).
- ``pairs/pairs_XXXX.csv``: the pair table of each increment (with its load factor).
- ``summary.json``: the run summary (schema in ``docs/outputs.md``).

Every file is written to a temporary name and renamed (:mod:`dolfinx_nnqem.io.safe_io`): a kill or
a full disk never leaves a truncated file under a real name, and ``pairs.pvd`` only lists
complete files. :class:`ResultsWriter` holds the folder's lock (:mod:`dolfinx_nnqem.io.locking`)
for the run and starts by clearing an earlier run's outputs (unless it resumes from a
checkpoint, or ``overwrite=False`` makes it refuse a used folder).
"""

from __future__ import annotations

import csv
import json
import math
import os
import time
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

import dolfinx_nnqem.io.results as res
from dolfinx_nnqem import interrupts
from dolfinx_nnqem.collective import on_rank0
from dolfinx_nnqem.contact.laws import STATE_NAMES
from dolfinx_nnqem.io.deformed_fields import writes_deformed_mesh
from dolfinx_nnqem.io.field_series import CellField, FieldSeriesWriter
from dolfinx_nnqem.io.locking import OutputLock, clear_outputs, previous_outputs
from dolfinx_nnqem.io.obstacle_shapes import obstacle_records
from dolfinx_nnqem.io.quadratic_fields import QuadraticFieldWriter, writes_quadratic_fields
from dolfinx_nnqem.io.run_pictures import (ALL_PICTURES, PictureDrawer, draw_live_pictures, missing_pictures,
                                          pictures_enabled)
from dolfinx_nnqem.io.safe_io import StagedFiles, atomic_write, atomic_write_text, commit, remove_stale_temporaries
from dolfinx_nnqem.io.vtk_xml import point_cloud_text
from dolfinx_nnqem.material.kinematics import von_mises_stress
from dolfinx_nnqem.problem.validation import check_output_folder
from dolfinx_nnqem.solvers.convergence import ConvergenceError

Probe = Sequence[float] | tuple[Sequence[float], int]
"""A probed node: its position (x, y, z), or ((x, y, z), cell_tag) to pick one body's node."""


def von_mises(sigma: np.ndarray) -> np.ndarray:
    """Deprecated (removed in 0.2): :func:`dolfinx_nnqem.material.von_mises_stress`."""
    warnings.warn("dolfinx_nnqem.io.output.von_mises is deprecated and will be removed in 0.2; use "
                  "dolfinx_nnqem.material.von_mises_stress", DeprecationWarning, stacklevel=2)
    return von_mises_stress(sigma)


class PairWriter:
    """Pair point cloud (VTK .vtp per increment + .pvd collection) and a CSV table per increment.

    ``staged``: stage ``pairs.pvd`` there (renamed at the run's commit point, which also makes the
    increment's files durable) instead of writing every file durably at once.
    """

    def __init__(self, problem, folder: str | os.PathLike, staged: StagedFiles | None = None):
        self.problem = problem
        self.folder = Path(folder)
        self.staged = staged
        self.rank = problem.comm.rank
        self.entries: list[tuple[float, str]] = []
        if self.rank == 0:
            (self.folder / "pairs").mkdir(parents=True, exist_ok=True)

    def __call__(self, result, table: dict | None = None) -> None:
        """Write the increment's pair files; ``table``: its :func:`~dolfinx_nnqem.io.results.pair_table`
        if the caller has it (made here otherwise: collective)."""
        if table is None:
            table = res.pair_table(self.problem)
        on_rank0(self.problem.comm, self._write, result, table)

    def _write(self, result, table) -> None:
        name = f"pairs_{result.index:04d}"
        t = float(result.load_factor)
        durable = self.staged is None  # else the commit point's sync makes them durable
        atomic_write(self.folder / "pairs" / f"{name}.csv", lambda tmp: self._write_csv(tmp, table, t),
                     durable=durable)
        atomic_write(self.folder / "pairs" / f"{name}.vtp", lambda tmp: self._write_vtp(tmp, table, t),
                     durable=durable)
        self.entries = [e for e in self.entries if e[1] != f"pairs/{name}.vtp"] + [(t, f"pairs/{name}.vtp")]
        self._write_pvd(self.folder / "pairs.pvd", at_once=durable)  # only after the .vtp is complete

    def state(self) -> dict:
        """What a restart needs (:meth:`resume`): the pair files written, as [load factor, path] pairs."""
        return {"entries": [list(e) for e in self.entries]}

    def resume(self, state: dict) -> None:
        """Continue from a checkpoint: its entries; later increments' files are removed."""
        self.entries = [(float(t), str(f)) for t, f in state.get("entries", [])]
        keep = {Path(f).stem for _, f in self.entries}

        def tidy():
            for f in (self.folder / "pairs").glob("pairs_*.*"):
                if f.stem not in keep:
                    f.unlink()
            self._write_pvd(self.folder / "pairs.pvd", at_once=True)  # now: later files are gone

        on_rank0(self.problem.comm, tidy)

    @staticmethod
    def _write_csv(path: Path, t: dict, load_factor: float = float("nan")) -> None:
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["pair", "interface", "x", "y", "z", "state", "p_n_on_body1", "t1_on_body1", "t2_on_body1",
                        "Fx_on_body1", "Fy_on_body1", "Fz_on_body1", "gap", "slip1", "slip2",
                        "u1x", "u1y", "u1z", "u2x", "u2y", "u2z", "area", "pressure", "weighted_gap",
                        "slave_x", "slave_y", "slave_z", "load_factor"])
            for i in range(len(t["state"])):
                w.writerow([i, t["interface_name"][i], *t["position"][i], STATE_NAMES[t["state"][i]],
                            *t["force_local_body1"][i], *t["force_on_body1"][i], t["gap"][i], *t["slip"][i],
                            *t["u_body1"][i], *t["u_body2"][i], t["area"][i], t["pressure"][i],
                            t["weighted_gap"][i], *t["position_b"][i], repr(load_factor)])

    @staticmethod
    def _write_vtp(path: Path, t: dict, load_factor: float = float("nan")) -> None:
        local = t["force_local_body1"]
        arrays = {
            "p_n": -local[:, 0],  # compression on body 2, N
            "friction_on_body2": -t["force_on_body1"] - (-local[:, 0])[:, None] * t["frame"][:, 0, :],
            "force_on_body1": t["force_on_body1"],
            "state": t["state"].astype(np.int32),
            "interface": t["interface"].astype(np.int32),
            "gap": t["gap"],
            "pressure": t["pressure"],  # p_n / tributary area, Pa
            "weighted_gap": t["weighted_gap"],
            "area": t["area"],
            "slip": np.linalg.norm(t["slip"], axis=1),
            "u_body1": t["u_body1"],
            "u_body2": t["u_body2"],
        }
        text = point_cloud_text(t["position"], {k: np.asarray(v, dtype=np.int32 if v.dtype == np.int32 else np.float64)
                                                for k, v in arrays.items()},
                                {"load_factor": np.array([load_factor])})
        with open(path, "w", encoding="ascii") as fh:  # a full disk raises OSError, named by atomic_write
            fh.write(text)

    def _write_pvd(self, path: Path, at_once: bool) -> None:
        lines = ['<?xml version="1.0"?>',
                 '<VTKFile type="Collection" version="0.1">', "  <Collection>"]
        lines += [f'    <DataSet timestep="{t:.12g}" file="{f}"/>' for t, f in self.entries]
        lines += ["  </Collection>", "</VTKFile>"]
        if at_once or self.staged is None:
            atomic_write_text(path, "\n".join(lines) + "\n")
        else:
            self.staged.stage(path, "\n".join(lines) + "\n")


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
    staged
        Stage each increment's summary there (renamed at the run's commit point) instead of
        replacing it durably at once.
    """

    def __init__(self, problem, method: str, path: str | os.PathLike, increments: int,
                 probes: Mapping[str, Probe] | None = None, extra: dict | None = None,
                 staged: StagedFiles | None = None):
        self.problem = problem
        self.path = Path(path)
        self.staged = staged
        self.size = 0  #: bytes of the last summary text
        self.t0 = time.perf_counter()
        self.data = {
            "method": method, "increments": int(increments) if isinstance(increments, int) else "auto", "converged": False, "status": "running",
            "load_factors": [], "iterations": [], "residual_histories": [], "checks": [],
            "plastic_gauss_points": [], "num_gauss_points": problem.state.num_gauss_points(),
            "num_pairs": problem.num_pairs, "wall_time_s": 0.0, "mpi_ranks": problem.comm.size,
            "kinematics": getattr(problem, "kinematics", "small"),
        }
        if extra:
            self.data.update(extra)
        probes = probes or {}
        self.probe_names = list(probes)
        points, blocks = [], []
        for name in self.probe_names:
            spec = probes[name]
            point, tag = (spec, None) if np.ndim(spec[0]) == 0 else spec
            points.append(np.asarray(point, dtype=float))
            blocks.append(res.node_blocks_at_points(problem, points[-1], cell_tag=None if tag is None else int(tag))[0])
        self.probe_points = np.array(points).reshape(-1, 3)
        self.probe_blocks = np.array(blocks, dtype=np.int64)

    def __call__(self, result, table: dict | None = None) -> None:
        """Add the increment to the summary and write it; ``table``: the increment's
        :func:`~dolfinx_nnqem.io.results.pair_table` if the caller has it (made here otherwise)."""
        p = self.problem
        d = self.data
        d["load_factors"].append(float(result.load_factor))
        d["iterations"].append(int(result.iterations))
        d["residual_histories"].append(
            [[h.equilibrium, h.contact] for h in result.report.history])
        d["plastic_gauss_points"].append(int(result.plastic_points))
        d["materials"] = p.state.maxima_by_body()  # per body: the largest p and f/σ_y
        d["system_order"] = int(result.report.system_order)
        d["wall_time_s"] = time.perf_counter() - self.t0
        d["converged"] = bool(math.isclose(result.load_factor, 1.0))
        d["status"] = "completed" if d["converged"] else "running"
        if result.check is not None:
            c = result.check
            d["checks"].append({"equilibrium": c.equilibrium, "contact": c.contact, "coulomb": c.coulomb,
                                "max_strain": c.max_strain, "max_rotation": c.max_rotation,
                                "force_scale": c.force_scale, "tolerance": c.tolerance,
                                "own_stresses": c.own_stresses})
            if not math.isnan(c.min_shape_ratio):  # finite strain: the deformed mesh's smallest
                d["checks"][-1]["min_shape_ratio"] = c.min_shape_ratio
        eq = res.equilibrium_check(p)
        d["applied_load"] = eq["applied_load"].tolist()
        d["reactions"] = {str(k): v.tolist() for k, v in eq["reactions"].items()}
        # per increment, for the load curve (run_pictures): the reactions and the probes' displacements
        d.setdefault("reaction_history", []).append(d["reactions"])
        if eq["obstacle_forces"]:
            d["obstacle_forces"] = {k: v.tolist() for k, v in eq["obstacle_forces"].items()}
            d.setdefault("obstacle_force_history", []).append(d["obstacle_forces"])
            d["obstacles"] = obstacle_records(p, result.load_factor)  # where the pictures draw them
        d["reaction_sum"] = eq["reaction_sum"].tolist()
        d["equilibrium_residual"] = eq["global_imbalance"]
        d["free_dof_residual"] = eq["residual_norm"]
        if len(self.probe_blocks):
            u = res.values_at_blocks(p, self.probe_blocks)
            d["probes"] = [{"name": n, "position": x.tolist(), "u": ui.tolist()}
                           for n, x, ui in zip(self.probe_names, self.probe_points, u)]
            d.setdefault("probe_history", []).append([ui.tolist() for ui in u])
        if p.has_contact:
            model = p.contact
            # where each interface's pairs come from now ("auto" moves one to "current" once it slides)
            d["contact_geometry"] = {i.contact.label: "current" if following else "reference"
                                     for i, following in zip(model.interfaces, model.geometry.following)}
            t = res.pair_table(p) if table is None else table
            d["pairs"] = [
                {"position": t["position"][i].tolist(), "state": str(t["state_name"][i]),
                 "force_on_body1": t["force_on_body1"][i].tolist(),
                 "force_local_body1": t["force_local_body1"][i].tolist(),
                 "u_body1": t["u_body1"][i].tolist(), "u_body2": t["u_body2"][i].tolist(),
                 "gap": float(t["gap"][i]), "pressure": float(t["pressure"][i]),
                 "weighted_gap": float(t["weighted_gap"][i]), "area": float(t["area"][i]),
                 "interface": str(t["interface_name"][i])}
                for i in range(len(t["state"]))]
        self.write(at_once=self.staged is None)

    def write(self, at_once: bool = True) -> None:
        """Write the summary (rank 0; atomic: a crash never leaves half a file; collective);
        unless ``at_once``, stage it for the commit point."""
        def write():
            text = summary_json(self.data)
            self.size = len(text)
            if at_once or self.staged is None:
                atomic_write_text(self.path, text)
            else:
                self.staged.stage(self.path, text)

        on_rank0(self.problem.comm, write)

    def failed(self, failure: dict) -> None:
        """Record the increment that did not converge (from :func:`solve_load_steps`)."""
        self.data["converged"] = False
        self.data["status"] = "not converged"
        self.data["failure"] = failure
        self.data["wall_time_s"] = time.perf_counter() - self.t0
        self.write()

    def ended(self, status: str, message: str = "") -> None:
        """Record how the run ended when it did not complete ("interrupted", "error"), without
        waiting for the other ranks. An interrupt replaces "completed" and "not converged" too
        (it came while the run closed or drew its pictures: the command line exits 130 or 143,
        and the status says why; ``converged`` and ``failure`` stay); an error does not."""
        if self.data.get("status") in ("completed", "not converged") and status != "interrupted":
            return
        self.data["status"] = status
        if message:
            self.data["error"] = message
        self.data["wall_time_s"] = time.perf_counter() - self.t0
        # NOT collective: the other ranks may be stuck in a collective call (an error or a
        # signal seen by some ranks only), so every rank that gets here writes the same data
        # (each through its own temporary file and an atomic rename); a failure to write is
        # ignored: the run is ending on an error already (e.g. a full disk), keep that one
        try:
            atomic_write_text(self.path, summary_json(self.data))
        except OSError:
            pass

    def state(self) -> dict:
        """The summary's data for a checkpoint: the data itself, not a copy (the checkpoint encodes
        it at once; a copy cost every increment as much as encoding it)."""
        return {"data": self.data}

    def resume(self, state: dict) -> None:
        """Continue from a checkpoint's summary: "running", or "completed" when the checkpoint is
        of the last increment (nothing is left to solve)."""
        data = dict(state.get("data", {}))
        data.pop("failure", None)
        data["status"] = "completed" if data.get("converged") else "running"
        self.data.update(data)
        self.t0 -= float(data.get("wall_time_s", 0.0))


def summary_json(data: dict) -> str:
    """``data`` as strict JSON text, one top-level key per line: a value that is not a finite
    number (NaN, ±inf: e.g. a residual of a diverged iterate) is written as ``null``, and
    ``non_finite`` lists each such key with the value it had (JSON has no NaN: ``json.dumps``
    would write a bare ``NaN``, which strict readers refuse)."""
    try:  # the usual case, plain finite data: the json module's C encoder (it has no indentation)
        values = {str(k): json.dumps(v, allow_nan=False) for k, v in data.items() if k != "non_finite"}
    except (TypeError, ValueError):  # numpy values, or a number that is not finite: cleaned first
        non_finite: dict[str, str] = {}
        clean = _jsonable({k: v for k, v in data.items() if k != "non_finite"}, "", non_finite)
        if non_finite:
            clean["non_finite"] = non_finite
        values = {k: json.dumps(v, allow_nan=False) for k, v in clean.items()}
    return "{\n" + ",\n".join(f" {json.dumps(k)}: {v}" for k, v in values.items()) + "\n}"


def jsonable_copy(value: object) -> Any:
    """A JSON-ready deep copy of ``value`` (numpy values as Python ones, non-finite floats as
    None), through the C encoder when it can (a checkpoint saves the writers' state every
    increment)."""
    try:
        return json.loads(json.dumps(value, allow_nan=False))
    except (TypeError, ValueError):
        return _jsonable(value)


def _jsonable(value, path: str = "", non_finite: dict | None = None):
    """``value`` with numpy scalars and arrays turned into Python numbers and lists; a float
    that is not finite becomes None (recorded in ``non_finite`` under its path)."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v, f"{path}.{k}" if path else str(k), non_finite) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_jsonable(v, f"{path}[{i}]", non_finite) for i, v in enumerate(value)]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        if non_finite is not None:
            non_finite[path] = repr(value)
        return None
    return value


class ResultsWriter:
    """All writers of a run in one folder: fields.xdmf, pairs (when there is contact), summary.json.

    Each increment has one durable commit point (:func:`~dolfinx_nnqem.io.safe_io.commit`): the
    writers write the increment's new files and stage the index files that list them
    (``fields.xdmf``, ``pairs.pvd``, ``summary.json``); one sync of the file system, and the
    staged files are renamed into place. When a :class:`~dolfinx_nnqem.io.checkpoint.Checkpointer`
    of this writer saves at the increment, its files join the same commit point.

    Parameters
    ----------
    overwrite
        What to do with a folder that holds an earlier run's outputs (:func:`locking.previous_outputs`):
        True (default) removes them first, so nothing of the old run stays mixed in; False
        refuses with :class:`FileExistsError`.
    resume
        Continue a checkpointed run in this folder: keep its files (call :meth:`resume` with the
        checkpoint's writer state before the first increment).
    lock
        Hold the folder's lock (:class:`locking.OutputLock`) until :meth:`close`: a second run
        into the same folder refuses to start.
    pictures
        Draw the run's pictures into ``folder/pictures`` at :meth:`close`
        (:mod:`dolfinx_nnqem.io.run_pictures`): after a completed run, and after one that stopped
        at an increment that did not converge (its converged increments). None (default): yes,
        unless the environment sets ``DOLFINX_NNQEM_PICTURES=0``; False: never.
    picture_worker
        :class:`~dolfinx_nnqem.io.picture_worker.PictureWorkers` started with the run (rank 0's;
        None elsewhere) that draw the pictures (the caller owns them and closes them); None:
        the pictures are drawn in this process.
    cell_fields
        Further per-cell fields for ``fields.xdmf`` and the pictures
        (:class:`~dolfinx_nnqem.io.field_series.CellField`, e.g.
        :class:`dolfinx_nnqem.estimates.RecoveryIndicator`).
    deformed_mesh
        Also write ``fields_deformed.xdmf``, the same steps on the mesh moved by u
        (:mod:`dolfinx_nnqem.io.deformed_fields`). None (default): at finite strain only.
    """

    def __init__(self, problem, method: str, folder: str | os.PathLike, increments: int,
                 probes: Mapping[str, Probe] | None = None, extra: dict | None = None,
                 fields: bool = True, *, overwrite: bool = True, resume: bool = False, lock: bool = True,
                 pictures: bool | None = None, picture_worker: PictureDrawer | None = None,
                 cell_fields: Sequence[CellField] = (), deformed_mesh: bool | None = None):

        check_output_folder(folder)
        self.folder = Path(folder)
        self.problem = problem
        self.pictures = pictures
        self.picture_worker = picture_worker
        self.drawn: dict = {}  # what close() drew: picture name -> path, or why it was not drawn
        self.written = 0  #: increments written by this writer (a restart of a completed run: none)
        self._lock = OutputLock(self.folder) if lock else None

        def prepare():
            self.folder.mkdir(parents=True, exist_ok=True)
            if self._lock is not None:
                self._lock.acquire()
            try:
                remove_stale_temporaries(self.folder)
                if not resume:
                    old = previous_outputs(self.folder)
                    if old and not overwrite:
                        raise FileExistsError(17, f"output folder {self.folder} holds an earlier run's results "
                                                  f"({', '.join(p.name for p in old)}); use --overwrite to replace "
                                                  "them, --restart to continue that run, or another folder",
                                              str(self.folder))
                    clear_outputs(self.folder)
            except BaseException:
                if self._lock is not None:
                    self._lock.release()
                raise

        on_rank0(problem.comm, prepare)
        self.staged = StagedFiles()  #: the index files of the increment, renamed at its commit point
        self.checkpoint_every = 0  #: set by a Checkpointer of this writer: it commits those increments
        self.writers: list[FieldSeriesWriter | QuadraticFieldWriter | PairWriter | SummaryWriter] = []
        keep = pictures_enabled(pictures)  # the pictures are drawn from the last fields written, in memory
        self.fields = (FieldSeriesWriter(problem, self.folder, self.staged, keep_last=keep, cell_fields=cell_fields,
                                         deformed_mesh=writes_deformed_mesh(problem, deformed_mesh))
                       if fields else None)
        if self.fields is not None:
            self.writers.append(self.fields)
        # degree 2: the displacement at its own nodes too (fields.xdmf holds the mesh's nodes only)
        quadratic = fields and writes_quadratic_fields(problem)
        self.quadratic = QuadraticFieldWriter(problem, self.folder, keep_last=keep) if quadratic else None
        if self.quadratic is not None:
            self.writers.append(self.quadratic)
        self.pairs = PairWriter(problem, self.folder, self.staged) if problem.has_contact else None
        if self.pairs is not None:
            on_rank0(problem.comm, lambda: (self.folder / "pairs").mkdir(parents=True, exist_ok=True))
            self.writers.append(self.pairs)
        self.summary = SummaryWriter(problem, method, self.folder / "summary.json", increments, probes, extra,
                                     staged=self.staged)
        self.writers.append(self.summary)

    def __call__(self, result) -> None:
        if self.problem.comm.allreduce(bool(self.staged)):  # a checkpoint due at the last one did not come
            self.commit()
        # the pair table (collective) once, for the pair files and the summary
        table = res.pair_table(self.problem) if self.problem.has_contact else None
        for w in self.writers:
            if isinstance(w, (PairWriter, SummaryWriter)):
                w(result, table)
            else:
                w(result)
        if not (self.checkpoint_every and result.index % self.checkpoint_every == 0):
            self.commit()
        self._reserve()
        self.written += 1

    def commit(self) -> None:
        """The increment's commit point (collective): sync, then the staged index files in place."""
        commit(self.problem.comm, self.folder, self.staged)

    def _commit_here(self) -> None:
        """What is staged, committed by this rank alone (the run ends; every rank may not be here)."""
        try:
            self.staged.commit_here(self.folder)
        except OSError:
            self.staged.discard()  # the previous complete index stays in force

    def _reserve(self) -> None:
        """Keep room on disk for the summary's last rewrite (rank 0, which holds the lock): its
        size now plus 64 kB for the failure or error it may add; twice that under MPI, where
        :meth:`SummaryWriter.ended` may write from two ranks at once."""
        if self._lock is not None and self.problem.comm.rank == 0 and self.summary.size:
            copies = 2 if self.problem.comm.size > 1 else 1
            self._lock.reserve(copies * self.summary.size + 65536)

    def _free_reserve(self) -> None:
        if self._lock is not None and self.problem.comm.rank == 0:
            self._lock.free_reserve()

    def failed(self, failure: dict) -> None:
        """The run gave up at an increment: ``summary.json`` says which, and why."""
        self._free_reserve()
        self._commit_here()
        self.summary.failed(failure)

    def ended(self, status: str, message: str = "") -> None:
        """The run stopped otherwise ("interrupted", "error"): ``summary.json`` says so (on a
        full disk too: the space reserved after every increment is given back first)."""
        self._free_reserve()
        self._commit_here()
        self.summary.ended(status, message)

    def record_end(self, error: BaseException) -> None:
        """Record in ``summary.json`` how a run ended on ``error`` (call it from the run's
        ``except``): "interrupted" for Ctrl-C or SIGTERM (also when numba wrapped the interrupt
        in a SystemError), nothing for a :class:`ConvergenceError` (:meth:`failed` recorded it),
        "error" with the message otherwise."""
        seen: set[int] = set()
        cause: BaseException | None = error
        while cause is not None and id(cause) not in seen:
            if isinstance(cause, KeyboardInterrupt):
                self.ended("interrupted")
                return
            seen.add(id(cause))
            cause = cause.__cause__ or cause.__context__
        if interrupts.received:  # an error raised while the command line handled an interrupt
            self.ended("interrupted")
        elif not isinstance(error, ConvergenceError):
            self.ended("error", f"{type(error).__name__}: {error}")

    def state(self) -> dict:
        """The writers' state for a checkpoint (JSON)."""
        return {"fields": self.fields.state() if self.fields else None,
                "quadratic": self.quadratic.state() if self.quadratic else None,
                "pairs": self.pairs.state() if self.pairs else None, "summary": self.summary.state()}

    def resume(self, state: dict) -> None:
        """Continue from a checkpoint's writer state (drops the files of later increments)."""
        if self.fields is not None and state.get("fields"):
            self.fields.resume(state["fields"])
        if self.quadratic is not None:
            self.quadratic.resume(state.get("quadratic") or {})
        if self.pairs is not None and state.get("pairs"):
            self.pairs.resume(state["pairs"])
        self.summary.resume(state["summary"])
        self.summary.write()

    def __enter__(self) -> ResultsWriter:
        return self

    def __exit__(self, kind, error, traceback) -> None:
        """``with ResultsWriter(...) as writer:`` records how a run ended on an exception
        (:meth:`record_end`), then closes (:meth:`close`)."""
        if error is not None:
            self.record_end(error)
        self.close()

    def close(self) -> None:
        """Close the files, draw the pictures (see ``pictures``), release the folder's lock.

        An interrupt meanwhile (Ctrl-C or SIGTERM while the pictures are drawn) is recorded in
        ``summary.json`` ("interrupted") and raised; a picture is written whole or not at all
        (:func:`~dolfinx_nnqem.io.run_pictures.draw_run_pictures`). Then the run's outcome is
        final (:func:`dolfinx_nnqem.interrupts.end_of_run`)."""
        try:
            self._commit_here()  # the last renames made durable too
            for w in self.writers:
                if hasattr(w, "close"):
                    w.close()
            self._draw_pictures()
            if interrupts.received:  # the command line's handler acted, its exception was lost
                self.ended("interrupted")  # (it is raised again: cli._raise_swallowed_interrupt)
        except BaseException as error:
            self.record_end(error)
            raise
        finally:
            interrupts.end_of_run()
            self._release()

    def _draw_pictures(self) -> None:
        """The run's pictures (collective): all of them after a run that wrote increments; only
        the missing ones after a restart of a run that had completed (it wrote none)."""
        status = self.summary.data.get("status")
        # only where every rank agrees on how the run ended (drawing is collective): not after
        # an error or an interrupt, which some ranks may not have seen
        if (not pictures_enabled(self.pictures) or status not in ("completed", "not converged")
                or not self.summary.data.get("load_factors")):
            return
        names = ALL_PICTURES if self.written else self.problem.comm.bcast(
            missing_pictures(self.folder) if self.problem.comm.rank == 0 else None, root=0)
        if not names:
            return
        self.drawn = draw_live_pictures(self.problem, self.folder, completed=status == "completed",
                                        step=self._last_field_step(), worker=self.picture_worker, names=names)

    def _last_field_step(self) -> dict | None:
        """Collective: on rank 0 the fields of the last increment written, as a picture step
        (:func:`~dolfinx_nnqem.io.live_fields.gather_field_step`); None elsewhere, and where this
        process wrote none (no fields, or a restart that converged no further increment: the
        pictures then read ``fields.xdmf``). A degree-2 run gives its quadratic displacement
        on its Lagrange cells, as ``fields_p2.pvd`` holds it."""
        if self.fields is None or self.fields.last_written is None:  # the same on every rank
            return None
        from dolfinx_nnqem.io.live_fields import gather_field_step

        t, space, values = self.fields.last_written
        whole = False
        if self.quadratic is not None and self.quadratic.last_written is not None:
            t, values = self.quadratic.last_written
            space, whole = self.problem.V, True
        return gather_field_step(space, values, self.fields.cell_means(), t, whole_cells=whole)

    def _release(self) -> None:
        if self._lock is not None and self.problem.comm.rank == 0:
            self._lock.release()

