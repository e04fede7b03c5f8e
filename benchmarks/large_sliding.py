"""What the current contact geometry costs (issue 27): Newton iterations, solves and seconds.

A sphere pressed in place (``cases.large_sliding.sliding_sphere`` with start = end, n³ hexahedra,
``increments`` increments over the press) solved with the reference and with the current
geometry, and the issue's slide (0.3 -> 0.7) with the current geometry, which the reference one
cannot finish. Prints figures; asserts nothing::

    python benchmarks/large_sliding.py [n] [increments]
"""

from __future__ import annotations

import sys
import time

import numpy as np

from dolfinx_nnqem.cases.large_sliding import PRESSED_AT, obstacle_force, sliding_sphere
from dolfinx_nnqem.solvers import ConvergenceError, SolverOptions, make_solver, solve_load_steps


def run(n: int, increments: int, geometry: str, method: str, end: float, final: float) -> str:
    problem = sliding_sphere(n, start=0.3, end=end, geometry=geometry)
    t0 = time.perf_counter()
    try:
        with make_solver(method, problem, SolverOptions(rtol=1e-10, max_iterations=40)) as solver:
            results = solve_load_steps(problem, solver, increments, final_load_factor=final)
    except ConvergenceError as error:
        return f"failed: {str(error).splitlines()[0][:90]}... ({time.perf_counter() - t0:.2f} s)"
    seconds = time.perf_counter() - t0
    model = problem.contact
    assert model is not None
    iterations = sum(r.iterations for r in results)
    solves = sum(r.report.geometry_passes for r in results)
    force = obstacle_force(problem)
    return (f"{len(results)} increments, {iterations} Newton iterations, {solves} solves, {seconds:.2f} s; "
            f"F_y = {force[1]:.9g}")


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 8
    increments = int(sys.argv[2]) if len(sys.argv) > 2 else 4
    for method in ("monolithic", "nneqm1"):
        for geometry in ("reference", "current"):
            print(f"{method:10s} press in place, {geometry:9s} geometry, {n}³: "
                  f"{run(n, increments, geometry, method, 0.3, PRESSED_AT)}", flush=True)
        for geometry in ("reference", "current"):
            print(f"{method:10s} slide 0.3 -> 0.7, {geometry:9s} geometry, {n}³: "
                  f"{run(n, 5 * increments, geometry, method, 0.7, 1.0)}", flush=True)


if __name__ == "__main__":
    np.set_printoptions(precision=6)
    main()
