"""The seed benchmark through the command line: serial, V9 (MPI on 2 and 3 ranks), V10 (laws)."""

import json
import sys

import numpy as np
import pytest

from dolfinx_nnqem import compat
from dolfinx_nnqem.cases.two_beams import run_two_beams

from mpi_job import run_mpi_job


def _pair_arrays(summary):
    forces = np.array([p["force_on_body1"] for p in summary["pairs"]])
    displacements = np.array([p["u_body1"] + p["u_body2"] for p in summary["pairs"]])
    return forces, displacements


@pytest.fixture(scope="module")
def serial_monolithic(tmp_path_factory):
    out = tmp_path_factory.mktemp("two_beams_serial")
    return run_two_beams("monolithic", 15, out, fields=False)


def test_two_beams_monolithic_serial(serial_monolithic):
    s = serial_monolithic
    states = [p["state"] for p in s["pairs"]]
    print(f"\n  states {states}; iterations {s['iterations']}; plastic GP {s['plastic_gauss_points']}")
    print(f"  global equilibrium |F + R| / |F| = {s['equilibrium_residual']:.2e}; "
          f"free-dof residual {s['free_dof_residual']:.2e}; wall time {s['wall_time_s']:.1f} s")
    assert s["converged"] and len(s["pairs"]) == 9 and s["num_gauss_points"] == 640
    assert s["equilibrium_residual"] < 1e-8
    assert s["plastic_gauss_points"][0] == 0 and s["plastic_gauss_points"][1] > 0  # yield from increment 2
    # superlinear convergence in the last iterations of each increment
    for history in s["residual_histories"]:
        e = [max(r, c) for r, c in history]
        if len(e) >= 3 and e[-2] < 1e-3:
            assert e[-1] <= 1e-2 * e[-2], e


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_v9_two_beams_mpi_matches_serial(ranks, serial_monolithic, tmp_path):
    # a failure explains itself (issue 39, item 13: a fresh-clone CI saw exit 9 once on 3 ranks,
    # i.e. a rank SIGKILLed): which rank ended how, every rank's output and peak memory, the
    # machine's memory and out-of-memory kills (tests/mpi_job.py)
    run, report = run_mpi_job([sys.executable, "-m", "dolfinx_nnqem", "-q", "two-beams", "--method", "monolithic",
                               "--out", str(tmp_path), "--no-fields"], ranks, timeout=600,
                              env=compat.mpi_environment())
    assert run.returncode == 0, report
    parallel = json.loads((tmp_path / "summary.json").read_text())
    f0, u0 = _pair_arrays(serial_monolithic)
    f, u = _pair_arrays(parallel)
    df = np.abs(f - f0).max() / np.abs(f0).max()
    du = np.abs(u - u0).max() / np.abs(u0).max()
    c0 = np.array([c["u"] for c in serial_monolithic["free_end_corners"]])
    c = np.array([c["u"] for c in parallel["free_end_corners"]])
    dc = np.abs(c - c0).max() / np.abs(c0).max()
    print(f"\n  {ranks} ranks vs serial: pair forces {df:.2e}, pair displacements {du:.2e}, "
          f"free-end corners {dc:.2e} (tolerance 1e-8); iterations {parallel['iterations']}")
    assert parallel["mpi_ranks"] == ranks
    assert [p["state"] for p in parallel["pairs"]] == [p["state"] for p in serial_monolithic["pairs"]]
    assert max(df, du, dc) < 1e-8


