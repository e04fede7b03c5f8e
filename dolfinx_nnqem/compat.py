"""Every difference between the software stacks the package runs on, in one place.

DOLFINx 0.9 (Debian 13) and 0.11 (the PyPI wheel), and the libraries around it: gmsh (Debian's
is built without Netgen) and pyvista (Debian 13 has 0.44, PyPI 0.49). The rest of the package
calls these functions and never tests versions itself. DOLFINx differences are told apart by
version (checked on both stacks, ``../shared/spec/environments.md``); gmsh's and pyvista's by
capability (what the installed build offers), since both vary with how they were built.

The PyPI wheel ``dolfinx-solver-real`` requires ``import dolfinx_solver`` before
``dolfinx``/``petsc4py``: this module does it, and ``dolfinx_nnqem/__init__.py``
imports this module first.
"""

from __future__ import annotations

import os
import shutil
import sys
from collections.abc import Iterable
from typing import TYPE_CHECKING

H5PY_BEFORE_DOLFINX: bool = "h5py" in sys.modules and "dolfinx" not in sys.modules
"""h5py was imported before DOLFINx: only then can it share the process with the PyPI wheel,
whose DOLFINx loads its own HDF5 (h5py imported after it fails with "Not a datatype"). The
package's reader (:mod:`dolfinx_nnqem.io.reader`) reads in a child process otherwise."""

try:  # the PyPI wheel: loads MPI and its PETSc before dolfinx/petsc4py
    import dolfinx_solver  # noqa: F401
except ImportError:  # Debian's python3-dolfinx, or a source build
    pass

import dolfinx
import dolfinx.fem.petsc
import dolfinx.io
import numpy as np
from petsc4py import PETSc

if TYPE_CHECKING:  # types of the arguments only: gmsh is imported where it is used (its import costs)
    import gmsh
    from mpi4py import MPI

from dolfinx_nnqem.pyvista_compat import extract_outer_surface, import_pyvista, set_plot_colour, vtk_render_problem  # noqa: F401  (their home: no DOLFINx)

_major, _minor = dolfinx.__version__.split(".")[:2]
DOLFINX_VERSION: tuple[int, int] = (int(_major), int(_minor))
"""(major, minor) of the DOLFINx in use."""

if DOLFINX_VERSION < (0, 9):
    raise ImportError(
        f"dolfinx_nnqem needs DOLFINx >= 0.9, found {dolfinx.__version__} at {dolfinx.__file__}"
    )

_NEW = DOLFINX_VERSION >= (0, 10)


def assemble_matrix(a: dolfinx.fem.Form, bcs: Iterable[dolfinx.fem.DirichletBC] = (),
                    diagonal: float = 1.0) -> PETSc.Mat:
    """Assemble a bilinear form into a new PETSc AIJ matrix (``diag``/``diagonal`` keyword)."""
    if _NEW:
        return dolfinx.fem.petsc.assemble_matrix(a, bcs=list(bcs), diag=diagonal)
    return dolfinx.fem.petsc.assemble_matrix(a, bcs=list(bcs), diagonal=diagonal)


def create_vector(V: dolfinx.fem.FunctionSpace) -> PETSc.Vec:
    """A ghosted PETSc vector for the function space ``V``."""
    if _NEW:
        return dolfinx.fem.petsc.create_vector(V)
    # 0.9 builds vectors from a dof layout (index map + block size)
    return dolfinx.la.create_petsc_vector(V.dofmap.index_map, V.dofmap.index_map_bs)


def model_to_mesh(model: type[gmsh.model] | None, comm: MPI.Comm, rank: int = 0, gdim: int = 3
                  ) -> tuple[dolfinx.mesh.Mesh, dolfinx.mesh.MeshTags | None, dolfinx.mesh.MeshTags | None]:
    """gmsh model -> ``(mesh, cell_tags, facet_tags)`` (``io.gmshio`` in 0.9, ``io.gmsh`` after).

    ``model``: ``gmsh.model`` on the rank ``rank`` that holds it (None on the others). A tag is None
    from DOLFINx 0.10 when the model has no physical group of that dimension.
    """
    if _NEW:
        data = dolfinx.io.gmsh.model_to_mesh(model, comm, rank, gdim=gdim)
        return data.mesh, data.cell_tags, data.facet_tags
    mesh, cell_tags, facet_tags = dolfinx.io.gmshio.model_to_mesh(model, comm, rank, gdim=gdim)
    return mesh, cell_tags, facet_tags


