"""Bulk materials behind one interface (:mod:`.interface`): von Mises plasticity with isotropic
hardening of any shape (:mod:`.von_mises`, :mod:`.isotropic`, :mod:`.hardening`) and kinematic
hardening (:mod:`.kinematic`), Drucker–Prager (:mod:`.drucker_prager`) and linear elasticity
(:mod:`.elastic`); the mesh-wide Gauss-point state built from them (:mod:`.state`); the
kinematics and tensor algebra they share (:mod:`.kinematics`); finite strain (:mod:`.finite_strain`:
every material above by the logarithmic strain, and the Neo-Hookean law ``NeoHooke``)."""

from dolfinx_nnqem.material.drucker_prager import DruckerPrager
from dolfinx_nnqem.material.elastic import Elastic
from dolfinx_nnqem.material.finite_strain.neo_hooke import NeoHooke
from dolfinx_nnqem.material.hardening import LinearHardening, TabulatedHardening, VoceHardening
from dolfinx_nnqem.material.kinematic import BackStress
from dolfinx_nnqem.material.interface import (GaussPointValues, Material, MaterialPart, MaterialState,
                                              PointwiseMaterial, PointwisePlasticity)
from dolfinx_nnqem.material.kinematics import (DEVIATORIC_BASIS, deviator_coordinates, deviator_tensors,
                                               elastic_stress, equivalent_stress, strain, von_mises_stress)
from dolfinx_nnqem.material.state import GaussPointState, material_state
from dolfinx_nnqem.material.von_mises import (ELASTIC_YIELD_STRESS, PlasticState, ReturnMap, VonMises, VonMisesAtPoints,
                                              can_yield, flow_direction, radial_return, return_map_plastic_strain,
                                              return_map_tangent, yield_function, yield_stress_unit)

__all__ = ["DEVIATORIC_BASIS", "ELASTIC_YIELD_STRESS", "BackStress", "DruckerPrager", "Elastic", "GaussPointState", "GaussPointValues",
           "LinearHardening", "Material", "MaterialPart", "MaterialState", "NeoHooke", "PlasticState", "PointwiseMaterial",
           "PointwisePlasticity", "ReturnMap", "TabulatedHardening", "VoceHardening", "VonMises", "VonMisesAtPoints",
           "can_yield", "deviator_coordinates", "deviator_tensors", "elastic_stress", "equivalent_stress",
           "flow_direction", "material_state", "radial_return", "return_map_plastic_strain", "return_map_tangent",
           "strain", "von_mises_stress", "yield_function", "yield_stress_unit"]
