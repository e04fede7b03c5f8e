"""Checks run before solving, so that a configuration error is reported as itself.

A PETSc option that names an unknown or unavailable solver package makes PETSc fail at the first
factorisation; inside a Newton loop such a failure looks like "did not converge". Before a run
starts, :func:`check_direct_solver` factorises a tiny matrix with the run's options and lets
PETSc's error out as a :class:`PetscSetupError` (collective).

A combination that is known to fail after cutbacks is refused before the first increment, with
what to use instead: :func:`check_iterative_contact` (the monolithic solver's iterative linear
solver with the polar law on degree-2 surface pairs with friction).
"""

from __future__ import annotations

from petsc4py import PETSc

from dolfinx_nnqem.numerics.linalg import clear_options, create_ksp, direct_options, relative_residual

__all__ = ["PetscSetupError", "check_direct_solver", "check_iterative_contact"]


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


SURFACE_PAIRS = ("node-to-surface", "mortar")
"""The pair sets whose rows couple a slave node to the nodes of master facets."""


def check_iterative_contact(problem, linear_solver: str, iterative: bool) -> None:
    """Refuse the iterative linear solver (FGMRES, Schur field split, AMG) where it is known to
    fail: an interface with the polar law, friction and node-to-surface or mortar pairs on
    degree-2 elements. At the slip onset of the Q2 block slide its Krylov solves stop at 3e-2 to
    1e-1 of the right-hand side (the pair block's ``selfp`` Schur approximation; ``docs/theory.md``,
    "A known failure"), and the run ends after cutbacks. Raises ValueError naming the interface,
    how the iterative solver was chosen (``linear_solver``: "iterative", or "auto" for a
    large problem) and the two remedies: the direct linear
    solver or the Alart–Curnier law, with which the same slide converges."""
    if not iterative:  # the solver's choice (for "auto": by the problem's size)
        return
    chosen_by = 'linear_solver = "auto" chose it' if linear_solver == "auto" else f'linear_solver = "{linear_solver}"'
    model = problem.contact
    if model is None or problem.definition.degree != 2:
        return
    for interface in model.interfaces:
        if (interface.law.name == "polar" and interface.contact.mu_f > 0
                and interface.pairs.kind in SURFACE_PAIRS):
            raise ValueError(
                f"contact {interface.contact.label}: the polar law with friction (mu_f = {interface.contact.mu_f:g}) on "
                f"degree-2 {interface.pairs.kind} pairs is not supported by the iterative linear solver ({chosen_by}): "
                "its Krylov solves stall at the slip onset and the run would end after cutbacks (docs/theory.md, "
                "'A known failure'). Use linear_solver = \"direct\" (MUMPS) or law = \"alart-curnier\"")
