"""Where the pressed blocks' matrix assembly spends its time: the material's kernel or the insertion.

    python benchmarks/assembly_split.py [--level 6] [--repeat 5]
    mpiexec -n 2 python benchmarks/assembly_split.py --level 10

Assembles, on the pressed blocks of ``--level`` in their initial state, each of these into its
own matrix ``--repeat`` times and prints the CPU seconds of one assembly (the busiest rank):

* the tangent K_t (the von Mises return map and its consistent tangent in the kernel, as in every
  Newton iteration);
* the elastic stiffness K_e (the same sparsity, the same Gauss rule, no return map);
* a vector mass matrix with one Gauss point a cell (the same sparsity, an almost empty kernel):
  about the cost of inserting 24 × 24 element matrices into PETSc's AIJ matrix and of assembling it;
* the internal force (a vector: no insertion into a matrix).

The difference between the first and the last matrix is what the kernels cost; the rest is the
insertion. Asserts nothing; the figures are in ``docs/performance.md``.
"""

from __future__ import annotations

import argparse
import time

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
import dolfinx.fem.petsc
import ufl
from mpi4py import MPI

from dolfinx_nnqem import jit
from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem


def cpu_seconds(assemble, repeat: int, comm) -> float:
    """CPU seconds of one call of ``assemble`` (the mean of ``repeat``; the largest over the ranks)."""
    assemble()  # first call: allocation and any lazy set-up
    comm.Barrier()
    t0 = time.process_time()
    for _ in range(repeat):
        assemble()
    return comm.allreduce((time.process_time() - t0) / repeat, op=MPI.MAX)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--level", type=int, default=6)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    problem = pressed_blocks_problem(args.level, comm)
    V = problem.V
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    one_point_mass = jit.form(ufl.inner(u, v) * ufl.dx(metadata={"quadrature_degree": 0}))
    M = dolfinx.fem.petsc.create_matrix(one_point_mass)

    def assemble_mass():
        M.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(M, one_point_mass)
        M.assemble()

    K_t, K_e = problem.assemble_tangent(), problem.assemble_elastic_stiffness()
    F = problem.assemble_internal_force()
    figures = {
        "tangent K_t": cpu_seconds(lambda: problem.assemble_tangent(K_t), args.repeat, comm),
        "elastic stiffness K_e": cpu_seconds(lambda: problem.assemble_elastic_stiffness(K_e), args.repeat, comm),
        "one-point mass matrix (insertion)": cpu_seconds(assemble_mass, args.repeat, comm),
        "internal force": cpu_seconds(lambda: problem.assemble_internal_force(F), args.repeat, comm),
    }
    cells = comm.allreduce(V.mesh.topology.index_map(3).size_local, op=MPI.SUM)
    nonzeros = K_t.getInfo()["nz_used"]  # collective: the sum over the ranks
    if comm.rank == 0:
        dofs = V.dofmap.index_map.size_global * V.dofmap.index_map_bs
        print(f"pressed blocks, level {args.level}: {dofs} dofs, {cells} cells, {comm.size} rank(s); "
              f"K_t has {nonzeros:.0f} nonzeros")
        for name, seconds in figures.items():
            share = seconds / figures["tangent K_t"]
            print(f"  {name:36s} {seconds:7.3f} s CPU ({1e6 * seconds * comm.size / cells:5.1f} µs a cell, "
                  f"{share:4.2f} of K_t)")


if __name__ == "__main__":
    main()
