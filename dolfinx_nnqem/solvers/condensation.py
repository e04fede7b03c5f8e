r"""The displacement solves of NNEQM1 and NNEQM2, condensed onto the contact pairs.

Both methods factorise a stiffness K (NNEQM1 the consistent tangent K_t, NNEQM2 the elastic K_e,
with identity rows and columns at constrained dofs) and express the displacement through the
pair forces: du = K⁻¹ (f + Bᵀ Δλ), w = B du, C = B K⁻¹ Bᵀ (``formulation.md`` §5).

Floating bodies. A body held only by contact (possibly with partial supports) has free rigid
modes N (:mod:`dolfinx_nnqem.problem.bodies`): K is singular along them. As FETI does, K is made
regular by fixing one well-chosen dof per mode (identity row and column: K̃), and

    G = K̃⁻¹ P   (P zeroes the constrained and fixing rows of a right-hand side)

is a generalised inverse of K on self-equilibrated loads: for f with Nᵀ f = 0, K (G f) = f at
every free dof, the fixing dofs included (their "reactions" vanish because the fixing is
statically determinate: N restricted to the fixing dofs is regular). The displacement is then

    du = G (f + Bᵀ Δλ) + N α,   with   Nᵀ (f + Bᵀ Δλ) = 0,

α the rigid-mode amplitudes: n_r more unknowns and n_r more (linear, self-equilibrium) equations
in the dense nonsmooth system, and w = B du picks up B N α. The fixing dofs are chosen by a
column-pivoted QR of Nᵀ (the best-conditioned rows of N: far apart nodes, the right components).
With no free mode, nothing changes: G = K⁻¹.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import dolfinx.fem as fem
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.numerics.linalg import clear_options, create_ksp, direct_options, factorise
from dolfinx_nnqem.solvers.timings import Timings

if TYPE_CHECKING:
    from dolfinx_nnqem.solvers.contract import SolvableProblem

__all__ = ["Condensation", "check_dense_memory", "dense_memory"]

DENSE_SYSTEM_COPIES = 6
"""(3NC + n_r)² arrays the dense contact solve holds at once, counted in :func:`dense_memory`:
the gathered flexibility C, the Jacobian and its LU factors, ∂_wH·C, and the driver's trial
and best iterates' Jacobians."""


def dense_memory(problem, factorisations: int = 1) -> dict[str, float]:
    """Bytes this rank's dense condensation needs (:meth:`Condensation.pair_flexibility` and the
    dense contact solve), by part; the factorisations of the stiffness come on top of it.

    The flexibility is computed as X = G Bᵀ from Bᵀ made dense (n_u × 3NC, n_u this rank's
    displacement dofs), X itself and the copy of X the solvers keep: three n_u × 3NC arrays. On
    the pressed blocks of level 8 (n_u = 111 078, 3NC = 3 267 on one rank) that is 8.7 GB.
    """
    n_u = 3 * problem.V.dofmap.index_map.size_local
    m = 3 * problem.num_pairs
    order = m + problem.rigid_modes.count
    return {"columns": 3.0 * 8 * n_u * m * factorisations, "rows": 8.0 * 3 * problem.contact.num_local * m,
            "dense system": 8.0 * DENSE_SYSTEM_COPIES * order * order}


