"""A body held only by contact, solved by every method (issue "One contact model under every solver").

The pressed blocks of ``pressed_blocks.py`` (level 1, both von Mises), with body 2 held by
nothing but contact and u_z = 0 on its z faces: its free rigid modes are the translations along
x and y and the rotation about z. A pressure p and a drag τ = 0.2 p (below μ_f p = 0.3 p) on its
top rise together from rest. NNEQM1 and NNEQM2 hold the modes through their amplitudes and
self-equilibrium rows (``condensation.py``); the monolithic solver through its contact rows. The
solutions agree, in the plastic range (NNEQM2 with updated flow directions, i.e. the radial
return) and in the elastic one.

A body no contact can hold (frictionless contact against a sideways load) is refused before any
solve, with the body and the motion named.
"""

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem.cases.geometries import StackedBlocksTags as T
from dolfinx_nnqem.cases.geometries import build_stacked_blocks
from dolfinx_nnqem.cases.pressed_blocks import MATERIAL, PRESSURE
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure, Traction
from dolfinx_nnqem.io import equilibrium_check, pair_table
from dolfinx_nnqem.solvers import METHODS, NNEQM2Options, SolverOptions, make_solver
from dolfinx_nnqem.solvers import solve_load_path, solve_load_steps


def floating_blocks(mu_f=0.3, drag=0.2, pressure=PRESSURE, comm=MPI.COMM_WORLD):
    mesh, ct, ft = build_stacked_blocks(comm, 1.0, 0.5, 0.5, 1.0, 4, 2, 2, 4)
    return ContactProblem(
        mesh, ct, ft, materials={T.BODY1: MATERIAL, T.BODY2: MATERIAL},
        dirichlet=[Dirichlet(T.BOTTOM), Dirichlet(T.BODY1_ZMIN, 0.0, [2]), Dirichlet(T.BODY1_ZMAX, 0.0, [2]),
                   Dirichlet(T.BODY2_ZMIN, 0.0, [2]), Dirichlet(T.BODY2_ZMAX, 0.0, [2])],
        tractions=[Pressure(T.TOP, pressure), Traction(T.TOP, (drag * pressure, 0.0, 0.0))],
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=mu_f))


def solve(method, pressure, increments=5, load_factors=None, flow_directions="return-map"):
    problem = floating_blocks(pressure=pressure)
    extra = {"nneqm2": NNEQM2Options(flow_directions=flow_directions)} if method == "nneqm2" else {}
    solver = make_solver(method, problem, SolverOptions(rtol=1e-11), **extra)
    if load_factors is None:
        results = solve_load_steps(problem, solver, increments)
    else:  # along a given path (friction and plasticity depend on it)
        results = solve_load_path(problem, solver, load_factors)
    t = pair_table(problem)
    return {"u": problem.u.x.array.copy(), "f": t["force_on_body1"], "states": t["state_name"],
            "its": [r.iterations for r in results], "cutbacks": sum(r.cutbacks for r in results),
            "load_factors": [r.load_factor for r in results],
            "plastic": int(MPI.COMM_WORLD.allreduce(np.count_nonzero(problem.state.p_n.x.array > 0), op=MPI.SUM)),
            "imbalance": equilibrium_check(problem)["global_imbalance"], "modes": problem.rigid_modes.description}


def compare(runs, reference="monolithic"):
    ref = runs[reference]
    print(f"\n  body 2's free rigid modes: {ref['modes']}")
    for method, run in runs.items():
        du = np.abs(run["u"] - ref["u"]).max() / np.abs(ref["u"]).max()
        df = np.abs(run["f"] - ref["f"]).max() / np.abs(ref["f"]).max()
        counts = {s: int(np.sum(run["states"] == s)) for s in ("open", "stick", "slip")}
        print(f"  {method}: iterations {run['its']} ({run['cutbacks']} cutbacks), {run['plastic']} Gauss points with "
              f"p > 0, pairs {counts}, global imbalance {run['imbalance']:.1e}; vs {reference}: u {du:.2e}, pair "
              f"forces {df:.2e} (tolerance 1e-6)")
        assert run["imbalance"] < 1e-9 and du < 1e-6 and df < 1e-6
    assert len(ref["modes"]) == 3


def test_body_held_only_by_contact_plastic_every_method_agrees():
    """p = 1.5 σ_y0: both blocks yield; NNEQM2 with its default flow directions (the radial
    return's), the floating body's rigid motions among its unknowns."""
    compare({method: solve(method, PRESSURE) for method in METHODS})


def test_body_held_only_by_contact_elastic_every_method_agrees():
    """p = 0.1 σ_y0: no Gauss point yields; all three methods (NNEQM2's flow directions frozen, as
    in the seed: without plastic flow they do not matter)."""
    runs = {method: solve(method, 0.1 * MATERIAL.sigma_y0, flow_directions="frozen") for method in METHODS}
    compare(runs)
    assert all(run["plastic"] == 0 for run in runs.values())


def test_a_body_nothing_holds_is_refused_before_solving():
    """Frictionless contact cannot hold body 2 against sliding along x: refused, body and motion named."""
    with pytest.raises(ValueError, match=r"body 2 \(cells tagged 2\).*translation along \(1, 0, 0\)") as error:
        floating_blocks(mu_f=0.0)
    print(f"\n  {error.value}")
