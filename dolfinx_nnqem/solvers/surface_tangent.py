"""The tangent with the node-to-surface pairs' geometric blocks: K_t − K as a matrix of its own.

With the consistent current geometry (:mod:`~dolfinx_nnqem.contact.surface_stiffness`) a pair's
force block K couples its slave node with the master facet's nodes, which the tangent K_t's
pattern does not hold. :class:`SurfaceTangent` keeps K_t − K between Newton iterates: made anew
when the pairs' columns change (a pair on another master facet: the Newton matrix's pattern
changes with it) and refilled in place otherwise, so that MUMPS keeps its analysis.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.contact.surface_stiffness import SurfaceTerms, stiffness_matrix
from dolfinx_nnqem.solvers.block_system import MonolithicMatrix

__all__ = ["SurfaceTangent"]


class SurfaceTangent:
    """K_t − K of the node-to-surface pairs, kept from one Newton iterate to the next."""

    def __init__(self) -> None:
        self.matrix: PETSc.Mat | None = None  #: K_t − K (its own pattern)
        self._columns: np.ndarray | None = None  # the pairs' columns that made its pattern

    def with_terms(self, K: PETSc.Mat, terms: list[SurfaceTerms], layout: MonolithicMatrix, rows,
                   B_values: np.ndarray | None, comm: MPI.Comm) -> tuple[PETSc.Mat, np.ndarray, bool]:
        """(K_t − K, B + W, new pattern) for the tangent ``K`` and the pairs' geometric blocks ``terms``
        (collective); ``rows`` are the model's pair rows B, ``B_values`` their values if the obstacles'
        terms already changed them."""
        values = rows.values.copy() if B_values is None else B_values
        for part in terms:
            part.add_rows(values, rows)
        G = stiffness_matrix(terms, [layout.pair_free(t.pairs, t.columns.shape[1]) for t in terms], K)
        columns = np.concatenate([np.zeros(0, dtype=np.int64)] + [t.columns.ravel() for t in terms])
        same = self.matrix is not None and self._columns is not None and np.array_equal(columns, self._columns)
        same = bool(comm.allreduce(same, op=MPI.LAND))
        if same:
            assert self.matrix is not None  # same: made before
            self.matrix.zeroEntries()
            self.matrix.axpy(1.0, K, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)  # type: ignore[arg-type]  # petsc4py's stub types the Structure constants as int
            self.matrix.axpy(-1.0, G, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)  # type: ignore[arg-type]  # as above
        else:
            self.destroy()
            self.matrix = K.copy()
            self.matrix.axpy(-1.0, G, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)  # type: ignore[arg-type]  # as above
            self._columns = columns
        G.destroy()
        return self.matrix, values, not same

    def destroy(self) -> None:
        """Free the matrix (a new one is made at the next use)."""
        if self.matrix is not None:
            self.matrix.destroy()
        self.matrix = None
