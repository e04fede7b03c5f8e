r"""Where an NNEQM2 increment starts: the elastic predictor and the data both variants share.

For the load factor ℓ, from the converged state (u_n, σ_n, p_n), with the elastic stiffness K_e
factorised once (:class:`~dolfinx_nnqem.solvers.condensation.Condensation`, generalised inverse G
where bodies float):

    b = F_ext(ℓ) − ∫ σ_n : ε(v) dx − K_e Δu_D   on the free rows,   b = Δu_D on the constrained ones,
    du_0 = G b,

Δu_D the increment of the prescribed displacements (lifted). Every displacement of the increment
is du = G (b + Bᵀλ + q) + N α for pair forces λ, the force q of the Gauss points' plastic strains
and the free rigid modes' amplitudes α: ∫ σ : ε(v) dx = F_ext + Bᵀλ holds at the free dofs with
the stress σ = σ_n + C (ε(du) − Δε_p) for every such du (equilibrium by construction), and
writing b against ∫ σ_n : ε(v) rather than the load increment keeps the previous increments'
round-off from accumulating.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from petsc4py import PETSc

from dolfinx_nnqem.contact.pair_laws import PairLaws
from dolfinx_nnqem.material.kinematics import deviator_coordinates
from dolfinx_nnqem.problem.contact_problem import ContactProblem
from dolfinx_nnqem.solvers.condensation import Condensation
from dolfinx_nnqem.solvers.nneqm2.gauss_points import GaussPointOperators
from dolfinx_nnqem.solvers.prediction import predict_increment

__all__ = ["IncrementStart", "start_increment"]


@dataclass
class IncrementStart:
    """The data of one increment both NNEQM2 variants start from.

    Attributes
    ----------
    load_factor
        ℓ.
    b, du0
        The predictor's right-hand side (a PETSc vector laid out like V) and G b (owned rows).
    F_ext
        F_ext(ℓ).
    sigma_n, s_n, p_n, internal_n
        The converged stresses (n_gp, 3, 3), their deviators (n_gp, 5), p_n (n_gp,) and every
        internal variable by name ("p": p_n) at the owned Gauss points.
    force_scale
        F = the problem's force scale with the internal force ∫ σ_n : ε(v) + K_e Δu_D.
    extrapolation
        β of the secant extrapolation of the last two increments the increment starts from (the
        problem's u and pair unknowns hold it), or None.
    laws, w_prev, z, w_start
        Gathered over the ranks (global pair order): the pair laws, w at the end of the last
        increment (NC, 3), the pair unknowns the increment starts from (NC, 3) and w where it
        starts (B u + m(ℓ) with the prescribed values applied, (NC, 3)); None without contact.
    """

    load_factor: float
    b: PETSc.Vec
    du0: np.ndarray
    F_ext: PETSc.Vec
    sigma_n: np.ndarray
    s_n: np.ndarray
    p_n: np.ndarray
    force_scale: float
    extrapolation: float | None
    laws: PairLaws | None
    w_prev: np.ndarray | None
    z: np.ndarray | None
    w_start: np.ndarray | None
    internal_n: dict[str, np.ndarray] = field(default_factory=dict)

    def destroy(self) -> None:
        """Free the vectors b and F_ext (collective)."""
        for vec in (self.b, self.F_ext):
            vec.destroy()


def start_increment(problem: ContactProblem, gp: GaussPointOperators, elastic: Condensation,
                    load_factor: float, extrapolate: bool) -> IncrementStart:
    """Start the increment as every solver does (the secant extrapolation of the last two
    increments when ``extrapolate``, the prescribed values of ℓ, the touching pairs closed:
    :func:`~dolfinx_nnqem.solvers.prediction.predict_increment`) and build the elastic predictor,
    the jump of the prescribed values in its right-hand side (collective)."""
    p, st = problem, problem.state
    # the pair unknowns start from the secant extrapolation of the last two increments; so does u,
    # where w_start (the pair branches a floating body's first step freezes) is read
    beta = predict_increment(p, load_factor, extrapolate).beta
    sigma_n = st.sigma_n.x.array[:9 * gp.n_gp].reshape(gp.n_gp, 3, 3).copy()
    F_n = gp.force(sigma_n)
    F_ext = p.external_force()
    du_D = np.zeros_like(p.u.x.array)
    du_D[p.bc_dofs] = p.u.x.array[p.bc_dofs] - st.u_n.x.array[p.bc_dofs]
    lift = gp.elastic_force(du_D)
    b = F_ext.copy()
    b.axpy(-1.0, F_n)
    b.axpy(-1.0, lift)
    owned_bc = p.owned_bc_dofs()
    b.getArray()[owned_bc] = du_D[owned_bc]
    F_n.axpy(1.0, lift)  # the internal force of σ_n and of the prescribed increments, elastically
    scale = p.force_scale(F_n, F_ext)
    du0 = elastic.solve(b)
    laws = w_prev = z = w_start = None
    if p.contact is not None:  # p.has_contact
        model = p.contact
        laws = model.gathered_laws()
        w_prev = model.gather(model.w_n)
        z = model.gather(model.z)
        w_start = model.gather(p.relative_displacement())
    start = IncrementStart(
        load_factor=float(load_factor), b=b, du0=du0.getArray(readonly=True).copy(), F_ext=F_ext,
        sigma_n=sigma_n, s_n=deviator_coordinates(sigma_n), p_n=st.p_n.x.array[:gp.n_gp].copy(),
        force_scale=scale, extrapolation=beta, laws=laws, w_prev=w_prev, z=z, w_start=w_start,
        internal_n=st.internal_at_points())
    for vec in (F_n, lift, du0):
        vec.destroy()
    return start
