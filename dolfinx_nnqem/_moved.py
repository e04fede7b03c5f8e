"""Deprecated module paths and names, kept importable until release 0.2.

The package's modules moved into subpackages by layer (``docs/architecture.md``). An old path
still imports, as the same module object under its old name, with a ``DeprecationWarning`` that
names the new path: ``import dolfinx_nnqem.stepping`` gives ``dolfinx_nnqem.solvers.stepping``.
The table :data:`MOVED` is the whole mechanism: a finder on ``sys.meta_path`` answers for these
names only.

Names that moved out of a module that stays (``contact/model.py`` split by idea, the benchmark
geometries out of ``problem/meshing.py``) are in :data:`MOVED_NAMES`; the old module's
``__getattr__`` hands them out through :func:`moved_name`, with the same warning:
``from dolfinx_nnqem.contact.model import Contact`` gives ``dolfinx_nnqem.contact.specification.Contact``,
``from dolfinx_nnqem.problem.meshing import build_two_beams`` gives
``dolfinx_nnqem.cases.geometries.build_two_beams``.

Members that moved off a class that stays (the geometry of ``ContactModel``, now
``ContactModel.geometry``) are in :data:`MOVED_MEMBERS`; :func:`install_members` gives the class a
descriptor per old name that hands out the new member with the same warning.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import operator
import sys
import warnings

__all__ = ["MOVED", "MOVED_MEMBERS", "MOVED_NAMES", "REMOVED_IN", "install_members", "moved_name"]

REMOVED_IN = "0.2"
"""The release in which the old paths stop importing."""

MOVED: dict[str, str] = {
    "amplitude": "problem.amplitude", "block_system": "solvers.block_system",
    "bodies": "problem.bodies", "checkpoint": "io.checkpoint", "checks": "solvers.checks",
    "condensation": "solvers.condensation", "convergence": "solvers.convergence", "fclib": "io.fclib",
    "field_series": "io.field_series", "hertz": "cases.hertz", "linalg": "numerics.linalg",
    "linear_solver": "solvers.linear_solver", "locking": "io.locking", "meshing": "problem.meshing",
    "monolithic": "solvers.monolithic", "newton": "numerics.newton", "nneqm1": "solvers.nneqm1",
    "nneqm2": "solvers.nneqm2", "nonsmooth": "numerics.nonsmooth", "output": "io.output", "plots": "io.plots",
    "preflight": "solvers.preflight", "pressed_blocks": "cases.pressed_blocks", "reader": "io.reader",
    "results": "io.results", "run_pictures": "io.run_pictures", "safe_io": "io.safe_io",
    "sphere_on_block": "cases.sphere_on_block", "step_control": "solvers.step_control",
    "stepping": "solvers.stepping", "two_beams": "cases.two_beams", "validation": "problem.validation",
    "solver": "solvers",
    # NNEQM2's modules in a folder of their own (issue 42)
    "solvers.nneqm2_return_map": "solvers.nneqm2.return_map", "solvers.nneqm2_frozen": "solvers.nneqm2.frozen",
    "solvers.increment_start": "solvers.nneqm2.increment_start", "solvers.gauss_points": "solvers.nneqm2.gauss_points",
}
"""Old module path (under ``dolfinx_nnqem.``) → its new path (under ``dolfinx_nnqem.``)."""

MOVED_NAMES: dict[str, dict[str, str]] = {
    "contact.model": {
        "Contact": "contact.specification", "R_RANGE": "contact.specification",
        "GeometryTracker": "contact.geometry_tracking", "LostContactError": "contact.geometry_tracking",
        "zero_displacement": "contact.geometry_tracking",
        "LawGroup": "contact.pair_laws", "PairLaws": "contact.pair_laws",
    },
    # the benchmark geometries out of the mesh reading and writing (issue 42)
    "problem.meshing": {name: "cases.geometries" for name in (
        "TwoBeamsTags", "build_two_beams", "StackedBlocksTags", "build_stacked_blocks", "BlockStackTags",
        "build_block_stack", "ThickCylinderTags", "build_thick_cylinder", "graded_nodes", "build_graded_block",
        "build_graded_contact_blocks", "SphereOnBlockTags", "build_sphere_on_block")},
}
"""Module (under ``dolfinx_nnqem.``) → its names that moved → the module they are in now."""

MOVED_MEMBERS: dict[str, dict[str, str]] = {
    "contact.model.ContactModel": {
        "current_geometry": "geometry.follows_bodies", "geometry_version": "geometry.version",
        "update_geometry": "geometry.update", "obstacle_geometry": "geometry.obstacles_follow",
        "surface_geometry": "geometry.surfaces_follow", "refresh_obstacle_geometry": "geometry.refresh_obstacles",
        "geometric_terms": "geometry.geometric_terms", "geometry_state": "geometry.state",
        "set_geometry_state": "geometry.set_state", "slipped": "geometry.slipped",
        "why_not_current": "geometry.why_not_current", "follow_bodies": "geometry.start_following",
        "pairs_may_change": "geometry.pairs_may_change", "following_bodies()": "geometry.following",
    },
}
"""Class (module under ``dolfinx_nnqem.``, then its name) → its members that moved → their path on
an instance. An old name written with ``()`` was a method whose value is now an attribute: the alias
is still called."""


def moved_name(module: str, name: str):
    """``name`` of the module ``module`` (a full name) from the module it moved to, with a
    ``DeprecationWarning`` naming the new path; :class:`AttributeError` for any other name (what a
    module-level ``__getattr__`` returns)."""
    new = MOVED_NAMES.get(module.removeprefix("dolfinx_nnqem."), {}).get(name)
    if new is None:
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    warnings.warn(f"{module}.{name} is deprecated and will be removed in dolfinx_nnqem {REMOVED_IN}; "
                  f"import it from dolfinx_nnqem.{new} instead", DeprecationWarning, stacklevel=3)
    return getattr(importlib.import_module(f"dolfinx_nnqem.{new}"), name)


class _MovedMember:
    """An old member of a class (:data:`MOVED_MEMBERS`): on an instance, the member at its new path,
    with a DeprecationWarning naming that path."""

    def __init__(self, owner: str, old: str, new: str):
        self.owner, self.old, self.new = owner, old.removesuffix("()"), new
        self.called = old.endswith("()")  # a method whose value is now an attribute

    def __get__(self, instance, owner=None):
        if instance is None:
            return self
        warnings.warn(f"{self.owner}.{self.old} is deprecated and will be removed in dolfinx_nnqem {REMOVED_IN}; "
                      f"use {self.owner}.{self.new} instead", DeprecationWarning, stacklevel=2)
        value = operator.attrgetter(self.new)(instance)
        return (lambda: value) if self.called else value


def install_members(cls: type) -> None:
    """Give ``cls`` the aliases of its members that moved (:data:`MOVED_MEMBERS`). Outside the type
    checker's view: the package itself must use the new paths."""
    owner = f"{cls.__module__.removeprefix('dolfinx_nnqem.')}.{cls.__qualname__}"
    for old, new in MOVED_MEMBERS.get(owner, {}).items():
        member = _MovedMember(f"dolfinx_nnqem.{owner}", old, new)
        if member.old in vars(cls):
            raise RuntimeError(f"{owner}.{member.old} is both a member and a moved name ({new})")
        setattr(cls, member.old, member)


class _Alias(importlib.abc.Loader):
    """Loads an old path as the module at its new path."""

    def __init__(self, new: str):
        self.new = new
        self._spec: importlib.machinery.ModuleSpec | None = None  # the new module's, kept by create_module

    def create_module(self, spec):
        warnings.warn(f"{spec.name} is deprecated and will be removed in dolfinx_nnqem {REMOVED_IN}; "
                      f"import {self.new} instead", DeprecationWarning, stacklevel=3)
        module = importlib.import_module(self.new)
        self._spec = module.__spec__
        return module

    def exec_module(self, module) -> None:
        """Nothing to run (the new module is executed); the import system has just given the module
        the old path's spec: give it back its own, so that it still knows where it lives."""
        module.__spec__ = self._spec


class _Finder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path, target=None):
        old = fullname.removeprefix("dolfinx_nnqem.")
        if old == fullname or old not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, _Alias(f"dolfinx_nnqem.{MOVED[old]}"))


def install() -> None:
    """Put the finder on ``sys.meta_path`` (once)."""
    if not any(isinstance(finder, _Finder) for finder in sys.meta_path):
        sys.meta_path.append(_Finder())
