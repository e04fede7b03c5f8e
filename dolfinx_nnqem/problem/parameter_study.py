"""A parameter study: the same problem solved again in one process with other loads, material
parameters or friction, without new forms and without a compile (:meth:`ContactProblem.update
<dolfinx_nnqem.problem.ContactProblem.update>`).

The forms are compiled once, when the problem is built. What a study may change is what they
read at run time, or what never enters them:

* E, ν and the density of every material, σ_y0 and H of a linear-hardening ``VonMises``: cell-wise
  (DG 0) functions, coefficients of the forms (:data:`CHANGEABLE_FIELDS`). The contact scale
  r = E h and the force floor follow E; the self-weight follows the density;
* μ_f of every interface: the pair laws' array (no form holds it);
* the magnitude of a traction, pressure, body force or self-weight: a factor of its assembled
  vector; any load's or support's amplitude, and the values of prescribed displacements (arrays).

What is refused, with an error naming it: a load's direction (its numbers are compiled into its
form), a load's or support's kind, tag or components, a material's kind, the parameters of the
materials whose return map runs on arrays built with the problem (hardening laws of another shape,
back-stresses, Drucker–Prager), and an interface's law or anything but μ_f. Those need a new
problem. Every change is checked before anything changes.

After an update the problem is back at its initial state (:func:`reset_state`). Build the solver
again after an update: NNEQM2 holds the materials it was built with (its Gauss-point operators,
the factorised elastic stiffness) and refuses to solve after they changed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Protocol

from dolfinx_nnqem.contact.specification import Contact
from dolfinx_nnqem.material.interface import Material
from dolfinx_nnqem.problem.bodies import check_rigid_modes, friction_held_motions
from dolfinx_nnqem.problem.interfaces import interface_moduli, largest_modulus
from dolfinx_nnqem.problem.loads import load_factor_between

if TYPE_CHECKING:
    from dolfinx_nnqem.contact.model import ContactModel
    from dolfinx_nnqem.material.finite_strain.gauss_state import FiniteStrainGaussState
    from dolfinx_nnqem.material.state import GaussPointState
    from dolfinx_nnqem.problem.bodies import FrictionHeld, RigidModes
    from dolfinx_nnqem.problem.loads import ExternalLoads
    from dolfinx_nnqem.problem.predictor import SecantPredictor
    from dolfinx_nnqem.problem.supports import Supports

__all__ = ["CHANGEABLE_FIELDS", "StudiedProblem", "reset_state", "update_parameters"]


class StudiedProblem(Protocol):
    """What a parameter study reads of a problem and changes in it
    (:class:`~dolfinx_nnqem.problem.ContactProblem`, which imports this module)."""

    definition: Any  #: the ProblemDefinition
    state: GaussPointState | FiniteStrainGaussState
    supports: Supports
    loads: ExternalLoads
    contact: ContactModel | None
    facet_tags: Any
    rigid_modes: RigidModes
    friction_held: FrictionHeld
    force_floor: float
    u: Any
    load_factor: float
    load_factor_n: float
    predictor: SecantPredictor
    warm_start: bool
    slip_warnings: list[str]

    def moduli_force_floor(self) -> float:
        """The force floor of the current moduli."""

CHANGEABLE_FIELDS: dict[str, tuple[str, ...]] = {"elastic": ("E", "nu", "density"),
                                                 "von-mises": ("E", "nu", "density", "sigma_y0", "H")}
"""The material parameters a study may change, per material kind (``Material.part_kind``): those
held in cell-wise (DG 0) functions (the state's E, ν, density; ``VonMisesPart``'s σ_y0 and H)."""


def update_parameters(problem: StudiedProblem, *, materials: Material | Mapping[int, Material] | None = None,
                      mu_f: float | Mapping[str, float] | None = None, tractions: Sequence | None = None,
                      body_forces: Sequence | None = None, dirichlet: Sequence | None = None) -> None:
    """Change parameters of a built problem (collective); the problem then starts again from its
    initial state. See :meth:`ContactProblem.update <dolfinx_nnqem.problem.ContactProblem.update>`.

    Raises
    ------
    ValueError
        Naming the first parameter that cannot change without a new compile or a new problem; the
        problem is then unchanged.
    """
    definition = problem.definition
    new_materials = None if materials is None else checked_materials(problem.state, materials)
    contacts = list(definition.contact) if mu_f is None else friction_changed(definition.contact, mu_f)
    loads = [*(definition.tractions if tractions is None else tractions),
             *(definition.body_forces if body_forces is None else body_forces)]
    if tractions is not None or body_forces is not None:  # checked before anything changes
        if len(loads) != len(problem.loads.built):
            raise ValueError(f"loads: {len(loads)} tractions and body forces given for the {len(problem.loads.built)} "
                             "the problem was built with; only their magnitudes and amplitudes may change")
        for old, new in zip(problem.loads.built, loads):
            load_factor_between(old, new)
    if dirichlet is not None:
        problem.supports.revalued(dirichlet)  # (the check alone)
    # applied: first the one change that can still be refused (a body held by friction alone)
    if mu_f is not None:
        _set_contact_parameters(problem, contacts)
    if dirichlet is not None:
        problem.supports.revalue(dirichlet)
    if tractions is not None or body_forces is not None:
        problem.loads.rescale(loads)
    if new_materials is not None:
        _refill_materials(problem.state, new_materials)
        problem.loads.reassemble()  # the self-weight follows the densities
        problem.force_floor = problem.moduli_force_floor()
        if problem.contact is not None:  # r = E h follows E
            E = problem.state.E
            problem.contact.set_parameters(contacts, interface_moduli(E, problem.facet_tags, contacts,
                                                                      largest_modulus(E)))
    problem.definition = dataclasses.replace(
        definition, materials=_definition_materials(definition.materials, new_materials),
        dirichlet=tuple(problem.supports.conditions), tractions=tuple(loads[:len(definition.tractions)]),
        body_forces=tuple(loads[len(definition.tractions):]), contact=tuple(contacts))
    reset_state(problem)


def checked_materials(state: GaussPointState | FiniteStrainGaussState, materials: Material | Mapping[int, Material]
                      ) -> dict[int | None, Material]:
    """``{tag: material}`` of the bodies whose material changes, each checked against the one it
    replaces (the same kind; only :data:`CHANGEABLE_FIELDS` differ).

    Raises
    ------
    ValueError
        Naming the cell tag and the parameter that cannot change.
    """
    current = state.materials
    if isinstance(materials, Material):
        if None not in current:
            raise ValueError(f"materials: one material given, but the problem has one per cell tag "
                             f"{sorted(str(t) for t in current)}: give {{cell_tag: material}}")
        new: dict[int | None, Material] = {None: materials}
    elif isinstance(materials, Mapping):
        new = {tag: material for tag, material in materials.items()}
    else:
        raise TypeError(f"materials = {materials!r}: expected a material or {{cell_tag: material}}")
    for tag, material in new.items():
        where = "materials" if tag is None else f"materials[{tag}]"
        if tag not in current:
            raise ValueError(f"{where}: the problem has no body with this cell tag; its tags are "
                             f"{sorted(str(t) for t in current)}")
        _check_same_kind(where, current[tag], material)
    return new


def _check_same_kind(where: str, old: Material, new: Material) -> None:
    """``new`` may replace ``old`` in the built forms (see :func:`checked_materials`)."""
    if not isinstance(new, Material) or type(new) is not type(old) or new.part_kind != old.part_kind:
        raise ValueError(f"{where}: {new!r} replaces a {type(old).__name__} of kind {old.part_kind!r}; a body's "
                         "material kind is compiled into the forms: build a new ContactProblem")
    changeable = CHANGEABLE_FIELDS.get(old.part_kind)
    for field in dataclasses.fields(old):  # type: ignore[arg-type]  # every material is a dataclass (models.py)
        name = field.name
        if getattr(old, name) == getattr(new, name) or (changeable is not None and name in changeable):
            continue
        why = (f"a {old.part_kind!r} material's return map keeps its parameters in arrays built with the problem"
               if changeable is None else f"only {', '.join(changeable)} of a {old.part_kind!r} material can change")
        raise ValueError(f"{where}.{name}: {getattr(old, name)!r} -> {getattr(new, name)!r} cannot change in a "
                         f"parameter study ({why}): build a new ContactProblem")


def _refill_materials(state: GaussPointState | FiniteStrainGaussState, new: Mapping[int | None, Material]) -> None:
    """The state's and the parts' cell-wise fields from the new materials (no compile)."""
    state.materials.update(new)
    state.parameters_changed()


def friction_changed(contacts: Sequence[Contact], mu_f: float | Mapping[str, float]) -> list[Contact]:
    """The contacts with the friction coefficients ``mu_f``: one for every interface, or
    ``{interface name: μ_f}`` (checked as :class:`Contact` checks it).

    Raises
    ------
    ValueError
        If the problem has no contact, an interface name is unknown or a μ_f is not a number ≥ 0.
    """
    if not contacts:
        raise ValueError("mu_f: the problem has no contact interface")
    labels = [c.label for c in contacts]
    values = {label: mu_f for label in labels} if not isinstance(mu_f, Mapping) else dict(mu_f)
    unknown = sorted(set(values) - set(labels))
    if unknown:
        raise ValueError(f"mu_f: no interface named {unknown[0]!r}; the interfaces are {labels}")
    return [dataclasses.replace(c, mu_f=values[c.label]) if c.label in values else c for c in contacts]


def _set_contact_parameters(problem: StudiedProblem, contacts: list[Contact]) -> None:
    """μ_f of the contact model (r of the current moduli); the rigid-mode checks again (a body held
    by friction alone must keep some friction). Back to the old parameters if that check fails.

    Raises
    ------
    ValueError
        Naming the body and the motion nothing holds any more (:func:`~dolfinx_nnqem.problem.bodies.check_rigid_modes`).
    """
    model = problem.contact
    assert model is not None  # the caller checked
    old = [i.contact for i in model.interfaces]
    E_max = largest_modulus(problem.state.E)
    model.set_parameters(contacts, interface_moduli(problem.state.E, problem.facet_tags, contacts, E_max))
    try:
        check_rigid_modes(problem.rigid_modes, model)
    except ValueError:
        model.set_parameters(old, interface_moduli(problem.state.E, problem.facet_tags, old, E_max))
        raise
    problem.friction_held = friction_held_motions(problem.rigid_modes, model)


def _definition_materials(materials: object, new: Mapping[int | None, Material] | None) -> object:
    """The problem definition's materials after ``new`` (one material, or ``{tag: material}``)."""
    if new is None:
        return materials
    if None in new:
        return new[None]
    return {**materials, **new} if isinstance(materials, Mapping) else materials


def reset_state(problem: StudiedProblem) -> None:
    """Back to the initial state of a new problem: u = 0, the Gauss-point state and the pair
    unknowns as built, load factor 0, no predictor history (collective).

    Raises
    ------
    ValueError
        If an interface follows the bodies (current geometry): its pairs of the initial state are
        not kept.
    """
    contact = problem.contact
    if contact is not None and (contact.geometry.follows_bodies or contact.geometry.version != 0):
        following = [i.contact.label for i, f in zip(contact.interfaces, contact.geometry.following) if f]
        raise ValueError(f"reset: the contact interfaces {following} follow the bodies (current geometry): their "
                         "pairs have moved with them and those of the initial state are not kept; build a new "
                         "ContactProblem")
    problem.u.x.array[:] = 0.0
    problem.state.reset()
    if contact is not None:
        contact.reset()
    problem.load_factor = problem.load_factor_n = 0.0
    problem.predictor.clear()
    problem.warm_start = False
    problem.slip_warnings = []
