r"""The contact problem condensed onto the pairs: what NNEQM1 and NNEQM2 share.

Both methods factorise a stiffness K and express the displacement through the pair forces
(:class:`~dolfinx_nnqem.solvers.condensation.Condensation`): for a condensed problem
(:class:`CondensedProblem`: the contact flexibility C = B G Bᵀ, the relative displacement w_m and
the forces λ_m at the iterate, the free relative displacement w_free = B G r of an out-of-balance
load r, the free rigid modes B N and their loads e = Nᵀ r),

    w(z, ξ, α) = w_m + w_free + C (λ(z) − λ_m) + W_ξ ξ + (B N) α,
    H(w, z) = 0,                               (the pair laws, rows / F)
    e + (B N)ᵀ (λ(z) − λ_m) + E_ξ ξ = 0,       (the floating bodies' self-equilibrium, rows / F)

with z the pair unknowns (each law's own, force λ(z)), α the free rigid modes' amplitudes and ξ
further unknowns that load the pairs linearly (NNEQM2's seed variant: the Gauss points' plastic
multipliers, W_ξ = B G Q, E_ξ = Nᵀ Q), whose own rows the caller adds
(:class:`ExtraRows`). :class:`CondensedSystem` is that dense nonsmooth system for the package's
Newton driver (:func:`~dolfinx_nnqem.numerics.nonsmooth.solve_dense`): its residual, its
chain-rule Jacobian

    ∂H/∂z = blockdiag(∂H/∂w) C blockdiag(∂λ/∂y) + blockdiag(∂H/∂y),
    ∂H/∂ξ = blockdiag(∂H/∂w) W_ξ,    ∂H/∂α = blockdiag(∂H/∂w) (B N),

taken in the laws' step coordinates y (``PairLaws.linearise``), the step rule (``advance``),
the polar angles put on the slip (``on_the_slip``), and the frozen-branch Newton step
(:meth:`CondensedSystem.frozen_step`): the pair laws linearised at a given (w, z), every
branch frozen there, solved once. NNEQM1 solves the system to convergence in every outer
iteration; NNEQM2 (the radial-return variant) takes one frozen-branch step per Newton iteration
with the tangent's C; both start a floating body's increment from a frozen-branch step.

Unknowns are scaled so that the system is of order one: pair forces by the force scale F (the
polar angle by 1), ξ by the caller's scale, α by F / r.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import NamedTuple

import numpy as np

from dolfinx_nnqem.contact.laws import LawEvaluation, Linearisation
from dolfinx_nnqem.contact.pair_laws import PairLaws

__all__ = ["CondensedProblem", "CondensedSystem", "PairRows", "newton_step", "rigid_start"]


@dataclass
class CondensedProblem:
    """One condensed contact problem (all pairs, global order).

    Attributes
    ----------
    C
        (3NC, 3NC) contact flexibility B G Bᵀ.
    w_free, w_m, lam_m
        (3NC,) relative displacement of the out-of-balance load, at the iterate, and its forces.
    mu_f, g0
        (NC,) friction coefficients and initial gaps.
    w_prev
        (NC, 3) w at the start of the increment.
    r
        The laws' scaling (the largest over the interfaces).
    BN, e
        (3NC, n_r) the free rigid modes seen by the pairs, (n_r,) their loads Nᵀ r (empty without
        free modes).
    """

    C: np.ndarray
    w_free: np.ndarray
    w_m: np.ndarray
    lam_m: np.ndarray
    mu_f: np.ndarray
    g0: np.ndarray
    w_prev: np.ndarray
    r: float
    BN: np.ndarray
    e: np.ndarray

    def as_dict(self) -> dict:
        """The problem's fields as a dictionary (what :func:`~dolfinx_nnqem.io.fclib.write_condensed_problem` takes)."""
        return asdict(self)


def rigid_start(BN: np.ndarray, w_change: np.ndarray) -> np.ndarray:
    """Starting mode amplitudes α_0 = −(B N)⁺ Δw: the rigid motion that undoes the change ``w_change``
    of the pairs' relative displacements, in the least-squares sense.

    The generalised inverse fixes a floating body at its fixing dofs, so the elastic predictor
    moves it rigidly by an arbitrary amount; started from α = 0, its pairs would open or
    penetrate for no physical reason (and an interface whose pairs all open leaves the body's
    modes without a Jacobian column). Started from α_0, the pairs keep their relative position.
    """
    if BN.shape[1] == 0:
        return np.zeros(0)
    return -np.linalg.lstsq(BN, w_change, rcond=None)[0]


class PairRows(NamedTuple):
    """The pair rows (and the self-equilibrium rows) of :class:`CondensedSystem` at one point."""

    H: np.ndarray  #: (3NC + n_r,) scaled rows: H / F, then the self-equilibrium / F
    J: np.ndarray  #: (3NC + n_r, n) their Jacobian in the scaled step coordinates
    lam: np.ndarray  #: (NC, 3) the pair forces
    lin: Linearisation  #: the laws' step coordinates (∂λ/∂y, the chart)
    y_scale: np.ndarray  #: (3NC,) the scale of the pair step coordinates
    state: np.ndarray  #: (NC,) the pairs' states


