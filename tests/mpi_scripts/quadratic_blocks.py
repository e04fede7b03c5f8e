"""MPI helper of tests/integration/test_quadratic_contact.py: contact with degree-2 displacements on any number of ranks.

    mpiexec -n N python quadratic_blocks.py OUT.npz

Cases (every one degree 2):

* ``tet-node-to-surface/monolithic`` and ``.../nneqm1``: body 1 (y in [0, 0.5], tetrahedra with
  4 × 2 × 4 edge divisions, bottom clamped) under body 2 (3 × 2 × 3): non-matching interfaces,
  node-to-surface pairs (tri6 facets: transformed slave basis). A pressure on body 2's top is
  ramped, then the top is dragged in x far enough that part of the interface slips.
* ``tet-mortar/monolithic``, ``tet-mortar/nneqm1`` and ``hex-mortar/nneqm2``: the same blocks
  (hexahedra: Q2, 4 × 2 × 4 against 3 × 2 × 3) with dual mortar pairs on the quadratic facets.
* ``hex-plane/monolithic``: a rigid plane pressed into the top of a Q2 block (clamped bottom,
  μ_f = 0.3), then moved sideways until the contact slides.
* ``sphere-order2/monolithic``: a hemisphere (R = 5) pressed on a block, a second-order gmsh mesh
  (10-node tetrahedra, the cap's facets curved; degree 2 by default), node-to-surface, frictionless;
  ``sphere-order2-mortar/monolithic``: the same with dual mortar on the curved cap.

For each case rank 0 writes (keys prefixed ``CASE/``) the pair table's slave positions, forces on
body 1, slave displacements and states, and the pairs each rank owns.
"""

import sys
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dolfinx_nnqem.contact.obstacles import Plane  # noqa: E402
from dolfinx_nnqem.io.results import pair_table  # noqa: E402
from dolfinx_nnqem.material import VonMises  # noqa: E402
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, PiecewiseLinearPath, Pressure  # noqa: E402
from dolfinx_nnqem.cases.geometries import BlockStackTags as T  # noqa: E402
from dolfinx_nnqem.cases.geometries import SphereOnBlockTags as S  # noqa: E402
from dolfinx_nnqem.cases.geometries import build_block_stack, build_sphere_on_block  # noqa: E402
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps  # noqa: E402

P = 1.0e6
DRAG = 2.0e-3
MU_F = 0.3
INCREMENTS = 4
CASES = ("tet-node-to-surface/monolithic", "tet-node-to-surface/nneqm1", "hex-plane/monolithic",
         "sphere-order2/monolithic", "tet-mortar/monolithic", "tet-mortar/nneqm1", "hex-mortar/nneqm2",
         "sphere-order2-mortar/monolithic")


def pressure_amplitude(load_factor: float) -> float:
    return min(load_factor / 0.3, 1.0)


def drag_amplitude(load_factor: float) -> float:
    return max(load_factor - 0.3, 0.0) / 0.7


def blocks(comm, discretisation: str = "node-to-surface", cell_type: str = "tetrahedron") -> ContactProblem:
    mesh, ct, ft = build_block_stack(comm, 1.0, 1.0, [0.5, 0.5], [(4, 2, 4), (3, 2, 3)], cell_type=cell_type)
    material = VonMises(E=1.0e9, nu=0.3)
    dirichlet = [Dirichlet(T.bottom(1)), Dirichlet(T.top(2), DRAG, [0], amplitude=drag_amplitude)]
    dirichlet += [Dirichlet(face(k), 0.0, [2]) for k in (1, 2) for face in (T.zmin, T.zmax)]
    return ContactProblem(mesh, ct, ft, materials={1: material, 2: material}, dirichlet=dirichlet,
                          tractions=[Pressure(T.top(2), P, amplitude=pressure_amplitude)],
                          contact=Contact(T.top(1), T.bottom(2), mu_f=MU_F, discretisation=discretisation),
                          degree=2)


