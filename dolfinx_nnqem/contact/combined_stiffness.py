r"""The geometric terms of rigid-obstacle pairs that combine nodes (6-node triangle facets, issue 41).

On a surface of 6-node triangles (P2 tetrahedra) a rigid obstacle's pair i acts on the transformed
displacement of its nodes (:mod:`~dolfinx_nnqem.contact.quadratic_facets`,
:class:`~dolfinx_nnqem.contact.obstacles.CombinedNodes`),

    d̂_i = Σ_k a_ik u_k,   the point x̂_i = X̂_i + d̂_i − d(ℓ) seen from the obstacle at rest,

and B's rows of the pair are R(x̂_i) a_ik on node k. Re-evaluated at every Newton iterate
(:class:`~dolfinx_nnqem.contact.current_geometry.CombinedObstacleTracker`), the pair's frame, gap
and slip depend on d̂_i only: they are a degree-1 obstacle pair's at the point x̂_i, whose per-pair
3 × 3 blocks K_i and W_i (:func:`~dolfinx_nnqem.contact.geometric_stiffness.obstacle_terms`, with
the slip a_i = d̂_i − d̂_i,n − (d(ℓ) − d(ℓ_n))) are the derivatives with respect to d̂_i. The chain
rule through ∂d̂_i/∂u_l = a_il I gives the pair's terms on its nodes:

    ∂(gap, slip)_i/∂u_l − R_i a_il = a_il W_i            (B + W keeps B's pattern),
    ∂(Bᵀλ)_k/∂u_l at fixed λ      = a_ik a_il K_i         (the force a_ik R_iᵀλ_i on node k).

The K blocks couple the nodes of one combination: the nodes of one facet edge (an edge node and the
edge's two vertices) or a vertex alone, all in one cell, so the tangent's sparsity holds them (unlike
node-to-surface pairs, :func:`~dolfinx_nnqem.contact.surface_stiffness.stiffness_matrix`); a node of
the combination may be owned by another rank than the pair, and PETSc sends its rows there.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from petsc4py import PETSc

from dolfinx_nnqem.contact.current_geometry import CombinedObstacleTracker
from dolfinx_nnqem.contact.geometric_stiffness import obstacle_terms
from dolfinx_nnqem.contact.obstacles import ObstaclePairs
from dolfinx_nnqem.contact.pairset import PairRows

__all__ = ["CombinedTerms", "combined_obstacle_terms", "combined_terms"]


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


def combined_obstacle_terms(pairs: ObstaclePairs, u_hat: np.ndarray, u_hat_n: np.ndarray, d: np.ndarray,
                            d_n: np.ndarray, lam: np.ndarray, local: np.ndarray) -> CombinedTerms:
    """The :class:`CombinedTerms` of a tri6 surface's obstacle pairs evaluated at d̂ = ``u_hat`` (module).

    Parameters
    ----------
    pairs
        The pairs, evaluated at ``u_hat`` (their R is R(x̂)); ``pairs.combination`` is not None.
    u_hat, u_hat_n
        (m, 3) the pairs' transformed displacements d̂ at the iterate and at the last converged increment.
    d, d_n
        (3,) the obstacle's translation d(ℓ) and d(ℓ_n).
    lam
        (m, 3) the pairs' local forces λ = (p_n, q1, q2).
    local
        (m,) the pairs' indices among the model's local pairs.
    """
    nodes = pairs.combination
    assert nodes is not None  # a tri6 surface's pairs
    # the per-pair blocks of a degree-1 pair at the point X̂ + d̂: derivatives with respect to d̂
    K, W = obstacle_terms(replace(pairs, X_slave=nodes.X), u_hat, u_hat_n, d, d_n, lam)
    pair = np.repeat(np.arange(pairs.num_local), np.diff(nodes.indptr))
    order = np.lexsort((nodes.blocks, pair))  # ascending nodes within each pair: B's columns
    return CombinedTerms(np.asarray(local, dtype=np.int64), np.asarray(nodes.indptr, dtype=np.int64),
                         np.asarray(nodes.blocks, dtype=np.int64)[order], nodes.coefficients[order], K, W)


def combined_terms(interfaces: Sequence[Any], trackers: Sequence[Any], u, load_factor: float, u_n, load_factor_n: float,
                   lam: np.ndarray) -> CombinedTerms | None:
    """The :class:`CombinedTerms` of every interface whose tracker is a
    :class:`~dolfinx_nnqem.contact.current_geometry.CombinedObstacleTracker`, at (u, ℓ) and the forces
    ``lam`` of the model's local pairs; None if there is none (collective: every rank has the same
    trackers, and gets terms, empty or not)."""
    parts = []
    for interface, tracker in zip(interfaces, trackers):
        if not isinstance(tracker, CombinedObstacleTracker):
            continue
        pairs = interface.pairs
        assert isinstance(pairs, ObstaclePairs)  # a combined obstacle tracker's pairs
        local = interface.local
        parts.append(combined_obstacle_terms(
            pairs, tracker.displacement(pairs, u), tracker.displacement(pairs, u_n),
            pairs.obstacle.displacement(load_factor), pairs.obstacle.displacement(load_factor_n), lam[local],
            np.arange(local.start, local.stop)))
    if not parts:
        return None
    offsets = np.cumsum([0] + [p.indptr[-1] for p in parts[:-1]])
    indptr = np.concatenate([np.zeros(1, dtype=np.int64)] + [p.indptr[1:] + o for p, o in zip(parts, offsets)])
    return CombinedTerms(np.concatenate([p.pairs for p in parts]), indptr, np.concatenate([p.blocks for p in parts]),
                         np.concatenate([p.coefficients for p in parts]), np.concatenate([p.K for p in parts]),
                         np.concatenate([p.W for p in parts]))
