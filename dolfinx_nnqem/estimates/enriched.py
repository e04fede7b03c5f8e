"""Discretisation-error estimates from an enriched solve: the same load path on a richer space.

A run on degree-1 elements is solved again, along the same converged load factors, with
degree-2 elements on the same mesh (any cell type, any contact discretisation the package
supports on quadratic facets); a degree-2 run on tetrahedra is solved again on the uniformly
refined mesh. For every quantity Q a user reads (:mod:`dolfinx_nnqem.estimates.quantities`),

    e(Q_h) ≈ ‖Q_h − Q_enriched‖,

the estimate of the run's discretisation error. The enriched solution converges faster than the
run's (one order more in h for smooth solutions; for contact and plasticity, whose solutions are
only piecewise smooth, still a fraction of the run's error), so that the effectivity
e / ‖Q_h − Q‖ is 1 − ε with ε the ratio of the two errors (``docs/error-estimates.md`` gives
the measured effectivities and the cost). The same load factors are taken because friction and
plasticity make the solution depend on the load path (an increment the enriched solve cannot take
in one step is halved: the states at the run's load factors are compared).

A hexahedral mesh run at degree 2 has no enrichment here (DOLFINx refines simplices only and
the package has no degree 3): :func:`choose_enrichment` refuses it with the reason.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.estimates.quantities import Measure, ProbePoints, Quantities, read_quantities
from dolfinx_nnqem.estimates.refinement import refine_mesh_and_tags
from dolfinx_nnqem.problem.contact_problem import ContactProblem
from dolfinx_nnqem.solvers.convergence import ConvergenceError
from dolfinx_nnqem.solvers.registry import make_solver
from dolfinx_nnqem.solvers.stepping import solve_load_steps

if TYPE_CHECKING:
    import dolfinx.mesh

    from dolfinx_nnqem.solvers.checks import CheckOptions
    from dolfinx_nnqem.solvers.options import SolverOptions

__all__ = ["ENRICHMENTS", "ErrorEstimates", "QuantityEstimate", "choose_enrichment", "enriched_problem",
           "estimate_errors", "rebuild_problem"]

_log = logging.getLogger("dolfinx_nnqem")

ENRICHMENTS = ("auto", "degree-2", "refine")
"""``auto``: degree 2 for a degree-1 run, the uniformly refined mesh for a degree-2 run (tetrahedra);
``degree-2``: degree 2 on the same mesh; ``refine``: the same degree on the uniformly refined mesh
(tetrahedra only)."""


def choose_enrichment(problem: ContactProblem, enrichment: str = "auto") -> str:
    """The enrichment that applies to ``problem`` (``degree-2`` or ``refine``), or a clear refusal.

    Raises
    ------
    ValueError
        An unknown ``enrichment``; ``degree-2`` for a degree-2 run; ``refine`` (or ``auto`` at
        degree 2) on a mesh that is not tetrahedral.
    """
    if enrichment not in ENRICHMENTS:
        raise ValueError(f"enrichment = {enrichment!r}; expected one of {ENRICHMENTS}")
    degree = problem.definition.degree
    if enrichment == "auto":
        enrichment = "degree-2" if degree == 1 else "refine"
    if enrichment == "degree-2" and degree != 1:
        raise ValueError("enrichment = 'degree-2': the run is degree 2 already (the package has no degree 3); "
                         "on tetrahedra use enrichment = 'refine'")
    cell = problem.mesh.topology.cell_name()
    if enrichment == "refine" and cell != "tetrahedron":
        raise ValueError(f"enrichment = 'refine' needs a tetrahedral mesh, this one has {cell} cells: DOLFINx "
                         "refines simplex meshes only. A degree-2 run on hexahedra has no enriched solve; run it "
                         "at degree 1 to get the estimate from degree 2, or mesh it with tetrahedra")
    return enrichment


def rebuild_problem(problem: ContactProblem, mesh: dolfinx.mesh.Mesh, cell_tags: dolfinx.mesh.MeshTags | None,
                    facet_tags: dolfinx.mesh.MeshTags | None, degree: int) -> ContactProblem:
    """``problem``'s definition (materials, supports, loads, contact) on another mesh or degree."""
    d = problem.definition
    return ContactProblem(
        mesh, cell_tags, facet_tags, materials=d.materials, dirichlet=d.dirichlet, tractions=d.tractions,
        body_forces=d.body_forces, contact=list(d.contact) or None, degree=degree,
        quadrature_degree=d.quadrature_degree if degree == d.degree else None, kinematics=d.kinematics)


def enriched_problem(problem: ContactProblem, enrichment: str = "auto") -> ContactProblem:
    """The enriched problem (see :func:`choose_enrichment`), unsolved."""
    kind = choose_enrichment(problem, enrichment)
    if kind == "degree-2":
        return rebuild_problem(problem, problem.mesh, problem.cell_tags, problem.facet_tags, 2)
    mesh, cell_tags, facet_tags = refine_mesh_and_tags(problem.mesh, problem.cell_tags, problem.facet_tags)
    return rebuild_problem(problem, mesh, cell_tags, facet_tags, problem.definition.degree)


