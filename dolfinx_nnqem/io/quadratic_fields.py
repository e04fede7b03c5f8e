"""The quadratic displacement as ParaView shows it: VTK Lagrange cells at the field's own nodes.

``fields.xdmf`` stores fields at the mesh's geometry nodes: a P2 displacement on a straight-sided
(first-order) mesh is written there at the vertices only, its edge (and face, cell) values lost.
A degree-2 run therefore also writes the displacement at its own nodes with DOLFINx's
``VTKFile``, whose cells are VTK's Lagrange tetrahedra and hexahedra of the field's degree
(10-node tetrahedra, 27-node hexahedra): ParaView draws them as quadratic cells (raise "Nonlinear
Subdivision Level" to see the curvature), and a second-order mesh keeps its curved faces.

Crash-safe like :mod:`dolfinx_nnqem.io.field_series`:

* increment k is written, complete, into ``fields/u_p2_k*.pvtu`` + ``.vtu`` (one ``.vtu`` per
  rank) by its own ``VTKFile``, which is closed before anything refers to it;
* then rank 0 replaces ``fields_p2.pvd`` atomically: a collection of every completed increment
  (timestep = load factor), each pointing to its step file.

A restart from a checkpoint keeps the steps up to the checkpoint and removes later ones.
ParaView reads ``fields_p2.pvd`` natively (no ADIOS2 needed); so does pyvista
(``pyvista.get_reader``), which reads back the values at the P2 nodes exactly.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from dolfinx.io import VTKFile

from dolfinx_nnqem.collective import on_rank0
from dolfinx_nnqem.io.safe_io import atomic_write_text

if TYPE_CHECKING:
    from dolfinx_nnqem.problem.contact_problem import ContactProblem

__all__ = ["INDEX", "QuadraticFieldWriter", "writes_quadratic_fields"]

INDEX = "fields_p2.pvd"
FOLDER = "fields"


def writes_quadratic_fields(problem: ContactProblem) -> bool:
    """Whether a run of ``problem`` writes ``fields_p2.pvd``: its displacement is of degree 2."""
    return problem.V.ufl_element().embedded_superdegree >= 2


def _step_stem(index: int) -> str:
    return f"u_p2_{index:04d}"


def _pvd_files(path: Path) -> list[str]:
    """The data set files a ``.pvd`` collection lists (relative to its folder)."""
    return [d.attrib["file"] for d in ET.parse(path).iter("DataSet")]


def _write_vtk(path: Path, u, t: float) -> None:
    """``u`` at time ``t`` into the one-step collection ``path`` and its step files, closed.

    The ``VTKFile`` is closed and destroyed here: its destructor writes the ``.pvd`` again
    (DOLFINx 0.11), which must not bring the file back after the caller removed it.
    """
    vtk = VTKFile(u.function_space.mesh.comm, str(path), "w")
    try:
        vtk.write_function(u, t)
    finally:
        vtk.close()
        del vtk


class QuadraticFieldWriter:
    """The degree-2 displacement, one VTK step file per converged increment (a load-stepping
    callback of :class:`~dolfinx_nnqem.io.output.ResultsWriter`).

    Parameters
    ----------
    problem
        A :class:`~dolfinx_nnqem.problem.contact_problem.ContactProblem` of degree 2.
    folder
        The run's output folder: writes ``fields_p2.pvd`` and ``fields/u_p2_*``.
    keep_last
        Keep the values of the last increment written (:attr:`last_written`), for the run's
        pictures.
    """

    def __init__(self, problem, folder: str | os.PathLike, *, keep_last: bool = False):
        self.problem = problem
        self.keep_last = keep_last
        self.last_written: tuple[float, np.ndarray] | None = None
        """(load factor, local values of ``problem.u``) last written, with ``keep_last``."""
        self.folder = Path(folder)
        self.comm = problem.mesh.comm
        self.steps: list[tuple[int, float, str]] = []  # (increment, load factor, file) in the index
        on_rank0(self.comm, lambda: (self.folder / FOLDER).mkdir(parents=True, exist_ok=True))

    def __call__(self, result) -> None:
        t = float(result.load_factor)
        step = self.folder / FOLDER / f"{_step_stem(result.index)}.pvd"
        _write_vtk(step, self.problem.u, t)
        if self.keep_last:  # a copy: problem.u moves on in the next increment
            self.last_written = (t, self.problem.u.x.array.copy())

        def first_file() -> str:
            name = _pvd_files(step)[0]  # the .pvtu DOLFINx named
            step.unlink()  # the one-step collection: the index lists the step instead
            return f"{FOLDER}/{name}"

        file = self.comm.bcast(on_rank0(self.comm, first_file), root=0)
        self.steps = [s for s in self.steps if s[0] < result.index] + [(result.index, t, file)]
        on_rank0(self.comm, self._write_index)

    def _write_index(self) -> None:
        lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1">', "  <Collection>"]
        lines += [f'    <DataSet timestep="{t!r}" part="0" file="{f}"/>' for _, t, f in self.steps]
        lines += ["  </Collection>", "</VTKFile>"]
        atomic_write_text(self.folder / INDEX, "\n".join(lines) + "\n")

    # -- restart -------------------------------------------------------------------------------------
    def state(self) -> dict:
        """The steps in the index (JSON, for a checkpoint)."""
        return {"steps": [list(s) for s in self.steps]}

    def resume(self, state: dict) -> None:
        """Continue a run from a checkpoint: keep the steps it had written, drop later ones."""
        self.steps = [(int(i), float(t), str(f)) for i, t, f in state.get("steps", [])]
        last = self.steps[-1][0] if self.steps else 0

        def tidy() -> None:
            for f in (self.folder / FOLDER).glob("u_p2_*"):
                try:
                    if int(f.name[5:9]) > last:
                        f.unlink()
                except ValueError:
                    pass
            self._write_index()

        on_rank0(self.comm, tidy)

    def close(self) -> None:
        """Nothing to close: each step's files are written and closed with that step."""
        pass
