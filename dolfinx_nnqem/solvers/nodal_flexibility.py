r"""The contact flexibility from the unit loads of the dofs the pairs touch (issue 43).

NNEQM1 condenses the displacement onto the pairs with C = B G Bᵀ (``formulation.md`` §5,
:mod:`~dolfinx_nnqem.solvers.condensation`). Every column of Bᵀ lives on the few dofs D that
B's rows touch (an obstacle pair: its slave node's three dofs), so

    Bᵀ = E_D B_Dᵀ,   G Bᵀ = Y B_Dᵀ,   C = B_D S B_Dᵀ,   with  Y = G E_D,  S = E_Dᵀ G E_D,

E_D the unit loads of the dofs D (|D| columns) and B_D B's columns at D (a small matrix, gathered
on every rank). Y and S depend on the factorised stiffness only, not on the contact geometry:
where the pairs' frames and gaps move with the bodies (current geometry) B_D changes at every
evaluation, but Y is computed once per factorisation, and when D grows (a node-to-surface pair
onto a new master facet) only the new dofs' columns are solved for.

The same unit loads give the geometric stiffness of current-geometry obstacles
(:mod:`~dolfinx_nnqem.contact.geometric_stiffness`) without another factorisation: the Newton
matrix's u block is K_t − E_A K_g E_Aᵀ, K_g the pairs' 3 × 3 blocks K_s on the dofs A of the
slave nodes that carry a force (A ⊂ D), and by the Sherman–Morrison–Woodbury identity

    (K − E_A K_g E_Aᵀ)⁻¹ E_D = Y + Y_A M⁻¹ K_g S_AD,   M = I − K_g S_AA,

so the flexibility of the consistent linearisation is C = (B_D + W_D) S_g B_Dᵀ with
S_g = S + S_DA M⁻¹ K_g S_AD (order |A|, the pressed pairs' dofs), W the pairs' geometric rows
(the slip measured in a frame that turns).

Every rank holds D, S, B_D and the dense algebra (the same data, the same decisions); Y has the
owned rows of the displacement.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse
from petsc4py import PETSc

from dolfinx_nnqem.contact.geometric_stiffness import GeometricTerms
from dolfinx_nnqem.solvers.condensation import Condensation

__all__ = ["GeometricUpdate", "NodalFlexibility", "pair_dofs", "rows_on_dofs"]


def pair_dofs(model, zero_rows: np.ndarray) -> np.ndarray:
    """D: the global dofs that B's rows touch, constrained and fixing dofs left out (collective;
    sorted, the same on every rank). ``zero_rows``: this rank's constrained and fixing rows."""
    comm = model.comm
    columns = np.unique(np.concatenate(comm.allgather(np.unique(model.rows.columns).astype(np.int64))))
    zero = np.concatenate(comm.allgather(np.asarray(zero_rows, dtype=np.int64)))
    return np.setdiff1d(columns, zero)


def rows_on_dofs(model, values: np.ndarray, dofs: np.ndarray) -> scipy.sparse.csr_matrix:
    """The rows of all pairs (3NC, |D|) with the CSR ``values`` (laid out like ``model.rows``) at
    their columns in ``dofs`` (D, sorted); columns outside D (constrained dofs) are dropped
    (collective)."""
    rows = model.rows
    counts = np.diff(rows.indptr)
    row_of = np.repeat(np.arange(3 * model.num_local), counts) + 3 * model.offset
    position = np.searchsorted(dofs, rows.columns)
    inside = position < len(dofs)
    inside[inside] = dofs[position[inside]] == rows.columns[inside]
    parts = model.comm.allgather((row_of[inside], position[inside], np.asarray(values)[inside]))
    r, c, v = (np.concatenate([part[k] for part in parts]) for k in range(3))
    return scipy.sparse.csr_matrix((v, (r, c)), shape=(3 * model.num_global, len(dofs)))


@dataclass
class GeometricUpdate:
    """The Woodbury correction of the geometric stiffness on the pressed slave nodes' dofs A.

    Attributes
    ----------
    A
        (|A|,) positions of the dofs A among the pairs' dofs D (:func:`pair_dofs`).
    Kg
        (|A|, |A|) the blocks K_s on A (block diagonal).
    lu
        The LU factors of M = I − K_g S_AA.
    """

    A: np.ndarray
    Kg: np.ndarray
    lu: tuple

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """M⁻¹ K_g ``rhs`` (``rhs``: |A| rows)."""
        return scipy.linalg.lu_solve(self.lu, self.Kg @ rhs)


