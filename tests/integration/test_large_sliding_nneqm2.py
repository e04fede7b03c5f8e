"""NNEQM2 in the current contact geometry at small strain (issue 41: its refusal lifted).

NNEQM2 keeps its elastic stiffness factorised once per run and follows the pairs: what it built on
B is made again when the geometry changes, and load stepping's repeated solves end at the state
whose own geometry it was solved in (``solvers/nneqm2/current_geometry.py``). On the cases of
:mod:`dolfinx_nnqem.cases.large_sliding`:

* the frictionless sphere slid over a block (rigid obstacle), both laws: the monolithic solver's
  and NNEQM1's force and pair forces; every increment's last solve is the last state checked in the
  geometry evaluated at it (no iteration, u unchanged), and that geometry evaluated again at the
  committed u is the same to the bit;
* the same with the seed's frozen flow directions (its G Bᵀ made again from the same K_e);
* a cylinder dragged over an elastoplastic strip (plasticity, friction, a path-dependent state):
  NNEQM1's state on the same load path;
* the block slid 1.6 master facets over another (node-to-surface: pairs change their master facet
  and a third of them go), both laws, and with friction on dual mortar pairs: NNEQM1's force.
The problem-file run, the default geometry's switch and 2 ranks: tests/integration/test_large_sliding.py
and tests/mpi/test_large_sliding_mpi.py.
"""

import numpy as np
import pytest

from dolfinx_nnqem.cases.large_sliding import ironing, obstacle_force, slave_force, sliding_blocks, sliding_sphere
from dolfinx_nnqem.io import pair_table
from dolfinx_nnqem.solvers import NNEQM2Options, SolverOptions, make_solver, solve_load_path, solve_load_steps

LAWS = ["alart-curnier", "polar"]
OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)


def _run(problem, method, increments, callbacks=(), **settings):
    with make_solver(method, problem, OPTIONS, **settings) as solver:
        return solve_load_steps(problem, solver, increments, callbacks=list(callbacks))


def _pair_forces(problem) -> np.ndarray:
    t = pair_table(problem)
    return t["force_on_body1"][np.lexsort(t["position_b"].round(9).T[::-1])]


def _geometry(problem) -> tuple[np.ndarray, ...]:
    """B's values (CSR), the gaps and the frames of the pairs as the model holds them."""
    model = problem.contact
    _, _, values = model.B.getValuesCSR()
    return values.copy(), model.g0.copy(), model.R.copy()


class _EvaluatedAgain:
    """A load-stepping callback: the geometry evaluated again at every committed u, and whether it is the one
    the state was solved in, bit for bit (B's values, the gaps, the frames)."""

    def __init__(self, problem):
        self.problem, self.same = problem, []

    def __call__(self, result):
        before = _geometry(self.problem)
        self.problem.update_contact_geometry(result.load_factor)  # at the committed u
        self.same.append(all(np.array_equal(a, b) for a, b in zip(before, _geometry(self.problem))))


@pytest.mark.parametrize("law", LAWS)
def test_sphere_slide_equals_monolithic_and_nneqm1(law):
    """The sphere pressed into a 4³ block at x = 0.3 and slid to 0.7 in 8 increments: NNEQM2's force and
    pair forces are the monolithic solver's and NNEQM1's to 1e-8; every increment ends in a solve that
    took no iteration, and the committed state's geometry, evaluated again at its u, is the one it was
    solved in, bit for bit."""
    problem = sliding_sphere(4, law=law)
    evaluated_again = _EvaluatedAgain(problem)
    results = _run(problem, "nneqm2", 8, callbacks=[evaluated_again])
    others = {}
    for method in ("monolithic", "nneqm1"):
        other = sliding_sphere(4, law=law)
        others[method] = (_run(other, method, 8), obstacle_force(other), _pair_forces(other))
    f, pairs = obstacle_force(problem), _pair_forces(problem)
    scale = np.abs(pairs).max()
    errors = {m: (np.linalg.norm(f - o[1]) / np.linalg.norm(o[1]), np.abs(pairs - o[2]).max() / scale)
              for m, o in others.items()}
    counts = {m: [r.iterations for r in o[0]] for m, o in others.items()}
    print(f"\n  {law}: F = {f}; |ΔF|/|F|, max |Δλ|/max |λ| against {errors}; iterations nneqm2 "
          f"{[r.iterations for r in results]}, solves {[r.report.geometry_passes for r in results]}; {counts}; "
          f"largest |H|/F of the check {max(r.check.contact for r in results):.1e}")
    assert len(results) == 8 and all(e < 1e-8 and ep < 1e-8 for e, ep in errors.values())
    assert all(len(r.report.history) == 1 and r.report.history[0].iteration == 0 for r in results)
    assert all(r.report.geometry_passes >= 2 for r in results) and all(evaluated_again.same)
    assert all(r.check.ok and r.check.contact < 1e-9 and r.check.equilibrium < 1e-9 for r in results)


