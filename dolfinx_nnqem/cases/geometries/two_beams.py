"""The seed benchmark's two overlapping cantilever beams (``benchmark-two-beams.md``): the gmsh
geometry, its structured hexahedra and its tags (:class:`TwoBeamsTags`). The problem built on it
is :mod:`dolfinx_nnqem.cases.two_beams`."""

from __future__ import annotations

import os

import gmsh
from mpi4py import MPI

from dolfinx_nnqem.problem.gmsh_tools import (add_group, box_curve_counts, fragment_boxes, round_node_coordinates,
                                              structured_hexahedra, surfaces_in_box)
from dolfinx_nnqem.problem.meshing import MeshAndTags, mesh_from_gmsh

__all__ = ["TwoBeamsTags", "build_two_beams"]


class TwoBeamsTags:
    """Tags of :func:`build_two_beams` (the seed benchmark, ``benchmark-two-beams.md``).

    Cells: ``BODY1`` = 1 (beam 1, lower), ``BODY2`` = 2 (beam 2, upper).
    Facets: ``CLAMP1`` = 11 (beam 1, x = 0), ``CLAMP2`` = 12 (beam 2, x = 3.6),
    ``LOAD`` = 13 (beam 2's top face, y = 0.8), ``CONTACT1`` = 21 (beam 1, y = 0.4,
    x in [1.6, 2.0]), ``CONTACT2`` = 22 (beam 2, y = 0.4, x in [1.6, 2.0]).
    """

    BODY1 = 1
    BODY2 = 2
    CLAMP1 = 11
    CLAMP2 = 12
    LOAD = 13
    CONTACT1 = 21
    CONTACT2 = 22


def build_two_beams(
    comm: MPI.Comm = MPI.COMM_WORLD,
    refine: int = 1,
    msh_file: str | os.PathLike | None = None,
    *,
    refine2: int | None = None,
    order: int = 1,
) -> MeshAndTags:
    """The seed benchmark's two overlapping cantilever beams (``benchmark-two-beams.md``).

    Beam 1: x in [0, 2], y in [0, 0.4], z in [0, 0.4]; beam 2: x in [1.6, 3.6],
    y in [0.4, 0.8], z in [0, 0.4]. Structured hexahedra of edge ``0.2 / refine`` m
    (``refine = 1``: 10 x 2 x 2 = 40 per beam). Each beam is built from two boxes fragmented
    with each other only (beam 1 split at x = 1.6, beam 2 at x = 2.0), so the contact surfaces
    are exactly the overlap x in [1.6, 2.0] on y = 0.4 and the beams share no nodes
    (``(2 refine + 1)**2`` coincident node pairs there). With ``refine2``, beam 2's edge is
    ``0.2 / refine2`` m instead: the contact surfaces no longer match (non-matching interface).

    Parameters
    ----------
    comm
        Communicator of the mesh; the gmsh model is built on its rank 0.
    refine
        Positive integer dividing the element edge 0.2 m.
    msh_file
        If given, the gmsh model is also written to this ``.msh`` file (by rank 0).
    refine2
        Positive integer dividing beam 2's element edge 0.2 m; default ``refine`` (matching
        interface meshes).
    order
        2: 27-node hexahedra (for quadratic elements, ``ContactProblem``'s default on them).

    Returns
    -------
    MeshAndTags
        The mesh and its tags, numbered as in :class:`TwoBeamsTags`.
    """
    for label, n in (("refine", refine), ("refine2", refine if refine2 is None else refine2)):
        if int(n) != n or n < 1:
            raise ValueError(f"{label} must be a positive integer, got {n!r}")
    return mesh_from_gmsh(comm, "two_beams", lambda: _build_two_beams_model(refine, refine2), msh_file, order)


_BEAM_WIDTH = 0.4
"""The two beams' height (y) and width (z)."""


def _build_two_beams_model(refine: int, refine2: int | None) -> None:
    """The gmsh model of :func:`build_two_beams` (current model, rank 0): geometry, groups, mesh."""
    width = _BEAM_WIDTH
    # each beam in two boxes, split where the other beam starts or ends and fragmented with each
    # other only: the contact surfaces are exactly the overlap, and the beams share no node
    beam1 = fragment_boxes([(0.0, 0.0, 0.0, 1.6, width, width), (1.6, 0.0, 0.0, 0.4, width, width)])
    beam2 = fragment_boxes([(1.6, width, 0.0, 0.4, width, width), (2.0, width, 0.0, 1.6, width, width)])
    gmsh.model.occ.synchronize()
    structured_hexahedra(_two_beams_curve_counts(beam1, beam2, refine, refine2))
    _tag_two_beams(beam1, beam2)
    gmsh.model.mesh.generate(3)
    round_node_coordinates()


def _two_beams_curve_counts(beam1: list[int], beam2: list[int], refine: int,
                            refine2: int | None) -> dict[int, int]:
    """Element count of each curve of the two beams: edges of 0.2 / ``refine`` m, beam 2's of
    0.2 / ``refine2`` m when it is given."""
    h = 0.2 / int(refine)
    counts = box_curve_counts(beam1 + beam2, lambda d: max(1, round(float(d.max()) / h)))
    if refine2 is not None:  # the beams share no curve: beam 2's counts are its own
        h2 = 0.2 / int(refine2)
        counts |= box_curve_counts(beam2, lambda d: max(1, round(float(d.max()) / h2)))
    return counts


def _tag_two_beams(beam1: list[int], beam2: list[int]) -> None:
    """The physical groups of the two beams (:class:`TwoBeamsTags`)."""
    width = _BEAM_WIDTH
    size = 3.6  # the model's length: the scale of surfaces_in_box's tolerance
    add_group(3, beam1, TwoBeamsTags.BODY1, "beam1")
    add_group(3, beam2, TwoBeamsTags.BODY2, "beam2")
    add_group(
        2, surfaces_in_box((0, 0, 0), (0, width, width), beam1, size),
        TwoBeamsTags.CLAMP1, "clamp1",
    )  # fmt: skip
    add_group(
        2, surfaces_in_box((3.6, width, 0), (3.6, 2 * width, width), beam2, size),
        TwoBeamsTags.CLAMP2, "clamp2",
    )  # fmt: skip
    add_group(
        2, surfaces_in_box((1.6, 2 * width, 0), (3.6, 2 * width, width), beam2, size),
        TwoBeamsTags.LOAD, "load",
    )  # fmt: skip
    add_group(
        2, surfaces_in_box((1.6, width, 0), (2.0, width, width), beam1, size),
        TwoBeamsTags.CONTACT1, "contact1",
    )  # fmt: skip
    add_group(
        2, surfaces_in_box((1.6, width, 0), (2.0, width, width), beam2, size),
        TwoBeamsTags.CONTACT2, "contact2",
    )  # fmt: skip
