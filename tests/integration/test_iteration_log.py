"""The iteration log's count of trial plastic Gauss points: made only where it is read.

The count interpolates the return map at every Gauss point (an extra pass over the Gauss points
at every Newton iteration: 65 of them in the seed run, 0.2 ms each there, and a pass over 2.6
million points at a million dofs). It is made when the package's logger is at INFO on some rank
(``-v``; every rank then counts, as the count is collective) and for a failure's message; the
records carry None otherwise.
"""

import logging
import subprocess
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

from dolfinx_nnqem import compat
from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
from dolfinx_nnqem.material.von_mises import PlasticState
from dolfinx_nnqem.solvers import ConvergenceError, SolverOptions, make_solver, solve_load_steps

SCRIPT = Path(__file__).resolve().parents[1] / "mpi_scripts" / "iteration_log.py"


def _counting(monkeypatch) -> list[int]:
    calls: list[int] = []
    original = PlasticState.count_trial_plastic_points

    def counted(self, u):
        calls.append(1)
        return original(self, u)

    monkeypatch.setattr(PlasticState, "count_trial_plastic_points", counted)
    return calls


@pytest.mark.parametrize("method", ["monolithic", "nneqm1"])
def test_no_count_without_the_iteration_log(method, monkeypatch, caplog):
    calls = _counting(monkeypatch)
    problem = pressed_blocks_problem(1, MPI.COMM_SELF)
    with caplog.at_level(logging.WARNING, logger="dolfinx_nnqem"), make_solver(method, problem) as solver:
        results = solve_load_steps(problem, solver, 3, final_load_factor=0.5)
    records = [h for r in results for h in r.report.history]
    print(f"\n  {method}: {len(records)} records, {len(calls)} counts, plastic points {results[-1].plastic_points}")
    assert results[-1].plastic_points > 0 and all(h.plastic_points is None for h in records) and not calls
    assert "plastic GP -" in records[-1].line(method)


@pytest.mark.parametrize("method", ["monolithic", "nneqm1"])
def test_the_iteration_log_counts_at_every_iterate(method, caplog):
    problem = pressed_blocks_problem(1, MPI.COMM_SELF)
    with caplog.at_level(logging.INFO, logger="dolfinx_nnqem"), make_solver(method, problem) as solver:
        results = solve_load_steps(problem, solver, 3, final_load_factor=0.5)
    counts = [[h.plastic_points for h in r.report.history] for r in results]
    print(f"\n  {method}: trial plastic points per iterate {counts}; committed {[r.plastic_points for r in results]}")
    assert all(isinstance(c, int) for cs in counts for c in cs)
    # at the converged iterate the trial count is the committed one
    assert [cs[-1] for cs in counts] == [r.plastic_points for r in results]
    assert f"plastic GP {counts[-1][-1]}" in caplog.text


def test_a_failure_names_the_plastic_points_of_its_last_iterate(caplog):
    problem = pressed_blocks_problem(1, MPI.COMM_SELF)
    with (caplog.at_level(logging.WARNING, logger="dolfinx_nnqem"),
          make_solver("monolithic", problem, SolverOptions(max_iterations=1)) as solver):
        with pytest.raises(ConvergenceError) as error:
            solve_load_steps(problem, solver, 1, final_load_factor=0.5, max_cutbacks=0)
    message = str(error.value)
    print(f"\n  {message}")
    assert "plastic Gauss points = " in message and "plastic Gauss points = None" not in message
    count = int(message.split("plastic Gauss points = ")[1].split()[0].rstrip(","))
    assert count > 0


@pytest.mark.mpi
def test_a_log_on_rank_0_alone_counts_on_every_rank(tmp_path):
    """Logging configured on rank 0 only (a common script pattern): rank 1 counts too (the count's
    reduction would otherwise wait for it forever), and rank 0's log has the counts."""
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(SCRIPT)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    print(f"\n  exit {run.returncode}; {run.stdout.strip().splitlines()[-1] if run.stdout.strip() else run.stderr[-2000:]}")
    assert run.returncode == 0 and "plastic GP -" not in run.stderr
    counts = [int(line.split("plastic GP ")[1].split()[0]) for line in run.stderr.splitlines() if "plastic GP " in line]
    assert counts and max(counts) > 0
    assert "committed" in run.stdout and int(run.stdout.split("committed ")[1].split()[0]) == counts[-1]
