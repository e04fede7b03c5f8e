"""Checks of input values that several entry points share (the Python API and problem files).

Every check raises :class:`ValueError` (or :class:`TypeError`) naming the value, before anything
is solved; numpy scalars are accepted wherever Python numbers are. Checks that look at the mesh
are collective and give the same answer on every rank.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.numerics.ranges import (MAX_MAGNITUDE, MIN_MODULUS, check_integer,  # noqa: F401  (re-exported)
                                           check_magnitude, check_real, shown)

__all__ = ["MAX_CUTBACKS", "MAX_INCREMENTS", "MAX_MAGNITUDE", "MIN_MODULUS", "check_cell_tag", "check_components",
           "check_integer", "check_load_factors", "check_magnitude", "check_mesh", "check_one_contact_per_pair",
           "check_output_folder", "check_real", "check_stepping_arguments"]

MAX_INCREMENTS = 100_000
"""Largest number of load increments accepted (a larger number is a typo, not a plan)."""
MAX_CUTBACKS = 50
"""Largest number of halvings in a row (2⁻⁵⁰ of an increment is below any meaning)."""


def check_stepping_arguments(increments, max_cutbacks, final_load_factor, max_displacement) -> tuple:
    """The arguments of :func:`~dolfinx_nnqem.solvers.stepping.solve_load_steps`, checked
    (``increments`` None: automatic incrementation, nothing to check)."""
    if increments is not None:
        increments = check_integer("increments", increments, low=1, high=MAX_INCREMENTS)
    max_cutbacks = check_integer("max_cutbacks", max_cutbacks, low=0, high=MAX_CUTBACKS)
    final_load_factor = check_real("final_load_factor", final_load_factor)
    if max_displacement is not None:
        max_displacement = check_real("max_displacement", max_displacement, low=0.0)
    return increments, max_cutbacks, final_load_factor, max_displacement


def check_load_factors(load_factors, start: float, final: float) -> None:
    """The load factors automatic incrementation must stop at lie on the path from ``start`` to
    ``final``: one outside it is never reached (one above 1 used to be dropped without a word)."""
    low, high = min(start, final), max(start, final)
    outside = [float(x) for x in load_factors if not low <= x <= high]
    if outside:
        raise ValueError(f"automatic increments: load_factors {outside} lie outside the load path from {start:g} to "
                         f"{final:g}; a run never stops there")


def check_components(components, what: str) -> tuple[int, ...]:
    """A Dirichlet condition's components: distinct, among 0, 1, 2 (None: all three)."""
    if components is None:
        return (0, 1, 2)
    listed = list(components)
    if any(isinstance(c, (bool, np.bool_)) or c not in (0, 1, 2) for c in listed):
        raise ValueError(f"{what}: components {shown(listed)} must be among 0, 1, 2")
    if len(set(int(c) for c in listed)) != len(listed):
        raise ValueError(f"{what}: components {[int(c) for c in listed]} list a component twice; give each once")
    return tuple(int(c) for c in listed)


def check_one_contact_per_pair(contacts) -> None:
    """Refuse two Contacts on the same (unordered) pair of facet tags, naming both: their pairs would
    hold the same nodes twice and no equilibrium splits the force between them (the solvers
    stalled). Several obstacles may touch one surface."""
    seen: dict[frozenset[int], str] = {}  # the pair of facet tags: the first interface's label
    for contact in contacts:
        if contact.obstacle is not None:
            continue
        pair = frozenset((int(contact.surface1), int(contact.surface2)))
        if pair in seen:
            a, b = sorted(pair)
            raise ValueError(f"contact interfaces {seen[pair]!r} and {contact.label!r} both join the facet tags "
                             f"{a} and {b}; give one Contact per pair of surfaces")
        seen[pair] = contact.label


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