def read_from_msh(filename: str, comm: MPI.Comm, rank: int = 0, gdim: int = 3
                  ) -> tuple[dolfinx.mesh.Mesh, dolfinx.mesh.MeshTags | None, dolfinx.mesh.MeshTags | None]:
    """Read a gmsh ``.msh`` file -> ``(mesh, cell_tags, facet_tags)``."""
    if _NEW:
        data = dolfinx.io.gmsh.read_from_msh(filename, comm, rank, gdim=gdim)
        return data.mesh, data.cell_tags, data.facet_tags
    mesh, cell_tags, facet_tags = dolfinx.io.gmshio.read_from_msh(filename, comm, rank, gdim=gdim)
    return mesh, cell_tags, facet_tags


def interpolation_points(V: dolfinx.fem.FunctionSpace) -> np.ndarray:
    """Reference interpolation points of the element of ``V`` (a method in 0.9, a property after)."""
    points = V.element.interpolation_points
    return points() if callable(points) else points


def interpolate_expression(f: dolfinx.fem.Function, expression: dolfinx.fem.Expression) -> None:
    """``f`` ← the compiled ``expression`` (``dolfinx.fem.Expression``) at ``f``'s interpolation points,
    on every cell of the mesh (owned and ghost), as ``f.interpolate(expression)`` does.

    ``Function.interpolate`` defines its dispatch functions anew at every call (a third of a
    millisecond), which shows in runs of many small interpolations (the Gauss-point values of
    every increment); this calls the C++ method it ends in. The method is ``interpolate_expr``
    in DOLFINx 0.11 (cells None: all of them) and ``interpolate`` with explicit cells in 0.9; 0.10
    is told apart by the method it has.
    """
    cpp = f._cpp_object
    if hasattr(cpp, "interpolate_expr"):
        cpp.interpolate_expr(expression._cpp_object, None, None)
        return
    mesh = f.function_space.mesh
    cells = mesh.topology.index_map(mesh.topology.dim)
    all_cells = np.arange(cells.size_local + cells.num_ghosts, dtype=np.int32)
    cpp.interpolate(expression._cpp_object, all_cells, np.arange(0, dtype=np.int32))


def create_vector_wrap(x: dolfinx.la.Vector) -> PETSc.Vec:
    """Wrap a ``dolfinx.la.Vector`` as a PETSc vector sharing its memory."""
    if _NEW:
        import dolfinx.la.petsc

        return dolfinx.la.petsc.create_vector_wrap(x)
    return dolfinx.la.create_petsc_vector_wrap(x)


def mpiexec() -> list[str]:
    """The ``mpiexec`` that belongs to this Python's MPI, as a command prefix.

    The PyPI stack ships MPICH's ``mpiexec`` in the venv's ``bin``; Debian uses OpenMPI's,
    which refuses to run as root unless told.
    """
    candidate = os.path.join(os.path.dirname(sys.executable), "mpiexec")
    exe = candidate if os.path.exists(candidate) else shutil.which("mpiexec")
    if exe is None:
        raise RuntimeError("no mpiexec found next to the Python interpreter or on PATH")
    return [exe]


def mpi_environment() -> dict[str, str]:
    """Environment for ``mpiexec`` subprocesses (OpenMPI as root needs explicit consent)."""
    env = dict(os.environ)
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    env.setdefault("OMPI_MCA_btl", "self,sm")
    # more ranks than cores (the MPI tests use 3): OpenMPI 4 reads the first, OpenMPI 5 (PRRTE,
    # Debian 13) only the second; MPICH ignores both
    env.setdefault("OMPI_MCA_rmaps_base_oversubscribe", "1")
    env.setdefault("PRTE_MCA_rmaps_default_mapping_policy", ":oversubscribe")
    return env


def geometry_dofmap(mesh: dolfinx.mesh.Mesh) -> np.ndarray:
    """Cell -> geometry node array ``(num_cells, nodes_per_cell)`` of a single-cell-type mesh.

    ``geometry.dofmap`` in 0.9; deprecated in favour of the list ``geometry.dofmaps[0]`` after.
    """
    if _NEW:
        return mesh.geometry.dofmaps[0]
    return mesh.geometry.dofmap


def coordinate_element(mesh: dolfinx.mesh.Mesh) -> dolfinx.fem.CoordinateElement:
    """The coordinate element of a single-cell-type mesh (its ``degree``, ``create_dof_layout()``).

    ``geometry.cmap`` in 0.9; deprecated in favour of the list ``geometry.cmaps[0]`` after.
    """
    if _NEW:
        return mesh.geometry.cmaps[0]
    return mesh.geometry.cmap


