"""Field output that survives a kill: one closed XDMF/HDF5 file per increment, an atomic index.

Measured on this package's stacks (``docs/reliability.md``): a run SIGKILLed while it appends
time steps to ONE ``XDMFFile`` leaves an HDF5 file that no reader opens ("bad object header
version number": HDF5 keeps its metadata in memory until the file is closed), although the
``.xdmf`` lists every step; VTX (ADIOS2 BP4) keeps every completed step readable. This writer
keeps XDMF (ParaView and plain h5py read it; no ADIOS2 Python module is needed) and makes it
crash-safe:

* increment k is written, with the mesh, into ``fields/fields_k.xdmf`` + ``.h5`` by DOLFINx's
  ``XDMFFile`` and the file is closed (HDF5 flushes everything) before anything refers to it;
* then rank 0 replaces ``fields.xdmf`` atomically (temporary file + rename): a temporal
  collection of every completed increment, each grid pointing into its own file. Given the
  run's :class:`~dolfinx_nnqem.io.safe_io.StagedFiles`, the new index is staged instead and
  renamed at the increment's commit point, after the sync that makes the step file durable.

So ``fields.xdmf`` always lists complete, readable increments only; a step file of an increment
the index does not list yet is ignored and overwritten by a later run or restart. Each step
file holds the mesh again (its geometry and topology): the price of independent files.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

import dolfinx.fem as fem
import numpy as np
from dolfinx.io import XDMFFile

from dolfinx_nnqem import compat
from dolfinx_nnqem.collective import on_rank0
from dolfinx_nnqem.io.deformed_fields import DEFORMED_INDEX, deformed_geometry, write_deformed_geometry
from dolfinx_nnqem.io.memory_steps import copy_step_files, memory_folder, remove_memory_folder
from dolfinx_nnqem.io.safe_io import OutputError, StagedFiles, atomic_write_text
from dolfinx_nnqem.io.xdmf_steps import child, data_path, read_field_index
from dolfinx_nnqem.material.kinematics import von_mises_stress

__all__ = ["CellField", "CellMeans", "FieldSeriesWriter", "read_field_index"]

INDEX = "fields.xdmf"
FOLDER = "fields"


def _step_name(index: int) -> str:
    return f"fields_{index:04d}"


class CellMeans:
    """Cell means of the Gauss-point state, as piecewise-constant fields for the output files:
    the von Mises stress ``von_mises``, the equivalent plastic strain ``p``, the fraction of
    the cell's Gauss points that yielded in the last increment ``plastic`` and the yield
    function's value over the yield stress ``yield_function`` (f/σ_y: 0 on the yield surface,
    −1 where the material cannot yield); with a material that has back-stresses, also the
    equivalent back-stress ``back_stress`` (q(α) = √(3/2)|α|, α = Σ_k α_k). At finite strain
    (``kinematics = "finite"``) the stresses are Cauchy's, and the cell mean of the Cauchy stress tensor
    ``cauchy_stress`` is written too (:attr:`tensors`; a field of the reference mesh, like u;
    ``fields_deformed.xdmf`` shows it on the deformed mesh x = X + u, :mod:`dolfinx_nnqem.io.deformed_fields`)."""

    def __init__(self, problem):
        self.problem = problem
        self.Q0 = problem.state.Q0  # the state's DG 0 space of the mesh (one per problem, not per writer)
        self.q = fem.Function(self.Q0, name="von_mises")
        self.p = fem.Function(self.Q0, name="p")
        self.plastic = fem.Function(self.Q0, name="plastic")
        self.yield_function = fem.Function(self.Q0, name="yield_function")
        self.back_stress = (fem.Function(self.Q0, name="back_stress")
                            if problem.state.back_stress_values() is not None else None)
        self.cauchy = (fem.Function(fem.functionspace(problem.mesh, ("DG", 0, (3, 3))), name="cauchy_stress")
                       if getattr(problem, "kinematics", "small") == "finite" else None)

    @property
    def tensors(self) -> tuple[fem.Function, ...]:
        """The DG 0 tensor fields written besides :attr:`fields`: ``cauchy_stress`` at finite strain."""
        return () if self.cauchy is None else (self.cauchy,)

    @property
    def fields(self) -> tuple[fem.Function, ...]:
        """The DG 0 functions written: von_mises (q), p, plastic, yield_function, and back_stress where a
        material has back-stresses."""
        if self.back_stress is not None:
            return self.q, self.p, self.plastic, self.yield_function, self.back_stress
        return self.q, self.p, self.plastic, self.yield_function

    def update(self) -> None:
        """The means of the last converged state (owned and ghost cells)."""
        state = self.problem.state
        tdim = self.problem.mesh.topology.dim
        imap = self.problem.mesh.topology.index_map(tdim)
        cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
        qdofs = state.W_scalar.dofmap.list[cells]  # (ncells, points per cell)
        dg = self.Q0.dofmap.list[cells, 0]
        sigma = state.sigma_n.x.array.reshape(-1, 3, 3)
        self.q.x.array[dg] = von_mises_stress(sigma[qdofs]).mean(axis=1)
        self.p.x.array[dg] = state.p_n.x.array[qdofs].mean(axis=1)
        self.plastic.x.array[dg] = (state.dp_n.x.array[qdofs] > 0).mean(axis=1)
        self.yield_function.x.array[dg] = state.yield_function_values()[qdofs].mean(axis=1)
        back_stress = state.back_stress_values()
        if self.back_stress is not None and back_stress is not None:
            self.back_stress.x.array[dg] = back_stress[qdofs].mean(axis=1)
        if self.cauchy is not None:
            self.cauchy.x.array.reshape(-1, 9)[dg] = sigma[qdofs].mean(axis=1).reshape(-1, 9)


class CellField(Protocol):
    """A per-cell field the writer adds to each step: a DG0 ``function`` refreshed by ``update()``
    (collective) from the converged state."""

    function: fem.Function

    def update(self) -> None:
        """Refresh ``function`` from the converged state (collective)."""
        ...


class FieldSeriesWriter:
    """The displacement and cell means of the Gauss-point state, one file per increment.

    Parameters
    ----------
    problem
        The :class:`~dolfinx_nnqem.problem.contact_problem.ContactProblem`.
    folder
        The run's output folder: writes ``fields.xdmf`` and ``fields/``.
    staged
        Stage the index here (renamed at the run's commit point, :func:`~dolfinx_nnqem.io.safe_io.commit`)
        instead of replacing it durably at once.
    keep_last
        Keep the displacement values of the last increment written (:attr:`last_written`): the
        run's pictures are drawn from them, not read back from the file.
    cell_fields
        Further per-cell fields written with the cell means (:class:`CellField`: e.g. the error
        indicator of :mod:`dolfinx_nnqem.estimates.indicators`), updated before each increment is
        written.
    deformed_mesh
        Also write each step's mesh moved by u and the index ``fields_deformed.xdmf`` of the
        steps on it (:mod:`dolfinx_nnqem.io.deformed_fields`).
    """

    def __init__(self, problem, folder: str | os.PathLike, staged: StagedFiles | None = None, *,
                 keep_last: bool = False, cell_fields: Sequence[CellField] = (), deformed_mesh: bool = False):
        self.problem = problem
        self.deformed_mesh = deformed_mesh
        self.cell_fields = list(cell_fields)
        self.keep_last = keep_last
        self.last_written: tuple[float, fem.FunctionSpace, np.ndarray] | None = None
        """(load factor, space, local values) of the displacement last written, with ``keep_last``."""
        self.folder = Path(folder)
        self.staged = staged
        self._grids: dict[tuple[int, float], str] = {}  # a step's grid as index text, read once from its file
        self._deformed_grids: dict[tuple[int, float], str] = {}  # the same on the deformed mesh
        self.comm = problem.mesh.comm
        self.steps: list[tuple[int, float]] = []  # (increment, load factor) in the index
        self._means = CellMeans(problem)
        mesh = problem.mesh
        # XDMF stores fields of the mesh's geometry degree: a quadratic displacement on a first-order
        # mesh is written at the vertices (interpolated to P1; io/quadratic_fields.py writes it whole)
        degree = compat.coordinate_element(mesh).degree
        if problem.V.ufl_element().embedded_superdegree != degree:
            self.u_out = fem.Function(fem.functionspace(mesh, ("Lagrange", degree, (3,))), name="u")
        else:
            self.u_out = None
        on_rank0(self.comm, lambda: (self.folder / FOLDER).mkdir(parents=True, exist_ok=True))

    def __call__(self, result) -> None:
        self._means.update()
        for extra in self.cell_fields:
            extra.update()
        t = float(result.load_factor)
        u = self.problem.u
        if self.u_out is not None:
            self.u_out.interpolate(u)
            u = self.u_out
        name = _step_name(result.index)
        path = self.folder / FOLDER / f"{name}.xdmf"
        # HDF5 must not meet a full disk: after a failed collective write it can neither close
        # the file nor be left to close it at exit (see _write_step), so a disk without room
        # for the step file is refused here, with the figures
        needed = self._bytes_needed()
        on_rank0(self.comm, check_free_space, path.with_suffix(".h5"), needed)
        functions = [u, *self._means.fields, *self._means.tensors, *(f.function for f in self.cell_fields)]
        moved_by = u if self.deformed_mesh else None
        memory = memory_folder(self.comm.size, needed)
        if memory is None:
            self._write_step(path, functions, t, moved_by)
        else:  # written in memory, then copied whole (io/memory_steps.py: the XML's rewrites)
            try:
                self._write_step(memory / path.name, functions, t, moved_by, named=path)
                copy_step_files(memory / path.name, path)
            finally:
                remove_memory_folder(memory)
        if self.keep_last:  # a copy: problem.u moves on in the next increment
            self.last_written = (t, u.function_space, u.x.array.copy())
        self.steps = [s for s in self.steps if s[0] < result.index] + [(result.index, t)]
        self._grids.pop((result.index, t), None)  # a step file written again (after a restart)
        self._deformed_grids.pop((result.index, t), None)
        on_rank0(self.comm, self._write_index)

    def cell_means(self) -> dict[str, fem.Function]:
        """The cell fields as last written, by name (``von_mises``, ``p``, ``plastic``, ``yield_function``, and
        the writer's extra ``cell_fields``, e.g. ``error_indicator``)."""
        return {f.name: f for f in (*self._means.fields, *(extra.function for extra in self.cell_fields))}

    def _bytes_needed(self) -> int:
        """Room a step file needs: 1.25 × the last one's size (every step holds the same
        arrays), or before the first one its arrays' size, plus 64 kB for HDF5's metadata."""
        last = self.folder / FOLDER / f"{_step_name(self.steps[-1][0])}.h5" if self.steps else None
        if self.comm.rank == 0 and last is not None and last.is_file():
            size = last.stat().st_size
        else:
            mesh = self.problem.mesh
            nodes = mesh.geometry.index_map().size_global
            cells = mesh.topology.index_map(mesh.topology.dim).size_global
            # geometry and u (nodes × 3 doubles, and the deformed geometry), topology (int64 per
            # cell node), three cell fields
            size = 8 * ((9 if self.deformed_mesh else 6) * nodes + cells * (compat.geometry_dofmap(mesh).shape[1] + 3))
        return int(1.25 * size) + 65536

    def _write_step(self, path: Path, functions: list, t: float, moved_by: fem.Function | None = None,
                    named: Path | None = None) -> None:
        """One closed XDMF/HDF5 step file; a failed write raises OutputError naming the .h5 (of
        ``named``, the step file's place in the output folder, if ``path`` is a copy's source).
        With ``moved_by``, the mesh's geometry moved by it too (the grid ``deformed``).

        DOLFINx leaves the dataset of a failed write open, so on MPI the file can no longer be
        closed (H5Fclose fails; the next attempt, in XDMFFile's destructor, throws from a C++
        destructor: std::terminate, SIGABRT, no message) and HDF5's own clean-up at exit hangs
        in a collective close. Such a file is kept alive (its destructor never runs) and
        :func:`hdf5_left_open` tells the command line to end the job itself.
        """
        xdmf = XDMFFile(self.comm, str(path), "w")
        try:
            xdmf.write_mesh(self.problem.mesh)
            for f in functions:
                xdmf.write_function(f, t)
            if moved_by is not None:
                write_deformed_geometry(xdmf, moved_by)
            xdmf.close()
        except RuntimeError as error:  # HDF5 reports a full disk as a RuntimeError
            _abandon(xdmf, self.comm)
            named = path if named is None else named
            raise OutputError(28, f"cannot write {named.with_suffix('.h5')}: {error}", str(named)) from error

    def _write_index(self, at_once: bool = False) -> None:
        """The index of the steps (rank 0): staged, or with ``at_once`` (or no staging) replaced now.

        Each step's grid is parsed from its step file and serialised once (:func:`_grid_text`);
        the index is their concatenation (re-serialising every grid at every increment made the
        index cost grow with the number of increments). With ``deformed_mesh``, the index of the
        steps on the deformed mesh (``fields_deformed.xdmf``) likewise."""
        indices = [(INDEX, self._grids, False)]
        if self.deformed_mesh:
            indices.append((DEFORMED_INDEX, self._deformed_grids, True))
        for name, cache, deformed in indices:
            grids = []
            for index, t in self.steps:
                if (index, t) not in cache:
                    step_file = self.folder / FOLDER / f"{_step_name(index)}.xdmf"
                    cache[(index, t)] = _grid_text(_step_grid(step_file, t, deformed))
                grids.append(cache[(index, t)])
            text = _INDEX_HEAD + "".join(grids) + _INDEX_TAIL
            if self.staged is None or at_once:
                atomic_write_text(self.folder / name, text)
            else:
                self.staged.stage(self.folder / name, text)

    # -- restart -------------------------------------------------------------------------------------
    def state(self) -> dict:
        """What a restart needs (:meth:`resume`): the steps written, as [index, load factor] pairs."""
        return {"steps": [list(s) for s in self.steps]}

    def resume(self, state: dict) -> None:
        """Continue a run from a checkpoint: keep the steps it had written, drop later ones."""
        self.steps = [(int(i), float(t)) for i, t in state.get("steps", [])]
        last = self.steps[-1][0] if self.steps else 0

        def tidy():
            for f in (self.folder / FOLDER).glob("fields_*.*"):
                try:
                    if int(f.stem.split("_")[1]) > last:
                        f.unlink()
                except (ValueError, IndexError):
                    pass
            self._write_index(at_once=True)  # now: the files of later steps are gone

        on_rank0(self.comm, tidy)

    def close(self) -> None:
        """Nothing to close: each step's files are written and closed with that step."""
        pass


_LEFT_OPEN: list = []
"""XDMF files whose HDF5 file could not be closed after a failed write (kept alive on purpose)."""


def hdf5_left_open() -> bool:
    """True after a failed field write left an HDF5 file that cannot be closed: the process must
    end without HDF5's clean-up (``cli.main`` aborts the job with its exit code)."""
    return bool(_LEFT_OPEN)


def _abandon(xdmf, comm) -> None:
    """After a failed write: close ``xdmf`` if HDF5 still can, else keep it open for good."""
    if comm.size == 1:  # no collective state to break: the serial driver closes it
        try:
            xdmf.close()
            return
        except RuntimeError:
            pass
    import ctypes

    _LEFT_OPEN.append(xdmf)
    ctypes.pythonapi.Py_IncRef(ctypes.py_object(xdmf))  # not even interpreter shutdown destroys it


def check_free_space(path: Path, needed: int) -> None:
    """Refuse to write ``path`` (OutputError, ENOSPC) when its file system has less than
    ``needed`` bytes free for this user."""
    try:
        st = os.statvfs(path.parent)
    except OSError:
        return  # cannot tell: the write itself will say
    free = st.f_bavail * st.f_frsize
    if free < needed:
        raise OutputError(28, f"cannot write {path}: No space left on device ({free / 1024:.0f} kB free, the "
                              f"step file needs about {needed / 1024:.0f} kB)", str(path))


_INDEX_HEAD = ('<?xml version="1.0"?>\n<Xdmf Version="3.0" xmlns:xi="http://www.w3.org/2001/XInclude">\n'
               '  <Domain>\n    <Grid Name="fields" GridType="Collection" CollectionType="Temporal">\n')
_INDEX_TAIL = "    </Grid>\n  </Domain>\n</Xdmf>\n"
"""The index around its step grids (what ElementTree writes for these elements, indented)."""


def _grid_text(grid: ET.Element) -> str:
    """A step's grid as it stands in the index: indented at its depth (3), with its line end."""
    ET.indent(grid, space="  ", level=3)
    return "      " + ET.tostring(grid, encoding="unicode") + "\n"


def _step_grid(step_file: Path, t: float, deformed: bool = False) -> ET.Element:
    """One Uniform grid at time ``t``: the mesh and every function of ``step_file``, with data
    paths made relative to the index's folder; with ``deformed``, the mesh's geometry is the
    deformed one of the step file (:mod:`dolfinx_nnqem.io.deformed_fields`)."""
    tree = ET.parse(step_file)
    prefix = f"{FOLDER}/"
    grid = ET.Element("Grid", {"Name": step_file.stem, "GridType": "Uniform"})
    mesh_grid = next(g for g in tree.iter("Grid") if g.find("Topology") is not None and g.find("Geometry") is not None)
    for tag in ("Topology", "Geometry"):
        element = deformed_geometry(step_file) if deformed and tag == "Geometry" else child(mesh_grid, tag)
        for item in element.iter("DataItem"):
            item.text = prefix + data_path(item)
        grid.append(element)
    ET.SubElement(grid, "Time", {"Value": f"{t:.17g}"})
    for attribute in tree.iter("Attribute"):
        for item in attribute.iter("DataItem"):
            item.text = prefix + data_path(item)
        grid.append(attribute)
    return grid
