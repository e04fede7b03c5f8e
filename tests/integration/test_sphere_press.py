"""The sphere press of the hardening laws' verification (``cases.sphere_press``; against CalculiX in
``tests/integration/test_calculix_sphere_press.py``): every solver and both pair laws give the same answer, a
problem file gives the Python run's, the CalculiX model's sphere lies on the sphere, and bad input
is refused. On a coarse mesh (h = 1 mm), one press and lift in four increments."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem import compat
from dolfinx_nnqem.cases import sphere_press as case
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import calculix_sphere_press as ccx_sphere  # noqa: E402

H = 1.0  # mm: a coarse mesh (a code-to-code comparison needs no converged one)


def press(method: str, law: str = "alart-curnier", material: str = "combined", comm: MPI.Comm = MPI.COMM_SELF,
          **build) -> tuple[list, list]:
    """(force, depth) after each of 4 increments (two down, two up) of ``case.sphere_press_problem(H, ...)``."""
    problem = case.sphere_press_problem(H, material, 1, law=law, comm=comm, **build)
    forces, depths = [], []

    def record(result):
        forces.append(case.indentation_force(problem))
        depths.append(case.surface_depth(problem))

    with make_solver(method, problem, SolverOptions(rtol=1e-11, max_iterations=60)) as solver:
        solve_load_steps(problem, solver, 4, callbacks=[record])
    return forces, depths


@pytest.fixture(scope="module")
def reference():
    return press("monolithic")


@pytest.mark.parametrize("method, law", [("monolithic", "polar"), ("nneqm1", "alart-curnier"), ("nneqm1", "polar"),
                                         ("nneqm2", "alart-curnier"), ("nneqm2", "polar")])
def test_every_solver_and_law_gives_the_monolithic_answer(reference, method, law):
    """Combined hardening (the table and a Prager back-stress), frictionless: the same forces at the
    peak and after the lift, and the same residual depth, as the monolithic solver's Alart–Curnier run."""
    forces, depths = press(method, law)
    f_ref, d_ref = reference
    df = np.abs(np.subtract(forces, f_ref)).max() / max(f_ref)
    dd = np.abs(np.subtract(depths, d_ref)).max() / max(d_ref)
    print(f"\n  {method}/{law}: force {forces[1]:.6g} N at the peak (monolithic {f_ref[1]:.6g}); residual depth "
          f"{depths[-1]:.6g} mm; differences {df:.1e} (force), {dd:.1e} (depth)")
    assert f_ref[1] > 0 and f_ref[-1] == pytest.approx(0.0, abs=1e-9 * f_ref[1])  # lifted off at the end
    assert 0 < d_ref[-1] < d_ref[1]  # a residual indentation
    assert df < 1e-8 and dd < 1e-8


def test_problem_file_gives_the_python_run(tmp_path, reference):
    from dolfinx_nnqem.cli import EXIT_OK, main

    mesh = tmp_path / "sphere_press.msh"
    case.sphere_press_problem(H, "combined", 1, comm=MPI.COMM_SELF, msh_file=mesh)
    toml = tmp_path / "sphere_press.toml"
    toml.write_text(case.problem_file_text("combined", 1, 2, folder=str(tmp_path / "out")))
    assert main(["-q", "run", str(toml)]) == EXIT_OK
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    forces = [-case.SYMMETRY * f["sphere"][1] for f in summary["obstacle_force_history"]]
    f_ref, _ = reference
    print(f"\n  problem file: forces {np.round(forces, 6).tolist()} N; Python {np.round(f_ref, 6).tolist()}")
    assert summary["converged"] and len(forces) == 4
    assert np.abs(np.subtract(forces, f_ref)).max() < 1e-9 * max(f_ref)


def test_calculix_sphere_lies_on_the_sphere():
    """The CalculiX model's cap: outer nodes on the sphere, inner ones CAP_THICKNESS inside, every
    element right-handed, the block's top covered up to CAP_EXTENT with one facet beyond x, z = 0."""
    coords, cells = ccx_sphere.cap_elements(case.R_SPHERE, 0.1)
    r = np.linalg.norm(coords - [0.0, case.R_SPHERE, 0.0], axis=1)
    outer = np.isclose(r, case.R_SPHERE, rtol=1e-14)
    assert outer.sum() == len(coords) // 2
    assert np.allclose(r[~outer], case.R_SPHERE - ccx_sphere.CAP_THICKNESS, rtol=1e-14)
    assert coords[outer][:, [0, 2]].min() == pytest.approx(-0.1) and coords[outer][:, 0].max() >= ccx_sphere.CAP_EXTENT
    assert np.array_equal(ccx_sphere.outward(coords, cells), cells)  # no element needed turning over


def test_calculix_materials_map_the_laws():
    """The ``*PLASTIC`` cards: the table as it is; kinematic: a line of slope C from σ_y0 (CalculiX
    keeps the first row as the yield stress and moves the surface by the line's rise); combined:
    that line and the combined law's isotropic table as ``*CYCLIC HARDENING``."""
    table = ccx_sphere.plastic_lines("table")
    assert table[0] == "*PLASTIC" and [tuple(map(float, row.split(","))) for row in table[1:]] == list(case.TABLE)
    kinematic = ccx_sphere.plastic_lines("kinematic")
    (s0, p0), (s1, p1) = (tuple(map(float, row.split(","))) for row in kinematic[1:])
    assert kinematic[0] == "*PLASTIC, HARDENING=KINEMATIC"
    assert (s0, p0) == (case.TABLE[0][0], 0.0) and (s1 - s0) / (p1 - p0) == pytest.approx(case.C_KINEMATIC, rel=1e-12)
    combined = ccx_sphere.plastic_lines("combined")
    assert combined[0] == "*PLASTIC, HARDENING=COMBINED" and combined[1:3] == kinematic[1:]
    assert combined[3] == "*CYCLIC HARDENING"
    assert [tuple(map(float, row.split(","))) for row in combined[4:]] == list(case.TABLE_COMBINED)


@pytest.mark.parametrize("kwargs, match", [({"material": "steel"}, "material = 'steel'"),
                                           ({"cycles": 0}, "cycles = 0")])
def test_bad_input_is_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        case.sphere_press_problem(H, **{"material": "table", **kwargs})


@pytest.mark.mpi
def test_two_ranks_match_serial(tmp_path, reference):
    """The combined-hardening press and lift on 2 ranks: the serial forces and depths."""
    out = tmp_path / "out.npz"
    script = Path(__file__).resolve().parents[1] / "mpi_scripts" / "sphere_press.py"
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(script), str(out)]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=compat.mpi_environment())
    assert result.returncode == 0, f"{' '.join(cmd)} failed:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    parallel = np.load(out)
    f_ref, d_ref = reference
    df = np.abs(parallel["forces"] - f_ref).max() / max(f_ref)
    dd = np.abs(parallel["depths"] - d_ref).max() / max(d_ref)
    print(f"\n  2 ranks (cells per rank {parallel['cells'].tolist()}): peak force {parallel['forces'][1]:.6g} N, "
          f"residual depth {parallel['depths'][-1]:.6g} mm; differences from serial {df:.1e} (force), {dd:.1e} (depth)")
    assert min(parallel["cells"]) > 0 and df < 1e-8 and dd < 1e-8
