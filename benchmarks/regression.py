"""Before/after regression: run a fixed set of cases and save, or compare with, their results.

Used to show that a refactoring leaves the results unchanged::

    git worktree add /tmp/old <old commit>
    PYTHONPATH=/tmp/old python benchmarks/regression.py --save /tmp/before.npz   # the old code
    python benchmarks/regression.py --compare /tmp/before.npz                   # the new code

(``PYTHONPATH`` makes Python import the old checkout's package and tests first.) For every case
it stores the final displacement, Gauss-point stresses and plastic strains, the pair forces on
body 1 (global pair order), and the Newton iterations of every increment; ``--compare`` prints
the largest relative difference of each array (scaled by the array's largest entry) and any
difference in the iteration counts. Serial only. Prints figures; asserts nothing.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel)
import numpy as np
from mpi4py import MPI

ROOT = Path(dolfinx_nnqem.__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "tests" / "integration"))  # the test modules whose cases this runs


def _options(**kwargs):
    try:
        from dolfinx_nnqem.solvers import SolverOptions  # the new layout
    except ImportError:
        from dolfinx_nnqem.problem.contact_problem import SolverOptions

    return SolverOptions(**kwargs)


def _solver(method, problem, **options):
    """A solver; the monolithic linear-solver choice is a per-solver option after the redesign."""
    try:
        from dolfinx_nnqem.solvers import make_solver
    except ImportError:
        from dolfinx_nnqem.solvers import make_solver

    linear_solver = options.pop("linear_solver", None)
    try:
        from dolfinx_nnqem.solvers import MonolithicOptions  # the new layout

        extra = {} if linear_solver is None else {"monolithic": MonolithicOptions(linear_solver=linear_solver)}
        return make_solver(method, problem, _options(**options), **extra)
    except ImportError:
        if linear_solver is not None:
            options["linear_solver"] = linear_solver
        return make_solver(method, problem, _options(**options))


def _state(problem, results) -> dict:
    from dolfinx_nnqem.io import pair_table

    out = {
        "u": problem.u.x.array.copy(),
        "sigma": problem.state.sigma_n.x.array.copy(),
        "p": problem.state.p_n.x.array.copy(),
        "iterations": np.array([r.iterations for r in results], dtype=float),
        "load_factors": np.array([r.load_factor for r in results]),
    }
    if problem.num_pairs:
        out["pair_force"] = pair_table(problem)["force_on_body1"]
    return out


def two_beams(method: str, law: str) -> dict:
    from dolfinx_nnqem.solvers import solve_load_steps
    from dolfinx_nnqem.cases.two_beams import two_beams_problem

    problem = two_beams_problem(MPI.COMM_WORLD, law=law)
    solver = _solver(method, problem)
    results = solve_load_steps(problem, solver, 15)
    return _state(problem, results)


def patch_test() -> dict:
    from dolfinx_nnqem.material import VonMises
    from dolfinx_nnqem.cases.geometries import StackedBlocksTags as T
    from dolfinx_nnqem.cases.geometries import build_stacked_blocks
    from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure
    from dolfinx_nnqem.solvers import solve_load_steps

    elastic = VonMises(E=1.0e9, nu=0.3)
    mesh, ct, ft = build_stacked_blocks(MPI.COMM_WORLD, 1.0, 0.5, 0.5, 1.0, 3, 2, 2, 3)
    problem = ContactProblem(
        mesh, ct, ft, materials={T.BODY1: elastic, T.BODY2: elastic},
        dirichlet=[Dirichlet(T.BOTTOM, 0.0, [1]),
                   Dirichlet(T.BODY1_XMIN, 0.0, [0]), Dirichlet(T.BODY2_XMIN, 0.0, [0]),
                   Dirichlet(T.BODY1_ZMIN, 0.0, [2]), Dirichlet(T.BODY2_ZMIN, 0.0, [2])],
        tractions=[Pressure(T.TOP, 1.0e6)],
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=0.3),
    )
    results = solve_load_steps(problem, _solver("monolithic", problem, rtol=1e-13), 1)
    return _state(problem, results)


def sliding_block(law: str) -> dict:
    from dolfinx_nnqem.solvers import ConvergenceError
    from dolfinx_nnqem.solvers import solve_load_steps
    from test_contact_verification import sliding_block as build

    problem, _ = build(law)
    solver = _solver("monolithic", problem, rtol=1e-12, max_iterations=40)
    results = []
    try:
        solve_load_steps(problem, solver, 10, callbacks=[results.append], max_cutbacks=2)
    except ConvergenceError:
        pass  # the polar law stops part way (V10): compare what converged
    return _state(problem, results)


def hertz_v6() -> dict:
    from dolfinx_nnqem.solvers import solve_load_steps
    from test_hertz import A_NOMINAL, hertz_problem

    problem = hertz_problem(A_NOMINAL / 3)
    results = solve_load_steps(problem, _solver("monolithic", problem, rtol=1e-12), 1)
    return _state(problem, results)


def mindlin_v7(law: str = "alart-curnier") -> dict:
    from dolfinx_nnqem.solvers import ConvergenceError
    from dolfinx_nnqem.solvers import solve_load_steps
    from test_hertz import A_NOMINAL, hertz_problem

    n = 5
    problem = hertz_problem(A_NOMINAL / 3, half=True, mu_f=0.3, drag=0.004, law=law,
                            normal=lambda ell: min(n * ell, 1.0),
                            tangential=lambda ell: max(n * ell - 1.0, 0.0) / (n - 1))
    results = []
    try:
        solve_load_steps(problem, _solver("monolithic", problem, rtol=1e-12), n,
                         callbacks=[results.append], max_cutbacks=2)
    except ConvergenceError:
        pass
    return _state(problem, results)


def pressed_blocks(linear_solver: str) -> dict:
    from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
    from dolfinx_nnqem.solvers import solve_load_steps

    problem = pressed_blocks_problem(2, MPI.COMM_SELF)
    results = solve_load_steps(problem, _solver("monolithic", problem, linear_solver=linear_solver), 6)
    return _state(problem, results)


def tension_then_shear(method: str, flow_directions: str = "return-map") -> dict:
    from test_nneqm2 import _tension_then_shear

    try:
        from dolfinx_nnqem.solvers import make_solver
    except ImportError:
        from dolfinx_nnqem.solvers import make_solver

    if method == "nneqm2":
        try:
            from dolfinx_nnqem.solvers import NNEQM2Options

            factory = lambda p: make_solver("nneqm2", p, _options(), nneqm2=NNEQM2Options(  # noqa: E731
                flow_directions=flow_directions))
        except ImportError:
            factory = lambda p: make_solver("nneqm2", p, _options())  # noqa: E731
    else:
        factory = lambda p: make_solver(method, p, _options())  # noqa: E731
    problem, _, _, _, _ = _tension_then_shear(factory)
    return {"u": problem.u.x.array.copy(), "sigma": problem.state.sigma_n.x.array.copy(),
            "p": problem.state.p_n.x.array.copy()}


def thick_cylinder() -> dict:
    from dolfinx_nnqem.solvers import solve_load_steps
    from test_thick_cylinder import cylinder_problem, limit_pressure
    from test_thick_cylinder import MATERIAL

    problem = cylinder_problem(0.95 * limit_pressure(MATERIAL))
    results = solve_load_steps(problem, _solver("monolithic", problem, max_iterations=15), 8)
    return _state(problem, results)


CASES = {
    "two_beams/monolithic/alart-curnier": lambda: two_beams("monolithic", "alart-curnier"),
    "two_beams/monolithic/polar": lambda: two_beams("monolithic", "polar"),
    "two_beams/nneqm1/polar": lambda: two_beams("nneqm1", "polar"),
    "two_beams/nneqm1/alart-curnier": lambda: two_beams("nneqm1", "alart-curnier"),
    "two_beams/nneqm2/polar": lambda: two_beams("nneqm2", "polar"),
    "two_beams/nneqm2/alart-curnier": lambda: two_beams("nneqm2", "alart-curnier"),
    "V4 patch test": patch_test,
    "V5 sliding block/alart-curnier": lambda: sliding_block("alart-curnier"),
    "V10 sliding block/polar": lambda: sliding_block("polar"),
    "V6 Hertz h=a/3": hertz_v6,
    "V7 Mindlin h=a/3": mindlin_v7,
    "V7 Mindlin h=a/3/polar": lambda: mindlin_v7("polar"),
    "pressed blocks L2/direct": lambda: pressed_blocks("direct"),
    "pressed blocks L2/iterative": lambda: pressed_blocks("iterative"),
    "tension-shear/monolithic": lambda: tension_then_shear("monolithic"),
    "tension-shear/nneqm2 frozen": lambda: tension_then_shear("nneqm2", "frozen"),
    "tension-shear/nneqm2 return-map": lambda: tension_then_shear("nneqm2"),
    "V3 thick cylinder": thick_cylinder,
}


def run(names) -> dict[str, dict]:
    out = {}
    for name in names:
        t0 = time.perf_counter()
        out[name] = CASES[name]()
        print(f"  {name}: {time.perf_counter() - t0:.1f} s", flush=True)
    return out


def save(path: str, data: dict[str, dict]) -> None:
    flat = {f"{case}|{key}": value for case, arrays in data.items() for key, value in arrays.items()}
    np.savez(path, **flat)


def compare(path: str, data: dict[str, dict]) -> float:
    ref = np.load(path)
    worst = 0.0
    print(f"{'case':42s} {'array':12s} {'max |Δ| / max |ref|':>20s}")
    for case, arrays in data.items():
        for key, value in arrays.items():
            name = f"{case}|{key}"
            if name not in ref:
                print(f"{case:42s} {key:12s} {'(no reference)':>20s}")
                continue
            before = ref[name]
            if before.shape != value.shape:
                print(f"{case:42s} {key:12s} shape {before.shape} -> {value.shape}")
                worst = np.inf
                continue
            if key in ("iterations", "load_factors"):
                same = np.array_equal(before, value)
                print(f"{case:42s} {key:12s} {'same' if same else f'{before.tolist()} -> {value.tolist()}':>20s}")
                continue
            scale = max(np.abs(before).max(initial=0.0), 1e-300)
            diff = float(np.abs(value - before).max(initial=0.0) / scale)
            worst = max(worst, diff)
            print(f"{case:42s} {key:12s} {diff:20.2e}")
    print(f"worst relative difference: {worst:.2e}")
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--save", help="write the results to this .npz file")
    parser.add_argument("--compare", help="compare with the results in this .npz file")
    parser.add_argument("--cases", nargs="*", default=list(CASES), help="case names (default: all)")
    args = parser.parse_args()
    print(f"dolfinx_nnqem from {Path(dolfinx_nnqem.__file__).parent}")
    importlib.import_module("dolfinx_nnqem.problem.contact_problem")
    data = run(args.cases)
    if args.save:
        save(args.save, data)
    if args.compare:
        compare(args.compare, data)


if __name__ == "__main__":
    main()
