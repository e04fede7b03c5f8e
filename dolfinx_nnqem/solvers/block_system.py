r"""The semismooth Newton matrix of the monolithic solver as PETSc objects, created once and refilled.

    J = [ K_t        −B_freeᵀ Λ' ]      u rows: equilibrium (constrained rows: identity)
        [ ∂_wH · B    ∂_zH       ]      z rows: the pair laws H(Bu + m, z) = 0

Λ' = ∂λ/∂z is the identity for the Cartesian law and the polar → Cartesian derivative for the
seed's polar law; B_free is B with the columns of constrained dofs zeroed (du = 0 there, so the
rows of constrained dofs in the u block are exactly the identity). The contact blocks have B's
sparsity (blockdiag(D) B) and a 3×3 block diagonal, all fixed over the run: every block, the
nest and its AIJ conversion are made at the first iteration and refilled in place afterwards
(PETSc then reuses its symbolic work, MUMPS's analysis included).

* :class:`MonolithicMatrix`: the direct solver's J, the nest converted to one AIJ matrix whose
  local rows are [owned u rows, owned pair rows] on every rank (the nest's layout).
* :class:`AugmentedSystem`: the iterative solver's equivalent system with the augmented u block,
  as a MatNest.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from petsc4py import PETSc

from dolfinx_nnqem.contact.geometric_stiffness import GeometricTerms
from dolfinx_nnqem.contact.pairset import PairRows, rows_matrix
from dolfinx_nnqem.contact.surface_stiffness import SurfaceTerms, stiffness_matrix

if TYPE_CHECKING:
    from dolfinx_nnqem.contact.combined_stiffness import CombinedTerms
    from dolfinx_nnqem.contact.model import ContactModel
    from dolfinx_nnqem.solvers.contract import SolvableProblem

__all__ = ["AugmentedSystem", "BlockDiagonal", "MonolithicMatrix", "free_columns", "free_rows", "weighted_rows"]


class BlockDiagonal:
    """An AIJ matrix of 3×3 blocks on the diagonal (one per owned pair), refilled in place."""

    def __init__(self, num_local: int, offset: int, num_global: int, comm):
        n = num_local
        self.indptr = np.arange(0, 9 * n + 1, 3, dtype=PETSc.IntType)
        cols = 3 * (offset + np.repeat(np.arange(n), 3))[:, None] + np.arange(3)[None, :]
        self.columns = cols.reshape(-1).astype(PETSc.IntType)
        self.matrix = PETSc.Mat().createAIJWithArrays(
            size=((3 * n, 3 * num_global), (3 * n, 3 * num_global)),
            csr=(self.indptr, self.columns, np.zeros(9 * n)), comm=comm)
        self.matrix.assemble()

    def fill(self, D: np.ndarray) -> PETSc.Mat:
        """The matrix with the blocks ``D`` (n, 3, 3)."""
        values = np.ascontiguousarray(D, dtype=np.float64).reshape(-1)
        self.matrix.setValuesCSR(self.indptr, self.columns, values)  # type: ignore[arg-type]  # petsc4py's stub asks Sequence; arrays are what it takes
        self.matrix.assemble()
        return self.matrix

    def destroy(self) -> None:
        """Free the block-diagonal matrix (collective)."""
        self.matrix.destroy()


def free_rows(model: ContactModel, free_mask: PETSc.Vec) -> PairRows:
    """B_free's rows: B's rows with the columns of constrained dofs zeroed (same sparsity).

    ``free_mask`` is laid out like V's owned dofs: 0 at constrained dofs, 1 elsewhere.
    """
    B = model.B.copy()
    B.diagonalScale(R=free_mask)
    indptr, columns, values = B.getValuesCSR()
    B.destroy()
    if not (np.array_equal(indptr, model.rows.indptr) and np.array_equal(columns, model.rows.columns)):
        raise RuntimeError("B lost entries when its constrained columns were zeroed")
    return PairRows(model.rows.indptr, model.rows.columns, values)


def free_columns(model: ContactModel, free_mask: PETSc.Vec) -> np.ndarray:
    """Per entry of B's layout: 1 if its column is a free dof, 0 if a constrained one (B's values may
    be exact zeros, so the mask is that of a matrix of ones with B's pattern)."""
    ones = PairRows(model.rows.indptr, model.rows.columns, np.ones_like(model.rows.values))
    M = rows_matrix(model.comm, ones, model.num_global, model.V.dofmap.index_map)
    M.diagonalScale(R=free_mask)
    indptr, columns, values = M.getValuesCSR()
    M.destroy()
    if not (np.array_equal(indptr, model.rows.indptr) and np.array_equal(columns, model.rows.columns)):
        raise RuntimeError("B's pattern lost entries when its constrained columns were zeroed")
    return np.asarray(values, dtype=np.float64)


