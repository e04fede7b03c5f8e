"""Ironing with Neo-Hookean bodies at finite strain (issue 41): every method and law, and the meshes.

The case: :mod:`dolfinx_nnqem.cases.neo_hooke_ironing` (a stiff Neo-Hookean die pressed a fifth of a
soft slab's thickness into it, then dragged four times its own length with friction μ_f = 0.3). Each
run steps the load in ``--increments`` equal increments (rtol 1e-10) and records the contact force
on the die at every increment. It prints, per run:

* the Newton iterations per increment, the CPU seconds (``time.process_time`` of this rank);
* the press force F_y at the end of the press (ℓ = 0.2);
* over the drag's increments after the first (ℓ ≥ 0.3): the mean drag −F_x and press F_y, their ratio
  (the friction coefficient if every pair slides in a plane normal to y), and the spread of F_y
  (max − min over mean: the faceting of the discretisation as the die passes the slab's nodes).

Then the largest difference of the force histories from the first run, relative to the largest
press force. ``--runs`` lists ``method/law/discretisation/level`` runs; NNEQM2 is refused at finite
strain before solving (its message is printed). Under MPI (``mpiexec -n 2``) every figure is the
whole problem's; ``--save FILE.npz`` / ``--compare FILE.npz`` store and compare the histories::

    OPENBLAS_NUM_THREADS=1 python benchmarks/neo_hooke_ironing.py \\
        --runs monolithic/alart-curnier/mortar/1 nneqm1/polar/mortar/1 monolithic/alart-curnier/mortar/2
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from mpi4py import MPI

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
from dolfinx_nnqem.cases.neo_hooke_ironing import PRESSED_AT, die_force, neo_hooke_ironing
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

DEFAULT_RUNS = ["monolithic/alart-curnier/mortar/1", "monolithic/polar/mortar/1", "nneqm1/alart-curnier/mortar/1",
                "nneqm1/polar/mortar/1", "monolithic/alart-curnier/node-to-surface/1", "nneqm2/alart-curnier/mortar/1",
                "monolithic/alart-curnier/mortar/2", "monolithic/alart-curnier/mortar/3"]


def run(method: str, law: str, discretisation: str, level: int, increments: int) -> dict:
    """One run: the load factors, the die's force at each increment, the Newton iterations, CPU seconds."""
    problem = neo_hooke_ironing(level, law=law, discretisation=discretisation)
    forces: list[np.ndarray] = []
    start = time.process_time()
    with make_solver(method, problem, SolverOptions(rtol=1e-10, max_iterations=40)) as solver:
        results = solve_load_steps(problem, solver, increments, callbacks=[lambda r: forces.append(die_force(problem))])
    return {"load_factors": np.array([r.load_factor for r in results]), "forces": np.array(forces),
            "iterations": [r.iterations for r in results], "cpu": time.process_time() - start,
            "pairs": problem.num_pairs}


def figures(record: dict) -> str:
    """The press force at ℓ = 0.2 and the drag's means, ratio and spread (module docstring)."""
    lf, f = record["load_factors"], record["forces"]
    press = f[np.argmin(np.abs(lf - PRESSED_AT)), 1]
    drag = lf >= PRESSED_AT + 0.1 - 1e-12
    fx, fy = -f[drag, 0].mean(), f[drag, 1].mean()
    spread = (f[drag, 1].max() - f[drag, 1].min()) / fy
    return (f"press F_y {press:.5g}; drag: -F_x {fx:.5g}, F_y {fy:.5g}, ratio {fx / fy:.4f}, "
            f"F_y spread {spread:.2%}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", nargs="+", default=DEFAULT_RUNS, help="method/law/discretisation/level")
    parser.add_argument("--increments", type=int, default=20)
    parser.add_argument("--save", help="store the first run's force history (.npz)")
    parser.add_argument("--compare", help="compare the first run's force history with one stored (.npz)")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    say = print if comm.rank == 0 else (lambda *a, **k: None)
    say(f"Neo-Hookean ironing, {comm.size} rank(s), {args.increments} increments")
    records: dict[str, dict] = {}
    for name in args.runs:
        method, law, discretisation, level = name.split("/")
        try:
            record = run(method, law, discretisation, int(level), args.increments)
        except ValueError as refusal:
            say(f"{name}: refused: {refusal}")
            continue
        records[name] = record
        say(f"{name}: {record['pairs']} pairs, Newton {sum(record['iterations'])} {record['iterations']}, "
            f"CPU {record['cpu']:.1f} s\n    {figures(record)}")
    if not records:
        return
    first_name, first = next(iter(records.items()))
    scale = np.abs(first["forces"]).max()
    for name, record in records.items():
        if name != first_name and record["forces"].shape == first["forces"].shape:
            difference = np.abs(record["forces"] - first["forces"]).max() / scale
            say(f"{name} against {first_name}: force histories differ by {difference:.2e} of the largest force")
    if args.save and comm.rank == 0:
        np.savez(args.save, load_factors=first["load_factors"], forces=first["forces"])
    if args.compare:
        stored = np.load(args.compare)
        say(f"{first_name} against {args.compare}: "
            f"{np.abs(stored['forces'] - first['forces']).max() / scale:.2e} of the largest force")


if __name__ == "__main__":
    main()
