"""The converged references of the error-estimate effectivity tests (``docs/error-estimates.md``).

    python benchmarks/estimate_references.py two-beams    # the tip of beam 1, degree 1 and 2, refine 1..4
    python benchmarks/estimate_references.py cylinder     # the thick cylinder at 0.9 p_lim

Each prints one line per mesh (degree, refinement, dofs, the quantities, wall time) and the
extrapolated limit: u(h) = u_inf + C h^p fitted through the three finest degree-2 meshes (p from
the ratio of successive differences; the meshes' sizes need not halve). The two-beam study takes
about 45 minutes on two shared cores (degree 2 at 0.2/3 m: 62 000 dofs, 15 increments).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from scipy.optimize import brentq

from dolfinx_nnqem.estimates import probe_points, read_quantities
from dolfinx_nnqem.solvers import make_solver, solve_load_steps

ROOT = Path(__file__).resolve().parents[1]


def extrapolate(h: list[float], u: list[float]) -> tuple[float, float]:
    """(u_inf, p) of u = u_inf + C h^p through three (h, u)."""
    (h1, h2, h3), (u1, u2, u3) = h, u
    ratio = (u1 - u2) / (u2 - u3)

    def mismatch(p):
        return (h1 ** p - h2 ** p) / (h2 ** p - h3 ** p) - ratio

    p = brentq(mismatch, 0.2, 8.0)
    C = (u2 - u3) / (h2 ** p - h3 ** p)
    return u3 - C * h3 ** p, p


def solve(problem, increments: int):
    t0 = time.perf_counter()
    with make_solver("monolithic", problem) as solver:
        solve_load_steps(problem, solver, increments)
    return time.perf_counter() - t0


def two_beams() -> None:
    from dolfinx_nnqem.cases.two_beams import FREE_END_CORNERS, two_beams_problem

    tip = "beam1 x=2.0 y=0.0 z=0.0"
    probes = probe_points({tip: FREE_END_CORNERS[tip]})
    finest: list[tuple[float, np.ndarray]] = []
    for degree, refine in ((1, 1), (1, 2), (1, 4), (2, 1), (2, 2), (2, 3)):
        problem = two_beams_problem(degree=degree, refine=refine)
        elapsed = solve(problem, 15)
        u = read_quantities(problem, probes)[f"u:{tip}"]
        print(f"degree {degree}, h = 0.2/{refine} m: {problem.V.dofmap.index_map.size_global * 3} dofs, tip u = "
              f"{1e3 * u} mm, {elapsed:.0f} s", flush=True)
        if degree == 2:
            finest.append((0.2 / refine, u))
        problem.destroy()
    for k, name in ((1, "u_y"), (2, "u_z")):
        limit, p = extrapolate([h for h, _ in finest], [u[k] for _, u in finest])
        print(f"{name}: limit {1e3 * limit:.5f} mm (order {p:.2f})")


def cylinder() -> None:
    sys.path.insert(0, str(ROOT / "tests"))
    sys.path.insert(0, str(ROOT / "tests" / "integration"))  # the test module whose case this runs
    from test_thick_cylinder import A, MATERIAL, cylinder_problem, limit_pressure

    p_max = 0.9 * limit_pressure(MATERIAL)
    probes = probe_points({"inner": (A, 0.0, 0.0)})
    finest: list[tuple[float, float, float]] = []
    for degree, n in ((1, 4), (1, 8), (1, 16), (2, 4), (2, 8), (2, 16)):
        problem = cylinder_problem(p_max, degree=degree, n_radial=n, n_circumferential=3 * n)
        elapsed = solve(problem, 5)
        q = read_quantities(problem, probes)
        print(f"degree {degree}, {n} x {3 * n}: {problem.V.dofmap.index_map.size_global * 3} dofs, u_inner = "
              f"{q['u:inner'][0]:.6e}, max p = {q['max_p'][0]:.6e}, {elapsed:.0f} s", flush=True)
        if degree == 2:
            finest.append((1.0 / n, q["u:inner"][0], q["max_p"][0]))
        problem.destroy()
    for k, name in ((1, "u_inner"), (2, "max_p")):
        limit, p = extrapolate([f[0] for f in finest], [f[k] for f in finest])
        print(f"{name}: limit {limit:.5e} (order {p:.2f})")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("case", choices=("two-beams", "cylinder"))
    {"two-beams": two_beams, "cylinder": cylinder}[parser.parse_args().case]()
