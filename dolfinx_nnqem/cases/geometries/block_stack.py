"""Blocks stacked along y, each meshed on its own (several contact interfaces): the gmsh geometry,
its hexahedra or tetrahedra and its tags (:class:`BlockStackTags`)."""

from __future__ import annotations

import os
from collections.abc import Sequence

import gmsh
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.problem.gmsh_tools import (add_group, box_curve_counts, fragment_boxes, round_node_coordinates,
                                              structured_hexahedra, surfaces_in_box)
from dolfinx_nnqem.problem.meshing import MeshAndTags, mesh_from_gmsh

__all__ = ["BlockStackTags", "build_block_stack"]


class BlockStackTags:
    """Tags of :func:`build_block_stack` (blocks numbered k = 1, 2, ... from the bottom up).

    Cells: block k has tag k. Facets of block k: ``bottom(k)`` = 100 + k (y min),
    ``top(k)`` = 200 + k (y max), ``xmin(k)`` = 300 + k, ``xmax(k)`` = 400 + k,
    ``zmin(k)`` = 500 + k, ``zmax(k)`` = 600 + k.
    """

    @staticmethod
    def body(k: int) -> int:
        """The cell tag of block k: k."""
        return k

    @staticmethod
    def bottom(k: int) -> int:
        """The facet tag of block k's bottom face (y min): 100 + k."""
        return 100 + k

    @staticmethod
    def top(k: int) -> int:
        """The facet tag of block k's top face (y max): 200 + k."""
        return 200 + k

    @staticmethod
    def xmin(k: int) -> int:
        """The facet tag of block k's x-min face: 300 + k."""
        return 300 + k

    @staticmethod
    def xmax(k: int) -> int:
        """The facet tag of block k's x-max face: 400 + k."""
        return 400 + k

    @staticmethod
    def zmin(k: int) -> int:
        """The facet tag of block k's z-min face: 500 + k."""
        return 500 + k

    @staticmethod
    def zmax(k: int) -> int:
        """The facet tag of block k's z-max face: 600 + k."""
        return 600 + k


def build_block_stack(
    comm: MPI.Comm = MPI.COMM_WORLD,
    Lx: float = 1.0,
    Lz: float = 1.0,
    heights: Sequence[float] = (0.5, 0.5, 0.5),
    divisions: Sequence[tuple[int, int, int]] = ((2, 1, 2), (2, 1, 2), (2, 1, 2)),
    *,
    y0: float = 0.0,
    centred: bool = False,
    cell_type: str = "hexahedron",
    structured: bool = False,
    msh_file: str | os.PathLike | None = None,
    order: int = 1,
) -> MeshAndTags:
    """Blocks stacked along y, each meshed on its own (no shared nodes): several contact interfaces.

    Block k (1 at the bottom) spans y in [y0 + Σ_{i<k} h_i, y0 + Σ_{i≤k} h_i] and x in [0, Lx],
    z in [0, Lz] (or, with ``centred``, [-Lx/2, Lx/2] and [-Lz/2, Lz/2]), with
    ``divisions[k-1] = (nx, ny, nz)`` structured hexahedra. Neighbouring blocks with the same nx
    and nz have coincident interface nodes; different ones make non-matching interfaces. With
    ``cell_type="tetrahedron"`` the blocks are meshed with unstructured tetrahedra whose edges
    divide the block's edges into nx, ny, nz parts (the faces are meshed on their own, so even
    equal divisions give non-matching interfaces); with ``structured`` as well, with tetrahedra
    from transfinite volumes, whose faces are all triangulated alike: equal nx and nz then give
    matching interfaces (coincident nodes and triangles). ``order = 2``: a second-order mesh
    (27-node hexahedra, 10-node tetrahedra).

    Returns
    -------
    MeshAndTags
        Tags as in :class:`BlockStackTags`.
    """
    heights = [float(h) for h in heights]
    if len(heights) != len(divisions) or not heights:
        raise ValueError(f"heights ({len(heights)}) and divisions ({len(divisions)}) must have one entry per block")
    for k, (h, n) in enumerate(zip(heights, divisions), start=1):
        if not h > 0:
            raise ValueError(f"block {k}: height must be positive, got {h!r}")
        if len(n) != 3 or any(int(c) != c or c < 1 for c in n):
            raise ValueError(f"block {k}: divisions must be three positive integers, got {n!r}")
    if not (Lx > 0 and Lz > 0):
        raise ValueError(f"Lx and Lz must be positive, got {Lx!r}, {Lz!r}")
    if cell_type not in ("hexahedron", "tetrahedron"):
        raise ValueError(f"cell_type must be 'hexahedron' or 'tetrahedron', got {cell_type!r}")
    return mesh_from_gmsh(
        comm, "block_stack",
        lambda: _build_block_stack_model(Lx, Lz, heights, divisions, y0, centred, cell_type, structured), msh_file,
        order)


def _build_block_stack_model(Lx: float, Lz: float, heights: Sequence[float],
                             divisions: Sequence[tuple[int, int, int]], y0: float = 0.0,
                             centred: bool = False, cell_type: str = "hexahedron", structured: bool = False) -> None:
    """The gmsh model of :func:`build_block_stack` (current model, rank 0): geometry, groups, mesh."""
    x0 = -Lx / 2 if centred else 0.0
    z0 = -Lz / 2 if centred else 0.0
    bottoms = y0 + np.concatenate([[0.0], np.cumsum(heights)[:-1]])
    volumes = [fragment_boxes([(x0, yb, z0, Lx, h, Lz)]) for yb, h in zip(bottoms, heights)]
    gmsh.model.occ.synchronize()
    counts: dict[int, int] = {}
    for body, (n_x, n_y, n_z) in zip(volumes, divisions):
        # called before the next body: the lambda needs no default to hold this body's divisions
        counts |= box_curve_counts(body, lambda d: (n_x, n_y, n_z)[int(np.argmax(d))])
    if cell_type == "hexahedron":
        structured_hexahedra(counts)
    elif structured:  # transfinite, not recombined: every face's triangles alike (matching interfaces)
        structured_hexahedra(counts, recombine=False)
    else:  # the edges' divisions only: unstructured triangles on the faces, tetrahedra inside
        for c, n in counts.items():
            gmsh.model.mesh.setTransfiniteCurve(c, n + 1)
    size = float(np.linalg.norm([Lx, sum(heights), Lz]))
    x1, z1 = x0 + Lx, z0 + Lz
    T = BlockStackTags
    for k, (body, yb, h) in enumerate(zip(volumes, bottoms, heights), start=1):
        add_group(3, body, T.body(k), f"block{k}")
        yt = yb + h
        for lower, upper, tag, label in (
            ((x0, yb, z0), (x1, yb, z1), T.bottom(k), "bottom"),
            ((x0, yt, z0), (x1, yt, z1), T.top(k), "top"),
            ((x0, yb, z0), (x0, yt, z1), T.xmin(k), "xmin"),
            ((x1, yb, z0), (x1, yt, z1), T.xmax(k), "xmax"),
            ((x0, yb, z0), (x1, yt, z0), T.zmin(k), "zmin"),
            ((x0, yb, z1), (x1, yt, z1), T.zmax(k), "zmax"),
        ):
            add_group(2, surfaces_in_box(lower, upper, body, size), tag, f"block{k}_{label}")
    gmsh.model.mesh.generate(3)
    round_node_coordinates()
