r"""The geometric terms of a rigid obstacle's pairs in the current geometry (issue 27, "a linearisation
that keeps Newton fast").

With ``Contact(obstacle, ..., geometry="current")`` the monolithic solver re-evaluates an obstacle's
pairs at every Newton iterate
(:meth:`~dolfinx_nnqem.contact.geometry_tracking.ContactGeometry.refresh_obstacles`): the frame
R(x) = (n, t1, t2) and the gap g(x) of the slave node at x = X_s + u_s − d(ℓ), the obstacle seen at
rest. The residuals are then

    R(u, z) = F_int(u) − F_ext − Σ_s P_sᵀ R(x_s)ᵀ λ_s(z),
    H(u, z) = H(gap, slip, z),  gap = g(x_s),  slip = T(x_s) a_s,  a_s = u_s − u_s,n − (d(ℓ) − d(ℓ_n)),

(P_s picks the slave node's dofs, T the tangent rows t1, t2), and their derivatives with respect
to u_s are those of the frozen geometry plus, per pair, two 3 × 3 blocks on the slave node:

    K_s = Σ_i λ_i ∂r_i/∂x          (the force Rᵀλ turning with the normal: u rows get −K_s),
    W_s = [0; aᵀ ∂t1/∂x; aᵀ ∂t2/∂x]  (the slip measured in a frame that turns: H rows get ∂H/∂w W_s).

The gap has no extra term: ∂g/∂x = n exactly (the signed distance's gradient), which is B's
normal row. ∂r_i/∂x = ∂r_i/∂n · ∂n/∂x with ∂n/∂x the obstacle's curvature
(:meth:`RigidObstacle.normal_derivative`: zero for a plane, (I − n nᵀ)/ρ for a sphere,
(I − e eᵀ − n nᵀ)/ρ for a cylinder) and ∂R/∂n that of the frame's construction
(:func:`~dolfinx_nnqem.contact.surfaces.local_frames_derivative`). For a frictionless pair only
p_n ∂n/∂x remains; the frame's rotation enters with friction (q ≠ 0, and the slip a ≠ 0).

An obstacle's pairs on 6-node triangle facets (P2 tetrahedra) act on combinations of nodes: their
blocks are these at the combined point, put on the nodes with the coefficients
(:mod:`~dolfinx_nnqem.contact.combined_stiffness`, :attr:`GeometricTerms.combined`).
Node-to-surface pairs have theirs in :mod:`~dolfinx_nnqem.contact.surface_stiffness` (their closest
point moves too, and the force acts on the master nodes), dual mortar pairs in
:mod:`~dolfinx_nnqem.contact.mortar_linearisation` (``docs/theory.md``, "Large sliding").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from petsc4py import PETSc

from dolfinx_nnqem.contact.obstacles import ObstaclePairs
from dolfinx_nnqem.contact.pairset import PairRows
from dolfinx_nnqem.contact.surfaces import local_frames_derivative

if TYPE_CHECKING:
    from dolfinx_nnqem.contact.combined_terms import CombinedTerms

__all__ = ["GeometricTerms", "frame_derivative", "no_terms", "obstacle_terms"]


@dataclass(frozen=True)
class GeometricTerms:
    """The geometric blocks of the local pairs that have them, each on its slave node's 3 dofs.

    Attributes
    ----------
    pairs
        (k,) local pair indices (into the model's pairs).
    slave_blocks
        (k,) the pairs' slave nodes, global dof blocks (owned by this rank).
    K
        (k, 3, 3) ∂(R(x)ᵀλ)/∂u_s = Σ_i λ_i ∂r_i/∂x.
    W
        (k, 3, 3) ∂(gap, slip)/∂u_s − R(x): the rows of B a consistent Newton step adds.
    combined
        The terms of the pairs that combine nodes (6-node triangle facets,
        :mod:`~dolfinx_nnqem.contact.combined_stiffness`), on every rank where some interface has such
        pairs (empty on a rank without them); None where none has. The attributes above, and
        :meth:`add_to_tangent`, are the other pairs'.
    """

    pairs: np.ndarray
    slave_blocks: np.ndarray
    K: np.ndarray
    W: np.ndarray
    combined: CombinedTerms | None = None

    def __len__(self) -> int:
        return len(self.pairs) + (0 if self.combined is None else len(self.combined))

    def rows_values(self, rows: PairRows) -> np.ndarray:
        """The values of B + W in B's layout ``rows`` (the pairs with terms have their slave node's 3
        columns only, in order: their 9 entries are the 3 × 3 block, row by row; those that combine
        nodes, their nodes' columns)."""
        values = rows.values.copy()
        if self.combined is not None:
            self.combined.add_rows(values, rows)
        if len(self.pairs):
            start = rows.indptr[3 * self.pairs]
            if np.any(rows.indptr[3 * self.pairs + 3] - start != 9):
                raise ValueError("GeometricTerms: a pair with geometric terms has other columns than its slave node's")
            values[start[:, None] + np.arange(9)] += self.W.reshape(-1, 9)
        return values

    def slave_dofs(self) -> np.ndarray:
        """(k, 3) the slave nodes' global dofs."""
        return 3 * self.slave_blocks[:, None] + np.arange(3)

    def add_to_tangent(self, K: PETSc.Mat, free: np.ndarray, extra: np.ndarray | None = None, *,
                       combined: tuple[np.ndarray, Sequence[np.ndarray] | None] | None = None) -> None:
        """K −= K_s (+ ``extra``) on every slave node's free rows and columns (the constrained rows
        keep their identity), in place; K must hold the slave nodes' 3 × 3 blocks already (it does:
        a node's dofs are coupled within its elements). With ``combined``, the blocks of the pairs
        that combine nodes too (:meth:`~dolfinx_nnqem.contact.combined_stiffness.CombinedTerms.add_values`).

        Parameters
        ----------
        K
            The tangent, assembled.
        free
            (k, 3) 1 at the slave nodes' free dofs, 0 at constrained ones.
        extra
            (k, 3, 3) blocks added as they are (the iterative solver's augmentation of W), or None.
        combined
            (free, extra) of :attr:`combined`'s pairs: (nnz, 3) 1 at their nodes' free dofs, and per pair
            a block added as it is, or None; None (default) leaves them out.
        """
        blocks = -self.K if extra is None else extra - self.K
        blocks = free[:, :, None] * blocks * free[:, None, :]
        dofs = self.slave_dofs().astype(PETSc.IntType)
        for index, block in zip(dofs, blocks):
            K.setValues(index, index, block, addv=PETSc.InsertMode.ADD_VALUES)
        if self.combined is not None and combined is not None:
            self.combined.add_values(K, *combined)
        K.assemble()

    def tangent_action(self, delta: np.ndarray, start: int) -> np.ndarray:
        """(k, 3) K_s δ_s of a displacement ``delta`` (V's local array, owned blocks from ``start``)."""
        d = delta.reshape(-1, 3)[self.slave_blocks - start]
        return np.einsum("kij,kj->ki", self.K, d)

    def w_action(self, delta: np.ndarray, start: int) -> np.ndarray:
        """(k, 3) W_s δ_s of a displacement ``delta`` (V's local array, owned blocks from ``start``)."""
        d = delta.reshape(-1, 3)[self.slave_blocks - start]
        return np.einsum("kij,kj->ki", self.W, d)


def no_terms() -> GeometricTerms:
    """No pair with geometric terms."""
    return GeometricTerms(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 3, 3)),
                          np.zeros((0, 3, 3)))


