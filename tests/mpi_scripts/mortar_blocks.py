"""MPI helper of tests/mpi/test_nonmatching_mpi.py: a non-matching block pair (dual mortar) on any number of ranks.

    mpiexec -n N python mortar_blocks.py OUT.npz METHOD [METHOD ...]

Body 1 (y in [0, 0.5], 4 × 2 × 4 hexahedra, bottom clamped) under body 2 (y in [0.5, 1], 3 × 2 × 3):
the interface meshes do not match, body 1's finer face is the mortar slave. A pressure on body 2's
top is ramped first, then the top is dragged in x (u_x prescribed) far enough that friction
matters: part of the interface slips. u_z = 0 on the z faces. For each METHOD, rank 0 writes
(keys prefixed ``METHOD/``) the pair table's slave positions, forces on body 1 (the master side)
and slave displacements in the global pair order, the displacements at the probe nodes, the
Newton iterations per increment and the pairs each rank owns.
"""

import sys
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dolfinx_nnqem.material import VonMises  # noqa: E402
from dolfinx_nnqem.cases.geometries import BlockStackTags as T  # noqa: E402
from dolfinx_nnqem.cases.geometries import build_block_stack  # noqa: E402
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure  # noqa: E402
from dolfinx_nnqem.io.results import node_blocks_at_points, pair_table, values_at_blocks  # noqa: E402
from dolfinx_nnqem.solvers import SolverOptions, make_solver  # noqa: E402
from dolfinx_nnqem.solvers import solve_load_steps  # noqa: E402

P = 1.0e6
DRAG = 2.0e-3
MU_F = 0.3
INCREMENTS = 6
PROBES = [  # (node position, body): corners of both blocks and interior interface nodes
    ((1.0, 1.0, 1.0), 2), ((0.0, 1.0, 0.0), 2), ((1.0 / 3.0, 0.5, 2.0 / 3.0), 2), ((1.0, 0.5, 0.0), 2),
    ((0.5, 0.5, 0.5), 1), ((0.25, 0.5, 0.75), 1), ((1.0, 0.5, 1.0), 1), ((0.0, 0.25, 0.0), 1),
]


def pressure_amplitude(load_factor: float) -> float:
    return min(load_factor / 0.3, 1.0)


def drag_amplitude(load_factor: float) -> float:
    return max(load_factor - 0.3, 0.0) / 0.7


def mortar_blocks(comm=MPI.COMM_WORLD) -> ContactProblem:
    """The problem (see the module docstring)."""
    mesh, ct, ft = build_block_stack(comm, 1.0, 1.0, [0.5, 0.5], [(4, 2, 4), (3, 2, 3)])
    material = VonMises(E=1.0e9, nu=0.3)
    dirichlet = [Dirichlet(T.bottom(1)), Dirichlet(T.top(2), DRAG, [0], amplitude=drag_amplitude)]
    dirichlet += [Dirichlet(face(k), 0.0, [2]) for k in (1, 2) for face in (T.zmin, T.zmax)]
    return ContactProblem(mesh, ct, ft, materials={1: material, 2: material}, dirichlet=dirichlet,
                          tractions=[Pressure(T.top(2), P, amplitude=pressure_amplitude)],
                          contact=Contact(T.top(1), T.bottom(2), mu_f=MU_F, discretisation="mortar"))


def solve(method: str, comm=MPI.COMM_WORLD) -> dict[str, np.ndarray]:
    """Solve with ``method``; the gathered results (the same on every rank)."""
    problem = mortar_blocks(comm)
    solver = make_solver(method, problem, SolverOptions(rtol=1e-12, max_iterations=40))
    results = solve_load_steps(problem, solver, INCREMENTS)
    t = pair_table(problem)
    probe_u = np.array([values_at_blocks(problem, node_blocks_at_points(problem, np.array([x]), body))[0]
                        for x, body in PROBES])
    return {"position": t["position_b"], "force": t["force_on_body1"], "u": t["u_body2"], "state": t["state"],
            "probe_u": probe_u, "iterations": np.array([r.iterations for r in results]),
            "pairs_per_rank": np.array(comm.allgather(problem.contact.interfaces[0].pairs.num_local))}


if __name__ == "__main__":
    out, methods = sys.argv[1], sys.argv[2:]
    data = {f"{method}/{key}": value for method in methods for key, value in solve(method).items()}
    if MPI.COMM_WORLD.rank == 0:
        np.savez(out, **data)
