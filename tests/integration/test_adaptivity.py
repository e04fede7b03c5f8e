"""Adaptive refinement to a target error on tetrahedra (``docs/error-estimates.md``).

* Hertz on tetrahedra (a rigid sphere on an elastic block): the adaptive sequence reaches the
  contact radius and the peak pressure to 1 % of the closed form with fewer dofs than uniform
  refinement of the same initial mesh (slow: a few minutes);
* step-42's setting (a ball pressed into an elastoplastic cube): the contact force per adaptive
  cycle, against step-42's published sequence and the uniform-refinement limit (slow);
* a small adaptive sequence: the refinement concentrates where the indicator is, the tags follow.
"""

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem.cases.hertz import effective_modulus, hertz_contact, hertz_quantities
from dolfinx_nnqem.cases.indentation import (A_HERTZ, HERTZ_MATERIAL, R_HERTZ, STEP42_PUBLISHED,
                                             hertz_tetrahedra_problem, step42_problem)
from dolfinx_nnqem.estimates import read_quantities, rebuild_problem, refine_mesh_and_tags
from dolfinx_nnqem.estimates.adaptive import solve_adaptively
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.solvers import make_solver, solve_load_steps
from dolfinx_nnqem.solvers.checks import CheckOptions

E_STAR = effective_modulus(HERTZ_MATERIAL.E, HERTZ_MATERIAL.nu)
HERTZ = hertz_quantities(T.top(1), A_HERTZ)


def solve(problem, increments=1, check=None):
    with make_solver("monolithic", problem) as solver:
        return [r.load_factor for r in solve_load_steps(problem, solver, increments, check=check)]


STEP42_CHECK = CheckOptions(max_strain=None, max_rotation=None)
"""step-42 is a small-strain model whose strains at the ball's edge pass 10 % on fine meshes (a
contact edge on a material with 1 % hardening): its setting, not a collapse, so the package's
small-strain limit is lifted for it."""


def hertz_errors(problem) -> tuple[int, float, float]:
    """(dofs, |a/a_Hertz − 1|, |p0/p0_Hertz − 1|) at the computed force (quarter model)."""
    q = read_quantities(problem, extra=HERTZ)
    a, p0 = hertz_contact(4 * abs(q["contact:sphere"][1]), R_HERTZ, E_STAR)
    return problem.V.dofmap.index_map.size_global * 3, abs(q["hertz:a"][0] / a - 1), abs(q["hertz:p0"][0] / p0 - 1)


def test_a_small_adaptive_sequence_refines_at_the_contact():
    """Two cycles from 4³ cubes: the second mesh's smallest cells lie at the contact, the tags hold."""
    result = solve_adaptively(hertz_tetrahedra_problem(4), lambda problem, cycle: solve(problem), "monolithic",
                              1e-3, max_cycles=2, quantities=["contact"], enrichment="refine")
    problem = result.problem
    assert [c.index for c in result.cycles] == [1, 2] and result.cycles[1].dofs > result.cycles[0].dofs
    mesh = problem.mesh
    tdim = mesh.topology.dim
    cells = np.arange(mesh.topology.index_map(tdim).size_local, dtype=np.int32)
    h = mesh.h(tdim, cells)
    from dolfinx.mesh import compute_midpoints

    r = np.linalg.norm(compute_midpoints(mesh, tdim, cells)[:, [0, 2]], axis=1)
    y = compute_midpoints(mesh, tdim, cells)[:, 1]
    near = (r < 1.5) & (y > 4.5)
    smallest = MPI.COMM_WORLD.allreduce(h.min(), op=MPI.MIN)
    near_min = MPI.COMM_WORLD.allreduce(h[near].min() if near.any() else np.inf, op=MPI.MIN)
    print(f"\n  cycles: {[(c.dofs, round(c.relative_error, 4)) for c in result.cycles]}; smallest cell "
          f"{smallest:.3f}, near the contact {near_min:.3f}")
    assert near_min == smallest
    top_facets = MPI.COMM_WORLD.allreduce(problem.facet_tags.find(T.top(1)).size, op=MPI.SUM)
    assert problem.num_pairs > 0 and top_facets > 4 * 4 * 2  # the contact surface refined with its body


@pytest.mark.slow
def test_hertz_adaptive_reaches_one_per_cent_with_fewer_dofs_than_uniform():
    history = []

    def run(problem, cycle):
        factors = solve(problem)
        history.append(hertz_errors(problem))
        return factors

    result = solve_adaptively(hertz_tetrahedra_problem(6), run, "monolithic", 0.01, max_cycles=6, quantities=["hertz"],
                              extra=HERTZ, enrichment="refine")
    uniform = []
    problem = hertz_tetrahedra_problem(6)
    for level in range(3):
        solve(problem)
        uniform.append(hertz_errors(problem))
        if level < 2:
            mesh, ct, ft = refine_mesh_and_tags(problem.mesh, problem.cell_tags, problem.facet_tags)
            problem = rebuild_problem(problem, mesh, ct, ft, 1)
    print("\n  adaptive: " + "; ".join(f"{d} dofs a {100 * ea:.2f} % p0 {100 * ep:.2f} % (estimate "
                                       f"{100 * c.relative_error:.2f} %)" for (d, ea, ep), c in zip(history, result.cycles)))
    print("  uniform:  " + "; ".join(f"{d} dofs a {100 * ea:.2f} % p0 {100 * ep:.2f} %" for d, ea, ep in uniform))
    dofs, err_a, err_p0 = history[-1]
    assert result.reached and max(err_a, err_p0) < 0.01
    reached = [d for d, ea, ep in uniform if max(ea, ep) < 0.01]
    assert dofs < (reached[0] if reached else uniform[-1][0])


@pytest.mark.slow
def test_step42_sphere_on_an_elastoplastic_cube_adaptive_and_uniform():
    forces = []

    def run(problem, cycle):
        factors = solve(problem, 4, STEP42_CHECK)
        forces.append((problem.V.dofmap.index_map.size_global * 3,
                       4 * abs(read_quantities(problem)["contact:ball"][1])))
        return factors

    result = solve_adaptively(step42_problem(4), run, "monolithic", 0.005, max_cycles=5, quantities=["contact"],
                              enrichment="refine", check=STEP42_CHECK)
    uniform = []
    problem = step42_problem(4)
    for level in range(3):
        solve(problem, 4, STEP42_CHECK)
        uniform.append((problem.V.dofmap.index_map.size_global * 3,
                        4 * abs(read_quantities(problem)["contact:ball"][1])))
        if level < 2:
            mesh, ct, ft = refine_mesh_and_tags(problem.mesh, problem.cell_tags, problem.facet_tags)
            problem = rebuild_problem(problem, mesh, ct, ft, 1)
    print(f"\n  step-42 published (whole cube): {STEP42_PUBLISHED}")
    print("  adaptive (quarter, force × 4): " + "; ".join(f"{d} dofs F = {f:.3f}" for d, f in forces))
    print("  uniform: " + "; ".join(f"{d} dofs F = {f:.3f}" for d, f in uniform))
    (_, f1), (_, f2), (_, f3) = uniform  # h, h/2, h/4: Richardson's limit with the observed order
    limit = f3 - (f2 - f3) ** 2 / ((f1 - f2) - (f2 - f3))
    print(f"  uniform limit (extrapolated) F = {limit:.3f}")
    assert abs(forces[-1][1] / limit - 1) < 0.05 and forces[-1][0] < uniform[-1][0]
    assert all(f > 0 for _, f in forces)