def plane(comm) -> ContactProblem:
    mesh, ct, ft = build_block_stack(comm, 1.0, 1.0, [0.5], [(2, 2, 2)])
    path = PiecewiseLinearPath([[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, -1.0e-3, 0.0], [1.0, 2.0e-3, -1.0e-3, 0.0]])
    obstacle = Plane(point=(0.0, 0.5, 0.0), normal=(0.0, -1.0, 0.0), motion=path)
    return ContactProblem(mesh, ct, ft, materials=VonMises(E=1.0e9, nu=0.3), dirichlet=[Dirichlet(T.bottom(1))],
                          contact=Contact(obstacle, T.top(1), mu_f=MU_F), degree=2)


def sphere(comm, discretisation: str = "node-to-surface") -> ContactProblem:
    mesh, ct, ft = build_sphere_on_block(comm, 5.0, 3.0, 0.5, h_max=1.0, fine_radius=0.8, contact_radius=1.5, order=2)
    steel, aluminium = VonMises(E=210e3, nu=0.3), VonMises(E=70e3, nu=0.33)
    dirichlet = [Dirichlet(S.BOTTOM), Dirichlet(S.LOAD, -0.1, [1])]
    dirichlet += [Dirichlet(tag, 0.0, [0]) for tag in (S.BLOCK_XMIN, S.SPHERE_XMIN)]
    dirichlet += [Dirichlet(tag, 0.0, [2]) for tag in (S.BLOCK_ZMIN, S.SPHERE_ZMIN)]
    return ContactProblem(mesh, ct, ft, materials={S.BLOCK: aluminium, S.SPHERE: steel}, dirichlet=dirichlet,
                          contact=Contact(S.CONTACT1, S.CONTACT2, mu_f=0.0, discretisation=discretisation))


def solve(case: str, comm=MPI.COMM_WORLD) -> dict[str, np.ndarray]:
    """Solve ``case``; the gathered results (the same on every rank)."""
    name, method = case.split("/")
    problem = {"tet-node-to-surface": blocks, "hex-plane": plane, "sphere-order2": sphere,
               "tet-mortar": lambda c: blocks(c, "mortar"),
               "hex-mortar": lambda c: blocks(c, "mortar", "hexahedron"),
               "sphere-order2-mortar": lambda c: sphere(c, "mortar")}[name](comm)
    solver = make_solver(method, problem, SolverOptions(rtol=1e-12, max_iterations=40))
    results = solve_load_steps(problem, solver, INCREMENTS)
    t = pair_table(problem)
    return {"position": t["position_b"], "force": t["force_on_body1"], "u": t["u_body2"], "state": t["state"],
            "iterations": np.array([r.iterations for r in results]),
            "pairs_per_rank": np.array(comm.allgather(problem.contact.interfaces[0].pairs.num_local))}


def compare(serial: dict, parallel: dict) -> dict:
    """Pair by pair (sorted by the slave node's position): the largest relative differences."""
    def order(position):
        x = position.round(9)
        return np.lexsort((x[:, 2], x[:, 1], x[:, 0]))

    i, j = order(parallel["position"]), order(serial["position"])
    states = dict(zip(*np.unique(serial["state"], return_counts=True)))
    return {"pairs": len(j), "states": {int(k): int(v) for k, v in states.items()},
            "same_states": bool(len(i) == len(j) and np.array_equal(parallel["state"][i], serial["state"][j])),
            "force": float(np.abs(parallel["force"][i] - serial["force"][j]).max() / np.abs(serial["force"]).max()),
            "u": float(np.abs(parallel["u"][i] - serial["u"][j]).max() / np.abs(serial["u"]).max()),
            "pairs_per_rank": parallel["pairs_per_rank"].tolist(),
            "iterations": (serial["iterations"].tolist(), parallel["iterations"].tolist())}


if __name__ == "__main__":
    data = {f"{case}/{key}": value for case in CASES for key, value in solve(case).items()}
    if MPI.COMM_WORLD.rank == 0:
        np.savez(sys.argv[1], **data)
