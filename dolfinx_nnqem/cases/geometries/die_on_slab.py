"""A die on a slab: two blocks of :func:`~.block_stack.build_block_stack`, the upper one (the die)
narrowed in x to stand on part of the lower one (the slab), as the Neo-Hookean ironing uses it
(:mod:`dolfinx_nnqem.cases.neo_hooke_ironing`); also written to a gmsh file for the problem file
``demos/neo_hooke_ironing.toml``."""

from __future__ import annotations

import os

import gmsh
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem import compat
from dolfinx_nnqem.cases.geometries.block_stack import BlockStackTags, _build_block_stack_model, build_block_stack
from dolfinx_nnqem.problem.meshing import MeshAndTags, mesh_from_gmsh

__all__ = ["SLAB_LENGTH", "build_die_on_slab"]

SLAB_LENGTH = 2.0  #: the slab's length along x (the stack's Lx)
WIDTH = 0.25  #: the thickness along z of slab and die (the stack's Lz)
HEIGHTS = (0.25, 0.25)  #: the slab's and the die's heights along y


def build_die_on_slab(comm: MPI.Comm = MPI.COMM_WORLD, refine: int = 1, die_x: tuple[float, float] = (0.25, 0.5),
                      *, msh_file: str | os.PathLike | None = None) -> MeshAndTags:
    """The slab 2 × 0.25 × 0.25 (x, y up, z) in 16r × 2r × 2r hexahedra and on its top the die
    over x ∈ ``die_x``, 0.25 high, in 4r × 2r × 2r hexahedra (r = ``refine``).

    The two blocks are built as a stack of equal length (:func:`build_block_stack`); the die's
    nodes are then mapped to x' = die_x[0] + (die_x[1] − die_x[0]) / 2 · x, in the DOLFINx mesh
    and, with ``msh_file``, in the gmsh model written to that file (rank 0), by the same
    arithmetic: the file read back holds the same coordinates. (Only the file's mesh nodes are
    moved: its geometry entities keep the stack's extent, which DOLFINx does not read.)

    Returns
    -------
    MeshAndTags
        Tags as :class:`BlockStackTags`: the slab is block 1, the die block 2.
    """
    divisions = _divisions(refine)
    mesh, cell_tags, facet_tags = build_block_stack(comm, SLAB_LENGTH, WIDTH, list(HEIGHTS), divisions)
    die_nodes = np.unique(compat.geometry_dofmap(mesh)[cell_tags.indices[cell_tags.values == BlockStackTags.body(2)]])
    x = mesh.geometry.x
    x[die_nodes, 0] = _die_x(x[die_nodes, 0], die_x)
    if msh_file is not None and comm.rank == 0:
        def build() -> None:
            _build_block_stack_model(SLAB_LENGTH, WIDTH, list(HEIGHTS), divisions)
            _move_die_nodes(die_x)

        mesh_from_gmsh(MPI.COMM_SELF, "die_on_slab", build, msh_file)
    return MeshAndTags(mesh, cell_tags, facet_tags)


def _divisions(refine: int) -> list[tuple[int, int, int]]:
    """The hexahedra of slab and die along x, y, z at level ``refine``."""
    if isinstance(refine, bool) or not isinstance(refine, int) or refine < 1:
        raise ValueError(f"build_die_on_slab: refine = {refine!r}; expected an integer >= 1")
    r = refine
    return [(16 * r, 2 * r, 2 * r), (4 * r, 2 * r, 2 * r)]


def _die_x(x: np.ndarray, die_x: tuple[float, float]) -> np.ndarray:
    """The die's x from the stack's x ∈ [0, SLAB_LENGTH] (one formula for the mesh and the file)."""
    return die_x[0] + (die_x[1] - die_x[0]) / SLAB_LENGTH * x


def _move_die_nodes(die_x: tuple[float, float]) -> None:
    """Map the gmsh model's die nodes (its volume's and its boundary's) to :func:`_die_x`."""
    for volume in gmsh.model.getEntitiesForPhysicalGroup(3, BlockStackTags.body(2)):
        tags, coords, _ = gmsh.model.mesh.getNodes(3, int(volume), includeBoundary=True)
        coords = coords.reshape(-1, 3)
        coords[:, 0] = _die_x(coords[:, 0], die_x)
        for tag, point in zip(tags, coords):
            gmsh.model.mesh.setNode(int(tag), point.tolist(), [])
