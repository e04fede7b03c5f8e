"""What every Gauss-point state of a mesh holds, whatever its kinematics: the bodies' cell-wise
elastic moduli and density, the quadrature spaces and the measure whose points they are, and the
counts and values at those points.

:class:`GaussPointFields` is the base of the small-strain
:class:`~dolfinx_nnqem.material.state.GaussPointState` and of the finite-strain
:class:`~dolfinx_nnqem.material.finite_strain.gauss_state.FiniteStrainGaussState`: the two differ in
what they store at the points and in their forms, not in these.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import basix.ufl
import dolfinx.fem as fem
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.material.kinematics import strain
from dolfinx_nnqem.material.state_report import maxima_by_body as _maxima_by_body

__all__ = ["GaussPointFields"]


class GaussPointFields:
    """Cell-wise material fields and quadrature spaces of a mesh made of one or more bodies.

    Parameters
    ----------
    V
        Vector Lagrange space of the displacement.
    materials
        ``{cell_tag: material}`` (tag None: one material for every cell), each with the attributes
        E, nu and density.
    cell_tags
        Cell tags naming the bodies (None with one material).
    quadrature_degree
        Degree of the Gauss rule used by the forms and the state.
    """

    p_n: fem.Function  #: the converged equivalent plastic strain (a subclass creates it)
    dp_n: fem.Function  #: its last converged increment
    sigma_n: fem.Function  #: the converged stress
    _others: dict[str, fem.Function]  #: the internal variables besides p (a subclass creates them)

    def __init__(self, V: fem.FunctionSpace, materials: Mapping[int | None, object], cell_tags=None,
                 quadrature_degree: int = 2):
        mesh = V.mesh
        self.V, self.mesh, self.quadrature_degree, self.cell_tags = V, mesh, quadrature_degree, cell_tags
        self.materials: dict[int | None, Any] = dict(materials)
        # piecewise-constant fields (one value per cell): bodies of different materials share one form
        self.Q0 = fem.functionspace(mesh, ("DG", 0))
        self.E = fem.Function(self.Q0, name="E")
        self.nu = fem.Function(self.Q0, name="nu")
        self.density = fem.Function(self.Q0, name="density")
        self.fill_cellwise({"E": self.E, "nu": self.nu, "density": self.density})
        E, nu = self.E, self.nu
        self.mu = E / (2 * (1 + nu))
        self.lmbda = E * nu / ((1 + nu) * (1 - 2 * nu))
        self.kappa = self.lmbda + 2 * self.mu / 3
        cell = mesh.topology.cell_name()
        self._metadata = {"quadrature_degree": quadrature_degree, "quadrature_scheme": "default"}
        self.dx = ufl.Measure("dx", domain=mesh, metadata=self._metadata)
        self.W_tensor = fem.functionspace(
            mesh, basix.ufl.quadrature_element(cell, value_shape=(3, 3), degree=quadrature_degree))
        self.W_scalar = fem.functionspace(
            mesh, basix.ufl.quadrature_element(cell, value_shape=(), degree=quadrature_degree))
        self._points = compat.interpolation_points(self.W_scalar)
        self.version = 0
        """Counts the changes of the converged state (commits, restores): what caches a return map
        at u (``evaluate``) recomputes it when this moves."""
        self.parameters_version = 0
        """Counts the changes of the materials' parameters (``parameters_changed``): what holds the
        material at the points (``at_points``) takes it again when this moves."""

    # -- set-up ---------------------------------------------------------------------------------------
    def cells_of(self, tag: int | None) -> np.ndarray:
        """Local cells (owned and ghost) of the body tagged ``tag`` (None: every cell)."""
        tdim = self.mesh.topology.dim
        imap = self.mesh.topology.index_map(tdim)
        if tag is None:
            return np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
        return self.cell_tags.find(tag)

    def points_of(self, cells: np.ndarray) -> np.ndarray:
        """The local Gauss points (indices into the quadrature spaces) of ``cells``."""
        return np.sort(self.W_scalar.dofmap.list[cells].reshape(-1))

    def fill_cellwise(self, fields: Mapping[str, fem.Function], default: Mapping[str, float] | None = None,
                      tags: Iterable[int | None] | None = None) -> None:
        """Set cell-wise (DG 0) ``fields`` from the materials' attributes of the same names (of the
        bodies ``tags``, all by default; the other cells get ``default``)."""
        tags = list(self.materials) if tags is None else list(tags)
        for name, f in fields.items():
            if default is not None:
                f.x.array[:] = default[name]
        assigned = np.zeros(self.Q0.dofmap.index_map.size_local + self.Q0.dofmap.index_map.num_ghosts, dtype=bool)
        for tag in tags:
            material = self.materials[tag]
            dofs = self.Q0.dofmap.list[self.cells_of(tag), 0]
            assigned[dofs] = True
            for name, f in fields.items():
                f.x.array[dofs] = getattr(material, name)
        if default is None:
            n_owned = self.Q0.dofmap.index_map.size_local
            n_missing = self.mesh.comm.allreduce(int(np.count_nonzero(~assigned[:n_owned])), op=MPI.SUM)
            if n_missing:
                raise ValueError(f"materials: {n_missing} cells carry none of the tags {sorted(str(t) for t in self.materials)}; "
                                 "every cell needs a material")
        for f in fields.values():
            f.x.scatter_forward()

    def _space_of(self, shape: tuple[int, ...]) -> fem.FunctionSpace:
        if shape == ():
            return self.W_scalar
        if shape == (3, 3):
            return self.W_tensor
        cell = self.mesh.topology.cell_name()
        return fem.functionspace(self.mesh, basix.ufl.quadrature_element(cell, value_shape=shape,
                                                                          degree=self.quadrature_degree))

    # -- the elastic forms ------------------------------------------------------------------------------
    def elastic_stress(self, eps: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """σ = λ tr(ε) I + 2μ ε."""
        return self.lmbda * ufl.tr(eps) * ufl.Identity(3) + 2 * self.mu * eps

    def elastic_stiffness_form(self, du: ufl.core.expr.Expr, v: ufl.Argument) -> ufl.Form:
        """K_e[du, v] = ∫ (C : ε(du)) : ε(v) dx."""
        return ufl.inner(self.elastic_stress(strain(du)), strain(v)) * self.dx

    # -- counts and values at points ---------------------------------------------------------------------------
    def num_owned_points(self) -> int:
        """Number of Gauss points this rank owns."""
        return self.W_scalar.dofmap.index_map.size_local

    def count_plastic_points(self) -> int:
        """Number of Gauss points (over all ranks) that yielded in the last converged increment."""
        imap = self.W_scalar.dofmap.index_map
        n_local = imap.size_local * self.W_scalar.dofmap.index_map_bs
        local = int(np.count_nonzero(self.dp_n.x.array[:n_local] > 0.0))
        return self.mesh.comm.allreduce(local, op=MPI.SUM)

    def num_gauss_points(self) -> int:
        """Total number of Gauss points (over all ranks)."""
        imap = self.W_scalar.dofmap.index_map
        return imap.size_global * self.W_scalar.dofmap.index_map_bs

    def values_at_points(self, expr: ufl.core.expr.Expr) -> np.ndarray:
        """A scalar UFL expression (e.g. a material field) at this rank's owned Gauss points."""
        return self.owned_at_points(jit.expression(expr, self._points)).copy()

    def owned_at_points(self, compiled: fem.Expression, tensor: bool = False) -> np.ndarray:
        """A compiled expression at this rank's owned Gauss points: (n,) for a scalar, (n, 3, 3) for
        a ``tensor``; a view of a function of its own (kept alive by the view, dropped with it)."""
        f = fem.Function(self.W_tensor if tensor else self.W_scalar)
        compat.interpolate_expression(f, compiled)
        n = self.W_scalar.dofmap.index_map.size_local
        return f.x.array[:9 * n].reshape(n, 3, 3) if tensor else f.x.array[:n]

    # -- outputs ----------------------------------------------------------------------------------------------
    def internal_at_points(self) -> dict[str, np.ndarray]:
        """The converged internal variables at the owned Gauss points, by name (each subclass's own)."""
        raise NotImplementedError  # pragma: no cover - each subclass defines it

    def yield_function_values(self) -> np.ndarray:
        """f/σ_y at the converged state at every local Gauss point (each subclass's own)."""
        raise NotImplementedError  # pragma: no cover - each subclass defines it

    def back_stress_values(self) -> np.ndarray | None:
        """q(α) = √(3/2)|α| of the total back-stress α = Σ_k α_k at the converged state at every local
        Gauss point (0 where a material has none); None when no material has back-stresses."""
        names = [name for name in self._others if name.startswith("alpha_")]
        if not names:
            return None
        alpha = sum(self._others[name].x.array.reshape(-1, 3, 3) for name in names)
        return np.sqrt(1.5 * np.einsum("nij,nij->n", alpha, alpha))

    def maxima_by_body(self) -> dict[str, dict[str, float]]:
        """Per body, the largest p and f/σ_y of the converged state over all ranks (collective):
        :func:`~dolfinx_nnqem.material.state_report.maxima_by_body`."""
        return _maxima_by_body(self)
