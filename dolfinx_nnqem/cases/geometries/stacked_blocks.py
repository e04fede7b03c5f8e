"""Two stacked blocks, body 1 below body 2, meshed apart (patch tests, Hertz-type verification):
the gmsh geometry, its structured hexahedra and its tags (:class:`StackedBlocksTags`)."""

from __future__ import annotations

import os

import gmsh
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.problem.gmsh_tools import (add_group, box_curve_counts, fragment_boxes, round_node_coordinates,
                                              structured_hexahedra, surfaces_in_box)
from dolfinx_nnqem.problem.meshing import MeshAndTags, mesh_from_gmsh

__all__ = ["StackedBlocksTags", "build_stacked_blocks"]


class StackedBlocksTags:
    """Tags of :func:`build_stacked_blocks` (body 1 below, body 2 on top).

    Cells: ``BODY1`` = 1, ``BODY2`` = 2.
    Facets: ``BOTTOM`` = 11 (body 1's bottom), ``TOP`` = 13 (body 2's top),
    ``CONTACT1`` = 21 (body 1's top), ``CONTACT2`` = 22 (body 2's bottom);
    lateral faces of body 1: ``BODY1_XMIN`` = 31, ``BODY1_XMAX`` = 32, ``BODY1_ZMIN`` = 33,
    ``BODY1_ZMAX`` = 34; of body 2: ``BODY2_XMIN`` = 41, ``BODY2_XMAX`` = 42,
    ``BODY2_ZMIN`` = 43, ``BODY2_ZMAX`` = 44.
    """

    BODY1 = 1
    BODY2 = 2
    BOTTOM = 11
    TOP = 13
    CONTACT1 = 21
    CONTACT2 = 22
    BODY1_XMIN = 31
    BODY1_XMAX = 32
    BODY1_ZMIN = 33
    BODY1_ZMAX = 34
    BODY2_XMIN = 41
    BODY2_XMAX = 42
    BODY2_ZMIN = 43
    BODY2_ZMAX = 44


def _check_blocks(counts: dict[str, int], lengths: dict[str, float]) -> None:
    """Element counts must be positive integers and lengths positive; the message names the argument."""
    for label, n in counts.items():
        if int(n) != n or n < 1:
            raise ValueError(f"{label} must be a positive integer, got {n!r}")
    for label, length in lengths.items():
        if not length > 0:
            raise ValueError(f"{label} must be positive, got {length!r}")


def build_stacked_blocks(
    comm: MPI.Comm = MPI.COMM_WORLD,
    Lx: float = 1.0,
    Ly1: float = 0.5,
    Ly2: float = 0.5,
    Lz: float = 1.0,
    nx: int = 4,
    ny1: int = 2,
    ny2: int = 2,
    nz: int = 4,
    *,
    y_interface: float | None = None,
    centred: bool = False,
    gap: float = 0.0,
    nx2: int | None = None,
    nz2: int | None = None,
    msh_file: str | os.PathLike | None = None,
    order: int = 1,
) -> MeshAndTags:
    """Body 1, a block below the plane y = ``y_interface``; body 2, a block on top of it.

    Body 1 spans y in [y_interface - Ly1, y_interface], body 2 y in [y_interface + gap,
    y_interface + gap + Ly2]; both span x in [0, Lx] and z in [0, Lz] (or, with ``centred``,
    [-Lx/2, Lx/2] and [-Lz/2, Lz/2]). Structured hexahedra, ``nx x ny1 x nz`` in body 1 and
    ``nx2 x ny2 x nz2`` in body 2 (``nx2 = nx``, ``nz2 = nz`` by default, so that the
    interface nodes coincide when ``gap = 0``). The blocks share no nodes.

    Parameters
    ----------
    comm
        Communicator of the mesh; the gmsh model is built on its rank 0.
    Lx, Ly1, Ly2, Lz
        Block sizes: common width (x) and depth (z), heights of body 1 and body 2.
    nx, ny1, ny2, nz
        Element counts per direction (body 1: nx, ny1, nz; body 2: nx2, ny2, nz2).
    y_interface
        Height of body 1's top face; default ``Ly1`` (body 1 rests on y = 0).
    centred
        Centre both blocks at x = z = 0 (axisymmetric set-ups such as Hertz contact).
    gap
        Initial distance between the blocks (negative: overlapping; for tests of the pair
        search only).
    nx2, nz2
        Body 2's element counts in x and z when they differ from body 1's (non-matching
        interface meshes).
    msh_file
        If given, the gmsh model is also written to this ``.msh`` file (by rank 0).
    order
        2: 27-node hexahedra.

    Returns
    -------
    MeshAndTags
        The mesh and its tags, numbered as in :class:`StackedBlocksTags`.
    """
    nx2 = nx if nx2 is None else nx2
    nz2 = nz if nz2 is None else nz2
    _check_blocks({"nx": nx, "ny1": ny1, "ny2": ny2, "nz": nz, "nx2": nx2, "nz2": nz2},
                  {"Lx": Lx, "Ly1": Ly1, "Ly2": Ly2, "Lz": Lz})
    y_i = Ly1 if y_interface is None else float(y_interface)
    x0 = -Lx / 2 if centred else 0.0
    z0 = -Lz / 2 if centred else 0.0
    return mesh_from_gmsh(
        comm, "stacked_blocks",
        lambda: _build_stacked_blocks_model(x0, z0, y_i, gap, (Lx, Ly1, Ly2, Lz), (nx, ny1, nz), (nx2, ny2, nz2)),
        msh_file, order)


