"""The slip check of reference-geometry interfaces: no state is committed in a stale geometry.

An interface whose pairs were found in the reference configuration describes the surfaces only
while they slide little against each other. Past :data:`SLIP_LIMIT` × the facet size the closest
points, normals and gaps no longer fit. Load stepping measures the slip of every converged state
before it commits it (:func:`slipped_interfaces`); an interface past the limit is either
re-evaluated in the current configuration from that increment on (``geometry = "auto"``, where
the current geometry is available) or the run stops there, naming the interface
(:func:`stale_message`). ``docs/reliability.md`` states the rule.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

__all__ = ["SLIP_LIMIT", "Slip", "facet_size_of", "slipped_interfaces", "stale_message", "switch_message"]

SLIP_LIMIT = 0.25
"""A reference-geometry interface whose relative tangential displacement exceeds this fraction of its
facet size no longer describes the surfaces (:func:`slipped_interfaces`)."""


@dataclass(frozen=True)
class Slip:
    """A reference-geometry interface that slid past :data:`SLIP_LIMIT` × its facet size."""

    index: int  #: the interface's position in the model
    label: str  #: its name
    kind: str  #: its discretisation ("node-to-node", "rigid obstacle", ...)
    slip: float  #: the largest relative tangential displacement of a pair
    facet_size: float  #: the slave surface's facet size (:func:`facet_size_of`)

    def describe(self) -> str:
        """What slid, by how much, against what limit."""
        return (f"contact {self.label} ({self.kind}, reference geometry): the surfaces slid {self.slip:.4g} "
                f"relative to each other, {self.slip / self.facet_size:.3g} × the facet size {self.facet_size:.4g} "
                f"(more than {SLIP_LIMIT:g})")


def facet_size_of(comm: MPI.Comm, area: np.ndarray) -> float:
    """The facet size of a slave surface: the square root of the 90th percentile of its nodes'
    tributary areas (collective). An interior node of a quadrilateral mesh carries one facet's area;
    the many nodes on a coarse surface's edges and corners carry a half and a quarter of it, which a
    median would take."""
    areas = np.concatenate(comm.allgather(np.asarray(area, dtype=np.float64)))
    return float(np.sqrt(np.percentile(areas, 90.0))) if len(areas) else 0.0


def slipped_interfaces(comm: MPI.Comm, interfaces: Sequence, facet_sizes: Sequence[float | None],
                       w: np.ndarray) -> list[Slip]:
    """The reference-geometry interfaces whose relative tangential displacement ``w[:, 1:]`` exceeds
    :data:`SLIP_LIMIT` × their facet size (collective: every rank gets the same list).

    Parameters
    ----------
    interfaces
        The model's interfaces.
    facet_sizes
        Per interface, its facet size (:func:`facet_size_of`), or None where it is in the current
        geometry (not checked).
    w
        (num_local, 3) the model's relative displacements, measured from the reference configuration.
    """
    checked = [k for k, size in enumerate(facet_sizes) if size is not None]
    local = np.array([np.hypot(*w[interfaces[k].local, 1:].T).max(initial=0.0) for k in checked])
    slips = np.empty_like(local)
    comm.Allreduce(local, slips, op=MPI.MAX)  # one reduction for every interface
    out = []
    for k, slip in zip(checked, slips):
        size = float(facet_sizes[k])  # type: ignore[arg-type]  # checked: not None
        if slip > SLIP_LIMIT * size:
            out.append(Slip(k, interfaces[k].contact.label, interfaces[k].pairs.kind, float(slip), size))
    return out


def switch_message(slip: Slip, load_factor: float) -> str:
    """The warning of an interface that ``geometry = "auto"`` moves to the current geometry."""
    return (f"{slip.describe()} at load factor {load_factor:.6g}: the pairs, normals and gaps found in the reference "
            "configuration no longer describe the surfaces; geometry = 'auto': from this increment on they are "
            "re-evaluated in the current configuration, and the increment is solved again")


def stale_message(slip: Slip, load_factor: float, why_not_current: str) -> str:
    """Why the run stops at an interface that slid past the limit and cannot follow the bodies
    (``why_not_current``: the reason, with what to use instead)."""
    return (f"{slip.describe()} at load factor {load_factor:.6g}: the pairs, normals and gaps found in the reference "
            f"configuration no longer describe the surfaces, and the state is not committed; the interface cannot "
            f"be re-evaluated in the current configuration: {why_not_current}")
