r"""The geometric blocks of rigid-obstacle pairs that combine nodes, and where they go in the Newton
matrix (6-node triangle facets, issue 41).

:class:`CombinedTerms` holds, for the local pairs of a tri6 surface that act on combinations of nodes
(d̂_i = Σ_k a_ik u_k), the per-pair 3 × 3 blocks K_i and W_i at the combined point and puts them on
the pair's nodes: a_il W_i on B's rows, (a aᵀ) ⊗ K_i on the u rows. How they are computed is in
:mod:`~dolfinx_nnqem.contact.combined_stiffness`; this module holds only the data and its placement,
so that :mod:`~dolfinx_nnqem.contact.geometric_stiffness` can carry them without importing what
computes them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from petsc4py import PETSc

from dolfinx_nnqem.contact.pairset import PairRows

__all__ = ["CombinedTerms"]


@dataclass(frozen=True)
class CombinedTerms:
    """The geometric blocks of the local obstacle pairs that combine nodes.

    Attributes
    ----------
    pairs
        (k,) local pair indices (into the model's pairs).
    indptr
        (k + 1,) pair i combines ``blocks[indptr[i]:indptr[i + 1]]``.
    blocks
        Global dof blocks of the combined nodes, ascending within each pair (B's column order).
    coefficients
        a_ik, one per entry of ``blocks``.
    K
        (k, 3, 3) ∂(R(x̂)ᵀλ)/∂d̂ = Σ_j λ_j ∂r_j/∂x̂ of each pair.
    W
        (k, 3, 3) ∂(gap, slip)/∂d̂ − R(x̂) of each pair.
    """

    pairs: np.ndarray
    indptr: np.ndarray
    blocks: np.ndarray
    coefficients: np.ndarray
    K: np.ndarray
    W: np.ndarray

    def __len__(self) -> int:
        return len(self.pairs)

    def _row_positions(self, rows: PairRows) -> np.ndarray:
        """Where this terms' own rows (:meth:`own_rows`) sit in B's layout ``rows``, entry by entry."""
        own = self.own_rows()
        k = len(self)
        first = 3 * np.arange(k)
        count = own.indptr[first + 3] - own.indptr[first]
        start = rows.indptr[3 * self.pairs]
        if np.any(rows.indptr[3 * self.pairs + 3] - start != count):
            raise ValueError("CombinedTerms: a pair's rows of B have other columns than its combined nodes'")
        at = np.arange(len(own.values)) + np.repeat(start - own.indptr[first], count)
        if not np.array_equal(rows.columns[at], own.columns):
            raise ValueError("CombinedTerms: a pair's rows of B have other columns than its combined nodes'")
        return at

    def own_rows(self) -> PairRows:
        """W's rows a_il W_i in the pairs' own layout (that of B's rows of these pairs alone)."""
        return PairRows.from_weighted_nodes(self.W, self.indptr, self.blocks, self.coefficients)

    def add_rows(self, values: np.ndarray, rows: PairRows) -> np.ndarray:
        """``values`` in B's layout ``rows`` with W added on these pairs' rows (in place; returned)."""
        if len(self):
            values[self._row_positions(rows)] += self.own_rows().values
        return values

    def free_in(self, column_free: np.ndarray, rows: PairRows) -> np.ndarray:
        """(nnz, 3): ``column_free`` (1 at free columns, one entry per entry of B's layout ``rows``) at
        the pairs' nodes, read off each pair's normal row (its nodes ascending, 3 components each)."""
        m = np.diff(self.indptr)
        within = np.arange(3 * len(self.blocks)) - np.repeat(3 * self.indptr[:-1], 3 * m)
        return column_free[np.repeat(rows.indptr[3 * self.pairs], 3 * m) + within].reshape(-1, 3)

    def node_blocks(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per pair: its nodes' global dofs (3 m,) and the block (a aᵀ) ⊗ K_i (3 m, 3 m) on them."""
        out = []
        for i in range(len(self)):
            nodes = slice(self.indptr[i], self.indptr[i + 1])
            a = self.coefficients[nodes]
            dofs = (3 * self.blocks[nodes, None] + np.arange(3)).reshape(-1)
            out.append((dofs, np.kron(np.outer(a, a), self.K[i])))
        return out

    def augmentation(self, free_values: np.ndarray, rows: PairRows, dH_dw: np.ndarray, c: float) -> list[np.ndarray]:
        """Per pair, c B_fᵀ D_wᵀ D_w W (3 m, 3 m): the iterative solver's augmentation of the rows' geometric
        part (:meth:`~dolfinx_nnqem.solvers.block_system.AugmentedSystem.augmented_geometric_blocks`), with
        B_f the pair's rows in ``free_values`` (B_free's values in the layout ``rows``) and W the pair's
        rows a_il W_i on its nodes."""
        out = []
        for i, pair in enumerate(self.pairs):
            a = self.coefficients[self.indptr[i]:self.indptr[i + 1]]
            B_f = free_values[rows.indptr[3 * pair]:rows.indptr[3 * pair + 3]].reshape(3, 3 * len(a))
            W = np.kron(a[None, :], self.W[i])  # (3, 3 m): a_il W_i on node l
            D = dH_dw[pair]
            out.append(c * B_f.T @ (D.T @ (D @ W)))
        return out

    def add_values(self, K: PETSc.Mat, free: np.ndarray, extra: Sequence[np.ndarray] | None = None) -> None:
        """K −= (a aᵀ) ⊗ K_i (+ ``extra``) on every pair's nodes, free rows and columns only (the
        constrained rows keep their identity), added to K unassembled: the caller assembles it
        (:meth:`~dolfinx_nnqem.contact.geometric_stiffness.GeometricTerms.add_to_tangent`).

        Parameters
        ----------
        K
            The tangent, assembled; its pattern holds the couplings of a pair's nodes (one facet).
        free
            (nnz, 3) 1 at the nodes' free dofs, 0 at constrained ones (:meth:`free_in`).
        extra
            Per pair, a (3 m, 3 m) block added as it is (:meth:`augmentation`), or None.
        """
        for i, (dofs, block) in enumerate(self.node_blocks()):
            mask = free[self.indptr[i]:self.indptr[i + 1]].reshape(-1)
            block = -block if extra is None else extra[i] - block
            index = dofs.astype(PETSc.IntType)
            K.setValues(index, index, mask[:, None] * block * mask[None, :],  # type: ignore[arg-type]  # petsc4py's stub asks Sequence; arrays are what it takes
                        addv=PETSc.InsertMode.ADD_VALUES)
