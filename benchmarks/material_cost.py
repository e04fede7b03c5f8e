"""Cost per Newton iteration of each material against linear von Mises, on the same problem in one process.

The pressed and dragged blocks (``tests/integration/test_materials.py``: an upper block pressed 3e7 Pa and
dragged 0.2 of it onto a lower one, ``--cells`` hexahedra per block edge), both blocks of one
material: linear von Mises (closed-form UFL), Voce and a table (the return map on arrays at the
Gauss points, ``material/quadrature_part.py``), linear elasticity (``Elastic``), kinematic
hardening (Prager; Chaboche with two back-stresses on Voce) and Drucker–Prager (associated and
ψ = 5°, an unsymmetric tangent). Prints, per
material:

* ``assembly``: the time of one F_int and one K_t at a new plastic iterate (the material's
  evaluation included), the median of ``--repeat`` iterates;
* ``per iteration``: the monolithic solver's own time (its ``timings``: assembly, contact,
  factorisation, solves) per Newton iteration over a 5-increment run;

each also as a ratio to linear von Mises. Asserts nothing::

    python benchmarks/material_cost.py --cells 6
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dolfinx_nnqem.material import (BackStress, DruckerPrager, Elastic, TabulatedHardening, VoceHardening,  # noqa: E402
                                    VonMises)
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure, Traction  # noqa: E402
from dolfinx_nnqem.cases.geometries import BlockStackTags as B  # noqa: E402
from dolfinx_nnqem.cases.geometries import build_block_stack  # noqa: E402
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps  # noqa: E402

MATERIALS = {
    "von-mises linear": VonMises(E=2.0e10, nu=0.2, sigma_y0=2.0e7, H=2.0e9),
    "von-mises voce": VonMises(E=2.0e10, nu=0.2, hardening=VoceHardening(2.0e7, 1.0e7, 200.0, 2.0e8)),
    "von-mises table": VonMises(E=2.0e10, nu=0.2, hardening=TabulatedHardening(
        [[2.0e7, 0.0], [2.5e7, 0.002], [2.8e7, 0.01], [3.0e7, 0.05]])),
    "elastic": Elastic(E=2.0e10, nu=0.2),
    "prager": VonMises(E=2.0e10, nu=0.2, sigma_y0=2.0e7, H=2.0e9, kinematic=[BackStress(2.0e9)]),
    "chaboche-2 voce": VonMises(E=2.0e10, nu=0.2, hardening=VoceHardening(2.0e7, 5.0e6, 200.0, 0.0),
                                kinematic=[BackStress(4.0e9, 400.0), BackStress(5.0e8)]),
    "drucker-prager": DruckerPrager(E=2.0e10, nu=0.2, cohesion=4.0e6, friction_angle=30.0, H=1.0e8),
    "dp psi=5": DruckerPrager(E=2.0e10, nu=0.2, cohesion=4.0e6, friction_angle=30.0, dilatancy_angle=5.0, H=1.0e8),
}


def blocks(material, cells: int) -> ContactProblem:
    mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, (0.5, 0.5),
                                     ((cells, max(cells // 2, 1), cells), (cells, max(cells // 2, 1), cells)))
    return ContactProblem(
        mesh, ct, ft, materials={1: material, 2: material},
        dirichlet=[Dirichlet(B.bottom(1))] + [Dirichlet(f(k), 0.0, [2]) for k in (1, 2) for f in (B.zmin, B.zmax)],
        tractions=[Pressure(B.top(2), 3.0e7), Traction(B.top(2), (0.2 * 3.0e7, 0.0, 0.0))],
        contact=Contact(B.top(1), B.bottom(2), mu_f=0.3))


def assembly_time(problem: ContactProblem, repeat: int, clock=time.perf_counter) -> float:
    """Median seconds of F_int + K_t at new iterates near the converged plastic state, by ``clock``."""
    rng = np.random.default_rng(0)
    u0 = problem.u.x.array.copy()
    F, A = problem.assemble_internal_force(), problem.assemble_tangent()  # compiled, allocated
    times = []
    for _ in range(repeat):
        problem.u.x.array[:] = u0 * (1.0 + 1e-3 * rng.standard_normal())  # a new iterate: no cache
        t0 = clock()
        problem.assemble_internal_force(F)
        problem.assemble_tangent(A)
        times.append(clock() - t0)
    problem.u.x.array[:] = u0
    F.destroy()
    A.destroy()
    return statistics.median(times)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=6, help="hexahedra per block edge")
    parser.add_argument("--repeat", type=int, default=15)
    args = parser.parse_args(argv)
    rows = {}
    for name, material in MATERIALS.items():
        for _ in range(2):  # the second run's figures: the kernels are compiled by the first
            problem2 = blocks(material, args.cells)
            with make_solver("monolithic", problem2, SolverOptions(rtol=1e-10)) as solver:
                results = solve_load_steps(problem2, solver, 5)
                solving = sum(solver.timings.values())  # assembly, contact, factorisation, solves
            iterations = sum(r.iterations for r in results)
        rows[name] = (assembly_time(problem2, args.repeat), solving / max(iterations, 1), iterations,
                      problem2.state.count_plastic_points(), problem2.state.num_gauss_points())
    base = rows["von-mises linear"]
    print(f"pressed blocks, {args.cells} cells per edge, {MPI.COMM_WORLD.size} rank(s)")
    print(f"{'material':18s} {'F+K (ms)':>9s} {'ratio':>6s} {'per iteration (ms)':>19s} {'ratio':>6s} "
          f"{'iterations':>10s} {'plastic GP':>10s}")
    for name, (assembly, per_iteration, iterations, plastic, total) in rows.items():
        print(f"{name:18s} {1e3 * assembly:9.2f} {assembly / base[0]:6.2f} {1e3 * per_iteration:19.2f} "
              f"{per_iteration / base[1]:6.2f} {iterations:10d} {plastic:>5d}/{total}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
