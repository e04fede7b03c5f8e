"""The shape of every cell of the deformed mesh, x + u: what the independent check asks of a
converged state at finite strain instead of a small-strain limit.

At finite strain a strain of 100 % is a legitimate answer, so the small-strain check's
``max_strain`` means nothing there; what does is whether the deformed cells are still cells. The
deformed geometry map x(ξ) + u(ξ) is measured with the scaled Jacobian s of
:mod:`~dolfinx_nnqem.problem.mesh_quality` (at the Gauss points of the forms' rule and the
reference vertices, relative to the undeformed cell's orientation): s ≤ 0 where the deformation
turned the cell inside out, s = sin θ for a cube sheared to a parallelepiped of angle θ, towards
0 as it flattens. A deformed cell with s below a bound (``CheckOptions.min_scaled_jacobian``)
is named: its input index, cell tag and undeformed centre.
"""

from __future__ import annotations

from dataclasses import dataclass

import dolfinx.fem as fem
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem import compat
from dolfinx_nnqem.problem.mesh_quality import NAMED, _gathered, cell_measures, sample_points

__all__ = ["DeformedCells", "deformed_cells", "node_displacements"]


@dataclass(frozen=True)
class DeformedCells:
    """The deformed mesh's cells below a bound of s (the same on every rank)."""

    min_scaled_jacobian: float  #: the smallest s over all cells and sample points
    count: int  #: cells with s below the bound
    named: tuple[str, ...]  #: at most :data:`~dolfinx_nnqem.problem.mesh_quality.NAMED` of them, the worst first

    def reason(self, bound: float) -> str:
        """The check's sentence for these cells (empty if there are none)."""
        if not self.count:
            return ""
        more = " and more" if self.count > NAMED else ""
        return (f"{self.count} cell(s) of the deformed mesh are inverted or badly distorted (scaled Jacobian of "
                f"x + u below min_scaled_jacobian = {bound:g}; s <= 0: turned inside out): "
                f"{'; '.join(self.named)}{more}")


def node_displacements(u: fem.Function) -> np.ndarray:
    """u at every geometry node of its mesh, laid out like ``mesh.geometry.x`` (n_nodes, 3): u
    interpolated into the coordinate element's space, whose cell dofs are the geometry nodes'."""
    mesh = u.function_space.mesh
    degree = compat.coordinate_element(mesh).degree
    V_x = fem.functionspace(mesh, ("Lagrange", degree, (3,)))
    u_x = fem.Function(V_x)
    u_x.interpolate(u)
    out = np.zeros_like(mesh.geometry.x)
    out[compat.geometry_dofmap(mesh)] = u_x.x.array.reshape(-1, 3)[V_x.dofmap.list]
    return out


def deformed_cells(u: fem.Function, cell_tags, quadrature_degree: int, bound: float) -> DeformedCells:
    """The owned cells of the mesh of ``u`` deformed by ``u`` whose s falls below ``bound`` (collective)."""
    mesh = u.function_space.mesh
    num_owned = mesh.topology.index_map(mesh.topology.dim).size_local
    cells = np.arange(num_owned, dtype=np.int32)
    s, _ = cell_measures(mesh, sample_points(mesh, quadrature_degree), cells, node_displacements(u))
    bad = s < bound
    tags = np.full(num_owned, -1, dtype=np.int64)
    if cell_tags is not None:
        owned = cell_tags.indices < num_owned
        tags[cell_tags.indices[owned]] = cell_tags.values[owned]
    chosen = cells[bad]
    cell = mesh.topology.cell_type.name
    num_vertices = {"tetrahedron": 4, "hexahedron": 8}.get(cell, 4)
    centre = mesh.geometry.x[compat.geometry_dofmap(mesh)[chosen][:, :num_vertices]].mean(axis=1) \
        if len(chosen) else np.zeros((0, 3))
    found = (mesh.topology.original_cell_index[chosen].astype(np.int64), tags[chosen], centre, s[bad],
             np.full(len(chosen), -1.0))
    comm = mesh.comm
    count, named = _gathered(comm.allgather(found), worst_first=True)
    return DeformedCells(comm.allreduce(float(s.min(initial=np.inf)), op=MPI.MIN), count, named)
