"""The loads of a problem: tractions, pressures, body forces and self-weight, each with its amplitude.

Every load is assembled once into its force vector F_k for a unit amplitude; the external force
at the load factor ℓ is F_ext(ℓ) = Σ_k a_k(ℓ) F_k, with a_k(ℓ) = ℓ unless the load has an
``amplitude`` of its own (a non-proportional load path). The compiled forms are kept, so that
the vectors can be assembled again after a change of the densities (self-weight) without a
new compile (:meth:`ExternalLoads.reassemble`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import dolfinx.fem as fem
import dolfinx.mesh
import numpy as np
import ufl
from petsc4py import PETSc

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.problem.assembly import assemble_vector
from dolfinx_nnqem.problem.validation import check_cell_tag, check_magnitude

__all__ = ["BodyForce", "ExternalLoads", "Gravity", "Pressure", "Traction", "check_finite", "load_amplitude",
           "load_factor_between"]

Amplitude = Callable[[float], float]


@dataclass(frozen=True)
class Traction:
    """Surface traction ``ℓ · value`` (Pa, global frame) on the facets tagged ``tag``."""

    tag: int
    value: Sequence[float]
    amplitude: Amplitude | None = None  #: a(ℓ) replacing ℓ


@dataclass(frozen=True)
class Pressure:
    """Pressure ``ℓ · p`` (Pa) on the facets tagged ``tag``: traction −p n (n the outward normal)."""

    tag: int
    p: float
    amplitude: Amplitude | None = None  #: a(ℓ) replacing ℓ


@dataclass(frozen=True)
class BodyForce:
    """Body force ``ℓ · value`` (N/m³) on the cells tagged ``cell_tag`` (all cells if None)."""

    value: Sequence[float]
    cell_tag: int | None = None
    amplitude: Amplitude | None = None  #: a(ℓ) replacing ℓ


@dataclass(frozen=True)
class Gravity:
    """Self-weight ``ℓ · ρ g`` with each body's density (from its material)."""

    g: Sequence[float] = (0.0, -9.81, 0.0)
    amplitude: Amplitude | None = None  #: a(ℓ) replacing ℓ


Load = Traction | Pressure | BodyForce | Gravity


def load_amplitude(amplitude: Amplitude | None, load_factor: float) -> float:
    """a(ℓ): ``amplitude(load_factor)``, or the load factor itself when ``amplitude`` is None.

    Raises
    ------
    ValueError
        If the amplitude is not finite.
    """
    value = load_factor if amplitude is None else float(amplitude(load_factor))
    if not math.isfinite(value):
        raise ValueError(f"a load amplitude gave {value} at load factor {load_factor}")
    return value


def check_finite(name: str, values: object, length: int | None = None) -> None:
    """``values`` are ``length`` finite numbers within the supported magnitude (else an error
    naming ``name``: not numpy's "could not convert string to float")."""
    expected = f"{length} numbers" if length is not None else "numbers"
    try:
        array = np.atleast_1d(np.asarray(values, dtype=float))
    except (TypeError, ValueError):
        raise TypeError(f"{name} = {values!r}: expected {expected}"
                        + (", e.g. (0.0, -9.81, 0.0)" if length == 3 else "")) from None
    if length is not None and array.shape != (length,):
        raise ValueError(f"{name} = {array.tolist()}: expected {length} components")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} = {array.tolist()} is not finite")
    check_magnitude(name, array)


def traction_form(t: Traction | Pressure, v: ufl.Argument, ds: ufl.Measure, n: ufl.core.expr.Expr) -> ufl.Form:
    """The linear form of a unit amplitude of the traction or pressure ``t`` (values checked)."""
    if isinstance(t, Pressure):
        check_finite(f"Pressure(tag={t.tag}).p", [t.p])
        return -float(t.p) * ufl.dot(n, v) * ds(t.tag)
    if isinstance(t, Traction):
        check_finite(f"Traction(tag={t.tag}).value", t.value, 3)
        return ufl.dot(ufl.as_vector([float(c) for c in t.value]), v) * ds(t.tag)
    raise TypeError(f"tractions: {t!r} is neither a Traction nor a Pressure")


def body_force_form(b: BodyForce | Gravity, v: ufl.Argument, dx: ufl.Measure, density: fem.Function,
                    cell_tags: dolfinx.mesh.MeshTags | None) -> ufl.Form:
    """The linear form of a unit amplitude of the body force or self-weight ``b`` (values checked)."""
    if isinstance(b, Gravity):
        check_finite("Gravity.g", b.g, 3)
        g = ufl.as_vector([float(c) for c in b.g])
        return density * ufl.dot(g, v) * dx
    if isinstance(b, BodyForce):
        check_finite("BodyForce.value", b.value, 3)
        if b.cell_tag is not None:
            check_cell_tag(b.cell_tag, cell_tags, density.function_space.mesh.comm, "BodyForce")
        f = ufl.as_vector([float(c) for c in b.value])
        return ufl.dot(f, v) * (dx if b.cell_tag is None else dx(b.cell_tag))
    raise TypeError(f"body_forces: {b!r} is neither a BodyForce nor a Gravity")


