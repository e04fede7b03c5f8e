r"""Per-cell error indicators by stress recovery (Zienkiewicz–Zhu), for the fields, the pictures and
adaptive refinement.

The Gauss-point stress σ_h of the converged state jumps between cells; its recovered field σ* is
continuous within each body: the lumped L2 projection onto P1,

    σ*_a = ∫ σ_h φ_a dx / ∫ φ_a dx

(with the state's own Gauss rule, so that σ_h enters exactly as the solver holds it; bodies in
contact share no node, so σ* is continuous within each body only, as the stress is). The
indicator of cell K is the complementary energy of the difference,

    η_K² = ∫_K (σ* − σ_h) : C⁻¹ : (σ* − σ_h) dx
         = ∫_K |dev(σ* − σ_h)|² / (2μ) + tr(σ* − σ_h)² / (9κ) dx,

an energy (J): η_K is in √J. η = (Σ η_K²)^½ estimates the error of the stress in the energy
norm, and η / (η² + ‖σ_h‖²_{C⁻¹})^½ its relative size. It is cheap (two vector assemblies and
one cell integral: no solve) and costs nothing in the contact and plastic laws; it does not see
the error of a contact pressure itself, only the stress gradients a contact or a plastic zone
makes around it, which is what refinement has to resolve.
"""

from __future__ import annotations

import dolfinx.fem as fem
import dolfinx.la
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_nnqem import jit

__all__ = ["INDICATOR_NAME", "RecoveryIndicator"]

INDICATOR_NAME = "error_indicator"
"""The name of the per-cell field (η_K, √J) in ``fields.xdmf`` and the pictures."""


def _complementary_energy(state, s) -> ufl.core.expr.Expr:
    """s : C⁻¹ : s for the isotropic elasticity of the state's cells."""
    return ufl.inner(ufl.dev(s), ufl.dev(s)) / (2 * state.mu) + ufl.tr(s) ** 2 / (9 * state.kappa)


class RecoveryIndicator:
    """η_K of the problem's converged state, refreshed by :meth:`update` (collective).

    Parameters
    ----------
    problem
        The :class:`~dolfinx_nnqem.problem.contact_problem.ContactProblem`.

    Attributes
    ----------
    function
        η_K per cell (DG0, named :data:`INDICATOR_NAME`), owned and ghost cells.
    """

    def __init__(self, problem):
        state = problem.state
        mesh = problem.mesh
        self.comm = mesh.comm
        self.function = fem.Function(fem.functionspace(mesh, ("DG", 0)), name=INDICATOR_NAME)
        self.sigma_star = fem.Function(fem.functionspace(mesh, ("Lagrange", 1, (3, 3))), name="sigma_recovered")
        P1 = fem.functionspace(mesh, ("Lagrange", 1))
        self._rhs = jit.form(ufl.inner(state.sigma_n, ufl.TestFunction(self.sigma_star.function_space)) * state.dx)
        self._lumped = jit.form(ufl.TestFunction(P1) * state.dx)
        w = ufl.TestFunction(self.function.function_space)
        self._eta2 = jit.form(w * _complementary_energy(state, self.sigma_star - state.sigma_n) * state.dx)
        self._energy = jit.form(_complementary_energy(state, state.sigma_n) * state.dx)
        self._mass: np.ndarray | None = None  # ∫ φ_a dx per node (owned and ghost), computed once

    def _assembled(self, form) -> np.ndarray:
        """A vector form assembled, summed over the ranks and scattered to the ghosts."""
        vector = fem.assemble_vector(form)
        vector.scatter_reverse(dolfinx.la.InsertMode.add)
        vector.scatter_forward()
        return vector.array

    def update(self) -> None:
        """Recover σ* and compute η_K from the current converged state."""
        if self._mass is None:
            self._mass = self._assembled(self._lumped).copy()
        rhs = self._assembled(self._rhs)
        self.sigma_star.x.array[:] = rhs / np.repeat(self._mass, 9)
        eta2 = fem.assemble_vector(self._eta2)  # a cell integral: no sum over ranks needed
        self.function.x.array[:] = np.sqrt(np.maximum(eta2.array, 0.0))
        self.function.x.scatter_forward()

    def owned(self) -> np.ndarray:
        """η_K of this rank's owned cells (after :meth:`update`)."""
        imap = self.function.function_space.dofmap.index_map
        return self.function.x.array[:imap.size_local]

    def global_estimate(self) -> tuple[float, float]:
        """(η, η relative to the energy norm of the stress) after :meth:`update` (collective)."""
        eta2 = self.comm.allreduce(float(np.sum(self.owned() ** 2)), op=MPI.SUM)
        energy = self.comm.allreduce(fem.assemble_scalar(self._energy), op=MPI.SUM)
        total = eta2 + energy
        return float(np.sqrt(eta2)), float(np.sqrt(eta2 / total)) if total > 0.0 else 0.0
