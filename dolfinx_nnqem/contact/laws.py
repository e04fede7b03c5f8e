r"""Per-pair frictional contact laws written as nonsmooth equations H_i(w_i, z_i) = 0.

The mathematics is ``formulation.md`` §2--§3. For ``nc`` node-to-node pairs:

* ``w`` (nc, 3): relative displacement of the pair in its local frame, w = R (u_b - u_a);
  ``w[:, 0]`` is normal, ``w[:, 1:3]`` tangential.
* ``w_prev`` (nc, 3): the converged ``w`` at the start of the load step. The slip of the step is
  s = w[:, 1:3] - w_prev[:, 1:3] (friction is incremental).
* ``g0`` (nc,): initial gap; the gap is g = g0 + w[:, 0].
* ``mu_f`` (nc,): Coulomb friction coefficient of each pair.
* ``r`` > 0: scaling parameter in force/length (see :func:`default_r`).
* ``z`` (nc, 3): the law's unknowns.

  - Cartesian Alart--Curnier law: z = lambda = (p_n, q1, q2), the local contact force on
    body 2 (p_n >= 0 is compression).
  - Polar (seed) law: z = (p_n, p_r, theta), force lambda = (p_n, -p_r cos theta,
    -p_r sin theta), p_r a SIGNED magnitude.

Every kernel returns ``H`` (nc, 3), ``dH_dw`` (nc, 3, 3), ``dH_dz`` (nc, 3, 3) and ``state``
(nc,) int8 (:data:`OPEN`, :data:`STICK`, :data:`SLIP`). All rows of H are in force units (the
polar H3, a length, is multiplied by r).

Generalized (B-)Jacobians and kink conventions
----------------------------------------------
Each kernel differentiates the active branch. Where two branches meet, one is picked by a fixed
rule, the one ``formulation.md`` states for min: ``min(a, b)`` with a = b takes ``a``, the first
argument *as the formula is written*; the same rule is used for max. Consequences:

1. Signorini, both laws: ``min(p_n, r g)`` and ``p_n - max(0, p_n - r g)`` are the same function;
   at p_n = r g both take the OPEN branch (H_n = p_n, dH_n/dp_n = 1) and the friction bound
   rho = mu_f max(0, p_n - r g) takes its 0 branch (rho = 0, d rho = 0).
2. Polar projection onto [-rho, rho], written ``max(-rho, min(rho, y))`` with
   y = p_r + r s.d(theta): at y = rho, ``min`` takes rho; at y = -rho, ``max`` takes -rho. So
   on both edges the BOUND (slip) branch is used: H2 = p_r -+ rho.
3. Disc projection P_D (Cartesian): ``formulation.md`` defines it as "x if |x| <= rho, else
   rho x/|x|", so at |x| = rho > 0 the INTERIOR (stick) branch is used: H_t = r s.
4. rho = 0 (open pair, the tie p_n = r g, or mu_f = 0): the admissible set is the single point
   {0}, whose projection is identically 0 and smooth in its argument; both laws use the bound
   branch, H_t = q (Cartesian; at x = 0 this overrides rule 3, both branches being 0 there) and
   H2 = p_r (polar; rule 2 gives the same for every y, the ties included). No division by |x|
   happens, so x = 0 and s = 0 give no NaN. The polar H3 = r (s1 sin theta - s2 cos theta) is
   smooth; at s = 0 its theta-derivative is simply 0.

``state`` reports the branch that was differentiated: OPEN when p_n - r g <= 0, otherwise STICK
on the interior branch of the friction projection and SLIP on its bound (including rho = 0 in
contact, i.e. mu_f = 0, a frictionless pair sliding freely). A solution on the slip cone edge
with s = 0 is therefore STICK for the Cartesian law (rule 3) and SLIP for the polar one
(rule 2).
"""

from __future__ import annotations

import math
import time
from typing import NamedTuple, Protocol

import numpy as np
import numpy.typing as npt

from dolfinx_nnqem.names import LAW_ALIASES, LAW_NAMES

__all__ = [
    "OPEN",
    "STICK",
    "SLIP",
    "STATE_NAMES",
    "LAW_ALIASES",
    "LAW_NAMES",
    "LawEvaluation",
    "Linearisation",
    "ContactLaw",
    "AlartCurnierLaw",
    "PolarLaw",
    "get_law",
    "alart_curnier_kernel",
    "polar_kernel",
    "force_from_unknowns",
    "unknowns_from_force",
    "default_r",
]

OPEN: int = 0
"""Pair state: no contact (p_n - r g <= 0)."""
STICK: int = 1
"""Pair state: contact, interior branch of the friction projection (no slip)."""
SLIP: int = 2
"""Pair state: contact, bound branch of the friction projection (|q| = mu_f p_n)."""
STATE_NAMES: tuple[str, str, str] = ("open", "stick", "slip")
"""Names of the states, indexed by the state code."""


class LawEvaluation(NamedTuple):
    """Values and generalized Jacobians of a pair law at (w, z).

    Attributes
    ----------
    H
        (nc, 3) residuals, force units.
    dH_dw
        (nc, 3, 3) B-Jacobian with respect to the relative displacement w.
    dH_dz
        (nc, 3, 3) B-Jacobian with respect to the law's unknowns z.
    state
        (nc,) int8, :data:`OPEN`, :data:`STICK` or :data:`SLIP` (the differentiated branch).
    """

    H: np.ndarray
    dH_dw: np.ndarray
    dH_dz: np.ndarray
    state: np.ndarray


class Linearisation(NamedTuple):
    """The law's part of a Newton step, in the coordinates y the law steps in.

    A Newton step solves for dy; the new unknowns are ``law.advance(z, dy, α, cartesian, force_unit)``. For
    the Cartesian law y = z. For the polar law y = z except on the pairs flagged ``cartesian``,
    whose tangential step is taken in the friction force itself (see
    :meth:`PolarLaw.linearise`).

    Attributes
    ----------
    dH_dy
        (nc, 3, 3) ∂H/∂y.
    dlam_dy
        (nc, 3, 3) ∂λ/∂y.
    cartesian
        (nc,) bool, or None: pairs whose y = (p_n, λ_t1, λ_t2).
    augmentation
        (nc, 3) weights of the pair rows where the Newton system is augmented with them (the
        monolithic solver's iterative system, :class:`~dolfinx_nnqem.solvers.block_system.AugmentedSystem`),
        or None: every row at weight 1. See :meth:`PolarLaw.augmentation_weights`.
    """

    dH_dy: np.ndarray
    dlam_dy: np.ndarray
    cartesian: np.ndarray | None
    augmentation: np.ndarray | None = None


