"""Every method on every driver: the same elastoplastic answer from any state (issue "NNEQM2: the
right answer on every load path").

Rows, each with yield in the first increment (one increment) and yield starting later (four
increments): a traction, a prescribed displacement, a rigid plane's motion, a rigid sphere's
motion and gravity. Columns: the monolithic solver, NNEQM1 and NNEQM2 (its default, the
backward-Euler answer). A von Mises bar (E = 200 000, ν = 0.3, σ_y0 = 400, H = 20 000) rests on a
frictionless rigid plane (x = 0, y = 0 or the plane pressing it), on rollers elsewhere, so every
row has contact and uniaxial stress, where the closed form holds:

    σ = σ_y0 + E H / (E + H) (ε − σ_y0 / E)   (strain driven),   ε = σ / E + (σ − σ_y0) / H  (stress driven).

Every cell must agree with the monolithic solver to 1e-8 and, where the closed form exists, with
it to 1e-8; every converged state passes the independent check, which verifies the constitutive
law at every Gauss point (``dolfinx_nnqem.solvers.constitutive``).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_with_face_tags
from mpi4py import MPI

from dolfinx_nnqem.contact.obstacles import Plane, Sphere
from dolfinx_nnqem.io import pair_table
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Gravity, Traction
from dolfinx_nnqem.solvers import METHODS, SolverOptions, make_solver, solve_load_steps

STEEL = VonMises(E=200_000.0, nu=0.3, sigma_y0=400.0, H=20_000.0, density=1.0)
EPS_Y = STEEL.sigma_y0 / STEEL.E  # the yield strain
X0, X1, Y0, Y1, Z0, Z1 = 1, 2, 3, 4, 5, 6  # box_with_face_tags


def strain_driven(eps: float) -> float:
    """|σ| of a bar compressed to the strain ``eps`` (uniaxial stress, linear hardening)."""
    if eps <= EPS_Y:
        return STEEL.E * eps
    return STEEL.sigma_y0 + STEEL.E * STEEL.H / (STEEL.E + STEEL.H) * (eps - EPS_Y)


def stress_driven(sigma: float) -> float:
    """The strain of a bar under the compressive stress ``sigma``."""
    return sigma / STEEL.E + max(sigma - STEEL.sigma_y0, 0.0) / STEEL.H


def on_a_plane(driver: str):
    """The unit cube on a frictionless rigid plane at x = 0 (rollers on y = 0, z = 0), compressed
    along x by a traction on x = 1 (1.5 σ_y0), a prescribed displacement of x = 1 (3 ε_y) or a
    rigid plane pressing x = 1 (3 ε_y); (problem, the closed-form contact force)."""
    mesh, ft = box_with_face_tags((2, 2, 2))
    rollers = [Dirichlet(Y0, 0.0, [1]), Dirichlet(Z0, 0.0, [2])]
    support = Contact(Plane(point=(0.0, 0.0, 0.0), normal=(1.0, 0.0, 0.0)), X0, mu_f=0.0, name="support")
    if driver == "traction":
        sigma = 1.5 * STEEL.sigma_y0
        problem = ContactProblem(mesh, None, ft, materials=STEEL, dirichlet=rollers,
                                 tractions=[Traction(X1, (-sigma, 0.0, 0.0))], contact=support)
        return problem, sigma
    delta = 3.0 * EPS_Y
    if driver == "displacement":
        problem = ContactProblem(mesh, None, ft, materials=STEEL, dirichlet=[*rollers, Dirichlet(X1, -delta, [0])],
                                 contact=support)
        return problem, strain_driven(delta)
    press = Contact(Plane(point=(1.0, 0.0, 0.0), normal=(-1.0, 0.0, 0.0), motion=(-delta, 0.0, 0.0)), X1,
                    mu_f=0.0, name="press")
    return ContactProblem(mesh, None, ft, materials=STEEL, dirichlet=rollers, contact=[support, press]), \
        strain_driven(delta)


def column(driver: str = "gravity"):
    """A column (0.2 × 1 × 0.2) standing on a frictionless rigid plane at y = 0 under its own weight,
    1.5 σ_y0 at its foot (rollers on x = 0 and z = 0); no closed form on the discretisation."""
    mesh, ft = box_with_face_tags((1, 4, 1), L=(0.2, 1.0, 0.2))
    g = 1.5 * STEEL.sigma_y0 / STEEL.density  # ρ g L with L = 1
    support = Contact(Plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0)), Y0, mu_f=0.0)
    return ContactProblem(mesh, None, ft, materials=STEEL, dirichlet=[Dirichlet(X0, 0.0, [0]), Dirichlet(Z0, 0.0, [2])],
                          body_forces=[Gravity((0.0, -g, 0.0))], contact=support), None


def indented(driver: str = "sphere"):
    """A rigid sphere (R = 2) pressed 0.002 into the top of a block (rollers below and on the
    symmetry planes x = 0, z = 0): the first Gauss points yield at about half of it; no closed form."""
    mesh, ft = box_with_face_tags((3, 2, 3), L=(0.6, 0.4, 0.6))
    sphere = Sphere(centre=(0.0, 2.4, 0.0), radius=2.0, motion=(0.0, -0.002, 0.0))
    return ContactProblem(mesh, None, ft, materials=STEEL,
                          dirichlet=[Dirichlet(Y0, 0.0, [1]), Dirichlet(X0, 0.0, [0]), Dirichlet(Z0, 0.0, [2])],
                          contact=Contact(sphere, Y1, mu_f=0.0)), None


ROWS = {"traction": on_a_plane, "displacement": on_a_plane, "plane": on_a_plane, "sphere": indented,
        "gravity": column}


def solve(driver: str, method: str, increments: int) -> dict:
    problem, exact = ROWS[driver](driver)
    first_yield = []

    def note(result):
        if result.plastic_points and not first_yield:
            first_yield.append(result.index)

    with make_solver(method, problem, SolverOptions(rtol=1e-12)) as solver:
        results = solve_load_steps(problem, solver, increments, callbacks=[note])
    table = pair_table(problem)
    interface = table["interface"] == 0
    force = -table["force_local_body1"][interface, 0].sum()  # the support's contact force
    n = problem.V.dofmap.index_map.size_local * 3
    return {"u": problem.u.x.array[:n].copy(), "force": force, "exact": exact, "first_yield": first_yield,
            "p": MPI.COMM_WORLD.allreduce(float(problem.state.p_n.x.array.max()), op=MPI.MAX),
            "iterations": [r.iterations for r in results], "cutbacks": sum(r.cutbacks for r in results),
            "checks": [r.check.constitutive for r in results]}


_MONOLITHIC: dict = {}


def monolithic(driver: str, increments: int) -> dict:
    key = (driver, increments)
    if key not in _MONOLITHIC:
        _MONOLITHIC[key] = solve(driver, "monolithic", increments)
    return _MONOLITHIC[key]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("increments", [1, 4])
@pytest.mark.parametrize("driver", list(ROWS))
def test_every_method_gives_the_backward_euler_answer(driver, increments, method):
    run, ref = solve(driver, method, increments), monolithic(driver, increments)
    du = np.abs(run["u"] - ref["u"]).max() / np.abs(ref["u"]).max()
    df = abs(run["force"] - ref["force"]) / abs(ref["force"])
    worst = max(max(c.values()) for c in run["checks"])
    line = (f"\n  {driver}, {increments} increment(s), {method}: first yield in increment {run['first_yield']}, "
            f"max p {run['p']:.4e}, iterations {run['iterations']}, cutbacks {run['cutbacks']}; vs monolithic: u "
            f"{du:.1e}, force {df:.1e}; worst constitutive relation {worst:.1e} σ_u")
    if run["exact"] is not None:
        line += f"; force {run['force']:.6f} against the closed form {run['exact']:.6f}"
    print(line)
    assert run["cutbacks"] == 0
    assert run["first_yield"] == ([1] if increments == 1 else run["first_yield"]) and run["first_yield"]
    if increments > 1:
        assert run["first_yield"][0] > 1  # yielding starts in a later increment
    assert du < 1e-8 and df < 1e-8
    if run["exact"] is not None:
        assert abs(run["force"] - run["exact"]) < 1e-8 * run["exact"]
    assert worst < 1e-8


@pytest.mark.mpi
def test_every_cell_on_two_ranks_equals_the_serial_one(tmp_path):
    """The whole matrix on 2 ranks in one job: each cell's contact force equals the serial
    monolithic one (and the closed form where there is one), yield starts in the same increment,
    and the independent check holds at every Gauss point."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    from dolfinx_nnqem import compat

    out = tmp_path / "cells.json"
    script = Path(__file__).resolve().parents[1] / "mpi_scripts" / "load_paths.py"
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(script), str(out)]
    job = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=compat.mpi_environment())
    assert job.returncode == 0, f"{' '.join(cmd)} failed:\n{job.stdout[-3000:]}\n{job.stderr[-3000:]}"
    cells = json.loads(out.read_text())
    assert len(cells) == len(ROWS) * 2 * len(METHODS)
    worst_force, worst_check = 0.0, 0.0
    for key, cell in cells.items():
        driver, increments, _ = key.split("/")
        ref = monolithic(driver, int(increments))
        df = abs(cell["force"] - ref["force"]) / abs(ref["force"])
        worst_force, worst_check = max(worst_force, df), max(worst_check, cell["worst_check"])
        assert cell["cutbacks"] == 0 and cell["first_yield"] == ref["first_yield"], key
        assert df < 1e-8 and cell["worst_check"] < 1e-8, key
        if cell["exact"] is not None:
            assert abs(cell["force"] - cell["exact"]) < 1e-8 * cell["exact"], key
    print(f"\n  {len(cells)} cells on 2 ranks: contact force vs serial monolithic at most {worst_force:.1e}, "
          f"worst constitutive relation {worst_check:.1e} σ_u")