def _build_stacked_blocks_model(x0: float, z0: float, y_i: float, gap: float,
                                lengths: tuple[float, float, float, float], divisions1: tuple[int, int, int],
                                divisions2: tuple[int, int, int]) -> None:
    """The gmsh model of :func:`build_stacked_blocks` (current model, rank 0): geometry, groups, mesh.

    ``(x0, z0)``: the blocks' lowest corner in x and z; ``y_i``: the height of body 1's top face;
    ``lengths``: (Lx, Ly1, Ly2, Lz); ``divisions1``, ``divisions2``: the element counts (x, y, z)
    of body 1 and of body 2.
    """
    Lx, Ly1, Ly2, Lz = lengths
    y2 = y_i + gap
    body1 = fragment_boxes([(x0, y_i - Ly1, z0, Lx, Ly1, Lz)])
    body2 = fragment_boxes([(x0, y2, z0, Lx, Ly2, Lz)])
    gmsh.model.occ.synchronize()
    structured_hexahedra(_axis_curve_counts(body1, divisions1) | _axis_curve_counts(body2, divisions2))

    size = float(np.linalg.norm([Lx, Ly1 + Ly2 + abs(gap), Lz]))
    add_group(3, body1, StackedBlocksTags.BODY1, "body1")
    add_group(3, body2, StackedBlocksTags.BODY2, "body2")
    for body, lower, upper, tag, label in _stacked_block_faces(body1, body2, (x0, x0 + Lx), (z0, z0 + Lz),
                                                               (y_i - Ly1, y_i), (y2, y2 + Ly2)):
        add_group(2, surfaces_in_box(lower, upper, body, size), tag, label)
    gmsh.model.mesh.generate(3)
    round_node_coordinates()


def _axis_curve_counts(volumes: list[int], divisions: tuple[int, int, int]) -> dict[int, int]:
    """Element count of each curve of the boxes ``volumes``: ``divisions`` (x, y, z) by the
    curve's direction, the axis of its (only) non-zero extent."""
    return box_curve_counts(volumes, lambda d: divisions[int(np.argmax(d))])


def _stacked_block_faces(body1: list[int], body2: list[int], xs: tuple[float, float], zs: tuple[float, float],
                         ys1: tuple[float, float], ys2: tuple[float, float]) -> list[tuple]:
    """(body, box corner low, box corner high, tag, name) of every tagged face of the stacked
    blocks (:class:`StackedBlocksTags`): bottom, top, the two contact faces and the sides."""
    (x0, x1), (z0, z1) = xs, zs
    T = StackedBlocksTags
    faces = [
        (body1, (x0, ys1[0], z0), (x1, ys1[0], z1), T.BOTTOM, "bottom"),
        (body2, (x0, ys2[1], z0), (x1, ys2[1], z1), T.TOP, "top"),
        (body1, (x0, ys1[1], z0), (x1, ys1[1], z1), T.CONTACT1, "contact1"),
        (body2, (x0, ys2[0], z0), (x1, ys2[0], z1), T.CONTACT2, "contact2"),
    ]
    for body, (lo_y, hi_y), base, label in ((body1, ys1, T.BODY1_XMIN, "body1"), (body2, ys2, T.BODY2_XMIN, "body2")):
        faces += [
            (body, (x0, lo_y, z0), (x0, hi_y, z1), base, f"{label}_xmin"),
            (body, (x1, lo_y, z0), (x1, hi_y, z1), base + 1, f"{label}_xmax"),
            (body, (x0, lo_y, z0), (x1, hi_y, z0), base + 2, f"{label}_zmin"),
            (body, (x0, lo_y, z1), (x1, hi_y, z1), base + 3, f"{label}_zmax"),
        ]
    return faces
