"""Cost of the cell-shape check (``problem/mesh_quality.py``) against the problem set-up it is part of.

    python benchmarks/mesh_check_cost.py                    # about 10⁶ displacement dofs per mesh
    python benchmarks/mesh_check_cost.py --n 20 --n2 8      # quick check
    mpiexec -n 2 python benchmarks/mesh_check_cost.py

A unit box of n³ trilinear hexahedra (degree 1, 2 × 2 × 2 Gauss points and 8 vertices per cell),
the same box cut into 6 n³ linear tetrahedra (degree 1, one point per cell), and a unit box of gmsh's second-order (10-node) tetrahedra, n2 divisions per edge (degree 2,
4th-degree rule: 14 Gauss points and 4 vertices). For each it times, in the same process: building the ``ContactProblem`` (supports
and a load, no contact; the shape check included, JIT warm from a first small build), and the
shape check alone (``check_cells``, repeated 3 times, the best). Times are the process's CPU
seconds (the largest over the ranks), so that a machine shared with other work shows the cost of
the work itself. Prints the seconds and their ratio; asserts nothing.
"""

import argparse
import time

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
import dolfinx
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.problem import ContactProblem, Dirichlet, Pressure
from dolfinx_nnqem.problem.mesh_quality import check_cells
from dolfinx_nnqem.cases.geometries import build_block_stack


def boxed(mesh, degree: int) -> tuple:
    """The mesh's boundary x = 0 (tag 1, clamped) and x = 1 (tag 2, pressed), and its problem."""
    fdim = mesh.topology.dim - 1
    left = dolfinx.mesh.locate_entities_boundary(mesh, fdim, lambda x: np.isclose(x[0], 0.0))
    right = dolfinx.mesh.locate_entities_boundary(mesh, fdim, lambda x: np.isclose(x[0], 1.0))
    facets = np.concatenate([left, right])
    values = np.concatenate([np.full(len(left), 1, dtype=np.int32), np.full(len(right), 2, dtype=np.int32)])
    order = np.argsort(facets)
    facet_tags = dolfinx.mesh.meshtags(mesh, fdim, facets[order], values[order])
    t0 = time.process_time()
    problem = ContactProblem(mesh, None, facet_tags, materials=VonMises(E=1e9, nu=0.3), dirichlet=[Dirichlet(1)],
                             tractions=[Pressure(2, 1e6)], degree=degree)
    return problem, time.process_time() - t0


def measure(comm, name: str, make, degree: int) -> None:
    mesh = make()
    problem, setup = boxed(mesh, degree)
    dofs = 3 * problem.V.dofmap.index_map.size_global
    quadrature_degree = problem.state.quadrature_degree
    best = np.inf
    for _ in range(3):
        comm.Barrier()
        t0 = time.process_time()
        quality = check_cells(mesh, None, quadrature_degree)
        best = min(best, comm.allreduce(time.process_time() - t0, op=MPI.MAX))
    setup = comm.allreduce(setup, op=MPI.MAX)
    if comm.rank == 0:
        print(f"{name}: {quality.num_cells} cells, {dofs} dofs, {quality.num_points} points per cell; "
              f"set-up {setup:.2f} s CPU, shape check {best:.3f} s = {best / setup:.1%} of the set-up "
              f"(smallest s {quality.min_scaled_jacobian:.3f}, ρ {quality.min_ratio:.3f})", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=69, help="hexahedra per side (69: 1.03e6 dofs)")
    parser.add_argument("--n2", type=int, default=34, help="tetrahedron box divisions (34: about 10⁶ dofs at degree 2)")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    hexahedron, tetrahedron = dolfinx.mesh.CellType.hexahedron, dolfinx.mesh.CellType.tetrahedron
    boxed(dolfinx.mesh.create_unit_cube(comm, 2, 2, 2, hexahedron), 1)  # JIT warm
    boxed(dolfinx.mesh.create_unit_cube(comm, 2, 2, 2, tetrahedron), 2)
    measure(comm, "Q1 hexahedra", lambda: dolfinx.mesh.create_unit_cube(comm, args.n, args.n, args.n, hexahedron), 1)
    measure(comm, "P1 tetrahedra (one point: J is constant)",
            lambda: dolfinx.mesh.create_unit_cube(comm, args.n, args.n, args.n, tetrahedron), 1)
    measure(comm, "P2 on 10-node tetrahedra (gmsh)",
            lambda: build_block_stack(comm, 1.0, 1.0, [1.0], [(args.n2,) * 3], cell_type="tetrahedron", order=2)[0], 2)


if __name__ == "__main__":
    main()
