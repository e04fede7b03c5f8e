"""Mesh reading and writing, and the gmsh session every mesh generator runs in.

:func:`read_msh` reads a user's ``.msh`` of first or second order (4- or 10-node tetrahedra, 8- or
27-node hexahedra); other gmsh volume elements (20-node hexahedra, third-order ones) are refused
with the reason (:func:`unsupported_gmsh_cells`). :func:`write_xdmf` writes a mesh and its tags as
a problem file reads them without gmsh.

:func:`mesh_from_gmsh` runs a gmsh model builder on rank 0 only, optionally writes the model to a
``.msh`` file, and distributes the mesh with :func:`dolfinx_nnqem.compat.model_to_mesh`, with its
physical groups as cell and facet tags. Second order: with ``order = 2`` it raises the mesh with
gmsh to complete second-order elements (27-node hexahedra, 10-node tetrahedra) whose new nodes lie
on the geometry (a sphere's facets are curved); ``ContactProblem`` then takes degree 2 by default.

The benchmark geometries built this way (two beams, stacked blocks, a block stack, a thick
cylinder, graded blocks, a sphere on a block) are in :mod:`dolfinx_nnqem.cases.geometries`, the
gmsh helpers they share in :mod:`dolfinx_nnqem.problem.gmsh_tools`. Their names still import from
here, with a DeprecationWarning naming the new path, until release 0.2 (:mod:`dolfinx_nnqem._moved`).
"""

from __future__ import annotations

import inspect
import os
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, NamedTuple

from dolfinx_nnqem import compat  # noqa: I001  (first: loads MPI/PETSc for the PyPI wheel)
from dolfinx_nnqem import _moved, chatter

import dolfinx
import gmsh
from mpi4py import MPI

from dolfinx_nnqem.problem.gmsh_tools import round_node_coordinates

__all__ = [
    "MeshAndTags",
    "mesh_from_gmsh",
    "read_msh",
    "unsupported_gmsh_cells",
    "write_xdmf",
]


class MeshAndTags(NamedTuple):
    """A distributed mesh with its cell and facet tags (as returned by every builder)."""

    mesh: dolfinx.mesh.Mesh
    cell_tags: dolfinx.mesh.MeshTags
    facet_tags: dolfinx.mesh.MeshTags


def _initialize_gmsh() -> bool:
    """Initialise gmsh unless it already is; return whether this call initialised it."""
    if gmsh.isInitialized():
        return False
    # interruptible=False: gmsh must not install a SIGINT handler (that fails off the main
    # thread, e.g. under pytest-xdist); older gmsh versions lack the keyword.
    if "interruptible" in inspect.signature(gmsh.initialize).parameters:
        gmsh.initialize(interruptible=False)
    else:
        gmsh.initialize()
    restore_signal_handlers()
    return True


