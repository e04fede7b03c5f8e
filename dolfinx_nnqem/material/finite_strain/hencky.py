"""Elastoplasticity at finite strain by the logarithmic (Hencky) strain and the exponential map:
every small-strain return map of :mod:`dolfinx_nnqem.material` reused unchanged.

Simo (1992), Eterovic & Bathe (1990), Miehe, Apel & Lambrecht (2002); ``formulation.md`` §1c.
F = F_e F_p, b_e = F_e F_eᵀ; the state of an increment is (F_n, b_e,n, the internal variables).
From the deformation gradient F = F_{n+1}:

1. the relative deformation f = F F_n⁻¹ and the elastic trial b_e^tr = f b_e,n fᵀ (the plastic
   flow frozen), its logarithmic strain ε^tr = ½ ln b_e^tr (spectral decomposition:
   :mod:`.spectral`);
2. the small-strain return map of the material (its
   :class:`~dolfinx_nnqem.material.interface.PointwiseMaterial`, called as it is) at the trial
   strain ε^tr: its trial stress C : ε^tr is the σ_n + C : Δε of the small-strain code with
   ε_e,n in the place of ε_n − ε_p,n. It gives Δε_p, Δp and ∂Δε_p/∂ε; ε_e = ε^tr − Δε_p and the
   Kirchhoff stress τ = C : ε_e (Hencky's hyperelastic law in the logarithmic space);
3. b_e = exp(2 ε_e): the exponential map of the plastic flow (for an isotropic law ε_e is coaxial
   with ε^tr and takes its eigenvectors), which keeps det b_e = det b_e^tr
   exp(−2 tr Δε_p) (plastic incompressibility exactly, for a deviatoric flow);
4. P = τ F⁻ᵀ, σ = τ / J.

For an isotropic law (von Mises with isotropic hardening of any shape, Drucker–Prager, Hencky
elasticity) τ is coaxial with b_e^tr and the update is Simo's. **Back-stresses** (kinematic
hardening) are spatial tensors in the logarithmic space, and need a transport from one
configuration to the next: here they turn with the rotation r of the polar decomposition
f = r u of the increment's deformation (α_n → r α_n rᵀ, a Green–Naghdi-type rule). This is a
model choice of its own (``formulation.md`` §1c: "for kinematic hardening it is a model of its
own"); it is objective, and exact for loading without rotation (the uniaxial closed forms).
The return map runs in the increment's rotated frame, ε̄ = rᵀ ε^tr r with the stored α_n. For an
isotropic law that frame changes nothing: its return map τ̂ is an isotropic function,
τ̂(rᵀ ε r) = rᵀ τ̂(ε) r, so r τ̂(ε̄) rᵀ = τ̂(ε^tr) exactly; the route takes r = I there (no polar
decomposition) and the back-stress laws alone (:class:`~dolfinx_nnqem.material.kinematic.KinematicAtPoints`)
run in the rotated frame.

**Consistent tangent.** Along a direction δF, with δf = δF F_n⁻¹,
δb = δf b_e,n fᵀ + f b_e,n δfᵀ, δε^tr = ½ d ln(b_e^tr)[δb] (:func:`.spectral.log_derivative`,
exact as eigenvalues coincide), Ω = rᵀδr (:func:`.spectral.rotation_derivative`),

    δε̄ = rᵀ δε^tr r − Ω ε̄ + ε̄ Ω,   δτ̄ = D : δε̄,   δτ = r (Ω τ̄ − τ̄ Ω + δτ̄) rᵀ,
    δP = δτ F⁻ᵀ − τ F⁻ᵀ δFᵀ F⁻ᵀ,

with D = C (I − ∂Δε_p/∂ε) the small-strain algorithmic tangent in the logarithmic space. The
nine directions δF = e_k ⊗ e_l give ∂P/∂F (n, 3, 3, 3, 3). With r = I (an isotropic law) the
terms in Ω cancel: differentiating τ̂(e^{−tΩ} ε e^{tΩ}) = e^{−tΩ} τ̂(ε) e^{tΩ} at t = 0 gives
D : (ε̄ Ω − Ω ε̄) = τ̄ Ω − Ω τ̄, and δτ = D : δε^tr (the compiled tangent, :mod:`.kernels`, leaves
them out there; :func:`tangent_by_arrays` keeps them, and the tests compare the two).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dolfinx_nnqem.material.drucker_prager import DruckerPragerAtPoints
from dolfinx_nnqem.material.elastic import ElasticAtPoints
from dolfinx_nnqem.material.finite_strain.interface import (FiniteStrainResponse, FiniteStrainState,
                                                            checked_deformation_gradients)
from dolfinx_nnqem.material.finite_strain.spectral import (eigen, log_derivative, polar_decomposition,
                                                           rotation_derivative)
from dolfinx_nnqem.material.interface import PointwiseMaterial
from dolfinx_nnqem.material.isotropic import IsotropicAtPoints
from dolfinx_nnqem.material.kinematic import KinematicAtPoints, back_stresses
from dolfinx_nnqem.material.kinematics import (deviator_coordinates, deviator_tensors, symmetric_coordinates,
                                               symmetric_tensors)
from dolfinx_nnqem.material.von_mises import VonMisesAtPoints

__all__ = ["SUPPORTED_POINTWISE", "HenckyAtPoints", "LogarithmicReturn", "algorithmic_tangent", "flow_tangent",
           "logarithmic_return"]

SUPPORTED_POINTWISE = (VonMisesAtPoints, IsotropicAtPoints, KinematicAtPoints, DruckerPragerAtPoints, ElasticAtPoints)
"""The pointwise materials the route takes: each is a small-strain return map with C = 2μ on the
deviators and 3κ on the volume, and internal variables the route knows how to carry ("p"; the
back-stresses of :class:`~dolfinx_nnqem.material.kinematic.KinematicAtPoints`)."""
_DIRECTIONS = np.eye(9).reshape(9, 3, 3)
_COORDINATE_BASIS = np.ascontiguousarray(symmetric_coordinates(_DIRECTIONS).T)
"""B (6, 9): the coordinates of a tensor T (9 components, row-major) are B T (:func:`symmetric_coordinates`)."""


@dataclass(frozen=True)
class LogarithmicReturn:
    """The small-strain return map at logarithmic trial strains, n points (coordinates of
    :mod:`~dolfinx_nnqem.material.kinematics`: (n, 6), the volumetric one tr/√3 last)."""

    eps_e: np.ndarray  #: (n, 6) elastic logarithmic strain ε_e = ε^tr − Δε_p
    deps_p: np.ndarray  #: (n, 6) plastic strain increment Δε_p
    dp: np.ndarray  #: (n,) equivalent plastic strain increment Δp
    tau: np.ndarray  #: (n, 6) Kirchhoff stress τ = C : ε_e
    D: np.ndarray | None  #: (n, 6, 6) algorithmic tangent dτ/dε^tr = C (I − ∂Δε_p/∂ε); None if not asked for


def _moduli(pointwise: PointwiseMaterial) -> np.ndarray:
    """C in the coordinates (n, 6): 2μ on the five deviatoric ones, 3κ on the volumetric one."""
    mu, kappa = pointwise.mu, pointwise.lmbda + 2.0 * pointwise.mu / 3.0
    return np.concatenate([np.repeat((2.0 * mu)[:, None], 5, axis=1), (3.0 * kappa)[:, None]], axis=1)


def _trial_stress(pointwise: PointwiseMaterial, C6: np.ndarray, e: np.ndarray) -> np.ndarray:
    """What the return map takes at the trial strain's coordinates e (n, 6): the trial deviator
    t = 2μ dev ε^tr (n, 5) for a deviatoric flow, else the full trial stress C : ε^tr (n, 6)."""
    return 2.0 * pointwise.mu[:, None] * e[:, :5] if pointwise.deviatoric_flow else C6 * e


def logarithmic_return(pointwise: PointwiseMaterial, eps_tr: np.ndarray, internal: dict[str, np.ndarray],
                       tangent: bool = True) -> LogarithmicReturn:
    """The material's own return map (:class:`~dolfinx_nnqem.material.interface.PointwiseMaterial`)
    at the trial logarithmic strains ``eps_tr`` (n, 3, 3) from the converged ``internal`` variables,
    with its algorithmic tangent D if ``tangent`` (:func:`algorithmic_tangent`).

    A deviatoric flow takes the trial deviator t = 2μ dev ε^tr (coordinates (n, 5)); a
    pressure-dependent one (``deviatoric_flow`` False) the full trial stress C : ε^tr (n, 6).
    """
    C6 = _moduli(pointwise)
    e = symmetric_coordinates(eps_tr)
    t = _trial_stress(pointwise, C6, e)
    if pointwise.deviatoric_flow:
        deps_p = np.zeros((e.shape[0], 6))
        deps_p[:, :5], dp = pointwise.plastic_strain(t, internal)
    else:
        deps_p, dp = pointwise.plastic_strain(t, internal)
    eps_e = e - deps_p
    D = algorithmic_tangent(pointwise, eps_tr, internal) if tangent else None
    return LogarithmicReturn(eps_e, deps_p, dp, C6 * eps_e, D)


def algorithmic_tangent(pointwise: PointwiseMaterial, eps_tr: np.ndarray, internal: dict[str, np.ndarray]
                        ) -> np.ndarray:
    """D = dτ/dε^tr = C (I − ∂Δε_p/∂ε) (n, 6, 6) of :func:`logarithmic_return` at the same arguments
    (from :func:`flow_tangent`)."""
    C6, R = flow_tangent(pointwise, eps_tr, internal)
    return C6[:, :, None] * (np.eye(6) - R)


def flow_tangent(pointwise: PointwiseMaterial, eps_tr: np.ndarray, internal: dict[str, np.ndarray]
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(C (n, 6), ∂Δε_p/∂ε (n, 6, 6)) of :func:`logarithmic_return` at the same arguments, the factors of
    its algorithmic tangent D = C (I − ∂Δε_p/∂ε): the material's ∂Δε_p/∂e (n, 5, 5) for a deviatoric
    flow, ∂Δε_p/∂ε (n, 6, 6) otherwise. Apart from the return, for an update whose tangent is asked
    for later (or never); the compiled tangent forms D point by point (:mod:`.kernels`)."""
    C6 = _moduli(pointwise)
    e = symmetric_coordinates(eps_tr)
    t = _trial_stress(pointwise, C6, e)
    if pointwise.deviatoric_flow:
        R = np.zeros((e.shape[0], 6, 6))
        R[:, :5, :5] = pointwise.plastic_strain_tangent(t, internal)
    else:
        R = pointwise.plastic_strain_tangent(t, internal)
    return C6, R