def frame_derivative(pairs: ObstaclePairs, x: np.ndarray) -> np.ndarray:
    """dR[s, i, k, j] = ∂R_ik/∂x_j: the pairs' frames (rows n, t1, t2) as the points ``x`` (m, 3), seen
    from the obstacle at rest, move."""
    dn_dx = pairs.obstacle.normal_derivative(x)
    dR_dn = local_frames_derivative(pairs.R[:, 0])
    return np.einsum("sikl,slj->sikj", dR_dn, dn_dx)


def obstacle_terms(pairs: ObstaclePairs, u_s: np.ndarray, u_s_n: np.ndarray, d: np.ndarray, d_n: np.ndarray,
                   lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K, W) (m, 3, 3) of an obstacle's pairs evaluated at their slave displacements ``u_s`` (module).

    Parameters
    ----------
    pairs
        The pairs, evaluated at ``u_s`` (their R is R(x)).
    u_s, u_s_n
        (m, 3) the slave nodes' displacements at the iterate and at the last converged increment.
    d, d_n
        (3,) the obstacle's translation d(ℓ) and d(ℓ_n).
    lam
        (m, 3) the pairs' local forces λ = (p_n, q1, q2).
    """
    x = pairs.X_slave + u_s - d
    dR = frame_derivative(pairs, x)
    K = np.einsum("si,sikj->skj", lam, dR)
    a = u_s - u_s_n - (d - d_n)
    W = np.zeros_like(K)
    W[:, 1:] = np.einsum("sk,sakj->saj", a, dR[:, 1:])
    return K, W
