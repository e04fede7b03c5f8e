r"""The contact specification: what a user says of one interface (:class:`Contact`), checked where it
is given, and the scaling r that the interface's pair laws take (:func:`interface_r`).

A :class:`Contact` names the two surfaces (or a rigid obstacle and a surface), the friction
coefficient, the law and how the interface is discretised and followed; it holds no mesh data.
The contact model (:class:`~dolfinx_nnqem.contact.model.ContactModel`) turns a list of them into
pairs.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass

from dolfinx_nnqem.contact.current_geometry import GEOMETRIES
from dolfinx_nnqem.contact.discretisation import DISCRETISATIONS, OBSTACLE_DISCRETISATIONS
from dolfinx_nnqem.contact.laws import default_r, get_law
from dolfinx_nnqem.contact.obstacles import RigidObstacle
from dolfinx_nnqem.numerics.ranges import check_magnitude, shown

__all__ = ["R_RANGE", "Contact", "interface_r"]


R_RANGE = (1e-6, 1e3)
"""Supported r / (E h), E the softer Young's modulus at the interface and h the mean cell size (E h
is the default r). Inside it every method and law converged on the two-beam benchmark; outside it convergence
became erratic (r/(E h) = 1e-9 and 1e6 failed with every method; 1e-12 and 1e-20 converged
with the monolithic solver, 1e-50 did not; NNEQM2 failed from 1e4): r = 1e-300 stopped
"stalled" at a load factor the run used to pass (issue 31)."""


def interface_r(contact: Contact, E: float, h: float) -> float:
    """The scaling r of an interface's pair laws (force/length): ``contact.r``, or E h without it
    (:func:`~dolfinx_nnqem.contact.laws.default_r`).

    A given r is refused, naming the interface and the range, outside :data:`R_RANGE` × E h.

    Parameters
    ----------
    contact
        The interface.
    E, h
        The softer Young's modulus at the interface and the mean cell size.
    """
    reference = float(default_r(E, h))
    if contact.r is None:
        return reference
    ratio = float(contact.r) / reference
    low, high = R_RANGE
    if not low <= ratio <= high:
        raise ValueError(f"contact {contact.label}: r = {contact.r:g} is {ratio:.3g} × E h = {reference:.4g} N/m "
                         f"(E the softer body's Young's modulus at the interface, h the mean cell size); "
                         f"the supported range is "
                         f"[{low:g}, {high:g}] × E h = [{low * reference:.4g}, {high * reference:.4g}] N/m: "
                         "outside it the law mixes forces and displacements of too different sizes and "
                         "the Newton iterations stall (leave r out for E h)")
    return float(contact.r)


def _real(name: str, value, *, positive: bool = False, allow_none: bool = False) -> float | None:
    """``value`` as a finite float (numpy scalars accepted); ``name`` in the error."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)):
        raise ValueError(f"Contact: {name} = {shown(value)}; expected a finite number")
    value = float(value)
    if positive and value <= 0.0:
        raise ValueError(f"Contact: {name} = {value!r}; expected a value > 0")
    if not positive and value < 0.0:
        raise ValueError(f"Contact: {name} = {value!r}; expected a value >= 0")
    check_magnitude(f"Contact: {name}", value)
    return value