@dataclass(frozen=True)
class _Trial:
    """The elastic trial state of an increment at n points (the module docstring, step 1)."""

    F_n_inv: np.ndarray  #: F_n⁻¹
    b_n: np.ndarray  #: b_e,n
    f: np.ndarray  #: F F_n⁻¹
    left: np.ndarray  #: f b_e,n
    lam: np.ndarray  #: eigenvalues of b_e^tr (n, 3)
    Q: np.ndarray  #: its eigenvectors (columns)
    r: np.ndarray  #: polar rotation of f (I where not ``rotating``)
    u: np.ndarray  #: its stretch (I where not ``rotating``)
    eps_bar: np.ndarray  #: rᵀ ε^tr r
    rotating: bool  #: the return map runs in the rotated frame (back-stresses); else r = I


def _trial(F: np.ndarray, state: FiniteStrainState, rotating: bool = True) -> _Trial:
    """b_e^tr = f b_e,n fᵀ, its eigen-decomposition and ε̄ = rᵀ (½ ln b_e^tr) r; r = I unless
    ``rotating`` (an isotropic law: the module docstring). The per-point algebra is compiled
    (:func:`.point_kernels.elastic_trial`)."""
    from dolfinx_nnqem.material.finite_strain.point_kernels import elastic_trial  # (imports numba: when needed)

    n = F.shape[0]
    F_n_inv, f, left, Q, eps_tr = (np.empty((n, 3, 3)) for _ in range(5))
    lam = np.empty((n, 3))
    elastic_trial(np.ascontiguousarray(F), np.ascontiguousarray(state.F), np.ascontiguousarray(state.b_e),
                  F_n_inv, f, left, lam, Q, eps_tr)
    if np.any(~(lam > 0.0)):
        raise ValueError(f"the elastic trial b_e has an eigenvalue <= 0 at {np.count_nonzero(~(lam > 0).all(1))} "
                         "Gauss point(s): the state's b_e is not positive definite")
    if not rotating:
        eye = np.broadcast_to(np.eye(3), F.shape).copy()
        return _Trial(F_n_inv, state.b_e, f, left, lam, Q, eye, eye, eps_tr, False)
    r, u = polar_decomposition(f)
    return _Trial(F_n_inv, state.b_e, f, left, lam, Q, r, u, np.swapaxes(r, 1, 2) @ eps_tr @ r, True)


