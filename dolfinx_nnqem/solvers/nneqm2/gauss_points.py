"""The Gauss-point operators NNEQM2 works with: strains at the Gauss points, the force of a
quadrature stress, the material values there, and the bookkeeping of the points that can yield.

NNEQM2 writes the yield conditions of every Gauss point of a material that can yield (an elastic
material's points, σ_y0 = inf, carry no unknown) as equations of its own, so it needs, beside
the problem's forms: the strain operator A (rows (j, kl) of the owned Gauss points: A u =
w_j ε_j(u)_kl, w_j the quadrature weight times det J), the quadrature force ∫ σ : ε(v) dx of
Gauss-point stresses, and the Gauss points' material values. Deviatoric tensors are handled in
the orthonormal coordinates of :data:`~dolfinx_nnqem.material.kinematics.DEVIATORIC_BASIS`.
"""

from __future__ import annotations

import dolfinx.fem as fem
import dolfinx.fem.petsc
import numpy as np
import ufl
from petsc4py import PETSc

from dolfinx_nnqem import jit
from dolfinx_nnqem.material.kinematics import DEVIATORIC_BASIS, deviator_coordinates, strain
from dolfinx_nnqem.problem.contact_problem import ContactProblem, assemble_vector

__all__ = ["GaussPointOperators"]


class GaussPointOperators:
    """Strain operator, quadrature force and material values at this rank's owned Gauss points.

    ``n_gp`` counts the owned Gauss points; ``material`` is the material there
    (:class:`~dolfinx_nnqem.material.interface.PointwisePlasticity`), with its elastic moduli
    ``mu``, ``lmbda``, the yield rows' stress unit ``stress_unit`` and the points that can yield
    ``yields`` at hand; ``n_yield``, ``offset`` and ``num_yield_points`` count the owned yielding
    points, give their offset in the numbering over the ranks, and count them over all ranks.
    """

    def __init__(self, problem: ContactProblem):
        self.problem = problem
        st = problem.state
        V, Wt, Ws = problem.V, st.W_tensor, st.W_scalar
        du, tau = ufl.TrialFunction(V), ufl.TestFunction(Wt)
        self.A = dolfinx.fem.petsc.assemble_matrix(jit.form(ufl.inner(strain(du), tau) * st.dx))
        self.A.assemble()
        weights = assemble_vector(jit.form(ufl.TestFunction(Ws) * st.dx), Ws)
        self.n_gp = Ws.dofmap.index_map.size_local
        self.weights = weights.getArray(readonly=True)[:self.n_gp].copy()
        weights.destroy()
        if self.A.getLocalSize()[0] != 9 * self.n_gp:
            raise RuntimeError("NNEQM2: the strain operator's rows do not match the Gauss points")
        self.material = st.at_points()
        self.mu, self.lmbda = self.material.mu, self.material.lmbda
        self.stress_unit, self.yields = self.material.stress_unit, self.material.yields
        self.n_yield = int(np.count_nonzero(self.yields))
        counts = problem.comm.allgather(self.n_yield)
        self.offset = int(sum(counts[:problem.comm.rank]))
        self.num_yield_points = int(sum(counts))
        v = ufl.TestFunction(V)
        self._sigma = fem.Function(Wt)
        self._force_form = jit.form(ufl.inner(self._sigma, strain(v)) * st.dx)
        self._lift_u = fem.Function(V)
        self._lift_form = jit.form(ufl.inner(st.elastic_stress(strain(self._lift_u)), strain(v)) * st.dx)
        self._strain = self.A.createVecLeft()

    # -- fields at the Gauss points ------------------------------------------------------------------
    def strains(self, vec: PETSc.Vec) -> np.ndarray:
        """ε_j(u) at the owned Gauss points, (n_gp, 3, 3), for a vector laid out like V."""
        self.A.mult(vec, self._strain)
        return self._strain.getArray(readonly=True).reshape(self.n_gp, 3, 3) / self.weights[:, None, None]

    def deviatoric_strains(self, vec: PETSc.Vec) -> np.ndarray:
        """dev ε_j(u) at the owned Gauss points, in deviator coordinates (n_gp, 5)."""
        return deviator_coordinates(self.strains(vec))

    def dev_strains_of_columns(self, Y: PETSc.Mat) -> np.ndarray:
        """dev ε_j of every column of the dense matrix Y at the owned Gauss points that can yield,
        gathered over the ranks: (NG, 5, ncols)."""
        AY = self.A.matMult(Y)
        ncols = Y.getSize()[1]
        e9 = AY.getDenseArray().reshape(self.n_gp, 9, ncols)
        e5 = (DEVIATORIC_BASIS @ e9.transpose(1, 0, 2).reshape(9, -1)).reshape(5, self.n_gp, ncols)
        AY.destroy()
        return self.gather_yielding(e5.transpose(1, 0, 2) / self.weights[:, None, None])

    def force(self, sigma: np.ndarray) -> PETSc.Vec:
        """∫ σ : ε(v) dx for owned Gauss-point stresses (n_gp, 3, 3) (a new vector)."""
        self._sigma.x.array[:9 * self.n_gp] = np.asarray(sigma).reshape(-1)
        self._sigma.x.scatter_forward()
        return assemble_vector(self._force_form, self.problem.V)

    def elastic_force(self, displacement: np.ndarray) -> PETSc.Vec:
        """K_e g with no row or column removed, for a displacement ``g`` (local array, ghosts
        included): the lifting of prescribed increments."""
        self._lift_u.x.array[:] = displacement
        return assemble_vector(self._lift_form, self.problem.V)

    # -- the points that can yield, over the ranks --------------------------------------------------
    def gather(self, local: np.ndarray) -> np.ndarray:
        """Owned Gauss-point rows of every rank, in global Gauss-point order, on every rank."""
        comm = self.problem.comm
        if comm.size == 1:
            return np.asarray(local)
        return np.concatenate(comm.allgather(np.ascontiguousarray(local)), axis=0)

    def gather_yielding(self, local: np.ndarray) -> np.ndarray:
        """The rows of the owned Gauss points that can yield, gathered (global order, every rank)."""
        return self.gather(np.asarray(local)[self.yields])

    def local_yielding(self, gathered: np.ndarray) -> np.ndarray:
        """This rank's rows of a gathered array over the Gauss points that can yield."""
        return gathered[self.offset:self.offset + self.n_yield]

    def owned(self, gathered: np.ndarray) -> np.ndarray:
        """A gathered array over the points that can yield, at every owned Gauss point (0 at the
        elastic ones)."""
        local = self.local_yielding(gathered)
        out = np.zeros((self.n_gp,) + local.shape[1:])
        out[self.yields] = local
        return out

    def destroy(self) -> None:
        """Free the PETSc objects of the operators (collective)."""
        self.A.destroy()
        self._strain.destroy()
