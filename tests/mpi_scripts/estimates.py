"""MPI helper of tests/mpi/test_error_estimates_mpi.py: a run and its error estimates on any number of ranks.

    mpiexec -n N python estimates.py CASE OUT.npz

CASE: "sphere" (a rigid sphere on a graded hexahedral block, degree 2 on the same mesh, with the
Hertz radius and peak pressure as extra quantities) or "refine" (the Hertz quarter model on
tetrahedra, enriched on the uniformly refined mesh: refinement and tag transfer across ranks).
Rank 0 writes every quantity's value, enriched value and estimate, and the recovery indicator's
global η.
"""

import sys
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from dolfinx_nnqem.cases.hertz import hertz_quantities  # noqa: E402
from dolfinx_nnqem.cases.indentation import hertz_tetrahedra_problem  # noqa: E402
from dolfinx_nnqem.estimates import RecoveryIndicator, estimate_errors, probe_points  # noqa: E402
from dolfinx_nnqem.cases.geometries import BlockStackTags as T  # noqa: E402
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps  # noqa: E402


def sphere_problem(comm):
    """The rigid sphere of tests/integration/test_obstacles.py on its graded block (h = a/2), on ``comm``."""
    from dolfinx_nnqem.contact.obstacles import Sphere
    from dolfinx_nnqem.material import VonMises
    from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet
    from dolfinx_nnqem.cases.geometries import build_graded_block

    mesh, ct, ft = build_graded_block(comm, 0.5, fine_width=1.25, fine_depth=0.5)
    sphere = Sphere(centre=(0.0, 50.0, 0.0), radius=50.0, motion=(0.0, -1.0 / 50.0, 0.0))
    return ContactProblem(mesh, ct, ft, materials=VonMises(E=210e3, nu=0.3),
                          dirichlet=[Dirichlet(T.bottom(1)), Dirichlet(T.xmin(1), 0.0, [0]),
                                     Dirichlet(T.zmin(1), 0.0, [2])],
                          contact=Contact(sphere, T.top(1), mu_f=0.0))


def solve_case(case: str, comm) -> dict:
    """Solve ``case`` on ``comm`` and estimate its errors; the same arrays on every rank."""
    if case == "sphere":
        problem, enrichment, extra = sphere_problem(comm), "auto", hertz_quantities(T.top(1), 1.0)
    else:
        problem, enrichment, extra = hertz_tetrahedra_problem(4, comm), "refine", None
    options = SolverOptions(rtol=1e-12)
    with make_solver("monolithic", problem, options) as solver:
        factors = [r.load_factor for r in solve_load_steps(problem, solver, 1)]
    indicator = RecoveryIndicator(problem)
    indicator.update()
    top = comm.allreduce(float(problem.mesh.geometry.x[:, 1].max()), op=MPI.MAX)
    est = estimate_errors(problem, "monolithic", factors, probes=probe_points({"pole": (0.0, top, 0.0)}),
                          enrichment=enrichment, options=options, extra=extra)
    return {"names": np.array([q.name for q in est.quantities]),
            "value": np.array([np.resize(q.value, 3) for q in est.quantities]),
            "enriched": np.array([np.resize(q.enriched, 3) for q in est.quantities]),
            "estimate": np.array([q.estimate for q in est.quantities]),
            "eta": np.array(indicator.global_estimate()), "dofs": np.array([est.dofs, est.enriched_dofs])}


if __name__ == "__main__":
    case, out = sys.argv[1], sys.argv[2]
    data = solve_case(case, MPI.COMM_WORLD)
    if MPI.COMM_WORLD.rank == 0:
        np.savez(out, **data)
