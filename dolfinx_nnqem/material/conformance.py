"""The materials, held to the interface's Protocols by the type checker.

Each function returns an implementation as its Protocol; mypy (run by ``.ci/run``) verifies that
the implementation has every member with compatible signatures, and ``tests/unit/test_contracts.py``
calls them on real objects. A new material adds its classes here (``CONTRIBUTING.md``).
"""

from __future__ import annotations

from dolfinx_nnqem.material.composite import CompositeAtPoints
from dolfinx_nnqem.material.drucker_prager import DruckerPrager, DruckerPragerAtPoints, DruckerPragerPart
from dolfinx_nnqem.material.elastic import Elastic, ElasticAtPoints, ElasticPart
from dolfinx_nnqem.material.finite_strain import FiniteStrainMaterial, HenckyAtPoints, NeoHooke, NeoHookeAtPoints
from dolfinx_nnqem.material.finite_strain.gauss_state import FiniteStrainGaussState
from dolfinx_nnqem.material.interface import Material, MaterialPart, MaterialState, PointwiseMaterial
from dolfinx_nnqem.material.isotropic import IsotropicAtPoints, IsotropicHardeningPart
from dolfinx_nnqem.material.kinematic import KinematicAtPoints, KinematicHardeningPart
from dolfinx_nnqem.material.state import GaussPointState
from dolfinx_nnqem.material.von_mises import VonMises, VonMisesAtPoints, VonMisesPart

__all__ = ["as_finite_strain_material", "as_material", "as_material_part", "as_material_state", "as_pointwise_material",
           "as_pointwise_plasticity"]


def as_material(material: VonMises | Elastic | DruckerPrager | NeoHooke) -> Material:
    """``material`` as the :class:`~dolfinx_nnqem.material.interface.Material` Protocol."""
    return material


def as_material_part(part: VonMisesPart | IsotropicHardeningPart | KinematicHardeningPart | DruckerPragerPart
                     | ElasticPart) -> MaterialPart:
    """``part`` as the :class:`~dolfinx_nnqem.material.interface.MaterialPart` Protocol."""
    return part


def as_material_state(state: GaussPointState | FiniteStrainGaussState) -> MaterialState:
    """``state`` as the :class:`~dolfinx_nnqem.material.interface.MaterialState` Protocol."""
    return state


def as_pointwise_material(points: VonMisesAtPoints | IsotropicAtPoints | KinematicAtPoints | DruckerPragerAtPoints
                          | ElasticAtPoints | CompositeAtPoints) -> PointwiseMaterial:
    """``points`` as the :class:`~dolfinx_nnqem.material.interface.PointwiseMaterial` Protocol."""
    return points



def as_finite_strain_material(points: HenckyAtPoints | NeoHookeAtPoints) -> FiniteStrainMaterial:
    """``points`` as the :class:`~dolfinx_nnqem.material.finite_strain.interface.FiniteStrainMaterial` Protocol."""
    return points


as_pointwise_plasticity = as_pointwise_material
