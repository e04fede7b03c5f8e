"""The seed benchmark: two overlapping cantilever beams (``benchmark-two-beams.md``).

Beam 1 (x ∈ [0, 2], y ∈ [0, 0.4]) is clamped at x = 0, beam 2 (x ∈ [1.6, 3.6],
y ∈ [0.4, 0.8]) at x = 3.6; they touch on y = 0.4 over x ∈ [1.6, 2.0] through 9 node pairs.
Traction (1e5, −1e5, 0.5e5) Pa on beam 2's top and self-weight, all × ℓ, ℓ: 0 → 1.

:func:`run_two_beams` builds the problem, solves it with one method and writes the results;
:func:`format_tables` prints tables like the seed's tables 1–3.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.material.von_mises import VonMises
from dolfinx_nnqem.cases.geometries import TwoBeamsTags as T
from dolfinx_nnqem.cases.geometries import build_two_beams
from dolfinx_nnqem.problem.contact_problem import Contact, ContactProblem, Dirichlet, Gravity, Traction
from dolfinx_nnqem.estimates.indicators import RecoveryIndicator
from dolfinx_nnqem.io.output import ResultsWriter
from dolfinx_nnqem.solvers.contract import contact_model
from dolfinx_nnqem.solvers.options import SolverOptions
from dolfinx_nnqem.solvers.registry import make_solver
from dolfinx_nnqem.solvers.stepping import IncrementResult, solve_load_steps

MATERIAL = VonMises(E=2.0e10, nu=0.17, sigma_y0=5.0e5, H=2.0e10, density=2400.0)
MU_F = 0.5
TRACTION = (1.0e5, -1.0e5, 0.5e5)
GRAVITY = (0.0, -9.81, 0.0)

FREE_END_CORNERS = {
    # beam 1's free end x = 2.0 and beam 2's free end x = 1.6 (node of that beam)
    "beam1 x=2.0 y=0.0 z=0.0": ((2.0, 0.0, 0.0), T.BODY1),
    "beam1 x=2.0 y=0.0 z=0.4": ((2.0, 0.0, 0.4), T.BODY1),
    "beam1 x=2.0 y=0.4 z=0.0": ((2.0, 0.4, 0.0), T.BODY1),
    "beam1 x=2.0 y=0.4 z=0.4": ((2.0, 0.4, 0.4), T.BODY1),
    "beam2 x=1.6 y=0.4 z=0.0": ((1.6, 0.4, 0.0), T.BODY2),
    "beam2 x=1.6 y=0.4 z=0.4": ((1.6, 0.4, 0.4), T.BODY2),
    "beam2 x=1.6 y=0.8 z=0.0": ((1.6, 0.8, 0.0), T.BODY2),
    "beam2 x=1.6 y=0.8 z=0.4": ((1.6, 0.8, 0.4), T.BODY2),
}

DEFAULT_LAW = {"monolithic": "alart-curnier", "nneqm1": "polar", "nneqm2": "polar"}
"""NNEQM1/NNEQM2 use the seed's polar law by default (fidelity); the monolithic solver the
Cartesian law (robust, fewer iterations). Both give the same solution (V10)."""


def two_beams_problem(comm: MPI.Comm = MPI.COMM_WORLD, *, law: str = "alart-curnier",
                      refine: int = 1, r: float | None = None, refine2: int | None = None,
                      discretisation: str = "auto", degree: int = 1) -> ContactProblem:
    """The benchmark as a :class:`ContactProblem` (mesh built with gmsh).

    ``refine2`` meshes beam 2 at edge 0.2 / ``refine2`` m (a non-matching interface, see
    :func:`~dolfinx_nnqem.cases.geometries.build_two_beams`); ``discretisation`` is the contact's (see
    :class:`~dolfinx_nnqem.problem.contact_problem.Contact`). ``degree = 2``: triquadratic (27-node)
    hexahedra; a non-matching interface then needs ``discretisation = "node-to-surface"``.
    """
    mesh, cell_tags, facet_tags = build_two_beams(comm, refine=refine, refine2=refine2)
    return ContactProblem(
        mesh, cell_tags, facet_tags,
        materials={T.BODY1: MATERIAL, T.BODY2: MATERIAL},
        dirichlet=[Dirichlet(T.CLAMP1), Dirichlet(T.CLAMP2)],
        tractions=[Traction(T.LOAD, TRACTION)],
        body_forces=[Gravity(GRAVITY)],
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=MU_F, law=law, r=r, discretisation=discretisation),
        degree=degree,
    )


def run_two_beams(method: str = "monolithic", increments: int = 15, out: str | Path = "results/two_beams",
                  *, law: str | None = None, refine: int = 1, options: SolverOptions | None = None,
                  fields: bool = True, comm: MPI.Comm = MPI.COMM_WORLD,
                  progress: Callable[[IncrementResult], None] | None = None,
                  method_options: dict | None = None) -> dict:
    """Solve the benchmark with ``method`` and write ``out``/summary.json (+ fields, pairs).

    ``method_options``: e.g. ``{"nneqm2": NNEQM2Options(...)}`` (see :func:`make_solver`).
    Returns the summary dictionary (the content of summary.json).
    """

    law = law or DEFAULT_LAW.get(method, "alart-curnier")
    t0 = time.perf_counter()
    problem = two_beams_problem(comm, law=law, refine=refine)
    extra = {"law": law, "refine": refine, "r": contact_model(problem).r_max,
             "model": "two overlapping cantilevers (benchmark-two-beams.md)"}
    writer = ResultsWriter(problem, method, out, increments, probes=FREE_END_CORNERS, extra=extra,
                           fields=fields, cell_fields=[RecoveryIndicator(problem)])
    callbacks = [writer] + ([progress] if progress is not None else [])
    try:
        with make_solver(method, problem, options, **(method_options or {})) as solver:
            solve_load_steps(problem, solver, increments, callbacks=callbacks)
            timings = dict(solver.timings)
    except BaseException as error:  # noqa: BLE001  (an interrupt too: the summary says how the run ended)
        writer.record_end(error)
        raise
    finally:
        writer.close()
    summary = writer.summary.data
    summary["wall_time_s"] = time.perf_counter() - t0
    summary["timings_s"] = timings
    summary["free_end_corners"] = summary.pop("probes", [])
    writer.summary.data = summary
    writer.summary.write()  # atomic, rank 0, errors raised on every rank
    return summary


# -- tables -------------------------------------------------------------------------------------
def format_tables(summary: dict) -> str:
    """Tables like the seed's 1–3 for one method's summary."""
    lines = [f"== {summary['method']} (law {summary.get('law')}, {summary['increments']} increments, "
             f"system order {summary.get('system_order')}) =="]
    lines.append("Pair forces on beam 1, local frame (N): normal n = +y, tangential t1 = +x, t2 = -z")
    lines.append(f"{'pair':>4} {'x':>5} {'z':>5} {'state':>6} {'normal':>11} {'tang. 1':>11} {'tang. 2':>11}")
    for i, pr in enumerate(summary.get("pairs", [])):
        f = pr["force_local_body1"]
        lines.append(f"{i:>4} {pr['position'][0]:5.2f} {pr['position'][2]:5.2f} {pr['state']:>6} "
                     f"{f[0]:11.2f} {f[1]:11.2f} {f[2]:11.2f}")
    lines.append("Pair node displacements, global frame (mm): beam 1 node (beam 2 node)")
    lines.append(f"{'pair':>4} {'X':>21} {'Y':>21} {'Z':>21}")
    for i, pr in enumerate(summary.get("pairs", [])):
        a, b = np.array(pr["u_body1"]) * 1e3, np.array(pr["u_body2"]) * 1e3
        lines.append(f"{i:>4} " + " ".join(f"{a[k]:9.4f} ({b[k]:8.4f})" for k in range(3)))
    lines.append("Free-end corner displacements (mm)")
    for c in summary.get("free_end_corners", []):
        u = np.array(c["u"]) * 1e3
        lines.append(f"  {c['name']:<26} {u[0]:9.4f} {u[1]:9.4f} {u[2]:9.4f}")
    lines.append("Reactions (N) and global equilibrium")
    for tag, r in summary.get("reactions", {}).items():
        lines.append(f"  clamp tag {tag}: {r[0]:12.2f} {r[1]:12.2f} {r[2]:12.2f}")
    al = summary.get("applied_load", [0, 0, 0])
    lines.append(f"  applied load : {al[0]:12.2f} {al[1]:12.2f} {al[2]:12.2f}")
    lines.append(f"  |applied + reactions| / |applied| = {summary.get('equilibrium_residual', float('nan')):.2e}")
    lines.append(f"Iterations per increment: {summary['iterations']}")
    lines.append(f"Plastic Gauss points per increment (of {summary.get('num_gauss_points')}): "
                 f"{summary['plastic_gauss_points']}")
    lines.append(f"Wall time: {summary['wall_time_s']:.2f} s")
    return "\n".join(lines)


def format_differences(summaries: list[dict]) -> str:
    """Differences of pair forces and displacements between methods (relative to the first)."""
    if len(summaries) < 2:
        return ""
    ref = summaries[0]
    lines = [f"== Differences relative to {ref['method']} =="]
    f_ref = np.array([p["force_local_body1"] for p in ref["pairs"]])
    u_ref = np.array([p["u_body1"] + p["u_body2"] for p in ref["pairs"]])
    c_ref = np.array([c["u"] for c in ref["free_end_corners"]])
    for s in summaries[1:]:
        f = np.array([p["force_local_body1"] for p in s["pairs"]])
        u = np.array([p["u_body1"] + p["u_body2"] for p in s["pairs"]])
        c = np.array([c["u"] for c in s["free_end_corners"]])
        same_states = [p["state"] for p in s["pairs"]] == [p["state"] for p in ref["pairs"]]
        lines.append(f"  {s['method']:>10}: max |Δ force| / max |force| = "
                     f"{np.abs(f - f_ref).max() / max(np.abs(f_ref).max(), 1e-300):.2e}, "
                     f"max |Δ u_pair| / max |u| = {np.abs(u - u_ref).max() / max(np.abs(u_ref).max(), 1e-300):.2e}, "
                     f"max |Δ u_corner| / max |u| = {np.abs(c - c_ref).max() / max(np.abs(c_ref).max(), 1e-300):.2e}, "
                     f"same pair states: {same_states}")
    return "\n".join(lines)


__all__ = ["two_beams_problem", "run_two_beams", "make_solver", "format_tables", "format_differences",
           "FREE_END_CORNERS", "MATERIAL", "MU_F", "TRACTION", "GRAVITY"]
