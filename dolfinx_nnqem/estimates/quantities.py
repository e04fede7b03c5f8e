"""The quantities a user reads off a run, as one flat record: what the error estimates are about.

Every quantity is a small vector with a name:

* ``contact:NAME`` — the contact resultant of interface NAME: the sum of its pair forces on
  body 2 (the ``surface2`` side; against a rigid obstacle, the force of the obstacle on the
  body), N, global frame;
* ``reaction:TAG`` — the support reaction of the Dirichlet facet tag TAG (the force of the
  support on the body, N; constrained components only, as in ``summary.json``);
* ``u:NAME`` — the displacement of the probe NAME (``[output.probes]``, ``probes=``), m;
* ``max_p`` — the largest equivalent plastic strain over the Gauss points (one component).

:func:`read_quantities` reads them from a solved problem (collective; the same values on every
rank).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI

import dolfinx_nnqem.io.results as res

if TYPE_CHECKING:
    from dolfinx_nnqem.problem.contact_problem import ContactProblem

__all__ = ["Measure", "ProbePoints", "QUANTITY_KINDS", "Quantities", "probe_points", "read_quantities"]

QUANTITY_KINDS = ("contact", "reaction", "u", "max_p")
"""The kinds of quantity, the prefix of each name."""

Quantities = dict[str, np.ndarray]
"""Quantity name -> its value (a 1-D array: 3 components, or 1 for ``max_p``)."""


@dataclass(frozen=True)
class ProbePoints:
    """Named points whose displacement is a quantity: ``{name: (x, y, z)}`` or
    ``{name: ((x, y, z), cell_tag)}`` (one body's node where bodies have coincident nodes)."""

    names: tuple[str, ...]
    points: np.ndarray  #: (n, 3)
    cell_tags: tuple[int | None, ...]


def probe_points(probes: Mapping[str, Sequence] | None) -> ProbePoints:
    """The :class:`ProbePoints` of a probe table as ``SummaryWriter`` takes it."""
    names, points, tags = [], [], []
    for name, spec in (probes or {}).items():
        point, tag = (spec, None) if np.ndim(spec[0]) == 0 else spec
        names.append(str(name))
        points.append(np.asarray(point, dtype=float))
        tags.append(None if tag is None else int(tag))
    return ProbePoints(tuple(names), np.array(points, dtype=float).reshape(-1, 3), tuple(tags))


Measure = Callable[[object], Quantities]
"""``measure(problem)``: further quantities of the caller's (collective), e.g. a Hertz contact's
radius and peak pressure (:func:`dolfinx_nnqem.cases.hertz.hertz_quantities`)."""


def read_quantities(problem: ContactProblem, probes: ProbePoints | None = None, extra: Measure | None = None) -> Quantities:
    """Every quantity of the problem's current (converged) state, by name (collective).

    A probe is located on the mesh of ``problem`` (the nearest node, of the probe's body): on an
    enriched or refined mesh it is the node at the same point. ``extra`` adds the caller's
    quantities (their names must not clash with these).
    """
    values: Quantities = {}
    if problem.has_contact:
        assert problem.contact is not None  # has_contact is "contact is not None"
        table = res.pair_table(problem)
        for name in dict.fromkeys(str(i.contact.label) for i in problem.contact.interfaces):
            on_body2 = -table["force_on_body1"][table["interface_name"] == name].sum(axis=0)
            values[f"contact:{name}"] = np.asarray(on_body2, dtype=float).reshape(3)
    for tag, force in res.reactions(problem).items():
        values[f"reaction:{tag}"] = np.asarray(force, dtype=float)
    if probes is not None and probes.names:
        blocks = np.array([res.node_blocks_at_points(problem, x, cell_tag=t)[0]
                           for x, t in zip(probes.points, probes.cell_tags)], dtype=np.int64)
        for name, u in zip(probes.names, res.values_at_blocks(problem, blocks)):
            values[f"u:{name}"] = np.asarray(u, dtype=float)
    p = problem.state.p_n.x.array
    local = float(p.max()) if p.size else 0.0
    values["max_p"] = np.array([problem.comm.allreduce(local, op=MPI.MAX)])
    if extra is not None:
        for name, value in extra(problem).items():
            if name in values:
                raise ValueError(f"extra quantity {name!r}: the name of a built-in quantity")
            values[name] = np.atleast_1d(np.asarray(value, dtype=float))
    return values
