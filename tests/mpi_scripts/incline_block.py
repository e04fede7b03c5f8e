"""MPI helper of tests/integration/test_symmetry_planes.py: a block on an incline, held at its side, on any number of ranks.

    mpiexec -n N python incline_block.py OUT.npz DISCRETISATION METHOD MU_F

Body 1 (4 × 2 × 2 hexahedra, bottom clamped) has its top sheared into an incline of slope
:data:`SLOPE`; body 2 (3 × 2 × 2, the slave) rests on it under its own weight G. Body 2's side
face x = 0 is held along x (u_x prescribed: 0 without friction, :data:`DRIVE` up the incline with
it); both bodies' z faces are held along z (a slice in plane strain, the planes z = 0 and z = 0.5
symmetry planes of the interface). The reaction on the side face is statically determinate:
G tan α without friction, G tan(α + φ) (tan φ = μ_f) once every pair slides up the incline. Rank 0
writes the reaction, G, the pair states, the pair normals and the slave positions.
"""

import sys
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dolfinx_nnqem.io import pair_table  # noqa: E402
from dolfinx_nnqem.io.results import reactions  # noqa: E402
from dolfinx_nnqem.material import VonMises  # noqa: E402
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Gravity  # noqa: E402
from dolfinx_nnqem.cases.geometries import BlockStackTags as T  # noqa: E402
from dolfinx_nnqem.cases.geometries import build_block_stack  # noqa: E402
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps  # noqa: E402

SLOPE = 0.1  #: tan α
DRIVE = 1.0e-2  #: u_x of the side face with friction: 40 times the elastic displacements, every pair slides
DENSITY, GRAVITY = 1000.0, 9.81
LX, LZ, HEIGHT = 1.0, 0.5, 0.5


def incline_block(discretisation: str, law: str = "alart-curnier", mu_f: float = 0.0, drive: float = 0.0, *,
                  slope: float = SLOPE, nu: float = 0.3, divisions=((4, 2, 2), (3, 2, 2)),
                  cell_type: str = "hexahedron", comm=MPI.COMM_WORLD) -> tuple[ContactProblem, float]:
    """The problem (module docstring; ``slope`` 0: a flat block) and the weight G of body 2."""
    mesh, ct, ft = build_block_stack(comm, LX, LZ, [HEIGHT, HEIGHT], divisions, cell_type=cell_type)
    x = mesh.geometry.x
    x[:, 1] += slope * x[:, 0]  # a shear: horizontal faces become inclines, the side faces stay planes x = const
    material = VonMises(E=1.0e7, nu=nu, density=DENSITY)
    dirichlet = [Dirichlet(T.xmin(2), drive, [0]), Dirichlet(T.bottom(1))]
    dirichlet += [Dirichlet(face(k), 0.0, [2]) for k in (1, 2) for face in (T.zmin, T.zmax)]
    problem = ContactProblem(mesh, ct, ft, materials={1: material, 2: material}, dirichlet=dirichlet,
                             body_forces=[Gravity((0.0, -GRAVITY, 0.0))],
                             contact=Contact(T.top(1), T.bottom(2), mu_f=mu_f, law=law,
                                             discretisation=discretisation, slave=T.bottom(2)))
    return problem, DENSITY * GRAVITY * LX * HEIGHT * LZ


def exact_reaction(weight: float, mu_f: float) -> float:
    """G tan(α + φ): the side face's force along x on a block sliding up the incline (φ = 0: held)."""
    return weight * np.tan(np.arctan(SLOPE) + np.arctan(mu_f))


def solve(discretisation: str, method: str, mu_f: float, comm=MPI.COMM_WORLD) -> dict[str, np.ndarray]:
    problem, weight = incline_block(discretisation, mu_f=mu_f, drive=DRIVE if mu_f else 0.0, comm=comm)
    with make_solver(method, problem, SolverOptions()) as solver:
        solve_load_steps(problem, solver, 1, max_cutbacks=0)
    table = pair_table(problem)
    return {"reaction": reactions(problem)[T.xmin(2)], "weight": np.array(weight), "state": table["state"],
            "normal": table["frame"][:, 0, :], "position": table["position_b"],
            "describe": np.array(problem.contact.describe()[0])}


if __name__ == "__main__":
    out, discretisation, method, mu_f = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
    data = solve(discretisation, method, mu_f)
    if MPI.COMM_WORLD.rank == 0:
        np.savez(out, **data)
