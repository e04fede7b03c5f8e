"""Small gmsh helpers on the current model (rank 0 only), shared by the mesh generators.

Boxes added and fragmented into one body (:func:`fragment_boxes`), element counts per curve
(:func:`box_curve_counts`), structured hexahedra (:func:`structured_hexahedra`), boundary surfaces
located by bounding box (:func:`surfaces_in_box`), physical groups (:func:`add_group`) and node
coordinates rounded back to their grid (:func:`round_node_coordinates`). They act on gmsh's current
model, inside a builder run by :func:`dolfinx_nnqem.problem.meshing.mesh_from_gmsh`.

Bodies that may come into contact are meshed WITHOUT shared nodes: their sub-boxes are
fragmented body by body, never together, so gmsh keeps two copies of the interface (two
surfaces, two sets of nodes) and DOLFINx sees two disconnected parts.
"""

from __future__ import annotations

from collections.abc import Callable

import gmsh
import numpy as np

__all__ = [
    "EPS",
    "add_group",
    "box_curve_counts",
    "curves_of",
    "fragment_boxes",
    "round_node_coordinates",
    "structured_hexahedra",
    "surfaces_in_box",
    "surfaces_of",
]


EPS = 1e-7
"""Relative tolerance for locating gmsh entities by their bounding boxes (OCC boxes are padded
by its own tolerance of ~1e-7, so searches use this times the model size)."""


def curves_of(volumes: list[int]) -> list[int]:
    """Curve tags on the boundary of the given volumes."""
    surfaces = gmsh.model.getBoundary([(3, v) for v in volumes], combined=False, oriented=False)
    curves = gmsh.model.getBoundary(surfaces, combined=False, oriented=False)
    return sorted({abs(tag) for _, tag in curves})


def surfaces_of(volumes: list[int]) -> set[int]:
    """Surface tags on the boundary of the given volumes."""
    dim_tags = gmsh.model.getBoundary([(3, v) for v in volumes], combined=False, oriented=False)
    return {abs(tag) for _, tag in dim_tags}


def surfaces_in_box(
    lower: tuple[float, float, float],
    upper: tuple[float, float, float],
    volumes: list[int],
    size: float,
) -> list[int]:
    """Boundary surfaces of ``volumes`` lying entirely in the box ``[lower, upper]``.

    Restricting to one body's boundary matters: the two contact surfaces occupy the same box.
    """
    pad = EPS * size
    inside = gmsh.model.getEntitiesInBoundingBox(
        lower[0] - pad, lower[1] - pad, lower[2] - pad,
        upper[0] + pad, upper[1] + pad, upper[2] + pad,
        dim=2,
    )  # fmt: skip
    own = surfaces_of(volumes)
    found = sorted(tag for _, tag in inside if tag in own)
    if not found:
        raise RuntimeError(f"no boundary surface of volumes {volumes} in the box {lower}-{upper}")
    return found


def add_group(dim: int, tags: list[int], tag: int, name: str) -> None:
    """The entities ``tags`` of dimension ``dim`` as the physical group ``tag`` named ``name``."""
    gmsh.model.addPhysicalGroup(dim, tags, tag)
    gmsh.model.setPhysicalName(dim, tag, name)


def box_curve_counts(volumes: list[int], count: Callable[[np.ndarray], int]) -> dict[int, int]:
    """Element count of each (straight, axis-aligned) curve of ``volumes``.

    ``count`` receives the curve's extent ``(dx, dy, dz)`` (from its bounding box).
    """
    counts = {}
    for c in curves_of(volumes):
        box = np.array(gmsh.model.getBoundingBox(1, c))
        counts[c] = count(box[3:] - box[:3])
    return counts


def structured_hexahedra(curve_counts: dict[int, int], recombine: bool = True) -> None:
    """Transfinite curves (``n`` elements each), surfaces and volumes, recombined: hexahedra
    (not recombined: tetrahedra, each face's triangles with the same diagonals)."""
    for c, n in curve_counts.items():
        gmsh.model.mesh.setTransfiniteCurve(c, n + 1)
    for _, s in gmsh.model.getEntities(2):
        gmsh.model.mesh.setTransfiniteSurface(s)
        if recombine:
            gmsh.model.mesh.setRecombine(2, s)
    for _, v in gmsh.model.getEntities(3):
        gmsh.model.mesh.setTransfiniteVolume(v)


def round_node_coordinates(decimals: int = 12) -> None:
    """Round all mesh node coordinates to ``decimals`` decimal places.

    gmsh's transfinite interpolation leaves round-off of ~1e-16 in the nodes of box meshes
    (0.39999999999999991 for 0.4), which would tilt the facet normals of flat contact
    surfaces by as much. Rounding restores the exact grid coordinates (up to binary
    representation) and moves no node by more than 0.5e-``decimals``.
    """
    tags, coords, _ = gmsh.model.mesh.getNodes()
    coords = coords.reshape(-1, 3)
    rounded = np.round(coords, decimals) + 0.0  # + 0.0 turns -0.0 into 0.0
    for tag, x, y in zip(tags, coords, rounded):
        if not np.array_equal(x, y):
            gmsh.model.mesh.setNode(int(tag), y.tolist(), [])


def fragment_boxes(boxes: list[tuple[float, float, float, float, float, float]]) -> list[int]:
    """Add boxes ``(x, y, z, dx, dy, dz)`` and fragment them with each other (one body).

    Fragmenting makes the sub-boxes of ONE body conforming (shared interface nodes); calling
    this once per body keeps different bodies' nodes separate.
    """
    occ = gmsh.model.occ
    tags = [occ.addBox(*box) for box in boxes]
    if len(tags) == 1:
        return tags
    out, _ = occ.fragment([(3, tags[0])], [(3, t) for t in tags[1:]])
    return sorted(tag for dim, tag in out if dim == 3)
