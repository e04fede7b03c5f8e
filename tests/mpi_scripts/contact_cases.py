"""MPI helper of tests/mpi/test_contact_mpi.py: a contact case solved on any number of ranks.

    mpiexec -n N python contact_cases.py CASE METHOD OUT.npz

CASE: "three_blocks" (two interfaces, the drag making the lower one slide), "elastic_on_plastic"
(pressed and dragged blocks, the lower one elastic), "plastic_drag" (the same, both plastic: the
robustness suite's drag-0.2-hex), "plane_press" (a rigid plane pressed into a von Mises cube in one
increment: yield in the first) or "sphere" (a rigid sphere pressed on a graded block, then sliding
sideways). METHOD: a method's name, or "nneqm2-frozen" (NNEQM2's seed variant). Rank 0 writes the pair table's slave
positions, interfaces, forces on body 1 and slave displacements (global pair order) and the
iterations per increment.
"""

import sys
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "integration"))  # the test module this script runs

from dolfinx_nnqem.io import pair_table  # noqa: E402
from dolfinx_nnqem.solvers import SolverOptions, make_solver  # noqa: E402
from dolfinx_nnqem.solvers import solve_load_steps  # noqa: E402


def elastic_on_plastic_blocks(comm, plastic_below: bool = False):
    """The pressed blocks of the robustness suite (drag 0.2 p), the lower block elastic (unless
    ``plastic_below``): NNEQM2 has plastic unknowns in the upper block only, numbered across ranks."""
    from dolfinx_nnqem.material import VonMises
    from dolfinx_nnqem.cases.geometries import BlockStackTags as B
    from dolfinx_nnqem.cases.geometries import build_block_stack
    from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure, Traction

    mesh, ct, ft = build_block_stack(comm, 1.0, 1.0, (0.5, 0.5), ((4, 2, 4), (4, 2, 4)))
    plastic = VonMises(E=2.0e10, nu=0.2, sigma_y0=2.0e7, H=2.0e9)
    return ContactProblem(
        mesh, ct, ft, materials={1: plastic if plastic_below else VonMises(E=2.0e10, nu=0.2), 2: plastic},
        dirichlet=[Dirichlet(B.bottom(1))] + [Dirichlet(f(k), 0.0, [2]) for k in (1, 2) for f in (B.zmin, B.zmax)],
        tractions=[Pressure(B.top(2), 3.0e7), Traction(B.top(2), (0.2 * 3.0e7, 0.0, 0.0))],
        contact=Contact(B.top(1), B.bottom(2), mu_f=0.3))


def plane_press(comm):
    """The unit cube (4 × 4 × 4 hexahedra, rollers) pressed 0.01 by a frictionless rigid plane."""
    from dolfinx_nnqem.contact.obstacles import Plane
    from dolfinx_nnqem.material import VonMises
    from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet
    from dolfinx_nnqem.cases.geometries import BlockStackTags as B
    from dolfinx_nnqem.cases.geometries import build_block_stack

    mesh, ct, ft = build_block_stack(comm, 1.0, 1.0, (1.0,), ((4, 4, 4),))
    plane = Plane(point=(0.0, 1.0, 0.0), normal=(0.0, -1.0, 0.0), motion=(0.0, -0.01, 0.0))
    return ContactProblem(
        mesh, ct, ft, materials=VonMises(E=200000.0, nu=0.3, sigma_y0=400.0, H=2000.0),
        dirichlet=[Dirichlet(B.bottom(1), 0.0, [1]), Dirichlet(B.xmin(1), 0.0, [0]), Dirichlet(B.zmin(1), 0.0, [2])],
        contact=Contact(plane, B.top(1), mu_f=0.0))


def solve_case(case: str, method: str, comm=MPI.COMM_WORLD) -> dict:
    if case == "three_blocks":
        from test_interfaces import three_blocks

        problem, increments = three_blocks(mu_f=(0.2, 0.4), drag=1.0e-2, comm=comm), 10
    elif case == "elastic_on_plastic":
        problem, increments = elastic_on_plastic_blocks(comm), 5
    elif case == "plastic_drag":
        problem, increments = elastic_on_plastic_blocks(comm, plastic_below=True), 5
    elif case == "plane_press":
        problem, increments = plane_press(comm), 1
    elif case == "sphere":
        from test_obstacles import sphere_problem_sliding

        problem, increments = sphere_problem_sliding(comm), 4
    else:
        raise ValueError(f"unknown case {case!r}")
    extra = {}
    if method == "nneqm2-frozen":
        from dolfinx_nnqem.solvers import NNEQM2Options

        method, extra = "nneqm2", {"nneqm2": NNEQM2Options(flow_directions="frozen")}
    solver = make_solver(method, problem, SolverOptions(rtol=1e-12, max_iterations=40), **extra)
    results = solve_load_steps(problem, solver, increments)
    t = pair_table(problem)
    return {"position": t["position_b"], "interface": t["interface"], "force": t["force_on_body1"],
            "u": t["u_body2"], "iterations": np.array([r.iterations for r in results])}


if __name__ == "__main__":
    case, method, out = sys.argv[1:4]
    data = solve_case(case, method)
    if MPI.COMM_WORLD.rank == 0:
        np.savez(out, **data)
