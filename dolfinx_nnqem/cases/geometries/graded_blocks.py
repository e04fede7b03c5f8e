"""Blocks graded towards a contact point (Hertz-type and indentation tests): the structured
meshes of :mod:`.stacked_blocks` and :mod:`.block_stack`, made of unit elements, mapped onto a
grid whose elements grow away from the point (:func:`graded_nodes`)."""

from __future__ import annotations

import os

import gmsh
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.cases.geometries.block_stack import _build_block_stack_model, build_block_stack
from dolfinx_nnqem.cases.geometries.stacked_blocks import build_stacked_blocks
from dolfinx_nnqem.problem.meshing import MeshAndTags, mesh_from_gmsh

__all__ = ["build_graded_block", "build_graded_contact_blocks", "graded_nodes"]


def graded_nodes(h: float, n_fine: int, length: float, ratio: float = 1.3) -> np.ndarray:
    """Node positions 0 ≤ s ≤ length: ``n_fine`` elements of size ``h``, then sizes growing by
    ``ratio``, the last ones stretched so that the grid ends exactly at ``length``."""
    grid = list(h * np.arange(n_fine + 1))
    size = h
    while grid[-1] < length - 1e-12:
        size *= ratio
        grid.append(grid[-1] + size)
    nodes = np.array(grid)
    s0 = nodes[n_fine]
    nodes[n_fine:] = s0 + (nodes[n_fine:] - s0) * (length - s0) / (nodes[-1] - s0)
    return nodes


def build_graded_contact_blocks(comm: MPI.Comm = MPI.COMM_WORLD, h: float = 0.25, *, fine_width: float = 1.25,
                                fine_depth: float = 0.5, block: float = 6.0, half: bool = False,
                                ratio: float = 1.3) -> MeshAndTags:
    """Two blocks meeting at y = 0, graded towards the contact point x = z = 0 (Hertz-type tests).

    Elements of size ``h`` over |x|, z ≤ ``fine_width`` and ``fine_depth`` on both sides of the
    interface, growing by ``ratio`` beyond, out to ``block`` (half width, depth and height of each
    block). Quarter model (x, z ≥ 0) or, with ``half``, half model (z ≥ 0). The structured mesh of
    :func:`build_stacked_blocks` (unit elements) is mapped onto the graded grid; the same map for
    both bodies keeps the interface nodes coincident. Tags as :class:`StackedBlocksTags`.
    """
    s = graded_nodes(h, round(fine_width / h), block, ratio)
    t = graded_nodes(h, round(fine_depth / h), block, ratio)
    xs = np.concatenate([-s[:0:-1], s]) if half else s
    ys = np.concatenate([-t[:0:-1], t])  # body 1 below y = 0, body 2 above
    zs = s
    nx, ny, nz = len(xs) - 1, len(t) - 1, len(zs) - 1
    mesh, cell_tags, facet_tags = build_stacked_blocks(comm, nx, ny, ny, nz, nx, ny, ny, nz)
    x = mesh.geometry.x
    index = np.rint(x).astype(np.int64)
    if not np.allclose(x, index, atol=1e-9):
        raise RuntimeError("build_graded_contact_blocks: the unit block mesh has non-integer nodes")
    x[:, 0], x[:, 1], x[:, 2] = xs[index[:, 0]], ys[index[:, 1]], zs[index[:, 2]]
    return MeshAndTags(mesh, cell_tags, facet_tags)


def build_graded_block(comm: MPI.Comm = MPI.COMM_WORLD, h: float = 0.25, *, fine_width: float = 1.25,
                       fine_depth: float = 0.5, block: float = 6.0, half: bool = False,
                       ratio: float = 1.3, msh_file: str | os.PathLike | None = None) -> MeshAndTags:
    """One block below y = 0, graded towards the point x = z = 0 of its top (indentation tests).

    Elements of size ``h`` over |x|, z ≤ ``fine_width`` and ``fine_depth`` below the top,
    growing by ``ratio`` beyond, out to ``block`` (half width, depth and height). Quarter model
    (x, z ≥ 0) or, with ``half``, half model (z ≥ 0). Tags as :class:`BlockStackTags` (block 1:
    top = 201, bottom = 101, x = 0 plane 301, z = 0 plane 501). With ``msh_file``, the graded
    mesh is also written to that file (rank 0).
    """
    s = graded_nodes(h, round(fine_width / h), block, ratio)
    t = graded_nodes(h, round(fine_depth / h), block, ratio)
    xs = np.concatenate([-s[:0:-1], s]) if half else s
    ys = -t[::-1]  # from y = -block up to the top y = 0
    zs = s
    nx, ny, nz = len(xs) - 1, len(ys) - 1, len(zs) - 1
    mesh, cell_tags, facet_tags = build_block_stack(comm, nx, nz, [ny], [(nx, ny, nz)])
    x = mesh.geometry.x
    index = np.rint(x).astype(np.int64)
    if not np.allclose(x, index, atol=1e-9):
        raise RuntimeError("build_graded_block: the unit block mesh has non-integer nodes")
    x[:, 0], x[:, 1], x[:, 2] = xs[index[:, 0]], ys[index[:, 1]], zs[index[:, 2]]
    if msh_file is not None:
        _write_graded_msh(msh_file, comm, nx, ny, nz, xs, ys, zs)
    return MeshAndTags(mesh, cell_tags, facet_tags)


def _write_graded_msh(msh_file, comm, nx, ny, nz, xs, ys, zs) -> None:
    """Write the unit block's gmsh model with its nodes moved to the graded grid (rank 0)."""
    if comm.rank != 0:
        return

    def move() -> None:
        tags, coords, _ = gmsh.model.mesh.getNodes()
        coords = coords.reshape(-1, 3)
        index = np.rint(coords).astype(np.int64)
        for tag, i in zip(tags, index):
            gmsh.model.mesh.setNode(int(tag), [xs[i[0]], ys[i[1]], zs[i[2]]], [])

    def build() -> None:
        _build_block_stack_model(nx, nz, [ny], [(nx, ny, nz)])
        move()

    mesh_from_gmsh(MPI.COMM_SELF, "graded_block", build, msh_file)
