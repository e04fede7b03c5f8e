"""Issue 39, item 11: a tolerance below the round-off floor is named as such, with the tolerance
that can be reached, instead of "a local minimum, a plateau or a cycle of the merit function".

* the dense driver on x² = 2, which no double solves: |H| stops at 4.4e-16, the floor of rounding x;
  and on x² = −1 (no solution: a true local minimum of Ψ), where the merit function is still blamed;
* stiff blocks (E = 2e11) pressed 1e-6 onto each other and slid 0.4 in the current geometry: with
  rtol = 1e-10, |R|/F stalls at 1.0–2.4e-10 (the displacements carry the slide, the forces come from
  strains of 2e-6); the monolithic solver and NNEQM1 now say so, and the rtol they name converges
  the increment that failed.
"""

import re

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.numerics.newton import Globalisation
from dolfinx_nnqem.numerics.nonsmooth import solve_dense
from dolfinx_nnqem.numerics.roundoff import ROUNDOFF_MARGIN, dense_floor
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.cases.geometries import build_block_stack
from dolfinx_nnqem.solvers import ConvergenceError, SolverOptions, make_solver, solve_load_steps

DRIVER = (Globalisation(watchdog=0, stall_window=5),)


def _square(c: float):
    return lambda x: (x * x - c, np.diag(2.0 * x))


def test_the_dense_driver_names_a_floor_it_cannot_pass():
    out = solve_dense(_square(2.0), np.array([1.0]), tol=1e-20, max_iter=30, globalisations=DRIVER)
    floor = dense_floor(np.diag(2.0 * out.x), out.x)
    print(f"\n  x² = 2: |H| = {abs(out.x[0] ** 2 - 2.0):.1e}, floor {floor:.1e}; {out.message}")
    assert not out.converged and abs(out.x[0] ** 2 - 2.0) <= ROUNDOFF_MARGIN * floor
    assert "round-off: tol 1.0e-20 is at or below the round-off floor ~2.6e-16" in out.message
    assert "the smallest reachable tol here is about 8e-16" in out.message and "local minimum" not in out.message


def test_a_true_local_minimum_is_still_named_so():
    out = solve_dense(_square(-1.0), np.array([0.3]), tol=1e-12, max_iter=30, globalisations=DRIVER)
    print(f"\n  x² = −1: {out.message}")
    assert not out.converged and "local minimum" in out.message and "round-off" not in out.message


def _stiff_blocks_sliding() -> ContactProblem:
    """The upper of two steel-like blocks (6 × 2 × 6 on 4 × 2 × 4 hexahedra) pressed 1e-6 onto the
    clamped lower one over ℓ ≤ ¼, then slid 0.4 along x, μ_f = 0.3, node-to-surface in the current
    geometry (cases.large_sliding.sliding_blocks, stiff and barely pressed)."""
    mesh, cell_tags, facet_tags = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [0.5, 0.5], [(4, 2, 4), (6, 2, 6)])
    dirichlet = [Dirichlet(T.bottom(1)), Dirichlet(T.top(2), -1.0e-6, [1], amplitude=lambda ell: min(1.0, 4.0 * ell)),
                 Dirichlet(T.top(2), 0.4, [0], amplitude=lambda ell: max(0.0, (ell - 0.25) / 0.75)),
                 Dirichlet(T.top(2), 0.0, [2])]
    return ContactProblem(mesh, cell_tags, facet_tags, materials=VonMises(E=2.0e11, nu=0.3), dirichlet=dirichlet,
                          contact=Contact(T.top(1), T.bottom(2), mu_f=0.3, discretisation="node-to-surface",
                                          geometry="current"))


@pytest.mark.parametrize("method", ["monolithic", "nneqm1"])
def test_a_tolerance_below_the_round_off_floor_is_named(method):
    """rtol 3e-11, a quarter of the floor (the issue's 1e-10 is within the residual's scatter about
    it: on Debian 13 the monolithic solver stopped at |R|/F = 1.04e-10, and could meet it)."""
    problem = _stiff_blocks_sliding()
    with pytest.raises(ConvergenceError) as error:
        solve_load_steps(problem, make_solver(method, problem, SolverOptions(rtol=3e-11)), 8, max_cutbacks=1)
    message = str(error.value).splitlines()[0]
    print(f"\n  {method}, rtol 3e-11: {message}")
    assert "round-off: rtol 3.0e-11 is at or below the round-off floor" in message and "local minimum" not in message
    reachable = float(re.search(r"the smallest reachable rtol here is about ([0-9.e+-]+)", message).group(1))
    target = error.value.failure["load_factor"]  # the increment that failed, from the last converged state
    results = solve_load_steps(problem, make_solver(method, problem, SolverOptions(rtol=reachable)), 1,
                               max_cutbacks=0, final_load_factor=target)
    print(f"  rtol {reachable:g}, as named: the increment to load factor {target:g} converged in "
          f"{results[-1].iterations} iterations")
    assert results[-1].load_factor == target
