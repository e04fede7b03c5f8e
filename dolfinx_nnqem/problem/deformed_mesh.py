"""The shape of every cell of the deformed mesh, x + u: what the independent check asks of a
converged state at finite strain instead of a small-strain limit.

At finite strain a strain of 100 % is a legitimate answer, so the small-strain check's
``max_strain`` means nothing there; what does is whether the deformed cells are still cells. Each
cell's shape is measured with the scaled Jacobian s of :mod:`~dolfinx_nnqem.problem.mesh_quality`
(its smallest value over the Gauss points of the forms' rule and the reference vertices, relative
to the undeformed cell's orientation) on the deformed geometry map x(ξ) + u(ξ) and on the
undeformed one: s ≤ 0 where the deformation turned the cell inside out; the **shape ratio**
s(x + u) / s(x) is 1 for a cell moved rigidly or stretched without shear (a cube stays a box), sin θ
for a cube sheared to a parallelepiped of angle θ, and tends to 0 as the deformation flattens the
cell. Relative to the undeformed shape, so that a mesh whose cells start far from their reference
shape (gmsh's tetrahedra of curved bodies, s down to 0.016) is judged by what the deformation did.
A cell with a ratio below a bound (``CheckOptions.min_shape_ratio``), or inverted, is named: its
input index, cell tag and undeformed centre.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import dolfinx.fem as fem
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem import compat
from dolfinx_nnqem.problem.mesh_quality import INVERTED, NAMED, _gathered, cell_measures, sample_points

__all__ = ["DeformedCells", "deformed_cells", "node_displacements"]


@dataclass(frozen=True)
class DeformedCells:
    """The deformed mesh's cells that are inverted or below a bound of the shape ratio (the same on every rank)."""

    min_shape_ratio: float  #: the smallest s(x + u) / s(x) over all cells
    count: int  #: cells inverted or with a ratio below the bound
    named: tuple[str, ...]  #: at most :data:`~dolfinx_nnqem.problem.mesh_quality.NAMED` of them, the worst first

    def reason(self, bound: float) -> str:
        """The check's sentence for these cells (empty if there are none)."""
        if not self.count:
            return ""
        more = " and more" if self.count > NAMED else ""
        return (f"{self.count} cell(s) of the deformed mesh are inverted or badly distorted (scaled Jacobian of "
                f"x + u at most {INVERTED:g}, or below min_shape_ratio = {bound:g} times the undeformed cell's; "
                f"s: the deformed cell's, ρ: the ratio): {'; '.join(self.named)}{more}")


#: The coordinate element's vector space for each displacement function seen (made once: a new
#: function space costs more than the check it serves, which runs at every converged increment).
#: Keyed by the function (a function space is not hashable), kept while it lives.
_COORDINATE_SPACES: weakref.WeakKeyDictionary[fem.Function, fem.FunctionSpace] = weakref.WeakKeyDictionary()


def coordinate_space(u: fem.Function) -> fem.FunctionSpace:
    """The vector Lagrange space of the coordinate element's degree on the mesh of ``u``, whose cell
    dofs are the geometry nodes' (made once per function)."""
    V_x = _COORDINATE_SPACES.get(u)
    if V_x is None:
        mesh = u.function_space.mesh
        V_x = fem.functionspace(mesh, ("Lagrange", compat.coordinate_element(mesh).degree, (3,)))
        _COORDINATE_SPACES[u] = V_x
    return V_x


def node_displacements(u: fem.Function) -> np.ndarray:
    """u at every geometry node of its mesh, laid out like ``mesh.geometry.x`` (n_nodes, 3): u
    interpolated into the coordinate element's space, whose cell dofs are the geometry nodes'."""
    mesh = u.function_space.mesh
    V_x = coordinate_space(u)
    u_x = fem.Function(V_x)
    u_x.interpolate(u)
    out = np.zeros_like(mesh.geometry.x)
    out[compat.geometry_dofmap(mesh)] = u_x.x.array.reshape(-1, 3)[V_x.dofmap.list]
    return out


def deformed_cells(u: fem.Function, cell_tags, quadrature_degree: int, bound: float) -> DeformedCells:
    """The owned cells of the mesh of ``u`` that ``u`` inverts, or deforms to a shape ratio below
    ``bound`` (collective)."""
    mesh = u.function_space.mesh
    num_owned = mesh.topology.index_map(mesh.topology.dim).size_local
    cells = np.arange(num_owned, dtype=np.int32)
    points = sample_points(mesh, quadrature_degree)
    s_reference, _ = cell_measures(mesh, points, cells)  # > INVERTED: the problem checked the mesh
    s, _ = cell_measures(mesh, points, cells, node_displacements(u))
    ratio = s / s_reference
    bad = (s <= INVERTED) | (ratio < bound)
    tags = np.full(num_owned, -1, dtype=np.int64)
    if cell_tags is not None:
        owned = cell_tags.indices < num_owned
        tags[cell_tags.indices[owned]] = cell_tags.values[owned]
    chosen = cells[bad]
    num_vertices = {"tetrahedron": 4, "hexahedron": 8}[mesh.topology.cell_type.name]
    centre = mesh.geometry.x[compat.geometry_dofmap(mesh)[chosen][:, :num_vertices]].mean(axis=1) \
        if len(chosen) else np.zeros((0, 3))
    found = (mesh.topology.original_cell_index[chosen].astype(np.int64), tags[chosen], centre, s[bad], ratio[bad])
    comm = mesh.comm
    count, named = _gathered(comm.allgather(found), worst_first=True)
    return DeformedCells(comm.allreduce(float(ratio.min(initial=np.inf)), op=MPI.MIN), count, named)
