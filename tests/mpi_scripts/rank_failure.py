"""MPI helper of tests/mpi/test_reliability_mpi.py: the command line with a failure on ONE rank.

    mpiexec -n 2 python rank_failure.py CASE RANK -- dolfinx-nnqem arguments...

CASE ``solve``: the solver raises ValueError on rank RANK only, in the middle of increment 2
(the other rank is then inside a collective call); CASE ``writer``: rank RANK's writes of
summary.json and pairs.pvd fail with a full disk (only rank 0 writes them: RANK 0).
The script exits with the command line's exit code; it must never hang.
"""

import sys

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
from mpi4py import MPI

from dolfinx_nnqem import cli


def main() -> int:
    case, rank = sys.argv[1], int(sys.argv[2])
    argv = sys.argv[sys.argv.index("--") + 1:]
    if MPI.COMM_WORLD.rank == rank:
        if case == "solve":
            from dolfinx_nnqem.solvers.monolithic import MonolithicSolver

            original = MonolithicSolver.solve_increment
            calls = [0]

            def failing(self, load_factor):
                calls[0] += 1
                if calls[0] == 2:
                    raise ValueError(f"a bad value found on rank {rank} only")
                return original(self, load_factor)

            MonolithicSolver.solve_increment = failing
        elif case == "writer":
            import errno

            from dolfinx_nnqem.io import output, safe_io

            def full(path, text, **kwargs):  # what safe_io raises when the disk is full
                raise OSError(errno.ENOSPC, f"cannot write {path}: No space left on device", str(path))

            output.atomic_write_text = full
            safe_io.StagedFiles.stage = lambda self, path, text: full(path, text)  # the increments' index files
    return cli.main(argv)


if __name__ == "__main__":
    sys.exit(main())
