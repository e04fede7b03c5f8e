"""Mesh refinement with the tags carried to the children (tetrahedra: DOLFINx's Plaza refinement).

:func:`refine_mesh_and_tags` splits the marked cells' edges (all cells: uniform refinement) and
gives every child cell and facet its parent's tag, so that materials, supports, loads and contact
surfaces hold on the refined mesh: a contact surface is refined with its body (its facets' tags
pass to their children). :func:`mark_bulk` chooses the cells to refine from per-cell
indicators (Dörfler's bulk criterion).

DOLFINx refines simplex meshes only: :func:`check_refinable` refuses a hexahedral mesh with
that reason.
"""

from __future__ import annotations

import dolfinx.mesh
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem import compat

__all__ = ["check_refinable", "mark_bulk", "refine_mesh_and_tags"]


def check_refinable(mesh) -> None:
    """Raise ValueError unless ``mesh`` is tetrahedral (naming the reason)."""
    cell = mesh.topology.cell_name()
    if cell != "tetrahedron":
        raise ValueError(f"adaptive refinement needs a tetrahedral mesh, this one has {cell} cells: DOLFINx "
                         "refines simplex meshes only (dolfinx.mesh.refine). The error estimate is still "
                         "available; for adaptivity mesh the bodies with tetrahedra")


def refine_mesh_and_tags(mesh, cell_tags, facet_tags, cells: np.ndarray | None = None):
    """The refined mesh and its tags: ``cells`` (local indices) refined, or every cell when None.

    Returns
    -------
    tuple
        ``(mesh, cell_tags, facet_tags)`` of the refined mesh (collective).
    """
    check_refinable(mesh)
    edges = None
    if cells is not None:
        tdim = mesh.topology.dim
        mesh.topology.create_connectivity(tdim, 1)
        edges = dolfinx.mesh.compute_incident_entities(mesh.topology, np.asarray(cells, dtype=np.int32), tdim, 1)
    fine, parent_cell, parent_facet = compat.refine_mesh(mesh, edges)
    fine.topology.create_connectivity(fine.topology.dim - 1, fine.topology.dim)
    new_cells = None if cell_tags is None else compat.transfer_meshtag(cell_tags, fine, parent_cell)
    new_facets = None if facet_tags is None else compat.transfer_meshtag(facet_tags, fine, parent_cell, parent_facet)
    return fine, new_cells, new_facets


def mark_bulk(indicators: np.ndarray, fraction: float, comm: MPI.Comm) -> np.ndarray:
    """Dörfler marking: the fewest cells whose η_K² sum to ``fraction`` of Σ η_K² (collective).

    ``indicators``: η_K of this rank's owned cells. Returns the local indices of the marked cells
    (ties at the threshold are all marked, so every rank decides alike).
    """
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction = {fraction!r}; expected a number in (0, 1]")
    eta2 = np.asarray(indicators, dtype=float) ** 2
    everything = np.sort(np.concatenate(comm.allgather(eta2)))[::-1]
    total = everything.sum()
    if total <= 0.0:
        return np.zeros(0, dtype=np.int32)
    count = int(np.searchsorted(np.cumsum(everything), fraction * total)) + 1
    threshold = everything[min(count, everything.size) - 1]
    return np.flatnonzero(eta2 >= threshold).astype(np.int32)
