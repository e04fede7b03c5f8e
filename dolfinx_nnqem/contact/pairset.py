r"""The pair-set contract: what the contact model needs from a discretisation of an interface.

``formulation.md`` §2b: whatever the discretisation (node-to-node, rigid obstacle, node-to-
surface, dual mortar), an interface is a set of pairs j, each with

* a local frame R_j (rows n_j, t1_j, t2_j) and an initial gap g0_j,
* three rows of B such that the relative displacement in the frame is
  w_j = (B u)_j + m_j(ℓ), with m_j(ℓ) a known motion of the master side (a moving rigid
  obstacle; zero otherwise),
* an owner: the rank that owns the pair's slave node,
* a tributary area A_j of the slave node (∫ N_j dA over the slave surface; D_jj of dual
  mortar), which turns the pair force into a contact pressure p_n / A_j.

The pair force λ_j = (p_n, q1, q2) acts on the slave side; the global nodal force is Bᵀλ. The
laws and the solvers see nothing else, so a new discretisation is a new :class:`PairSet`
implementation and nothing more.

B's rows are given as :class:`PairRows`: the three rows of a pair share one sorted set of
columns (3 components of each node the pair involves), so any number of nodes per row works
(2 for node-to-node, 1 for an obstacle, 1 + the master facet's nodes for node-to-surface).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

if TYPE_CHECKING:
    import dolfinx

__all__ = ["PairRows", "PairSet", "rows_matrix"]


@dataclass(frozen=True, eq=False)
class PairRows:
    """The local rows of B, three per pair, in CSR form.

    Pair i owns rows 3i, 3i + 1, 3i + 2 (its normal, t1 and t2 components of w), and the three
    rows have the same columns in the same (ascending) order. Columns are global indices
    3 × (dof block) + component, laid out like V's dofs.

    Attributes
    ----------
    indptr
        (3 n + 1,) row pointers.
    columns
        (nnz,) global column indices, ascending within each row.
    values
        (nnz,) entries of B.
    """

    indptr: np.ndarray
    columns: np.ndarray
    values: np.ndarray

    @classmethod
    def from_blocks(cls, columns: np.ndarray, blocks: np.ndarray) -> PairRows:
        """Rows of pairs that all involve the same number m of columns.

        Parameters
        ----------
        columns
            (n, m) global columns of each pair (any order; they are sorted here).
        blocks
            (n, 3, m) the pair's 3 × m block of B, in the order of ``columns``.
        """
        columns = np.asarray(columns, dtype=np.int64)
        blocks = np.asarray(blocks, dtype=np.float64)
        n, m = columns.shape
        order = np.argsort(columns, axis=1, kind="stable")
        columns = np.take_along_axis(columns, order, axis=1)
        blocks = np.take_along_axis(blocks, order[:, None, :], axis=2)
        return cls(
            np.arange(0, 3 * n * m + 1, m, dtype=PETSc.IntType),
            np.repeat(columns, 3, axis=0).reshape(-1).astype(PETSc.IntType),
            blocks.reshape(-1).copy(),
        )

    @classmethod
    def from_weighted_nodes(cls, R: np.ndarray, nodes_indptr: np.ndarray, nodes: np.ndarray,
                            coefficients: np.ndarray) -> PairRows:
        """Rows w_i = R_i Σ_k a_ik u(k) of pairs with any number of nodes each.

        Parameters
        ----------
        R
            (n, 3, 3) the pairs' frames.
        nodes_indptr
            (n + 1,) pair i involves ``nodes[nodes_indptr[i]:nodes_indptr[i + 1]]``.
        nodes
            Global dof-block indices, distinct within a pair.
        coefficients
            a_ik, one per entry of ``nodes`` (e.g. 1 for the slave node, −N_k for master nodes).
        """
        R = np.asarray(R, dtype=np.float64)
        nodes_indptr = np.asarray(nodes_indptr, dtype=np.int64)
        nodes = np.asarray(nodes, dtype=np.int64)
        coefficients = np.asarray(coefficients, dtype=np.float64)
        n = len(nodes_indptr) - 1
        m = np.diff(nodes_indptr)  # nodes per pair
        pair = np.repeat(np.arange(n), m)
        order = np.lexsort((nodes, pair))  # ascending nodes within each pair: ascending columns
        nodes, coefficients = nodes[order], coefficients[order]
        if np.any((nodes[1:] == nodes[:-1]) & (pair[1:] == pair[:-1])):
            raise ValueError("a pair lists the same node twice")
        # row 3i + r holds 3 m_i entries: for each node (ascending), its three components
        row_length = np.repeat(3 * m, 3)
        indptr = np.concatenate([[0], np.cumsum(row_length)]).astype(PETSc.IntType)
        e = np.arange(len(nodes))
        position_in_pair = e - nodes_indptr[pair]
        r = np.arange(3)[None, :, None]
        c = np.arange(3)[None, None, :]
        at = (indptr[3 * pair][:, None, None] + r * (3 * m[pair])[:, None, None]
              + 3 * position_in_pair[:, None, None] + c)  # (entries, 3 rows, 3 components)
        columns = np.empty(int(indptr[-1]), dtype=PETSc.IntType)
        values = np.empty(int(indptr[-1]))
        columns[at.ravel()] = np.broadcast_to(3 * nodes[:, None, None] + c, at.shape).ravel()
        values[at.ravel()] = (coefficients[:, None, None] * R[pair]).ravel()
        return cls(indptr, columns, values)

    @classmethod
    def concatenate(cls, parts: list[PairRows]) -> PairRows:
        """The rows of several pair sets, one after the other."""
        indptr = [np.zeros(1, dtype=PETSc.IntType)]
        start = 0
        for part in parts:
            indptr.append(part.indptr[1:] + start)
            start += int(part.indptr[-1])
        return cls(np.concatenate(indptr).astype(PETSc.IntType),
                   np.concatenate([p.columns for p in parts]).astype(PETSc.IntType),
                   np.concatenate([p.values for p in parts]))

    @property
    def num_pairs(self) -> int:
        """The number of pairs (three rows each)."""
        return (len(self.indptr) - 1) // 3

    @cached_property
    def _sources(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For every entry e (row 3p + r, position q in the row): p, r and the positions of the
        entries at the same place in rows 3p, 3p + 1, 3p + 2."""
        rows = np.repeat(np.arange(len(self.indptr) - 1), np.diff(self.indptr))
        pair, r = np.divmod(rows, 3)
        q = np.arange(len(self.columns)) - self.indptr[rows]
        sources = np.stack([self.indptr[3 * pair + l] + q for l in range(3)])
        return pair, r, sources

    def pair_entries(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For every entry: its pair p, its row r within the pair, and (3, nnz) the positions of the
        entries at the same place in the pair's three rows."""
        return self._sources

    def scaled(self, D: np.ndarray, values: np.ndarray | None = None) -> np.ndarray:
        """Values of blockdiag(D_i) B in this layout (row 3i + r = Σ_l D_i[r, l] · row 3i + l).

        Parameters
        ----------
        D
            (n, 3, 3) one matrix per pair.
        values
            Another matrix's values in this layout to scale instead of B's (e.g. B + W, the rows of
            a consistent linearisation: :mod:`~dolfinx_nnqem.contact.geometric_stiffness`).
        """
        D = np.asarray(D, dtype=np.float64)
        if D.shape != (self.num_pairs, 3, 3):
            raise ValueError(f"D must have shape ({self.num_pairs}, 3, 3), got {D.shape}")
        pair, r, s = self._sources
        v = self.values if values is None else values
        return D[pair, r, 0] * v[s[0]] + D[pair, r, 1] * v[s[1]] + D[pair, r, 2] * v[s[2]]


def rows_matrix(comm: MPI.Comm, rows: PairRows, num_global_pairs: int, index_map: dolfinx.common.IndexMap,
                values: np.ndarray | None = None) -> PETSc.Mat:
    """A PETSc AIJ matrix with ``rows`` as its local rows (3 per local pair).

    Parameters
    ----------
    comm
        The communicator of the pairs.
    rows
        The local rows.
    num_global_pairs
        Pairs over all ranks.
    index_map
        V's dof index map (block size 3): the column layout.
    values
        Values to use instead of ``rows.values`` (same layout), e.g. :meth:`PairRows.scaled`.
    """
    n = rows.num_pairs
    A = PETSc.Mat().createAIJ(
        size=((3 * n, 3 * num_global_pairs), (3 * index_map.size_local, 3 * index_map.size_global)),
        csr=(rows.indptr, rows.columns, rows.values if values is None else values),
        comm=comm,  # type: ignore[arg-type]  # petsc4py's stub asks a PETSc.Comm; it takes an mpi4py one too
    )
    A.assemble()
    return A


@runtime_checkable
class PairSet(Protocol):
    """A discretised contact interface (``formulation.md`` §2b), owned pairs of this rank.

    Pair i of this rank is global pair ``offset + i`` of the set; pairs are owned by the rank
    that owns their slave node, and their global order is the same for any number of ranks
    up to that ownership. Per-pair arrays hold the LOCAL pairs.
    """

    @property
    def comm(self) -> MPI.Comm:
        """The communicator of the mesh."""
        ...

    @property
    def num_local(self) -> int:
        """Pairs this rank owns."""
        ...

    @property
    def num_global(self) -> int:
        """Pairs of the set over all ranks."""
        ...

    @property
    def offset(self) -> int:
        """The global index of this rank's first pair."""
        ...

    @property
    def R(self) -> np.ndarray:
        """(num_local, 3, 3) frames, rows (n, t1, t2); n points from the master to the slave side."""
        ...

    @property
    def g0(self) -> np.ndarray:
        """(num_local,) initial gaps."""
        ...

    @property
    def rows(self) -> PairRows:
        """The local rows of B."""
        ...

    @property
    def X_slave(self) -> np.ndarray:
        """(num_local, 3) slave node positions."""
        ...

    @property
    def X_master(self) -> np.ndarray:
        """(num_local, 3) the facing point of the master side."""
        ...

    @property
    def slave_blocks(self) -> np.ndarray:
        """(num_local,) global dof-block indices of the slave nodes."""
        ...

    @property
    def area(self) -> np.ndarray:
        """(num_local,) the slave nodes' tributary areas (pressure = p_n / area)."""
        ...

    @property
    def kind(self) -> str:
        """What discretises the interface: "node-to-node", "rigid obstacle", ..."""
        ...

    @property
    def pins_supported_slave_tangents(self) -> bool:
        """Pin the tangential force of slave nodes whose tangential motion a support prescribes
        (rows coupling one slave node to several master nodes; ``ContactModel``)."""
        ...

    def motion(self, load_factor: float) -> np.ndarray:
        """(num_local, 3): m(ℓ), the known part of w (the master side's prescribed motion)."""
        ...

    def motion_amplitudes(self, load_factor: float) -> np.ndarray:
        """The master side's motion as numbers (for the secant predictor); empty if it does not move."""
        ...

    def describe(self) -> str:
        """One line for logs: the kind, the surfaces and the number of pairs."""
        ...
