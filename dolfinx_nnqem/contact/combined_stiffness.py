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
from dataclasses import replace
from typing import Any

import numpy as np

from dolfinx_nnqem.contact.combined_terms import CombinedTerms
from dolfinx_nnqem.contact.current_geometry import CombinedObstacleTracker
from dolfinx_nnqem.contact.geometric_stiffness import obstacle_terms
from dolfinx_nnqem.contact.obstacles import ObstaclePairs

__all__ = ["CombinedTerms", "combined_obstacle_terms", "combined_terms"]


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
