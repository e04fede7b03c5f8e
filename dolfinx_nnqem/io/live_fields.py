"""The last written increment's fields, gathered from memory for the run's own pictures.

At the end of a run the pictures (:mod:`dolfinx_nnqem.io.run_pictures`) need the fields of the
last converged increment. The run still holds them: the writers keep the displacement values they
wrote (:class:`~dolfinx_nnqem.io.field_series.FieldSeriesWriter`,
:class:`~dolfinx_nnqem.io.quadratic_fields.QuadraticFieldWriter`), and the cell means are in their
piecewise-constant functions. Reading them back from ``fields.xdmf`` instead took a child process
(h5py cannot share a process with the PyPI DOLFINx), and for a degree-2 run it gave the
displacement at the mesh's vertices only.

:func:`gather_field_step` returns the same kind of step as
:func:`dolfinx_nnqem.io.xdmf_steps.read_field_index` (``time``, ``geometry``, ``topology`` and one
array per field), plus ``cell_type``, the VTK cell type of the topology's rows, so that a
quadratic displacement is drawn on its own Lagrange cells.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import dolfinx.fem

__all__ = ["LINEAR_VTK_CELLS", "gather_field_step"]

LINEAR_VTK_CELLS = {10: (10, 4), 71: (10, 4), 24: (10, 4), 12: (12, 8), 72: (12, 8), 29: (12, 8)}
"""VTK cell type → (its first-order cell type, corner nodes): tetrahedra and hexahedra, linear,
Lagrange or quadratic. VTK lists a higher-order cell's corners first, in the first-order order."""


def gather_field_step(space: dolfinx.fem.FunctionSpace, u_values: np.ndarray, cell_fields: Mapping[str, Any],
                      time: float, *, whole_cells: bool) -> dict | None:
    """The displacement ``u_values`` of ``space`` and cell fields as one picture step, on rank 0.

    Collective. Every rank sends its owned cells (with the nodes they use, ghosts included);
    rank 0 places each node at its global index, so nodes shared by ranks appear once, as in
    ``fields.xdmf``.

    Parameters
    ----------
    space
        The vector Lagrange space of the displacement (degree 1 or 2).
    u_values
        The displacement's local values (``Function.x.array`` of ``space``, ghosts included), as
        they were written.
    cell_fields
        Name → piecewise-constant (DG 0) function: ``von_mises``, ``p``, ``plastic``.
    time
        The increment's load factor.
    whole_cells
        Keep a quadratic space's Lagrange cells whole (its nodes off the vertices drawn too);
        otherwise each cell is reduced to its corners, as pictures read from ``fields.xdmf`` draw it.

    Returns
    -------
    dict or None
        On rank 0 the step; None on the other ranks.
    """
    import dolfinx.plot

    mesh = space.mesh
    owned_cells = mesh.topology.index_map(mesh.topology.dim).size_local
    cells, cell_types, x = dolfinx.plot.vtk_mesh(space, np.arange(owned_cells, dtype=np.int32))
    cell_types = np.asarray(cell_types)
    vtk_type = int(cell_types[0]) if len(cell_types) else -1  # a rank may own no cell
    cells = np.asarray(cells).reshape(len(cell_types), -1)[:, 1:]  # rows [n, i0, ..., i(n-1)]
    index_map = space.dofmap.index_map
    nodes = index_map.size_local + index_map.num_ghosts
    global_nodes = index_map.local_to_global(np.arange(nodes, dtype=np.int32))
    u = np.asarray(u_values).reshape(-1, 3)[:nodes]
    values = {}
    for name, function in cell_fields.items():
        dofs = function.function_space.dofmap.list[:owned_cells, 0]
        values[name] = np.asarray(function.x.array[dofs])
    parts = mesh.comm.gather((vtk_type, global_nodes[cells], global_nodes, np.asarray(x)[:nodes], u, values), root=0)
    if mesh.comm.rank != 0:
        return None
    kinds = {kind for kind, top, *_ in parts if len(top)}
    if len(kinds) != 1:
        raise ValueError(f"cells of VTK types {sorted(kinds)}: one cell type expected")
    vtk_type = kinds.pop()
    size = index_map.size_global
    geometry, displacement = np.zeros((size, 3)), np.zeros((size, 3))
    for _, _, where, xx, uu, _ in parts:
        geometry[where], displacement[where] = xx, uu
    topology = np.concatenate([top for _, top, *_ in parts if len(top)]).astype(np.int64)
    if not whole_cells and vtk_type in LINEAR_VTK_CELLS:
        vtk_type, corners = LINEAR_VTK_CELLS[vtk_type]
        topology = topology[:, :corners]
        # the nodes no corner uses (edge and face nodes) are dropped: the grid holds what it draws
        used = np.unique(topology)
        topology = np.searchsorted(used, topology)
        geometry, displacement = geometry[used], displacement[used]
    step: dict = {"time": float(time), "geometry": geometry, "topology": topology, "cell_type": vtk_type,
                  "u": displacement}
    for name in cell_fields:
        step[name] = np.concatenate([part[5][name] for part in parts])
    return step
