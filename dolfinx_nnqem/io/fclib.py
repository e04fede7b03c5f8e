"""Export of NNEQM1's condensed contact problem in the FCLIB HDF5 format (local problem).

FCLIB (the Frictional Contact LIBrary, https://frictionalcontactlibrary.github.io) stores
frictional contact problems in HDF5 so that solvers can be compared on the same data.
This module writes the dense inner problem of one NNEQM1 outer iteration (``formulation.md``
§5, step 3) as an FCLIB *local* problem, reads such files back, and evaluates FCLIB's
error of a solution. It needs only ``h5py`` (no FCLIB C library).

Layout followed
---------------
The layout is that of the reference implementation, FrictionalContactLibrary/fclib,
``src/fclib.h`` (the header-only library) at commit b8845f7cab4ac017728a5feb44359209c2b67f4b:
``fclib_write_local``, ``write_matrix``, ``write_local_vectors``, ``write_problem_info``,
``fclib_write_solution``, ``fclib_write_guesses`` and ``fclib_merit_local``. The same
layout is in ``src/fclib.c`` at commit 8d03864ddc262ecfafb498f9232ed6e092f0df06 (the older
``src/fclib.c`` at 061a7dd4… wrote ``/a`` instead of ``/q`` and absolute paths: not followed).
Every numeric item is a *dataset*, none is an attribute: ``H5LTmake_dataset_int`` gives a
rank-1 dataset of ``H5T_NATIVE_INT`` (int32), ``H5LTmake_dataset_double`` a rank-1 dataset of
``H5T_NATIVE_DOUBLE`` (float64), scalars with shape (1,); ``H5LTmake_dataset_string`` a
*scalar* dataset of type ``H5T_C_S1`` of size strlen + 1 padded ``H5T_STR_NULLTERM`` (the
C reader allocates the type size and expects the terminating NUL, so this is reproduced
exactly)::

    /fclib_local/spacedim        int32 (1,)    3
    /fclib_local/W/nzmax         int32 (1,)    number of stored entries
    /fclib_local/W/m, /W/n       int32 (1,)    rows, columns (= 3 nc)
    /fclib_local/W/nz            int32 (1,)    -1: compressed columns (CSC), -2: compressed rows,
                                               >= 0: triplet with nz entries
    /fclib_local/W/p             int32         CSC: n+1 column pointers; CSR: m+1 row pointers;
                                               triplet: nz column indices
    /fclib_local/W/i             int32 (nzmax) CSC: row indices; CSR: column indices;
                                               triplet: row indices
    /fclib_local/W/x             float64 (nzmax) values
    [/fclib_local/W/comment      string; /W/conditioning, /W/determinant float64 (1,);
     /W/rank int32 (1,)]         optional fclib_matrix_info (all three numbers or none)
    /fclib_local/vectors/q       float64 (m,)
    /fclib_local/vectors/mu      float64 (m / spacedim,)
    /fclib_local/info/title, description, math_info    strings (optional)
    /solution/u, /solution/r     float64 (n,)  (fclib_write_solution; local: no v, no l)
    /guesses/number_of_guesses   int32 (1,);  /guesses/1/u, /guesses/1/r, /guesses/2/...

``fclib_matrix`` has the member order of CSparse's ``cs`` (nzmax, m, n, p, i, x, nz) and
fclib's own ``fclib_merit_local`` casts it to ``cs*``: the conventions are CSparse's (for a
triplet, ``i`` holds rows and ``p`` columns; the comment in ``fclib.h`` says the opposite
for triplets, which is why this module writes CSC, ``nz = -1``, like a CSparse matrix). The
optional matrices V, R and vector s of the mixed local problem are not written (our
problem has no equality constraints). There is no ``numberOfContacts`` item in the format:
it is ``W.m / spacedim`` (Siconos' ``from_fclib_local`` computes it so; Siconos'
``frictionContact_fclib_write`` adds an int *attribute* ``numberOfDegreeOfFreedom`` to
``/fclib_local/info``, written here when ``number_of_dofs`` is given). An extra group
``/dolfinx_nnqem`` keeps our raw condensed data (C, w_free, w_m, lam_m, g0, w_prev, mu_f, r)
so that the file reads back to the same C and w_free; FCLIB readers open fixed paths only
and ignore it.

The FCLIB local problem
-----------------------
Given W (m × m, positive semi-definite), q and μ (one per contact), find u, r ∈ R^m with, per
contact α (normal component first, then the two tangential ones)::

    û = W r + q + [μ^α ‖u^α_T‖, 0, 0]^α,        K*_μ ∋ û ⊥ r ∈ K_μ,
    K_μ^α = {r^α : ‖r^α_T‖ ≤ μ^α r^α_N}                (the Coulomb cone; K* its dual),

with u = W r + q the local velocity — for quasi-static problems "position/displacement"
(``fclib_solution`` in fclib.h) — and r the reaction. De Saxcé's modified velocity û makes
this equivalent, contact by contact, to Coulomb's law: open (r = 0, u_N ≥ 0), stick
(‖r_T‖ < μ r_N, u = 0) or slip (‖r_T‖ = μ r_N, u_N = 0, r_T = −μ r_N u_T/‖u_T‖).

Mapping of our condensed problem (derivation)
---------------------------------------------
Outer iteration m of NNEQM1 (``formulation.md`` §2 and §5; ``nneqm1.py``): the relative
displacement of the pairs, in the local frames (rows n, t1, t2 per pair, pairs in global
order), is affine in the contact forces λ (force on body 2, λ_i = (p_n, q1, q2))::

    w(λ) = w_m + w_free + C (λ − λ_m),      C = B K_m⁻¹ Bᵀ   (3 nc × 3 nc),

and the pair law is Coulomb's law in terms of the gap and the incremental slip::

    g_i = g0_i + w_i,n,     s_i = w_i,t − w^n_i,t   (w^n: converged value of the last step),
    g ≥ 0, p_n ≥ 0, g p_n = 0;  ‖q‖ ≤ μ_f p_n;  s = 0 if ‖q‖ < μ_f p_n,
    q = −μ_f p_n s/‖s‖ otherwise.

Take FCLIB's unknowns u_i = (g_i, s_i) and r_i = λ_i. Then u = w(λ) + d with
d_i = (g0_i, −w^n_i,t1, −w^n_i,t2), that is u = W r + q with::

    W = C
    q = w_m + w_free − C λ_m + d,   i.e.   q_i,n = g0_i + (w_m + w_free − C λ_m)_i,n
                                          q_i,t = (w_m + w_free − C λ_m)_i,t − w^n_i,t
    μ_i = μ_f,i,   spacedim = 3,

exactly, with no sign change and no reordering: p_n ≥ 0 is the compression that opens the
gap (C is positive definite: pushing body 2 away increases g), so r_N = p_n and u_N = g have
FCLIB's signs; FCLIB's slip rule r_T = −μ r_N u_T/‖u_T‖ is our q = −μ_f p_n s/‖s‖; FCLIB's
per-contact order (normal, tangential) is our (n, t1, t2); and the cone is isotropic, so the
orientation of (t1, t2) does not matter. Units: W in m/N, q and u in m, r in N (SI units
of the model). The Alart–Curnier / polar parameter r of the law is a solver choice and not
part of the problem (it is kept in ``/dolfinx_nnqem`` only).

Directions that the supports fix (each law's ``pin``) have zero rows and
columns in C; NNEQM1 sets their λ component to zero (the minimum-norm choice). FCLIB's
problem has no such rule: there, any λ component is admissible that Coulomb's law allows
with the fixed u component. ``last_condensed`` does not record these directions; in the
two-beam benchmark there are none.

Error of a solution
-------------------
:func:`fclib_merit` is FCLIB's ``fclib_merit_local`` (MERIT_1) verbatim: the natural map
‖r − P_K(r − û)‖ over all contacts divided by 1 + sqrt(‖q‖) — note it mixes units (N and m)
and its denominator is not scale invariant. :func:`complementarity_error` is the same
natural map with the velocity scaled by a stiffness ρ (default 1/mean diag W), divided by
max(‖r‖, ρ‖q‖): dimensionless, zero exactly at FCLIB solutions (r = P_K(r − ρû) ⇔
K ∋ r ⊥ û ∈ K* for every ρ > 0).

MPI
---
The condensed data are the same on every rank (NNEQM1 gathers them); the writers are
collective on ``comm`` (default ``MPI.COMM_WORLD``): rank 0 writes, then all ranks wait at a
barrier, so the file is complete on return on every rank.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np
import numpy.typing as npt


def _import_h5py():
    """Import h5py so that it uses its own HDF5 even after DOLFINx has loaded another one.

    The DOLFINx wheel's stack puts its libhdf5 (1.14) into the process's global symbol scope
    (it is there after ``import dolfinx.fem.petsc``); an h5py wheel imported afterwards then
    binds part of its HDF5 calls to that library and fails at import ("Not a datatype").
    Loading h5py's extension modules with RTLD_DEEPBIND makes them resolve to the HDF5 they
    were built with first. Harmless where both share one HDF5 (Debian's packages).
    """
    if "h5py" in sys.modules:
        return sys.modules["h5py"]
    flags = sys.getdlopenflags()
    deepbind = getattr(os, "RTLD_DEEPBIND", 0)
    try:
        sys.setdlopenflags(flags | deepbind)
        import h5py
    finally:
        sys.setdlopenflags(flags)
    return h5py


if TYPE_CHECKING:
    import h5py
    from mpi4py import MPI

    from dolfinx_nnqem.solvers.contract import CondensingSolver
else:
    h5py = _import_h5py()

__all__ = [
    "FCLIB_REFERENCE",
    "fclib_local_from_condensed",
    "write_fclib_problem",
    "write_fclib_local",
    "write_condensed_problem",
    "write_nneqm1_problem",
    "read_fclib_local",
    "fclib_merit",
    "complementarity_error",
    "coulomb_violations",
    "CSCMatrix",
    "dense_to_csc",
    "fclib_matrix_to_dense",
]

FCLIB_REFERENCE = ("FrictionalContactLibrary/fclib src/fclib.h @ "
                   "b8845f7cab4ac017728a5feb44359209c2b67f4b")
"""The FCLIB source whose layout this module follows."""

_INT = np.dtype(np.intc)  # H5T_NATIVE_INT
_DOUBLE = np.dtype(np.float64)  # H5T_NATIVE_DOUBLE
_EXTRA_GROUP = "dolfinx_nnqem"

DEFAULT_TITLE = "dolfinx_nnqem NNEQM1 condensed contact problem"
DEFAULT_MATH_INFO = ("W = C = B K^-1 B^T: contact flexibility of the consistent tangent K "
                     "(symmetric positive definite when every body is held by its supports); "
                     "u = (gap, incremental slip) [m], r = contact force on body 2 (p_n, q1, q2) [N].")


# -- sparse storage --------------------------------------------------------------------------------
@dataclass
class CSCMatrix:
    """An ``fclib_matrix`` (CSparse ``cs``) in compressed columns: nz = -1."""

    m: int
    n: int
    p: np.ndarray  # n + 1 column pointers
    i: np.ndarray  # nzmax row indices
    x: np.ndarray  # nzmax values

    @property
    def nzmax(self) -> int:
        """Number of stored entries (FCLIB's ``nzmax``)."""
        return int(self.x.size)

    nz = -1


def dense_to_csc(A: npt.ArrayLike, *, keep_zeros: bool = False) -> CSCMatrix:
    """Compressed-column storage of a dense matrix (exact zeros dropped unless ``keep_zeros``)."""
    A = np.asarray(A, dtype=np.float64)
    if A.ndim != 2:
        raise ValueError(f"expected a matrix, got shape {A.shape}")
    m, n = A.shape
    mask = np.ones_like(A, dtype=bool) if keep_zeros else (A != 0.0)
    # column-major traversal: for each column the stored rows in increasing order
    cols, rows = np.nonzero(mask.T)
    p = np.zeros(n + 1, dtype=_INT)
    np.cumsum(np.bincount(cols, minlength=n), out=p[1:])
    return CSCMatrix(m, n, p, rows.astype(_INT), A[rows, cols].copy())


def fclib_matrix_to_dense(m: int, n: int, nz: int, p: np.ndarray, i: np.ndarray,
                          x: np.ndarray) -> np.ndarray:
    """Dense array of an ``fclib_matrix`` stored as CSC (nz = -1), CSR (-2) or triplets (nz ≥ 0).

    Duplicate triplets are summed (CSparse's ``cs_compress``).
    """
    A = np.zeros((m, n))
    p, i, x = np.asarray(p, np.int64), np.asarray(i, np.int64), np.asarray(x, np.float64)
    if nz == -1:
        counts = np.diff(p)
        cols = np.repeat(np.arange(n), counts)
        k = slice(0, int(p[-1]))
        np.add.at(A, (i[k], cols), x[k])
    elif nz == -2:
        counts = np.diff(p)
        rows = np.repeat(np.arange(m), counts)
        k = slice(0, int(p[-1]))
        np.add.at(A, (rows, i[k]), x[k])
    elif nz >= 0:
        np.add.at(A, (i[:nz], p[:nz]), x[:nz])
    else:
        raise ValueError(f"unknown fclib matrix storage nz = {nz}")
    return A


# -- HDF5 primitives reproducing H5LTmake_dataset_{int,double,string} ------------------------------
def _make_int(group: h5py.Group, name: str, values) -> None:
    group.create_dataset(name, data=np.atleast_1d(np.asarray(values, dtype=_INT)))


def _make_double(group: h5py.Group, name: str, values) -> None:
    group.create_dataset(name, data=np.atleast_1d(np.asarray(values, dtype=_DOUBLE)))


def _make_string(group: h5py.Group, name: str, text: str) -> None:
    """A scalar H5T_C_S1 dataset of size strlen + 1, NULLTERM (``H5LTmake_dataset_string``)."""
    data = str(text).encode("utf-8")
    if b"\0" in data:
        raise ValueError(f"{name}: a C string cannot contain NUL characters")
    size = len(data) + 1
    tid = h5py.h5t.C_S1.copy()
    tid.set_size(size)
    tid.set_strpad(h5py.h5t.STR_NULLTERM)
    sid = h5py.h5s.create(h5py.h5s.SCALAR)
    did = h5py.h5d.create(group.id, name.encode(), tid, sid)
    did.write(h5py.h5s.ALL, h5py.h5s.ALL, np.array(data + b"\0", dtype=f"S{size}"), mtype=tid)
    did.close()


def _read_string(dataset: h5py.Dataset) -> str:
    value = dataset[()]
    if isinstance(value, np.ndarray):
        value = value.reshape(-1)[0]
    if isinstance(value, bytes):
        return value.split(b"\0", 1)[0].decode("utf-8", errors="replace")
    return str(value)


def _write_matrix(group: h5py.Group, A: CSCMatrix, info: Mapping[str, Any] | None) -> None:
    """``write_matrix`` of fclib.h for a CSC matrix (+ optional ``fclib_matrix_info``)."""
    _make_int(group, "nzmax", A.nzmax)
    _make_int(group, "m", A.m)
    _make_int(group, "n", A.n)
    _make_int(group, "nz", A.nz)
    _make_int(group, "p", A.p)
    _make_int(group, "i", A.i)
    _make_double(group, "x", A.x)
    if info is not None:
        if info.get("comment"):
            _make_string(group, "comment", info["comment"])
        _make_double(group, "conditioning", info["conditioning"])
        _make_double(group, "determinant", info["determinant"])
        _make_int(group, "rank", info["rank"])


def _matrix_info(W: np.ndarray) -> dict:
    """fclib_matrix_info of a dense W: 2-norm condition number, determinant, numerical rank."""
    sym = np.allclose(W, W.T, rtol=0.0, atol=1e-12 * max(np.abs(W).max(initial=0.0), 1e-300))
    sv = np.linalg.svd(W, compute_uv=False)  # descending
    tol = sv[0] * max(W.shape) * np.finfo(float).eps
    rank = int((sv > tol).sum())
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    with np.errstate(under="ignore", over="ignore"):
        det = float(np.linalg.det(W))
    comment = (f"dense contact flexibility stored in compressed columns; "
               f"{'symmetric' if sym else 'non-symmetric'} to round-off; "
               f"singular values in [{sv[-1]:.3e}, {sv[0]:.3e}] m/N; "
               f"the determinant is a product of 3nc such values and underflows to 0 for large nc")
    return {"comment": comment, "conditioning": cond, "determinant": det, "rank": rank}


# -- mapping --------------------------------------------------------------------------------------
def fclib_local_from_condensed(C: npt.ArrayLike, w_free: npt.ArrayLike, mu_f: npt.ArrayLike, *,
                               w_m: npt.ArrayLike, lam_m: npt.ArrayLike, g0: npt.ArrayLike,
                               w_prev: npt.ArrayLike) -> dict:
    """W, q, μ of the FCLIB local problem equivalent to NNEQM1's condensed problem.

    W = C; q = w_m + w_free − C λ_m + d with d_i = (g0_i, −w^n_i,t1, −w^n_i,t2) (module
    docstring). Arrays are in global pair order, 3 rows (n, t1, t2) per pair.
    """
    C = np.asarray(C, dtype=np.float64)
    nc3 = C.shape[0]
    if C.shape != (nc3, nc3) or nc3 % 3:
        raise ValueError(f"C must be 3nc × 3nc, got shape {C.shape}")
    nc = nc3 // 3
    w_free = _vector("w_free", w_free, nc3)
    w_m = _vector("w_m", w_m, nc3)
    lam_m = _vector("lam_m", lam_m, nc3)
    g0 = _vector("g0", g0, nc)
    mu = _vector("mu_f", mu_f, nc)
    w_prev = np.asarray(w_prev, dtype=np.float64).reshape(nc, 3)
    d = np.column_stack((g0, -w_prev[:, 1], -w_prev[:, 2])).reshape(-1)
    q = w_m + w_free - C @ lam_m + d
    return {"W": C.copy(), "q": q, "mu": mu.copy(), "spacedim": 3}


def _vector(name: str, value, size: int) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64).reshape(-1)
    if v.size != size:
        raise ValueError(f"{name} must have {size} entries, got {v.size}")
    return v


# -- writers --------------------------------------------------------------------------------------
def _default_comm(comm):
    if comm is None:
        from mpi4py import MPI

        comm = MPI.COMM_WORLD
    return comm


def _solution_pair(W: np.ndarray, q: np.ndarray, value) -> tuple[np.ndarray, np.ndarray]:
    """(u, r) of a solution/guess given as r (array) or {"r": ..., "u": ...}."""
    if isinstance(value, Mapping):
        r = _vector("r", value["r"], W.shape[1])
        u = _vector("u", value["u"], W.shape[0]) if value.get("u") is not None else W @ r + q
    else:
        r = _vector("r", value, W.shape[1])
        u = W @ r + q
    return u, r


def write_fclib_problem(path: str | Path, W: npt.ArrayLike, q: npt.ArrayLike, mu: npt.ArrayLike, *,
                        title: str = DEFAULT_TITLE, description: str = "",
                        math_info: str = DEFAULT_MATH_INFO,
                        solution: npt.ArrayLike | Mapping[str, npt.ArrayLike] | None = None,
                        guesses: Sequence | None = None, matrix_info: bool = True,
                        number_of_dofs: int | None = None, extra: Mapping[str, Any] | None = None,
                        overwrite: bool = True, comm: MPI.Comm | None = None) -> Path:
    """Write an FCLIB local problem FC(W, q, μ) (spacedim 3) to ``path``.

    Parameters
    ----------
    W
        Dense (m × m) matrix, stored in compressed columns (exact zeros dropped).
    solution, guesses
        ``r`` arrays (u = W r + q is then computed) or ``{"r": r, "u": u}``; written to
        ``/solution`` and ``/guesses/1``, ``/guesses/2``, …
    matrix_info
        Also write W's ``fclib_matrix_info`` (condition number, determinant, rank, comment).
    number_of_dofs
        Written as Siconos' int attribute ``numberOfDegreeOfFreedom`` of ``/fclib_local/info``.
    extra
        Arrays (datasets) and scalars (attributes) for the ``/dolfinx_nnqem`` group.
    overwrite
        Truncate an existing file (FCLIB's C writer refuses to write a second local problem
        into a file; here the file is replaced). ``False`` raises if ``path`` exists.
    comm
        MPI communicator (collective; rank 0 writes). Default ``MPI.COMM_WORLD``.
    """
    comm = _default_comm(comm)
    path = Path(path)
    error = None
    if comm.rank == 0:
        try:
            _write(path, W, q, mu, title, description, math_info, solution, guesses, matrix_info,
                   number_of_dofs, extra, overwrite)
        except Exception as exc:  # re-raised on every rank below
            error = exc
    error_text = comm.bcast(None if error is None else f"{type(error).__name__}: {error}", root=0)
    if error is not None:
        raise error
    if error_text is not None:
        raise RuntimeError(f"FCLIB export failed on rank 0: {error_text}")
    return path


def _write(path, W, q, mu, title, description, math_info, solution, guesses, matrix_info,
           number_of_dofs, extra, overwrite) -> None:
    W = np.asarray(W, dtype=np.float64)
    m = W.shape[0]
    if W.ndim != 2 or W.shape != (m, m) or m == 0 or m % 3:
        raise ValueError(f"W must be a non-empty 3nc × 3nc matrix, got shape {W.shape}")
    q = _vector("q", q, m)
    mu = _vector("mu", mu, m // 3)
    if not (np.all(np.isfinite(W)) and np.all(np.isfinite(q)) and np.all(np.isfinite(mu))):
        raise ValueError("W, q and mu must be finite")
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists (pass overwrite=True to replace it)")
    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, "w") as f:
        main = f.create_group("fclib_local")
        _make_int(main, "spacedim", 3)
        _write_matrix(main.create_group("W"), dense_to_csc(W), _matrix_info(W) if matrix_info else None)
        vectors = main.create_group("vectors")
        _make_double(vectors, "q", q)
        _make_double(vectors, "mu", mu)
        info = main.create_group("info")
        for name, text in (("title", title), ("description", description), ("math_info", math_info)):
            if text is not None:
                _make_string(info, name, text)
        if number_of_dofs is not None:
            info.attrs.create("numberOfDegreeOfFreedom", np.intc(number_of_dofs), shape=(1,), dtype=_INT)
        if solution is not None:
            u, r = _solution_pair(W, q, solution)
            group = f.create_group("solution")
            _make_double(group, "u", u)
            _make_double(group, "r", r)
        if guesses:
            group = f.create_group("guesses")
            _make_int(group, "number_of_guesses", len(guesses))
            for k, guess in enumerate(guesses, start=1):
                u, r = _solution_pair(W, q, guess)
                g = group.create_group(str(k))
                _make_double(g, "u", u)
                _make_double(g, "r", r)
        if extra:
            g = f.create_group(_EXTRA_GROUP)
            for key, value in extra.items():
                if isinstance(value, str):
                    g.attrs[key] = value  # h5py variable-length UTF-8 string
                    continue
                arr = np.asarray(value)
                if arr.ndim == 0:
                    g.attrs[key] = arr
                else:
                    g.create_dataset(key, data=arr)


def write_fclib_local(path: str | Path, C: npt.ArrayLike, w_free: npt.ArrayLike, mu_f: npt.ArrayLike, *,
                      w_m: npt.ArrayLike, lam_m: npt.ArrayLike, g0: npt.ArrayLike, w_prev: npt.ArrayLike,
                      title: str = DEFAULT_TITLE, description: str | None = None,
                      math_info: str = DEFAULT_MATH_INFO,
                      solution: npt.ArrayLike | Mapping[str, npt.ArrayLike] | None = None,
                      guesses: Sequence | None = None, r: float | None = None, **kwargs: Any) -> Path:
    """Write NNEQM1's condensed problem (C, w_free, μ_f, …) as an FCLIB local problem.

    W = C and q from :func:`fclib_local_from_condensed`; ``solution`` / ``guesses`` are
    contact forces λ (3nc, or (nc, 3)) or ``{"r", "u"}`` dicts. The raw data are kept in
    ``/dolfinx_nnqem``. Other keyword arguments go to :func:`write_fclib_problem`. Collective.
    """
    fc = fclib_local_from_condensed(C, w_free, mu_f, w_m=w_m, lam_m=lam_m, g0=g0, w_prev=w_prev)
    nc = fc["mu"].size
    if description is None:
        description = (f"{nc} node-to-node contact pairs, frames (n, t1, t2); incremental Coulomb "
                       f"friction. q = w_m + w_free - C lam_m + (g0, -w_prev_t1, -w_prev_t2) per pair.")
    extra = {"C": np.asarray(C, np.float64), "w_free": _vector("w_free", w_free, 3 * nc),
             "w_m": _vector("w_m", w_m, 3 * nc), "lam_m": _vector("lam_m", lam_m, 3 * nc),
             "g0": _vector("g0", g0, nc), "w_prev": np.asarray(w_prev, np.float64).reshape(nc, 3),
             "mu_f": fc["mu"], "fclib_reference": FCLIB_REFERENCE}
    if r is not None:
        extra["r"] = float(r)
    return write_fclib_problem(path, fc["W"], fc["q"], fc["mu"], title=title, description=description,
                               math_info=math_info, solution=_flat(solution), guesses=guesses and
                               [_flat(g) for g in guesses], extra=extra, **kwargs)


def _flat(value):
    if value is None or isinstance(value, Mapping):
        return value
    return np.asarray(value, dtype=np.float64).reshape(-1)


def write_condensed_problem(path: str | Path, condensed: Mapping[str, Any], *,
                            solution: npt.ArrayLike | Mapping[str, npt.ArrayLike] | None = None,
                            include_start_guess: bool = True, **kwargs: Any) -> Path:
    """Write a condensed problem (``NNEQM1Solver.last_condensed.as_dict()``) as an FCLIB local problem (collective).

    ``solution``: the contact forces λ solving this inner problem, if known. With
    ``include_start_guess``, NNEQM1's starting point λ_m is written as guess 1.
    """
    c = condensed
    guesses = [c["lam_m"]] if include_start_guess else None
    return write_fclib_local(path, c["C"], c["w_free"], c["mu_f"], w_m=c["w_m"], lam_m=c["lam_m"],
                             g0=c["g0"], w_prev=c["w_prev"], r=c.get("r"), solution=solution,
                             guesses=guesses, **kwargs)


def write_nneqm1_problem(path: str | Path, solver: CondensingSolver, *, with_solution: bool = True, **kwargs: Any) -> Path:
    """Export the last inner problem of an NNEQM1 solver, with its solution (collective).

    The solution is the solver's current contact force λ(z): after an increment has
    converged (or after any completed inner solve) it is the inner solution of
    ``solver.last_condensed``. Collective on the problem's communicator.
    """
    condensed = solver.last_condensed
    if condensed is None:
        raise ValueError("the solver has not set up a condensed problem yet (solve an increment first)")
    if condensed.BN.shape[1]:
        raise ValueError(f"the condensed problem has {condensed.BN.shape[1]} free rigid modes (a body held only "
                         "by contact): their amplitudes and self-equilibrium equations have no place in FCLIB's "
                         "local problem W r + q = u")
    p = solver.problem
    solution = None
    if with_solution:
        assert p.contact is not None  # last_condensed is set only by a solve on the problem's contact model
        solution = p.contact.gather(p.contact.force()).reshape(-1)
    kwargs.setdefault("comm", p.comm)
    kwargs.setdefault("number_of_dofs", int(p.V.dofmap.index_map.size_global * p.V.dofmap.index_map_bs))
    return write_condensed_problem(path, condensed.as_dict(), solution=solution, **kwargs)


# -- reader ---------------------------------------------------------------------------------------
def read_fclib_local(path: str | Path) -> dict:
    """Read an FCLIB local problem (any rank may call it; no MPI).

    Returns
    -------
    dict
        ``W`` (dense), ``q``, ``mu``, ``spacedim``, ``number_of_contacts`` (= W.m / spacedim),
        ``W_storage`` (the stored nzmax, m, n, nz, p, i, x), ``W_info`` (or None), ``info``
        (title, description, math_info, attributes), ``V``, ``R``, ``s`` (None when absent),
        ``solution`` ({"u", "r"} or None), ``guesses`` (list of {"u", "r"}) and ``condensed``
        (the ``/dolfinx_nnqem`` data, or None).
    """
    with h5py.File(path, "r") as f:
        if "fclib_local" not in f:
            raise ValueError(f"{path}: no /fclib_local group (not an FCLIB local problem)")
        main = f["fclib_local"]
        spacedim = int(main["spacedim"][0])
        W, W_storage, W_info = _read_matrix(main["W"])
        V = R = s = None
        if "V" in main:
            V, _, _ = _read_matrix(main["V"])
            R, _, _ = _read_matrix(main["R"])
            s = main["vectors/s"][()]
        q = main["vectors/q"][()]
        mu = main["vectors/mu"][()]
        if W.shape[0] % spacedim:
            raise ValueError("number of W rows is not divisible by the spatial dimension")
        info: dict[str, Any] = {"title": None, "description": None, "math_info": None, "attributes": {}}
        if "info" in main:
            for name in ("title", "description", "math_info"):
                if name in main["info"]:
                    info[name] = _read_string(main["info"][name])
            info["attributes"] = {k: v for k, v in main["info"].attrs.items()}
        solution = _read_solution(f["solution"]) if "solution" in f else None
        guesses = []
        if "guesses" in f:
            for k in range(int(f["guesses/number_of_guesses"][0])):
                guesses.append(_read_solution(f["guesses"][str(k + 1)]))
        condensed = None
        if _EXTRA_GROUP in f:
            g = f[_EXTRA_GROUP]
            condensed = {k: g[k][()] for k in g}
            condensed.update({k: (v.item() if isinstance(v, np.generic) else v)
                              for k, v in g.attrs.items()})
            for k, v in condensed.items():
                if isinstance(v, bytes):
                    condensed[k] = v.decode()
    return {"W": W, "q": q, "mu": mu, "spacedim": spacedim,
            "number_of_contacts": W.shape[0] // spacedim, "W_storage": W_storage, "W_info": W_info,
            "V": V, "R": R, "s": s, "info": info, "solution": solution, "guesses": guesses,
            "condensed": condensed}


def _read_matrix(group: h5py.Group):
    storage: dict[str, Any] = {k: int(group[k][0]) for k in ("nzmax", "m", "n", "nz")}
    storage.update({k: group[k][()] for k in ("p", "i", "x")})
    A = fclib_matrix_to_dense(storage["m"], storage["n"], storage["nz"], storage["p"], storage["i"],
                              storage["x"])
    info = None
    if "conditioning" in group:
        info = {"comment": _read_string(group["comment"]) if "comment" in group else None,
                "conditioning": float(group["conditioning"][0]),
                "determinant": float(group["determinant"][0]), "rank": int(group["rank"][0])}
    return A, storage, info


def _read_solution(group: h5py.Group) -> dict:
    return {k: group[k][()] for k in ("u", "r", "v", "l") if k in group}


# -- errors of a solution --------------------------------------------------------------------------
def _project_on_cone(x: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Projection of each row (n, t1, t2) on the Coulomb cone ‖x_t‖ ≤ μ x_n (fclib.h's
    ``projectionOnCone``)."""
    x = np.array(x, dtype=np.float64)
    normT = np.hypot(x[:, 1], x[:, 2])
    polar = mu * normT <= -x[:, 0]
    inside = (normT <= mu * x[:, 0]) & ~polar
    other = ~(polar | inside)
    xn = (mu[other] * normT[other] + x[other, 0]) / (mu[other] ** 2 + 1.0)
    x[other, 1] = mu[other] * xn * x[other, 1] / normT[other]
    x[other, 2] = mu[other] * xn * x[other, 2] / normT[other]
    x[other, 0] = xn
    x[polar] = 0.0
    return x


def _natural_map(W, q, mu, r, scale: float = 1.0) -> np.ndarray:
    """r − P_K(r − scale · û), û = W r + q + μ‖u_T‖ e_N, per contact (nc, 3)."""
    W = np.asarray(W, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64).reshape(-1)
    u = (W @ r + np.asarray(q, dtype=np.float64).reshape(-1)).reshape(-1, 3)
    mu = np.asarray(mu, dtype=np.float64).reshape(-1)
    r3 = r.reshape(-1, 3)
    u_hat = u.copy()
    u_hat[:, 0] += mu * np.hypot(u[:, 1], u[:, 2])
    return r3 - _project_on_cone(r3 - scale * u_hat, mu)


def fclib_merit(W: npt.ArrayLike, q: npt.ArrayLike, mu: npt.ArrayLike, r: npt.ArrayLike) -> float:
    """FCLIB's ``fclib_merit_local`` (MERIT_1, spacedim 3, no V/R): ‖r − P_K(r − û)‖ / (1 + sqrt‖q‖)."""
    nat = _natural_map(W, q, mu, r)
    return float(np.sqrt((nat ** 2).sum()) / (1.0 + np.sqrt(np.linalg.norm(q))))


def complementarity_error(W: npt.ArrayLike, q: npt.ArrayLike, mu: npt.ArrayLike, r: npt.ArrayLike, *,
                          rho: float | None = None) -> float:
    """Dimensionless natural-map error ‖r − P_K(r − ρ û)‖ / max(‖r‖, ρ‖q‖).

    ρ (force per length) defaults to 1 / mean(diag W). Zero exactly at solutions of FC(W, q, μ).
    """
    W = np.asarray(W, dtype=np.float64)
    if rho is None:
        rho = 1.0 / float(np.mean(np.diag(W)))
    nat = _natural_map(W, q, mu, r, rho)
    scale = max(np.linalg.norm(r), rho * np.linalg.norm(q), 1e-300)
    return float(np.linalg.norm(nat) / scale)


def coulomb_violations(W: npt.ArrayLike, q: npt.ArrayLike, mu: npt.ArrayLike, r: npt.ArrayLike) -> dict:
    """Readable violations of Coulomb's law at (u = W r + q, r), relative to max|r|, max|u|.

    penetration max(−u_N)/max|u|, tension max(−r_N)/max|r|, cone max(‖r_T‖ − μ r_N)/max|r|,
    normal complementarity max|r_N u_N|/(max|r| max|u|), stick max ‖u_T‖/max|u| over contacts
    strictly inside the cone (‖r_T‖ < μ r_N (1 − 1e-6), r_N > 1e-10 max|r|), slip direction
    max ‖r_T + μ r_N u_T/‖u_T‖‖ / max|r| over slipping contacts (‖u_T‖ > 1e-8 max|u|).
    """
    W = np.asarray(W, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64).reshape(-1)
    u = (W @ r + np.asarray(q, dtype=np.float64).reshape(-1)).reshape(-1, 3)
    r3 = r.reshape(-1, 3)
    mu = np.asarray(mu, dtype=np.float64).reshape(-1)
    R = max(np.abs(r3).max(initial=0.0), 1e-300)
    U = max(np.abs(u).max(initial=0.0), 1e-300)
    rT, uT = np.hypot(r3[:, 1], r3[:, 2]), np.hypot(u[:, 1], u[:, 2])
    active = r3[:, 0] > 1e-10 * R
    inside = active & (rT < mu * r3[:, 0] * (1 - 1e-6))
    slipping = uT > 1e-8 * U
    direction = r3[:, 1:] + (mu * r3[:, 0])[:, None] * u[:, 1:] / np.where(slipping, uT, 1.0)[:, None]
    return {
        "penetration": float(max(0.0, (-u[:, 0]).max(initial=0.0)) / U),
        "tension": float(max(0.0, (-r3[:, 0]).max(initial=0.0)) / R),
        "cone": float(max(0.0, (rT - mu * r3[:, 0]).max(initial=0.0)) / R),
        "normal_complementarity": float(np.abs(r3[:, 0] * u[:, 0]).max(initial=0.0) / (R * U)),
        "stick": float(uT[inside].max(initial=0.0) / U),
        "slip_direction": float(np.hypot(*direction[slipping].T).max(initial=0.0) / R),
        "contacts": {"open": int((~active).sum()), "stick": int(inside.sum()),
                     "slip": int((active & ~inside).sum())},
    }
