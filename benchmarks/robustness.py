"""Robustness suite: hard load paths × every method and law (issue "Every method and both laws converge").

Rows are hard cases, columns method × law (monolithic, NNEQM1, NNEQM2 × Alart–Curnier, polar);
a cell holds converged or not, Newton iterations (total, largest and median per increment),
cutbacks and wall time. The monolithic solver also runs each case with automatic incrementation
(``increments="auto"``), to show the Newton iterations it saves. Prints the matrix and saves it
as JSON::

    python benchmarks/robustness.py                       # every case (about half an hour)
    python benchmarks/robustness.py --fast                 # the quick subset the tests run
    python benchmarks/robustness.py --cases drag-0.2-hex two-beams-5 --json out.json

Cases marked ``expect_failure`` carry a load no state can carry: their cell is green when the run
ends in a ConvergenceError (a clear report), red if it claims convergence. Cases a method cannot
solve by construction are "n/a" with the reason (NNEQM1 and NNEQM2 need contact pairs).
Prints figures; asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel)
from mpi4py import MPI

from dolfinx_nnqem.problem import PiecewiseLinearPath
from dolfinx_nnqem.solvers import ConvergenceError
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.cases.geometries import BlockStackTags as B
from dolfinx_nnqem.cases.geometries import StackedBlocksTags as T
from dolfinx_nnqem.cases.geometries import build_block_stack, build_stacked_blocks
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure, Traction
from dolfinx_nnqem.solvers import METHODS, SolverOptions, make_solver
from dolfinx_nnqem.solvers import solve_load_steps

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "tests" / "integration"))  # the test modules whose cases this runs

LAWS = ("alart-curnier", "polar")
STEEL_LIKE = VonMises(E=2.0e10, nu=0.2, sigma_y0=2.0e7, H=2.0e9)  # the pressed blocks' material
PRESSURE = 3.0e7
MU_F = 0.3


@dataclass
class Case:
    """A row of the matrix: ``build(law)`` returns the problem; solved in ``increments``."""

    name: str
    build: Callable[[str], ContactProblem]
    increments: int
    what: str
    expect_failure: bool = False
    contact: bool = True
    max_displacement: float | None = None
    fast: bool = False


@dataclass
class Cell:
    converged: bool
    iterations: int = 0
    max_per_increment: int = 0
    median_per_increment: float = 0.0
    increments: int = 0
    cutbacks: int = 0
    wall_time_s: float = 0.0
    message: str = ""
    green: bool = False
    difference: float | None = None  #: largest difference from the monolithic cell of the same law (Solution)
    extra: dict = field(default_factory=dict)


@dataclass
class Solution:
    """A converged cell's displacements (owned dofs) and pair forces at every increment, to
    compare methods along the load path (a final state can be unloaded: near zero)."""

    load_factors: list[float] = field(default_factory=list)
    u: list[np.ndarray] = field(default_factory=list)
    forces: list[np.ndarray] = field(default_factory=list)

    def keep(self, problem, load_factor: float) -> None:
        n = problem.V.dofmap.index_map.size_local * 3
        self.load_factors.append(round(float(load_factor), 12))
        self.u.append(problem.u.x.array[:n].copy())
        self.forces.append(problem.contact.force().copy() if problem.has_contact else np.zeros((0, 3)))

    def difference(self, reference: Solution) -> float | None:
        """max(|Δu|∞, |Δλ|∞) along the path, each relative to the reference's largest value on
        the path (the pair forces, not the pair unknowns: a polar angle without force means
        nothing); None if the two took different load paths (with friction the answer depends
        on the path)."""
        if self.load_factors != reference.load_factors:
            return None

        def largest(arrays):
            return max((float(np.abs(a).max(initial=0.0)) for a in arrays), default=0.0)

        du = largest([a - b for a, b in zip(self.u, reference.u)]) / max(largest(reference.u), 1e-300)
        scale = largest(reference.forces)
        if scale == 0.0:
            return du
        return max(du, largest([a - b for a, b in zip(self.forces, reference.forces)]) / scale)


# -- the cases ---------------------------------------------------------------------------------
def pressed_and_dragged(ratio: float, cell_type: str = "hexahedron") -> Callable[[str], ContactProblem]:
    """Two von Mises blocks 4×2×4 (hex) or the same divisions in tetrahedra; bottom clamped,
    u_z = 0 on the z faces; pressure p and a top traction ratio·p in x together from rest."""

    def build(law: str) -> ContactProblem:
        mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, (0.5, 0.5), ((4, 2, 4), (4, 2, 4)),
                                         cell_type=cell_type)
        return ContactProblem(
            mesh, ct, ft, materials={1: STEEL_LIKE, 2: STEEL_LIKE},
            dirichlet=[Dirichlet(B.bottom(1))] + [Dirichlet(f(k), 0.0, [2]) for k in (1, 2) for f in (B.zmin, B.zmax)],
            tractions=[Pressure(B.top(2), PRESSURE), Traction(B.top(2), (ratio * PRESSURE, 0.0, 0.0))],
            contact=Contact(B.top(1), B.bottom(2), mu_f=MU_F, law=law))

    return build


def two_beams(law: str) -> ContactProblem:
    from dolfinx_nnqem.cases.two_beams import two_beams_problem

    return two_beams_problem(law=law)


def cyclic(law: str) -> ContactProblem:
    """Press (top of body 2 moved down 1 mm), drag forward 2 mm, back to −2 mm past the reversal,
    then lift until the pairs open; elastoplastic blocks 4×2×4."""
    mesh, ct, ft = build_stacked_blocks(MPI.COMM_WORLD, 1.0, 0.5, 0.5, 1.0, 4, 2, 2, 4)
    path = PiecewiseLinearPath([(0.0, 0.0, 0.0, 0.0), (0.2, 0.0, -1.0, 0.0), (0.45, 2.0, -1.0, 0.0),
                                (0.85, -2.0, -1.0, 0.0), (1.0, -2.0, 0.5, 0.0)])
    return ContactProblem(
        mesh, ct, ft, materials={T.BODY1: STEEL_LIKE, T.BODY2: STEEL_LIKE},
        dirichlet=[Dirichlet(T.BOTTOM),
                   Dirichlet(T.TOP, 1.0e-3, [0], amplitude=lambda ell: path(ell)[0]),
                   Dirichlet(T.TOP, 1.0e-3, [1], amplitude=lambda ell: path(ell)[1]),
                   Dirichlet(T.TOP, 0.0, [2])]
        + [Dirichlet(tag, 0.0, [2]) for tag in (T.BODY1_ZMIN, T.BODY1_ZMAX, T.BODY2_ZMIN, T.BODY2_ZMAX)],
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=MU_F, law=law))


def gap_closes_and_reopens(law: str) -> ContactProblem:
    """An initial gap of 0.1 mm closed inside the first increment (top moved down 0.3 mm, with
    a drag of 0.1 mm), then unloaded until the gap re-opens; elastic blocks."""
    mesh, ct, ft = build_stacked_blocks(MPI.COMM_WORLD, 1.0, 0.5, 0.5, 1.0, 4, 2, 2, 4, gap=1.0e-4)
    up_and_down = lambda ell: 1.0 - abs(2.0 * ell - 1.0)  # noqa: E731
    elastic = VonMises(E=2.0e10, nu=0.2)
    return ContactProblem(
        mesh, ct, ft, materials={T.BODY1: elastic, T.BODY2: elastic},
        dirichlet=[Dirichlet(T.BOTTOM), Dirichlet(T.TOP, -3.0e-4, [1], amplitude=up_and_down),
                   Dirichlet(T.TOP, 1.0e-4, [0], amplitude=up_and_down), Dirichlet(T.TOP, 0.0, [2])]
        + [Dirichlet(tag, 0.0, [2]) for tag in (T.BODY1_ZMIN, T.BODY1_ZMAX, T.BODY2_ZMIN, T.BODY2_ZMAX)],
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=MU_F, law=law, search_distance=2.0e-4))


def hertz_v6(law: str) -> ContactProblem:
    from test_hertz import hertz_problem

    return hertz_problem(0.5, law=law)


def mindlin_v7(law: str) -> ContactProblem:
    """V7: the approach in the first of 4 increments, then a drag from q = 0 (half model, h = a/2)."""
    from test_hertz import MU_F as MU

    from test_hertz import hertz_problem

    return hertz_problem(0.5, half=True, mu_f=MU, drag=1.0e-3, law=law,
                         normal=lambda ell: min(4.0 * ell, 1.0),
                         tangential=lambda ell: max(4.0 * ell - 1.0, 0.0) / 3.0)


def sliding_block_v5(law: str) -> ContactProblem:
    from test_contact_verification import sliding_block

    return sliding_block(law)[0]


def held_only_by_contact(law: str) -> ContactProblem:
    """Three stacked blocks, the middle one held only by contact (μ_f 0.2 below, 0.4 above); the
    top block pressed, then dragged 1 cm: the lower interface slides."""
    from test_interfaces import three_blocks

    return three_blocks(mu_f=(0.2, 0.4), law=law, drag=1.0e-2)


def perfect_plasticity(law: str) -> ContactProblem:
    """The thick cylinder (V3), H = 0, to 0.95 of its limit pressure (no contact)."""
    from test_thick_cylinder import MATERIAL, cylinder_problem, limit_pressure

    return cylinder_problem(0.95 * limit_pressure(MATERIAL))


CASES = [
    Case("drag-0.2-hex", pressed_and_dragged(0.2), 5, "pressure + drag 0.2 p together from rest, μ_f = 0.3, hexahedra", fast=True),
    Case("drag-0.29-hex", pressed_and_dragged(0.29), 5, "the same, drag 0.29 p (close to sliding off)"),
    Case("drag-0.2-tet", pressed_and_dragged(0.2, "tetrahedron"), 5, "pressure + drag 0.2 p, tetrahedra"),
    Case("drag-0.35-hex", pressed_and_dragged(0.35), 5, "drag 0.35 p > μ_f p: no state carries it",
         expect_failure=True, max_displacement=0.05),
    Case("two-beams-15", two_beams, 15, "the seed's two beams in 15 increments", fast=True),
    Case("two-beams-5", two_beams, 5, "the two beams in 5 increments"),
    Case("two-beams-3", two_beams, 3, "the two beams in 3 increments"),
    Case("cyclic", cyclic, 10, "press, drag forward, drag back past the reversal, lift off"),
    Case("gap-closes-reopens", gap_closes_and_reopens, 4, "a gap closed inside one increment, re-opened by unloading"),
    Case("hertz-v6", hertz_v6, 1, "Hertz (V6), h = a/2, frictionless"),
    Case("mindlin-v7", mindlin_v7, 4, "Hertz then a tangential load from q = 0 (V7), h = a/2"),
    Case("sliding-block-v5", sliding_block_v5, 10, "the sliding block (V5)", fast=True),
    Case("held-by-contact", held_only_by_contact, 5, "three blocks, the middle one held only by contact, pressed then dragged"),
    Case("perfect-plasticity", perfect_plasticity, 10, "thick cylinder, H = 0, to 0.95 of the limit pressure",
         contact=False),
]


# -- running -------------------------------------------------------------------------------------
def run_cell(case: Case, method: str, law: str, increments) -> tuple[Cell, Solution | None]:
    """The cell, and its final solution if it converged."""
    if not case.contact and method != "monolithic":
        return Cell(converged=False, message="n/a: NNEQM1 and NNEQM2 solve contact problems (no pairs here)",
                    green=True), None
    if not case.contact and law != LAWS[0]:
        return Cell(converged=False, message="n/a: no contact, the law plays no part", green=True), None
    problem = case.build(law)
    try:
        solver = make_solver(method, problem, SolverOptions())
    except ValueError as error:  # a method refusing the problem before solving, with its reason
        return Cell(converged=False, message=f"refused before solving: {error}", green=True), None
    solution = Solution()
    t0 = time.perf_counter()
    with solver:  # frees its PETSc objects
        try:
            results = solve_load_steps(problem, solver, increments, max_displacement=case.max_displacement,
                                       callbacks=[lambda r: solution.keep(problem, r.load_factor)])
            converged, message = True, "converged"
        except ConvergenceError as error:
            results, converged, message = [], False, str(error).splitlines()[0]
    wall = time.perf_counter() - t0
    its = [r.iterations for r in results]
    cell = Cell(converged=converged, iterations=sum(its), max_per_increment=max(its, default=0),
                median_per_increment=float(statistics.median(its)) if its else 0.0, increments=len(its),
                cutbacks=int(sum(1 for r in results if r.cutbacks)), wall_time_s=wall, message=message)
    if case.expect_failure:
        cell.green = not converged
    else:
        cell.green = converged and (cell.cutbacks == 0 or increments == "auto")
    return cell, solution if converged else None


def cell_text(cell: Cell) -> str:
    if cell.message.startswith("n/a"):
        return "n/a"
    if cell.message.startswith("refused before solving"):
        return "refused (size)" if "dense system" in cell.message else "refused"
    if not cell.converged:
        return "refused ✓" if cell.green else "FAILED"
    mark = "" if cell.green else " !"
    diff = f", Δ {cell.difference:.0e}" if cell.difference is not None else ""
    return (f"{cell.iterations}/{cell.max_per_increment}/{cell.median_per_increment:g} it, "
            f"{cell.cutbacks} cb, {cell.wall_time_s:.1f} s{diff}{mark}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="*", help="names of the cases to run (default: all)")
    parser.add_argument("--fast", action="store_true", help="only the quick subset")
    parser.add_argument("--methods", nargs="*", default=list(METHODS))
    parser.add_argument("--laws", nargs="*", default=list(LAWS))
    parser.add_argument("--no-auto", action="store_true", help="skip the automatic-incrementation column")
    parser.add_argument("--json", default="benchmarks/results/robustness.json")
    args = parser.parse_args(argv)
    cases = [c for c in CASES if (not args.cases or c.name in args.cases) and (not args.fast or c.fast)]
    matrix: dict[str, dict[str, dict]] = {}
    for case in cases:
        row = matrix.setdefault(case.name, {})
        columns = [(m, law, case.increments) for m in args.methods for law in args.laws]
        if not args.no_auto:
            columns += [("monolithic", law, "auto") for law in args.laws]
        if "monolithic" in args.methods:  # the reference of the difference column runs first
            columns.sort(key=lambda c: c[0] != "monolithic")
        references: dict[str, Solution] = {}
        for method, law, increments in columns:
            key = f"{method}/{law}" + ("/auto" if increments == "auto" else "")
            cell, solution = run_cell(case, method, law, increments)
            if solution is not None and method == "monolithic" and increments != "auto":
                references[law] = solution
            elif solution is not None and law in references and increments != "auto":  # same load path only
                cell.difference = solution.difference(references[law])
            row[key] = asdict(cell)
            print(f"{case.name:20s} {key:28s} {cell_text(cell):40s} {'' if cell.green else cell.message[:120]}",
                  flush=True)
            save(Path(args.json), cases, matrix)  # after every cell: a long run killed keeps what it measured
    print_matrix(cases, matrix)
    print(f"saved {args.json}")
    return 0


def save(out: Path, cases, matrix) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps({"cases": {c.name: c.what for c in cases}, "matrix": matrix}, indent=1))
    tmp.replace(out)


def print_matrix(cases, matrix) -> None:
    keys = list(next(iter(matrix.values())).keys()) if matrix else []
    print("\ncells: total/largest/median Newton iterations per increment, cutbacks, wall time, Δ = largest "
          "relative difference of u and the pair forces from the monolithic cell of the same law "
          "(! = converged with cutbacks)")
    print("| case | " + " | ".join(keys) + " |")
    print("|---" * (len(keys) + 1) + "|")
    for case in cases:
        row = matrix[case.name]
        print(f"| {case.name} | " + " | ".join(cell_text(Cell(**row[k])) for k in keys) + " |")
    saved = []
    for case in cases:
        row = matrix[case.name]
        for law in LAWS:
            fixed, auto = row.get(f"monolithic/{law}"), row.get(f"monolithic/{law}/auto")
            if fixed and auto and fixed["converged"] and auto["converged"]:
                saved.append((case.name, law, fixed["iterations"], auto["iterations"]))
    if saved:
        print("\nautomatic incrementation (monolithic): Newton iterations fixed -> auto")
        for name, law, a, b in saved:
            print(f"  {name:20s} {law:14s} {a:4d} -> {b:4d}")
        total_a, total_b = sum(s[2] for s in saved), sum(s[3] for s in saved)
        print(f"  total {total_a} -> {total_b} ({100.0 * (total_b - total_a) / max(total_a, 1):+.0f} %)")


if __name__ == "__main__":
    sys.exit(main())