def test_sphere_slide_frozen_directions():
    """The seed's frozen-direction variant on the same slide: its dense system's G Bᵀ and B G Bᵀ are made
    again from the same factorisation when the pairs move; the monolithic solver's force to 1e-8. A repeated
    solve whose dense solves start converged still moves u (with the new B): it is not the last, and the
    committed state's geometry evaluated again at its u is the one it was solved in, bit for bit."""
    frozen = sliding_sphere(4)
    evaluated_again = _EvaluatedAgain(frozen)
    results = _run(frozen, "nneqm2", 8, callbacks=[evaluated_again], nneqm2=NNEQM2Options(flow_directions="frozen"))
    mono = sliding_sphere(4)
    _run(mono, "monolithic", 8)
    f, f_m = obstacle_force(frozen), obstacle_force(mono)
    error = np.linalg.norm(f - f_m) / np.linalg.norm(f_m)
    print(f"\n  frozen directions: F = {f}, monolithic {f_m}: {error:.1e}; iterations {[r.iterations for r in results]}")
    assert error < 1e-8 and all(r.check.ok for r in results) and all(evaluated_again.same)


def test_plastic_ironing_equals_nneqm1():
    """A cylinder pressed into an elastoplastic strip (8 × 2 × 2) and dragged along it with μ_f = 0.1 in the
    current geometry: NNEQM2 on NNEQM1's load path ends in NNEQM1's state (force, u, plastic strain)."""
    nested = ironing(8, geometry="current")
    results = _run(nested, "nneqm1", 20)
    path = [r.load_factor for r in results]
    problem = ironing(8, geometry="current")
    with make_solver("nneqm2", problem, OPTIONS) as solver:
        own = solve_load_path(problem, solver, path)
    f, f_n = obstacle_force(problem), obstacle_force(nested)
    df = np.linalg.norm(f - f_n) / np.linalg.norm(f_n)
    du = np.abs(problem.u.x.array - nested.u.x.array).max() / np.abs(nested.u.x.array).max()
    dp = np.abs(problem.state.p_n.x.array - nested.state.p_n.x.array).max() / nested.state.p_n.x.array.max()
    plastic = int(np.count_nonzero(nested.state.p_n.x.array > 0))
    print(f"\n  {len(path)} increments; NNEQM1 F = {f_n} ({sum(r.iterations for r in results)} iterations), NNEQM2 "
          f"F = {f} ({sum(r.iterations for r in own)}); |ΔF|/|F| = {df:.1e}, max |Δu|/max |u| = {du:.1e}, "
          f"max |Δp|/max p = {dp:.1e}; {plastic} Gauss points plastic")
    assert df < 1e-7 and du < 1e-7 and dp < 1e-6
    assert plastic > 10 and f[0] > 0


@pytest.mark.parametrize("law", LAWS)
def test_block_slid_over_several_facets_equals_nneqm1(law):
    """The upper block slid 1.6 master facets (node-to-surface, frictionless): NNEQM1's normal force to 1e-8,
    with the pairs 49 -> 28."""
    problem = sliding_blocks(slide=0.4, law=law)
    results = _run(problem, "nneqm2", 12)
    nested = sliding_blocks(slide=0.4, law=law)
    _run(nested, "nneqm1", 12)
    f, f_n = slave_force(problem), slave_force(nested)
    error = abs(f[1] - f_n[1]) / abs(f_n[1])
    print(f"\n  {law}: NNEQM2 F = {f}, NNEQM1 F = {f_n}: {error:.1e}; iterations {[r.iterations for r in results]}")
    assert problem.num_pairs == nested.num_pairs == 28
    assert error < 1e-8 and all(r.check.ok for r in results)


def test_mortar_frictional_slide_equals_nneqm1():
    """The frictional block slide (μ_f = 0.3) with dual mortar pairs, integrated afresh on the moved facets
    at every evaluation: NNEQM1's force on the slave body to 1e-8."""
    problem = sliding_blocks(slide=0.4, mu_f=0.3, discretisation="mortar")
    results = _run(problem, "nneqm2", 12)
    nested = sliding_blocks(slide=0.4, mu_f=0.3, discretisation="mortar")
    _run(nested, "nneqm1", 12)
    f, f_n = slave_force(problem), slave_force(nested)
    error = np.linalg.norm(f - f_n) / np.linalg.norm(f_n)
    print(f"\n  mortar: NNEQM2 F = {f}, NNEQM1 F = {f_n}: {error:.1e}; iterations {[r.iterations for r in results]}, "
          f"solves {[r.report.geometry_passes for r in results]}")
    assert problem.num_pairs == nested.num_pairs and problem.contact.interfaces[0].pairs.kind == "mortar"
    assert error < 1e-8 and all(r.check.ok for r in results)
