"""The solvers by name: :func:`make_solver`."""

from __future__ import annotations

from dolfinx_nnqem.numerics.linalg import SYMMETRIC_ONLY_OPTIONS
from dolfinx_nnqem.problem.contact_problem import ContactProblem
from dolfinx_nnqem.solvers.contract import Solver
from dolfinx_nnqem.solvers.options import (METHODS, MonolithicOptions, NNEQM1Options, NNEQM2Options,
                                           SolverOptions)

__all__ = ["make_solver"]

_OPTIONS = {"monolithic": MonolithicOptions, "nneqm1": NNEQM1Options, "nneqm2": NNEQM2Options}


def _solver_class(method: str) -> type:
    """The class of ``method``, imported when it is chosen (a run imports one solver's modules)."""
    if method == "monolithic":
        from dolfinx_nnqem.solvers.monolithic import MonolithicSolver

        return MonolithicSolver
    if method == "nneqm1":
        from dolfinx_nnqem.solvers.nneqm1 import NNEQM1Solver

        return NNEQM1Solver
    from dolfinx_nnqem.solvers.nneqm2 import NNEQM2Solver

    return NNEQM2Solver


def make_solver(method: str, problem: ContactProblem, options: SolverOptions | None = None,
                **method_options: MonolithicOptions | NNEQM1Options | NNEQM2Options) -> Solver:
    """The solver called ``method`` ("monolithic", "nneqm1", "nneqm2") for ``problem``.

    Parameters
    ----------
    method
        The method's name (case does not matter).
    problem
        The :class:`~dolfinx_nnqem.problem.ContactProblem` to solve.
    options
        :class:`~dolfinx_nnqem.solvers.options.SolverOptions`, what every solver shares.
    method_options
        The chosen method's own options, by its name: ``monolithic=MonolithicOptions(...)``,
        ``nneqm1=NNEQM1Options(...)`` or ``nneqm2=NNEQM2Options(...)``.

    Raises
    ------
    TypeError
        An argument of the wrong type, named (e.g. a ``MonolithicOptions`` given as ``options``).
    ValueError
        An unknown method, or options of another method.
    """
    if not isinstance(method, str):
        raise TypeError(f"make_solver: method = {method!r} must be a str, one of {list(METHODS)}")
    method = method.lower()
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {list(METHODS)}")
    if not isinstance(problem, ContactProblem):
        raise TypeError(f"make_solver: problem must be a ContactProblem, got {type(problem).__name__}")
    if options is not None and not isinstance(options, SolverOptions):
        raise TypeError(f"make_solver: options must be a SolverOptions, got {type(options).__name__}"
                        + _where_it_goes(options))
    unknown = sorted(set(method_options) - {method})
    if unknown:
        raise ValueError(f"make_solver({method!r}): options {unknown} belong to another method")
    options_class = _OPTIONS[method]
    own = method_options.get(method)
    if own is not None and not isinstance(own, options_class):
        raise TypeError(f"make_solver: {method}= must be a {options_class.__name__}, got {type(own).__name__}"
                        + _where_it_goes(own))
    refuse_symmetric_options(problem, options)
    return _solver_class(method)(problem, options, own)


def refuse_symmetric_options(problem: ContactProblem, options: SolverOptions | None) -> None:
    """Raise, naming the option, if the problem's tangent is unsymmetric (non-associated flow,
    Armstrong–Frederick back-stresses) and ``petsc_options`` assume a symmetric matrix
    (:data:`~dolfinx_nnqem.numerics.linalg.SYMMETRIC_ONLY_OPTIONS`)."""
    petsc_options = (options.petsc_options if options is not None else None) or {}
    if problem.state.symmetric_tangent:
        return
    for key, value in petsc_options.items():
        assumes = [values for name, values in SYMMETRIC_ONLY_OPTIONS.items() if str(key).endswith(name)]
        if assumes and str(value).lower() in assumes[0]:
            raise ValueError(
                f"petsc_options {key} = {value!r} assumes a symmetric matrix, but the problem's consistent tangent is "
                "unsymmetric (a material with non-associated flow or Armstrong–Frederick back-stresses): use LU "
                "(pc_type = 'lu', the default, with MUMPS) and GMRES-type Krylov methods (docs/materials.md)")


def _where_it_goes(value: object) -> str:
    """A hint naming the keyword that takes ``value``'s type, if it is some method's options."""
    for name, options_class in _OPTIONS.items():
        if isinstance(value, options_class):
            return f" (a {options_class.__name__} goes in {name}={options_class.__name__}(...))"
    if isinstance(value, SolverOptions):
        return " (SolverOptions go in options=SolverOptions(...))"
    return ""