class ExternalLoads:
    """The loads of a problem as force vectors of a unit amplitude, F_ext(ℓ) = Σ_k a_k(ℓ) F_k.

    Parameters
    ----------
    V
        The displacement space.
    tractions, body_forces
        The loads (:class:`Traction`, :class:`Pressure`; :class:`BodyForce`, :class:`Gravity`).
    density
        The cell-wise density (self-weight).
    facet_tags, cell_tags
        The mesh's tags the loads name.

    Attributes
    ----------
    loads
        The loads in the order of :attr:`parts`: the tractions, then the body forces.
    parts
        ``[(amplitude, F_k)]``: each load's amplitude (None: ℓ) and force vector.
    """

    def __init__(self, V: fem.FunctionSpace, tractions: Sequence[Traction | Pressure],
                 body_forces: Sequence[BodyForce | Gravity], density: fem.Function,
                 facet_tags: dolfinx.mesh.MeshTags | None, cell_tags: dolfinx.mesh.MeshTags | None):
        mesh = V.mesh
        v = ufl.TestFunction(V)
        ds = ufl.Measure("ds", domain=mesh, subdomain_data=facet_tags)
        dx = ufl.Measure("dx", domain=mesh, subdomain_data=cell_tags)
        n = ufl.FacetNormal(mesh)
        # every value is checked before anything is compiled
        forms = [traction_form(t, v, ds, n) for t in tractions]
        forms += [body_force_form(b, v, dx, density, cell_tags) for b in body_forces]
        self.V = V
        self.loads: list[Load] = [*tractions, *body_forces]
        self.built = list(self.loads)  # the values compiled into the forms
        self.forms = [jit.form(form) for form in forms]
        self.scales = [1.0] * len(self.forms)  # F_k = scale_k · (the assembled form), see rescale
        self.parts = [(load.amplitude, assemble_vector(form, V)) for load, form in zip(self.loads, self.forms)]

    def force(self, load_factor: float, out: PETSc.Vec | None = None) -> PETSc.Vec:
        """F_ext(ℓ) = Σ_k a_k(ℓ) F_k: a new vector of V, or ``out`` overwritten."""
        F = compat.create_vector(self.V) if out is None else out
        with F.localForm() as local:
            local.set(0.0)
        for amplitude, F_k in self.parts:
            F.axpy(load_amplitude(amplitude, load_factor), F_k)
        return F

    def amplitudes(self, load_factor: float) -> list[float]:
        """a_k(ℓ) of every load."""
        return [load_amplitude(a, load_factor) for a, _ in self.parts]

    def rescale(self, loads: Sequence[Load]) -> None:
        """New magnitudes and amplitudes of the same loads (in the order of :attr:`loads`): each new
        load is the one the problem was built with times a factor s, its vector s F_k (assembled
        again from the compiled form), with any amplitude.

        The direction of a load is compiled into its form as numbers; its magnitude is a factor of
        the assembled vector, so a new magnitude needs no compile.

        Raises
        ------
        ValueError
            Naming the load that is not a multiple of the one it replaces (another direction, tag or
            kind).
        """
        if len(loads) != len(self.built):
            raise ValueError(f"loads: {len(loads)} given for the {len(self.built)} the problem was built with "
                             "(tractions, then body forces); only their magnitudes and amplitudes may change")
        self.scales = [load_factor_between(old, new) for old, new in zip(self.built, loads)]
        self.parts[:] = [(new.amplitude, F_k) for new, (_, F_k) in zip(loads, self.parts)]  # the problem holds it
        self.loads = list(loads)
        self.reassemble()

    def reassemble(self) -> None:
        """Assemble every F_k again from its compiled form (after a change of the densities), times
        its scale; nothing is compiled."""
        for form, scale, (_, F_k) in zip(self.forms, self.scales, self.parts):
            assemble_vector(form, self.V, F_k)
            if scale != 1.0:
                F_k.scale(scale)


def _magnitude(load: Load) -> np.ndarray:
    """The numbers a load's form is linear in: its value, pressure or g."""
    if isinstance(load, Pressure):
        return np.array([float(load.p)])
    return np.asarray(load.g if isinstance(load, Gravity) else load.value, dtype=float)


def _where(load: Load) -> object:
    """Where a load acts: its facet or cell tag."""
    return load.tag if isinstance(load, (Traction, Pressure)) else getattr(load, "cell_tag", None)


def load_factor_between(old: Load, new: Load) -> float:
    """s with new = s · old (value, pressure or g; the same kind and tag).

    Raises
    ------
    ValueError
        Naming the load, when ``new`` is of another kind or place, or not parallel to ``old``.
    """
    name = f"{type(old).__name__}(tag={_where(old)})"
    if type(new) is not type(old) or _where(new) != _where(old):
        raise ValueError(f"loads: {new!r} replaces {name}; a load's kind and tag are fixed when the problem "
                         "is built: build a new ContactProblem for another")
    check_finite(f"{name} (new)", _magnitude(new))
    a, b = _magnitude(old), _magnitude(new)
    norm = float(a @ a)
    s = float(b @ a) / norm if norm > 0.0 else 0.0
    if np.linalg.norm(b - s * a) > 1e-12 * np.linalg.norm(b):
        raise ValueError(f"loads: {name} changes from {a.tolist()} to {b.tolist()}, which is not a multiple of it: "
                         "the direction of a load is compiled into its form (only its magnitude and amplitude "
                         "may change without a new compile); build a new ContactProblem for another direction")
    return s
