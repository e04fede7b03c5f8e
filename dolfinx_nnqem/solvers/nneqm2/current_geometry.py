r"""NNEQM2 in the current contact geometry (``Contact(geometry="current")``, or ``"auto"`` past the slip limit).

At small strain the elastic stiffness K_e does not depend on where the bodies are: only the pair
operator B (the pairs, their frames and weights) and the gaps g0 do. NNEQM2 keeps its K_e
factorisation for the whole run and follows the pairs as NNEQM1 does:

* within a solve the geometry is frozen (B and g0 of the last evaluation, the gap expanded to
  first order about it); what the solver built on B is forgotten when the geometry changed
  (:meth:`GeometryFollower.follow`): Bᵀ, the pair flexibility and B N of both condensations (the
  return-map variant makes its flexibility B G_t Bᵀ from K_t at every step anyway; the frozen
  variant's G Bᵀ, W_BB = B G Bᵀ and dev ε(G Bᵀ) are made again from the same K_e factorisation:
  3NC back-solves, no factorisation);
* load stepping (:func:`~dolfinx_nnqem.solvers.stepping.solve_load_steps`) evaluates the geometry
  where the increment starts, solves, evaluates it again at the solution and solves again, until
  a solve starts converged: the fixed point of "the geometry the solution was computed in" and
  "the geometry at the solution".

NNEQM2's displacement is a function of its unknowns, du = G (b + Bᵀλ + q) + N α, so a repeated
solve that started from the last solution's unknowns would move u with the new B even where it
takes no iteration. The repeated solve therefore first asks whether the last solution, unchanged
(u, z and the Gauss-point values), already satisfies every equation in the geometry evaluated at
that very u (:func:`settled`):

* equilibrium with NNEQM2's own stresses and the new B, |R_free| ≤ tol · F at the free dofs
  (this holds by construction in the geometry of the solve, not in the new one);
* the pair laws H(w, z) at w = B u + m(ℓ) with the new B and g0, |H| ≤ tol · F;
* the Gauss points' rows do not depend on the geometry (u and Δε_p are unchanged): they hold as
  the last solve left them.

If so, the increment ends there with no iteration (and load stepping stops repeating it; a
repeated solve that did not settle but moved u reports at least one iteration, so that the
geometry is evaluated again: :meth:`GeometryFollower.moved`): the
committed state meets equilibrium, the material law at every Gauss point and the contact law at
every pair in the geometry at its own displacement, to the solver's tolerance — the fixed point's
tolerance is the solver's (tol = rtol + atol / F). Else the solve starts from that state: its
first step is linearised there (not at u_n with the prescribed jump lifted). The independent
check (:mod:`~dolfinx_nnqem.solvers.checks`) then measures the same three things, with the
model's B, which is the geometry at the committed u.
"""

from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.material.interface import GaussPointValues
from dolfinx_nnqem.numerics.linalg import global_norm, vec_norm
from dolfinx_nnqem.problem.contact_problem import ContactProblem
from dolfinx_nnqem.solvers.convergence import IterationRecord, count_states
from dolfinx_nnqem.solvers.nneqm2.gauss_points import GaussPointOperators
from dolfinx_nnqem.solvers.nneqm2.increment_start import IncrementStart

__all__ = ["GeometryFollower", "settled"]


class GeometryFollower:
    """What an NNEQM2 solver keeps to follow a contact geometry that moves with the bodies.

    Parameters
    ----------
    problem
        The problem.
    forget
        Called (collectively) when the geometry changed since the last solve: the solver forgets
        what it built on B.
    """

    def __init__(self, problem: ContactProblem, forget):
        self.problem = problem
        self._forget = forget
        model = problem.contact
        self._version = model.geometry.version if model is not None else 0
        self._last: tuple[float, GaussPointValues] | None = None  # the load factor and values of the last solve

    @property
    def follows(self) -> bool:
        """True if some interface is in the current geometry now (from the start, or moved there by
        ``geometry = "auto"``): only then does load stepping repeat a solve in a re-evaluated geometry."""
        model = self.problem.contact
        return model is not None and model.geometry.follows_bodies

    def follow(self) -> None:
        """Forget what was built on B if the geometry changed since the last call (collective: the
        version moves on every rank together)."""
        model = self.problem.contact
        if model is None or model.geometry.version == self._version:
            return
        self._version = model.geometry.version
        self._forget()

    def remember(self, load_factor: float, values: GaussPointValues) -> None:
        """The converged solve's load factor and Gauss-point values (their u is the solution)."""
        self._last = (float(load_factor), values)

    def moved(self, iterations: int, last: GaussPointValues) -> int:
        """The iterations to report for a repeated solve that did not settle: at least one where its
        u differs from ``last.u``, where the geometry was evaluated (collective). Its Newton driver
        can stop at its start with no iteration (the frozen variant's dense solves started
        converged, say) although its displacement, G (b + Bᵀλ + q) + N α with the new B, is not the
        last one; load stepping repeats a solve until one takes no iteration, and must evaluate the
        geometry again at this u."""
        same = bool(np.array_equal(last.u, self.problem.u.x.array))
        return iterations if iterations or self.problem.comm.allreduce(same, op=MPI.LAND) else 1

    def repeated(self, load_factor: float) -> GaussPointValues | None:
        """The last solve's values if this solve repeats it in a re-evaluated geometry: the problem
        warm-started at the last solution of the same load factor (collective); else None."""
        p, last = self.problem, self._last
        self._last = None
        if not (p.warm_start and self.follows) or last is None or last[0] != float(load_factor):
            return None
        same = bool(np.array_equal(last[1].u, p.u.x.array))
        return last[1] if p.comm.allreduce(same, op=MPI.LAND) else None


def settled(problem: ContactProblem, gp: GaussPointOperators, values: GaussPointValues, start: IncrementStart,
            tol: float) -> tuple[bool, IterationRecord]:
    """Whether the problem's u and pair unknowns with the Gauss-point ``values`` (the last solve's,
    at that u) satisfy equilibrium and the pair laws in the problem's present contact geometry,
    each to ``tol`` · F (F = ``start.force_scale``), and the record of that iterate (collective;
    module docstring)."""
    p, F = problem, start.force_scale
    F_int = gp.force(values.sigma)
    R = p.residual(F_int=F_int, F_ext=start.F_ext)
    R_free = p.free_residual(R)
    norm_R = vec_norm(R_free) / F
    for vec in (F_int, R, R_free):
        vec.destroy()
    norm_H, states = 0.0, (0, 0, 0)
    if p.contact is not None:
        law = p.contact.evaluate(p.relative_displacement())
        norm_H = global_norm(law.H, p.comm) / F
        states = count_states(law.state, p.comm)
    plastic = p.comm.allreduce(int(np.count_nonzero(np.asarray(values.dp) > 0.0)), op=MPI.SUM)
    record = IterationRecord(0, norm_R, norm_H, math.nan, "", states, plastic)
    return bool(norm_R <= tol and norm_H <= tol), record
