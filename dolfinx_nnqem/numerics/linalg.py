"""Small PETSc helpers shared by the solvers."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

DIRECT_SOLVER_OPTIONS = {
    "ksp_type": "preonly",
    "pc_type": "lu",
    "pc_factor_mat_solver_type": "mumps",
}
"""Default: MUMPS LU. User ``petsc_options`` are merged over these."""


def free_dropped_objects(comms) -> None:
    """Destroy the PETSc objects dropped on each of ``comms`` since the last call (collective).

    On more than one rank, petsc4py does not destroy a Vec or Mat when its last Python reference
    goes: destruction is collective, so the object waits on its communicator's garbage list
    until every rank calls ``PETSc.garbage_cleanup`` on that communicator. The list belongs to
    the object's own communicator (DOLFINx duplicates the mesh's for index maps, hence
    vectors). A Newton loop drops a few vectors and the block matrices at every iteration;
    without this call they pile up. Every rank must call it at the same point of the loop.

    Parameters
    ----------
    comms
        The communicators (mpi4py or PETSc) of the objects that may have been dropped, e.g.
        :attr:`dolfinx_nnqem.problem.contact_problem.ContactProblem.petsc_comms`.
    """
    for comm in comms:
        if comm.size > 1:
            PETSc.garbage_cleanup(comm)


def create_ksp(comm, prefix: str, options: dict) -> PETSc.KSP:
    """A KSP configured from ``options`` under ``prefix`` (``setFromOptions``).

    The options stay in PETSc's database until :func:`clear_options` is called: sub-solvers
    (a factorisation's MUMPS controls, fieldsplit blocks) read theirs at the first ``setUp``,
    so call it after that.
    """
    opts = PETSc.Options()
    for key, value in options.items():
        opts.setValue(prefix + key, value)  # what opts[name] = value calls (petsc4py's stub has no __setitem__)
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    ksp.setFromOptions()
    return ksp


def clear_options(prefix: str, options: dict) -> None:
    """Remove ``options`` under ``prefix`` from PETSc's database (as DOLFINx's solvers do)."""
    opts = PETSc.Options()
    for key in options:
        if opts.hasName(prefix + key):
            opts.delValue(prefix + key)


@contextmanager
def products_without_intermediates() -> Iterator[None]:
    """Within: the sparse matrix products PETSc creates drop their intermediate data after their
    numeric phase (the global option ``mat_product_clear``, restored on leaving).

    For an AMG set-up in the ``with`` block. GAMG's Galerkin products PᵀAP keep, by default,
    what a later product of the same pattern would reuse (AP, Pᵀ and the local parts of P): on
    the pressed blocks a tenth of the peak memory (``docs/performance.md``). The lagged
    hierarchy of :class:`~dolfinx_nnqem.solvers.linear_solver.IterativeSolver` is rebuilt after
    many Newton iterations, and GAMG then makes its products anew when they carry no data (it
    reuses only products that do). Only products made inside the block are affected: a caller's
    own products, which it may reuse, keep theirs (a reuse of a cleared product crashes PETSc).
    """
    opts = PETSc.Options()
    key = "mat_product_clear"
    before = opts.getString(key) if opts.hasName(key) else None
    opts.setValue(key, "true")
    try:
        yield
    finally:
        if before is None:
            opts.delValue(key)
        else:
            opts.setValue(key, before)


def relative_residual(J: PETSc.Mat, x: PETSc.Vec, b: PETSc.Vec) -> float:
    """‖J x − b‖ / ‖b‖ (collective; ‖J x‖ for b = 0)."""
    r = b.duplicate()
    J.mult(x, r)
    r.axpy(-1.0, b)
    norm_b = vec_norm(b)
    residual = vec_norm(r) / norm_b if norm_b > 0 else vec_norm(r)
    r.destroy()
    return residual


def direct_options(petsc_options: dict | None, ranks: int = 1) -> dict:
    """:data:`DIRECT_SOLVER_OPTIONS` (with MUMPS's ordering of
    :func:`~dolfinx_nnqem.compat.parallel_mumps_ordering` on more than one rank) updated by the
    user's ``petsc_options``."""
    options = {**DIRECT_SOLVER_OPTIONS, **(petsc_options or {})}
    if ranks > 1 and options.get("pc_factor_mat_solver_type") == "mumps":
        from dolfinx_nnqem import compat

        options = {**compat.parallel_mumps_ordering(), **options}  # METIS, or PORD where PETSc has no METIS
    return options


def factorise(ksp: PETSc.KSP, A: PETSc.Mat, solver: str, what: str) -> None:
    """Set ``A`` on ``ksp`` and factorise it; a failed factorisation becomes a clear ValueError."""
    ksp.setOperators(A)
    try:
        ksp.setUp()
    except PETSc.Error as error:
        raise ValueError(
            f"{solver}: the factorisation of {what} failed (PETSc error {error.ierr}); "  # type: ignore[attr-defined]  # petsc4py's stub lacks Error.ierr
            "the matrix is singular or the solver package is unavailable"
        ) from error