def free_mask(problem: SolvableProblem) -> PETSc.Vec:
    """A vector laid out like V: 0 at the constrained dofs, 1 elsewhere (the problem has contact)."""
    assert problem.contact is not None  # the monolithic solver makes it only when problem.has_contact
    mask = problem.contact.B.createVecRight()
    mask.set(1.0)
    start, _ = mask.getOwnershipRange()
    with mask as m:  # type: ignore[attr-defined]  # petsc4py's stub lacks Vec.__enter__/__exit__; constrained_rows are global indices of owned dofs
        m[np.asarray(problem.constrained_rows(), dtype=np.int64) - start] = 0.0
    return mask


def weighted_rows(rows: np.ndarray, weights: np.ndarray | None) -> np.ndarray:
    """Σ ``rows``: each pair's rows (axis 1 of an (n, 3) or (n, 3, k) array) times its augmentation
    weights ``weights`` (n, 3); ``rows`` itself where ``weights`` is None (every weight 1)."""
    if weights is None:
        return rows
    return rows * (weights if rows.ndim == 2 else weights[:, :, None])


class _ContactBlocks:
    """A01 = B_freeᵀ M (M per pair), A10 = ∂_wH B and A11 = ∂_zH, kept and refilled.

    B_free's values are taken from the model's B at every fill: B's values change within a solve
    when the model refreshes an obstacle's geometry at every iterate (its pattern does not).
    """

    def __init__(self, model, free_mask: PETSc.Vec):
        self.model = model
        self.rows_free = free_rows(model, free_mask)
        self.column_free = free_columns(model, free_mask)
        # made at the first fill, refilled afterwards
        self._MtB: PETSc.Mat | None = None
        self.A01: PETSc.Mat | None = None
        self.A10: PETSc.Mat | None = None
        self._A11 = BlockDiagonal(model.num_local, model.offset, model.num_global, model.comm)

    def refresh_rows(self) -> None:
        """B_free's values from the model's B (same pattern)."""
        self.rows_free.values[:] = self.model.rows.values * self.column_free

    def slave_free(self, terms: GeometricTerms) -> np.ndarray:
        """(k, 3): 1 at the free dofs of the slave nodes of ``terms``' pairs, 0 at constrained ones."""
        start = self.model.rows.indptr[3 * terms.pairs]
        return self.column_free[start[:, None] + np.arange(3)]  # row n of the pair: its 3 columns

    def combined_free(self, terms: CombinedTerms) -> np.ndarray:
        """(nnz, 3): 1 at the free dofs of the nodes that ``terms``' pairs combine, 0 at constrained ones."""
        return terms.free_in(self.column_free, self.model.rows)

    def pair_free(self, pairs: np.ndarray, c: int) -> np.ndarray:
        """(k, c): 1 at the free columns of the local pairs ``pairs`` (each with c columns), 0 at constrained ones."""
        start = self.model.rows.indptr[3 * np.asarray(pairs, dtype=np.int64)]
        return self.column_free[start[:, None] + np.arange(c)]

    def fill(self, M: np.ndarray, dH_dw: np.ndarray, dH_dz: np.ndarray,
             B_values: np.ndarray | None = None) -> tuple[PETSc.Mat, PETSc.Mat, PETSc.Mat]:
        """The three blocks for the per-pair matrices M (A01 = B_freeᵀ M), ∂H/∂w and ∂H/∂z;
        ``B_values``: the values of the rows A10 scales in B's layout (B + W), default B's."""
        model = self.model
        self.refresh_rows()
        # Bᵀ M = (Mᵀ B)ᵀ, and Mᵀ B has B's sparsity
        values = self.rows_free.scaled(np.ascontiguousarray(np.transpose(M, (0, 2, 1))))
        if self._MtB is None:
            self._MtB = rows_matrix(model.comm, self.rows_free, model.num_global, model.V.dofmap.index_map, values)
            self.A01 = self._MtB.transpose(PETSc.Mat())
        else:
            self._MtB.setValuesCSR(self.rows_free.indptr, self.rows_free.columns, values)  # type: ignore[arg-type]  # as in BlockDiagonal.fill
            self._MtB.assemble()
            self._MtB.transpose(self.A01)  # MAT_REUSE_MATRIX
        self.A10 = model.scaled_B(dH_dw, out=self.A10, values=B_values)
        assert self.A01 is not None  # made with _MtB
        return self.A01, self.A10, self._A11.fill(dH_dz)

    def destroy(self) -> None:
        for m in (self._MtB, self.A01, self.A10):
            if m is not None:
                m.destroy()
        self._A11.destroy()


