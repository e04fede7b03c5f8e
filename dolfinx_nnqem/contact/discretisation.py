"""How an interface between two meshed surfaces is discretised, and which side is the slave.

``Contact(..., discretisation=...)``:

* ``"node-to-node"``: the seed's pairs of coincident (or facing) nodes
  (:mod:`~dolfinx_nnqem.contact.pairs`);
* ``"node-to-surface"``: slave nodes projected onto the master facets
  (:mod:`~dolfinx_nnqem.contact.node_to_surface`);
* ``"mortar"``: dual mortar (:mod:`~dolfinx_nnqem.contact.mortar`);
* ``"auto"`` (the default): node-to-node where every node of each surface coincides with a node
  of the other (or where ``initial_gap`` is given, which only node-to-node takes), mortar
  otherwise.

The slave side is ``surface2`` for node-to-node (the seed's convention). For node-to-surface and
mortar it is the finer of the two surfaces (smaller mean facet area; ``surface2`` on a tie), the
usual choice: the contact pressure is then resolved on the finer mesh and every master facet sees
several slave nodes. ``Contact(slave=...)`` overrides either default; the log names the choice.
Against a rigid obstacle the body's surface is always the slave (the obstacle's exact geometry is
the master surface: node-to-surface onto the exact surface).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from dolfinx_nnqem.contact.nearest import nearest
from dolfinx_nnqem.contact.pairs import find_pairs
from dolfinx_nnqem.contact.pairset import PairSet
from dolfinx_nnqem.contact.surface_pairs import facet_size
from dolfinx_nnqem.contact.surfaces import (GatheredSurfaces, check_no_shared_nodes, gather_surfaces,
                                            mesh_tolerance)

if TYPE_CHECKING:
    import dolfinx

__all__ = ["DISCRETISATIONS", "OBSTACLE_DISCRETISATIONS", "discretise", "nodes_coincide", "slave_side"]

DISCRETISATIONS = ("auto", "node-to-node", "node-to-surface", "mortar")
OBSTACLE_DISCRETISATIONS = ("auto", "node-to-surface")


def nodes_coincide(surfaces: GatheredSurfaces, tolerance: float) -> bool:
    """Whether every node of each of the two surfaces has a node of the other within ``tolerance``."""
    first, second = surfaces.nodes
    if len(first.x) != len(second.x):
        return False
    return bool(np.all(nearest(first.x, second.x)[0] <= tolerance)
                and np.all(nearest(second.x, first.x)[0] <= tolerance))


def slave_side(surfaces: GatheredSurfaces, slave: int | None) -> tuple[int, str]:
    """The slave tag of a non-matching interface (the finer side unless given) and the reason, for the log."""
    tag1, tag2 = surfaces.tags
    h1, h2 = facet_size(surfaces.facets_of(0)), facet_size(surfaces.facets_of(1))
    if slave is not None:
        return int(slave), f" (slave chosen by the user; facet sizes {tag1}: {h1:.4g}, {tag2}: {h2:.4g})"
    if h1 < h2:
        return tag1, f" (slave: the finer side, facet size {h1:.4g} against {h2:.4g})"
    return tag2, f" (slave: the finer side or, on a tie, surface2; facet size {h2:.4g} against {h1:.4g})"


def discretise(V: dolfinx.fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags, surface1: int, surface2: int, discretisation: str = "auto", *,
               slave: int | None = None, tolerance: float | None = None, search_distance: float | None = None,
               initial_gap: Callable[[np.ndarray], np.ndarray] | None = None,
               supported: np.ndarray | None = None) -> PairSet:
    """The pair set of an interface between the meshed surfaces ``surface1`` and ``surface2`` (collective).

    Parameters
    ----------
    V, facet_tags
        The displacement space and the facet tags naming the surfaces.
    surface1, surface2
        The two surfaces' tags.
    discretisation
        One of :data:`DISCRETISATIONS`.
    slave
        The slave surface's tag (``surface1`` or ``surface2``); default: see the module.
    tolerance, search_distance
        See :class:`~dolfinx_nnqem.contact.specification.Contact`.
    initial_gap
        Node-to-node only.
    supported
        Node-to-surface and mortar: V's local dofs, non-zero at prescribed ones; slave normals on
        symmetry planes of the interface are moved into the plane (:mod:`~dolfinx_nnqem.contact.symmetry_planes`).
    """
    if discretisation not in DISCRETISATIONS:
        raise ValueError(f"discretisation = {discretisation!r}; expected one of {', '.join(DISCRETISATIONS)}")
    tolerance = mesh_tolerance(V.mesh) if tolerance is None else float(tolerance)
    tags = (int(surface1), int(surface2))
    if discretisation == "node-to-node" or (discretisation == "auto" and initial_gap is not None):
        master, slave = (tags[1], tags[0]) if slave == tags[0] else tags
        return find_pairs(V, facet_tags, master, slave, tolerance=tolerance, search_distance=search_distance,
                          initial_gap=initial_gap)
    surfaces = gather_surfaces(V, facet_tags, tags)
    check_no_shared_nodes(surfaces)
    if discretisation == "auto" and nodes_coincide(surfaces, tolerance):
        master, slave = (tags[1], tags[0]) if slave == tags[0] else tags
        return find_pairs(V, facet_tags, master, slave, tolerance=tolerance, search_distance=search_distance)
    slave, note = slave_side(surfaces, slave)
    if slave == tags[0]:
        surfaces = surfaces.swapped()  # the builders take (master, slave)
    # imported here: their numba kernels (and numba) are not needed for matching meshes
    if discretisation == "node-to-surface":
        from dolfinx_nnqem.contact.node_to_surface import node_to_surface_pairs

        return node_to_surface_pairs(V, surfaces, tolerance=tolerance, search_distance=search_distance, note=note,
                                     supported=supported)
    from dolfinx_nnqem.contact.mortar import mortar_pairs

    return mortar_pairs(V, surfaces, tolerance=tolerance, search_distance=search_distance, note=note,
                        supported=supported)
