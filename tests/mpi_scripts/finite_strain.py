"""MPI helper of tests/mpi/test_finite_strain_mpi.py: a rigid sphere pressed 10 % of its height into
an elastoplastic block at finite strain (``kinematics = "finite"``, the contact in the current
geometry), on any number of ranks.

    mpiexec -n N python finite_strain.py OUT.npz

Rank 0 writes, per method (monolithic, NNEQM1), the sphere's force on the block, the Newton
iterations per increment, and the converged Cauchy stress and p at every Gauss point with the
points' positions (gathered), so that the test compares them with the serial run point by point.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # this checkout's package, not an installed one

import dolfinx_nnqem  # noqa: F401, E402  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np  # noqa: E402
import ufl  # noqa: E402
from mpi4py import MPI  # noqa: E402

from dolfinx_nnqem import compat, jit  # noqa: E402
from dolfinx_nnqem.cases.geometries import BlockStackTags as T  # noqa: E402
from dolfinx_nnqem.cases.geometries import build_block_stack  # noqa: E402
from dolfinx_nnqem.contact.obstacles import Sphere  # noqa: E402
from dolfinx_nnqem.io import equilibrium_check  # noqa: E402
from dolfinx_nnqem.material import VonMises  # noqa: E402
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet  # noqa: E402
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps  # noqa: E402

H = 0.5
STEEL_LIKE = VonMises(E=1.0e9, nu=0.3, sigma_y0=2.0e6, H=1.0e8)
METHODS = ("monolithic", "nneqm1")


def sphere_into_block(law: str = "alart-curnier", kinematics: str = "finite", depth: float = 0.05, n: int = 4,
                      comm=MPI.COMM_WORLD) -> ContactProblem:
    """A block 1 × H × 1 clamped at its base; a rigid sphere of radius 0.5 above its centre pressed ``depth`` down."""
    mesh, ct, ft = build_block_stack(comm, 1.0, 1.0, [H], [(n, 2, n)])
    sphere = Sphere(centre=(0.5, H + 0.5, 0.5), radius=0.5, motion=(0.0, -depth, 0.0))
    return ContactProblem(mesh, ct, ft, materials=STEEL_LIKE, dirichlet=[Dirichlet(T.bottom(1))],
                          contact=Contact(sphere, T.top(1), mu_f=0.0, law=law, geometry="current"),
                          kinematics=kinematics)


def gauss_point_fields(problem) -> dict[str, np.ndarray]:
    """The positions, Cauchy stresses and p of every Gauss point over all ranks (owned points, gathered)."""
    st = problem.state
    n = st.num_owned_points()
    comm = problem.comm
    gather = lambda a: np.concatenate(comm.allgather(np.asarray(a)))  # noqa: E731
    return {"x": gather(_positions(problem)), "sigma": gather(st.sigma_n.x.array[:9 * n].reshape(n, 9)),
            "p": gather(st.p_n.x.array[:n])}


def _positions(problem) -> np.ndarray:
    """The reference positions of the owned Gauss points (n, 3)."""
    st = problem.state
    X = ufl.SpatialCoordinate(problem.mesh)
    expression = jit.expression(ufl.as_matrix([[X[0], X[1], X[2]], [0, 0, 0], [0, 0, 0]]),
                                compat.interpolation_points(st.W_tensor))
    return st.owned_at_points(expression, tensor=True)[:, 0, :].copy()


def solve(method: str, comm=MPI.COMM_WORLD, steps: int = 5) -> dict[str, np.ndarray]:
    """Solve the case with ``method``; the gathered results (the same on every rank)."""
    problem = sphere_into_block(comm=comm)
    with make_solver(method, problem, SolverOptions(rtol=1e-11)) as solver:
        results = solve_load_steps(problem, solver, steps)
    force = equilibrium_check(problem)["obstacle_forces"]["sphere-201"]
    return {"force": np.asarray(force), "iterations": np.array([r.iterations for r in results]),
            **gauss_point_fields(problem)}


if __name__ == "__main__":
    out = sys.argv[1]
    data = {f"{method}/{key}": value for method in METHODS for key, value in solve(method).items()}
    if MPI.COMM_WORLD.rank == 0:
        np.savez(out, **data)