class NodalFlexibility:
    """Y = G E_D and S = E_Dᵀ G E_D for the current factorisation of a :class:`Condensation`.

    Parameters
    ----------
    condensation
        The factorised stiffness (no free rigid modes: the Woodbury update needs G = K⁻¹).
    """

    def __init__(self, condensation: Condensation):
        self.condensation = condensation
        self.model = condensation.problem.contact
        imap = condensation.problem.V.dofmap.index_map
        self._start = 3 * imap.local_range[0]
        self._n_owned = 3 * imap.size_local
        self.dofs = np.zeros(0, dtype=np.int64)  #: D, the dofs whose columns are held
        self.Y = np.zeros((self._n_owned, 0))  #: G E_D, owned rows
        self.S = np.zeros((0, 0))  #: E_Dᵀ G E_D, on every rank
        self._factorisation = -1  # the condensation's factorisation the columns belong to
        self.columns_solved = 0  #: unit-load columns solved for, over the run

    def update(self) -> np.ndarray:
        """Bring Y and S to the current factorisation and the pairs' dofs; returns D's positions
        of the pairs' dofs (:func:`pair_dofs`) in :attr:`dofs` (collective)."""
        c = self.condensation
        wanted = pair_dofs(self.model, c.zero_rows)
        if self._factorisation != c.factorisations:
            self.dofs, self.Y, self._factorisation = np.zeros(0, dtype=np.int64), self.Y[:, :0], c.factorisations
        new = np.setdiff1d(wanted, self.dofs)
        if len(new):
            t0 = time.perf_counter()
            self.Y = np.hstack([self.Y, self._unit_load_columns(new)])
            self.dofs = np.concatenate([self.dofs, new])
            self.S = self._rows_at(self.dofs)
            self.columns_solved += len(new)
            c.timings.add("flexibility", t0)
        order = np.argsort(self.dofs)
        return order[np.searchsorted(self.dofs[order], wanted)]

    def _unit_load_columns(self, dofs: np.ndarray) -> np.ndarray:
        """G E for the unit loads of the global ``dofs`` (owned rows, (n_u, len(dofs)))."""
        c = self.condensation
        E = PETSc.Mat().createDense(((self._n_owned, None), (None, len(dofs))), comm=c.problem.comm)
        E.setUp()
        values = E.getDenseArray()
        values[:] = 0.0
        owned = (dofs >= self._start) & (dofs < self._start + self._n_owned)
        values[dofs[owned] - self._start, np.flatnonzero(owned)] = 1.0
        E.assemble()
        Y = E.duplicate()
        c.ksp.matSolve(E, Y)
        out = Y.getDenseArray().copy()
        E.destroy()
        Y.destroy()
        return out

    def _rows_at(self, dofs: np.ndarray) -> np.ndarray:
        """The rows of Y at the global ``dofs``, gathered on every rank (len(dofs), |D|)."""
        owned = (dofs >= self._start) & (dofs < self._start + self._n_owned)
        comm = self.condensation.problem.comm
        rows = comm.allgather((np.flatnonzero(owned), self.Y[dofs[owned] - self._start]))
        S = np.zeros((len(dofs), self.Y.shape[1]))
        for index, values in rows:
            S[index] = values
        return S

    def values_at(self, x: PETSc.Vec, positions: np.ndarray) -> np.ndarray:
        """The entries of ``x`` (laid out like V) at the dofs ``self.dofs[positions]``, on every rank."""
        dofs = self.dofs[positions]
        owned = (dofs >= self._start) & (dofs < self._start + self._n_owned)
        array = x.getArray(readonly=True)
        parts = self.condensation.problem.comm.allgather((np.flatnonzero(owned), array[dofs[owned] - self._start]))
        out = np.zeros(len(dofs))
        for index, values in parts:
            out[index] = values
        return out

    def geometric_update(self, terms: GeometricTerms, positions: np.ndarray) -> GeometricUpdate | None:
        """The Woodbury correction of the obstacle pairs' geometric blocks ``terms`` (None where no
        pair carries a force); ``positions``: D's positions in :attr:`dofs` (:meth:`update`).

        The blocks are gathered; a slave node's dof outside D (constrained) drops out, as in the
        monolithic solver, which keeps the identity rows of constrained dofs (collective)."""
        if terms.combined is not None:
            return self._combined_update(terms, positions)
        comm = self.condensation.problem.comm
        pressed = np.any(terms.K != 0.0, axis=(1, 2))
        dofs = np.concatenate(comm.allgather(terms.slave_dofs()[pressed].reshape(-1).astype(np.int64)))
        blocks = np.concatenate(comm.allgather(terms.K[pressed].reshape(-1, 3, 3)))
        if len(blocks) == 0:
            return None
        D = self.dofs[positions]  # sorted (pair_dofs)
        where = np.minimum(np.searchsorted(D, dofs), len(D) - 1)
        inside = D[where] == dofs
        Kg = scipy.linalg.block_diag(*blocks) * np.outer(inside, inside)
        S_AA = self.S[np.ix_(positions[where], positions[where])]
        return GeometricUpdate(where, Kg, scipy.linalg.lu_factor(np.eye(len(where)) - Kg @ S_AA))

    def _combined_update(self, terms: GeometricTerms, positions: np.ndarray) -> GeometricUpdate | None:
        """:meth:`geometric_update` with pairs that combine nodes (P2 tetrahedra): a pair's block
        (a aᵀ) ⊗ K_i couples its nodes, and a node belongs to several pairs, so K_g is summed on the
        union A of the pressed pairs' dofs (collective)."""
        assert terms.combined is not None  # the caller's branch
        pressed = np.any(terms.K != 0.0, axis=(1, 2))
        local = [(dofs, block) for dofs, block in zip(terms.slave_dofs()[pressed], terms.K[pressed])]
        local += [(dofs, block) for dofs, block in terms.combined.node_blocks() if np.any(block != 0.0)]
        gathered = [part for parts in self.condensation.problem.comm.allgather(local) for part in parts]
        if not gathered:
            return None
        all_dofs = np.unique(np.concatenate([dofs for dofs, _ in gathered]))
        D = self.dofs[positions]  # sorted (pair_dofs)
        inside = all_dofs[np.isin(all_dofs, D)]  # a constrained dof drops out, as in the monolithic solver
        if len(inside) == 0:
            return None
        Kg = np.zeros((len(inside), len(inside)))
        for dofs, block in gathered:
            keep = np.isin(dofs, inside)
            at = np.searchsorted(inside, dofs[keep])
            Kg[np.ix_(at, at)] += block[np.ix_(keep, keep)]
        where = np.searchsorted(D, inside)
        S_AA = self.S[np.ix_(positions[where], positions[where])]
        return GeometricUpdate(where, Kg, scipy.linalg.lu_factor(np.eye(len(where)) - Kg @ S_AA))

    def flexibility(self, positions: np.ndarray, B_D, Bc_D, update: GeometricUpdate | None) -> np.ndarray:
        """C = (B + W)_D S_g B_Dᵀ (3NC, 3NC): ``B_D`` and ``Bc_D`` the pairs' rows and their consistent
        rows B + W on D (:func:`rows_on_dofs`), S_g the nodal flexibility with the geometric
        stiffness (module docstring; S without ``update``)."""
        S = self.S[np.ix_(positions, positions)]
        if update is not None:
            S = S + S[:, update.A] @ update.solve(S[update.A])
        return np.asarray((B_D @ (Bc_D @ S).T).T)

    def free_response(self, x_r: PETSc.Vec, positions: np.ndarray, update: GeometricUpdate | None
                      ) -> tuple[np.ndarray, np.ndarray]:
        """(x, x_D): x = (K − E_A K_g E_Aᵀ)⁻¹ r from x_r = G r (owned rows), and x at D (every rank)."""
        x = x_r.getArray(readonly=True).copy()
        x_D = self.values_at(x_r, positions)
        if update is not None:
            a = update.solve(x_D[update.A])
            x += self.Y @ self._on_columns(positions[update.A], a)
            x_D += self.S[np.ix_(positions, positions[update.A])] @ a
        return x, x_D

    def response(self, v: np.ndarray, positions: np.ndarray, update: GeometricUpdate | None) -> np.ndarray:
        """(K − E_A K_g E_Aᵀ)⁻¹ E_D ``v`` (owned rows), ``v`` (|D|,) loads on the pairs' dofs."""
        loads = self._on_columns(positions, v)
        if update is not None:
            A = positions[update.A]
            loads += self._on_columns(A, update.solve(self.S[np.ix_(A, positions)] @ v))
        return self.Y @ loads  # one product with Y as it is: selecting its columns would copy it

    def _on_columns(self, columns: np.ndarray, values: np.ndarray) -> np.ndarray:
        """A vector over Y's columns with ``values`` added at ``columns``, zero elsewhere."""
        out = np.zeros(self.Y.shape[1])
        np.add.at(out, columns, values)
        return out