def entities_to_geometry(mesh: dolfinx.mesh.Mesh, dim: int, entities: np.ndarray) -> np.ndarray:
    """Geometry nodes of the given mesh entities, ``(len(entities), nodes per entity)``.

    DOLFINx 0.9 dies with an integer division by zero (SIGFPE) when asked for no entities (a rank
    that owns none of a surface's facets), so no entities give a ``(0, 0)`` array without asking.
    """
    entities = np.asarray(entities, dtype=np.int32)
    if len(entities) == 0:
        return np.zeros((0, 0), dtype=np.int32)
    nodes = np.asarray(dolfinx.mesh.entities_to_geometry(mesh, dim, entities))
    return nodes.reshape(len(entities), -1)


def gmsh_has_netgen() -> bool:
    """Whether the gmsh in use was built with Netgen (its tetrahedron optimizer).

    gmsh lists its compiled-in modules in the read-only option ``General.BuildOptions``; Debian's
    gmsh 4.13 has no Netgen, the PyPI wheel does. gmsh must be initialised.
    """
    import gmsh

    return "Netgen" in gmsh.option.getString("General.BuildOptions").split()


def optimize_tetrahedra() -> str:
    """Improve the current gmsh model's tetrahedra with the best optimizer this gmsh has.

    Netgen's optimizer where gmsh was built with it, otherwise gmsh's own ("", the default
    tetrahedron optimizer). Returns the name of the optimizer used ("Netgen" or "gmsh"): the two
    give different (equally valid) meshes, so a figure measured on one mesh is quoted with it.
    """
    import gmsh

    if gmsh_has_netgen():
        gmsh.model.mesh.optimize("Netgen")
        return "Netgen"
    gmsh.model.mesh.optimize("")
    return "gmsh"


def refine_mesh(mesh: dolfinx.mesh.Mesh, edges: np.ndarray | None = None
                ) -> tuple[dolfinx.mesh.Mesh, np.ndarray, np.ndarray]:
    """Plaza refinement of a simplex mesh -> ``(mesh, parent_cell, parent_facet)``.

    ``edges``: local indices of the edges to split (None: uniform refinement). ``partitioner=None``
    on both stacks: the refined cells stay on the rank of their parent, without ghost cells, as the
    package's meshes are made (gmsh's, unghosted), so that the parent maps index every local cell
    and the tags carry to all of them (0.10+'s default partitioner adds a ghost layer whose cells
    the parent maps do not cover).
    """
    option = dolfinx.mesh.RefinementOption.parent_cell_and_facet
    mesh.topology.create_entities(1)
    return dolfinx.mesh.refine(mesh, edges, partitioner=None, option=option)


def transfer_meshtag(tags: dolfinx.mesh.MeshTags, mesh: dolfinx.mesh.Mesh, parent_cell: np.ndarray,
                     parent_facet: np.ndarray | None = None) -> dolfinx.mesh.MeshTags:
    """Tags of a parent mesh carried to the refined ``mesh`` (cells: ``parent_cell``; facets:
    both maps); the children of a tagged entity get its tag."""
    mesh.topology.create_entities(tags.dim)
    mesh.topology.create_connectivity(tags.dim, mesh.topology.dim)
    if tags.dim == mesh.topology.dim:
        return dolfinx.mesh.transfer_meshtag(tags, mesh, parent_cell)
    return dolfinx.mesh.transfer_meshtag(tags, mesh, parent_cell, parent_facet)


def parallel_mumps_ordering() -> dict[str, int]:
    """MUMPS's fill-reducing ordering for a factorisation on more than one rank, by what this
    PETSc has: METIS (ICNTL(7) = 5) where PETSc was built with it (the PyPI wheel), PORD
    (ICNTL(7) = 4, MUMPS's own nested dissection) otherwise (Debian 13's PETSc has no METIS).

    The monolithic Newton matrix is a badly scaled saddle-point matrix (zero diagonal entries
    where pairs are closed). MUMPS's maximum-transversal permutation, which makes it safe on one
    rank, needs a centralised matrix, and PETSc passes a distributed one; MUMPS's automatic
    ordering then returns solutions with residuals of order one for it (on Debian 13 every time).
    One rank keeps MUMPS's own choice. The residuals of every ordering on both
    stacks: ``benchmarks/parallel_direct_orderings.py``, ``docs/theory.md`` ("Every direct solve
    is checked"). PORD is built into MUMPS and its fill stays close to METIS's as the mesh grows
    (AMD and QAMD, as accurate here, fill more).
    """
    return {"mat_mumps_icntl_7": 5 if PETSc.Sys.hasExternalPackage("metis") else 4}
