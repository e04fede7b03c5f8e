r"""The pair laws of a set of pairs: which law, r and μ_f each pair follows, applied to all of them.

The contact model concatenates the pairs of every interface; :class:`PairLaws` applies each
interface's law (a :class:`LawGroup`: the law, its r and the pairs that follow it) to its pairs,
with the directions the supports fix pinned. Solvers never ask which law a pair follows:
everything law-specific is a method of the law (:mod:`~dolfinx_nnqem.contact.laws`). The same
class holds this rank's pairs (:attr:`ContactModel.laws
<dolfinx_nnqem.contact.model.ContactModel.laws>`) or all pairs gathered on every rank, for the
dense methods (:meth:`~dolfinx_nnqem.contact.model.ContactModel.gathered_laws`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dolfinx_nnqem.contact.laws import NO_FORCE, SLIP, ContactLaw, LawEvaluation, Linearisation

__all__ = ["LawGroup", "PairLaws"]


@dataclass(frozen=True, eq=False)
class LawGroup:
    """The pairs (``index``) that follow ``law`` with the scaling ``r``."""

    law: ContactLaw
    r: float
    force_unit: float  #: r h: the force unit of rows that are not forces (the polar angle row)
    index: np.ndarray


@dataclass(frozen=True, eq=False)
class PairLaws:
    """Which law, r and μ_f each pair of a set follows (this rank's pairs, or all pairs gathered).

    Attributes
    ----------
    groups
        One :class:`LawGroup` per interface.
    g0, mu_f
        (n,) initial gaps and friction coefficients.
    constrained
        (n, 3) bool: local directions whose relative motion the supports fix.
    """

    groups: tuple[LawGroup, ...]
    g0: np.ndarray
    mu_f: np.ndarray
    constrained: np.ndarray

    @property
    def size(self) -> int:
        """The number of pairs."""
        return len(self.g0)

    @property
    def r_max(self) -> float:
        """The contact scale: the largest r of the laws (force/length). The solvers size what
        couples forces and displacements of all pairs with it (the augmentation of the monolithic
        solver's iterative system, the scale of the free rigid modes' amplitudes)."""
        return max(group.r for group in self.groups)

    def evaluate(self, w: np.ndarray, w_prev: np.ndarray, z: np.ndarray) -> LawEvaluation:
        """H, ∂H/∂w, ∂H/∂z and the states of every pair at (w, z), pinned directions applied."""
        n = self.size
        if len(self.groups) == 1:  # one interface: no copies
            return self._evaluate_group(self.groups[0], w, w_prev, z, slice(None))
        H, dH_dw, dH_dz = np.zeros((n, 3)), np.zeros((n, 3, 3)), np.zeros((n, 3, 3))
        state = np.zeros(n, dtype=np.int8)
        for group in self.groups:
            ev = self._evaluate_group(group, w, w_prev, z, group.index)
            H[group.index], dH_dw[group.index], dH_dz[group.index] = ev.H, ev.dH_dw, ev.dH_dz
            state[group.index] = ev.state
        return LawEvaluation(H, dH_dw, dH_dz, state)

    def _evaluate_group(self, group: LawGroup, w, w_prev, z, index) -> LawEvaluation:
        pinned = self.constrained[index]
        w, w_prev = w[index], w_prev[index]
        tangential = pinned & (np.arange(3) > 0)
        if tangential.any():
            # A pinned tangential direction takes no part in the friction law: its force is zero
            # and its relative motion is the supports' business (on a symmetry plane, master nodes
            # off the plane move along it although the mirrored half would cancel that). Left in,
            # it would widen the slip test and shrink the free direction's share of the friction
            # disk below μ_f p_n.
            w, w_prev = np.where(tangential, 0.0, w), np.where(tangential, 0.0, w_prev)
        ev = group.law.evaluate(w, w_prev, z[index], self.g0[index], self.mu_f[index], group.r)
        if tangential.any():
            ev = ev._replace(dH_dw=ev.dH_dw * ~tangential[:, None, :])
        return group.law.pin(ev, z[index], pinned, group.force_unit)

    def force(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """λ(z) (n, 3) and ∂λ/∂z (n, 3, 3)."""
        if len(self.groups) == 1:
            return self.groups[0].law.force(z)
        lam, dlam_dz = np.zeros((self.size, 3)), np.zeros((self.size, 3, 3))
        for group in self.groups:
            lam[group.index], dlam_dz[group.index] = group.law.force(z[group.index])
        return lam, dlam_dz

    def linearise(self, z: np.ndarray, evaluation: LawEvaluation, sliding_in_force: bool = True) -> Linearisation:
        """The Jacobian blocks of a Newton step at z in each law's step coordinates (see
        :meth:`ContactLaw.linearise`); ``evaluation`` is :meth:`evaluate`'s at z."""
        if len(self.groups) == 1:
            group = self.groups[0]
            return group.law.linearise(z, evaluation, self.constrained, group.force_unit, sliding_in_force)
        dH_dy, dlam_dy = np.zeros((self.size, 3, 3)), np.zeros((self.size, 3, 3))
        cartesian = np.zeros(self.size, dtype=bool)
        augmentation = None
        for group in self.groups:
            i = group.index
            part = group.law.linearise(z[i], LawEvaluation(*(a[i] for a in evaluation)), self.constrained[i],
                                       group.force_unit, sliding_in_force)
            dH_dy[i], dlam_dy[i] = part.dH_dy, part.dlam_dy
            if part.cartesian is not None:
                cartesian[i] = part.cartesian
            if part.augmentation is not None:
                augmentation = np.ones((self.size, 3)) if augmentation is None else augmentation
                augmentation[i] = part.augmentation
        return Linearisation(dH_dy, dlam_dy, cartesian if cartesian.any() else None, augmentation)

    def advance(self, z: np.ndarray, dy: np.ndarray, alpha: float, cartesian: np.ndarray | None) -> np.ndarray:
        """The unknowns after the step α dy from z in the step coordinates of :meth:`linearise`."""
        if len(self.groups) == 1:
            group = self.groups[0]
            return group.law.advance(z, dy, alpha, cartesian, group.force_unit)
        out = np.empty((self.size, 3))
        for group in self.groups:
            i = group.index
            out[i] = group.law.advance(z[i], dy[i], alpha, None if cartesian is None else cartesian[i],
                                       group.force_unit)
        return out

    def extrapolate(self, z_n: np.ndarray, z_prev: np.ndarray, beta: float) -> np.ndarray:
        """Secant prediction: the unknowns of the force λ_n + β (λ_n − λ_prev), taken nearest z_n.

        The force is extrapolated, not z (for the Cartesian law, z = λ, this is the same): the
        polar angle of a pair without friction force at the previous increment means nothing,
        and a line through it turns the predicted force by an arbitrary angle. The new unknowns
        come from :meth:`advance` with every pair stepping in the force.
        """
        lam_n, _ = self.force(z_n)
        lam_prev, _ = self.force(z_prev)
        return self.advance(z_n, lam_n - lam_prev, beta, np.ones(self.size, dtype=bool))

    @property
    def slip_following(self) -> bool:
        """True if some law has unknowns that :meth:`follow_slip` may move (the polar angle)."""
        return any(group.law.slip_following for group in self.groups)

    def follow_slip(self, z: np.ndarray, w: np.ndarray, w_prev: np.ndarray, sliding_too: bool = False
                    ) -> np.ndarray:
        """z with the unknowns no force depends on set on the slip (each law's ``follow_slip``);
        with ``sliding_too`` also the direction of the friction force of sliding pairs: those in
        the slip state at (w, z) whose slip r |s| is above rounding (:data:`laws.NO_FORCE` times
        the force unit; below it the slip has no direction)."""
        out = np.array(z, dtype=np.float64, copy=True)
        for group in self.groups:
            i = group.index
            sliding = None
            if sliding_too and group.law.slip_following:
                state = self._evaluate_group(group, w, w_prev, z, i).state
                s = w[i, 1:] - w_prev[i, 1:]
                sliding = (state == SLIP) & (group.r * np.hypot(s[:, 0], s[:, 1]) > NO_FORCE * group.force_unit)
            out[i] = group.law.follow_slip(z[i], w[i], w_prev[i], self.constrained[i], group.force_unit, sliding)
        return out

    def initial_unknowns(self) -> np.ndarray:
        """z of force-free pairs (each law's ``initial_unknowns`` for its pinned directions)."""
        z = np.zeros((self.size, 3))
        for group in self.groups:
            z[group.index] = group.law.initial_unknowns(self.constrained[group.index])
        return z

    def unknown_scale(self, force_scale: float) -> np.ndarray:
        """(n, 3): the scale of each unknown when forces are of order ``force_scale``."""
        scale = np.zeros((self.size, 3))
        for group in self.groups:
            scale[group.index] = group.law.unknown_scale(force_scale)
        return scale

    def step_scale(self, force_scale: float, cartesian: np.ndarray | None) -> np.ndarray:
        """(n, 3): the scale of each step coordinate of :meth:`linearise` (forces on ``cartesian`` pairs)."""
        scale = self.unknown_scale(force_scale)
        if cartesian is not None:
            scale[np.asarray(cartesian, dtype=bool)] = float(force_scale)
        return scale