@dataclass(frozen=True)
class Contact:
    """One frictional contact interface.

    Parameters
    ----------
    surface1
        The facet tag of body 1's contact surface, or a rigid obstacle
        (:class:`~dolfinx_nnqem.contact.obstacles.Plane`, ``Sphere``, ``Cylinder``). The master side
        unless ``slave`` says otherwise; the pair normal is the master's outward normal (for mortar,
        minus the slave's).
    surface2
        The facet tag of body 2's contact surface: the slave side by default for node-to-node
        pairs and obstacles (λ is the force on it; every one of its nodes gets a pair).
    mu_f
        Coulomb friction coefficient (≥ 0).
    law
        ``"alart-curnier"`` (Cartesian, the robust default) or ``"polar"`` (the seed's form).
    r
        Scaling of the pair laws (force/length); default E·h (see :func:`contact.laws.default_r`).
    tolerance
        Distance below which nodes coincide (default 1e-8 × the mesh's bounding-box diagonal).
    search_distance
        Node-to-node: the largest distance of non-coincident partners (see
        :func:`dolfinx_nnqem.contact.pairs.find_pairs`). Node-to-surface and mortar: the largest
        distance between a slave node (facet) and the master facets it can touch (default twice
        the larger facet size).
    initial_gap
        Node-to-node only: g0(x) replacing the geometric gap.
    name
        How logs and pair tables name the interface (default ``"21-22"`` or ``"sphere-22"``).
    discretisation
        ``"auto"`` (node-to-node where the surfaces' nodes coincide, else dual mortar),
        ``"node-to-node"``, ``"node-to-surface"`` or ``"mortar"`` (see
        :mod:`dolfinx_nnqem.contact.discretisation`). Against a rigid obstacle: ``"auto"`` or
        ``"node-to-surface"`` (the same thing: slave nodes projected onto the exact surface).
    slave
        The slave surface's tag, ``surface1`` or ``surface2``. Default: ``surface2`` for
        node-to-node; the finer side for node-to-surface and mortar. The pair table's body 1 is
        always the master side.
    geometry
        ``"auto"`` (the default), ``"reference"`` or ``"current"``: where the closest points,
        normals and gaps come from. ``"reference"``: computed once, in the reference configuration;
        ``"current"``: re-evaluated at X + u as the bodies move (large sliding,
        :mod:`~dolfinx_nnqem.contact.current_geometry`); ``"auto"``: the reference ones while the
        surfaces slide less than :data:`~dolfinx_nnqem.contact.slip_check.SLIP_LIMIT` × the facet
        size, the current ones from the increment where they slide more. No state is committed in a
        geometry known to be stale: a reference-geometry interface past the limit that cannot follow
        the bodies (``"reference"``, node-to-node pairs, degree 2, NNEQM2) stops the run there.
        ``"current"`` takes a rigid obstacle, node-to-surface or mortar pairs (``discretisation =
        "auto"`` then means node-to-surface); node-to-node pairs are refused.
    """

    surface1: int | RigidObstacle
    surface2: int
    mu_f: float
    law: str = "alart-curnier"
    r: float | None = None
    tolerance: float | None = None
    search_distance: float | None = None
    initial_gap: Callable | None = None
    name: str | None = None
    discretisation: str = "auto"
    slave: int | None = None
    geometry: str = "auto"

    def __post_init__(self):
        _real("mu_f", self.mu_f)
        _real("r", self.r, positive=True, allow_none=True)
        _real("tolerance", self.tolerance, positive=True, allow_none=True)
        _real("search_distance", self.search_distance, positive=True, allow_none=True)
        get_law(self.law)  # an unknown name raises here, before any mesh work
        if isinstance(self.surface2, bool) or not isinstance(self.surface2, numbers.Integral):
            raise ValueError(f"Contact: surface2 = {self.surface2!r}; expected a facet tag (an integer)")
        if self.obstacle is None:
            if isinstance(self.surface1, bool) or not isinstance(self.surface1, numbers.Integral):
                raise ValueError(f"Contact: surface1 = {self.surface1!r}; expected a facet tag or a rigid "
                                 "obstacle (Plane, Sphere, Cylinder)")
            if self.surface1 == self.surface2:
                raise ValueError(f"Contact: surface1 and surface2 are both tag {self.surface1}")
        elif self.search_distance is not None or self.initial_gap is not None:
            raise ValueError("Contact: search_distance and initial_gap apply to node-to-node contact, not to a "
                             "rigid obstacle (its gap is the exact distance)")
        allowed = DISCRETISATIONS if self.obstacle is None else OBSTACLE_DISCRETISATIONS
        if self.discretisation not in allowed:
            why = " (a rigid obstacle's exact surface takes the slave nodes' projections)" if self.obstacle else ""
            raise ValueError(f"Contact: discretisation = {self.discretisation!r}; expected one of "
                             f"{', '.join(allowed)}{why}")
        if self.slave is not None:
            sides = (self.surface2,) if self.obstacle is not None else (self.surface1, self.surface2)
            if isinstance(self.slave, bool) or self.slave not in sides:
                raise ValueError(f"Contact: slave = {self.slave!r}; expected one of the surfaces' tags "
                                 f"{', '.join(str(t) for t in sides)}")
        if self.initial_gap is not None and self.discretisation not in ("auto", "node-to-node"):
            raise ValueError(f"Contact: initial_gap applies to node-to-node contact, not to "
                             f"discretisation = {self.discretisation!r}")
        self._check_geometry()

    def _check_geometry(self) -> None:
        """Refuse ``geometry = "current"`` where this version does not re-evaluate the pairs."""
        if self.geometry not in GEOMETRIES:
            raise ValueError(f"Contact: geometry = {self.geometry!r}; expected one of {', '.join(GEOMETRIES)}")
        if self.geometry != "current" or self.obstacle is not None:
            return
        if self.discretisation == "node-to-node" or self.initial_gap is not None:
            raise ValueError("Contact: geometry = 'current' does not apply to node-to-node pairs: they join nodes "
                             "that face each other in a matching mesh and stay reference geometry; use "
                             "discretisation = 'node-to-surface' for large sliding")

    @property
    def obstacle(self) -> RigidObstacle | None:
        """The rigid obstacle of the master side, or None for two deformable surfaces."""
        return self.surface1 if isinstance(self.surface1, RigidObstacle) else None

    @property
    def deformable_surfaces(self) -> tuple[int, ...]:
        """The facet tags of the interface's deformable sides (one beside a rigid obstacle)."""
        if isinstance(self.surface1, RigidObstacle):
            return (int(self.surface2),)
        return (int(self.surface1), int(self.surface2))

    @property
    def label(self) -> str:
        """How logs and pair tables name the interface: ``name``, or ``"21-22"``, ``"sphere-22"``."""
        if self.name is not None:
            return self.name
        master = type(self.obstacle).__name__.lower() if self.obstacle is not None else str(self.surface1)
        return f"{master}-{self.surface2}"
