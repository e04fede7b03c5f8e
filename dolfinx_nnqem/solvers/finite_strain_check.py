r"""The constitutive law at every Gauss point at finite strain: part of the independent check of a
converged state when the problem's kinematics is "finite".

From the displacement itself (F = I + ∇u interpolated here, not the update's copy) and the
values the commit will store (the Kirchhoff stress τ, Δp, b_e and the internal variables after
the increment):

* **J > 0** at every Gauss point: a point where det F ≤ 0 has no stress; the failure names the
  count, the smallest J and the cells (input index, tag);
* **the logarithmic-strain route** (every small-strain material, :mod:`~dolfinx_nnqem.material.finite_strain.hencky`),
  in the logarithmic space: with the trial strain ε^tr = ½ ln(f b_e,n fᵀ), f = F F_n⁻¹, and the
  elastic strain ε_e = ½ ln b_e of the stored b_e, the plastic strain of the increment is
  Δε_p = ε^tr − ε_e, and the relations of :mod:`~dolfinx_nnqem.solvers.constitutive` are checked
  with σ ← τ, σ_n ← 0, Δε ← ε^tr: Hencky's law τ = C : ε_e, the size and direction of the flow
  Δε_p = Δp N(τ) (backward Euler), the yield function of τ with p_n + Δp (and the spatial
  back-stresses) f ≤ 0, and Δp ≥ 0 with f = 0 where Δp > 0 (consistency); each to tol · σ_u;
* **Neo-Hooke**: τ = μ (b − I) + λ ln J I with b = F Fᵀ, to tol · μ, and no plastic strain.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.material.finite_strain.gauss_state import FiniteStrainGaussState, LogarithmicLaw
from dolfinx_nnqem.solvers.constitutive import ConstitutiveCheck, check_constitutive_law

__all__ = ["check_finite_strain_law", "inverted_points"]


def inverted_points(state: FiniteStrainGaussState, F: np.ndarray) -> str:
    """The check's sentence for the owned Gauss points with det F ≤ 0 (collective; empty if none)."""
    J = np.linalg.det(F)
    bad = np.flatnonzero(~(J > 0.0))
    comm = state.mesh.comm
    count = comm.allreduce(len(bad), op=MPI.SUM)
    if not count:
        return ""
    smallest = comm.allreduce(float(np.min(J, initial=np.inf)), op=MPI.MIN)
    points_per_cell = state.W_scalar.dofmap.list.shape[1]
    cells = np.unique(np.argwhere(np.isin(state.W_scalar.dofmap.list, bad))[:, 0])
    named = sorted(set(int(i) for part in comm.allgather(state.mesh.topology.original_cell_index[cells].tolist())
                       for i in part))
    return (f"det F <= 0 at {count} Gauss point(s) (smallest J = {smallest:.4g}; {points_per_cell} points a cell): "
            f"the material is inverted there, in input cell(s) {named[:5]}{' and more' if len(named) > 5 else ''}")


def check_finite_strain_law(state: FiniteStrainGaussState, u, F: np.ndarray) -> ConstitutiveCheck:
    """The relations of the module docstring at the owned Gauss points (collective), for the
    deformation gradients ``F`` (n, 3, 3) of ``u`` at the owned points; call with J > 0 everywhere."""
    comm = state.mesh.comm
    worst = np.zeros(5)
    for law in state.law_values(u, F):  # the same bodies, in the same order, on every rank (collective calls)
        if isinstance(law, LogarithmicLaw):  # the logarithmic route
            result = check_constitutive_law(comm, law.trial_strain, law.tau, law.dp, law.plastic_strain,
                                            "backward-euler", np.zeros_like(law.tau), law.internal, law.material)
            worst = np.maximum(worst, np.asarray(result))
        else:  # Neo-Hooke
            worst = np.maximum(worst, _neo_hooke_law(comm, law.F, law.tau, law.dp, law.mu, law.lmbda))
    return ConstitutiveCheck(*worst.tolist())


def _neo_hooke_law(comm, F: np.ndarray, tau: np.ndarray, dp: np.ndarray, mu: np.ndarray,
                   lmbda: np.ndarray) -> np.ndarray:
    """(τ − μ (b − I) − λ ln J I)/μ and |Δp| (as the elasticity and complementarity relations), largest over all ranks."""
    J = np.linalg.det(F)
    b = F @ np.swapaxes(F, 1, 2)
    expected = mu[:, None, None] * (b - np.eye(3)) + (lmbda * np.log(J))[:, None, None] * np.eye(3)
    elasticity = np.linalg.norm((tau - expected).reshape(-1, 9), axis=1) / mu
    local = np.array([np.max(elasticity, initial=0.0), 0.0, 0.0, 0.0, np.max(np.abs(dp), initial=0.0)])
    every = np.empty_like(local)
    comm.Allreduce(local, every, op=MPI.MAX)
    return every
