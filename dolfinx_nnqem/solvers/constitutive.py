r"""The constitutive law checked at every Gauss point: part of the independent check of a converged state.

The Gauss-point values an increment will commit — the stress σ, the equivalent plastic strain
increment Δp and the plastic strain increment Δε_p, whether a solver computed them itself
(NNEQM2, :class:`~dolfinx_nnqem.material.interface.GaussPointValues`) or the material's return map
at u gives them (the monolithic solver, NNEQM1) — must satisfy, with Δε = ε(u) − ε(u_n) from the
displacement itself:

* elasticity: σ = σ_n + C (Δε − Δε_p), i.e. σ = C (ε − ε_p);
* the plastic strain: of the size Δp says, |Δε_p| = Δp |N|, with the volumetric part N gives
  (none for von Mises: √(3/2) Δp, deviatoric), i.e. ε_p,n+1 − ε_p,n = Δγ N and p_n+1 = p_n + Δγ;
* the flow direction of the rule the values claim: for "backward-euler" Δε_p = Δp N(σ), N the
  material's flow direction at the end of the increment ((3/2) s / q for von Mises); for
  "frozen-directions" (NNEQM2's seed variant, the directions of the increment's start) the size
  relation above only;
* admissibility and complementarity: Δp ≥ 0, f(σ, p_n + Δp) ≤ 0, and f = 0 where Δp > 0
  (Δγ f = 0), f the material's own yield function.

Each relation is measured in stress units over σ_u (the material's stress unit, min(σ_y0, 10⁻² E)
for von Mises; plastic strains times 2μ or 3μ + H') and must hold to the check's tolerance at
every Gauss point; the points of an elastic material must have no plastic strain at all. The
material enters only through its :class:`~dolfinx_nnqem.material.interface.PointwiseMaterial`:
each material's yield function and flow direction judge its own points.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.material.interface import PointwiseMaterial
from dolfinx_nnqem.material.kinematics import elastic_stress, symmetric_coordinates

__all__ = ["ConstitutiveCheck", "check_constitutive_law"]

_SQRT32 = math.sqrt(1.5)
_SQRT3 = math.sqrt(3.0)


class ConstitutiveCheck(NamedTuple):
    """The largest violation of each relation over all Gauss points (over σ_u), every rank the same."""

    elasticity: float
    plastic_strain: float  #: |Δε_p| = Δp |N|, its volumetric part Δp tr N (deviatoric von Mises: √(2/3)|Δε_p| = Δp)
    flow_direction: float  #: backward Euler: Δε_p = Δp N at the end stress (0 for frozen directions)
    yield_surface: float  #: max(f, 0)
    complementarity: float  #: |f| where Δp > 0, and −Δp where Δp < 0


CHUNK = 65_536
"""Gauss points checked at once: the check's arrays (a dozen of n × 9 values) stay small on any
mesh (at 10⁶ dofs, 1.3 million points per rank, the whole arrays took over a gigabyte)."""


def check_constitutive_law(comm: MPI.Comm, strain_increment: np.ndarray, sigma: np.ndarray, dp: np.ndarray,
                           deps_p: np.ndarray, flow_rule: str, sigma_n: np.ndarray,
                           internal: Mapping[str, np.ndarray], material: PointwiseMaterial) -> ConstitutiveCheck:
    """The relations of the module docstring at this rank's owned Gauss points (collective).

    Parameters
    ----------
    strain_increment, sigma, deps_p, sigma_n
        (n, 3, 3) Δε, σ, Δε_p and σ_n.
    dp
        (n,) Δp.
    flow_rule
        "backward-euler" or "frozen-directions".
    internal
        The internal variables at the end of the increment, by name ("p": p_n + Δp).
    material
        The material at the same Gauss points.
    """
    if flow_rule not in ("backward-euler", "frozen-directions"):
        raise ValueError(f"unknown flow rule {flow_rule!r}: expected 'backward-euler' or 'frozen-directions'")
    worst = np.zeros(5)
    for start in range(0, len(dp), CHUNK):  # the same values point by point; the largest of each
        part = slice(start, start + CHUNK)
        worst = np.maximum(worst, _largest_violations(
            strain_increment[part], sigma[part], dp[part], deps_p[part], flow_rule, sigma_n[part],
            {name: np.asarray(v)[part] for name, v in internal.items()}, material.subset(part)))
    every = np.empty_like(worst)
    comm.Allreduce(worst, every, op=MPI.MAX)
    return ConstitutiveCheck(*every.tolist())


def _largest_violations(strain_increment, sigma, dp, deps_p, flow_rule, sigma_n, internal, material) -> np.ndarray:
    """The largest violation of each relation (the order of :class:`ConstitutiveCheck`) at these points."""
    mu, su, yields = material.mu, material.stress_unit, material.yields
    H = material.hardening(internal)
    sigma_expected = sigma_n + elastic_stress(strain_increment - deps_p, material.lmbda, mu)
    elasticity = np.linalg.norm((sigma - sigma_expected).reshape(-1, 9), axis=1) / su
    s = symmetric_coordinates(sigma)
    e = symmetric_coordinates(deps_p)
    N = material.flow_direction_of(s, e, dp, internal)  # at a cone's apex, the normal nearest the flow
    f = material.yield_value(s, internal)
    size = np.linalg.norm(deps_p.reshape(-1, 9), axis=1)  # |Δε_p| (Frobenius)
    # |N| where the end stress gives one; where it gives none no point may flow (Δp must be 0)
    N_norm = np.linalg.norm(N, axis=1)
    N_size = np.where(N_norm > 0.0, N_norm, _SQRT32)
    volumetric = _SQRT3 * np.abs(e[:, 5] - dp * N[:, 5])  # |tr Δε_p − Δp tr N|
    plastic_strain = (2.0 * mu * volumetric + (3.0 * mu + H) * np.abs(size / N_size - dp)) / su
    if flow_rule == "backward-euler":
        flow = 2.0 * mu * np.linalg.norm(e - dp[:, None] * N, axis=1) / su
    else:
        flow = np.zeros_like(dp)
    yield_surface = np.where(yields, np.maximum(f, 0.0) / su, 0.0)
    complementarity = np.where(dp > 0.0, np.abs(f) / su, np.maximum(-dp, 0.0) * (3.0 * mu + H) / su)
    # a material that cannot yield has no plastic strain whatever its stress
    elastic = ~yields
    plastic_strain[elastic] = (2.0 * mu[elastic] * size[elastic] + (3.0 * mu[elastic] + H[elastic])
                               * np.abs(dp[elastic])) / su[elastic]
    complementarity[elastic] = 0.0
    flow[elastic] = 0.0

    return np.array([float(np.max(v, initial=0.0))
                     for v in (elasticity, plastic_strain, flow, yield_surface, complementarity)])
