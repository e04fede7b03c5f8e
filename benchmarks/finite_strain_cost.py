"""Cost per Newton iteration at finite strain against small strain, on the same problem in one process.

The pressed and dragged blocks of ``benchmarks/material_cost.py`` (an upper block pressed 3e7 Pa and
dragged 0.2 of it onto a lower one, ``--cells`` hexahedra per block edge), both blocks of one
material, built with ``kinematics="small"`` and ``kinematics="finite"`` (issue 41): von Mises with
linear hardening (small strain: the closed-form UFL return map; finite: the logarithmic route on
arrays), von Mises with Voce hardening (arrays in both), linear elasticity against Neo-Hooke (its
linearisation). Prints, per material and kinematics:

* ``F+K``: one F_int and one K_t at a new iterate near the converged state (the material's
  evaluation included), the median of ``--repeat`` iterates;
* ``per iteration``: the time of a 5-increment run (the monolithic solver's assembly, contact,
  factorisation and solves, and the load stepping's checks and commits) per Newton iteration;
* ``after the 1st``: the same for increments 2 to 5 alone: without what a run pays once (the
  first check's compiled expressions, the first evaluations' set-up), so the figure of a longer run;

and the finite/small ratios. Each figure is the least over ``--rounds`` runs, small and finite
strain alternated (after one run of each that compiles the kernels): on a shared machine the load
moves the two kinematics' runs apart, and the least of alternated runs is the figure it moves
least. ``--clock cpu`` (the default) measures the process's CPU time, ``--clock wall`` the wall
time: on a machine shared with other jobs the CPU time is the figure the load moves least (the runs
are serial; set ``OPENBLAS_NUM_THREADS=1``). Asserts nothing::

    OPENBLAS_NUM_THREADS=1 python benchmarks/finite_strain_cost.py --cells 6 [--clock cpu|wall]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from material_cost import assembly_time  # noqa: E402

from dolfinx_nnqem.cases.geometries import BlockStackTags as B  # noqa: E402
from dolfinx_nnqem.cases.geometries import build_block_stack  # noqa: E402
from dolfinx_nnqem.material import Elastic, VoceHardening, VonMises  # noqa: E402
from dolfinx_nnqem.material.finite_strain import NeoHooke  # noqa: E402
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure, Traction  # noqa: E402
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps  # noqa: E402

MATERIALS = {  # name: (small-strain material, finite-strain material)
    "von-mises linear": (VonMises(E=2.0e10, nu=0.2, sigma_y0=2.0e7, H=2.0e9),) * 2,
    "von-mises voce": (VonMises(E=2.0e10, nu=0.2, hardening=VoceHardening(2.0e7, 1.0e7, 200.0, 2.0e8)),) * 2,
    "elastic / neo-hooke": (Elastic(E=2.0e10, nu=0.2), NeoHooke(E=2.0e10, nu=0.2)),
}


def blocks(material, cells: int, kinematics: str) -> ContactProblem:
    """The pressed and dragged blocks of ``material_cost.py`` with ``kinematics``."""
    mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, (0.5, 0.5),
                                     ((cells, max(cells // 2, 1), cells), (cells, max(cells // 2, 1), cells)))
    return ContactProblem(
        mesh, ct, ft, materials={1: material, 2: material}, kinematics=kinematics,
        dirichlet=[Dirichlet(B.bottom(1))] + [Dirichlet(f(k), 0.0, [2]) for k in (1, 2) for f in (B.zmin, B.zmax)],
        tractions=[Pressure(B.top(2), 3.0e7), Traction(B.top(2), (0.2 * 3.0e7, 0.0, 0.0))],
        contact=Contact(B.top(1), B.bottom(2), mu_f=0.3))


CLOCKS = {"cpu": time.process_time, "wall": time.perf_counter}


def measure(material, cells: int, kinematics: str, repeat: int, clock=time.process_time
            ) -> tuple[float, float, float, int, int, int]:
    """One run: (F+K seconds, seconds per Newton iteration, the same after the first increment,
    iterations, plastic Gauss points, Gauss points)."""
    problem = blocks(material, cells, kinematics)
    ends: list[float] = []  # the clock at the end of each increment
    with make_solver("monolithic", problem, SolverOptions(rtol=1e-10)) as solver:
        t0 = clock()
        results = solve_load_steps(problem, solver, 5, callbacks=[lambda result: ends.append(clock())])
        solving = clock() - t0
    iterations = sum(r.iterations for r in results)
    later = (ends[-1] - ends[0]) / max(iterations - results[0].iterations, 1)
    return (assembly_time(problem, repeat, clock), solving / max(iterations, 1), later, iterations,
            problem.state.count_plastic_points(), problem.state.num_gauss_points())


def least_of_rounds(materials: tuple, cells: int, repeat: int, rounds: int, clock=time.process_time
                    ) -> list[tuple[float, float, float, int, int, int]]:
    """Per kinematics (small, finite): :func:`measure` with its times the least over ``rounds``
    alternated runs (after one run of each, which compiles the kernels)."""
    kinematics = ("small", "finite")
    for material, kind in zip(materials, kinematics):
        measure(material, cells, kind, 1)
    runs: list[list[tuple[float, float, float, int, int, int]]] = [[], []]
    for _ in range(rounds):
        for k, (material, kind) in enumerate(zip(materials, kinematics)):
            runs[k].append(measure(material, cells, kind, repeat, clock))
    return [(min(r[0] for r in rows), min(r[1] for r in rows), min(r[2] for r in rows), *rows[-1][3:])
            for rows in runs]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=6, help="hexahedra per block edge")
    parser.add_argument("--repeat", type=int, default=15)
    parser.add_argument("--rounds", type=int, default=3, help="alternated runs of each kinematics (the least is shown)")
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="cpu", help="CPU time of the process, or wall time")
    args = parser.parse_args(argv)
    print(f"pressed blocks, {args.cells} cells per edge, {MPI.COMM_WORLD.size} rank(s), least of {args.rounds} alternated "
          f"runs, {args.clock} time")
    print(f"{'material':20s} {'kinematics':>10s} {'F+K (ms)':>9s} {'ratio':>6s} {'per iteration (ms)':>19s} "
          f"{'ratio':>6s} {'after the 1st':>13s} {'ratio':>6s} {'iterations':>10s} {'plastic GP':>10s}")
    for name, materials in MATERIALS.items():
        small, finite = least_of_rounds(materials, args.cells, args.repeat, args.rounds, CLOCKS[args.clock])
        for kinematics, row in (("small", small), ("finite", finite)):
            assembly, per_iteration, later, iterations, plastic, total = row
            print(f"{name:20s} {kinematics:>10s} {1e3 * assembly:9.2f} {assembly / small[0]:6.2f} "
                  f"{1e3 * per_iteration:19.2f} {per_iteration / small[1]:6.2f} {1e3 * later:13.2f} "
                  f"{later / small[2]:6.2f} {iterations:10d} {plastic:>5d}/{total}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