@dataclass(frozen=True)
class QuantityEstimate:
    """One quantity with its discretisation-error estimate."""

    name: str
    value: np.ndarray  #: the run's value Q_h
    enriched: np.ndarray  #: the enriched solve's value
    estimate: float  #: ‖Q_h − Q_enriched‖
    components: np.ndarray  #: |Q_h − Q_enriched| per component
    relative: float | None  #: estimate / reference (None when the reference is 0 and the estimate is not)
    reference: float  #: ‖Q_enriched‖, or its family's largest where that is round-off (:data:`NEGLIGIBLE`)

    def as_dict(self) -> dict:
        """This quantity's entry in the ``quantities`` of ``summary.json``'s ``error_estimates``
        (``docs/outputs.md``)."""
        return {"name": self.name, "value": self.value.tolist(), "enriched": self.enriched.tolist(),
                "estimate": float(self.estimate), "estimate_components": self.components.tolist(),
                "relative": self.relative, "reference": self.reference}


FAMILIES = {"contact": "force", "reaction": "force", "u": "displacement"}
"""Quantities measured against a common scale: a force that vanishes (a reaction component set
by statics, an open interface) is measured against the largest force, not against its own
round-off."""

NEGLIGIBLE = 1e-9
"""A quantity smaller than this times its family's largest is a zero (round-off)."""


def _family(name: str) -> str:
    kind = name.split(":")[0]
    return FAMILIES.get(kind, name)


def _references(fine: Quantities) -> dict[str, float]:
    """The norm each quantity's relative estimate refers to: its own, or its family's largest
    where its own is negligible."""
    largest: dict[str, float] = {}
    for name, value in fine.items():
        largest[_family(name)] = max(largest.get(_family(name), 0.0), float(np.linalg.norm(value)))
    references = {}
    for name, value in fine.items():
        own, family = float(np.linalg.norm(value)), largest[_family(name)]
        references[name] = own if own > NEGLIGIBLE * family else family
    return references


def _relative(estimate: float, reference: float) -> float | None:
    if reference > 0.0:
        return estimate / reference
    return 0.0 if estimate == 0.0 else None


@dataclass
class ErrorEstimates:
    """The estimates of a run: every quantity, the method and its cost."""

    method: str  #: how the estimates were made, e.g. ``"enriched solve: degree 2 on the same mesh"``
    enrichment: str  #: ``degree-2`` or ``refine``
    quantities: list[QuantityEstimate]
    dofs: int  #: displacement dofs of the run
    enriched_dofs: int  #: displacement dofs of the enriched solve
    enriched_time_s: float  #: wall time of the enriched solve (build + solve)
    run_time_s: float | None = None  #: wall time of the run, when the caller knows it
    enriched_solver: str = ""  #: the method that solved the enriched problem
    note: str | None = None  #: why that is not the run's method, when it is not

    @classmethod
    def compare(cls, coarse: Quantities, fine: Quantities, **fields: Any) -> ErrorEstimates:
        """The estimates from the run's quantities and the enriched solve's (same names)."""
        items = []
        references = _references(fine)
        for name, value in coarse.items():
            if name not in fine:
                continue
            diff = np.abs(value - fine[name])
            estimate = float(np.linalg.norm(diff))
            items.append(QuantityEstimate(name, value, fine[name], estimate, diff,
                                          _relative(estimate, references[name]), references[name]))
        return cls(quantities=items, **fields)

    def __getitem__(self, name: str) -> QuantityEstimate:
        for q in self.quantities:
            if q.name == name:
                return q
        raise KeyError(f"no quantity {name!r}; the estimates have {[q.name for q in self.quantities]}")

    def max_relative(self) -> float:
        """The largest relative estimate (a quantity whose enriched value is 0 but whose estimate is
        not counts as infinite)."""
        return max((np.inf if q.relative is None else q.relative for q in self.quantities), default=0.0)

    def cost(self) -> float | None:
        """Wall time of the enriched solve over the run's (None when the run's is unknown)."""
        if not self.run_time_s:
            return None
        return self.enriched_time_s / self.run_time_s

    def as_dict(self) -> dict:
        """The ``error_estimates`` entry of ``summary.json`` (``docs/outputs.md``)."""
        return {"method": self.method, "enrichment": self.enrichment, "dofs": self.dofs,
                "enriched_dofs": self.enriched_dofs, "enriched_time_s": self.enriched_time_s,
                "run_time_s": self.run_time_s, "cost": self.cost(), "max_relative": _finite(self.max_relative()),
                "enriched_solver": self.enriched_solver, "note": self.note,
                "quantities": [q.as_dict() for q in self.quantities]}


