"""What the Gauss-point state reports of itself: the yield function at every point and the largest
p, f/σ_y and back-stress per body (the fields and the summary a run writes).

Functions of a :class:`~dolfinx_nnqem.material.state.GaussPointState`, read through its public
members; the state's methods of the same names call them.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

import dolfinx.fem as fem
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.material.interface import PointwiseMaterial
from dolfinx_nnqem.material.kinematics import symmetric_coordinates

__all__ = ["ReportedState", "maxima_by_body", "yield_function_values"]


class ReportedState(Protocol):
    """What the reports read of a Gauss-point state (:class:`~dolfinx_nnqem.material.state.GaussPointState`)."""

    @property
    def mesh(self) -> Any:
        """The mesh."""
    @property
    def materials(self) -> Mapping[int | None, Any]:
        """The material of each body (cell tag; None: one material)."""
    @property
    def sigma_n(self) -> fem.Function:
        """σ at the converged state (quadrature space)."""
    @property
    def p_n(self) -> fem.Function:
        """The accumulated plastic strain p at the converged state."""
    @property
    def W_scalar(self) -> fem.FunctionSpace:
        """The scalar quadrature space."""

    def num_owned_points(self) -> int:
        """The number of this rank's owned Gauss points."""

    def internal_at_points(self) -> dict[str, np.ndarray]:
        """The internal variables at the owned points, by name."""

    def yield_function_values(self) -> np.ndarray:
        """f/σ_y at every local point (:func:`yield_function_values`)."""

    def back_stress_values(self) -> np.ndarray | None:
        """q(α) at every local point; None without back-stresses."""

    def cells_of(self, tag: int | None) -> np.ndarray:
        """The local cells of a body."""

    def points_of(self, cells: np.ndarray) -> np.ndarray:
        """The local Gauss points of ``cells``."""


def yield_function_values(state: ReportedState, material: PointwiseMaterial) -> np.ndarray:
    """f/σ_y at the converged state at every local Gauss point (owned and ghost; −1 where the
    material cannot yield): 0 on the yield surface, −1 without deviatoric stress for von Mises.

    Parameters
    ----------
    state
        The Gauss-point state.
    material
        Its material at the points (``state.at_points()``).
    """
    n = state.num_owned_points()
    sigma = state.sigma_n.x.array[:9 * n].reshape(n, 3, 3)
    internal = state.internal_at_points()
    f = material.yield_value(symmetric_coordinates(sigma), internal)
    size = material.yield_stress(internal)
    ratio = np.full(n, -1.0)
    ok = material.yields & np.isfinite(size) & (size > 0.0)
    ratio[ok] = f[ok] / size[ok]
    out = fem.Function(state.W_scalar)
    out.x.array[:n] = ratio
    out.x.scatter_forward()
    return out.x.array


def maxima_by_body(state: ReportedState) -> dict[str, dict[str, float]]:
    """Per body (cell tag; "all" for a single material), the largest p and f/σ_y of the converged
    state over all ranks (collective), and the largest q(α) where a material has back-stresses."""
    n = state.num_owned_points()
    fields = {"p": (state.p_n.x.array[:n], 0.0), "f_over_sigma_y": (state.yield_function_values()[:n], -1.0)}
    back_stress = state.back_stress_values()
    if back_stress is not None:
        fields["back_stress"] = (back_stress[:n], 0.0)
    out: dict[str, dict[str, float]] = {key: {} for key in fields}
    for tag in state.materials:
        points = state.points_of(state.cells_of(tag))
        points = points[points < n]
        name = "all" if tag is None else str(tag)
        for key, (values, least) in fields.items():
            out[key][name] = state.mesh.comm.allreduce(float(np.max(values[points], initial=least)), op=MPI.MAX)
    return out
