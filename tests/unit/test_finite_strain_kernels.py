"""The compiled consistent tangent of the logarithmic-strain route
(``dolfinx_nnqem.material.finite_strain.kernels``, issue 41: its cost) against the same formulas on
numpy arrays of the nine directions (``hencky.tangent_by_arrays``): equal to rounding at many
points at once (plastic, elastic, back-stresses, the cone and its apex, equal eigenvalues,
rotations): the update's tangent (the compiled one) against the reference. For an isotropic law
the update leaves out the increment's rotated frame (r = I, the terms in Ω of the tangent) and
takes ε_e's eigenvectors from ε^tr (coaxial): its τ, b_e and tangent against the rotated frame's
with b_e = exp(2 ε_e) decomposed on its own, to rounding.
"""

from __future__ import annotations

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
import numpy as np
import pytest

from dolfinx_nnqem.material import BackStress, DruckerPrager, Elastic, VoceHardening, VonMises
from dolfinx_nnqem.material.finite_strain import HenckyAtPoints, finite_strain_material
from dolfinx_nnqem.material.finite_strain.hencky import _rotated, _trial, logarithmic_return, tangent_by_arrays
from dolfinx_nnqem.material.finite_strain.spectral import eigen, tensor_function
from dolfinx_nnqem.material.kinematics import symmetric_tensors

E, NU, SY = 200e9, 0.3, 250e6
MATERIALS = {
    "von-mises-linear": VonMises(E, NU, SY, 1e9),
    "von-mises-voce": VonMises(E, NU, hardening=VoceHardening(SY, 200e6, 20.0, 5e8)),
    "kinematic-af-on-voce": VonMises(E, NU, hardening=VoceHardening(SY, 100e6, 10.0, 0.0),
                                     kinematic=[BackStress(2e10, 100.0), BackStress(5e9, 0.0)]),
    "drucker-prager-nonassociated": DruckerPrager(E, NU, 100e6, 30.0, 10.0, H=1e9),
    "elastic": Elastic(E, NU),
}
N_RANDOM = 60


def _deformations(rng: np.random.Generator, size: float) -> np.ndarray:
    """N_RANDOM random deformation gradients near rotations, then the special ones: equal and nearly
    equal stretches, a pure dilation (three equal eigenvalues), hydrostatic tension (the cone's apex)."""
    A = rng.standard_normal((N_RANDOM, 3, 3))
    W = 0.5 * (A - np.swapaxes(A, 1, 2))
    rotations = np.linalg.qr(np.eye(3) + W)[0]
    rotations *= np.sign(np.linalg.det(rotations))[:, None, None]
    random = rotations @ (np.eye(3) + size * rng.standard_normal((N_RANDOM, 3, 3)))
    special = np.array([np.diag(d) for d in ((1.3, 0.88, 0.88), (1.3, 0.88, 0.88 * (1 + 1e-9)),
                                             (1.02, 1.02, 1.02), (1.01, 1.01, 1.0101))])
    return np.concatenate([random, special])


@pytest.mark.parametrize("name", list(MATERIALS))
def test_compiled_tangent_equals_the_array_form(name: str) -> None:
    rng = np.random.default_rng(41)
    F_start = _deformations(rng, 0.02)
    material = finite_strain_material(MATERIALS[name], F_start.shape[0])
    assert isinstance(material, HenckyAtPoints)
    state = material.update(F_start, material.initial_state(), tangent=False).state  # plastic pre-strain
    F = F_start @ (np.eye(3) + 0.01 * rng.standard_normal(F_start.shape))
    out = material.update(F, state)
    assert out.tangent is not None
    trial = _trial(F, state, rotating=True)  # the reference runs in the rotated frame also for an isotropic law
    ret = logarithmic_return(material.pointwise, trial.eps_bar, {k: np.asarray(v) for k, v in state.internal.items()})
    tau = _rotated(trial.r, symmetric_tensors(ret.tau))
    assert np.abs(out.tau - tau).max() <= 1e-12 * np.abs(tau).max()
    lam_e, Q_e = eigen(_rotated(trial.r, symmetric_tensors(ret.eps_e)))  # b_e = exp(2 ε_e) by a decomposition of its own
    b_e = tensor_function(Q_e, np.exp(2.0 * lam_e))
    assert np.abs(out.state.b_e - b_e).max() <= 1e-12 * np.abs(b_e).max()
    reference = tangent_by_arrays(F, trial, ret, tau)
    scale = np.abs(reference).reshape(-1, 81).max(axis=1)
    error = np.abs(out.tangent - reference).reshape(-1, 81).max(axis=1) / scale
    assert error.max() <= 1e-12, (error.max(), int(error.argmax()))
    if name != "elastic":
        assert np.count_nonzero(out.dp > 0.0) >= N_RANDOM // 2  # the comparison covers plastic points