class MonolithicMatrix:
    """The direct solver's Newton matrix J as one AIJ matrix, refilled every iteration.

    Parameters
    ----------
    model
        The contact model.
    free_mask
        0 at constrained dofs, 1 elsewhere (laid out like V).
    """

    def __init__(self, model, free_mask: PETSc.Vec):
        self._blocks = _ContactBlocks(model, free_mask)
        self._nest: PETSc.Mat | None = None  # made at the first assemble, refilled afterwards
        self._K: PETSc.Mat | None = None  # the u block of the nest
        self.J: PETSc.Mat | None = None

    def slave_free(self, terms: GeometricTerms) -> np.ndarray:
        """(k, 3): 1 at the free dofs of the slave nodes of ``terms``' pairs."""
        return self._blocks.slave_free(terms)

    def combined_blocks(self, terms: GeometricTerms) -> tuple[np.ndarray, None] | None:
        """(free, None) for ``terms``' pairs that combine nodes (:meth:`GeometricTerms.add_to_tangent`:
        1 at their nodes' free dofs, no extra block), or None if it has none."""
        return None if terms.combined is None else (self._blocks.combined_free(terms.combined), None)

    def pair_free(self, pairs: np.ndarray, c: int) -> np.ndarray:
        """(k, c): 1 at the free columns of the local pairs ``pairs`` (each with c columns), 0 at constrained ones."""
        return self._blocks.pair_free(pairs, c)

    def assemble(self, K: PETSc.Mat, dH_dw: np.ndarray, dH_dz: np.ndarray, dlam_dz: np.ndarray,
                 B_values: np.ndarray | None = None, new_pattern: bool = False) -> PETSc.Mat:
        """J at the current law evaluation; ``K`` is the tangent, assembled into the same matrix each time
        (with the geometric blocks already added, if any); ``B_values``: B + W for the pair rows;
        ``new_pattern``: K is another matrix than last time, with its own pattern (the tangent with
        node-to-surface geometric blocks, which couple the two bodies): J is made anew."""
        A01, A10, A11 = self._blocks.fill(-dlam_dz, dH_dw, dH_dz, B_values)
        if new_pattern or (self._nest is not None and K is not self._K):
            for m in (self._nest, self.J):
                if m is not None:
                    m.destroy()
            self._nest = self.J = None
        if self._nest is None:
            self._K = K
            self._nest = PETSc.Mat().createNest([[K, A01], [A10, A11]], comm=K.getComm())
        self._nest.assemble()
        if self.J is None:
            self.J = self._nest.convert("aij", out=PETSc.Mat())
        else:
            self._nest.convert("aij", out=self.J)  # MAT_REUSE_MATRIX: the same pattern, new values
        return self.J

    def destroy(self) -> None:
        """Free the blocks, the nest and the Newton matrix (collective)."""
        self._blocks.destroy()
        for m in (self._nest, self.J):
            if m is not None:
                m.destroy()


