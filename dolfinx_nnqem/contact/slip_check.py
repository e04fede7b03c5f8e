"""The slip check of reference-geometry interfaces (issue 27).

An interface whose pairs were found in the reference configuration describes the surfaces only
while they slide little against each other. Past :data:`SLIP_LIMIT` × the facet size the closest
points, normals and gaps no longer fit, and a run that then fails (e.g. on the strain check) fails
for that reason: :func:`stale_interfaces` names such interfaces once, and load stepping adds them to
a failure's message as the likely cause.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from mpi4py import MPI

__all__ = ["SLIP_LIMIT", "facet_size_of", "slip_message", "stale_interfaces"]

SLIP_LIMIT = 0.25
"""A reference-geometry interface whose relative tangential displacement exceeds this fraction of its
facet size is reported (:func:`stale_interfaces`)."""


def facet_size_of(comm: MPI.Comm, area: np.ndarray) -> float:
    """The facet size of a slave surface: the square root of the 90th percentile of its nodes'
    tributary areas (collective). An interior node of a quadrilateral mesh carries one facet's area;
    the many nodes on a coarse surface's edges and corners carry a half and a quarter of it, which a
    median would take."""
    areas = np.concatenate(comm.allgather(np.asarray(area, dtype=np.float64)))
    return float(np.sqrt(np.percentile(areas, 90.0))) if len(areas) else 0.0


def slip_message(interface, slip: float, size: float) -> str:
    """The warning of :func:`stale_interfaces` for ``interface`` (a model's ``Interface``)."""
    kind = interface.pairs.kind
    advice = ("use discretisation = 'node-to-surface' with geometry = 'current'" if kind == "node-to-node"
              else "use geometry = 'current'")
    return (f"contact {interface.contact.label} ({kind}, reference geometry): the surfaces slid {slip:.4g} "
            f"relative to each other, {slip / size:.3g} × the facet size {size:.4g} (more than {SLIP_LIMIT:g}): "
            f"the pairs, normals and gaps found in the reference configuration no longer describe the "
            f"surfaces; {advice} for large sliding")


def stale_interfaces(comm: MPI.Comm, interfaces: Sequence, trackers: Sequence, w: np.ndarray,
                     warned: set[str]) -> list[str]:
    """Messages for the reference-geometry interfaces (no tracker) whose relative tangential
    displacement ``w[:, 1:]`` exceeds :data:`SLIP_LIMIT` × their facet size, not yet in ``warned``
    (which they are added to; collective).

    Parameters
    ----------
    interfaces, trackers
        The model's interfaces and their geometry trackers (None: reference geometry).
    w
        (num_local, 3) the model's relative displacements.
    """
    lines = []
    for interface, tracker in zip(interfaces, trackers):
        label = interface.contact.label
        if tracker is not None or label in warned:
            continue
        w_t = w[interface.local, 1:]
        slip = comm.allreduce(float(np.hypot(w_t[:, 0], w_t[:, 1]).max(initial=0.0)), op=MPI.MAX)
        size = facet_size_of(comm, interface.pairs.area)
        if slip > SLIP_LIMIT * size:
            warned.add(label)
            lines.append(slip_message(interface, slip, size))
    return lines