def test_v10_polar_and_cartesian_laws_agree_on_two_beams():
    """The polar law (with the cutbacks it needs) and the Cartesian law on the SAME load path."""
    from dolfinx_nnqem.solvers.monolithic import MonolithicSolver
    from dolfinx_nnqem.io import pair_table
    from dolfinx_nnqem.solvers import solve_load_path, solve_load_steps
    from dolfinx_nnqem.cases.two_beams import two_beams_problem

    polar_problem = two_beams_problem(law="polar")
    polar = solve_load_steps(polar_problem, MonolithicSolver(polar_problem), 15)
    path = [r.load_factor for r in polar]
    cartesian_problem = two_beams_problem(law="alart-curnier")
    cartesian = solve_load_path(cartesian_problem, MonolithicSolver(cartesian_problem), path)
    tp, tc = pair_table(polar_problem), pair_table(cartesian_problem)
    f_scale = np.abs(tc["force_on_body1"]).max()
    u_scale = np.abs(tc["u_body1"]).max()
    df = np.abs(tp["force_on_body1"] - tc["force_on_body1"]).max() / f_scale
    du = max(np.abs(tp["u_body1"] - tc["u_body1"]).max(), np.abs(tp["u_body2"] - tc["u_body2"]).max()) / u_scale
    lm = [sum(1 for h in r.report.history if h.kind == "lm") for r in polar]
    print(f"\n  load path ({len(path)} increments, polar cutbacks {sum(r.cutbacks > 0 for r in polar)}): "
          f"forces {df:.2e}, displacements {du:.2e} (tolerance 1e-8)")
    print(f"  iterations polar {[r.iterations for r in polar]} (LM steps {lm}); "
          f"Cartesian {[r.iterations for r in cartesian]}")
    assert list(tp["state"]) == list(tc["state"])
    assert max(df, du) < 1e-8


@pytest.mark.mpi
def test_v9_nneqm1_on_two_ranks_matches_serial(tmp_path):
    """NNEQM1 gathers the dense contact problem on every rank; a rank may own no pair."""
    serial = run_two_beams("nneqm1", 15, tmp_path / "serial", law="alart-curnier", fields=False)
    run, report = run_mpi_job([sys.executable, "-m", "dolfinx_nnqem", "-q", "two-beams", "--method", "nneqm1",
                               "--law", "alart-curnier", "--out", str(tmp_path / "mpi"), "--no-fields"], 2,
                              timeout=600, env=compat.mpi_environment())
    assert run.returncode == 0, report
    parallel = json.loads((tmp_path / "mpi" / "summary.json").read_text())
    f0, u0 = _pair_arrays(serial)
    f, u = _pair_arrays(parallel)
    df = np.abs(f - f0).max() / np.abs(f0).max()
    du = np.abs(u - u0).max() / np.abs(u0).max()
    print(f"\n  NNEQM1, 2 ranks vs serial: forces {df:.2e}, displacements {du:.2e} (tolerance 1e-8)")
    assert max(df, du) < 1e-8


def test_iterative_linear_solver_gives_the_direct_answer(serial_monolithic):
    """linear_solver="iterative" (FGMRES, Schur fieldsplit, GAMG on K): the same Newton iterates."""
    from dolfinx_nnqem.solvers.monolithic import MonolithicSolver
    from dolfinx_nnqem.solvers import MonolithicOptions
    from dolfinx_nnqem.io import pair_table
    from dolfinx_nnqem.solvers import solve_load_steps
    from dolfinx_nnqem.cases.two_beams import two_beams_problem

    problem = two_beams_problem()
    results = solve_load_steps(problem, MonolithicSolver(problem, monolithic=MonolithicOptions(linear_solver="iterative")), 15)
    f = pair_table(problem)["force_on_body1"]
    f0, _ = _pair_arrays(serial_monolithic)
    diff = np.abs(f - f0).max() / np.abs(f0).max()
    print(f"\n  iterative vs direct: pair forces {diff:.2e} (tolerance 1e-8); Newton iterations "
          f"{[r.iterations for r in results]} vs {serial_monolithic['iterations']}")
    assert diff < 1e-8


def test_v8_nneqm1_with_the_seed_law_agrees_with_monolithic(serial_monolithic, tmp_path):
    """V8: NNEQM1 (polar law, as in the seed) vs the monolithic solver: same states, within 1 %."""
    nneqm1 = run_two_beams("nneqm1", 15, tmp_path, fields=False)
    f0, u0 = _pair_arrays(serial_monolithic)
    f, u = _pair_arrays(nneqm1)
    df = np.abs(f - f0).max() / np.abs(f0).max()
    du = np.abs(u - u0).max() / np.abs(u0).max()
    print(f"\n  NNEQM1 ({nneqm1['law']}, {len(nneqm1['iterations'])} increments after cutbacks, system order "
          f"{nneqm1['system_order']}) vs monolithic: forces {df:.2e}, displacements {du:.2e} (V8: 1e-2)")
    assert nneqm1["system_order"] == 27
    assert [p["state"] for p in nneqm1["pairs"]] == [p["state"] for p in serial_monolithic["pairs"]]
    assert max(df, du) < 1e-2