def restore_signal_handlers() -> None:
    """Give SIGTERM and SIGINT back to the Python handlers gmsh replaced.

    ``gmsh.initialize`` (even with ``interruptible=False``) installs its own C-level SIGTERM
    handler behind Python's back (``signal.getsignal`` still names the Python one): a SIGTERM
    then killed ``dolfinx-nnqem two-beams`` with no message and left its summary "running"
    (issue 31). Setting each Python handler again re-installs it at the C level.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return  # signal handlers belong to the main thread
    for signum in (signal.SIGTERM, signal.SIGINT):
        handler = signal.getsignal(signum)
        if handler is not None:  # None: not installed from Python; nothing to give back
            signal.signal(signum, handler)


GMSH_CELLS = {4: "4-node tetrahedra", 11: "10-node tetrahedra", 5: "8-node hexahedra", 12: "27-node hexahedra"}
"""The gmsh volume elements a mesh may have (by gmsh element type): first- and second-order Lagrange
tetrahedra and hexahedra, the cells DOLFINx reads."""


def unsupported_gmsh_cells(types: Sequence[int]) -> str | None:
    """Why gmsh volume elements of the element ``types`` cannot make the mesh, or None.

    The 20-node (serendipity) hexahedron is not a DOLFINx element: DOLFINx's hexahedra are
    Lagrange (tensor-product) elements of 8 or 27 nodes, and a serendipity geometry has no face
    or cell nodes to give the 27-node one. gmsh meshes of second order are complete when
    ``Mesh.SecondOrderIncomplete = 0`` (the default).
    """
    for t in types:
        if int(t) == 17:
            return ("20-node (serendipity) hexahedra are not a DOLFINx element (its hexahedra are Lagrange "
                    "elements of 8 or 27 nodes): mesh with 27-node hexahedra (gmsh: Mesh.ElementOrder = 2 "
                    "with Mesh.SecondOrderIncomplete = 0) or with 8-node ones")
        if int(t) not in GMSH_CELLS:
            name = gmsh.model.mesh.getElementProperties(int(t))[0] if gmsh.isInitialized() else f"type {t}"
            return (f"gmsh elements {name!r} are not supported; the volumes must be "
                    f"{', '.join(GMSH_CELLS.values())}")
    return None


def _check_order(order: int) -> None:
    """Refuse a mesh order other than 1 and 2 (a ValueError naming it)."""
    if order not in (1, 2):
        raise ValueError(f"order = {order!r}: a mesh of first (1) or second (2) order")


def _second_order() -> dict[str, float]:
    """Raise the current model's mesh to second order: complete elements (10-node tetrahedra, 27-node
    hexahedra), the new nodes placed on the geometry (curved surfaces stay curved); node
    coordinates rounded again, so that straight edges keep exact midpoints. Returns the option it
    changed with its previous value (the caller's gmsh session gets it back)."""
    previous = {"Mesh.SecondOrderIncomplete": gmsh.option.getNumber("Mesh.SecondOrderIncomplete")}
    gmsh.option.setNumber("Mesh.SecondOrderIncomplete", 0)
    gmsh.model.mesh.setOrder(2)
    round_node_coordinates()
    return previous


def read_msh(file: str | os.PathLike, comm: MPI.Comm = MPI.COMM_WORLD) -> MeshAndTags:
    """A gmsh ``.msh`` file (first or second order: 4- or 10-node tetrahedra, 8- or 27-node
    hexahedra), read on rank 0 and distributed, with its physical groups as cell and facet tags.

    A second-order mesh keeps its curved geometry: ``ContactProblem`` takes degree 2 on it by
    default. Other elements (20-node hexahedra among them) are refused with the reason, on every
    rank, before the collective distribution.
    """
    def check() -> None:
        gmsh.merge(os.fspath(file))
        problem = unsupported_gmsh_cells(gmsh.model.mesh.getElementTypes(3))
        if problem is not None:
            raise ValueError(f"{file}: {problem}")
        if len(gmsh.model.mesh.getElementTypes(3)) > 1:
            raise ValueError(f"{file}: the volumes mix cell types; use one (all tetrahedra or all hexahedra)")

    return mesh_from_gmsh(comm, "read_msh", check, None, reading=True)


def write_xdmf(file: str | os.PathLike, mesh: dolfinx.mesh.Mesh, cell_tags: dolfinx.mesh.MeshTags,
               facet_tags: dolfinx.mesh.MeshTags) -> None:
    """Write a mesh and its tags to ``file`` (``.xdmf`` + ``.h5``, collective) as a problem file
    reads them by default: grids ``mesh``, ``cell_tags`` and ``facet_tags`` (the three objects
    are given these names).

    DOLFINx reads this format itself; a ``.msh`` needs gmsh's library, whose loading alone costs
    a small run about 18 ms (``docs/performance.md``).
    """
    from dolfinx.io import XDMFFile

    mesh.name = "mesh"
    cell_tags.name = "cell_tags"
    facet_tags.name = "facet_tags"
    with XDMFFile(mesh.comm, os.fspath(file), "w") as xdmf:
        xdmf.write_mesh(mesh)
        xdmf.write_meshtags(cell_tags, mesh.geometry)
        xdmf.write_meshtags(facet_tags, mesh.geometry)


def mesh_from_gmsh(
    comm: MPI.Comm,
    name: str,
    build: Callable[[], None],
    msh_file: str | os.PathLike | None,
    order: int = 1,
    reading: bool = False,
) -> MeshAndTags:
    """Run ``build`` (geometry, physical groups, meshing) on rank 0 and distribute the mesh, with
    the physical groups as cell and facet tags.

    ``name``: the gmsh model's (made unique among the session's models); ``msh_file``: if given,
    the model is also written to it (by rank 0); ``order = 2`` raises the mesh to second order
    after ``build`` (:func:`_second_order`); ``reading``: ``build`` reads a file, its errors are
    raised as ValueError with their own words (otherwise as RuntimeError naming the model).

    gmsh is initialised if needed and finalised again only if this call initialised it; a
    gmsh session opened by the caller keeps its current model (ours is added and removed).
    An exception on rank 0 is broadcast and raised on every rank, so that no rank is left
    waiting in the collective mesh creation.
    """
    _check_order(order)  # an argument: every rank refuses it alike
    failure = ValueError if reading else RuntimeError
    if comm.rank != 0:
        error = comm.bcast(None, root=0)
        if error is not None:
            raise failure(error)
        mesh, cell_tags, facet_tags = compat.model_to_mesh(None, comm, 0, gdim=3)
        return MeshAndTags(mesh, cell_tags, facet_tags)

    initialised_here = False
    previous_model = None
    previous_options = None
    added_model = None
    error = None
    try:
        try:
            initialised_here = _initialize_gmsh()
            if not initialised_here:
                previous_model = gmsh.model.getCurrent()
            # gmsh's own lines only with -v (dolfinx_nnqem.chatter)
            previous_options = chatter.apply_gmsh_options()
            existing = set(gmsh.model.list())
            while name in existing:  # never touch a model of the caller's with the same name
                name += "_"
            gmsh.model.add(name)
            added_model = name
            build()
            if order == 2:
                previous_options = {**_second_order(), **(previous_options or {})}
            if msh_file is not None:
                gmsh.write(os.fspath(msh_file))
        except Exception as exc:  # reported on every rank, below
            error = str(exc) if reading else f"building the gmsh model {name!r} failed: {type(exc).__name__}: {exc}"
        comm.bcast(error, root=0)
        if error is not None:
            raise failure(error)
        mesh, cell_tags, facet_tags = compat.model_to_mesh(gmsh.model, comm, 0, gdim=3)
    finally:
        if initialised_here:
            gmsh.finalize()
        elif gmsh.isInitialized():  # leave the caller's session as it was
            if added_model is not None and added_model in gmsh.model.list():
                gmsh.model.setCurrent(added_model)
                gmsh.model.remove()
            if previous_model is not None and previous_model in gmsh.model.list():
                gmsh.model.setCurrent(previous_model)
            for option, value in (previous_options or {}).items():
                gmsh.option.setNumber(option, value)
    return MeshAndTags(mesh, cell_tags, facet_tags)


if not TYPE_CHECKING:  # for the type checker the moved names are gone: the package imports their new paths
    def __getattr__(name: str):
        """The geometries that moved to :mod:`dolfinx_nnqem.cases.geometries`, with a DeprecationWarning
        naming where they went."""
        return _moved.moved_name(__name__, name)
