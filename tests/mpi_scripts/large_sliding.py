"""MPI helper of tests/mpi/test_large_sliding_mpi.py: large-sliding cases on any number of ranks.

    mpiexec -n N python large_sliding.py OUT.npz [CASE ...]
    mpiexec -n N python large_sliding.py OUT.npz CASE/METHOD ...   (one method, any of ALL_METHODS)

The frictionless sphere slid over the block (6³, rigid obstacle), the frictional block slid 1.6
master facets over another (node-to-surface, μ_f = 0.3; the same with dual mortar; both frictionless
as ``blocks-frictionless`` and ``mortar-frictionless``) and the ironing of an elastoplastic strip
by a cylinder dragged 8 facets (μ_f = 0.1; the default geometry = "auto", which moves it to the current
geometry once the punch slides), the sphere slid over 4 × 1 × 4 Q2 hexahedra and over 3 × 2 × 3 × 6 P2 tetrahedra
with μ_f = 0.3 (degree 2), the mortar block slide on 2 × 1 × 2 | 3 × 1 × 3 Q2 hexahedra and P2 tetrahedra
(degree 2, 8 increments), the node-to-surface block slide with degree 2 on Q2 hexahedra and P2 tetrahedra,
current geometry, monolithic and NNEQM1 (NNEQM2, or ``iterative``: the monolithic
solver with the iterative linear solver, when named)
(:mod:`dolfinx_nnqem.cases.large_sliding`). Rank 0 writes, per ``CASE/METHOD/``, the pair table's
slave positions and forces on the master side in global pair order, the resultant force, the
Newton iterations and solves per increment, the pairs each rank owns and how many pairs have a master node
owned by another rank than their slave node.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # this checkout's package, not an installed one

import dolfinx_nnqem  # noqa: F401, E402  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402

from dolfinx_nnqem.cases.large_sliding import (ironing, obstacle_force, slave_force, sliding_blocks,  # noqa: E402
                                               sliding_sphere)
from dolfinx_nnqem.io.results import pair_table  # noqa: E402
from dolfinx_nnqem.solvers import MonolithicOptions, SolverOptions, make_solver, solve_load_steps  # noqa: E402

METHODS = ("monolithic", "nneqm1")  #: what a bare CASE runs
ALL_METHODS = (*METHODS, "nneqm2", "iterative")
CASES = {
    "sphere": (lambda comm: sliding_sphere(6, comm=comm), obstacle_force, 16),
    "blocks": (lambda comm: sliding_blocks(slide=0.4, mu_f=0.3, comm=comm), slave_force, 12),
    "mortar": (lambda comm: sliding_blocks(slide=0.4, mu_f=0.3, discretisation="mortar", comm=comm), slave_force, 12),
    "blocks-frictionless": (lambda comm: sliding_blocks(slide=0.4, mu_f=0.0, comm=comm), slave_force, 12),
    "mortar-frictionless": (lambda comm: sliding_blocks(slide=0.4, mu_f=0.0, discretisation="mortar", comm=comm),
                            slave_force, 12),
    "ironing": (lambda comm: ironing(16, geometry=None, comm=comm), obstacle_force, 40),
    "sphere-q2": (lambda comm: sliding_sphere(4, degree=2, ny=1, mu_f=0.3, comm=comm), obstacle_force, 16),
    "sphere-p2": (lambda comm: sliding_sphere(3, degree=2, ny=2, mu_f=0.3, cell_type="tetrahedron", comm=comm),
                  obstacle_force, 16),
    "mortar-q2": (lambda comm: sliding_blocks(slide=0.4, mu_f=0.3, discretisation="mortar", degree=2,
                                              divisions=((2, 1, 2), (3, 1, 3)), comm=comm), slave_force, 8),
    "mortar-p2": (lambda comm: sliding_blocks(slide=0.4, mu_f=0.3, discretisation="mortar", degree=2,
                                              cell_type="tetrahedron", divisions=((2, 1, 2), (3, 1, 3)), comm=comm),
                  slave_force, 8),
    "blocks-q2": (lambda comm: sliding_blocks(slide=0.4, mu_f=0.3, degree=2, comm=comm), slave_force, 12),
    "blocks-p2": (lambda comm: sliding_blocks(slide=0.4, mu_f=0.3, degree=2, cell_type="tetrahedron", comm=comm),
                  slave_force, 12),
}
DEGREE_1 = ("sphere", "blocks", "mortar", "ironing")  #: what a run without CASE names runs


def solve(case: str, method: str, comm=MPI.COMM_WORLD) -> dict[str, np.ndarray]:
    """Solve ``case`` with ``method``; the gathered results (the same on every rank)."""
    build, force, increments = CASES[case]
    problem = build(comm)
    options = SolverOptions(rtol=1e-12, max_iterations=40)
    if method == "iterative":  # the monolithic solver, its linear systems by the iterative solver
        solver = make_solver("monolithic", problem, options, monolithic=MonolithicOptions(linear_solver="iterative"))
    else:
        solver = make_solver(method, problem, options)
    with solver:
        results = solve_load_steps(problem, solver, increments)
    t = pair_table(problem)
    assert problem.contact is not None
    return {"position": t["position_b"], "force": t["force_on_body1"], "total": force(problem),
            "iterations": np.array([r.iterations for r in results]),
            "solves": np.array([r.report.geometry_passes for r in results]),
            "pairs_per_rank": np.array(comm.allgather(problem.contact.num_local)),
            "following": np.array(problem.contact.geometry.following),
            "foreign_masters": np.array(comm.allreduce(foreign_masters(problem), op=MPI.SUM))}


def foreign_masters(problem) -> int:
    """This rank's pairs with a master node that another rank owns (node-to-surface; 0 otherwise)."""
    pairs = problem.contact.interfaces[0].pairs
    if not hasattr(pairs, "master_blocks"):
        return 0
    start, end = problem.V.dofmap.index_map.local_range
    other = (pairs.master_blocks < start) | (pairs.master_blocks >= end)
    pair = np.repeat(np.arange(pairs.num_local), np.diff(pairs.master_indptr))
    return int(np.count_nonzero(np.bincount(pair, other, minlength=pairs.num_local)))


def runs(names: list[str]) -> list[tuple[str, str]]:
    """(case, method) of every name: CASE (every method of METHODS) or CASE/METHOD."""
    out = []
    for name in names:
        case, _, method = name.partition("/")
        if case not in CASES or (method and method not in ALL_METHODS):
            raise SystemExit(f"large_sliding.py: {name!r}: expected CASE or CASE/METHOD with CASE in {list(CASES)} "
                             f"and METHOD in {list(ALL_METHODS)}")
        out += [(case, method)] if method else [(case, m) for m in METHODS]
    return out


if __name__ == "__main__":
    out, names = sys.argv[1], sys.argv[2:] or list(DEGREE_1)
    data = {f"{case}/{method}/{key}": value for case, method in runs(names)
            for key, value in solve(case, method).items()}
    if MPI.COMM_WORLD.rank == 0:
        np.savez(out, **data)
