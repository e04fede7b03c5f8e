"""The Gauss-point state of a mesh whose bodies may have different materials, built from the materials.

:func:`material_state` is the factory the problem calls with ``{cell_tag: material}``: the
bodies are grouped by their material's kind (``Material.part_kind``) and each group gets one
:class:`~dolfinx_nnqem.material.interface.MaterialPart` (``Material.make_part``) over its cells.
:class:`GaussPointState` holds what every material has — the cell-wise elastic moduli and
density, the converged stress σ_n, displacement u_n and equivalent plastic strain p_n (with
its last increment Δp_n), in quadrature spaces (``basix.ufl.quadrature_element``) whose points
are the points of the integration measure ``dx`` — and composes the parts' stresses and
tangents into the forms: one part over the whole mesh integrates over ``dx`` itself, several
integrate each over its own cells.
"""

from __future__ import annotations

import functools
import operator
from collections.abc import Mapping

import basix.ufl
import dolfinx.fem as fem
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.material.gauss_fields import GaussPointFields
from dolfinx_nnqem.material.state_report import yield_function_values as _yield_function_values
from dolfinx_nnqem.material.composite import CompositeAtPoints
from dolfinx_nnqem.material.interface import (GaussPointValues, Material, MaterialPart, PointwiseMaterial,
                                              ReturnMapValues)
from dolfinx_nnqem.material.kinematics import strain, symmetric_coordinates

__all__ = ["GaussPointState", "material_state", "materials_by_tag"]


def material_state(V: fem.FunctionSpace, materials: Material | dict[int, Material],
                   cell_tags: dolfinx.mesh.MeshTags | None = None, quadrature_degree: int = 2) -> GaussPointState:
    """The Gauss-point state of the mesh of ``V`` for one material or ``{cell_tag: material}``."""
    return GaussPointState(V, materials, cell_tags, quadrature_degree)