def available_memory() -> float | None:
    """Bytes of memory this machine has available now (``MemAvailable``), None where unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return 1024.0 * float(line.split()[1])
    except OSError:
        pass
    return None


def check_dense_memory(problem: SolvableProblem, solver: str, limit_gb: float | None, factorisations: int = 1) -> None:
    """Refuse, before anything is assembled, a problem whose dense condensation does not fit.

    The need is :func:`dense_memory` summed over the ranks of each node; it must fit in
    ``limit_gb`` (GB per node) or, if None, in the memory the node has available. Raises
    ValueError on every rank, with the sizes, when it does not.
    """
    comm = problem.comm
    parts = dense_memory(problem, factorisations)
    node = comm.Split_type(MPI.COMM_TYPE_SHARED)
    try:
        need = node.allreduce(sum(parts.values()), op=MPI.SUM)
        limit = 1e9 * limit_gb if limit_gb is not None else available_memory()
        limit = node.allreduce(limit if limit is not None else math.inf, op=MPI.MIN)
    finally:
        node.Free()
    refuse = comm.allreduce(bool(need > limit), op=MPI.LOR)
    if not refuse:
        return
    n_u = 3 * problem.V.dofmap.index_map.size_global
    m = 3 * problem.num_pairs
    where = "set by max_memory_gb" if limit_gb is not None else "this machine has available"
    raise ValueError(
        f"{solver}: the dense condensation onto the {problem.num_pairs} pairs needs about {need / 1e9:.3g} GB "
        f"(on this node, besides the factorisation{'s' if factorisations > 1 else ''} of the stiffness): "
        f"{factorisations * 3} dense arrays of {n_u:,} displacement dofs × 3NC = {m:,} columns "
        f"({parts['columns'] / 1e9:.3g} GB on this rank) and the dense contact system of order {m:,} "
        f"({parts['dense system'] / 1e9:.3g} GB), more than the {limit / 1e9:.3g} GB {where}; use the "
        "monolithic solver (linear_solver='iterative' for large meshes), or set max_memory_gb in the "
        "method's options")


class Condensation:
    """Factorised stiffness, its generalised inverse G, and what the dense methods need of it.

    Parameters
    ----------
    problem
        The problem (its contact model and free rigid modes).
    solver
        The solver's name (for PETSc prefixes and messages).
    petsc_options
        Merged over MUMPS LU.
    """

    def __init__(self, problem, solver: str, petsc_options: dict | None):
        self.problem = problem
        self.solver = solver
        self.modes = problem.rigid_modes
        self.fixing_dofs, self.fixing_bcs = self._fixing_dofs()
        start = problem.V.dofmap.index_map.local_range[0] * 3
        n_owned = problem.V.dofmap.index_map.size_local * 3
        owned_fixing = self.fixing_dofs[(self.fixing_dofs >= start) & (self.fixing_dofs < start + n_owned)]
        self._owned_fixing = (owned_fixing - start).astype(np.int32)
        self.zero_rows = np.union1d(problem.constrained_rows(), owned_fixing).astype(PETSc.IntType)
        self.prefix = f"nnqem_{solver}_{id(self)}_"
        self._options = direct_options(petsc_options)
        self.ksp = create_ksp(problem.comm, self.prefix, self._options)
        self._options_cleared = False
        self._K: PETSc.Mat | None = None  # K̃, assembled by factorise into the same matrix every time
        self._K_trial: PETSc.Mat | None = None  # refactorise's assembly, compared with K̃ before K̃ changes
        self.factorisations = 0  #: numeric factorisations made (what depends on them is made again)
        # made at the first pair_flexibility (mode_coupling), refilled (kept) afterwards
        self._Bt_dense: PETSc.Mat | None = None
        self._X: PETSc.Mat | None = None
        self._C_rows: PETSc.Mat | None = None
        self._BN: np.ndarray | None = None
        self.timings = Timings()

    @property
    def K(self) -> PETSc.Mat:
        """K̃ as last factorised (vectors laid out like V's owned dofs come from it)."""
        if self._K is None:
            raise RuntimeError(f"{self.solver}: no stiffness factorised yet")
        return self._K

    @property
    def factorised(self) -> bool:
        """A stiffness has been factorised (:attr:`K` exists)."""
        return self._K is not None

    @property
    def num_modes(self) -> int:
        """Free rigid modes n_r (0 when every body is supported)."""
        return self.modes.count

    # -- the fixing dofs -------------------------------------------------------------------------
    def _fixing_dofs(self) -> tuple[np.ndarray, list]:
        """One dof per free rigid mode (global unrolled indices, the same on every rank) and the
        DirichletBCs (value 0) that fix them in K̃."""
        if self.modes.count == 0:
            return np.zeros(0, dtype=np.int64), []
        import scipy.linalg  # floating bodies only: other runs do not pay its import (0.1 s)

        p = self.problem
        comm, V = p.comm, p.V
        imap = V.dofmap.index_map
        start = 3 * imap.local_range[0]
        N = self.modes.local_array()  # (owned dofs, n_r)
        n_r = N.shape[1]
        # each rank proposes its n_r best-conditioned rows, then the best n_r of all proposals
        if N.shape[0]:
            _, _, pivots = scipy.linalg.qr(N.T, mode="economic", pivoting=True)
            local = pivots[:n_r]
        else:
            local = np.zeros(0, dtype=np.int64)
        candidates = np.concatenate(comm.allgather(start + local.astype(np.int64)))
        rows = np.concatenate(comm.allgather(N[local])).reshape(-1, n_r)
        _, _, pivots = scipy.linalg.qr(rows.T, mode="economic", pivoting=True)
        chosen = pivots[:n_r]
        smallest = np.linalg.svd(rows[chosen], compute_uv=False).min()
        if smallest < 1e-8:
            raise ValueError(f"{self.solver}: no well-conditioned fixing dofs for the free rigid modes "
                             f"({', '.join(self.modes.description)}); smallest singular value {smallest:.1e}")
        fixing = np.sort(candidates[chosen])
        # local indices (owned or ghost) of the fixing dofs on this rank
        blocks = np.concatenate([np.arange(*imap.local_range), imap.ghosts]).astype(np.int64)
        order = np.argsort(blocks)
        bcs = []
        for dof in fixing:
            block, component = divmod(int(dof), 3)
            k = np.searchsorted(blocks[order], block)
            local_dofs = np.zeros(0, dtype=np.int32)
            if k < len(blocks) and blocks[order][k] == block:
                local_dofs = np.array([3 * order[k] + component], dtype=np.int32)
            bcs.append(fem.dirichletbc(PETSc.ScalarType(0.0), local_dofs, V.sub(component)))  # type: ignore[operator]  # petsc4py's stub types ScalarType as a dtype; it is the scalar type (np.float64)
        return fixing, bcs

    # -- factorisation and solves ----------------------------------------------------------------
    def factorise(self, assemble: Callable[[PETSc.Mat | None, Any], PETSc.Mat], what: str) -> None:
        """Assemble K̃ with ``assemble(A, extra_bcs)`` (into the same matrix every time) and factorise it."""
        t0 = time.perf_counter()
        self._K = assemble(self._K, self.fixing_bcs)
        self.timings.add("assembly", t0)
        t0 = time.perf_counter()
        try:
            factorise(self.ksp, self._K, self.solver.upper(), what)
        finally:
            if not self._options_cleared:
                clear_options(self.prefix, self._options)
                self._options_cleared = True
        self.factorisations += 1
        self.timings.add("factorisation", t0)

    def refactorise(self, assemble: Callable[[PETSc.Mat | None, Any], PETSc.Mat], what: str) -> bool:
        """:meth:`factorise`, unless the stiffness ``assemble`` gives is bitwise the one factorised
        last (an elastic body's tangent in small strain): then the factors are kept. Returns True if
        it factorised.

        The stiffness is assembled into a second matrix and compared with K̃; only a changed one is
        copied into K̃ and factorised, so that the factors are those :meth:`factorise` makes.
        """
        if self._K is None:
            self.factorise(assemble, what)
            return True
        t0 = time.perf_counter()
        self._K_trial = assemble(self._K_trial, self.fixing_bcs)
        changed = not np.array_equal(self._K_trial.getValuesCSR()[2], self._K.getValuesCSR()[2])
        changed = bool(self.problem.comm.allreduce(changed, op=MPI.LOR))
        if changed:
            self._K_trial.copy(self._K, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)  # type: ignore[arg-type]  # petsc4py's stub types the Structure constants as int
        self.timings.add("assembly", t0)
        if changed:
            t0 = time.perf_counter()
            factorise(self.ksp, self._K, self.solver.upper(), what)
            self.factorisations += 1
            self.timings.add("factorisation", t0)
        return changed

    def solve(self, rhs: PETSc.Vec) -> PETSc.Vec:
        """K̃⁻¹ (rhs with the fixing rows zeroed); constrained rows of ``rhs`` are kept (lifting)."""
        b = rhs
        if self.num_modes:  # on every rank (a copy is collective), whichever owns the fixing dofs
            b = rhs.copy()
            b.getArray()[self._owned_fixing] = 0.0
        x = rhs.duplicate()
        t0 = time.perf_counter()
        self.ksp.solve(b, x)
        self.timings.add("solve", t0)
        if b is not rhs:
            b.destroy()
        return x

    def solve_columns(self, loads: PETSc.Mat) -> PETSc.Mat:
        """G applied to every column of ``loads`` (AIJ, laid out like V by rows): a dense matrix.

        ``loads`` is changed in place: its constrained and fixing rows are zeroed (they are
        loads) and it is converted to a dense matrix.
        """
        loads.zeroRows(self.zero_rows, diag=0.0)  # type: ignore[arg-type]  # petsc4py's stub asks IS or Sequence; arrays are what it takes
        dense = loads.convert("dense")  # petsc4py converts in place: ``loads`` is now dense
        Y = dense.duplicate()
        self.ksp.matSolve(dense, Y)
        return Y

    def transposed_B(self) -> PETSc.Mat:
        """Bᵀ (a new AIJ matrix) with the constrained and fixing rows zeroed."""
        Bt = self.problem.contact.B.transpose(PETSc.Mat())  # without an output matrix petsc4py transposes in place
        Bt.zeroRows(self.zero_rows, diag=0.0)
        return Bt

    def pair_flexibility(self) -> tuple[np.ndarray, np.ndarray]:
        """X = G Bᵀ (owned rows, dense (n_u, 3NC)) and C = B X gathered on every rank (3NC, 3NC)."""
        model = self.problem.contact
        t0 = time.perf_counter()
        if self._Bt_dense is None:
            self._Bt_dense = self.transposed_B().convert("dense")  # petsc4py converts in place
            self._X = self._Bt_dense.duplicate()
        assert self._X is not None  # made with _Bt_dense
        self.ksp.matSolve(self._Bt_dense, self._X)
        if self._C_rows is None:
            self._C_rows = model.B.matMult(self._X)
        else:
            model.B.matMult(self._X, self._C_rows)
        nc = model.num_global
        # (3 rows per owned pair) × 3NC, regrouped per pair for the gather (a rank may own none)
        C = model.gather(self._C_rows.getDenseArray().reshape(model.num_local, 9 * nc)).reshape(3 * nc, 3 * nc)
        self.timings.add("flexibility", t0)
        return self._X.getDenseArray().copy(), C

    def pairs_changed(self) -> None:
        """Forget what was built on B (after the contact geometry changed): Bᵀ, X, C's rows, B N."""
        for obj in (self._Bt_dense, self._X, self._C_rows):
            if obj is not None:
                obj.destroy()
        self._Bt_dense = self._X = self._C_rows = None
        self._BN = None

    def mode_coupling(self) -> np.ndarray:
        """B N gathered on every rank, (3NC, n_r): how each free rigid mode moves the pairs."""
        if self._BN is None:
            model = self.problem.contact
            columns = [model.B_times(v) for v in self.modes.vectors]
            local = np.stack(columns, axis=-1) if columns else np.zeros((model.num_local, 3, 0))
            self._BN = model.gather(local).reshape(3 * model.num_global, self.num_modes)
        return self._BN

    def mode_loads(self, f: PETSc.Vec) -> np.ndarray:
        """Nᵀ f (n_r,): the load ``f`` against each free rigid mode (collective)."""
        return np.array([v.dot(f) for v in self.modes.vectors])

    def mode_amplitudes(self, displacement: np.ndarray) -> np.ndarray:
        """α with N α = ``displacement`` at the fixing dofs (collective; ``displacement``: owned rows
        of a vector laid out like V): the free rigid motion a displacement carries, since
        everything G returns vanishes at the fixing dofs."""
        if self.num_modes == 0:
            return np.zeros(0)
        comm = self.problem.comm
        values = np.concatenate(comm.allgather(np.asarray(displacement)[self._owned_fixing]))
        rows = np.concatenate(comm.allgather(self.mode_array()[self._owned_fixing])).reshape(-1, self.num_modes)
        return np.linalg.solve(rows, values)

    def mode_array(self) -> np.ndarray:
        """N's owned rows (n_u, n_r)."""
        if self.num_modes == 0:
            return np.zeros((3 * self.problem.V.dofmap.index_map.size_local, 0))
        return self.modes.local_array()


    def destroy(self) -> None:
        """Free the factorisation, K̃ and the dense flexibility's PETSc objects (collective)."""
        for obj in (self.ksp, self._K, self._K_trial, self._Bt_dense, self._X, self._C_rows):
            if obj is not None:
                obj.destroy()