class AugmentedSystem:
    """The Newton system with its u rows augmented, for the iterative solver.

    Adding Bᵀ W times the pair rows to the u rows (W_i = c D_wᵢᵀ Σᵢ², c = ``augmentation`` / r,
    D_w = ∂_wH, Σᵢ the diagonal of the pair's row weights, ``weights``: 1 by default) gives the
    equivalent system

        [ K_t + Bᵀ P B    Bᵀ (−Λ' + c D_wᵀ Σ² D_z) ] [du]     [ R + c Bᵀ D_wᵀ Σ² H ]
        [ D_w B           D_z                       ] [dz] = − [ H                  ],

    P = c D_wᵀ Σ² D_w (per pair, symmetric positive semidefinite), D_z = ∂_zH. It has the same
    solution, but its u block is the stiffness plus a penalty of order ``augmentation`` · r on
    every closed pair direction: positive definite even for a body held only by contact, and
    a good fit for AMG, while the pair-block Schur complement becomes close to diagonal (the
    augmented-Lagrangian preconditioning idea). A row that does not constrain the relative
    displacement (the polar law's slip-direction row where θ turns with the slip) gets a
    weight below 1 from its law (:attr:`~dolfinx_nnqem.contact.laws.Linearisation.augmentation`):
    at weight 1 its penalty is a stiffness that the Schur complement has to take back, which
    the ``selfp`` approximation cannot. B here has its constrained columns zeroed
    (B_free): du = 0 at constrained dofs, so the system is unchanged, and the u block stays
    symmetric with identity rows and columns there.

    The matrix is a MatNest (no copy of K into one AIJ matrix), laid out like the direct
    solver's: on every rank the owned u rows, then the owned pair rows. The u block is K's own
    matrix, widened once to K's pattern plus the 6×6 couplings of all pairs and kept so over
    the iterations: no second copy of K, and PETSc reuses its symbolic work. With several
    interfaces, c = ``augmentation`` / max r.

    Node-to-surface and mortar pairs in the consistent current geometry
    (:mod:`~dolfinx_nnqem.contact.surface_stiffness`) have rows B + W and forces whose derivative
    at fixed λ is K (:meth:`surface_blocks`): the u block is then K_t − K + Bᵀ P (B + W)_free
    (the augmentation of rows B + W), and A10 scales B + W. K and Bᵀ P W couple only columns of
    one pair, each pair's columns being its row's in B: they fall in the widened pattern.
    """

    def __init__(self, model, free_mask: PETSc.Vec, r: float, augmentation: float):
        self.model = model
        self.c = augmentation / r
        self._mask = free_mask
        rows = free_rows(model, free_mask)
        self.B_free = rows_matrix(model.comm, rows, model.num_global, model.V.dofmap.index_map)
        self._blocks = _ContactBlocks(model, free_mask)
        self._P = BlockDiagonal(model.num_local, model.offset, model.num_global, model.comm)
        # made at the first matrix, refilled afterwards
        self._BtPB: PETSc.Mat | None = None
        self._nest: PETSc.Mat | None = None
        self._g = model.create_lambda_vector()
        self._Btg = self.B_free.createVecRight()
        self._b: PETSc.Vec | None = None  # the right-hand side, created once (the nest's layout is fixed)
        self.A00: PETSc.Mat | None = None  # K, widened at the first matrix
        # node-to-surface and mortar pairs' W, P W and B_freeᵀ P W (made at the first use, refilled afterwards)
        self._W: PETSc.Mat | None = None
        self._PW: PETSc.Mat | None = None
        self._BtPW: PETSc.Mat | None = None

    def _u_block(self, K: PETSc.Mat, dH_dw: np.ndarray,
                 surface: tuple[PETSc.Mat, np.ndarray] | None = None) -> PETSc.Mat:
        """K + B_freeᵀ P B_free, added in place to ``K``; with ``surface`` = (G, W_free) of
        :meth:`surface_blocks` also − G + B_freeᵀ P W_free.

        The first call widens K's sparsity to include the pair couplings (K then keeps that
        pattern: the caller assembles the next tangent into the same matrix, whose extra
        entries are zeroed by the assembly), so there is never a second copy of K.
        """
        P = self._P.fill(self.c * np.einsum("nki,nkj->nij", dH_dw, dH_dw))
        if self._BtPB is None:
            self._BtPB = P.PtAP(self.B_free)
        else:
            P.PtAP(self.B_free, self._BtPB)
        if self.A00 is None:
            lgmap = K.getLGMap()  # the new pattern comes without DOLFINx's local-to-global maps
            K.axpy(1.0, self._BtPB, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)  # type: ignore[arg-type]  # petsc4py's stub types the Structure constants as int
            K.setLGMap(*lgmap)
            self.A00 = K
        elif K is not self.A00:
            raise ValueError("AugmentedSystem: assemble the tangent into the matrix returned before")
        else:
            K.axpy(1.0, self._BtPB, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)  # type: ignore[arg-type]  # as above
        if surface is not None:
            self._add_surface_blocks(K, P, *surface)
        return K

    def _add_surface_blocks(self, K: PETSc.Mat, P: PETSc.Mat, G: PETSc.Mat, W_free: np.ndarray) -> None:
        """K − G + B_freeᵀ P W_free in place (both on the pairs' columns, in K's widened pattern; PETSc
        checks that and widens it if need be, the local-to-global maps kept)."""
        rows = self.model.rows
        if self._W is None:  # made at the first use, refilled afterwards (B's pattern is this system's)
            self._W = rows_matrix(self.model.comm, PairRows(rows.indptr, rows.columns, W_free), self.model.num_global,
                                  self.model.V.dofmap.index_map)
            self._PW = P.matMult(self._W)
            self._BtPW = self.B_free.transposeMatMult(self._PW)
        else:
            assert self._PW is not None and self._BtPW is not None  # (made with _W)
            self._W.setValuesCSR(rows.indptr, rows.columns, W_free)  # type: ignore[arg-type]  # as in BlockDiagonal.fill
            self._W.assemble()
            P.matMult(self._W, self._PW)  # MAT_REUSE_MATRIX
            self.B_free.transposeMatMult(self._PW, self._BtPW)
        lgmap = K.getLGMap()
        unknown = PETSc.Mat.Structure.UNKNOWN_NONZERO_PATTERN
        K.axpy(-1.0, G, structure=unknown)  # type: ignore[arg-type]  # as above
        K.axpy(1.0, self._BtPW, structure=unknown)  # type: ignore[arg-type]  # as above
        K.setLGMap(*lgmap)

    def surface_blocks(self, terms: list[SurfaceTerms], K: PETSc.Mat, B_values: np.ndarray | None
                       ) -> tuple[np.ndarray, PETSc.Mat, np.ndarray]:
        """(B + W, G, W_free) of the node-to-surface and mortar pairs' geometric ``terms`` (collective):
        the pair rows' values with W added (``B_values``: the rows' values so far, with an obstacle's W;
        default B's), G the pairs' blocks K laid out like the tangent ``K`` (constrained rows and columns
        left out), and W alone in B's layout with its constrained columns zeroed."""
        rows = self.model.rows
        W = np.zeros_like(rows.values)
        for part in terms:
            part.add_rows(W, rows)
        G = stiffness_matrix(terms, [self._blocks.pair_free(t.pairs, t.columns.shape[1]) for t in terms], K)
        base = rows.values if B_values is None else B_values
        return base + W, G, W * self._blocks.column_free

    def slave_free(self, terms: GeometricTerms) -> np.ndarray:
        """(k, 3): 1 at the free dofs of the slave nodes of ``terms``' pairs."""
        return self._blocks.slave_free(terms)

    def augmented_geometric_blocks(self, terms: GeometricTerms, dH_dw: np.ndarray,
                                   weights: np.ndarray | None = None) -> np.ndarray:
        """(k, 3, 3) c B_fᵀ D_wᵀ D_w W of each pair of ``terms``: the augmentation of the rows' geometric
        part W (the u block gets c B_freeᵀ D_wᵀ × the pair rows D_w (B + W) du + D_z dz = −H; its
        c Bᵀ P B part is :meth:`_u_block`'s). On the slave node alone: B_f and W have its columns only."""
        self._blocks.refresh_rows()
        start = self.model.rows.indptr[3 * terms.pairs]
        B_f = self._blocks.rows_free.values[start[:, None] + np.arange(9)].reshape(-1, 3, 3)
        D = weighted_rows(dH_dw, weights)[terms.pairs]
        return self.c * np.einsum("kri,kqr,kqs,ksj->kij", B_f, D, D, terms.W)

    def combined_blocks(self, terms: GeometricTerms, dH_dw: np.ndarray, weights: np.ndarray | None = None
                        ) -> tuple[np.ndarray, list[np.ndarray]] | None:
        """(free, extra) for ``terms``' pairs that combine nodes (:meth:`GeometricTerms.add_to_tangent`: 1 at
        their nodes' free dofs, and :meth:`augmented_combined_blocks`), or None if it has none."""
        if terms.combined is None:
            return None
        return (self._blocks.combined_free(terms.combined),
                self.augmented_combined_blocks(terms.combined, weighted_rows(dH_dw, weights)))

    def augmented_combined_blocks(self, terms: CombinedTerms, dH_dw: np.ndarray) -> list[np.ndarray]:
        """Per pair of ``terms`` (pairs that combine nodes), c B_fᵀ D_wᵀ D_w W on its nodes: what
        :meth:`augmented_geometric_blocks` is for a pair on one node."""
        self._blocks.refresh_rows()
        return terms.augmentation(self._blocks.rows_free.values, self.model.rows, dH_dw, self.c)

    def matrix(self, K: PETSc.Mat, dH_dw: np.ndarray, dH_dz: np.ndarray, dlam_dz: np.ndarray,
               B_values: np.ndarray | None = None, surface: tuple[PETSc.Mat, np.ndarray] | None = None,
               weights: np.ndarray | None = None) -> PETSc.Mat:
        """The augmented Newton matrix (MatNest) at the current law evaluation (``K`` with the
        obstacles' geometric blocks already added, if any; ``B_values``: B + W for the pair rows;
        ``surface``: (G, W_free) of the node-to-surface and mortar pairs, :meth:`surface_blocks`;
        ``weights``: the pair rows' weights Σ in the augmentation, (n, 3), or None: all 1)."""
        self._blocks.refresh_rows()
        rows = self._blocks.rows_free
        self.B_free.setValuesCSR(rows.indptr, rows.columns, rows.values)  # type: ignore[arg-type]  # as in BlockDiagonal.fill
        self.B_free.assemble()
        D_w, D_z = weighted_rows(dH_dw, weights), weighted_rows(dH_dz, weights)  # Σ D_w, Σ D_z
        A00 = self._u_block(K, D_w, surface)
        M = -dlam_dz + self.c * np.einsum("nki,nkj->nij", D_w, D_z)
        A01, A10, A11 = self._blocks.fill(M, dH_dw, dH_dz, B_values)
        if self._nest is None:
            self._nest = PETSc.Mat().createNest([[A00, A01], [A10, A11]], comm=K.getComm())
        self._nest.assemble()
        return self._nest

    def rhs(self, R_free: PETSc.Vec, H: np.ndarray, dH_dw: np.ndarray, weights: np.ndarray | None = None) -> PETSc.Vec:
        """−(R + c B_freeᵀ D_wᵀ Σ² H, H) in the nest's layout (a plain vector, the same one each call)."""
        D_w, H_weighted = weighted_rows(dH_dw, weights), weighted_rows(H, weights)
        self._g.getArray()[:] = np.einsum("nki,nk->ni", D_w, H_weighted).reshape(-1)
        self.B_free.multTranspose(self._g, self._Btg)
        n_u = R_free.getLocalSize()
        if self._b is None:
            self._b = PETSc.Vec().createMPI((n_u + H.size, PETSc.DECIDE), comm=R_free.getComm())
        b = self._b
        arr = b.getArray()
        arr[:n_u] = -R_free.getArray(readonly=True) - self.c * self._Btg.getArray(readonly=True)
        arr[n_u:] = -H.reshape(-1)
        return b

    def destroy(self) -> None:
        """Free the blocks, B_free, the nest and the work vectors (collective)."""
        self._blocks.destroy()
        self._P.destroy()
        for m in (self.B_free, self._BtPB, self._nest, self._g, self._Btg, self._b, self._W, self._PW, self._BtPW):
            if m is not None:
                m.destroy()
