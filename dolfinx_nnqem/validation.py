"""Checks of input values that several entry points share (the Python API and problem files).

Every check raises :class:`ValueError` (or :class:`TypeError`) naming the value, before anything
is solved; numpy scalars are accepted wherever Python numbers are. Checks that look at the mesh
are collective and give the same answer on every rank.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
from mpi4py import MPI

__all__ = ["MAX_CUTBACKS", "MAX_INCREMENTS", "MAX_MAGNITUDE", "MIN_MODULUS", "check_cell_tag", "check_integer",
           "check_magnitude", "check_mesh", "check_output_folder", "check_real", "check_stepping_arguments"]

MAX_INCREMENTS = 100_000
"""Largest number of load increments accepted (a larger number is a typo, not a plan)."""
MAX_CUTBACKS = 50
"""Largest number of halvings in a row (2⁻⁵⁰ of an increment is below any meaning)."""


MAX_MAGNITUDE = 1e20
"""Largest magnitude of a dimensional input: moduli, yield stress, density, loads, prescribed
displacements and motions, obstacle geometry, r, μ_f. Within it (and with the moduli not below
:data:`MIN_MODULUS`) the products and squares the solvers form (stiffness × displacement,
r × gap, the sums of squares of norms) stay far inside double precision (±1.8e308); E, a
traction, a density, r or a prescribed value of 1e300 overflowed to NaN in the first iteration
(issue 31). Any consistent unit system fits: Pa and m, MPa and mm, GPa."""
MIN_MODULUS = 1e-20
"""Smallest Young's modulus and yield stress: E = 1e-300 made the displacements overflow."""


def check_magnitude(name: str, values, limit: float = MAX_MAGNITUDE) -> None:
    """Raise ValueError naming ``name`` when a component of ``values`` exceeds ``limit`` in
    magnitude (the values are finite numbers already)."""
    array = np.abs(np.atleast_1d(np.asarray(values, dtype=float)))
    if array.size and float(array.max()) > limit:
        shown = values.tolist() if isinstance(values, np.ndarray) else values
        raise ValueError(f"{name} = {shown!r}: beyond the supported magnitude {limit:g} (a value this large "
                         "overflows double precision in the solvers' products; docs/reliability.md, "
                         "'Supported ranges')")


def check_real(name: str, value, *, low: float = -math.inf, high: float = math.inf,
               low_inclusive: bool = False) -> float:
    """``value`` as a float: a finite real (not a bool) in (low, high] (or [low, high])."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} = {value!r}: expected a number")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"{name} = {value!r}: expected a finite number")
    if (x < low if low_inclusive else x <= low) or x > high:
        bracket = "[" if low_inclusive else "("
        raise ValueError(f"{name} = {value!r}: expected a value in {bracket}{low:g}, {high:g}]")
    return x


def check_integer(name: str, value, *, low: int, high: int) -> int:
    """``value`` as an int: an integer (Python or numpy, not a bool) in [low, high]."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} = {value!r}: expected an integer")
    n = int(value)
    if not low <= n <= high:
        raise ValueError(f"{name} = {value!r}: expected an integer in [{low}, {high}]")
    return n


def check_stepping_arguments(increments, max_cutbacks, final_load_factor, max_displacement) -> tuple:
    """The arguments of :func:`~dolfinx_nnqem.stepping.solve_load_steps`, checked
    (``increments`` None: automatic incrementation, nothing to check)."""
    if increments is not None:
        increments = check_integer("increments", increments, low=1, high=MAX_INCREMENTS)
    max_cutbacks = check_integer("max_cutbacks", max_cutbacks, low=0, high=MAX_CUTBACKS)
    final_load_factor = check_real("final_load_factor", final_load_factor)
    if max_displacement is not None:
        max_displacement = check_real("max_displacement", max_displacement, low=0.0)
    return increments, max_cutbacks, final_load_factor, max_displacement


def check_mesh(mesh) -> None:
    """A 3D mesh of one cell type whose cells are 3D (collective)."""
    gdim, tdim = mesh.geometry.dim, mesh.topology.dim
    if gdim != 3 or tdim != 3:
        raise ValueError(f"the mesh has {tdim}D cells in a {gdim}D space; dolfinx_nnqem solves 3D solids "
                         "(a mesh of volume cells: tetrahedra or hexahedra)")
    types = getattr(mesh.topology, "cell_types", None)
    if types is not None and len(types) > 1:
        raise ValueError(f"the mesh mixes cell types {[str(t).split('.')[-1] for t in types]}; "
                         "dolfinx_nnqem needs one cell type (all tetrahedra or all hexahedra)")
    ncells = mesh.topology.index_map(tdim).size_global
    if ncells == 0:
        raise ValueError("the mesh has no cells")


def check_cell_tag(tag, cell_tags, comm, what: str) -> None:
    """``tag`` names at least one cell (collective)."""
    if cell_tags is None:
        raise ValueError(f"{what}: cell tag {tag} is used but no cell_tags were given")
    n = comm.allreduce(int(np.count_nonzero(cell_tags.values == tag)), op=MPI.SUM)
    if n == 0:
        present = sorted(set(np.concatenate(comm.allgather(np.unique(cell_tags.values))).tolist()))
        raise ValueError(f"{what}: cell tag {tag} has no cells; the mesh's cell tags are {present}")


def check_output_folder(folder) -> None:
    """An output folder must be named (an empty name would write into the current directory)."""
    if folder is None or str(folder).strip() == "" or str(folder) == ".":
        raise ValueError(f"output folder {str(folder)!r}: give a folder name (an empty name or '.' would mix the "
                         "results with whatever is in the current directory)")