Frozen = tuple[LawEvaluation, np.ndarray, np.ndarray]
"""A law evaluation and the relative displacement (NC, 3) and pair unknowns (NC, 3) it was made at:
pair rows linearised there (:meth:`CondensedSystem.at`)."""


class CondensedSystem:
    """The dense nonsmooth system of a condensed contact problem, in scaled unknowns.

    The unknowns x = [z / z_scale, ξ / ξ_scale, α r / F]: the pair unknowns, further unknowns ξ
    that load the pairs linearly (none for NNEQM1) and the free rigid modes' amplitudes.

    Parameters
    ----------
    laws
        The pairs' laws (gathered: every pair, global order).
    cond
        The condensed problem.
    force_scale
        F, the unit of the pair forces and rows.
    W_xi, E_xi, xi_scale
        (3NC, m) the pairs' relative displacement per unit ξ, (n_r, m) ξ's load on the free rigid
        modes, (m,) ξ's scale (default: no ξ).
    """

    def __init__(self, laws: PairLaws, cond: CondensedProblem, force_scale: float,
                 W_xi: np.ndarray | None = None, E_xi: np.ndarray | None = None, xi_scale: np.ndarray | None = None):
        self.laws, self.cond, self.F = laws, cond, float(force_scale)
        self.nc = laws.size
        self.n3 = 3 * self.nc
        self.n_r = cond.BN.shape[1]
        self.m = 0 if W_xi is None else W_xi.shape[1]
        self.n = self.n3 + self.m + self.n_r
        if self.m and self.n_r and E_xi is None:
            raise ValueError("CondensedSystem: W_xi with free rigid modes needs E_xi, ξ's load on them")
        # without ξ (or without free modes): no columns (rows) to add, the same as the branches skipped
        self.W_xi = np.zeros((self.n3, 0)) if W_xi is None else W_xi
        self.E_xi = np.zeros((self.n_r, self.m)) if E_xi is None else E_xi
        self.xi_scale = np.ones(self.m) if xi_scale is None else np.asarray(xi_scale, dtype=float)
        self.z_scale = laws.unknown_scale(self.F).reshape(-1)
        self.a_scale = self.F / cond.r  # α = α̃ · F / r
        self.x_scale = np.concatenate([self.z_scale, self.xi_scale, np.full(self.n_r, self.a_scale)])

    # -- the unknowns ----------------------------------------------------------------------------
    def scaled(self, z: np.ndarray, xi: np.ndarray | None = None, alpha: np.ndarray | None = None) -> np.ndarray:
        """x of the unknowns z (NC, 3), ξ (m,) and α (n_r,) (zeros where not given)."""
        xi = np.zeros(self.m) if xi is None else xi
        alpha = np.zeros(self.n_r) if alpha is None else alpha
        return np.concatenate([np.asarray(z).reshape(-1), xi, alpha]) / self.x_scale

    def pair_unknowns(self, x: np.ndarray) -> np.ndarray:
        """z (NC, 3) at x."""
        return (x[:self.n3] * self.z_scale).reshape(self.nc, 3)

    def xi(self, x: np.ndarray) -> np.ndarray:
        """ξ (m,) at x."""
        return x[self.n3:self.n3 + self.m] * self.xi_scale

    def modes(self, x: np.ndarray) -> np.ndarray:
        """α (n_r,) at x."""
        return x[self.n3 + self.m:] * self.a_scale

    def relative_displacement(self, x: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """w (3NC,) at x, whose pair forces are ``lam``."""
        c = self.cond
        w = c.w_m + c.w_free + c.C @ (lam.reshape(-1) - c.lam_m)
        if self.m:
            w = w + self.W_xi @ self.xi(x)
        if self.n_r:
            w = w + c.BN @ self.modes(x)
        return w

    # -- rows and Jacobian -------------------------------------------------------------------------
    def pair_rows(self, x: np.ndarray, frozen: Frozen | None = None) -> PairRows:
        """The pair rows and self-equilibrium rows at x, with their Jacobian (chain rule).

        With ``frozen`` = (evaluation, w_f, z_f) the pair rows are that evaluation linearised at
        (w_f, z_f): H_f + ∂H/∂w (w(x) − w_f), every branch as it was there, and the pair
        unknowns are z_f (a frozen-branch step is taken from a point whose z is z_f).
        """
        c, laws, F, nc, n3 = self.cond, self.laws, self.F, self.nc, self.n3
        z = self.pair_unknowns(x) if frozen is None else frozen[2]
        lam, _ = laws.force(z)
        w = self.relative_displacement(x, lam)
        if frozen is None:
            ev = laws.evaluate(w.reshape(nc, 3), c.w_prev, z)
        else:
            ev, w_f, _ = frozen
            ev = ev._replace(H=ev.H + np.einsum("nij,nj->ni", ev.dH_dw, w.reshape(nc, 3) - w_f))
        lin = laws.linearise(z, ev)
        y_scale = laws.step_scale(F, lin.cartesian).reshape(-1)
        H = np.empty(n3 + self.n_r)
        J = np.zeros((n3 + self.n_r, self.n))
        H[:n3] = ev.H.reshape(-1)
        # ∂H/∂z = blockdiag(∂H/∂w) C blockdiag(∂λ/∂y) + blockdiag(∂H/∂y)
        DwC = np.einsum("nij,njk->nik", ev.dH_dw, c.C.reshape(nc, 3, n3))
        Jz = np.einsum("anj,njk->ank", DwC.reshape(n3, nc, 3), lin.dlam_dy)
        idx = np.arange(nc)
        Jb = Jz.reshape(nc, 3, nc, 3)
        Jb[idx, :, idx, :] += lin.dH_dy
        J[:n3, :n3] = Jz.reshape(n3, n3) * y_scale[None, :] / F
        if self.m:
            DwW = np.einsum("nij,njk->nik", ev.dH_dw, self.W_xi.reshape(nc, 3, self.m))
            J[:n3, n3:n3 + self.m] = DwW.reshape(n3, self.m) * self.xi_scale[None, :] / F
        if self.n_r:
            # the floating bodies' self-equilibrium e + (B N)ᵀ(λ − λ_m) + E_ξ ξ = 0
            a = n3 + self.m
            DwN = np.einsum("nij,njk->nik", ev.dH_dw, c.BN.reshape(nc, 3, self.n_r))
            J[:n3, a:] = DwN.reshape(n3, self.n_r) * self.a_scale / F
            H[n3:] = c.e + c.BN.T @ (lam.reshape(-1) - c.lam_m)
            JE = np.einsum("anj,njk->ank", c.BN.T.reshape(self.n_r, nc, 3), lin.dlam_dy).reshape(self.n_r, n3)
            J[n3:, :n3] = JE * y_scale[None, :] / F
            if self.m:
                H[n3:] += self.E_xi @ self.xi(x)
                J[n3:, n3:a] = self.E_xi * self.xi_scale[None, :] / F
        return PairRows(H / F, J, lam, lin, y_scale, ev.state)

    def residual(self, x: np.ndarray, frozen: Frozen | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The whole system's (H, J, chart) when it has no ξ (NNEQM1's inner system)."""
        rows = self.pair_rows(x, frozen)
        return rows.H, rows.J, rows.lin.cartesian

    def at(self, w: np.ndarray, z: np.ndarray) -> Frozen:
        """The laws evaluated at (w, z) (flattened or (NC, 3) w), for a frozen-branch step."""
        w = np.asarray(w).reshape(self.nc, 3)
        return self.laws.evaluate(w, self.cond.w_prev, z), w, z

    # -- steps ---------------------------------------------------------------------------------------
    def advance(self, x: np.ndarray, dx: np.ndarray, alpha: float, cartesian) -> np.ndarray:
        """The pair unknowns step in the laws' coordinates; ξ and α linearly (in physical units)."""
        n3 = self.n3
        xs = x * self.x_scale
        dxs = dx * np.concatenate([self.laws.step_scale(self.F, cartesian).reshape(-1), self.x_scale[n3:]])
        z = self.laws.advance(xs[:n3].reshape(self.nc, 3), dxs[:n3].reshape(self.nc, 3), alpha, cartesian)
        return np.concatenate([z.reshape(-1), xs[n3:] + alpha * dxs[n3:]]) / self.x_scale

    def on_the_slip(self, x: np.ndarray) -> np.ndarray:
        """x with the unknowns no force depends on (the polar angle of pairs without friction
        force) set on the slip there (:meth:`PairLaws.follow_slip`)."""
        xs = x * self.x_scale
        z = xs[:self.n3].reshape(self.nc, 3)
        lam, _ = self.laws.force(z)
        w = self.relative_displacement(x, lam).reshape(self.nc, 3)
        z = self.laws.follow_slip(z, w, self.cond.w_prev)
        return np.concatenate([z.reshape(-1), xs[self.n3:]]) / self.x_scale

    def advance_on_the_slip(self, x: np.ndarray, dx: np.ndarray, alpha: float, cartesian) -> np.ndarray:
        """:meth:`advance`, then :meth:`on_the_slip`."""
        return self.on_the_slip(self.advance(x, dx, alpha, cartesian))


def newton_step(residual: tuple, x0: np.ndarray, advance: Callable) -> np.ndarray:
    """One full Newton step from x0 for the ``residual`` (H, J, chart) evaluated there, or x0
    when J is singular or the step is not finite."""
    H, J, chart = residual
    try:
        step = np.linalg.solve(J, -H)
    except np.linalg.LinAlgError:
        return x0
    return advance(x0, step, 1.0, chart) if np.all(np.isfinite(step)) else x0
