"""Finite-strain constitutive updates at Gauss points, on numpy arrays (issue 41, first layer).

* :mod:`.interface` — the :class:`FiniteStrainMaterial` Protocol, its state and its answer;
* :mod:`.hencky` — every small-strain material of :mod:`dolfinx_nnqem.material` at finite strain by
  the logarithmic strain and the exponential map (:class:`HenckyAtPoints`);
* :mod:`.neo_hooke` — the compressible Neo-Hookean law (:class:`NeoHooke`);
* :mod:`.spectral` — ln, exp and their derivatives for symmetric tensors, the polar decomposition.

:mod:`.gauss_state` wires them into the forms (``ContactProblem(..., kinematics="finite")``;
``docs/materials.md``, "Finite strain").
"""

from __future__ import annotations

import numpy as np

from dolfinx_nnqem.material.drucker_prager import DruckerPrager, DruckerPragerAtPoints, _Cone
from dolfinx_nnqem.material.elastic import Elastic, ElasticAtPoints
from dolfinx_nnqem.material.finite_strain.hencky import SUPPORTED_POINTWISE, HenckyAtPoints
from dolfinx_nnqem.material.finite_strain.interface import (FiniteStrainMaterial, FiniteStrainResponse,
                                                            FiniteStrainState)
from dolfinx_nnqem.material.finite_strain.neo_hooke import NeoHooke, NeoHookeAtPoints
from dolfinx_nnqem.material.hardening import HardeningAtPoints
from dolfinx_nnqem.material.interface import PointwiseMaterial
from dolfinx_nnqem.material.isotropic import IsotropicAtPoints
from dolfinx_nnqem.material.kinematic import KinematicAtPoints, back_stress_names
from dolfinx_nnqem.material.von_mises import ELASTIC_YIELD_STRESS, VonMises, VonMisesAtPoints

__all__ = ["SUPPORTED_POINTWISE", "FiniteStrainMaterial", "FiniteStrainResponse", "FiniteStrainState",
           "HenckyAtPoints", "NeoHooke", "NeoHookeAtPoints", "finite_strain_material", "pointwise_material"]


def pointwise_material(material: object, n: int) -> PointwiseMaterial:
    """The small-strain pointwise form (:class:`~dolfinx_nnqem.material.interface.PointwiseMaterial`)
    of ``material`` at n Gauss points, without a mesh (the parts' ``at_points`` give the same on one).

    Raises
    ------
    TypeError
        A material with no pointwise form here, named.
    """
    zeros = np.zeros(n, dtype=np.int64)
    if isinstance(material, Elastic):
        return ElasticAtPoints(np.full(n, material.mu), np.full(n, material.lmbda), np.full(n, material.E))
    if isinstance(material, VonMises):
        mu, lmbda, E = np.full(n, material.mu), np.full(n, material.lmbda), np.full(n, material.E)
        if material.kinematic:
            law = HardeningAtPoints(zeros, [material.isotropic_law])
            C = np.tile([b.C for b in material.kinematic], (n, 1))
            gamma = np.tile([b.gamma for b in material.kinematic], (n, 1))
            return KinematicAtPoints(mu, lmbda, E, law, C, gamma, tuple(back_stress_names(len(material.kinematic))))
        if material.hardening is None:
            sigma_y0 = material.sigma_y0 if np.isfinite(material.sigma_y0) else ELASTIC_YIELD_STRESS
            return VonMisesAtPoints(mu, lmbda, np.full(n, sigma_y0), np.full(n, material.H), E)
        return IsotropicAtPoints(mu, lmbda, E, HardeningAtPoints(zeros, [material.hardening]))
    if isinstance(material, DruckerPrager):
        eta, xi, eta_bar = material.coefficients
        mu, lmbda = np.full(n, material.mu), np.full(n, material.lmbda)
        cone = _Cone(mu, lmbda + 2.0 * mu / 3.0, np.full(n, eta), np.full(n, xi), np.full(n, eta_bar),
                     HardeningAtPoints(zeros, [material.cohesion_law]))
        return DruckerPragerAtPoints(cone, lmbda, np.full(n, material.E))
    raise TypeError(f"{type(material).__name__} has no finite-strain form: the logarithmic-strain route takes "
                    "VonMises (any isotropic hardening, back-stresses), DruckerPrager or Elastic; NeoHooke is "
                    "hyperelastic of its own")


def finite_strain_material(material: object, n: int) -> FiniteStrainMaterial:
    """``material`` at n Gauss points at finite strain: :class:`NeoHookeAtPoints` for a
    :class:`NeoHooke`, the logarithmic-strain route (:class:`HenckyAtPoints`) for a small-strain
    material of :mod:`dolfinx_nnqem.material`.

    Raises
    ------
    TypeError
        A material with no finite-strain form, named.
    """
    if isinstance(material, NeoHooke):
        return material.at_points(n)
    return HenckyAtPoints(pointwise_material(material, n))
