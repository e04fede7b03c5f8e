"""The pair directions a support holds, which the pair laws pin (``PairLaws.constrained``).

A row of B whose significant columns are all constrained dofs cannot move: its contact force would
act on the supports alone (a null space of the multipliers). And node-to-surface and mortar rows of
slave nodes held tangentially by a symmetry plane are pinned (:func:`supported_slave_tangents`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.contact.pairset import PairRows, PairSet, rows_matrix
from dolfinx_nnqem.contact.surface_pairs import SurfacePairs

__all__ = ["constrained_directions", "supported_slave_tangents"]


def constrained_directions(rows: PairRows, comm: MPI.Comm, num_global: int, index_map: Any,
                           interfaces: Sequence[tuple[PairSet, Any]], constrained_dofs: PETSc.Vec) -> np.ndarray:
    """(num_local, 3) bool: the pair directions a support holds.

    Parameters
    ----------
    rows
        The rows of B of this rank's pairs (3 per pair).
    comm, num_global, index_map
        The pairs' communicator and global count, and the displacement dofs' index map.
    interfaces
        Each interface's pair set and the positions of its pairs among this rank's.
    constrained_dofs
        1 at the constrained displacement dofs, 0 elsewhere.

    Returns
    -------
    np.ndarray
        True for the rows of B all of whose (significant) columns are constrained dofs, and for the
        slave tangents :func:`supported_slave_tangents` pins.
    """
    values = rows.values
    num_local = (len(rows.indptr) - 1) // 3
    pair = np.repeat(np.arange(len(rows.indptr) - 1), np.diff(rows.indptr)) // 3
    largest = np.zeros(num_local)
    np.maximum.at(largest, pair, np.abs(values))
    involved = (np.abs(values) > 1e-12 * largest[pair]).astype(float)
    M = rows_matrix(comm, rows, num_global, index_map, involved)
    free = constrained_dofs.duplicate()
    with free.localForm() as f, constrained_dofs.localForm() as c:
        f.array[:] = 1.0 - c.array
    y = M.createVecLeft()
    M.mult(free, y)
    out = y.getArray(readonly=True).reshape(-1, 3) == 0.0
    for obj in (M, free, y):
        obj.destroy()
    for pairs, local in interfaces:
        if pairs.pins_supported_slave_tangents:
            out[local] |= supported_slave_tangents(pairs)
    return out


def supported_slave_tangents(pairs: PairSet) -> np.ndarray:
    """(num_local, 3) bool: the pair directions a support holds (node-to-surface and mortar).

    Such rows couple a slave node to several master nodes, so the friction forces of slave
    nodes held tangentially by a symmetry plane crossing the interface may combine into forces
    that act on the supports alone: a null space of the multipliers and a singular Newton
    matrix. The support carries those components; the contact force there is pinned to zero
    (``docs/theory.md``). Which directions: :mod:`~dolfinx_nnqem.contact.symmetry_planes` (the
    symmetry planes of the interface, and supports of the slave side alone only where their
    rows would over-constrain the master). The normal direction is never pinned this way: a
    supported slave node still keeps the master out.
    """
    assert isinstance(pairs, SurfacePairs)  # the one pair set that pins supported slave tangents
    if pairs.support_pinned is None:  # built without knowing the supports
        return np.zeros((pairs.num_local, 3), dtype=bool)
    return pairs.support_pinned