def _finite(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def num_dofs(problem: ContactProblem) -> int:
    """Number of displacement dofs of ``problem`` over all ranks."""
    imap = problem.V.dofmap.index_map
    return int(imap.size_global * problem.V.dofmap.index_map_bs)


def estimate_errors(problem: ContactProblem, method: str, load_factors: Sequence[float], *,
                    probes: ProbePoints | None = None, enrichment: str = "auto", options: SolverOptions | None = None,
                    method_options: dict | None = None, run_time_s: float | None = None,
                    enriched: ContactProblem | None = None, extra: Measure | None = None,
                    check: CheckOptions | None = None) -> ErrorEstimates:
    """Estimate the discretisation error of every quantity of a solved run (collective).

    Parameters
    ----------
    problem
        The run's problem, in its converged final state (it is not changed).
    method
        The solver of the enriched solve (``monolithic``, ``nneqm1``, ``nneqm2``): the run's. Where
        it does not converge on the enriched problem, the monolithic solver solves it (the same
        discrete problem) and :attr:`ErrorEstimates.note` says so.
    load_factors
        The run's converged load factors, in order: the enriched solve takes the same path.
    probes
        Named points whose displacement is a quantity.
    enrichment
        See :data:`ENRICHMENTS`.
    options, method_options
        The solver options (as :func:`~dolfinx_nnqem.solvers.registry.make_solver` takes them).
    run_time_s
        The run's wall time, to state the estimate's cost relative to it.
    enriched
        An enriched problem of the caller's, unsolved, instead of :func:`enriched_problem` (e.g.
        the same geometry meshed finer by its generator: how a hexahedral degree-2 run gets its
        estimate); the caller keeps it (solved on return) and destroys it.
    extra
        Further quantities of the caller's, measured alike on both (see
        :data:`~dolfinx_nnqem.estimates.quantities.Measure`).
    check
        The run's :class:`~dolfinx_nnqem.solvers.checks.CheckOptions` of the independent check
        (default: the solver's).

    Raises
    ------
    ValueError
        No enrichment applies (:func:`choose_enrichment`), or no load factors.
    ConvergenceError
        The enriched solve did not converge at one of the load factors.
    """
    if len(load_factors) == 0:
        raise ValueError("estimate_errors: no load factors (the run converged no increment)")
    kind = "given" if enriched is not None else choose_enrichment(problem, enrichment)
    coarse = read_quantities(problem, probes, extra)
    t0 = time.perf_counter()
    solver_used, note = method, None
    fine_problem = enriched if enriched is not None else enriched_problem(problem, kind)
    try:
        try:
            _solve_path(fine_problem, method, load_factors, options, method_options, check)
        except ConvergenceError as error:
            if enriched is not None or method == "monolithic":
                raise
            # the enriched problem is the same discrete problem whichever method solves it: where the
            # run's method fails on it, the monolithic solver makes the estimate, and the estimate says so
            reason = str(error).splitlines()[0] if str(error) else type(error).__name__
            note = (f"{method} did not converge on the enriched problem ({reason[:200]}); "
                    "the monolithic solver solved it")
            _log.warning(f"error estimate: {note}")
            fine_problem.destroy()
            fine_problem = enriched_problem(problem, kind)
            solver_used = "monolithic"
            _solve_path(fine_problem, solver_used, load_factors, options, method_options, check)
        fine = read_quantities(fine_problem, probes, extra)
        enriched_dofs = num_dofs(fine_problem)
    finally:
        if enriched is None:
            fine_problem.destroy()
    elapsed = problem.comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    return ErrorEstimates.compare(coarse, fine, method=_method_text(kind, problem.definition.degree, enriched_dofs),
                                  enrichment=kind, dofs=num_dofs(problem), enriched_dofs=enriched_dofs,
                                  enriched_time_s=elapsed, run_time_s=run_time_s, enriched_solver=solver_used,
                                  note=note)


MAX_CUTBACKS = 6
"""Halvings allowed per increment of the enriched solve: a finer space may need smaller steps than
the run took; the converged states are still those at the run's load factors."""


def _solve_path(problem: ContactProblem, method: str, load_factors: Sequence[float], options,
                method_options: dict | None, check) -> None:
    """Solve ``problem`` to each of the run's ``load_factors`` in turn, each in one increment or,
    where that does not converge, in halved ones (:data:`MAX_CUTBACKS`)."""
    with make_solver(method, problem, options, **(method_options or {})) as solver:
        for target in load_factors:
            solve_load_steps(problem, solver, 1, final_load_factor=float(target), max_cutbacks=MAX_CUTBACKS,
                             check=check)


def _method_text(kind: str, degree: int, enriched_dofs: int) -> str:
    if kind == "degree-2":
        return "enriched solve: degree 2 on the same mesh"
    if kind == "refine":
        return f"enriched solve: degree {degree} on the uniformly refined mesh"
    return f"enriched solve: the given finer problem ({enriched_dofs} dofs)"