def vec_norm(vec: PETSc.Vec) -> float:
    """The 2-norm of a PETSc vector (collective).

    ``Vec.norm()`` returns a float for the default 2-norm; petsc4py's stub types it
    ``float | tuple[float, float]`` for every norm type (NORM_1_AND_2 returns the pair).
    """
    return vec.norm()  # type: ignore[return-value]  # the 2-norm is a float (see above)


def global_norm(array: np.ndarray, comm) -> float:
    """2-norm of an array distributed over ``comm`` (each rank holds its own rows)."""
    return math.sqrt(comm.allreduce(float(np.sum(np.asarray(array) ** 2)), op=MPI.SUM))


ITERATIVE_SOLVER_OPTIONS = {
    # Newton matrix [[K, −BᵀΛ'], [∂_wH·B, ∂_zH]]: FGMRES, Schur-complement fieldsplit
    "ksp_type": "fgmres",
    "ksp_rtol": 1e-12,  # the floor; each Newton step sets its own tolerance (inexact Newton)
    "ksp_atol": 1e-50,
    "ksp_max_it": 1000,
    "ksp_gmres_restart": 30,  # FGMRES keeps 2 vectors per iteration: bounded memory on large meshes
    "pc_type": "fieldsplit",
    "pc_fieldsplit_type": "schur",
    "pc_fieldsplit_schur_fact_type": "lower",
    "pc_fieldsplit_schur_precondition": "selfp",
    "fieldsplit_u_ksp_type": "preonly",
    "fieldsplit_u_pc_type": "gamg",
    "fieldsplit_u_pc_gamg_threshold": 0.01,
    "fieldsplit_u_mg_levels_ksp_type": "chebyshev",
    "fieldsplit_u_mg_levels_pc_type": "jacobi",
    "fieldsplit_z_ksp_type": "preonly",
    "fieldsplit_z_pc_type": "lu",
}
"""For large meshes (``SolverOptions(linear_solver="iterative")``), on the augmented Newton
matrix of :class:`dolfinx_nnqem.solvers.block_system.AugmentedSystem`: nothing factorises the u block.
It gets one V-cycle of smoothed-aggregation AMG (GAMG) with the rigid-body near-nullspace; the
Schur complement on the pair unknowns is approximated by A11 − A10 diag(A00)⁻¹ A01 ("selfp")
and factorised (3 rows per pair). ``ksp_rtol`` is the floor of the inexact-Newton tolerance."""

ITERATIVE_NO_CONTACT_OPTIONS = {
    "ksp_type": "cg",
    "ksp_rtol": 1e-9,
    "ksp_max_it": 1000,
    "pc_type": "gamg",
    "pc_gamg_threshold": 0.01,
    "mg_levels_ksp_type": "chebyshev",
    "mg_levels_pc_type": "jacobi",
}
"""Without contact: CG + GAMG on K_t (symmetric: associated plasticity, consistent tangent)."""

ITERATIVE_NO_CONTACT_UNSYMMETRIC_OPTIONS = {**ITERATIVE_NO_CONTACT_OPTIONS, "ksp_type": "gmres", "ksp_gmres_restart": 30}
"""Without contact, for an unsymmetric K_t (non-associated flow, Armstrong–Frederick back-stresses):
GMRES instead of CG, which assumes a symmetric matrix."""

SYMMETRIC_ONLY_OPTIONS = {"pc_type": ("cholesky", "icc"), "ksp_type": ("cg", "minres", "cr", "symmlq")}
"""PETSc options (any prefix, e.g. ``fieldsplit_u_pc_type``) whose values assume a symmetric matrix:
refused for an unsymmetric tangent (:func:`dolfinx_nnqem.solvers.registry.make_solver`); MUMPS
then factorises with its unsymmetric LU (the default ``pc_type = "lu"``)."""


def rigid_body_modes(V) -> PETSc.NullSpace:
    """The six rigid-body displacements of a 3D vector space, as an orthonormal PETSc near-nullspace.

    Built from the dof coordinates (translations and infinitesimal rotations about the centroid),
    orthonormalised across ranks, for smoothed-aggregation AMG.
    """
    from dolfinx_nnqem import compat

    imap = V.dofmap.index_map
    n = imap.size_local
    x = V.tabulate_dof_coordinates()[:n]
    centre = np.asarray(V.mesh.comm.allreduce(x.sum(axis=0), op=MPI.SUM)) / max(imap.size_global, 1)
    x = x - centre
    modes = []
    for k in range(6):
        v = compat.create_vector(V)
        a = v.getArray().reshape(-1, 3)
        a[:] = 0.0
        if k < 3:
            a[:, k] = 1.0
        elif k == 3:  # rotation about z: (−y, x, 0)
            a[:, 0], a[:, 1] = -x[:, 1], x[:, 0]
        elif k == 4:  # about x: (0, −z, y)
            a[:, 1], a[:, 2] = -x[:, 2], x[:, 1]
        else:  # about y: (z, 0, −x)
            a[:, 0], a[:, 2] = x[:, 2], -x[:, 0]
        modes.append(v)
    # Gram–Schmidt (PETSc's NullSpace wants an orthonormal basis)
    for i, v in enumerate(modes):
        for w in modes[:i]:
            v.axpy(-v.dot(w), w)
        v.normalize()
    return PETSc.NullSpace().create(vectors=modes, comm=V.mesh.comm)
