"""The pair rows' weights in the iterative solver's augmentation (:meth:`PolarLaw.augmentation_weights`).

The augmented u block carries c D_wᵀ Σ² D_w per pair. The polar law's slip-direction row H3 has
∂H3/∂w = r d′ in every state; at weight 1 it put a penalty r on the slip normal to d(θ) of open and
sliding pairs, where θ turns with the slip and nothing resists it, and the ``selfp`` Schur
approximation then gave the θ rows the wrong sign (docs/theory.md, the iterative linear solver).
"""

from __future__ import annotations

import numpy as np

from dolfinx_nnqem.contact.laws import OPEN, SLIP, STICK, AlartCurnierLaw, PolarLaw
from dolfinx_nnqem.contact.pair_laws import LawGroup, PairLaws

R = 200.0
MU = 0.3


def _sliding_pairs(rng, n: int):
    """(w, w_prev, z, g0) of ``n`` pairs pressed into contact and sliding at the upper bound of the
    friction interval, the force opposite to the slip: p_r = ρ, s = |s| d(θ)."""
    theta = rng.uniform(-np.pi, np.pi, n)
    d = np.column_stack((np.cos(theta), np.sin(theta)))
    slip = rng.uniform(1e-4, 1e-1, n)
    gap = -rng.uniform(1e-4, 1e-2, n)  # penetration: p_n − r g > 0 for p_n ≥ 0
    p_n = rng.uniform(0.0, 1.0, n)
    rho = MU * (p_n - R * gap)
    w = np.column_stack((gap, slip[:, None] * d))
    z = np.column_stack((p_n, rho, theta))
    return w, np.zeros_like(w), z, np.zeros(n)


def test_weighted_slip_direction_row_is_the_cartesian_laws_row_normal_to_the_slip():
    """σ₃ H3 of a sliding pair, in (w, q) coordinates (∂θ/∂q = −d′/p_r), is −1 times the Alart–Curnier
    row normal to the slip at the same force: r k dw⊥ + (1 − k) dq⊥, k = ρ / |q − r s|."""
    rng = np.random.default_rng(52)
    w, w_prev, z, g0 = _sliding_pairs(rng, 20)
    mu = np.full(len(z), MU)
    polar = PolarLaw()
    ev = polar.evaluate(w, w_prev, z, g0, mu, R)
    assert np.all(ev.state == SLIP)
    weights = polar.linearise(z, ev, np.zeros((len(z), 3), bool), R * 0.1, sliding_in_force=False).augmentation
    assert weights is not None and np.all(weights[:, :2] == 1.0) and np.all((weights[:, 2] > 0) & (weights[:, 2] < 1))
    theta, p_r = z[:, 2], z[:, 1]
    d_prime = np.column_stack((-np.sin(theta), np.cos(theta)))
    h3_w = ev.dH_dw[:, 2, :]
    h3_q = ev.dH_dz[:, 2, 2][:, None] * (-d_prime / p_r[:, None])
    cartesian = AlartCurnierLaw()
    lam = polar.force(z)[0]
    ac = cartesian.evaluate(w, w_prev, lam, g0, mu, R)
    assert np.all(ac.state == SLIP)
    ac_w = np.einsum("ni,nij->nj", d_prime, ac.dH_dw[:, 1:, :])
    ac_q = np.einsum("ni,nij->nj", d_prime, ac.dH_dz[:, 1:, 1:])
    sigma = weights[:, 2][:, None]
    assert np.abs(sigma * h3_w + ac_w).max() < 1e-12 * R
    assert np.abs(sigma * h3_q + ac_q).max() < 1e-12


def test_rows_that_do_not_constrain_the_slip_have_weight_zero():
    """Open pairs and frictionless contact (θ moves no force): H3 at weight 0; sticking pairs, whose rows
    are a rotation of r s (the Cartesian sticking rows), and the normal rows at 1. The Cartesian law's
    rows all have weight 1 (no weights)."""
    n = 4
    w = np.array([[1e-3, 1e-3, 0.0],  # open (gap > 0, p_n = 0)
                  [-1e-3, 2e-3, 1e-3],  # frictionless contact: slides freely
                  [-1e-3, 1e-6, 0.0],  # sticking
                  [1e-3, 0.0, 0.0]])  # open and at rest
    z = np.array([[0.0, 0.0, 0.3], [0.5, 0.0, 0.1], [0.5, 0.0, 0.0], [0.0, 0.0, 0.0]])
    mu = np.array([MU, 0.0, MU, MU])
    polar = PolarLaw()
    ev = polar.evaluate(w, np.zeros_like(w), z, np.zeros(n), mu, R)
    assert list(ev.state) == [OPEN, SLIP, STICK, OPEN]
    weights = polar.linearise(z, ev, np.zeros((n, 3), bool), R * 0.1, sliding_in_force=False).augmentation
    assert weights is not None
    assert np.array_equal(weights, [[1, 1, 0], [1, 1, 0], [1, 1, 1], [1, 1, 0]])
    ac = AlartCurnierLaw()
    assert ac.linearise(z, ac.evaluate(w, np.zeros_like(w), z, np.zeros(n), mu, R), np.zeros((n, 3), bool),
                        R * 0.1).augmentation is None


def test_interfaces_of_both_laws_weigh_their_own_pairs():
    """Two interfaces: the polar one's pairs take its weights, the Cartesian one's weight 1."""
    rng = np.random.default_rng(7)
    w, w_prev, z, g0 = _sliding_pairs(rng, 6)
    polar_pairs, cartesian_pairs = np.array([0, 2, 4]), np.array([1, 3, 5])
    z[cartesian_pairs] = PolarLaw().force(z[cartesian_pairs])[0]  # the Cartesian pairs' unknowns are forces
    groups = (LawGroup(PolarLaw(), R, R * 0.1, polar_pairs), LawGroup(AlartCurnierLaw(), R, R * 0.1, cartesian_pairs))
    laws = PairLaws(groups, g0, np.full(6, MU), np.zeros((6, 3), bool))
    weights = laws.linearise(z, laws.evaluate(w, w_prev, z), sliding_in_force=False).augmentation
    alone = PolarLaw().linearise(z[polar_pairs], PolarLaw().evaluate(w[polar_pairs], w_prev[polar_pairs],
                                                                      z[polar_pairs], g0[polar_pairs],
                                                                      np.full(3, MU), R),
                                 np.zeros((3, 3), bool), R * 0.1, sliding_in_force=False).augmentation
    assert weights is not None and np.array_equal(weights[cartesian_pairs], np.ones((3, 3)))
    assert np.array_equal(weights[polar_pairs], alone)
