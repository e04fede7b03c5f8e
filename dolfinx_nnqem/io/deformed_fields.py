"""The deformed mesh in the field output: ``fields_deformed.xdmf``, the fields on x = X + u.

``fields.xdmf`` holds every step on the reference mesh (restart, the readers and the pictures
read it so). At finite strain the displacements are large and the Cauchy stress lives on the
deformed body, so a run also writes the mesh moved by u at each step, the DOLFINx way: the
mesh's geometry nodes are moved by u, ``XDMFFile.write_geometry`` writes them into the step's
own file (``fields/fields_XXXX.h5``, grid ``deformed``, dataset ``/Geometry/deformed/geometry``)
and the geometry is put back, bit for bit. ``fields_deformed.xdmf`` is a second index of the same
steps: each grid takes its topology and fields from the step file as ``fields.xdmf`` does, and its
geometry from that deformed grid. So ParaView shows the deformed bodies at every time step without
a "Warp By Vector", and the deformed mesh costs one more array of nodes per step, not a second
copy of the fields.

Why not ``VTXWriter``: DOLFINx 0.9 and 0.11 both write the mesh at every step there
(``mesh_policy=VTXMeshPolicy.update``, the default), but into one ADIOS2 file appended step
after step, whose reading back needs ADIOS2; the per-step XDMF files keep the crash safety of
:mod:`dolfinx_nnqem.io.field_series` (an index that lists closed files only) and are read with
h5py. ``write_geometry`` is bound in both versions.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import dolfinx.fem as fem
import numpy as np

from dolfinx_nnqem.io.xdmf_steps import child

__all__ = ["DEFORMED_GRID", "DEFORMED_INDEX", "write_deformed_geometry", "writes_deformed_mesh"]

DEFORMED_INDEX = "fields_deformed.xdmf"
"""The index of the steps on the deformed mesh, beside ``fields.xdmf``."""
DEFORMED_GRID = "deformed"
"""The name of the step file's grid (and HDF5 group ``/Geometry/deformed``) of the moved nodes."""


def writes_deformed_mesh(problem, deformed_mesh: bool | None) -> bool:
    """Whether a run of ``problem`` writes :data:`DEFORMED_INDEX`: ``deformed_mesh`` if given,
    else at finite strain (``kinematics = "finite"``) only."""
    if deformed_mesh is not None:
        return bool(deformed_mesh)
    return getattr(problem, "kinematics", "small") == "finite"


def write_deformed_geometry(xdmf, u: fem.Function) -> None:
    """Write the geometry of the mesh of ``u`` moved by ``u`` into the open ``xdmf`` (collective).

    The nodes are moved for the write only: the mesh's geometry is restored exactly afterwards,
    also when the write fails.
    """
    from dolfinx_nnqem.problem.deformed_mesh import node_displacements

    geometry = u.function_space.mesh.geometry
    moved = node_displacements(u)  # u at each geometry node, ghosts included
    reference = geometry.x.copy()
    try:
        geometry.x[:] = reference + moved
        xdmf.write_geometry(geometry._cpp_object, DEFORMED_GRID)
    finally:
        geometry.x[:] = reference


def deformed_geometry(step_file: Path) -> ET.Element:
    """The ``Geometry`` element of the deformed grid of ``step_file`` (a ValueError naming the
    file where it has none)."""
    for grid in ET.parse(step_file).iter("Grid"):
        if grid.get("Name") == DEFORMED_GRID and grid.find("Geometry") is not None:
            return child(grid, "Geometry")
    raise ValueError(f"{step_file} holds no {DEFORMED_GRID!r} geometry")