class GaussPointState(GaussPointFields):
    """Material fields and Gauss-point state of a mesh made of one or more bodies.

    Parameters
    ----------
    V
        Vector Lagrange space of the displacement.
    materials
        One material (:class:`~dolfinx_nnqem.material.interface.Material`) for the whole mesh, or
        ``{cell_tag: material}``; the bodies may have materials of different kinds.
    cell_tags
        Cell tags naming the bodies; required when ``materials`` is a dict.
    quadrature_degree
        Degree of the Gauss rule used by the forms and the state (2 gives 2×2×2 points on
        hexahedra and 4 points on tetrahedra).
    """

    def __init__(self, V: fem.FunctionSpace, materials, cell_tags=None, quadrature_degree: int = 2):
        super().__init__(V, materials_by_tag(materials, cell_tags, V.mesh), cell_tags, quadrature_degree)
        self.materials: dict[int | None, Material]  # (checked: each a Material)
        # the parts (their cell-wise parameters are created here, before the state's functions,
        # so that UFL orders a closed-form return map's coefficients as it always has)
        groups: dict[str, dict[int | None, Material]] = {}
        for tag, material in self.materials.items():
            groups.setdefault(material.part_kind, {})[tag] = material
        self.kinds = list(groups)
        self.parts: list[MaterialPart] = [next(iter(m.values())).make_part(self, m) for m in groups.values()]
        self.sigma_n = fem.Function(self.W_tensor, name="sigma")  # converged stress
        self.p_n = fem.Function(self.W_scalar, name="p")  # converged equivalent plastic strain
        self.dp_n = fem.Function(self.W_scalar, name="dp")  # Δp of the last converged increment
        self.u_n = fem.Function(V, name="u_converged")  # converged displacement
        self._others = {name: fem.Function(self._space_of(shape), name=name)
                        for part in self.parts for name, shape in part.internal_variables.items()}
        self._part_of_point = self._point_owners(groups)
        self._dx_parts = self._part_measure(self._metadata) if len(self.parts) > 1 else None
        self._commit_u: fem.Function | None = None
        self._material_at_points: PointwiseMaterial | None = None

    # -- set-up ---------------------------------------------------------------------------------------
    def parameters_changed(self) -> None:
        """Fill E, ν and the density again from :attr:`materials` after their parameters changed (a
        parameter study, :mod:`dolfinx_nnqem.problem.parameter_study`), and the parts' own cell-wise
        fields (a part with ``refill_parameters``). The forms read these fields: nothing is compiled."""
        self.fill_cellwise({"E": self.E, "nu": self.nu, "density": self.density})
        for kind, part in zip(self.kinds, self.parts):
            refill = getattr(part, "refill_parameters", None)  # the parts whose parameters are cell-wise fields
            if refill is not None:
                refill({tag: m for tag, m in self.materials.items() if m.part_kind == kind})
        self._material_at_points = None  # the material at the points, from the old fields
        self.parameters_version += 1

    def reset(self) -> None:
        """Back to the initial state: σ_n, p_n, Δp_n, u_n and every internal variable zero, as built."""
        for f in (self.sigma_n, self.p_n, self.dp_n, self.u_n, *self._others.values()):
            f.x.array[:] = 0.0
        self.version += 1

    def _point_owners(self, groups) -> np.ndarray:
        """The part of every local Gauss point."""
        imap = self.W_scalar.dofmap.index_map
        owner = np.full(imap.size_local + imap.num_ghosts, -1, dtype=np.int64)
        for k, members in enumerate(groups.values()):
            for tag in members:
                owner[self.points_of(self.cells_of(tag))] = k
        return owner

    def _part_measure(self, metadata) -> ufl.Measure:
        """dx with the owned cells tagged by their part's index."""
        tdim = self.mesh.topology.dim
        cells = np.arange(self.mesh.topology.index_map(tdim).size_local, dtype=np.int32)
        first_point = self.W_scalar.dofmap.list[cells, 0]
        tags = dolfinx.mesh.meshtags(self.mesh, tdim, cells, self._part_of_point[first_point].astype(np.int32))
        return ufl.Measure("dx", domain=self.mesh, subdomain_data=tags, metadata=metadata)

    # -- the forms ----------------------------------------------------------------------------------------
    def _integral(self, integrand) -> ufl.Form:
        """∫ integrand(part) over each part's cells."""
        if self._dx_parts is None:
            return integrand(self.parts[0]) * self.dx
        dx = self._dx_parts
        return functools.reduce(operator.add, (integrand(part) * dx(k) for k, part in enumerate(self.parts)))

    def internal_force_form(self, u: fem.Function, v: ufl.Argument) -> ufl.Form:
        """F_int(u)[v] = ∫ σ(u) : ε(v) dx."""
        return self._integral(lambda part: ufl.inner(part.stress(u), strain(v)))

    def tangent_form(self, u: fem.Function, du: ufl.core.expr.Expr, v: ufl.Argument) -> ufl.Form:
        """K_t(u)[du, v] = ∫ (C_alg : ε(du)) : ε(v) dx."""
        return self._integral(lambda part: ufl.inner(part.tangent(u, strain(du)), strain(v)))

    def evaluate(self, u: fem.Function, tangent: bool = True) -> None:
        """Bring the quadrature data of the forms to ``u`` (the parts' return maps evaluated on arrays;
        their tangents with them, whatever ``tangent`` says: one evaluation gives both)."""
        for part in self.parts:
            part.evaluate(u)

    # -- the return map's values ----------------------------------------------------------------------------
    def _merged(self, values: list[np.ndarray]) -> np.ndarray:
        """Per-part arrays over every local point, merged by the points' parts."""
        if len(values) == 1:
            return values[0]
        out = np.array(values[0], copy=True)
        for k, part_values in enumerate(values[1:], start=1):
            mask = self._part_of_point == k
            out[mask] = part_values[mask]
        return out

    def local_return_map(self, u: fem.Function) -> ReturnMapValues:
        """The return map at ``u`` at every local Gauss point (owned and ghost)."""
        maps = [part.return_map(u) for part in self.parts]
        if len(maps) == 1:
            return maps[0]
        return ReturnMapValues(*(self._merged([getattr(m, name) for m in maps]) for name in ("sigma", "dp", "deps_p")))

    def return_map_values(self, u: fem.Function) -> GaussPointValues:
        """The return map's values at ``u`` at this rank's owned Gauss points."""
        n = self.num_owned_points()
        rm = self.local_return_map(u)
        return GaussPointValues(u.x.array.copy(), rm.sigma[:n], rm.dp[:n], rm.deps_p[:n], "backward-euler")

    # -- commit ---------------------------------------------------------------------------------------------
    def commit(self, u: fem.Function) -> None:
        """Accept ``u`` as converged: σ_n, p_n, Δp_n and u_n at every Gauss point from the return map."""
        if self._commit_u is None:
            self._commit_u = u
        elif u is not self._commit_u:
            raise ValueError("GaussPointState.commit must always be given the same displacement Function")
        rm = self.local_return_map(u)
        if self._others:  # from the converged values, before p_n moves
            every = np.arange(self._part_of_point.size)
            self._store_internal(every, self._internal_after(every, rm.deps_p, rm.dp))
        self.sigma_n.x.array[:] = np.asarray(rm.sigma).reshape(-1)
        self.dp_n.x.array[:] = rm.dp
        self.p_n.x.array[:] += self.dp_n.x.array
        self.u_n.x.array[:] = u.x.array
        self._scatter_state()

    def commit_values(self, u: fem.Function, values: GaussPointValues) -> None:
        """Accept ``u`` as converged with Gauss-point values computed by a solver (NNEQM2's own
        integration): σ_n ← ``values.sigma``, Δp_n ← ``values.dp``, p_n ← p_n + Δp_n, u_n ← ``u``, at
        this rank's OWNED Gauss points, in the order of :attr:`W_tensor`'s owned dofs."""
        n = self.num_owned_points()
        sigma = np.asarray(values.sigma, dtype=float).reshape(-1)
        dp = np.asarray(values.dp, dtype=float).reshape(-1)
        if sigma.size != 9 * n or dp.size != n:
            raise ValueError(f"commit_values: expected {n} owned Gauss points, got sigma of size "
                             f"{sigma.size} (9 per point) and dp of size {dp.size}")
        if self._others:  # the values' own, or from their plastic strains (before p_n moves)
            self._store_internal(np.arange(n), self.internal_at_points(values))
        self.sigma_n.x.array[:9 * n] = sigma
        self.dp_n.x.array[:n] = dp
        self.p_n.x.array[:n] += dp
        self.u_n.x.array[:] = u.x.array
        self._scatter_state()

    def _scatter_state(self) -> None:
        for f in (self.sigma_n, self.p_n, self.dp_n, self.u_n, *self._others.values()):
            f.x.scatter_forward()
        self.version += 1

    @property
    def symmetric_tangent(self) -> bool:
        """Every part's consistent tangent is symmetric (False: the solvers must not assume it)."""
        return all(part.symmetric_tangent for part in self.parts)

    @property
    def internal_variables(self) -> dict[str, fem.Function]:
        """Every converged internal variable by name, "p" first."""
        return {"p": self.p_n, **self._others}

    def internal_at_points(self, values: GaussPointValues | None = None) -> dict[str, np.ndarray]:
        """The internal variables at the owned Gauss points: converged, or after ``values`` (their
        own ``internal``, or the materials' update from their Δε_p and Δp)."""
        n = self.num_owned_points()
        owned = np.arange(n)
        if values is None:
            return self.local_internal(owned)
        out = {"p": self.p_n.x.array[:n] + np.asarray(values.dp).reshape(n)}
        if values.internal is not None:
            missing = sorted(set(self._others) - set(values.internal))
            if missing:
                raise ValueError(f"the Gauss-point values lack the internal variables {missing}")
            out.update({name: np.asarray(values.internal[name]) for name in self._others})
        elif self._others:
            if values.deps_p is None:
                raise ValueError(f"the Gauss-point values give neither the internal variables {sorted(self._others)} "
                                 "nor the plastic strain increments they follow from (deps_p)")
            out.update(self._internal_after(owned, np.asarray(values.deps_p).reshape(n, 3, 3),
                                            np.asarray(values.dp).reshape(n)))
        return out

    def local_internal(self, points: np.ndarray) -> dict[str, np.ndarray]:
        """The converged internal variables at the local Gauss points ``points``, by name ("p" first)."""
        out = {"p": self.p_n.x.array[points].copy()}
        for name, f in self._others.items():
            out[name] = f.x.array.reshape((-1, *f.ufl_shape))[points].copy()
        return out

    def _internal_after(self, points: np.ndarray, deps_p: np.ndarray, dp: np.ndarray) -> dict[str, np.ndarray]:
        """The internal variables besides p at ``points`` after an increment with Δε_p and Δp there
        (arrays over ``points``): each part updates its own points, the others keep theirs."""
        internal_n = self.local_internal(points)
        out = {name: internal_n[name].copy() for name in self._others}
        owner = self._part_of_point[points]
        for k, part in enumerate(self.parts):
            if not part.internal_variables:
                continue
            mine = np.flatnonzero(owner == k)
            new = part.updated_internal(points[mine], deps_p[mine], dp[mine],
                                        {name: v[mine] for name, v in internal_n.items()})
            for name, value in new.items():
                out[name][mine] = value
        return out

    def _store_internal(self, points: np.ndarray, internal: Mapping[str, np.ndarray]) -> None:
        for name, f in self._others.items():
            f.x.array.reshape((-1, *f.ufl_shape))[points] = internal[name]

    # -- checkpoints --------------------------------------------------------------------------------------------
    def checkpoint_arrays(self) -> dict[str, np.ndarray]:
        """The converged state as named local arrays (owned and ghost entries)."""
        arrays = {"u_n": self.u_n.x.array, "sigma_n": self.sigma_n.x.array, "p_n": self.p_n.x.array,
                  "dp_n": self.dp_n.x.array}
        arrays.update({f"internal_{name}": f.x.array for name, f in self._others.items()})
        return arrays

    def restore_arrays(self, arrays: Mapping[str, np.ndarray]) -> None:
        """Restore :meth:`checkpoint_arrays` (the same mesh and partition)."""
        targets = {"u_n": self.u_n, "sigma_n": self.sigma_n, "p_n": self.p_n, "dp_n": self.dp_n}
        targets.update({f"internal_{name}": f for name, f in self._others.items()})
        for name, f in targets.items():
            if name not in arrays:
                raise ValueError(f"restore_arrays: no array {name!r} (the checkpoint is of another material)")
            f.x.array[:] = arrays[name]
        self.version += 1

    # -- counts and values at points ---------------------------------------------------------------------------
    def count_trial_plastic_points(self, u: fem.Function) -> int:
        """Number of Gauss points (over all ranks) where the return map at ``u`` is plastic."""
        dp = self._merged([part.trial_dp(u) for part in self.parts])
        n_local = self.W_scalar.dofmap.index_map.size_local * self.W_scalar.dofmap.index_map_bs
        return self.mesh.comm.allreduce(int(np.count_nonzero(dp[:n_local] > 0.0)), op=MPI.SUM)

    def at_points(self) -> PointwiseMaterial:
        """The material at this rank's owned Gauss points."""
        n = self.num_owned_points()
        if len(self.parts) == 1:
            return self.parts[0].at_points(np.arange(n))
        owner = self._part_of_point[:n]
        return CompositeAtPoints(owner, [part.at_points(np.flatnonzero(owner == k))
                                         for k, part in enumerate(self.parts)])

    def plastic_strain_of(self, u: fem.Function, sigma: np.ndarray) -> np.ndarray:
        """dev Δε − dev(σ − σ_n)/(2μ) at the owned Gauss points (n, 3, 3), Δε = ε(u) − ε(u_n)."""
        n = sigma.shape[0]
        dev_increment = self.owned_at_points(jit.expression(ufl.dev(strain(u) - strain(self.u_n)), self._points),
                                             tensor=True)
        mu = self.values_at_points(self.mu)
        dsigma = sigma - self.sigma_n.x.array[:9 * n].reshape(n, 3, 3)
        dev_dsigma = dsigma - np.trace(dsigma, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3.0
        return dev_increment - dev_dsigma / (2.0 * mu[:, None, None])

    # -- outputs ----------------------------------------------------------------------------------------------
    def yield_function_values(self) -> np.ndarray:
        """f/σ_y at the converged state at every local Gauss point:
        :func:`~dolfinx_nnqem.material.state_report.yield_function_values`."""
        if self._material_at_points is None:
            self._material_at_points = self.at_points()
        return _yield_function_values(self, self._material_at_points)


def materials_by_tag(materials, cell_tags, mesh) -> dict:
    """``{tag: material}`` (tag None: one material for every cell), each a Material, each tag present."""
    if isinstance(materials, Material):
        return {None: materials}
    if not isinstance(materials, dict) or not materials:
        raise TypeError(f"materials = {materials!r}: expected a material (e.g. VonMises, Elastic) or a non-empty "
                        "dict {cell_tag: material}")
    if cell_tags is None:
        raise ValueError("materials given per cell tag, but no cell_tags were given")
    for tag, m in materials.items():
        if not isinstance(m, Material):
            raise TypeError(f"materials[{tag}] is {type(m).__name__}, expected a material (e.g. VonMises, Elastic)")
        n = mesh.comm.allreduce(int(np.count_nonzero(cell_tags.values == tag)), op=MPI.SUM)
        if n == 0:
            present = sorted(set(np.concatenate(mesh.comm.allgather(np.unique(cell_tags.values))).tolist()))
            raise ValueError(f"materials: cell tag {tag} has no cells; the mesh's cell tags are {present}")
    return dict(materials)
