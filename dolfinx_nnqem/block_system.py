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


class AugmentedSystem:
    """The Newton system with its u rows augmented, for the iterative solver.

    Adding Bᵀ W times the pair rows to the u rows (W_i = c D_wᵢᵀ, c = ``augmentation`` / r,
    D_w = ∂_wH) gives the equivalent system

        [ K_t + Bᵀ P B    Bᵀ (−Λ' + c D_wᵀ D_z) ] [du]     [ R + c Bᵀ D_wᵀ H ]
        [ D_w B           D_z                    ] [dz] = − [ H               ],

    P = c D_wᵀ D_w (per pair, symmetric positive semidefinite), D_z = ∂_zH. It has the same
    solution, but its u block is the stiffness plus a penalty of order ``augmentation`` · r on
    every closed pair direction: positive definite even for a body held only by contact, and
    a good fit for AMG, while the pair-block Schur complement becomes close to diagonal (the
    augmented-Lagrangian preconditioning idea). B here has its constrained columns zeroed
    (B_free): du = 0 at constrained dofs, so the system is unchanged, and the u block stays
    symmetric with identity rows and columns there.

    The matrix is a MatNest (no copy of K into one AIJ matrix), laid out like the direct
    solver's: on every rank the owned u rows, then the owned pair rows. The u block is K's own
    matrix, widened once to K's pattern plus the 6×6 couplings of all pairs and kept so over
    the iterations: no second copy of K, and PETSc reuses its symbolic work.
    """

    def __init__(self, pairs, constrained_rows: np.ndarray, r: float, augmentation: float):
        self.pairs = pairs
        self.c = augmentation / r
        B = pairs.B
        mask = B.createVecRight()
        mask.set(1.0)
        start, _ = mask.getOwnershipRange()
        with mask as m:  # constrained_rows are global indices of owned dofs
            m[np.asarray(constrained_rows, dtype=np.int64) - start] = 0.0
        self._mask = mask
        self.B_free = B.copy()
        self.B_free.diagonalScale(R=mask)
        self.Bt_free = self.B_free.transpose(PETSc.Mat())
        n = pairs.num_local
        self._P = block_diagonal_matrix(np.zeros((n, 3, 3)), pairs.offset, pairs.num_global,
                                        pairs.comm)
        self._csr = self._P.getValuesCSR()[:2]
        self._BtPB = None
        self.A00 = None

    def _u_block(self, K: PETSc.Mat, dH_dw: np.ndarray) -> PETSc.Mat:
        """K + B_freeᵀ P B_free, added in place to ``K``.

        The first call widens K's sparsity to include the pair couplings (K then keeps that
        pattern: the caller assembles the next tangent into the same matrix, whose extra
        entries are zeroed by the assembly), so there is never a second copy of K.
        """
        P = self.c * np.einsum("nki,nkj->nij", dH_dw, dH_dw)
        self._P.setValuesCSR(*self._csr, np.ascontiguousarray(P.reshape(-1)))
        self._P.assemble()
        if self._BtPB is None:
            self._BtPB = self._P.PtAP(self.B_free)
        else:
            self._P.PtAP(self.B_free, self._BtPB)
        if self.A00 is None:
            lgmap = K.getLGMap()  # the new pattern comes without DOLFINx's local-to-global maps
            K.axpy(1.0, self._BtPB, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
            K.setLGMap(*lgmap)
            self.A00 = K
        elif K is not self.A00:
            raise ValueError("AugmentedSystem: assemble the tangent into the matrix returned before")
        else:
            K.axpy(1.0, self._BtPB, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        return K

    def matrix(self, K: PETSc.Mat, dH_dw: np.ndarray, dH_dz: np.ndarray,
               dlam_dz: np.ndarray) -> PETSc.Mat:
        """The augmented Newton matrix (MatNest) at the current law evaluation."""
        pairs = self.pairs
        A00 = self._u_block(K, dH_dw)
        # A01 = B_freeᵀ M, M = −Λ' + c D_wᵀ D_z; Bᵀ Mᵀᵀ = (Mᵀ B)ᵀ has B's sparsity
        M = -dlam_dz + self.c * np.einsum("nki,nkj->nij", dH_dw, dH_dz)
        A01 = pairs.scaled_B(np.ascontiguousarray(np.transpose(M, (0, 2, 1))))
        A01.diagonalScale(R=self._mask)
        A01.transpose()  # in place
        A10 = pairs.scaled_B(dH_dw)
        A11 = block_diagonal_matrix(dH_dz, pairs.offset, pairs.num_global, pairs.comm)
        J = PETSc.Mat().createNest([[A00, A01], [A10, A11]], comm=K.getComm())
        J.assemble()
        return J

    def rhs(self, R_free: PETSc.Vec, H: np.ndarray, dH_dw: np.ndarray) -> PETSc.Vec:
        """−(R + c B_freeᵀ D_wᵀ H, H) in the nest's layout (a plain vector)."""
        g = self.pairs.create_lambda_vector()
        g.getArray()[:] = np.einsum("nki,nk->ni", dH_dw, H).reshape(-1)
        Btg = self.B_free.createVecRight()
        self.B_free.multTranspose(g, Btg)
        n_u = R_free.getLocalSize()
        b = PETSc.Vec().createMPI((n_u + H.size, PETSc.DECIDE), comm=R_free.getComm())
        arr = b.getArray()
        arr[:n_u] = -R_free.getArray(readonly=True) - self.c * Btg.getArray(readonly=True)
        arr[n_u:] = -H.reshape(-1)
        return b
