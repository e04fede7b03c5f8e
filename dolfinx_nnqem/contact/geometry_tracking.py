r"""Geometry tracking: where the pairs of each interface come from, and when they move.

An interface's pairs are computed once in the reference configuration, or re-evaluated where the
bodies are by a tracker (:mod:`~dolfinx_nnqem.contact.current_geometry`): from the start
(``geometry = "current"``), or from the increment where its surfaces slid past the slip limit
(``geometry = "auto"``, :mod:`~dolfinx_nnqem.contact.slip_check`).
"""

from __future__ import annotations

from dolfinx_nnqem import compat  # noqa: F401, I001  (first: loads MPI/PETSc for the PyPI wheel)

import numpy as np

from dolfinx_nnqem.contact.current_geometry import MortarTracker, ObstacleTracker, SurfaceTracker, surface_tracker
from dolfinx_nnqem.contact.discretisation import discretise
from dolfinx_nnqem.contact.obstacles import RigidObstacle, obstacle_pairs
from dolfinx_nnqem.contact.pairset import PairSet
from dolfinx_nnqem.contact.specification import Contact
from dolfinx_nnqem.contact.surfaces import ContactPairError, mesh_tolerance, space_degree

__all__ = ["GeometryTracker", "LostContactError", "reference_pairs", "starting_pairs", "tracker_of",
           "zero_displacement"]

GeometryTracker = ObstacleTracker | SurfaceTracker | MortarTracker


class LostContactError(ContactPairError):
    """A re-evaluation of the current geometry found no pair on an interface (the slave nodes left the
    master surface): load stepping takes it as a failed solve and cuts the increment back."""


def zero_displacement(V):
    """A zero displacement on V (the reference configuration)."""
    import dolfinx

    return dolfinx.fem.Function(V)


def starting_pairs(contact: Contact, V, facet_tags, supported: np.ndarray) -> tuple[PairSet, GeometryTracker | None]:
    """The interface's pairs where a run starts, and its tracker if it follows the bodies from there
    (``geometry = "current"``; collective).

    Parameters
    ----------
    contact
        The interface.
    V, facet_tags
        The displacement space and the facet tags naming the surfaces.
    supported
        V's local dofs, non-zero at prescribed ones (see
        :func:`~dolfinx_nnqem.contact.discretisation.discretise`).
    """
    if contact.geometry != "current":
        return reference_pairs(contact, V, facet_tags, supported), None
    if space_degree(V) != 1:
        raise ValueError(f"contact {contact.label}: geometry = 'current' takes degree-1 displacements in "
                         f"this version (its closest points and pair rows are those of linear facets); "
                         f"the displacements here have degree {space_degree(V)}: use geometry = "
                         f"'reference', or degree 1")
    tracker = tracker_of(contact, V, facet_tags, supported)
    return tracker.pairs_at(zero_displacement(V), 0.0), tracker


def reference_pairs(contact: Contact, V, facet_tags, supported: np.ndarray | None = None) -> PairSet:
    """The interface's pairs in the reference configuration (collective); ``supported``: see
    :func:`~dolfinx_nnqem.contact.discretisation.discretise`."""
    if isinstance(contact.surface1, RigidObstacle):  # contact.obstacle, narrowed for the type checker
        return obstacle_pairs(V, facet_tags, int(contact.surface2), contact.surface1, tolerance=contact.tolerance)
    return discretise(V, facet_tags, int(contact.surface1), int(contact.surface2), contact.discretisation,
                      slave=contact.slave, tolerance=contact.tolerance, search_distance=contact.search_distance,
                      initial_gap=contact.initial_gap, supported=supported)


def tracker_of(contact: Contact, V, facet_tags, supported: np.ndarray | None = None, *,
               reference: PairSet | None = None) -> GeometryTracker:
    """What re-evaluates the pairs of the interface in the current configuration (collective).

    ``reference``: the interface's reference-geometry pairs, when ``geometry = "auto"`` moves it to
    the current geometry during a run: the tracker then keeps their discretisation (mortar where
    ``discretisation = "auto"`` chose mortar) and slave side, so that every pair keeps its slave
    node. Without it, ``discretisation = "auto"`` means node-to-surface.
    """
    if isinstance(contact.surface1, RigidObstacle):
        tolerance = mesh_tolerance(V.mesh) if contact.tolerance is None else float(contact.tolerance)
        return ObstacleTracker(obstacle_pairs(V, facet_tags, int(contact.surface2), contact.surface1,
                                              tolerance=tolerance))
    slave = contact.slave
    if reference is not None:
        discretisation = "mortar" if reference.kind == "mortar" else "node-to-surface"
        slave = getattr(reference, "slave", slave)  # node-to-surface and mortar pairs name their slave side
    else:
        discretisation = "mortar" if contact.discretisation == "mortar" else "node-to-surface"  # auto: node-to-surface
    return surface_tracker(V, facet_tags, (int(contact.surface1), int(contact.surface2)), slave=slave,
                           search_distance=contact.search_distance, supported=supported,
                           discretisation=discretisation)
