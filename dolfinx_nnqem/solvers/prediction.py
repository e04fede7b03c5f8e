"""Where every solver starts an increment: the prediction of u and of the pair unknowns.

The three solvers (monolithic, NNEQM1, NNEQM2) start an increment to the load factor ℓ the same
way, here once:

1. the secant extrapolation of the last two converged increments, u ← u_n + β (u_n − u_{n−1})
   and the pair unknowns likewise, while the load path goes on in the same direction
   (:meth:`ContactProblem.extrapolate`);
2. the prescribed displacements of ℓ on the constrained dofs;
3. the pair unknowns of touching pairs closed (:meth:`ContactProblem.predict_contact`), seen in the
   predicted configuration.

What a solver does with the jump Δu_D of the prescribed values differs, and stays in the solver:
the monolithic solver and NNEQM1 take a lifted Newton step from the converged state when there was
no extrapolation (:attr:`IncrementPrediction.lift`); NNEQM2 puts the jump into its elastic
predictor's right-hand side.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

if TYPE_CHECKING:
    from dolfinx_nnqem.problem.contact_problem import ContactProblem

__all__ = ["IncrementPrediction", "lifted_residual", "newton_right_hand_side", "predict_increment"]


@dataclass(frozen=True)
class IncrementPrediction:
    """The start of an increment (:func:`predict_increment`).

    Attributes
    ----------
    extrapolated
        True if u and the pair unknowns were extrapolated from the last two increments.
    beta
        The secant factor β of the load path (``ContactProblem.extrapolation_factor``) when the
        caller asked for extrapolation, else None. Not None does not mean ``extrapolated``: a
        warm-started problem computes β but does not extrapolate.
    u_bc
        The converged values at the constrained dofs ``problem.bc_dofs``, before the prescribed
        values of ℓ were applied.
    delta_bc
        Their jump Δu_D: the prescribed values of ℓ minus ``u_bc``.
    lift
        True when the jump should be lifted by a Newton step from the converged state: it is not
        zero on some rank and u was not extrapolated (collective, the same on every rank).
    """

    extrapolated: bool
    beta: float | None
    u_bc: np.ndarray
    delta_bc: np.ndarray
    lift: bool


def predict_increment(problem: ContactProblem, load_factor: float, extrapolate: bool,
                      refresh_geometry: Callable[[], None] | None = None) -> IncrementPrediction:
    """Set u and the pair unknowns of ``problem`` to the start of the increment to ``load_factor``.

    Parameters
    ----------
    problem
        The problem; its u holds the prediction on return (the prescribed values of ℓ included).
    load_factor
        ℓ of the increment.
    extrapolate
        Whether the secant extrapolation may be used (the solver's setting).
    refresh_geometry
        Called after the prescribed values are set and before the pair unknowns are predicted,
        so that the starting active set sees the predicted configuration's gaps (the monolithic
        solver's current-geometry pairs).

    Returns
    -------
    IncrementPrediction
        What was done, and the jump of the prescribed values (collective).
    """
    p = problem
    beta = p.extrapolation_factor(load_factor) if extrapolate else None
    extrapolated = beta is not None and p.extrapolate(load_factor)
    u_bc = p.u.x.array[p.bc_dofs].copy()
    p.apply_prescribed_displacements(load_factor)
    if refresh_geometry is not None:
        refresh_geometry()
    p.predict_contact()
    delta_bc = p.u.x.array[p.bc_dofs] - u_bc
    moved = p.comm.allreduce(bool(np.any(delta_bc != 0.0)), op=MPI.LOR)
    return IncrementPrediction(extrapolated=extrapolated, beta=beta, u_bc=u_bc, delta_bc=delta_bc,
                               lift=not extrapolated and moved)


def lifted_residual(problem: ContactProblem, R_free: PETSc.Vec, delta: np.ndarray) -> PETSc.Vec:
    """R + K_t δ on the free rows: the residual a Newton step sees when it also moves the
    constrained dofs by δ (a new vector).

    The Newton matrix has identity rows and columns at the constrained dofs, so a step that moves
    them by δ (the jump Δu_D of the prescribed values, lifted) carries K_t δ
    (:meth:`ContactProblem.tangent_action`) on its right-hand side.

    Parameters
    ----------
    problem
        The problem, at the state where K_t is evaluated.
    R_free
        The residual with its constrained rows zeroed (``problem.free_residual``).
    delta
        δ: a local array (ghosts included), zero off ``problem.bc_dofs``.
    """
    K_delta = problem.tangent_action(delta)
    R_lifted = problem.free_residual(K_delta)
    R_lifted.axpy(1.0, R_free)
    K_delta.destroy()
    return R_lifted


def newton_right_hand_side(problem: ContactProblem, R_free: PETSc.Vec,
                           delta: np.ndarray | None = None) -> PETSc.Vec:
    """−(R + K_t δ) with δ in the constrained rows: the right-hand side of a Newton step for u
    that moves the constrained dofs by δ (a new vector; see :func:`lifted_residual`).

    Without ``delta``: −R, whose constrained rows are zero (a step that keeps them).
    """
    if delta is None:
        r = R_free.copy()
    else:
        r = lifted_residual(problem, R_free, delta)
    r.scale(-1.0)
    if delta is not None:  # the constrained rows of the step: the lifted jump (identity rows)
        owned = problem.owned_bc_dofs()
        r.getArray()[owned] = delta[owned]
    return r