def _rotated(r: np.ndarray, T: np.ndarray) -> np.ndarray:
    """r T rᵀ for (n, 3, 3) arrays."""
    return r @ T @ np.swapaxes(r, 1, 2)


def _spatial(trial: _Trial, coordinates: np.ndarray) -> np.ndarray:
    """The spatial tensor r T̄ rᵀ (n, 3, 3) of a tensor T̄ of the rotated frame given by its coordinates
    (n, 6) (T̄ itself where r = I)."""
    return _rotated(trial.r, symmetric_tensors(coordinates)) if trial.rotating else symmetric_tensors(coordinates)


def _tangent(trial: _Trial, flow: tuple[np.ndarray, np.ndarray], tau_bar: np.ndarray, F_inv: np.ndarray,
             P: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """∂P_ij/∂F_kl (n, 3, 3, 3, 3) along the nine directions e_k⊗e_l (the module docstring), by the
    compiled loop over the points of :mod:`.kernels`, given the algorithmic tangent's factors
    (:func:`flow_tangent`), τ̄'s coordinates, F⁻¹ and P = τ F⁻ᵀ; into ``out`` (C-contiguous) if given."""
    from dolfinx_nnqem.material.finite_strain.kernels import hencky_tangent  # (imports numba: here, when needed)

    out = np.empty((F_inv.shape[0], 3, 3, 3, 3)) if out is None else out
    hencky_tangent(trial.F_n_inv, trial.left, trial.lam, trial.Q, trial.r, trial.u, trial.eps_bar, *flow,
                   _COORDINATE_BASIS, symmetric_tensors(tau_bar), F_inv, P, trial.rotating, out)
    return out


def tangent_by_arrays(F: np.ndarray, trial: _Trial, ret: LogarithmicReturn, tau: np.ndarray) -> np.ndarray:
    """∂P_ij/∂F_kl (n, 3, 3, 3, 3) as :func:`_tangent` (with r of ``trial``), written on numpy arrays of the nine directions
    (n, 9, 3, 3) (the module docstring's formulas as they read): the reference the compiled
    kernel is tested against."""
    assert ret.D is not None, "the reference tangent needs the return's D (logarithmic_return with tangent=True)"
    n = F.shape[0]
    dF = np.broadcast_to(_DIRECTIONS, (n, 9, 3, 3))
    df = dF @ trial.F_n_inv[:, None]
    left = trial.left[:, None]
    db = df @ np.swapaxes(left, -1, -2) + left @ np.swapaxes(df, -1, -2)
    deps = 0.5 * log_derivative(trial.lam, trial.Q, db)
    r, rT = trial.r[:, None], np.swapaxes(trial.r, 1, 2)[:, None]
    Omega = rotation_derivative(trial.r, trial.u, df)
    eps_bar = trial.eps_bar[:, None]
    deps_bar = rT @ deps @ r - Omega @ eps_bar + eps_bar @ Omega
    dtau_bar = np.einsum("nab,nmb->nma", ret.D, symmetric_coordinates(deps_bar).reshape(n, 9, 6))
    tau_bar = symmetric_tensors(ret.tau)[:, None]
    dtau = r @ (Omega @ tau_bar - tau_bar @ Omega + symmetric_tensors(dtau_bar.reshape(-1, 6)).reshape(n, 9, 3, 3)) @ rT
    F_inv_T = np.swapaxes(np.linalg.inv(F), 1, 2)[:, None]
    dP = dtau @ F_inv_T - tau[:, None] @ F_inv_T @ np.swapaxes(dF, -1, -2) @ F_inv_T
    return dP.reshape(n, 3, 3, 3, 3).transpose(0, 3, 4, 1, 2)


def _exponential_map(F: np.ndarray, J: np.ndarray, tau: np.ndarray, Q_e: np.ndarray, lam_e: np.ndarray,
                     b_e: np.ndarray, F_inv: np.ndarray, P: np.ndarray, sigma: np.ndarray) -> None:
    """b_e = exp(2 ε_e) from its eigen-pairs, F⁻¹, P = τ F⁻ᵀ and σ = τ / J into the last four arrays
    (compiled: :func:`.point_kernels.exponential_map`)."""
    from dolfinx_nnqem.material.finite_strain.point_kernels import exponential_map  # (imports numba: when needed)

    exponential_map(F, J, np.ascontiguousarray(tau), np.ascontiguousarray(Q_e), np.ascontiguousarray(lam_e),
                    b_e, F_inv, P, sigma)


def _elastic_eigen(trial: _Trial, eps_e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(λ, Q) of the elastic logarithmic strain ε_e (n, 3, 3), for b_e = exp(2 ε_e). Where r = I (an
    isotropic law) ε_e is an isotropic function of ε^tr, hence coaxial with it: its eigenvalues are
    q_aᵀ ε_e q_a in the trial's eigenvectors Q (no second decomposition, compiled:
    :func:`.point_kernels.coaxial_eigenvalues`); else numpy's."""
    from dolfinx_nnqem.material.finite_strain.point_kernels import coaxial_eigenvalues  # (imports numba: when needed)

    if trial.rotating:
        return eigen(eps_e)
    lam = np.empty((eps_e.shape[0], 3))
    coaxial_eigenvalues(np.ascontiguousarray(eps_e), np.ascontiguousarray(trial.Q), lam)
    return lam, trial.Q


class HenckyAtPoints:
    """A small-strain material at n Gauss points, at finite strain by the logarithmic strain and the
    exponential map (the module docstring): a :class:`~.interface.FiniteStrainMaterial`.

    Parameters
    ----------
    pointwise
        The material's :class:`~dolfinx_nnqem.material.interface.PointwiseMaterial` at the points
        (one of :data:`SUPPORTED_POINTWISE`; :func:`~.finite_strain_material` makes it from a material).

    Raises
    ------
    TypeError
        A pointwise material of another kind, named: the route does not know how to carry its
        internal variables from one configuration to the next.
    """

    def __init__(self, pointwise: PointwiseMaterial):
        if not isinstance(pointwise, SUPPORTED_POINTWISE):
            raise TypeError(
                f"{type(pointwise).__name__} has no finite-strain form: the logarithmic-strain route takes the "
                f"pointwise return maps {[k.__name__ for k in SUPPORTED_POINTWISE]} (one material kind at a time), "
                "whose internal variables it knows how to carry between configurations")
        self.pointwise = pointwise
        self.back_stress_names: tuple[str, ...] = pointwise.names if isinstance(pointwise, KinematicAtPoints) else ()

    @property
    def size(self) -> int:
        """The number of Gauss points n."""
        return int(self.pointwise.mu.size)

    def initial_state(self) -> FiniteStrainState:
        """F = b_e = I, p = 0 and every back-stress 0."""
        n = self.size
        eye = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        internal = {"p": np.zeros(n), **{name: np.zeros((n, 3, 3)) for name in self.back_stress_names}}
        return FiniteStrainState(eye, eye.copy(), internal)

    def _updated_back_stresses(self, internal: dict[str, np.ndarray], ret: LogarithmicReturn, r: np.ndarray
                               ) -> dict[str, np.ndarray]:
        """The back-stresses at the end of the increment, spatial: r ᾱ_k rᵀ (:func:`back_stresses`
        in the rotated frame, from the stored α_k,n)."""
        if not self.back_stress_names:
            return {}
        pw = self.pointwise
        assert isinstance(pw, KinematicAtPoints)  # (back_stress_names is set for it alone)
        alpha_n = np.stack([deviator_coordinates(internal[name]) for name in self.back_stress_names], axis=1)
        alpha = back_stresses(alpha_n, ret.deps_p[:, :5], ret.dp, pw.C, pw.gamma)
        return {name: _rotated(r, deviator_tensors(alpha[:, k])) for k, name in enumerate(self.back_stress_names)}

    def update(self, F: np.ndarray, state: FiniteStrainState, tangent: bool = True,
               J: np.ndarray | None = None) -> FiniteStrainResponse:
        """The return map at the deformation gradients ``F`` (n, 3, 3) from the converged ``state``
        (the module docstring), with the consistent tangent ∂P/∂F if ``tangent``; ``J`` = det F if
        the caller has it (:meth:`~.interface.FiniteStrainMaterial.update`)."""
        F, J = checked_deformation_gradients(F, self.size, J)
        F = np.ascontiguousarray(F)  # (the compiled steps take C-ordered arrays)
        trial = _trial(F, state, rotating=bool(self.back_stress_names))
        internal = {name: np.asarray(v) for name, v in state.internal.items()}
        ret = logarithmic_return(self.pointwise, trial.eps_bar, internal, tangent=False)
        tau, eps_e = _spatial(trial, ret.tau), _spatial(trial, ret.eps_e)
        lam_e, Q_e = _elastic_eigen(trial, eps_e)
        new_internal = {**internal, "p": internal["p"] + ret.dp,
                        **self._updated_back_stresses(internal, ret, trial.r)}
        b_e, F_inv, P, sigma = (np.empty_like(F) for _ in range(4))
        _exponential_map(F, J, tau, Q_e, lam_e, b_e, F_inv, P, sigma)
        new_state = FiniteStrainState(F.copy(), b_e, new_internal)

        def later(out: np.ndarray | None = None) -> np.ndarray:  # D's factors, then ∂P/∂F, from this update's arrays
            return _tangent(trial, flow_tangent(self.pointwise, trial.eps_bar, internal), ret.tau, F_inv, P, out)
        if tangent:
            return FiniteStrainResponse(P=P, tau=tau, sigma=sigma, dp=ret.dp, state=new_state, tangent=later())
        return FiniteStrainResponse(P=P, tau=tau, sigma=sigma, dp=ret.dp, state=new_state, tangent_later=later)

