"""The solver contract: what load stepping, writers and users may use of a solver.

A solver takes a :class:`~dolfinx_nnqem.problem.ContactProblem` and solves one load increment
at a time; :func:`~dolfinx_nnqem.solvers.stepping.solve_load_steps` drives it. Every solver of
the package satisfies :class:`Solver` (checked by the type checker and by
``tests/test_contracts.py``), and frees its PETSc objects when used as a context manager::

    with make_solver("monolithic", problem) as solver:
        solve_load_steps(problem, solver, 15)
"""

from __future__ import annotations

from types import TracebackType
from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    from dolfinx_nnqem.solvers.convergence import SolveReport
    from dolfinx_nnqem.solvers.options import SolverOptions

__all__ = ["ReleasesPETSc", "Solver"]


@runtime_checkable
class Solver(Protocol):
    """What load stepping, writers and users may use of a solver."""

    name: str  #: "monolithic", "nneqm1" or "nneqm2"
    options: SolverOptions  #: the tolerances the independent check derives its own from

    @property
    def timings(self) -> dict[str, float]:
        """Seconds per phase, accumulated over the run."""
        ...

    def solve_increment(self, load_factor: float) -> SolveReport:
        """Solve for the load factor ``load_factor`` from the last converged state.

        The problem's iterate (u, z) is left at the solution (or the last iterate if the
        report says it did not converge); the problem's converged state is not touched: the
        caller commits (with ``report.gauss_point_values``) or restores.
        """
        ...

    def destroy(self) -> None:
        """Free the solver's PETSc objects."""
        ...

    def __enter__(self) -> Solver: ...

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None: ...


class ReleasesPETSc:
    """``with solver: ...`` calls ``solver.destroy()`` at the end, as DOLFINx's own solvers do."""

    def destroy(self) -> None:  # pragma: no cover - every solver defines its own
        raise NotImplementedError

    def __enter__(self):
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.destroy()
