"""The kinematics a problem is solved with, chosen per problem: ``ContactProblem(..., kinematics=...)``.

* ``"small"`` (the default): ε = sym ∇u, the small-strain Gauss-point state
  (:class:`~dolfinx_nnqem.material.state.GaussPointState`);
* ``"finite"``: the total Lagrangian formulation, F = I + ∇u, the forms on the reference
  configuration with the first Piola–Kirchhoff stress
  (:class:`~dolfinx_nnqem.material.finite_strain.gauss_state.FiniteStrainGaussState`; every
  small-strain material by the logarithmic strain, and ``NeoHooke``).

Both states answer to the :class:`~dolfinx_nnqem.material.interface.MaterialState` Protocol; the
problem and the solvers see no other difference (NNEQM2, whose Gauss-point rows are small-strain,
refuses ``"finite"``). ``docs/materials.md``, "Finite strain".
"""

from __future__ import annotations

from collections.abc import Mapping

import dolfinx.fem as fem

from dolfinx_nnqem.material.finite_strain.gauss_state import FiniteStrainGaussState
from dolfinx_nnqem.material.state import GaussPointState

__all__ = ["KINEMATICS", "checked_kinematics", "kinematics_of", "material_state_of"]

KINEMATICS = ("small", "finite")
"""The kinematics a problem takes."""


def checked_kinematics(kinematics: object, materials: object) -> str:
    """``kinematics`` if it is one of :data:`KINEMATICS` and the materials can take it.

    Raises
    ------
    ValueError
        Another value (named, with the choices), or a ``NeoHooke`` material with ``"small"`` (its
        law is written in F: no small-strain form).
    """
    if not isinstance(kinematics, str) or kinematics not in KINEMATICS:
        raise ValueError(f"kinematics = {kinematics!r}: expected 'small' (ε = sym grad u) or 'finite' "
                         "(total Lagrangian, F = I + grad u)")
    if kinematics == "small":
        given = materials.items() if isinstance(materials, Mapping) else [(None, materials)]
        for tag, material in given:
            if getattr(material, "part_kind", None) == "neo-hooke":
                where = "materials" if tag is None else f"materials[{tag}]"
                raise ValueError(f"{where} is NeoHooke, a finite-strain hyperelastic law (its stress is written in "
                                 "F = I + grad u) that has no small-strain form: build the problem with "
                                 "kinematics = 'finite', or use Elastic (its linearisation) at small strain")
    return kinematics


def material_state_of(kinematics: str, V: fem.FunctionSpace, materials, cell_tags,
                      quadrature_degree: int) -> GaussPointState | FiniteStrainGaussState:
    """The Gauss-point state of the mesh of ``V`` for ``kinematics`` (checked by :func:`checked_kinematics`)."""
    if kinematics == "finite":
        return FiniteStrainGaussState(V, materials, cell_tags, quadrature_degree)
    return GaussPointState(V, materials, cell_tags, quadrature_degree)


def kinematics_of(problem: object) -> str:
    """The kinematics of ``problem`` ("small" for a problem object without the attribute)."""
    return getattr(problem, "kinematics", "small")
