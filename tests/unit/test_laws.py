"""Tests of the per-pair contact laws (formulation.md §3) and of a pair against a spring.

Branch references: each smooth branch of each law is written out again below in plain NumPy
(single pair), from formulation.md. Away from kinks, the kernels' Jacobians are checked against
central finite differences of the kernels themselves, and their H against the branch the returned
state names. At each kink, the kernels' Jacobians are checked against the Jacobian of the branch
the module docstring documents (and shown to differ from the other branch's).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable

import numpy as np
import pytest

from dolfinx_nnqem.contact.laws import (
    OPEN,
    SLIP,
    STATE_NAMES,
    STICK,
    AlartCurnierLaw,
    PolarLaw,
    default_r,
    force_from_unknowns,
    get_law,
    unknowns_from_force,
)
from dolfinx_nnqem.numerics.nonsmooth import solve_nonsmooth

LAW_NAMES = ("alart-curnier", "polar")
FD_RTOL = 1e-6


# ---------------------------------------------------------------------------------------------
# Branch references (one pair; w, w_prev, z (3,), g0, mu scalars)
# ---------------------------------------------------------------------------------------------


def _gap_slip(w, w_prev, g0):
    return g0 + w[0], w[1:] - w_prev[1:]


def ac_open(w, w_prev, z, g0, mu, r):
    return z.copy()  # H_n = p_n, H_t = q


def ac_stick(w, w_prev, z, g0, mu, r):
    g, s = _gap_slip(w, w_prev, g0)
    return np.array([r * g, *(r * s)])


def ac_slip(w, w_prev, z, g0, mu, r):
    g, s = _gap_slip(w, w_prev, g0)
    rho = mu * (z[0] - r * g)
    x = z[1:] - r * s
    return np.array([r * g, *(z[1:] - rho * x / np.linalg.norm(x))])


def ac_open_interior(w, w_prev, z, g0, mu, r):
    _, s = _gap_slip(w, w_prev, g0)
    return np.array([z[0], *(r * s)])  # open, but the interior branch P_D(x) = x


def ac_contact_rho0(w, w_prev, z, g0, mu, r):
    g, _ = _gap_slip(w, w_prev, g0)
    return np.array([r * g, z[1], z[2]])


def _h3(w, w_prev, z, g0, r):
    _, s = _gap_slip(w, w_prev, g0)
    return r * (s[0] * np.sin(z[2]) - s[1] * np.cos(z[2]))


def polar_open(w, w_prev, z, g0, mu, r):
    return np.array([z[0], z[1], _h3(w, w_prev, z, g0, r)])


def polar_stick(w, w_prev, z, g0, mu, r):
    g, s = _gap_slip(w, w_prev, g0)
    s_d = s[0] * np.cos(z[2]) + s[1] * np.sin(z[2])
    return np.array([r * g, -r * s_d, _h3(w, w_prev, z, g0, r)])


def polar_slip_upper(w, w_prev, z, g0, mu, r):
    g, _ = _gap_slip(w, w_prev, g0)
    return np.array([r * g, z[1] - mu * (z[0] - r * g), _h3(w, w_prev, z, g0, r)])


def polar_slip_lower(w, w_prev, z, g0, mu, r):
    g, _ = _gap_slip(w, w_prev, g0)
    return np.array([r * g, z[1] + mu * (z[0] - r * g), _h3(w, w_prev, z, g0, r)])


def polar_open_interior(w, w_prev, z, g0, mu, r):
    _, s = _gap_slip(w, w_prev, g0)
    s_d = s[0] * np.cos(z[2]) + s[1] * np.sin(z[2])
    return np.array([z[0], -r * s_d, _h3(w, w_prev, z, g0, r)])


def polar_contact_rho0(w, w_prev, z, g0, mu, r):
    g, _ = _gap_slip(w, w_prev, g0)
    return np.array([r * g, z[1], _h3(w, w_prev, z, g0, r)])


# ---------------------------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------------------------


def _evaluate_one(law, w, w_prev, z, g0, mu, r):
    """Kernel at one pair: H (3,), dH_dw (3, 3), dH_dz (3, 3), state."""
    ev = law.evaluate(w[None], w_prev[None], z[None], np.array([g0]), mu, r)
    return ev.H[0], ev.dH_dw[0], ev.dH_dz[0], int(ev.state[0])


def _central_fd(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray, h: float) -> np.ndarray:
    """Central finite-difference Jacobian of fun at x."""
    columns = []
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = h
        columns.append((fun(x + e) - fun(x - e)) / (2.0 * h))
    return np.column_stack(columns)


def _branch_jacobians(branch, w, w_prev, z, g0, mu, r, h=1e-6):
    dw = _central_fd(lambda v: branch(v, w_prev, z, g0, mu, r), w, h)
    dz = _central_fd(lambda v: branch(w, w_prev, v, g0, mu, r), z, h)
    return dw, dz


def _relative_error(A: np.ndarray, B: np.ndarray) -> float:
    return float(np.linalg.norm(A - B) / max(np.linalg.norm(B), 1e-300))


def _classify(law_name, w, w_prev, z, g0, mu, r, margin=0.15):
    """(branch name, branch function) of a point, or None when within ``margin`` of a kink."""
    g, s = _gap_slip(w, w_prev, g0)
    a = z[0] - r * g
    scale = abs(z[0]) + abs(r * g)
    if abs(a) < margin * scale:
        return None
    if law_name == "alart-curnier":
        if a < 0:
            return "open", ac_open
        rho = mu * a
        x = np.linalg.norm(z[1:] - r * s)
        if abs(x - rho) < margin * rho:
            return None
        return ("stick", ac_stick) if x < rho else ("slip", ac_slip)
    if a < 0:
        branch = ("open", polar_open)
    else:
        rho = mu * a
        d = np.array([np.cos(z[2]), np.sin(z[2])])
        y = z[1] + r * s @ d
        if min(abs(y - rho), abs(y + rho)) < margin * rho:
            return None
        if y > rho:
            branch = ("slip+", polar_slip_upper)
        elif y < -rho:
            branch = ("slip-", polar_slip_lower)
        else:
            branch = ("stick", polar_stick)
    if abs(z[1]) < 0.05:
        return None
    return (branch[0] + (" p_r>0" if z[1] > 0 else " p_r<0"), branch[1])


def _random_point(rng, law_name):
    w = rng.normal(size=3)
    w_prev = rng.normal(size=3) * 0.5
    g0 = abs(rng.normal()) * 0.5
    z = rng.normal(size=3) * 2.0
    if law_name == "polar":
        z[2] = rng.uniform(-np.pi, np.pi)
    mu = rng.uniform(0.1, 1.0)
    r = rng.uniform(0.5, 4.0)
    return w, w_prev, z, g0, mu, r


EXPECTED_BRANCHES = {
    "alart-curnier": {"open", "stick", "slip"},
    "polar": {f"{b} p_r{sign}0" for b in ("open", "stick", "slip+", "slip-") for sign in "<>"},
}
STATE_OF_BRANCH = {"open": OPEN, "stick": STICK, "slip": SLIP, "slip+": SLIP, "slip-": SLIP}


# ---------------------------------------------------------------------------------------------
# Jacobians and states away from kinks
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("law_name", LAW_NAMES)
def test_jacobians_match_finite_differences_on_every_branch(law_name):
    law = get_law(law_name)
    rng = np.random.default_rng(20240611)
    per_branch = 12
    found: Counter[str] = Counter()
    worst: dict[str, float] = {}
    for _ in range(100_000):
        if min(found[b] for b in EXPECTED_BRANCHES[law_name]) >= per_branch:
            break
        w, w_prev, z, g0, mu, r = _random_point(rng, law_name)
        classified = _classify(law_name, w, w_prev, z, g0, mu, r)
        if classified is None or found[classified[0]] >= per_branch:
            continue
        name, branch = classified
        found[name] += 1
        H, dH_dw, dH_dz, state = _evaluate_one(law, w, w_prev, z, g0, mu, r)
        # the kernel is on the branch its state names, and the values agree with it
        assert state == STATE_OF_BRANCH[name.split()[0]], (name, STATE_NAMES[state])
        np.testing.assert_allclose(H, branch(w, w_prev, z, g0, mu, r), rtol=1e-13, atol=1e-13)
        # Jacobians against central differences of the kernel itself
        fd_w = _central_fd(lambda v: _evaluate_one(law, v, w_prev, z, g0, mu, r)[0], w, 1e-6)
        fd_z = _central_fd(lambda v: _evaluate_one(law, w, w_prev, v, g0, mu, r)[0], z, 1e-6)
        err = max(_relative_error(dH_dw, fd_w), _relative_error(dH_dz, fd_z))
        worst[name] = max(worst.get(name, 0.0), err)
        assert err < FD_RTOL, (name, err, dH_dw, fd_w, dH_dz, fd_z)
    print(f"\n{law_name}: max relative |J - J_fd| per branch ({per_branch} points each):")
    for name in sorted(worst):
        print(f"  {name:14s} {worst[name]:.2e}")
    assert set(worst) == EXPECTED_BRANCHES[law_name]


@pytest.mark.parametrize("law_name", LAW_NAMES)
def test_vectorised_evaluation_equals_pair_by_pair(law_name):
    law = get_law(law_name)
    rng = np.random.default_rng(5)
    points = [_random_point(rng, law_name) for _ in range(40)]
    r = 2.0
    w, w_prev, z = (np.array([p[i] for p in points]) for i in range(3))
    g0 = np.array([p[3] for p in points])
    mu = np.array([p[4] for p in points])
    ev = law.evaluate(w, w_prev, z, g0, mu, r)
    for i in range(len(points)):
        H, dH_dw, dH_dz, state = _evaluate_one(law, w[i], w_prev[i], z[i], g0[i], mu[i], r)
        np.testing.assert_array_equal(ev.H[i], H)
        np.testing.assert_array_equal(ev.dH_dw[i], dH_dw)
        np.testing.assert_array_equal(ev.dH_dz[i], dH_dz)
        assert ev.state[i] == state
    counts = Counter(STATE_NAMES[s] for s in ev.state)
    print(f"\n{law_name}: states of 40 random pairs {dict(counts)}")
    assert ev.state.dtype == np.int8 and len(counts) == 3


# ---------------------------------------------------------------------------------------------
# Kinks: exactly representable points on each kink
# ---------------------------------------------------------------------------------------------
# r = 4, w_prev = 0. Contact points: g = 0.5 + (-0.25) = 0.25, r g = 1, p_n = 11 -> a = 10,
# mu = 0.5 -> rho = 5. All of it exact in binary floating point.

_W_PREV = np.zeros(3)
_R = 4.0

KINKS = [
    # (law, description, w, z, g0, mu, documented branch, other branch, state)
    (
        "alart-curnier",
        "p_n = r g (Signorini tie): open branch",
        [0.25, 0.25, -0.5],
        [2.0, 0.75, -0.5],
        0.25,
        0.5,
        ac_open,
        ac_slip,  # contact with rho = mu (p_n - r g) -> 0
        OPEN,
    ),
    (
        "alart-curnier",
        "|q - r s| = rho > 0 (disc boundary): stick branch",
        [-0.25, 0.25, -0.5],
        [11.0, 4.0, 2.0],  # x = q - r s = (3, 4), |x| = 5 = rho
        0.5,
        0.5,
        ac_stick,
        ac_slip,
        STICK,
    ),
    (
        "alart-curnier",
        "rho = 0 in contact (mu_f = 0): H_t = q",
        [-0.25, 0.25, -0.5],
        [11.0, 4.0, 2.0],
        0.5,
        0.0,
        ac_contact_rho0,
        None,  # smooth: no other branch meets here
        SLIP,
    ),
    (
        "alart-curnier",
        "open with q = 0, s = 0 (x = 0): H_t = q, no NaN",
        [0.5, 0.0, 0.0],
        [0.0, 0.0, 0.0],
        0.5,
        0.5,
        ac_open,
        ac_open_interior,
        OPEN,
    ),
    (
        "polar",
        "p_n = r g (Signorini tie): open branch",
        [0.25, 0.25, -0.5],
        [2.0, 0.75, 0.3],
        0.25,
        0.5,
        polar_open,
        polar_slip_upper,  # contact with rho -> 0 and y > 0
        OPEN,
    ),
    (
        "polar",
        "p_r + r s.d = rho (upper edge): bound branch H2 = p_r - rho",
        [-0.25, 0.25, 0.5],  # theta = 0: d = (1, 0), r s.d = 1
        [11.0, 4.0, 0.0],  # y = 4 + 1 = 5 = rho
        0.5,
        0.5,
        polar_slip_upper,
        polar_stick,
        SLIP,
    ),
    (
        "polar",
        "p_r + r s.d = -rho (lower edge): bound branch H2 = p_r + rho",
        [-0.25, 0.25, 0.5],
        [11.0, -6.0, 0.0],  # y = -6 + 1 = -5 = -rho
        0.5,
        0.5,
        polar_slip_lower,
        polar_stick,
        SLIP,
    ),
    (
        "polar",
        "rho = 0 and y = 0 (open, p_r = 0, s = 0): H2 = p_r, no NaN",
        [0.5, 0.0, 0.0],
        [0.0, 0.0, 0.0],
        0.5,
        0.5,
        polar_open,
        polar_open_interior,
        OPEN,
    ),
    (
        "polar",
        "rho = 0 in contact (mu_f = 0): H2 = p_r",
        [-0.25, 0.25, 0.5],
        [11.0, 4.0, 0.0],
        0.5,
        0.0,
        polar_contact_rho0,
        None,  # smooth: no other branch meets here
        SLIP,
    ),
]


@pytest.mark.parametrize("kink", KINKS, ids=[f"{k[0]}: {k[1]}" for k in KINKS])
def test_kinks_take_the_documented_branch(kink):
    law_name, description, w, z, g0, mu, documented, other, expected_state = kink
    law = get_law(law_name)
    w, z = np.array(w), np.array(z)
    H, dH_dw, dH_dz, state = _evaluate_one(law, w, _W_PREV, z, g0, mu, _R)
    ref_w, ref_z = _branch_jacobians(documented, w, _W_PREV, z, g0, mu, _R)
    err = max(_relative_error(dH_dw, ref_w), _relative_error(dH_dz, ref_z))
    message = (
        f"\n{law_name}, {description}: state {STATE_NAMES[state]}, "
        f"|J - J_documented| = {err:.1e}"
    )
    if other is not None:
        other_w, other_z = _branch_jacobians(other, w, _W_PREV, z, g0, mu, _R)
        distance = max(_relative_error(dH_dw, other_w), _relative_error(dH_dz, other_z))
        message += f", |J - J_other branch| = {distance:.1e}"
    print(message)
    assert np.isfinite(H).all() and np.isfinite(dH_dw).all() and np.isfinite(dH_dz).all()
    np.testing.assert_allclose(H, documented(w, _W_PREV, z, g0, mu, _R), atol=1e-14)
    assert state == expected_state
    assert err < FD_RTOL
    if other is not None:
        # both branches give the same H: the point really is on the kink ...
        np.testing.assert_allclose(H, other(w, _W_PREV, z, g0, mu, _R), atol=1e-14)
        # ... and the check discriminates between the two branches' Jacobians
        assert distance > 1e-3


# ---------------------------------------------------------------------------------------------
# Force <-> unknowns
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("law_name", LAW_NAMES)
def test_force_derivative_matches_finite_differences(law_name):
    rng = np.random.default_rng(11)
    z = rng.normal(size=(30, 3)) * 2.0
    lam, dlam_dz = force_from_unknowns(law_name, z)
    worst = 0.0
    for i in range(z.shape[0]):
        fd = _central_fd(lambda v: force_from_unknowns(law_name, v[None])[0][0], z[i], 1e-6)
        err = _relative_error(dlam_dz[i], fd)
        worst = max(worst, err)
        assert err < FD_RTOL
    print(f"\n{law_name}: max relative |dlam/dz - FD| = {worst:.2e}")
    if law_name == "alart-curnier":
        np.testing.assert_array_equal(lam, z)
        np.testing.assert_array_equal(dlam_dz, np.broadcast_to(np.eye(3), (30, 3, 3)))
    else:  # |q| = |p_r|, q = -p_r d
        np.testing.assert_allclose(np.hypot(lam[:, 1], lam[:, 2]), np.abs(z[:, 1]), rtol=1e-14)


@pytest.mark.parametrize("law_name", LAW_NAMES)
def test_unknowns_force_round_trip(law_name):
    rng = np.random.default_rng(12)
    z = rng.normal(size=(50, 3)) * 2.0
    z[:, 2] = rng.uniform(-np.pi, np.pi, size=50)
    lam = force_from_unknowns(law_name, z)[0]
    z_back = unknowns_from_force(law_name, lam)
    lam_back = force_from_unknowns(law_name, z_back)[0]
    err = np.abs(lam_back - lam).max() / np.abs(lam).max()
    print(f"\n{law_name}: max |force(unknowns(force(z))) - force(z)| / |force| = {err:.1e}")
    assert err < 1e-14
    if law_name == "alart-curnier":
        np.testing.assert_array_equal(z_back, z)
    else:
        assert (z_back[:, 1] >= 0).all()
        np.testing.assert_allclose(z_back[:, 1], np.abs(z[:, 1]), rtol=1e-14)
        positive = z[:, 1] > 0  # the same (p_r, theta) when p_r > 0, theta in (-pi, pi]
        np.testing.assert_allclose(z_back[positive], z[positive], rtol=1e-13, atol=1e-13)
        # no tangential force: p_r = 0 and theta = 0
        z0 = unknowns_from_force(law_name, np.array([[3.0, 0.0, 0.0], [0.0, -0.0, -0.0]]))
        np.testing.assert_array_equal(z0, [[3.0, 0.0, 0.0], [0.0, 0.0, 0.0]])


# ---------------------------------------------------------------------------------------------
# Names, r and input validation
# ---------------------------------------------------------------------------------------------


def test_get_law_names():
    assert isinstance(get_law("alart-curnier"), AlartCurnierLaw)
    assert isinstance(get_law("Cartesian"), AlartCurnierLaw)
    assert isinstance(get_law("polar"), PolarLaw)
    assert isinstance(get_law("seed"), PolarLaw)
    law = PolarLaw()
    assert get_law(law) is law
    assert get_law("polar").name == "polar" and get_law("cartesian").name == "alart-curnier"
    with pytest.raises(ValueError, match="unknown contact law 'fischer'"):
        get_law("fischer")


def test_default_r():
    assert default_r(210e9, 0.01) == pytest.approx(2.1e9, rel=1e-15)
    with pytest.raises(ValueError, match="E must be"):
        default_r(-1.0, 0.01)
    with pytest.raises(ValueError, match="h must be"):
        default_r(1.0, 0.0)


@pytest.mark.parametrize("law_name", LAW_NAMES)
def test_bad_inputs_raise(law_name):
    law = get_law(law_name)
    nc = 4
    w, w_prev, z = np.zeros((nc, 3)), np.zeros((nc, 3)), np.zeros((nc, 3))
    g0 = np.zeros(nc)
    ok = dict(w=w, w_prev=w_prev, z=z, g0=g0, mu_f=0.3, r=1.0)
    law.evaluate(**ok)  # valid, with a scalar mu_f broadcast to all pairs
    bad_cases = [
        (dict(mu_f=-0.2), r"mu_f must be finite and >= 0, got mu_f = -0\.2"),
        (dict(mu_f=np.array([0.1, 0.2, np.nan, 0.3])), r"mu_f = nan \(pair 2"),
        (dict(mu_f=np.inf), r"mu_f = inf"),
        (dict(mu_f=np.zeros(3)), r"mu_f must be a scalar or have shape \(4,\)"),
        (dict(r=0.0), r"r must be finite and > 0, got r = 0\.0"),
        (dict(r=-2.0), r"r = -2\.0"),
        (dict(r=np.inf), r"r = inf"),
        (dict(w=np.zeros((nc, 2))), r"^w must have shape \(nc, 3\)"),
        (dict(w_prev=np.zeros((nc + 1, 3))), r"w_prev must have shape \(4, 3\)"),
        (dict(z=np.zeros((nc, 2))), r"^z must have shape \(4, 3\)"),
        (dict(g0=np.zeros((nc, 1))), r"g0 must have shape \(4,\)"),
        (dict(g0=np.array([0.0, np.nan, 0.0, 0.0])), r"g0 must be finite"),
    ]
    for change, message in bad_cases:
        with pytest.raises(ValueError, match=message):
            law.evaluate(**{**ok, **change})
    with pytest.raises(ValueError, match=r"lam must have shape \(nc, 3\)"):
        law.unknowns(np.zeros(3))


# ---------------------------------------------------------------------------------------------
# One pair against a linear spring w = w0 + C lambda
# ---------------------------------------------------------------------------------------------


def _spring_case(rng, well_posed=True):
    """Random single-pair problem (C, r, w0, g0, w_prev, mu_f).

    Well-posed class (used for the agreement test): the normal compliance along any slip
    direction e stays positive, C_nn - mu_f |C_nt| > 0 (otherwise friction can jam the pair and
    the law can have no or several solutions: both laws' merit functions then fold), and r is of
    the order of the pair stiffness, r = (1 .. 3)/|C| (what ``default_r`` = E h aims at).
    """
    while True:
        A = rng.normal(size=(3, 3))
        C = A @ A.T + 0.3 * np.eye(3)  # symmetric positive definite compliance
        mu = rng.uniform(0.05, 1.0)
        if not well_posed or mu * np.hypot(C[0, 1], C[0, 2]) < C[0, 0]:
            break
    r = rng.uniform(1.0, 3.0) / np.linalg.norm(C, 2)
    if not well_posed:
        r *= rng.choice([0.1, 1.0])
    w0 = rng.normal(size=3)
    # mostly pressed together (w0_n < 0), with small or large tangential loads: all states occur
    w0[0] = -abs(w0[0]) if rng.uniform() < 0.8 else abs(w0[0])
    w0[1:] *= rng.choice([0.1, 1.0])
    g0 = abs(rng.normal()) * rng.choice([0.0, 0.3, 1.0])
    w_prev = np.zeros(3)
    w_prev[1:] = rng.normal(size=2) * rng.choice([0.0, 0.5])
    return C, r, w0, g0, w_prev, mu


def _solve_spring(law_name, case, rtol=1e-12, max_iter=100):
    C, r, w0, g0, w_prev, mu = case
    law = get_law(law_name)

    def residual(z):
        lam, dlam_dz = law.force(z[None])
        w = w0 + C @ lam[0]
        ev = law.evaluate(w[None], w_prev[None], z[None], np.array([g0]), mu, r)
        # chain rule through w(lambda(z))
        return ev.H[0], ev.dH_dw[0] @ C @ dlam_dz[0] + ev.dH_dz[0]

    force_scale = _force_scale(case)
    z0 = law.unknowns(np.zeros((1, 3)))[0]
    result = solve_nonsmooth(residual, z0, tol=rtol * force_scale, max_iter=max_iter)
    lam = law.force(result.x[None])[0][0]
    state = law.evaluate(
        (w0 + C @ lam)[None], w_prev[None], result.x[None], np.array([g0]), mu, r
    ).state[0]
    return result, lam, int(state)


def _length_scale(case):
    C, r, w0, g0, w_prev, mu = case
    return max(np.linalg.norm(w0), g0, np.linalg.norm(w_prev))


def _force_scale(case):
    """Forces the spring exerts over the problem's lengths: |C^-1| L."""
    return np.linalg.norm(np.linalg.inv(case[0]), 2) * _length_scale(case)


def _coulomb_violations(case, lam, rtol=1e-9):
    """Violated conditions of Coulomb's law at lambda (relative to the problem's scales)."""
    C, r, w0, g0, w_prev, mu = case
    L, F = _length_scale(case), _force_scale(case)
    w = w0 + C @ lam
    g, s = g0 + w[0], w[1:] - w_prev[1:]
    p_n, q = lam[0], lam[1:]
    abs_q, abs_s = np.linalg.norm(q), np.linalg.norm(s)
    failures = []
    if g < -rtol * L:
        failures.append(f"g = {g:.3e} < 0")
    if p_n < -rtol * F:
        failures.append(f"p_n = {p_n:.3e} < 0")
    if abs(g * p_n) > rtol * L * F:
        failures.append(f"g p_n = {g * p_n:.3e} != 0")
    if abs_q > mu * p_n + rtol * F:
        failures.append(f"|q| = {abs_q:.6e} > mu p_n = {mu * p_n:.6e}")
    if abs_q < mu * p_n - rtol * F and abs_s > rtol * L:
        failures.append(f"stick (|q| < mu p_n) but |s| = {abs_s:.3e}")
    if abs_s > rtol * L and np.linalg.norm(q + mu * p_n * s / abs_s) > rtol * F:
        failures.append(f"slip but q + mu p_n s/|s| = {q + mu * p_n * s / abs_s}")
    return failures


def _stall_diagnosis(case, result, lam_solution, state_solution):
    """Where the polar iteration stopped, against the Cartesian solution."""
    C, r, w0, g0, w_prev, mu = case
    p_n, p_r, theta = result.x
    q_direction = -np.array([np.cos(theta), np.sin(theta)]) * np.sign(p_r)
    q_solution = lam_solution[1:]
    angle = np.degrees(
        np.arccos(np.clip(q_direction @ q_solution / np.linalg.norm(q_solution), -1.0, 1.0))
    )
    return (
        f"{result.message}\n    stalled at p_n = {p_n:.3e}, p_r = {p_r:.3e} (force scale "
        f"{_force_scale(case):.2e}); solution ({STATE_NAMES[state_solution]}) p_n = "
        f"{lam_solution[0]:.3e}, |q| = {np.linalg.norm(q_solution):.3e}; the stalled friction "
        f"direction is {angle:.0f} deg off the solution's"
    )


N_SPRING_CASES = 1000


def test_spring_pair_both_laws_satisfy_coulomb_and_agree():
    rng = np.random.default_rng(2024)
    cases = [_spring_case(rng) for _ in range(N_SPRING_CASES)]
    states: Counter[str] = Counter()
    polar_failures: list[str] = []
    agree = 0
    iterations = {"alart-curnier": [], "polar": []}
    lm_used = 0
    for index, case in enumerate(cases):
        cart, lam_c, state_c = _solve_spring("alart-curnier", case)
        assert cart.converged, f"case {index}: {cart.message}"
        violations = _coulomb_violations(case, lam_c)
        assert not violations, f"case {index} (alart-curnier): {violations}"
        states[STATE_NAMES[state_c]] += 1
        iterations["alart-curnier"].append(cart.iterations)

        polar, lam_p, state_p = _solve_spring("polar", case)
        iterations["polar"].append(polar.iterations)
        lm_used += polar.lm_steps > 0
        if not polar.converged:
            polar_failures.append(f"case {index}: {_stall_diagnosis(case, polar, lam_c, state_c)}")
            continue
        violations = _coulomb_violations(case, lam_p)
        assert not violations, f"case {index} (polar): {violations}"
        scale = max(np.linalg.norm(lam_c), _force_scale(case))
        difference = np.linalg.norm(lam_p - lam_c) / scale
        assert difference <= 1e-8, f"case {index}: polar {lam_p} vs Cartesian {lam_c}"
        agree += 1
    print(
        f"\n{N_SPRING_CASES} random single-pair spring problems (well-posed class); Cartesian "
        f"states at the solution: {dict(states)}"
    )
    for name, its in iterations.items():
        print(f"  {name}: iterations mean {np.mean(its):.1f}, max {max(its)}")
    print(f"  polar used LM steps in {lm_used} cases")
    print(
        f"  Cartesian converged {N_SPRING_CASES}/{N_SPRING_CASES}; polar converged and agrees "
        f"within 1e-8: {agree}/{N_SPRING_CASES}"
    )
    for failure in polar_failures:
        print(f"  polar did not converge, {failure}")
    # every state occurs, so all branches were exercised at solutions
    assert set(states) == {"open", "stick", "slip"}
    assert agree >= 0.99 * N_SPRING_CASES  # formulation.md: 999/1000 with plain LM


def test_spring_pair_outside_the_well_posed_class_never_returns_a_wrong_solution():
    """Jamming friction (mu_f |C_nt| >= C_nn) or small r: failures are reported, not wrong."""
    rng = np.random.default_rng(77)
    n_cases = 200
    converged = Counter()
    failed_messages: Counter[str] = Counter()
    for index in range(n_cases):
        case = _spring_case(rng, well_posed=False)
        for law_name in LAW_NAMES:
            result, lam, _ = _solve_spring(law_name, case)
            if result.converged:
                converged[law_name] += 1
                violations = _coulomb_violations(case, lam)
                assert not violations, f"case {index} ({law_name}): {violations}"
            else:
                assert result.message.startswith(("stopped", "not converged"))
                C, r, *_, mu = case
                failed_messages[law_name] += 1
                print(
                    f"\n  case {index} {law_name}: {result.message}\n    mu_f |C_nt| / C_nn = "
                    f"{mu * np.hypot(C[0, 1], C[0, 2]) / C[0, 0]:.3f}, r |C| = "
                    f"{r * np.linalg.norm(C, 2):.3f}",
                    end="",
                )
    print(f"\n{n_cases} spring problems without the well-posedness restriction:")
    for law_name in LAW_NAMES:
        print(f"  {law_name}: converged {converged[law_name]}/{n_cases}")
    assert converged["alart-curnier"] >= 0.9 * n_cases


def test_polar_follow_slip_sets_the_angle_of_pairs_without_friction_force():
    """Pairs with p_r = 0 (open, closed or frictionless): θ on the zero of H3 nearest the old θ,
    and a closed one then takes the Cartesian law's branch; pairs with a friction force (even
    open ones), pinned pairs and pairs at rest keep θ; the Cartesian law changes nothing."""
    from dolfinx_nnqem.contact.laws import AlartCurnierLaw, PolarLaw

    law, r, force_unit = PolarLaw(), 1.0e6, 1.0e5
    w_prev = np.zeros((7, 3))
    w = np.array([[1e-3, 2e-4, 2e-4],  # open, p_r = 0
                  [-1e-3, 2e-4, 0.0],  # closed, friction force
                  [-1e-3, 0.0, 3e-4],  # frictionless, p_r = 0
                  [1e-3, 1e-4, 1e-4],  # open, pinned t2
                  [1e-3, 0.0, 0.0],  # open, at rest
                  [-1e-3, 4e-4, -4e-4],  # closed, p_r = 0 (round-off), θ nearly across the slip
                  [1e-3, 2e-4, 2e-4]])  # open, p_r ≠ 0 (a damped step)
    z = np.array([[0.0, 0.0, 4.0], [5e2, 1e2, 1.0], [5e2, 0.0, -2.0], [0.0, 0.0, 0.3], [0.0, 0.0, 0.7],
                  [5e2, 1e-12, 0.3 * np.pi], [0.0, 3e1, 0.5]])
    g0, mu_f = np.zeros(7), np.array([0.3, 0.3, 0.0, 0.3, 0.3, 0.3, 0.3])
    constrained = np.zeros((7, 3), dtype=bool)
    constrained[3, 2] = True
    out = law.follow_slip(z, w, w_prev, constrained, force_unit)
    assert out[0, 2] == pytest.approx(np.pi / 4 + np.pi)  # nearest to 4.0 of π/4 + kπ
    assert out[2, 2] == pytest.approx(-np.pi / 2)  # slip along t2; nearest to −2.0
    assert out[5, 2] == pytest.approx(0.75 * np.pi)  # −π/4 + π, nearest to 0.3π
    np.testing.assert_array_equal(out[[1, 3, 4, 6]], z[[1, 3, 4, 6]])
    np.testing.assert_array_equal(out[:, :2], z[:, :2])  # only θ moves
    H = law.evaluate(w, w_prev, out, g0, mu_f, r).H
    assert np.all(np.abs(H[[0, 2, 5], 2]) < 1e-12 * r * 1e-3)
    # the closed pair with θ nearly across its slip sticks (|y| = r |s·d| = 88 < ρ = μ_f (p_n − r g)
    # = 450); on its slip it takes the Cartesian law's branch: |q − r s| = r |s| = 566 > ρ, slip
    before = law.evaluate(w[5:6], w_prev[5:6], z[5:6], g0[5:6], mu_f[5:6], r).state[0]
    after = law.evaluate(w[5:6], w_prev[5:6], out[5:6], g0[5:6], mu_f[5:6], r).state[0]
    cartesian = AlartCurnierLaw().evaluate(w[5:6], w_prev[5:6], np.zeros((1, 3)) + [5e2, 0, 0], g0[5:6], mu_f[5:6],
                                           r).state[0]
    assert (before, after, cartesian) == (STICK, SLIP, SLIP)
    np.testing.assert_array_equal(AlartCurnierLaw().follow_slip(z, w, w_prev, constrained, force_unit), z)
    assert PolarLaw.slip_following and not AlartCurnierLaw.slip_following


def test_secant_prediction_extrapolates_the_force_for_both_laws():
    """PairLaws.extrapolate: the force λ_n + β (λ_n − λ_prev) for both laws; the Cartesian
    unknowns are exactly z_n + β (z_n − z_prev); the polar angle is taken nearest θ_n (no line
    through the meaningless angle of a pair that had no friction force), a zero force keeps θ_n."""
    from dolfinx_nnqem.contact.laws import AlartCurnierLaw, PolarLaw
    from dolfinx_nnqem.contact.pair_laws import LawGroup, PairLaws

    n, beta = 4, 0.5
    #                    no friction force before      turning          reversing       open now and before
    lam_prev = np.array([[1e3, 0.0, 0.0], [1e3, 2e2, 0.0], [1e3, 1e2, 1e2], [0.0, 0.0, 0.0]])
    lam_n = np.array([[2e3, -3e2, 4e2], [2e3, 3e2, 3e2], [2e3, -1e1, -1e1], [0.0, 0.0, 0.0]])
    expected = lam_n + beta * (lam_n - lam_prev)
    common = dict(g0=np.zeros(n), mu_f=np.full(n, 0.3), constrained=np.zeros((n, 3), dtype=bool))

    cartesian = PairLaws((LawGroup(AlartCurnierLaw(), 1e6, 1e5, np.arange(n)),), **common)
    z = cartesian.extrapolate(lam_n, lam_prev, beta)
    np.testing.assert_array_equal(z, lam_n + beta * (lam_n - lam_prev))

    polar_law = PolarLaw()
    polar = PairLaws((LawGroup(polar_law, 1e6, 1e5, np.arange(n)),), **common)
    z_prev = polar_law.unknowns(lam_prev)
    z_prev[0, 2] = 2.5  # any angle: the pair had no friction force
    z_n = polar_law.unknowns(lam_n)
    z_n[3, 2] = -1.0
    z = polar.extrapolate(z_n, z_prev, beta)
    np.testing.assert_allclose(polar_law.force(z)[0], expected, rtol=1e-14, atol=1e-10)
    assert np.all(np.abs(z[:, 2] - z_n[:, 2]) <= 0.5 * np.pi + 1e-14)  # nearest representation
    assert z[3, 2] == -1.0 and z[3, 1] == 0.0
    # the old line through z gave another force wherever θ_prev was meaningless
    assert not np.allclose(polar_law.force(z_n + beta * (z_n - z_prev))[0][0], expected[0])


def test_polar_follow_slip_with_sliding_pairs_puts_their_friction_force_on_the_slip_line():
    """With ``sliding``, θ of the given pairs goes to θ_s + kπ nearest θ with p_r kept (their H3
    vanishes, the friction force's size does not change); pinned pairs and pairs at rest keep θ;
    through PairLaws, only pairs in the slip state with a slip above rounding are sliding."""
    from dolfinx_nnqem.contact.laws import AlartCurnierLaw, PolarLaw
    from dolfinx_nnqem.contact.pair_laws import LawGroup, PairLaws

    law, r, force_unit = PolarLaw(), 1.0e6, 1.0e5
    w_prev = np.zeros((5, 3))
    w = np.array([[-1e-3, 3e-3, 1e-3],  # closed, sliding, θ a radian off the slip line
                  [-1e-3, 1e-5, 0.0],  # closed, sticking
                  [-1e-3, 3e-4, 1e-4],  # closed, sliding, pinned t2
                  [-1e-3, 0.0, 0.0],  # closed, at rest
                  [-1e-3, 1e-25, 0.0]])  # closed, a slip of rounding size
    theta_s = np.arctan2(1e-3, 3e-3)
    z = np.array([[5e2, 150.0, theta_s + np.pi + 1.0], [5e2, 1e2, 0.1], [5e2, 150.0, 0.0], [5e2, 1e2, 0.4],
                  [5e2, 600.0, 2.0]])
    g0, mu_f = np.zeros(5), np.full(5, 0.3)
    constrained = np.zeros((5, 3), dtype=bool)
    constrained[2, 2] = True
    sliding = np.array([True, False, True, True, False])
    out = law.follow_slip(z, w, w_prev, constrained, force_unit, sliding)
    assert out[0, 2] == pytest.approx(theta_s + np.pi)  # nearest to 2.0 of θ_s + kπ
    np.testing.assert_array_equal(out[1:], z[1:])
    np.testing.assert_array_equal(out[:, :2], z[:, :2])
    H = law.evaluate(w, w_prev, out, g0, mu_f, r).H
    assert abs(H[0, 2]) < 1e-12 * r * 1e-3
    np.testing.assert_array_equal(law.follow_slip(z, w, w_prev, constrained, force_unit), z)  # no sliding given
    np.testing.assert_array_equal(AlartCurnierLaw().follow_slip(z, w, w_prev, constrained, force_unit, sliding), z)

    # PairLaws decides which pairs slide: the law's slip state and r |s| above NO_FORCE · force unit
    laws = PairLaws((LawGroup(law, r, force_unit, np.arange(5)),), g0, mu_f, constrained)
    states = law.evaluate(w, w_prev, z, g0, mu_f, r).state
    assert list(states[[0, 1, 4]]) == [SLIP, STICK, SLIP]
    aligned = laws.follow_slip(z, w, w_prev, sliding_too=True)
    assert aligned[0, 2] == pytest.approx(theta_s + np.pi)
    np.testing.assert_array_equal(aligned[1:], z[1:])  # sticking, pinned, at rest, rounding-size slip
    np.testing.assert_array_equal(laws.follow_slip(z, w, w_prev), z)


def test_polar_advance_keeps_the_angle_of_a_rounding_size_friction_force():
    """PolarLaw.advance on pairs stepping in the force: a new friction force of rounding size
    (|q| ≤ NO_FORCE · force unit, here 1e-20 N against 1e5 N) keeps θ, with p_r its component on
    −d(θ); a real force turns θ onto its direction (the representation nearest the old θ) and
    is reproduced exactly. The Cartesian law steps z + α dy whatever the force unit."""
    from dolfinx_nnqem.contact.laws import NO_FORCE

    law, force_unit = PolarLaw(), 1.0e5
    theta = np.array([0.7, 0.7, 0.7, -2.0])
    z = np.column_stack((np.full(4, 1e3), np.zeros(4), theta))  # no friction force before
    dy = np.array([[0.0, 1e-20, -3e-20],  # rounding (an open pair's leftover)
                   [0.0, 30.0, -40.0],  # a real force
                   [0.0, 0.0, 0.0],  # none at all
                   [0.0, -0.5 * NO_FORCE * force_unit, 0.0]])  # below the threshold, any direction
    out = law.advance(z, dy, 1.0, np.ones(4, dtype=bool), force_unit)
    np.testing.assert_array_equal(out[[0, 2, 3], 2], theta[[0, 2, 3]])  # θ kept
    d = np.column_stack((np.cos(theta), np.sin(theta)))
    np.testing.assert_allclose(out[[0, 3], 1], -np.sum(dy[[0, 3], 1:] * d[[0, 3]], axis=1), rtol=1e-15)
    assert out[2, 1] == 0.0
    assert np.all(np.abs(law.force(out)[0][[0, 3], 1:] - dy[[0, 3], 1:]) <= 1e-20 + 0.5 * NO_FORCE * force_unit)
    # the real force turns θ: d(θ) = ±q/|q|, the sign (of p_r) that keeps θ nearest 0.7
    q = dy[1, 1:]
    assert abs(out[1, 1]) == pytest.approx(50.0, rel=1e-15)
    assert abs(out[1, 2] - 0.7) <= 0.5 * np.pi and out[1, 2] != 0.7
    np.testing.assert_allclose(law.force(out)[0][1], [1e3, *q], rtol=1e-14)
    # the same rounding-size step taken with a tiny force unit is a real force: θ turns
    turned = law.advance(z[:1], dy[:1], 1.0, np.ones(1, dtype=bool), 1e-12)
    assert turned[0, 2] != 0.7
    np.testing.assert_allclose(law.force(turned)[0][0, 1:], dy[0, 1:], rtol=1e-12)
    np.testing.assert_array_equal(AlartCurnierLaw().advance(z, dy, 1.0, None, force_unit), z + dy)


def test_the_python_kernels_equal_numbas_bit_for_bit():
    """The laws run their kernels as plain Python until compiling pays (issue 32,
    ``laws._CompiledWhenItPays``): both must give the same bits, on smooth points, on every kink
    of the module docstring (a = 0, |x| = rho, y = ±rho, rho = 0) and on open pairs, and the
    switch must happen once the Python time reaches ``COMPILE_AFTER_S``."""
    from dolfinx_nnqem.contact import laws

    rng = np.random.default_rng(32)
    nc = 40
    r = 3.0e9
    cases = 0
    for trial in range(60):
        w = rng.normal(size=(nc, 3)) * 1e-5
        w_prev = w + rng.normal(size=(nc, 3)) * 1e-6 * rng.integers(0, 2, (nc, 1))
        z = rng.normal(size=(nc, 3)) * 1e4
        z[:, 0] = np.abs(z[:, 0]) * rng.integers(0, 2, nc)
        if trial % 2:
            z[:, 2] = rng.uniform(-4.0, 4.0, nc)  # polar angles
        g0 = rng.normal(size=nc) * 1e-5 * rng.integers(0, 2, nc)
        mu = rng.uniform(0.0, 1.0, nc) * rng.integers(0, 2, nc)
        # kinks: a = p_n - r g = 0 exactly on some pairs, |x| = rho (stick/slip edge) on others
        z[:5, 0] = r * (g0[:5] + w[:5, 0])
        s = w[5:10, 1:] - w_prev[5:10, 1:]
        rho = mu[5:10] * np.maximum(z[5:10, 0] - r * (g0[5:10] + w[5:10, 0]), 0.0)
        z[5:10, 1:] = r * s + rho[:, None] * np.array([1.0, 0.0])
        for kernel in (laws.alart_curnier_kernel, laws.polar_kernel):
            python = kernel(w, w_prev, z, g0, mu, r)
            compiled = laws._CompiledWhenItPays(kernel).compile()(w, w_prev, z, g0, mu, r)
            for a, b in zip(python, compiled):
                assert a.dtype == b.dtype and np.array_equal(a, b)
            cases += 1
    runner = laws._CompiledWhenItPays(laws.alart_curnier_kernel)
    runner.python_s = laws.COMPILE_AFTER_S - 1e-9
    runner(w, w_prev, z, g0, mu, r)
    print(f"\n  {cases} kernel evaluations of {nc} pairs: Python and numba bit for bit equal; "
          f"compiled after {runner.python_s:.3f} s of Python: {runner.compiled is not None}")
    assert runner.compiled is not None
