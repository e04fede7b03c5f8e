"""A material part whose return map runs on numpy arrays at the Gauss points.

UFL has no loops, so a return map that needs an iteration per point (a hardening law of any
shape, later kinematic hardening or a cone's apex) is evaluated on arrays: the strain increment
Δε = ε(u) − ε(u_n) is interpolated at the Gauss points with a compiled ``dolfinx.fem.Expression``,
the material's numpy return map gives σ, Δp, Δε_p and the consistent tangent C_alg there, and
they are stored in quadrature functions which the forms read:

    F_int[v] = ∫ σ_q : ε(v) dx,     K_t[du, v] = ∫ (C_q : ε(du)) : ε(v) dx.

:meth:`QuadraturePart.evaluate` does this for a displacement and is called by the problem before
it assembles at a new iterate (``MaterialState.evaluate``); it remembers the u and the state it
evaluated, so the internal force and the tangent at one iterate cost one evaluation. C_q is a
full fourth-order tensor per point (81 values): it holds unsymmetric tangents too (non-associated
flow). ``docs/materials.md`` compares this route with ``dolfinx-external-operator`` and with an
unrolled Newton iteration in UFL.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import basix.ufl
import dolfinx.fem as fem
import numpy as np
import ufl

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.material.interface import Material, ReturnMapValues
from dolfinx_nnqem.material.kinematics import strain

if TYPE_CHECKING:
    from dolfinx_nnqem.material.state import GaussPointState

__all__ = ["QuadraturePart"]


class QuadraturePart:
    """The state of the bodies ``members`` of one material kind whose return map runs on arrays.

    A material module subclasses it with :meth:`pointwise_return_map` (σ, Δp, Δε_p and C_alg at
    the part's local points from σ_n, Δε and the converged internal variables) and ``at_points``.

    Parameters
    ----------
    space
        The mesh-wide state (:class:`~dolfinx_nnqem.material.state.GaussPointState`).
    members
        ``{cell tag: material}`` of these bodies (tag None: every cell).
    """

    internal_variables: Mapping[str, tuple[int, ...]] = {}
    symmetric_tangent = True

    def __init__(self, space: GaussPointState, members: Mapping[int | None, Material]):
        self.space = space
        self.points = np.unique(np.concatenate([space.points_of(space.cells_of(tag)) for tag in members]))
        """The part's local Gauss points (owned and ghost), indices into the quadrature spaces."""
        mesh = space.mesh
        W_C = fem.functionspace(mesh, basix.ufl.quadrature_element(
            mesh.topology.cell_name(), value_shape=(3, 3, 3, 3), degree=space.quadrature_degree))
        self.sigma_q = fem.Function(space.W_tensor, name="sigma_q")  # σ at the last u evaluated
        self.dp_q = fem.Function(space.W_scalar, name="dp_q")
        self.deps_p_q = fem.Function(space.W_tensor, name="deps_p_q")
        self.C_q = fem.Function(W_C, name="C_alg")  # the consistent tangent there
        self._increment: tuple[fem.Function, fem.Expression, fem.Function] | None = None
        self._evaluated: tuple[fem.Function, np.ndarray, int] | None = None

    def values_at_local_points(self, expr: ufl.core.expr.Expr) -> np.ndarray:
        """A scalar UFL expression (a material field) at every local Gauss point."""
        f = fem.Function(self.space.W_scalar)
        compat.interpolate_expression(f, jit.expression(expr, self.space._points))
        return f.x.array.copy()

    def pointwise_return_map(self, sigma_n: np.ndarray, deps: np.ndarray, internal: Mapping[str, np.ndarray]
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(σ (m, 3, 3), Δp (m,), Δε_p (m, 3, 3), C_alg (m, 3, 3, 3, 3)) at the part's points."""
        raise NotImplementedError  # pragma: no cover - each material defines it

    def updated_internal(self, points: np.ndarray, deps_p: np.ndarray, dp: np.ndarray,
                         internal_n: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """{}: the base part has no internal variable besides p (a subclass that declares some
        computes them here)."""
        return {}

    # -- the forms --------------------------------------------------------------------------------------
    def stress(self, u: fem.Function) -> ufl.core.expr.Expr:
        """UFL: σ_q, the return map's stress at the last ``u`` evaluated (:meth:`evaluate`)."""
        return self.sigma_q

    def tangent(self, u: fem.Function, eps_du: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """UFL: C_q : ``eps_du``, the consistent tangent at the last ``u`` evaluated (:meth:`evaluate`)."""
        i, j, k, l = ufl.indices(4)
        return ufl.as_tensor(self.C_q[i, j, k, l] * eps_du[k, l], (i, j))

    def _strain_increment(self, u: fem.Function) -> np.ndarray:
        """Δε = ε(u) − ε(u_n) at the part's points (m, 3, 3) (the expression compiled once per u)."""
        if self._increment is None or self._increment[0] is not u:
            expression = jit.expression(strain(u) - strain(self.space.u_n), self.space._points)
            self._increment = (u, expression, fem.Function(self.space.W_tensor))
        _, expression, values = self._increment
        compat.interpolate_expression(values, expression)
        return values.x.array.reshape(-1, 3, 3)[self.points]

    def evaluate(self, u: fem.Function) -> None:
        """σ_q, Δp, Δε_p and C_q at ``u`` (nothing if they are at this u and converged state already)."""
        st = self.space
        if self._evaluated is not None:
            u_then, array, version = self._evaluated
            if u_then is u and version == st.version and np.array_equal(array, u.x.array):
                return
        pts = self.points
        sigma, dp, deps_p, C = self.pointwise_return_map(
            st.sigma_n.x.array.reshape(-1, 3, 3)[pts], self._strain_increment(u), st.local_internal(pts))
        self.sigma_q.x.array.reshape(-1, 9)[pts] = sigma.reshape(-1, 9)
        self.dp_q.x.array[pts] = dp
        self.deps_p_q.x.array.reshape(-1, 9)[pts] = deps_p.reshape(-1, 9)
        self.C_q.x.array.reshape(-1, 81)[pts] = C.reshape(-1, 81)
        self._evaluated = (u, u.x.array.copy(), st.version)

    # -- the values ----------------------------------------------------------------------------------------
    def return_map(self, u: fem.Function) -> ReturnMapValues:
        """σ, Δp and Δε_p of the return map at ``u`` on every local Gauss point (copies)."""
        self.evaluate(u)
        return ReturnMapValues(self.sigma_q.x.array.reshape(-1, 3, 3).copy(), self.dp_q.x.array.copy(),
                               self.deps_p_q.x.array.reshape(-1, 3, 3).copy())

    def trial_dp(self, u: fem.Function) -> np.ndarray:
        """Δp of the return map at ``u`` on every local Gauss point (a copy)."""
        self.evaluate(u)
        return self.dp_q.x.array.copy()
