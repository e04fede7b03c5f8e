"""Checks run before solving, so that a configuration error is reported as itself.

A PETSc option that names an unknown or unavailable solver package makes PETSc fail at the first
factorisation; inside a Newton loop such a failure looks like "did not converge". Before a run
starts, :func:`check_direct_solver` factorises a tiny matrix with the run's options and lets
PETSc's error out as a :class:`PetscSetupError` (collective).
"""

from __future__ import annotations

from petsc4py import PETSc

from dolfinx_nnqem.numerics.linalg import clear_options, create_ksp, direct_options

__all__ = ["PetscSetupError", "check_direct_solver"]


class PetscSetupError(RuntimeError):
    """PETSc refused the linear solver the options ask for (the message says which error)."""

    def __init__(self, message: str, ierr: int):
        super().__init__(message)
        self.ierr = ierr


def check_direct_solver(comm, petsc_options: dict | None) -> None:
    """Factorise a small diagonal matrix with the direct-solver options (the package's defaults
    updated by ``petsc_options``) on ``comm``; raise :class:`PetscSetupError` if PETSc fails."""
    options = direct_options(petsc_options)
    prefix = "nnqem_preflight_"
    n = 3
    A = PETSc.Mat().createAIJ(((n, None), (n, None)), nnz=1, comm=comm)
    start, end = A.getOwnershipRange()
    for i in range(start, end):
        A.setValue(i, i, 1.0)
    A.assemble()
    ksp = create_ksp(comm, prefix, options)
    try:
        ksp.setOperators(A)
        ksp.setUp()
        b, x = A.createVecs()
        b.set(1.0)
        ksp.solve(b, x)
        b.destroy()
        x.destroy()
    except PETSc.Error as error:
        package = options.get("pc_factor_mat_solver_type", "")
        raise PetscSetupError(
            f"PETSc error {error.ierr} setting up the linear solver (pc_type = {options.get('pc_type')!r}, "
            f"solver package {package!r}); PETSc's own message is printed above", error.ierr) from None
    finally:
        clear_options(prefix, options)
        ksp.destroy()
        A.destroy()
