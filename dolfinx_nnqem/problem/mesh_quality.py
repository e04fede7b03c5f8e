"""The shape of every cell, checked where a mesh enters the package (:class:`ContactProblem`).

A cell whose geometry map x(ξ) folds over (det J changes sign, or vanishes, somewhere in it: a
node of a second-order cell moved across it, a flat cell) makes the forms integrate with a
wrong volume weight: a solve may still "converge", to a wrong answer. A cell's orientation
itself is free: DOLFINx integrates with |det J|, and its own ``refine`` numbers half of the
children against the reference orientation (det J < 0 throughout: not inverted). Every cell is
therefore checked before anything else is set up, at the Gauss points of the rule the forms use
and at the reference vertices (where a second-order cell's Jacobian is smallest when a mid-edge
node moves towards a vertex), relative to its own orientation (the sign of det J at its
reference centroid), with two measures:

* the scaled Jacobian s(ξ) = o det J(ξ) / (‖∂x/∂ξ₁‖ ‖∂x/∂ξ₂‖ ‖∂x/∂ξ₃‖), J = ∂x/∂ξ, o = ±1 the
  cell's orientation: 1 where the cell has its reference shape (a cube; for a tetrahedron a
  right-angled corner at vertex 0, a regular tetrahedron has √2/2), sin θ for a parallelepiped
  of angle θ, towards 0 as the cell flattens, negative where it is inverted. It needs no length
  scale: it compares det J with the cube of the cell's own lengths there;
* the Jacobian ratio ρ = min o det J / max o det J over the cell's points: 1 for an affine cell,
  and towards 0 as a second-order cell's mid-edge node moves towards the quarter point of its edge.

An affine cell (a first-order tetrahedron: J is constant) cannot fold within itself; a vertex
moved across the opposite face turns it over onto its neighbour instead. For such meshes every
interior facet is checked too: the cells on either side of it must lie on either side of it
(their vertices off the facet on opposite sides of its plane); both cells of a facet that fails
are named.

A cell with s ≤ :data:`INVERTED` at a point is refused (ValueError, on every rank alike), naming
the cells: the input index (DOLFINx's ``original_cell_index``, the position in the mesh file's
list of volume cells), the cell tag and the centre, lowest position first so that the message
is the same for any number of ranks. A cell with s < :data:`POOR_SCALED` or ρ < :data:`POOR_RATIO`
is reported with a warning (rank 0), the worst named. The computation is vectorised over cells
in chunks (the geometry dofmap, the coordinate element's derivatives tabulated by basix at the
sample points); its cost is in ``docs/reliability.md``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

import basix
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem import collective, compat

if TYPE_CHECKING:
    import dolfinx.mesh

__all__ = ["INVERTED", "POOR_RATIO", "POOR_SCALED", "CellQuality", "cell_measures", "check_cells", "folded_facets",
           "jacobians", "sample_points"]

logger = logging.getLogger("dolfinx_nnqem")

INVERTED = 1e-12
"""A cell with s ≤ this at a sample point is refused: inverted there (s < 0) or flat to within
round-off (a flat cell's det J is round-off, ~10⁻¹⁶ of the product of its lengths)."""

POOR_SCALED = 1e-3
"""A cell with s < this is reported: a sliver, or a parallelepiped with an angle below 0.06°. Its
stiffness is about 1/s times that of a well-shaped cell of its size, which an iterative linear
solver feels first. gmsh's tetrahedral meshes of curved bodies have cells down to s ≈ 0.016 (the
sphere-on-block meshes, h from a/3 to a/14, which match Hertz's solution within 2 %): the bound
lies an order of magnitude below them."""

POOR_RATIO = 1.0 / 30.0
"""A cell with ρ < this is reported: a second-order cell whose mid-edge node sits 0.235 of its
edge off the middle (0.015 of the edge from the quarter point, where det J reaches 0 at the
vertex; measured on a reference tetrahedron and hexahedron, ``tests/reliability/test_mesh_quality.py``)."""

CHUNK = 1024
"""Cells per vectorised block: J's entries of a block (CHUNK × points doubles each) stay in the
processor's cache (4096 took 4 to 8 times as long per cell as 1024)."""

NAMED = 5
"""Cells a message names (the count is always complete)."""


@dataclass(frozen=True)
class CellQuality:
    """The shape check of a mesh (the same on every rank).

    Attributes
    ----------
    num_cells
        Cells checked (all ranks, each cell once).
    num_points
        Sample points per cell (Gauss points of the forms' rule and reference vertices).
    min_scaled_jacobian, min_ratio
        The smallest s and ρ over all cells.
    inverted, poor
        The cells with s ≤ :data:`INVERTED` (lowest position first), and those below
        :data:`POOR_SCALED` or :data:`POOR_RATIO` and not inverted (smallest s first), as text,
        at most :data:`NAMED` of each.
    num_inverted, num_poor
        How many cells of each.
    """

    num_cells: int
    num_points: int
    min_scaled_jacobian: float
    min_ratio: float
    inverted: tuple[str, ...]
    poor: tuple[str, ...]
    num_inverted: int
    num_poor: int


def sample_points(mesh: dolfinx.mesh.Mesh, quadrature_degree: int) -> np.ndarray:
    """(n, 3) reference points where a cell is checked: the Gauss points of the rule of
    ``quadrature_degree`` (basix's default, the one the forms use) and the reference vertices;
    for first-order tetrahedra, whose J is constant, the reference centroid alone."""
    cell = getattr(basix.CellType, mesh.topology.cell_type.name)
    if cell == basix.CellType.tetrahedron and compat.coordinate_element(mesh).degree == 1:
        return np.full((1, 3), 0.25)
    gauss, _ = basix.make_quadrature(cell, quadrature_degree)
    return np.concatenate([gauss, basix.geometry(cell)])


def cell_measures(mesh: dolfinx.mesh.Mesh, points: np.ndarray, cells: np.ndarray,
                  displacement: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The smallest s and the Jacobian ratio ρ = min o det J / max o det J of ``cells`` (local
    indices) over the reference ``points``, each (len(cells),), o the cell's orientation (the sign
    of det J at the reference centroid).

    With a ``displacement`` of every geometry node (laid out like ``mesh.geometry.x``), the
    measures are those of the deformed cells, x + displacement, and o stays the undeformed
    cell's: a cell the deformation turned inside out has s < 0."""
    cmap = compat.coordinate_element(mesh)
    cell = getattr(basix.CellType, mesh.topology.cell_type.name)
    element = basix.create_element(basix.ElementFamily.P, cell, cmap.degree, basix.LagrangeVariant(cmap.variant))
    centroid = basix.geometry(cell).mean(axis=0, keepdims=True)
    dphi = element.tabulate(1, np.concatenate([centroid, points]))[1:4, :, :, 0]  # (3, 1 + points, nodes)
    dofmap = compat.geometry_dofmap(mesh)
    s, ratio = np.empty(len(cells)), np.empty(len(cells))
    for start in range(0, len(cells), CHUNK):
        block = cells[start:start + CHUNK]
        X = mesh.geometry.x[dofmap[block]]
        det, scaled = jacobians(X, dphi)
        orientation = np.where(det[0] < 0.0, -1.0, 1.0)  # a cell numbered against the reference is not inverted
        if displacement is not None:
            det, scaled = jacobians(X + displacement[dofmap[block]], dphi)
        det, scaled = det[1:] * orientation, scaled[1:] * orientation
        s[start:start + len(block)] = scaled.min(axis=0)
        largest = det.max(axis=0)
        ratio[start:start + len(block)] = np.divide(det.min(axis=0), largest, out=np.full(len(block), -np.inf),
                                                    where=largest > 0.0)
    return s, ratio


def folded_facets(mesh: dolfinx.mesh.Mesh) -> np.ndarray:
    """(m, 2) local cells of the interior facets whose two cells lie on the same side of the facet
    (a first-order tetrahedron turned over onto its neighbour), of every local facet (owned and
    ghost: a cell's owner sees its neighbours as ghosts, so each folded cell is found by its owner).

    Each cell's vertex off the facet is tested against the facet's plane: opposite signs of
    n · (x − x_f) pass. Only for affine cells (first-order tetrahedra), where no fold shows within
    a cell.
    """
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    mesh.topology.create_connectivity(tdim, tdim - 1)
    facet_cells = mesh.topology.connectivity(tdim - 1, tdim)
    facet_map = mesh.topology.index_map(tdim - 1)
    num_facets = facet_map.size_local + facet_map.num_ghosts
    counts = np.diff(facet_cells.offsets[:num_facets + 1])
    facets = np.flatnonzero(counts == 2).astype(np.int32)
    if len(facets) == 0:
        return np.zeros((0, 2), dtype=np.int32)
    pairs = facet_cells.array[facet_cells.offsets[facets][:, None] + np.arange(2)]  # (m, 2)
    vertices = compat.geometry_dofmap(mesh)[:, :4].astype(np.int64)  # a first-order tetrahedron's nodes are its vertices
    x = mesh.geometry.x
    facet_nodes = compat.entities_to_geometry(mesh, tdim - 1, facets).astype(np.int64)  # (m, 3)
    a, b, c = (x[facet_nodes[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    sides = []
    for k in range(2):
        opposite = vertices[pairs[:, k]].sum(axis=1) - facet_nodes.sum(axis=1)  # the one node not on the facet
        sides.append(np.einsum("ij,ij->i", normal, x[opposite] - a))
    return pairs[sides[0] * sides[1] >= 0.0]


def jacobians(X: np.ndarray, dphi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """det J and s, each (p, c), of the cells with node coordinates X (c, nodes, 3) at the points
    where the coordinate element's derivatives are ``dphi`` (3, p, nodes); s is 0 where a column
    of J vanishes (a collapsed edge)."""
    coordinates = [np.ascontiguousarray(X[:, :, i].T) for i in range(3)]  # (nodes, c) each
    a = [[dphi[j] @ coordinates[i] for j in range(3)] for i in range(3)]  # a[i][j] = ∂x_i/∂ξ_j, (p, c)
    # the cofactor expansion along the first row, in place (the arrays of a block stay in cache)
    minor = a[1][1] * a[2][2]
    minor -= a[1][2] * a[2][1]
    det = a[0][0] * minor
    minor = a[1][0] * a[2][2]
    minor -= a[1][2] * a[2][0]
    minor *= a[0][1]
    det -= minor
    minor = a[1][0] * a[2][1]
    minor -= a[1][1] * a[2][0]
    minor *= a[0][2]
    det += minor
    lengths = np.ones_like(det)
    for j in range(3):  # ∏_j ‖∂x/∂ξ_j‖
        column = a[0][j] * a[0][j]
        column += a[1][j] * a[1][j]
        column += a[2][j] * a[2][j]
        lengths *= np.sqrt(column, out=column)
    return det, np.divide(det, lengths, out=np.zeros_like(det), where=lengths > 0.0)


def _local_cells(mesh, cell_tags, quadrature_degree: int) -> tuple[int, int, dict]:
    """This rank's owned cells: their number, the sample points per cell, the smallest s and ρ,
    and the inverted and poor cells (input index, tag, centre, s, ρ)."""
    num_owned = mesh.topology.index_map(mesh.topology.dim).size_local
    points = sample_points(mesh, quadrature_degree)
    cells = np.arange(num_owned, dtype=np.int32)
    s, ratio = cell_measures(mesh, points, cells)
    found: dict = {"s": float(s.min(initial=np.inf)), "ratio": float(ratio.min(initial=np.inf))}
    tags = np.full(num_owned, -1, dtype=np.int64)
    if cell_tags is not None:
        owned = cell_tags.indices < num_owned
        tags[cell_tags.indices[owned]] = cell_tags.values[owned]
    num_vertices = len(basix.geometry(getattr(basix.CellType, mesh.topology.cell_type.name)))
    inverted = s <= INVERTED
    if len(points) == 1:  # affine cells: a cell turned over shows against its neighbour only
        folded = folded_facets(mesh).ravel()
        inverted[folded[folded < num_owned]] = True
    for name, bad in (("inverted", inverted), ("poor", ~inverted & ((s < POOR_SCALED) | (ratio < POOR_RATIO)))):
        chosen = cells[bad]
        vertices = compat.geometry_dofmap(mesh)[chosen][:, :num_vertices]  # a cell's vertices come first
        centre = mesh.geometry.x[vertices].mean(axis=1) if len(chosen) else np.zeros((0, 3))
        found[name] = (mesh.topology.original_cell_index[chosen].astype(np.int64), tags[chosen], centre, s[bad],
                       ratio[bad])
    return num_owned, len(points), found


def _describe(index: int, tag: int, centre: np.ndarray, s: float, ratio: float) -> str:
    where = "(" + ", ".join(f"{v:.6g}" for v in centre) + ")"
    tagged = f", cell tag {tag}" if tag >= 0 else ""
    measures = f"s = {s:.3g}" + (f", ρ = {ratio:.3g}" if ratio > 0 else "")
    return f"input cell {index}{tagged} around {where} ({measures})"


def _gathered(parts: list[tuple], worst_first: bool) -> tuple[int, tuple[str, ...]]:
    """The count and the named cells of all ranks' ``parts``, lowest position first (or the
    smallest s first), the same on every rank."""
    index, tag, centre, s, ratio = (np.concatenate([p[k] for p in parts]) for k in range(5))
    centre = centre.reshape(-1, 3)
    keys = (centre[:, 2], centre[:, 1], centre[:, 0]) + ((np.minimum(s, ratio),) if worst_first else ())
    order = np.lexsort(keys)
    return len(index), tuple(_describe(int(index[i]), int(tag[i]), centre[i], float(s[i]), float(ratio[i]))
                             for i in order[:NAMED])


def check_cells(mesh: dolfinx.mesh.Mesh, cell_tags: dolfinx.mesh.MeshTags | None = None,
                quadrature_degree: int = 2) -> CellQuality:
    """Check the shape of every cell (collective; see the module).

    Parameters
    ----------
    mesh
        A 3D mesh of one cell type, of any geometry degree.
    cell_tags
        Named in the messages (optional).
    quadrature_degree
        The degree of the Gauss rule the forms use (its points are checked).

    Raises
    ------
    ValueError
        On every rank, if a cell is inverted or flat at a sample point (s ≤ :data:`INVERTED`).
    """
    comm = mesh.comm
    num_owned, num_points, found = collective.agree(comm, _local_cells, mesh, cell_tags, quadrature_degree)
    everything = comm.allgather(found)
    num_inverted, inverted = _gathered([f["inverted"] for f in everything], worst_first=False)
    num_poor, poor = _gathered([f["poor"] for f in everything], worst_first=True)
    quality = CellQuality(comm.allreduce(num_owned, op=MPI.SUM), num_points, min(f["s"] for f in everything),
                          min(f["ratio"] for f in everything), inverted, poor, num_inverted, num_poor)
    more = " and more"
    if num_inverted:
        raise ValueError(
            f"the mesh has {num_inverted} inverted cell(s): the geometry map folds over (det J changes sign or "
            f"vanishes within the cell: scaled Jacobian s ≤ {INVERTED:g} relative to the cell's orientation, at a "
            "Gauss point or a vertex; or, for first-order tetrahedra, the cell lies on the same side of an interior "
            f"face as its neighbour) at {'; '.join(inverted)}{more * (num_inverted > NAMED)}. Is a node of these "
            "cells on the wrong side (moved across its cell or a neighbour's face)?")
    if num_poor and comm.rank == 0:
        logger.warning(
            f"mesh: {num_poor} of {quality.num_cells} cells are badly shaped (scaled Jacobian s < {POOR_SCALED:g} or "
            f"Jacobian ratio ρ = min det J / max det J < {POOR_RATIO:.3g} over the Gauss points and vertices; 1 is "
            f"the reference shape), the worst: {'; '.join(poor)}{more * (num_poor > NAMED)}. Results on such cells "
            "are less accurate.")
    return quality
