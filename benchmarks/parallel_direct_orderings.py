"""Accuracy of the parallel direct solvers on the monolithic Newton matrices of the pressed blocks.

    mpiexec -n 2 python benchmarks/parallel_direct_orderings.py            # level 1, 6 matrices, 3 repetitions
    mpiexec -n 2 python benchmarks/parallel_direct_orderings.py --level 3 --matrices 1 --repeat 1   # the fill

The pressed blocks at level 1 (``dolfinx_nnqem.cases.pressed_blocks``, 525 rows) are solved by the
monolithic solver with the package's direct-solver options, and the Newton matrices J and
right-hand sides b of the first ``--matrices`` direct solves are kept (the first is the first
increment's, where the upper block is held only by contact: 65 zero diagonal entries, condition
2.8e10; the others follow the solver's path, the serial one when its solves are accurate). Each is
then solved again with every option set below, ``--repeat`` times with a fresh KSP (the parallel
factorisations are not reproducible from run to run), and the script prints, per option set, the
largest and the median relative residual ‖J x − b‖ / ‖b‖ over the matrices and repetitions, the
failed solves (above 1e-6, what the solvers count as failed) per matrix, and MUMPS's entries in
the factors (INFOG(29): the fill its ordering leaves) and the ordering it used (INFOG(7): the
automatic choice is 7's answer). Option sets that need a package PETSc lacks
(METIS, ParMETIS, PT-Scotch, SuperLU_dist) are listed as such. Asserts nothing; docs/install.md
has the figures on both software stacks.
"""

import argparse
import statistics

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
from dolfinx_nnqem.numerics.linalg import clear_options, create_ksp, relative_residual
from dolfinx_nnqem.solvers import ConvergenceError, MonolithicOptions, solve_load_steps
from dolfinx_nnqem.solvers import linear_solver
from dolfinx_nnqem.solvers.monolithic import MonolithicSolver

LU = {"ksp_type": "preonly", "pc_type": "lu"}
MUMPS = {**LU, "pc_factor_mat_solver_type": "mumps"}
SUPERLU = {**LU, "pc_factor_mat_solver_type": "superlu_dist"}
OPTION_SETS = {  # name: (options, the external packages it needs)
    "MUMPS, automatic ordering (ICNTL(7) = 7)": ({**MUMPS}, ()),
    "MUMPS, AMD (ICNTL(7) = 0)": ({**MUMPS, "mat_mumps_icntl_7": 0}, ()),
    "MUMPS, AMF (ICNTL(7) = 2)": ({**MUMPS, "mat_mumps_icntl_7": 2}, ()),
    "MUMPS, SCOTCH (ICNTL(7) = 3)": ({**MUMPS, "mat_mumps_icntl_7": 3}, ("scotch",)),
    "MUMPS, PORD (ICNTL(7) = 4)": ({**MUMPS, "mat_mumps_icntl_7": 4}, ()),
    "MUMPS, METIS (ICNTL(7) = 5)": ({**MUMPS, "mat_mumps_icntl_7": 5}, ("metis",)),
    "MUMPS, QAMD (ICNTL(7) = 6)": ({**MUMPS, "mat_mumps_icntl_7": 6}, ()),
    "MUMPS, parallel PT-Scotch (ICNTL(28) = 2, ICNTL(29) = 1)": (
        {**MUMPS, "mat_mumps_icntl_28": 2, "mat_mumps_icntl_29": 1}, ("ptscotch",)),
    "MUMPS, parallel ParMETIS (ICNTL(28) = 2, ICNTL(29) = 2)": (
        {**MUMPS, "mat_mumps_icntl_28": 2, "mat_mumps_icntl_29": 2}, ("parmetis",)),
    "MUMPS, automatic ordering, pivot threshold 0.1 (CNTL(1))": ({**MUMPS, "mat_mumps_cntl_1": 0.1}, ()),
    "MUMPS, automatic ordering, pivot threshold 0.5 (CNTL(1))": ({**MUMPS, "mat_mumps_cntl_1": 0.5}, ()),
    "MUMPS, centralised matrix (ICNTL(18) = 0)": ({**MUMPS, "mat_mumps_icntl_18": 0}, ()),
    "MUMPS, AMD, centralised matrix (ICNTL(18) = 0)": ({**MUMPS, "mat_mumps_icntl_7": 0, "mat_mumps_icntl_18": 0}, ()),
    "SuperLU_dist, defaults": ({**SUPERLU}, ("superlu_dist",)),
    "SuperLU_dist, colperm MMD_AT_PLUS_A": ({**SUPERLU, "mat_superlu_dist_colperm": "MMD_AT_PLUS_A"},
                                            ("superlu_dist",)),
    "SuperLU_dist, colperm MMD_ATA": ({**SUPERLU, "mat_superlu_dist_colperm": "MMD_ATA"}, ("superlu_dist",)),
    "SuperLU_dist, colperm NATURAL": ({**SUPERLU, "mat_superlu_dist_colperm": "NATURAL"}, ("superlu_dist",)),
    "SuperLU_dist, colperm COLAMD": ({**SUPERLU, "mat_superlu_dist_colperm": "COLAMD"}, ("superlu_dist",)),
    "SuperLU_dist, colperm PARMETIS": ({**SUPERLU, "mat_superlu_dist_colperm": "PARMETIS"},
                                       ("superlu_dist", "parmetis")),
}
"""SuperLU_dist's METIS_AT_PLUS_A is left out: the PyPI wheel's SuperLU_dist has no METIS of its own
(though PETSc has) and ends the process ("Invalid ISPEC ... get_perm_c.c")."""


