"""Bulk materials: von Mises plasticity with linear isotropic hardening (:mod:`.von_mises`), written
in UFL with its state in quadrature spaces, behind the interface the problem and the solvers use
(:mod:`.interface`)."""

from dolfinx_nnqem.material.interface import Material, MaterialState, PointwisePlasticity
from dolfinx_nnqem.material.von_mises import (DEVIATORIC_BASIS, ELASTIC_YIELD_STRESS, GaussPointValues,
                                              PlasticState, ReturnMap, VonMises, VonMisesAtPoints, can_yield,
                                              deviator_coordinates, deviator_tensors, elastic_stress,
                                              equivalent_stress, flow_direction, radial_return,
                                              return_map_plastic_strain, return_map_tangent, strain,
                                              von_mises_stress, yield_function, yield_stress_unit)

__all__ = ["DEVIATORIC_BASIS", "ELASTIC_YIELD_STRESS", "GaussPointValues", "Material", "MaterialState",
           "PlasticState", "PointwisePlasticity", "ReturnMap", "VonMises", "VonMisesAtPoints", "can_yield",
           "deviator_coordinates", "deviator_tensors", "elastic_stress", "equivalent_stress", "flow_direction",
           "radial_return", "return_map_plastic_strain", "return_map_tangent", "strain", "von_mises_stress",
           "yield_function", "yield_stress_unit"]
