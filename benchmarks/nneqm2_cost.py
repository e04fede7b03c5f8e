"""NNEQM2's cost against NNEQM1's, cell by cell: the robustness cases and an 8×8×8 plastic indentation.

For each case and law, both methods solve the same path ``--repeat`` times, alternating, in this
process; the script prints the minimum wall time of each, their ratio, the iterations, and
where NNEQM2's time goes (its phases). The issue's target: NNEQM2 at most 5× NNEQM1 everywhere.
Prints figures; asserts nothing::

    python benchmarks/nneqm2_cost.py                      # every case, both laws
    python benchmarks/nneqm2_cost.py --cases indentation-8 --repeat 1
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel)
from mpi4py import MPI

from dolfinx_nnqem.contact.obstacles import Sphere
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet
from dolfinx_nnqem.problem.meshing import BlockStackTags as T
from dolfinx_nnqem.problem.meshing import build_block_stack
from dolfinx_nnqem.solvers import ConvergenceError, NNEQM2Options, SolverOptions, make_solver, solve_load_steps

sys.path.insert(0, str(Path(__file__).resolve().parent))
import robustness as rb  # noqa: E402  (the cases)

STEEL = VonMises(E=200_000.0, nu=0.3, sigma_y0=400.0, H=20_000.0)


def indentation(law: str, n: int = 8) -> ContactProblem:
    """A rigid sphere (R = 2) pressed 0.02 into a von Mises cube of n × n × n hexahedra (a quarter:
    symmetry planes x = 0 and z = 0, rollers below), frictionless."""
    mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [1.0], [(n, n, n)])
    sphere = Sphere(centre=(0.0, 3.0, 0.0), radius=2.0, motion=(0.0, -0.02, 0.0))
    return ContactProblem(mesh, ct, ft, materials=STEEL,
                          dirichlet=[Dirichlet(T.bottom(1), 0.0, [1]), Dirichlet(T.xmin(1), 0.0, [0]),
                                     Dirichlet(T.zmin(1), 0.0, [2])],
                          contact=Contact(sphere, T.top(1), mu_f=0.0, law=law))


CASES = {c.name: (c.build, c.increments) for c in rb.CASES if c.contact and not c.expect_failure}
CASES["indentation-8"] = (indentation, 4)


def run(build, law: str, method: str, increments: int, variant: str) -> dict:
    problem = build(law)
    extra = {"nneqm2": NNEQM2Options(flow_directions=variant)} if method == "nneqm2" else {}
    t0 = time.perf_counter()
    try:
        with make_solver(method, problem, SolverOptions(), **extra) as solver:
            results = solve_load_steps(problem, solver, increments)
            timings = dict(solver.timings)
    except ConvergenceError as error:
        return {"time": time.perf_counter() - t0, "failed": str(error).splitlines()[0][:100]}
    return {"time": time.perf_counter() - t0, "iterations": sum(r.iterations for r in results),
            "cutbacks": sum(1 for r in results if r.cutbacks), "timings": timings}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="*", default=list(CASES))
    parser.add_argument("--laws", nargs="*", default=["alart-curnier", "polar"])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--variant", default="return-map", help="NNEQM2's flow_directions")
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore", DeprecationWarning)
    print(f"{'case':20s} {'law':14s} {'NNEQM1 s':>9s} {'NNEQM2 s':>9s} {'ratio':>6s}  iterations (NNEQM1, NNEQM2)  "
          "NNEQM2's phases (s)")
    worst = 0.0
    for name in args.cases:
        build, increments = CASES[name]
        for law in args.laws:
            runs = {"nneqm1": [], "nneqm2": []}
            for _ in range(args.repeat):  # alternating, so that the machine's load hits both alike
                for method in runs:
                    runs[method].append(run(build, law, method, increments, args.variant))
            best = {m: min(r, key=lambda x: x["time"]) for m, r in runs.items()}
            if any("failed" in b for b in best.values()):
                print(f"{name:20s} {law:14s} failed: {[b.get('failed', 'ok') for b in best.values()]}")
                continue
            ratio = best["nneqm2"]["time"] / best["nneqm1"]["time"]
            worst = max(worst, ratio)
            phases = ", ".join(f"{k} {v:.2f}" for k, v in sorted(best["nneqm2"]["timings"].items(), key=lambda kv: -kv[1])
                               if v > 0.01)
            print(f"{name:20s} {law:14s} {best['nneqm1']['time']:9.3f} {best['nneqm2']['time']:9.3f} {ratio:6.2f}  "
                  f"{best['nneqm1']['iterations']:4d} ({best['nneqm1']['cutbacks']} cb), "
                  f"{best['nneqm2']['iterations']:4d} ({best['nneqm2']['cutbacks']} cb)  {phases}", flush=True)
    print(f"largest ratio NNEQM2 / NNEQM1: {worst:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
