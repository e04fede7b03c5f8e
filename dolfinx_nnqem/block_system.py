"""The semismooth Newton matrix of the monolithic solver as one PETSc system.

    J = [ K_t        −Bᵀ Λ' ]      u rows: equilibrium (constrained rows: identity)
        [ ∂_wH · B   ∂_zH   ]      z rows: the pair laws H(Bu, z) = 0

Λ' = ∂λ/∂z is the identity for the Cartesian law and the polar → Cartesian derivative for the
seed's polar law. The four blocks are put in a MatNest and converted to one AIJ matrix, whose
local rows are [owned u rows, owned pair rows] on every rank (the nest's layout), so that MUMPS
(or any PETSc preconditioner) sees an ordinary sparse matrix.
"""

from __future__ import annotations

import numpy as np
from petsc4py import PETSc


def block_diagonal_matrix(D: np.ndarray, offset: int, num_global: int, comm) -> PETSc.Mat:
    """AIJ matrix with the 3×3 blocks ``D[i]`` on the diagonal (rows of the owned pairs).

    Parameters
    ----------
    D
        (n_local, 3, 3) blocks of the owned pairs.
    offset
        Global index of the first owned pair.
    num_global
        Number of pairs over all ranks.
    """
    n = D.shape[0]
    indptr = np.arange(0, 9 * n + 1, 3, dtype=PETSc.IntType)
    cols = 3 * (offset + np.repeat(np.arange(n), 3))[:, None] + np.arange(3)[None, :]
    M = PETSc.Mat().createAIJWithArrays(
        size=((3 * n, 3 * num_global), (3 * n, 3 * num_global)),
        csr=(indptr, cols.reshape(-1).astype(PETSc.IntType), np.ascontiguousarray(D.reshape(-1))),
        comm=comm,
    )
    M.assemble()
    return M


def contact_jacobian_blocks(pairs, dH_dw, dH_dz, dlam_dz, constrained_rows: np.ndarray):
    """The three contact blocks of J.

    Returns
    -------
    A01 : −Bᵀ Λ' (u rows × z columns), constrained rows zeroed
    A10 : ∂_wH · B (z rows × u columns)
    A11 : ∂_zH (block diagonal)
    """
    # Bᵀ Λ' = (Λ'ᵀ B)ᵀ, and Λ'ᵀ B has B's sparsity.
    A01 = pairs.scaled_B(np.ascontiguousarray(np.transpose(dlam_dz, (0, 2, 1))))
    A01.transpose()  # in place (petsc4py's transpose without an output matrix)
    A01.scale(-1.0)
    # constrained_rows are global unrolled indices of owned constrained dofs
    A01.zeroRows(constrained_rows, diag=0.0)
    A10 = pairs.scaled_B(dH_dw)
    A11 = block_diagonal_matrix(dH_dz, pairs.offset, pairs.num_global, A10.getComm().tompi4py())
    return A01, A10, A11


def monolithic_matrix(K: PETSc.Mat, blocks=None) -> PETSc.Mat:
    """J as one AIJ matrix; ``K`` alone when there is no contact."""
    if blocks is None:
        return K
    A01, A10, A11 = blocks
    J = PETSc.Mat().createNest([[K, A01], [A10, A11]], comm=K.getComm())
    J.assemble()
    # petsc4py converts in place (MAT_INPLACE_MATRIX) when no output matrix is given
    J.convert("aij")
    return J