def newton_matrices(count: int, comm, level: int = 1) -> list[tuple[PETSc.Mat, PETSc.Vec]]:
    """(J, b) of the first ``count`` direct solves of the monolithic solver on the pressed blocks
    with the default options (copies): the matrices of its path, when its solves are accurate."""
    kept: list[tuple[PETSc.Mat, PETSc.Vec]] = []
    solve = linear_solver.DirectSolver.solve

    def keeping(self, J, b, x, pair_state=None):
        if len(kept) < count:
            kept.append((J.copy(), b.copy()))
        return solve(self, J, b, x, pair_state)

    linear_solver.DirectSolver.solve = keeping
    problem = pressed_blocks_problem(level, comm)
    try:
        solve_load_steps(problem, MonolithicSolver(problem, monolithic=MonolithicOptions(linear_solver="direct")), 6,
                         max_cutbacks=0)
    except ConvergenceError:
        pass  # the matrices met before the failure are what is measured
    finally:
        linear_solver.DirectSolver.solve = solve
    return kept


def residual_with(options: dict, J: PETSc.Mat, b: PETSc.Vec, prefix: str) -> tuple[float, int, int]:
    """(‖J x − b‖ / ‖b‖, entries in the factors, ordering used) of one fresh solve with ``options``;
    the residual is inf when the factorisation fails; MUMPS's INFOG(29) and INFOG(7) (0 AMD, 2 AMF,
    3 SCOTCH, 4 PORD, 5 METIS, 6 QAMD), −1 for another package."""
    ksp = create_ksp(J.getComm(), prefix, options)
    ksp.setOperators(J)
    x = b.duplicate()
    entries, ordering = 0, -1
    try:
        ksp.setUp()
        ksp.solve(b, x)
        failed = ksp.getConvergedReason() <= 0 or not np.all(np.isfinite(x.getArray(readonly=True)))
        residual = float("inf") if failed else relative_residual(J, x, b)
        if options.get("pc_factor_mat_solver_type") == "mumps":
            factor = ksp.getPC().getFactorMatrix()
            entries, ordering = int(factor.getMumpsInfog(29)), int(factor.getMumpsInfog(7))
    except PETSc.Error:
        residual = float("inf")
    finally:
        clear_options(prefix, options)
        ksp.destroy()
        x.destroy()
    return MPI.COMM_WORLD.allreduce(residual, op=MPI.MAX), entries, ordering


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--level", type=int, default=1, help="the pressed blocks' level (default 1)")
    parser.add_argument("--matrices", type=int, default=6, help="Newton matrices kept (default 6)")
    parser.add_argument("--repeat", type=int, default=3, help="fresh solves per matrix and option set (default 3)")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    kept = newton_matrices(args.matrices, comm, args.level)
    say = print if comm.rank == 0 else (lambda *a, **k: None)
    say(f"{comm.size} ranks, PETSc {'.'.join(map(str, PETSc.Sys.getVersion()))}; {len(kept)} Newton matrices of "
        f"{kept[0][0].getSize()[0]} rows (level {args.level}); packages: "
        + ", ".join(f"{p} {'yes' if PETSc.Sys.hasExternalPackage(p) else 'no'}"
                    for p in ("metis", "parmetis", "scotch", "ptscotch", "superlu_dist")))
    say("| options | largest ‖Jx − b‖/‖b‖ | median | solves above 1e-6 (per matrix) | entries in the factors | "
        "ordering used (INFOG(7)) |\n|---|---|---|---|---|---|")
    for k, (name, (options, needs)) in enumerate(OPTION_SETS.items()):
        missing = [p for p in needs if not PETSc.Sys.hasExternalPackage(p)]
        if missing:
            say(f"| {name} | not in this PETSc ({', '.join(missing)}) | | | | |")
            continue
        solves = [[residual_with(options, J, b, f"ordering_{k}_{r}_") for r in range(args.repeat)] for J, b in kept]
        residuals = [r for per_matrix in solves for r, _, _ in per_matrix]
        bad = [sum(1 for r, _, _ in per_matrix if not r <= 1e-6) for per_matrix in solves]
        entries = max(e for per_matrix in solves for _, e, _ in per_matrix)
        used = sorted({o for per_matrix in solves for _, _, o in per_matrix if o >= 0})
        say(f"| {name} | {max(residuals):.1e} | {statistics.median(residuals):.1e} | {sum(bad)} of {len(residuals)} "
            f"({', '.join(map(str, bad))}) | {entries if entries else '–'} | {', '.join(map(str, used)) or '–'} |")


if __name__ == "__main__":
    main()