# ---------------------------------------------------------------------------------------------
# the kernels (one loop over pairs each), compiled by numba when it pays (_CompiledWhenItPays)
# ---------------------------------------------------------------------------------------------


def alart_curnier_kernel(w: np.ndarray, w_prev: np.ndarray, z: np.ndarray, g0: np.ndarray, mu_f: np.ndarray,
                         r: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cartesian Alart--Curnier law, z = (p_n, q1, q2) (``formulation.md`` §3 B).

    H_n = p_n - max(0, p_n - r g),  H_t = q - P_D(rho)(q - r s),  rho = mu_f max(0, p_n - r g).

    Inputs are not validated (use :class:`AlartCurnierLaw`). Returns H, dH_dw, dH_dz, state;
    see the module docstring for the kink conventions.
    """
    nc = w.shape[0]
    H = np.zeros((nc, 3))
    dH_dw = np.zeros((nc, 3, 3))
    dH_dz = np.zeros((nc, 3, 3))
    state = np.zeros(nc, dtype=np.int8)
    for i in range(nc):
        p_n = z[i, 0]
        q1 = z[i, 1]
        q2 = z[i, 2]
        mu = mu_f[i]
        gap = g0[i] + w[i, 0]
        s1 = w[i, 1] - w_prev[i, 1]
        s2 = w[i, 2] - w_prev[i, 2]
        a = p_n - r * gap

        # Normal row. a == 0 takes the open branch (rule 1): max(0, a) -> 0.
        if a > 0.0:
            H[i, 0] = r * gap
            dH_dw[i, 0, 0] = r
            rho = mu * a
        else:
            H[i, 0] = p_n
            dH_dz[i, 0, 0] = 1.0
            rho = 0.0

        if rho > 0.0:
            x1 = q1 - r * s1
            x2 = q2 - r * s2
            norm_x = math.sqrt(x1 * x1 + x2 * x2)
            if norm_x <= rho:
                # Stick (rule 3 at |x| = rho): P_D(x) = x, so H_t = q - x = r s.
                H[i, 1] = r * s1
                H[i, 2] = r * s2
                dH_dw[i, 1, 1] = r
                dH_dw[i, 2, 2] = r
                state[i] = 1
            else:
                # Slip: P_D(x) = rho n, n = x/|x|; |x| > rho > 0 so the division is safe.
                n1 = x1 / norm_x
                n2 = x2 / norm_x
                k = rho / norm_x
                # T = I - n n^T is dP/dx * |x|/rho.
                t11 = 1.0 - n1 * n1
                t12 = -n1 * n2
                t22 = 1.0 - n2 * n2
                H[i, 1] = q1 - rho * n1
                H[i, 2] = q2 - rho * n2
                # dH_t/dq = I - k T
                dH_dz[i, 1, 1] = 1.0 - k * t11
                dH_dz[i, 1, 2] = -k * t12
                dH_dz[i, 2, 1] = -k * t12
                dH_dz[i, 2, 2] = 1.0 - k * t22
                # dH_t/dw_t = -k T (-r I) = r k T
                dH_dw[i, 1, 1] = r * k * t11
                dH_dw[i, 1, 2] = r * k * t12
                dH_dw[i, 2, 1] = r * k * t12
                dH_dw[i, 2, 2] = r * k * t22
                # rho = mu (p_n - r (g0 + w_n)): d rho/dp_n = mu, d rho/dw_n = -mu r.
                dH_dz[i, 1, 0] = -mu * n1
                dH_dz[i, 2, 0] = -mu * n2
                dH_dw[i, 1, 0] = mu * r * n1
                dH_dw[i, 2, 0] = mu * r * n2
                state[i] = 2
        else:
            # rho = 0 (rule 4): projection onto {0}, H_t = q.
            H[i, 1] = q1
            H[i, 2] = q2
            dH_dz[i, 1, 1] = 1.0
            dH_dz[i, 2, 2] = 1.0
            state[i] = 0 if a <= 0.0 else 2
    return H, dH_dw, dH_dz, state


def polar_kernel(w: np.ndarray, w_prev: np.ndarray, z: np.ndarray, g0: np.ndarray, mu_f: np.ndarray,
                 r: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Polar (seed) law, z = (p_n, p_r, theta) (``formulation.md`` §3 A).

    H1 = min(p_n, r g),  H2 = p_r - max(-rho, min(rho, p_r + r s.d)),
    H3 = r (s1 sin theta - s2 cos theta),  d = (cos theta, sin theta),
    rho = mu_f max(0, p_n - r g).

    Inputs are not validated (use :class:`PolarLaw`). Returns H, dH_dw, dH_dz, state; see the
    module docstring for the kink conventions.
    """
    nc = w.shape[0]
    H = np.zeros((nc, 3))
    dH_dw = np.zeros((nc, 3, 3))
    dH_dz = np.zeros((nc, 3, 3))
    state = np.zeros(nc, dtype=np.int8)
    for i in range(nc):
        p_n = z[i, 0]
        p_r = z[i, 1]
        theta = z[i, 2]
        mu = mu_f[i]
        c = math.cos(theta)
        sn = math.sin(theta)
        gap = g0[i] + w[i, 0]
        s1 = w[i, 1] - w_prev[i, 1]
        s2 = w[i, 2] - w_prev[i, 2]
        a = p_n - r * gap

        # H1 = min(p_n, r g); the tie takes p_n (rule 1).
        if a > 0.0:
            H[i, 0] = r * gap
            dH_dw[i, 0, 0] = r
            rho = mu * a
        else:
            H[i, 0] = p_n
            dH_dz[i, 0, 0] = 1.0
            rho = 0.0

        s_d = s1 * c + s2 * sn  # s . d(theta)
        s_dp = -s1 * sn + s2 * c  # s . d'(theta)
        y = p_r + r * s_d

        if rho > 0.0:
            if y >= rho:
                # Upper bound (rule 2: min(rho, y) takes rho at y = rho).
                H[i, 1] = p_r - rho
                dH_dz[i, 1, 1] = 1.0
                dH_dz[i, 1, 0] = -mu
                dH_dw[i, 1, 0] = mu * r
                state[i] = 2
            elif y <= -rho:
                # Lower bound (rule 2: max(-rho, y) takes -rho at y = -rho).
                H[i, 1] = p_r + rho
                dH_dz[i, 1, 1] = 1.0
                dH_dz[i, 1, 0] = mu
                dH_dw[i, 1, 0] = -mu * r
                state[i] = 2
            else:
                # Interior: H2 = p_r - y = -r s.d.
                H[i, 1] = -r * s_d
                dH_dz[i, 1, 2] = -r * s_dp
                dH_dw[i, 1, 1] = -r * c
                dH_dw[i, 1, 2] = -r * sn
                state[i] = 1
        else:
            # rho = 0 (rule 4): projection onto {0}, H2 = p_r.
            H[i, 1] = p_r
            dH_dz[i, 1, 1] = 1.0
            state[i] = 0 if a <= 0.0 else 2

        # H3 = r (s x d): smooth; d/dtheta = r s.d, which is 0 (not NaN) at s = 0.
        H[i, 2] = r * (s1 * sn - s2 * c)
        dH_dz[i, 2, 2] = r * s_d
        dH_dw[i, 2, 1] = r * sn
        dH_dw[i, 2, 2] = -r * c
    return H, dH_dw, dH_dz, state


# ---------------------------------------------------------------------------------------------
# Input validation shared by the laws
# ---------------------------------------------------------------------------------------------


def _as_pairs_array(name: str, value: npt.ArrayLike, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as a C-contiguous float64 array of exactly ``shape`` (error names the array)."""
    array = np.ascontiguousarray(value, dtype=np.float64)
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {array.shape}")
    return array


def _check_r(r: float) -> float:
    """r as a float; it must be finite and > 0 (force/length)."""
    r = float(r)
    if not (math.isfinite(r) and r > 0.0):
        raise ValueError(f"r must be finite and > 0, got r = {r!r}")
    return r


def _check_mu_f(mu_f: npt.ArrayLike, nc: int) -> np.ndarray:
    """mu_f broadcast to (nc,); every value must be finite and >= 0."""
    mu = np.asarray(mu_f, dtype=np.float64)
    if mu.ndim == 0:
        mu = np.full(nc, float(mu))
    elif mu.shape != (nc,):
        raise ValueError(f"mu_f must be a scalar or have shape ({nc},), got {mu.shape}")
    bad = ~(np.isfinite(mu) & (mu >= 0.0))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"mu_f must be finite and >= 0, got mu_f = {float(mu[i])!r} (pair {i}, "
            f"{int(bad.sum())} invalid value(s))"
        )
    return np.ascontiguousarray(mu)


class _CompiledWhenItPays:
    """A pair-law kernel run as plain Python until compiling it with numba pays.

    Numba's first call of a kernel costs about a quarter of a second even with its disk cache
    warm (its import and the set-up of its compiler; together 0.35 s of CPU, of the 1.1 s a
    whole run of the two-beam benchmark took), while the plain Python kernel takes about 6 µs
    per pair (``docs/performance.md``). So the kernel runs as Python until the time spent there
    reaches what numba's start costs (:data:`COMPILE_AFTER_S`), then compiled (``cache=True``:
    numba's disk cache next to this file): never much more than twice the cheaper of the two
    choices in hindsight (the ski-rental rule), and a small run never pays for numba. Both
    perform the same IEEE operations in the same order (numba neither fuses nor reorders them
    without ``fastmath``): the results are bit for bit the same (``tests/unit/test_laws.py``).
    """

    def __init__(self, kernel):
        self.kernel = kernel
        self.compiled = None  #: numba's dispatcher, once compiling has paid
        self.python_s = 0.0  #: seconds spent in the Python kernel so far

    def __call__(self, *args):
        if self.compiled is not None:
            return self.compiled(*args)
        t0 = time.perf_counter()
        try:
            return self.kernel(*args)
        finally:
            self.python_s += time.perf_counter() - t0
            if self.python_s >= COMPILE_AFTER_S:
                self.compile()

    def compile(self):
        """numba's compiled kernel (from its disk cache when it is there); used from now on."""
        if self.compiled is None:
            import numba

            from dolfinx_nnqem.chatter import apply_numba_options

            apply_numba_options()
            self.compiled = numba.njit(cache=True)(self.kernel)
        return self.compiled


COMPILE_AFTER_S: float = 0.25
"""Seconds a pair-law kernel runs as plain Python before numba's compiled version takes over
(about what numba's start costs, :class:`_CompiledWhenItPays`)."""

_ALART_CURNIER = _CompiledWhenItPays(alart_curnier_kernel)
_POLAR = _CompiledWhenItPays(polar_kernel)


def _check_inputs(
    w: npt.ArrayLike,
    w_prev: npt.ArrayLike,
    z: npt.ArrayLike,
    g0: npt.ArrayLike,
    mu_f: npt.ArrayLike,
    r: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Validated, contiguous float64 copies of the kernel arguments.

    ``w``, ``w_prev`` and ``z`` are not checked for finiteness on purpose: a NaN iterate must
    reach the nonlinear solver as a NaN residual, which reports the iteration it appeared in.
    """
    w = np.ascontiguousarray(w, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != 3:
        raise ValueError(f"w must have shape (nc, 3), got {w.shape}")
    nc = w.shape[0]
    w_prev = _as_pairs_array("w_prev", w_prev, (nc, 3))
    z = _as_pairs_array("z", z, (nc, 3))
    g0 = _as_pairs_array("g0", g0, (nc,))
    if not np.isfinite(g0).all():
        raise ValueError("g0 must be finite")
    return w, w_prev, z, g0, _check_mu_f(mu_f, nc), _check_r(r)


def _check_z(name: str, z: npt.ArrayLike) -> np.ndarray:
    """``z`` as a float64 array of shape (nc, 3)."""
    array = np.asarray(z, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name} must have shape (nc, 3), got {array.shape}")
    return array


# ---------------------------------------------------------------------------------------------
# The laws as small objects
# ---------------------------------------------------------------------------------------------


class ContactLaw(Protocol):
    """What callers may use of a pair law (the contact model; solvers never look inside)."""

    name: str

    def evaluate(
        self,
        w: npt.ArrayLike,
        w_prev: npt.ArrayLike,
        z: npt.ArrayLike,
        g0: npt.ArrayLike,
        mu_f: npt.ArrayLike,
        r: float,
    ) -> LawEvaluation:
        """H, dH/dw, dH/dz and the states of the pairs at (w, z), with w_prev the relative
        displacement at the start of the step, gaps g0 (nc,), friction coefficients mu_f and the
        scaling parameter r (force/length)."""
        ...

    def force(self, z: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The contact force λ(z) (nc, 3) = (p_n, q1, q2) and dλ/dz (nc, 3, 3)."""
        ...

    def unknowns(self, lam: npt.ArrayLike, slip: npt.ArrayLike | None = None,
                 no_force: float = 0.0, constrained: npt.ArrayLike | None = None) -> np.ndarray:
        """The unknowns z (nc, 3) giving the force ``lam``: the inverse of :meth:`force` (``slip``,
        ``no_force`` and ``constrained`` choose z where the force gives no tangential direction)."""
        ...

    def unknown_scale(self, force_scale: float) -> np.ndarray:
        """(3,) the scale of each component of z when forces scale with ``force_scale``."""
        ...

    def pin(self, evaluation: LawEvaluation, z: npt.ArrayLike, constrained: npt.ArrayLike,
            force_unit: float) -> LawEvaluation:
        """``evaluation`` with the rows of the directions the supports fix (``constrained`` (nc, 3)
        bool) replaced by rows in z alone that vanish with λ_k (see :func:`_pin_rows`)."""
        ...

    def initial_unknowns(self, constrained: npt.ArrayLike) -> np.ndarray:
        """z of pairs without force, (nc, 3), for the pinned directions ``constrained`` (nc, 3)."""
        ...

    def linearise(self, z: npt.ArrayLike, evaluation: LawEvaluation, constrained: npt.ArrayLike,
                  force_unit: float, sliding_in_force: bool = True) -> Linearisation:
        """The Jacobian blocks of a Newton step at z (``evaluation`` pinned), in the law's step coordinates."""
        ...

    def advance(self, z: npt.ArrayLike, dy: npt.ArrayLike, alpha: float,
                cartesian: np.ndarray | None, force_unit: float) -> np.ndarray:
        """The unknowns after the step α dy from z (``cartesian`` from :meth:`linearise`;
        ``force_unit``: forces below :data:`NO_FORCE` times it are rounding)."""
        ...

    slip_following: bool
    """True if :meth:`follow_slip` can change z (the law has unknowns no force depends on)."""

    def follow_slip(self, z: npt.ArrayLike, w: npt.ArrayLike, w_prev: npt.ArrayLike, constrained: npt.ArrayLike,
                    force_unit: float, sliding: npt.ArrayLike | None = None) -> np.ndarray:
        """z with the unknowns on which no force depends at z set to where their rows vanish at
        (w, z), and on the ``sliding`` pairs (nc,) bool, if given, the unknowns that give the
        friction force its direction; the others as they are."""
        ...


class AlartCurnierLaw:
    """Cartesian Alart--Curnier law; unknowns z = lambda = (p_n, q1, q2).

    Regular wherever the polar form is singular: the robust default.
    """

    name: str = "alart-curnier"
    slip_following: bool = False

    def evaluate(
        self,
        w: npt.ArrayLike,
        w_prev: npt.ArrayLike,
        z: npt.ArrayLike,
        g0: npt.ArrayLike,
        mu_f: npt.ArrayLike,
        r: float,
    ) -> LawEvaluation:
        """H, dH/dw, dH/dz and states of all pairs (shapes in the module docstring).

        Parameters
        ----------
        w, w_prev, z
            (nc, 3) relative displacement, its value at the start of the step, unknowns.
        g0
            (nc,) initial gaps.
        mu_f
            Friction coefficient, scalar or (nc,), finite and >= 0.
        r
            Scaling parameter (force/length), finite and > 0.
        """
        return LawEvaluation(*_ALART_CURNIER(*_check_inputs(w, w_prev, z, g0, mu_f, r)))

    def force(self, z: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Force lambda = z and d lambda/dz = I (nc, 3, 3)."""
        z = _check_z("z", z)
        return z.copy(), np.broadcast_to(np.eye(3), (z.shape[0], 3, 3)).copy()

    def unknowns(self, lam: npt.ArrayLike, slip: npt.ArrayLike | None = None,
                 no_force: float = 0.0, constrained: npt.ArrayLike | None = None) -> np.ndarray:
        """Unknowns z = lambda (``slip``, ``no_force`` and ``constrained`` are not needed)."""
        return _check_z("lam", lam).copy()

    def unknown_scale(self, force_scale: float) -> np.ndarray:
        """Scale of (p_n, q1, q2): all forces, so all ``force_scale``."""
        return np.full(3, float(force_scale))

    def pin(self, evaluation: LawEvaluation, z: npt.ArrayLike, constrained: npt.ArrayLike,
            force_unit: float) -> LawEvaluation:
        """Rows of directions the supports fix become λ_k = 0 (see :func:`_pin_rows`)."""
        constrained = np.asarray(constrained, dtype=bool)
        if not constrained.any():
            return evaluation
        z = np.asarray(z, dtype=np.float64)
        values = np.zeros_like(evaluation.H)
        derivatives = np.zeros_like(evaluation.dH_dz)
        values[:, 0] = z[:, 0]
        derivatives[:, 0, 0] = 1.0
        values[:, 1:] = z[:, 1:]
        derivatives[:, 1, 1] = derivatives[:, 2, 2] = 1.0
        return _pin_rows(evaluation, constrained, values, derivatives)

    def initial_unknowns(self, constrained: npt.ArrayLike) -> np.ndarray:
        """Zero force: z = 0."""
        return np.zeros((np.shape(constrained)[0], 3))

    def linearise(self, z: npt.ArrayLike, evaluation: LawEvaluation, constrained: npt.ArrayLike,
                  force_unit: float, sliding_in_force: bool = True) -> Linearisation:
        """The unknowns are the force: y = z, ∂λ/∂y = I."""
        return Linearisation(evaluation.dH_dz, self.force(z)[1], None)

    def advance(self, z: npt.ArrayLike, dy: npt.ArrayLike, alpha: float,
                cartesian: np.ndarray | None, force_unit: float) -> np.ndarray:
        """z + α dy."""
        return np.asarray(z, dtype=np.float64) + alpha * np.asarray(dy, dtype=np.float64)

    def follow_slip(self, z: npt.ArrayLike, w: npt.ArrayLike, w_prev: npt.ArrayLike, constrained: npt.ArrayLike,
                    force_unit: float, sliding: npt.ArrayLike | None = None) -> np.ndarray:
        """z as it is: every Cartesian unknown is a force, and no row fixes a direction alone."""
        return np.asarray(z, dtype=np.float64)

    def __repr__(self) -> str:
        return "AlartCurnierLaw()"


MAX_TURN = 0.25 * np.pi
"""Largest turn of a polar angle θ in one Newton step (radians); see :meth:`PolarLaw.advance`."""

NO_FORCE = 1e-14
"""A polar force component at most this times the force unit r h is zero (rounding)."""


class PolarLaw:
    """Polar (seed) law; unknowns z = (p_n, p_r, theta), force (p_n, -p_r d(theta)).

    Its Jacobian in (p_r, theta) is singular where p_r = 0 in stick (d q/d theta = 0) and where
    s = 0 in the open state (H3 vanishes identically in theta); Newton steps are therefore taken
    in the coordinates of :meth:`linearise`, which are regular there.
    """

    name: str = "polar"
    slip_following: bool = True

    def evaluate(
        self,
        w: npt.ArrayLike,
        w_prev: npt.ArrayLike,
        z: npt.ArrayLike,
        g0: npt.ArrayLike,
        mu_f: npt.ArrayLike,
        r: float,
    ) -> LawEvaluation:
        """H, dH/dw, dH/dz and states of all pairs.

        Parameters as in :meth:`AlartCurnierLaw.evaluate`.
        """
        return LawEvaluation(*_POLAR(*_check_inputs(w, w_prev, z, g0, mu_f, r)))

    def force(self, z: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Force lambda = (p_n, -p_r cos theta, -p_r sin theta) and d lambda/dz (nc, 3, 3)."""
        z = _check_z("z", z)
        p_n, p_r, theta = z[:, 0], z[:, 1], z[:, 2]
        c, sn = np.cos(theta), np.sin(theta)
        lam = np.column_stack((p_n, -p_r * c, -p_r * sn))
        dlam_dz = np.zeros((z.shape[0], 3, 3))
        dlam_dz[:, 0, 0] = 1.0
        dlam_dz[:, 1, 1] = -c
        dlam_dz[:, 2, 1] = -sn
        dlam_dz[:, 1, 2] = p_r * sn
        dlam_dz[:, 2, 2] = -p_r * c
        return lam, dlam_dz

    def unknowns(self, lam: npt.ArrayLike, slip: npt.ArrayLike | None = None,
                 no_force: float = 0.0, constrained: npt.ArrayLike | None = None) -> np.ndarray:
        """(p_n, p_r, theta) with p_r = |q| >= 0 and d(theta) = -q/|q|.

        Where |q| <= ``no_force`` the force gives no direction: theta is the direction of
        ``slip`` (n, 2) if given (H3 needs slip parallel to d), else 0. Pairs with pinned
        tangential directions (``constrained`` (n, 3)) take the angle :meth:`pin` holds them at.
        """
        lam = _check_z("lam", lam)
        q1, q2 = lam[:, 1], lam[:, 2]
        p_r = np.hypot(q1, q2)
        # q = -p_r d  =>  d = -q/|q|; atan2 of -0.0 would give +-pi, hence the explicit 0.
        theta = np.where(p_r > 0.0, np.arctan2(-q2, -q1), 0.0)
        z = np.column_stack((lam[:, 0], p_r, theta))
        if slip is not None:
            slip = np.asarray(slip, dtype=np.float64)
            undirected = p_r <= no_force
            z[undirected, 2] = np.arctan2(slip[undirected, 1], slip[undirected, 0])
        if constrained is not None:  # pinned directions: θ on θ* (see pin), p_r the signed force along d(θ*)
            constrained = np.asarray(constrained, dtype=bool)
            only_t1, only_t2 = constrained[:, 1] & ~constrained[:, 2], constrained[:, 2] & ~constrained[:, 1]
            both = constrained[:, 1] & constrained[:, 2]
            z[only_t2, 1], z[only_t2, 2] = -q1[only_t2], 0.0  # d = (1, 0)
            z[only_t1, 1], z[only_t1, 2] = -q2[only_t1], 0.5 * np.pi  # d = (0, 1)
            z[both, 1], z[both, 2] = 0.0, 0.0
        return z

    def unknown_scale(self, force_scale: float) -> np.ndarray:
        """Scale of (p_n, p_r, theta): forces scale with ``force_scale``, the angle does not."""
        return np.array([float(force_scale), float(force_scale), 1.0])

    def pin(self, evaluation: LawEvaluation, z: npt.ArrayLike, constrained: npt.ArrayLike,
            force_unit: float) -> LawEvaluation:
        """Rows of directions the supports fix (see :func:`_pin_rows`).

        When both tangential directions are constrained, H2 = p_r and H3 = force_unit · θ; when
        only t2 (t1) is, the slip-direction row becomes H3 = force_unit · θ (force_unit · (θ − π/2)),
        so the friction force acts along t1 (t2) only and H2 still enforces Coulomb's law along it.
        """
        constrained = np.asarray(constrained, dtype=bool)
        if not constrained.any():
            return evaluation
        z = np.asarray(z, dtype=np.float64)
        rows = np.zeros_like(constrained)
        values = np.zeros_like(evaluation.H)
        derivatives = np.zeros_like(evaluation.dH_dz)
        rows[:, 0] = constrained[:, 0]
        values[:, 0] = z[:, 0]
        derivatives[:, 0, 0] = 1.0
        theta = z[:, 2]
        both = constrained[:, 1] & constrained[:, 2]
        only_t2 = constrained[:, 2] & ~constrained[:, 1]
        only_t1 = constrained[:, 1] & ~constrained[:, 2]
        rows[:, 1] = both
        rows[:, 2] = both | only_t1 | only_t2
        values[:, 1] = z[:, 1]
        derivatives[:, 1, 1] = 1.0
        # θ = 0 (force along t1) or θ = π/2 (along t2); the signed p_r gives either sense. Linear
        # in θ on purpose: sin θ or cos θ would have a zero derivative at the usual start θ = 0.
        values[:, 2] = force_unit * np.where(only_t1, theta - 0.5 * np.pi, theta)
        derivatives[:, 2, 2] = force_unit
        return _pin_rows(evaluation, rows, values, derivatives)

    def initial_unknowns(self, constrained: npt.ArrayLike) -> np.ndarray:
        """Zero force, p_n = p_r = 0; θ = π/2 where only t1 is pinned, else 0.

        With one tangential direction pinned, :meth:`pin` puts θ on θ* (0: the friction force
        along t1, π/2: along t2). Starting there matters: at θ = 0 with t1 pinned, d(θ) points
        along the pinned direction, whose force only feeds the supports, and both the force's
        p_r-derivative and the sticking row −r s·d would vanish from the free equations.
        """
        constrained = np.asarray(constrained, dtype=bool)
        z = np.zeros((constrained.shape[0], 3))
        z[constrained[:, 1] & ~constrained[:, 2], 2] = 0.5 * np.pi
        return z

    def linearise(self, z: npt.ArrayLike, evaluation: LawEvaluation, constrained: npt.ArrayLike,
                  force_unit: float, sliding_in_force: bool = True) -> Linearisation:
        """Newton step coordinates that keep the polar law's step regular.

        The map (p_r, θ) → q = −p_r d(θ) is singular at p_r = 0 (∂q/∂θ = 0): a sticking pair
        without friction force — every pair at the first iterate, the centre of a pressed face —
        gives the Newton matrix a zero column, and a step in (p_r, θ) can change q only along
        d(θ). Two changes of coordinates remove this without changing the equations H = 0:

        * Sticking pairs (interior branch, no pinned direction) step in the friction force
          itself, y = (p_n, λ_t1, λ_t2): ∂λ/∂y = I. Their rows H2 = −r s·d, H3 = r s×d (a
          rotation of r s) depend on θ only through terms of order |s|, which vanish at a
          sticking solution; they are dropped, as a Newton method may drop Jacobian terms of the
          order of the error without losing its quadratic rate. The step is then the
          Cartesian law's sticking step, and :meth:`advance` turns the new force back into
          (p_r, θ) with θ as close as possible to the old one.
        * Open or frictionless pairs (ρ = 0): H2 = p_r drives the force to zero and θ only has to
          follow the slip (H3 = r s×d). ∂λ/∂θ = −p_r d' is dropped (it vanishes with p_r at the
          solution; kept, a large turn of θ where the slip is nearly normal to d would enter
          every other row of the step), and at rest (s·d = 0, so H3 vanishes for every θ)
          ∂H3/∂θ is set to r h (``force_unit``): the step then turns θ towards the predicted slip.

        * With ``sliding_in_force`` (the dense solvers), sliding pairs (p_r ≠ 0) step in the
          force too, with the exact Jacobian by the chain rule (∂p_r/∂q = −d, ∂θ/∂q = −d'/p_r):
          the same Newton direction, but the force moves along a chord instead of θ turning
          (where the slip has just started, ∂H3/∂θ = r s·d is small and a step in θ large).

        (Pairs with one pinned tangential direction start at their angle θ*, see
        :meth:`initial_unknowns`.)
        """
        z = np.asarray(z, dtype=np.float64)
        constrained = np.asarray(constrained, dtype=bool)
        _, dlam_dz = self.force(z)
        dH_dy, dlam_dy = evaluation.dH_dz.copy(), dlam_dz
        free = ~constrained[:, 1] & ~constrained[:, 2]
        cartesian = (evaluation.state == STICK) & free
        dH_dy[cartesian, :, 1:] = 0.0
        dlam_dy[cartesian, 1:, 1:] = np.eye(2)
        # no friction bound (open, or frictionless): H2 = p_r drives the force to zero and θ only
        # has to follow the slip (H3). ∂λ/∂θ = −p_r d' vanishes with p_r at the solution; kept, it
        # couples a large turn of θ (slip nearly normal to d) into the whole system's step
        unbounded = free & ((evaluation.state == OPEN)
                            | ((evaluation.state == SLIP) & (evaluation.dH_dz[:, 1, 0] == 0.0)))
        dlam_dy[unbounded, 1:, 2] = 0.0
        tiny = NO_FORCE * float(force_unit)
        at_rest = unbounded & (np.abs(evaluation.dH_dz[:, 2, 2]) <= tiny)
        dH_dy[at_rest, 2, 2] = float(force_unit)
        # sliding pairs with a friction force: the same Newton direction, taken in the force
        # (∂H/∂q = ∂H/∂p_r ∂p_r/∂q + ∂H/∂θ ∂θ/∂q with ∂p_r/∂q = −d, ∂θ/∂q = −d'/p_r), so that the
        # step moves q along a chord instead of turning θ (a slip just started, |s| small, makes
        # ∂H3/∂θ = r s·d small and the step in θ large)
        sliding = free & (evaluation.state == SLIP) & ~unbounded & (np.abs(z[:, 1]) > tiny) & sliding_in_force
        if np.any(sliding):
            p_r, theta = z[sliding, 1], z[sliding, 2]
            d = np.column_stack((np.cos(theta), np.sin(theta)))
            d_prime = np.column_stack((-np.sin(theta), np.cos(theta)))
            dz_dq = -np.stack((d, d_prime / p_r[:, None]), axis=1)  # rows p_r, θ; columns q1, q2
            dH_dy[sliding, :, 1:] = np.einsum("nij,njk->nik", evaluation.dH_dz[sliding, :, 1:], dz_dq)
            dlam_dy[sliding, 1:, 1:] = np.eye(2)
            cartesian = cartesian | sliding
        return Linearisation(dH_dy, dlam_dy, cartesian, self.augmentation_weights(z, evaluation, unbounded))

    @staticmethod
    def augmentation_weights(z: np.ndarray, evaluation: LawEvaluation, unbounded: np.ndarray) -> np.ndarray:
        """(nc, 3) weights of the rows (H1, H2, H3) in an augmented Newton system: 1, except for H3
        of pairs without a friction bound (``unbounded``: open or frictionless), weight 0, and of
        pairs sliding at the bound, weight |p_r| / (|p_r| + r |s·d|).

        The augmentation adds c Bᵀ D_wᵀ Σ² times the pair rows to the u rows (Σ these weights):
        a penalty c D_wᵀ Σ² D_w on the pair's relative displacement. H3 = r s×d has
        ∂H3/∂w = −r d′ whatever the state, so at weight 1 every pair's slip normal to d(θ) is
        penalised with stiffness r — also where nothing resists it, since θ turns with the slip
        (∂H3/∂θ = r s·d): the u block then holds a stiffness that the pair block's Schur
        complement has to take back, the difference r s·d (1 − β) of two terms of order r |s| with
        β ≈ 1, where the answer is of order |p_r|. The ``selfp`` approximation of β (diag(A00)⁻¹
        for A00⁻¹) is off by O(1) and gives that entry the wrong sign (docs/theory.md, the
        iterative linear solver). At the weights above the penalty is what the Cartesian law's
        row normal to the slip gives: H3 times |p_r| / (|p_r| + r |s·d|) is −1 times that row,
        r k dw⊥ + (1 − k) dq⊥ with k = ρ / |q − r s|, where the force is at the bound and
        opposes the slip; open pairs' θ moves no force, and their H3 is no constraint on u.
        (Pinned rows have ∂H/∂w = 0: no weight matters there.) Only the iterative solver's
        augmented system uses the weights, and its solution, the Newton step, is the same for any.
        """
        z = np.asarray(z, dtype=np.float64)
        weights = np.ones((z.shape[0], 3))
        weights[unbounded, 2] = 0.0
        bound = (evaluation.state == SLIP) & ~unbounded
        friction = np.abs(z[bound, 1])
        total = friction + np.abs(evaluation.dH_dz[bound, 2, 2])  # |p_r| + r |s·d|
        weights[bound, 2] = np.divide(friction, total, out=np.ones_like(total), where=total > 0.0)
        return weights

    def advance(self, z: npt.ArrayLike, dy: npt.ArrayLike, alpha: float,
                cartesian: np.ndarray | None, force_unit: float) -> np.ndarray:
        """z + α dy, θ turned by at most :data:`MAX_TURN`; on ``cartesian`` pairs the new friction
        force λ_t + α dy_t in polar form.

        Of the two representations (|q|, θ) and (−|q|, θ + π) the one whose angle is nearer the
        old θ is taken, so that a small change of force is a small change of (p_r, θ) (θ is not
        wrapped: it moves continuously). A force of rounding size (|q| ≤ :data:`NO_FORCE` ·
        ``force_unit``, e.g. an open pair's p_r of 1e-20 N) keeps θ: its direction is the
        direction of rounding errors, which differ between machines and libraries (measured: the
        secant predictor of the polar law's pairs turned open pairs by up to 0.27 rad differently
        on the PyPI and the Debian stacks, and the contact solve that followed failed on one).
        """
        z = np.asarray(z, dtype=np.float64)
        dy = np.asarray(dy, dtype=np.float64)
        out = z + alpha * dy
        # H3 = r |s| sin(θ − θ_s) (θ_s the slip's angle): far from its zero, where the slope r s·d
        # is small, a Newton step spins θ by many turns; near the solution steps are small, so
        # clipping them (pair by pair: θ of an open pair is decoupled) keeps the local rate
        out[:, 2] = z[:, 2] + np.clip(alpha * dy[:, 2], -MAX_TURN, MAX_TURN)
        if cartesian is None or not np.any(cartesian):
            return out
        c = np.asarray(cartesian, dtype=bool)
        p_r, theta = z[c, 1], z[c, 2]
        q = -p_r[:, None] * np.column_stack((np.cos(theta), np.sin(theta))) + alpha * dy[c, 1:]
        size = np.hypot(q[:, 0], q[:, 1])
        direction = np.arctan2(-q[:, 1], -q[:, 0])  # d(direction) = −q/|q|: p_r = +|q|
        turn = np.mod(direction - theta + np.pi, 2.0 * np.pi) - np.pi  # in [−π, π)
        flip = np.abs(turn) > 0.5 * np.pi  # nearer the other representation (p_r = −|q|, θ + π)
        turn = np.where(flip, turn - np.copysign(np.pi, turn), turn)
        rounding = size <= NO_FORCE * float(force_unit)  # keeps θ; p_r the force's component on −d(θ)
        along = -(q[:, 0] * np.cos(theta) + q[:, 1] * np.sin(theta))
        out[c, 1] = np.where(rounding, along, np.where(flip, -size, size))
        out[c, 2] = np.where(rounding, theta, theta + turn)
        return out

    def follow_slip(self, z: npt.ArrayLike, w: npt.ArrayLike, w_prev: npt.ArrayLike, constrained: npt.ArrayLike,
                    force_unit: float, sliding: npt.ArrayLike | None = None) -> np.ndarray:
        """θ of the pairs without friction force (|p_r| ≤ :data:`NO_FORCE` · ``force_unit``; no pinned
        direction) set on their slip: θ_s + kπ, the zero of H3 = r (s1 sin θ − s2 cos θ) nearest θ.

        Where p_r = 0 no force depends on θ, so moving it changes neither a force nor the
        equilibrium, only two things that should not depend on a meaningless angle: H3, and the
        branch of H2, decided by y = p_r + r s·d, whose projection of the slip on an arbitrary
        d(θ) makes a pair stick or slip at random. On the slip (d = ±s/|s|), y = ±r |s| and the
        branch is the Cartesian law's (|q − r s| = r |s| against ρ). This concerns every pair at
        rest before its first slip, and open pairs after a full Newton step (H2 = p_r); an open
        pair whose slip turns would otherwise need several steps of at most :data:`MAX_TURN`,
        with its H3 (of order r |s|, no physics) dominating the residual. Pairs at rest (s = 0)
        keep θ.

        With ``sliding`` (pairs at the Coulomb bound whose slip is above rounding, see
        :meth:`PairLaws.follow_slip`), θ of those pairs is put on the slip line too (θ_s + kπ
        nearest θ, p_r kept), which zeroes their H3 = r |s| sin(θ − θ_s) exactly. That does move
        a force; it replaces Newton's linearisation of a sine, which a step can only trust within
        :data:`MAX_TURN` while the slip is small and turns, by the exact local solution of the
        row. The monolithic solver uses it to retry an increment that failed without it.
        """
        z = np.array(z, dtype=np.float64, copy=True)
        w = np.asarray(w, dtype=np.float64)
        constrained = np.asarray(constrained, dtype=bool)
        s = w[:, 1:] - np.asarray(w_prev, dtype=np.float64)[:, 1:]
        turned = np.abs(z[:, 1]) <= NO_FORCE * float(force_unit)  # no friction force
        if sliding is not None:
            turned |= np.asarray(sliding, dtype=bool)
        follow = turned & ~constrained[:, 1] & ~constrained[:, 2] & (np.hypot(s[:, 0], s[:, 1]) > 0.0)
        theta_s = np.arctan2(s[follow, 1], s[follow, 0])
        z[follow, 2] = theta_s + np.pi * np.round((z[follow, 2] - theta_s) / np.pi)
        return z

    def __repr__(self) -> str:
        return "PolarLaw()"


_LAWS: dict[str, type] = dict(zip(LAW_NAMES, (AlartCurnierLaw, PolarLaw), strict=True))
_LAWS.update({alias: _LAWS[name] for alias, name in LAW_ALIASES.items()})


def get_law(name: str | ContactLaw) -> ContactLaw:
    """The law called ``name``: "alart-curnier"/"cartesian" or "polar"/"seed".

    A law object is returned unchanged. Names are case-insensitive.
    """
    if not isinstance(name, str):
        if all(hasattr(name, attr) for attr in ("name", "evaluate", "force", "unknowns")):
            return name
        raise TypeError(f"expected a law name or a law object, got {name!r}")
    try:
        return _LAWS[name.strip().lower()]()
    except KeyError:
        raise ValueError(
            f"unknown contact law {name!r}; expected one of {sorted(_LAWS)}"
        ) from None


def force_from_unknowns(law: str | ContactLaw, z: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Contact force lambda (nc, 3) of the unknowns ``z`` and d lambda/dz (nc, 3, 3)."""
    return get_law(law).force(z)


def unknowns_from_force(law: str | ContactLaw, lam: npt.ArrayLike) -> np.ndarray:
    """Unknowns z (nc, 3) giving the force ``lam``; the inverse of :func:`force_from_unknowns`.

    For the polar law p_r >= 0 and theta follows the tangential force direction (theta = 0 when
    q = 0). Meant for initial guesses.
    """
    return get_law(law).unknowns(lam)


def default_r(E: float, h: float) -> float:
    """Default scaling parameter r = E h (force/length).

    r converts the displacement-like arguments of the laws (the gap g, the slip s) into forces,
    to be compared with p_n and q inside the max/projection. The solution of H = 0 does not
    depend on r (every r > 0 gives exactly Coulomb's law); the convergence of the nonsmooth
    Newton method does: r sets how far an iterate's force and displacement errors are traded
    against each other when the active branch is chosen. A natural scale is the stiffness a node
    of the surface has against a relative displacement, about E times the element size h (a
    nodal force of order E h^2 eps, eps ~ w/h). With this r the rows H_n = r g and H_n = p_n are
    of the same size and both terms of p_n - r g change comparably during the iteration.

    Parameters
    ----------
    E
        Young's modulus (of the softer body, or a representative value), > 0.
    h
        Representative element size at the contact surface, > 0.
    """
    E = float(E)
    h = float(h)
    if not (math.isfinite(E) and E > 0.0):
        raise ValueError(f"E must be finite and > 0, got E = {E!r}")
    if not (math.isfinite(h) and h > 0.0):
        raise ValueError(f"h must be finite and > 0, got h = {h!r}")
    return E * h


def _pin_rows(evaluation: LawEvaluation, rows: np.ndarray, values: np.ndarray,
              derivatives: np.ndarray) -> LawEvaluation:
    """Replace the rows of directions whose relative motion the supports fix.

    When both sides of a pair are held by Dirichlet conditions in every global component a
    local direction k involves, w_k cannot change and λ_k only feeds the support reactions:
    it is statically indeterminate and its column in −Bᵀ vanishes (a singular Jacobian). Such
    components are set to zero (the minimum-norm choice): row k of H becomes a function of z
    alone (``values``, with the z-derivatives ``derivatives``) that vanishes with λ_k.

    Parameters
    ----------
    rows
        (nc, 3) bool: the rows to replace.
    values, derivatives
        (nc, 3) and (nc, 3, 3): the new rows and their derivatives with respect to z.
    """
    H, dH_dw, dH_dz = evaluation.H.copy(), evaluation.dH_dw.copy(), evaluation.dH_dz.copy()
    H[rows] = values[rows]
    dH_dw[rows] = 0.0
    dH_dz[rows] = derivatives[rows]
    return LawEvaluation(H, dH_dw, dH_dz, evaluation.state)
