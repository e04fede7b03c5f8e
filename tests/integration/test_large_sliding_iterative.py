"""The consistent linearisation of node-to-surface and mortar pairs with the iterative linear solver
(issue 41): its augmented u block takes K_t − K + Bᵀ P (B + W) and its pair rows B + W
(:class:`~dolfinx_nnqem.solvers.block_system.AugmentedSystem`), so a slide ends in the direct
solver's state in about its Newton iterations, a fraction of the frozen geometry's."""

import numpy as np
import pytest

from dolfinx_nnqem.cases.large_sliding import slave_force, sliding_blocks
from dolfinx_nnqem.solvers import MonolithicOptions, SolverOptions, make_solver, solve_load_steps

OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)


def _slide(discretisation: str, linear_solver: str, consistent: bool):
    """The frictional block slide (μ_f = 0.3, 12 increments); (u, the slave body's contact force, Newton
    iterations per increment)."""
    problem = sliding_blocks(slide=0.4, mu_f=0.3, discretisation=discretisation)
    settings = MonolithicOptions(consistent_geometry=consistent, linear_solver=linear_solver)
    with make_solver("monolithic", problem, OPTIONS, monolithic=settings) as solver:
        results = solve_load_steps(problem, solver, 12)
    return problem.u.x.array.copy(), slave_force(problem), [r.iterations for r in results]


@pytest.mark.parametrize("discretisation", ["node-to-surface", "mortar"])
def test_the_iterative_solver_takes_the_consistent_geometry(discretisation):
    u_d, f_d, its_d = _slide(discretisation, "direct", True)
    u_i, f_i, its_i = _slide(discretisation, "iterative", True)
    _, _, its_frozen = _slide(discretisation, "iterative", False)
    du = np.abs(u_i - u_d).max() / np.abs(u_d).max()
    df = np.abs(np.asarray(f_i) - np.asarray(f_d)).max() / np.abs(np.asarray(f_d)).max()
    print(f"\n  {discretisation}: Newton iterations, iterative consistent {sum(its_i)} {its_i}, direct consistent "
          f"{sum(its_d)}, iterative frozen {sum(its_frozen)} {its_frozen}; state against the direct solver's: "
          f"u {du:.1e}, force {df:.1e}")
    assert du < 1e-9 and df < 1e-9
    assert sum(its_i) <= 1.3 * sum(its_d) and sum(its_i) < 0.4 * sum(its_frozen)
