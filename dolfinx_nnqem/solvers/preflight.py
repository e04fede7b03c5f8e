"""Checks run before solving, so that a configuration error is reported as itself.

A PETSc option that names an unknown or unavailable solver package makes PETSc fail at the first
factorisation; inside a Newton loop such a failure looks like "did not converge". Before a run
starts, :func:`check_direct_solver` factorises a tiny matrix with the run's options and lets
PETSc's error out as a :class:`PetscSetupError` (collective).
"""

from __future__ import annotations

from petsc4py import PETSc

from dolfinx_nnqem.numerics.linalg import clear_options, create_ksp, direct_options, relative_residual

__all__ = ["PetscSetupError", "check_direct_solver"]


class PetscSetupError(RuntimeError):
    """PETSc refused the linear solver the options ask for (the message says which error)."""

    def __init__(self, message: str, ierr: int):
        super().__init__(message)
        self.ierr = ierr


PREFLIGHT_RTOL = 1e-10
"""The test system must be solved to this relative residual: a direct solve reaches 1e-16."""


def check_direct_solver(comm, petsc_options: dict | None) -> None:
    """Solve a small tridiagonal system with the direct-solver options (the package's defaults
    updated by ``petsc_options``) on ``comm``; raise :class:`PetscSetupError` if PETSc fails,
    and ValueError naming the options if the solve is not a solve (e.g. ``pc_type = "none"``
    with the default ``ksp_type = "preonly"`` returns the right-hand side: the Newton
    iterations then stall with no hint of the cause, issue 31)."""
    options = direct_options(petsc_options)
    prefix = "nnqem_preflight_"
    n = 4  # tridiagonal (−1, 2, −1) + 1: not the identity, which any preconditioner "solves"
    A = PETSc.Mat().createAIJ(((None, n), (None, n)), nnz=3, comm=comm)
    start, end = A.getOwnershipRange()
    for i in range(start, end):
        A.setValue(i, i, 3.0)
        for j in (i - 1, i + 1):
            if 0 <= j < n:
                A.setValue(i, j, -1.0)
    A.assemble()
    ksp = create_ksp(comm, prefix, options)
    b, x = A.createVecs()  # type: ignore[misc]  # petsc4py's stub: Vec | tuple; without a side it is the pair
    try:
        ksp.setOperators(A)
        ksp.setUp()
        b.set(1.0)
        ksp.solve(b, x)
        residual = relative_residual(A, x, b)
    except PETSc.Error as error:
        package = options.get("pc_factor_mat_solver_type", "")
        raise PetscSetupError(
            f"PETSc error {error.ierr} setting up the linear solver (pc_type = {options.get('pc_type')!r}, "  # type: ignore[attr-defined]  # petsc4py's stub lacks Error.ierr
            f"solver package {package!r}); PETSc's own message is printed above", error.ierr) from None  # type: ignore[attr-defined]  # as above
    finally:
        clear_options(prefix, options)
        for obj in (ksp, A, b, x):
            obj.destroy()
    if not residual <= PREFLIGHT_RTOL:
        given = {k: v for k, v in (petsc_options or {}).items()}
        raise ValueError(
            f"[solver.petsc_options] {given}: the linear solver they make does not solve a 4 x 4 test system "
            f"(relative residual {residual:.2g} > {PREFLIGHT_RTOL:g}; ksp_type = {options.get('ksp_type')!r}, "
            f"pc_type = {options.get('pc_type')!r}): every Newton step would be wrong and the iterations stall. "
            "The solvers need a direct solve: leave pc_type out (LU) or use pc_type = \"lu\" or \"cholesky\"")
