"""MPI: an error on one rank is an error on all. Each case runs on 2 ranks under a time limit:
every rank must stop, with one message and the documented exit code, and nothing may hang."""

import json
import sys
import time

import numpy as np
import pytest

from dolfinx_nnqem import compat
from dolfinx_nnqem.cli import EXIT_BAD_INPUT, EXIT_IO, EXIT_OK

from reliability_helpers import (ROOT, env, finish, kill_session, problem_file, run_in_session, signal_ranks, start,
                                 wait_for_checkpoint)

pytestmark = pytest.mark.mpi
SCRIPT = ROOT / "tests" / "mpi_scripts" / "rank_failure.py"
LIMIT_S = 120


def _mpirun(args, timeout=LIMIT_S, ranks=2, **extra_env):
    e = env()
    e.update(extra_env)
    t0 = time.perf_counter()
    run = run_in_session([*compat.mpiexec(), "-n", str(ranks), sys.executable, *args], timeout, env=e)
    return run, time.perf_counter() - t0


def _cli(args):
    return ["-m", "dolfinx_nnqem", *args]


def test_output_folder_that_cannot_be_created(tmp_path):
    p = problem_file(tmp_path, increments=2)
    (tmp_path / "afile").write_text("x")
    run, wall = _mpirun(_cli(["-q", "run", str(p), "--out", str(tmp_path / "afile" / "out")]))
    lines = [line for line in run.stderr.splitlines() if line.startswith("dolfinx-nnqem")]
    print(f"\n  exit {run.returncode} after {wall:.1f} s: {lines}")
    assert run.returncode == EXIT_IO and len(lines) == 1 and "afile" in lines[0]


def test_a_corrupt_mesh_read_on_rank_0(tmp_path):
    bad = tmp_path / "bad.msh"
    bad.write_text("$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\ngarbage\n")
    p = problem_file(tmp_path, increments=2)
    p.write_text(p.read_text().replace((ROOT / "meshes" / "two_beams.msh").as_posix(), bad.as_posix()))
    run, wall = _mpirun(_cli(["-q", "run", str(p), "--out", str(tmp_path / "out")]))
    lines = [line for line in run.stderr.splitlines() if line.startswith("dolfinx-nnqem")]
    print(f"\n  exit {run.returncode} after {wall:.1f} s: {lines}")
    assert run.returncode == EXIT_BAD_INPUT and len(lines) == 1 and "bad.msh" in lines[0]


def test_a_full_disk_on_rank_0_only(tmp_path):
    p = problem_file(tmp_path, increments=3)
    run, wall = _mpirun([str(SCRIPT), "writer", "0", "--", "-q", "run", str(p), "--out", str(tmp_path / "out")])
    lines = [line for line in run.stderr.splitlines() if line.startswith("dolfinx-nnqem")]
    print(f"\n  exit {run.returncode} after {wall:.1f} s: {lines}")
    assert run.returncode == EXIT_IO and len(lines) == 1 and "No space left" in lines[0]


def test_a_refusal_on_two_ranks_is_one_line_without_petsc_warnings(tmp_path):
    """Issue 39, item 12: on 2 ranks a run refused after its solver was made (exit 4: a folder
    holding an earlier run; exit 3: nothing to restart from) was followed by PETSc's "WARNING!
    There are options you set that were not used!" (its MUMPS options, read at the first
    factorisation, which never came). The refusal is its one line (MPICH; Open MPI's launcher
    adds its own lines about the exit code, and Debian's PETSc did not warn)."""
    p = problem_file(tmp_path, increments=1)
    (tmp_path / "used").mkdir()
    (tmp_path / "used" / "summary.json").write_text("{}")
    refused = {}
    for code, extra in ((EXIT_IO, ["--out", str(tmp_path / "used")]),
                        (EXIT_BAD_INPUT, ["--out", str(tmp_path / "empty"), "--restart"])):
        run, wall = _mpirun(_cli(["-q", "run", str(p), *extra]))
        refused[code] = run
        print(f"\n  exit {run.returncode} after {wall:.1f} s: stderr {run.stderr!r}; stdout {run.stdout!r}")
    for code, run in refused.items():  # (Open MPI's launcher adds its own lines about the exit code)
        both = run.stdout + run.stderr
        assert run.returncode == code and "options you set that were not used" not in both
        assert "WARNING!" not in both and "Option left" not in both
        assert len([line for line in both.splitlines() if line.startswith("dolfinx-nnqem")]) == 1


def test_a_bad_value_found_by_one_rank_inside_a_collective_solve(tmp_path):
    """Rank 1 raises while rank 0 waits inside the solver: the job is aborted with the code."""
    p = problem_file(tmp_path, increments=3)
    run, wall = _mpirun([str(SCRIPT), "solve", "1", "--", "-q", "run", str(p), "--out", str(tmp_path / "out")],
                        NNQEM_ABORT_TIMEOUT="3")
    print(f"\n  exit {run.returncode} after {wall:.1f} s: "
          f"{[line for line in run.stderr.splitlines() if 'bad value' in line or 'abort' in line.lower()][:3]}")
    assert run.returncode == EXIT_BAD_INPUT and "a bad value found on rank 1 only" in run.stderr
    assert wall < LIMIT_S


def test_restart_on_two_ranks_equals_an_uninterrupted_run(tmp_path):
    p = problem_file(tmp_path, increments=12)
    ref, out = tmp_path / "ref", tmp_path / "killed"
    run, _ = _mpirun(_cli(["-q", "run", str(p), "--out", str(ref)]))
    assert run.returncode == EXIT_OK, run.stderr
    job = start(["-q", "run", str(p), "--out", str(out)], ranks=2)
    k = wait_for_checkpoint(out, 3, job)
    kill_session(job)
    job.wait()
    run, _ = _mpirun(_cli(["-q", "run", str(p), "--out", str(out), "--restart"]))
    assert run.returncode == EXIT_OK, run.stderr
    a = json.loads((ref / "summary.json").read_text())
    b = json.loads((out / "summary.json").read_text())
    f_ref = np.array([q["force_on_body1"] for q in a["pairs"]])
    f_out = np.array([q["force_on_body1"] for q in b["pairs"]])
    u_ref = np.array([q["u"] for q in a["probes"]])
    u_out = np.array([q["u"] for q in b["probes"]])
    df = np.max(np.abs(f_out - f_ref)) / np.max(np.abs(f_ref))
    du = np.max(np.abs(u_out - u_ref)) / np.max(np.abs(u_ref))
    print(f"\n  2 ranks, killed after checkpoint {k}, restarted: load factors equal {a['load_factors'] == b['load_factors']}"
          f", iterations equal {a['iterations'] == b['iterations']}, pair forces {df:.1e}, probe displacements {du:.1e}")
    assert b["mpi_ranks"] == 2 and b["load_factors"] == a["load_factors"] and b["iterations"] == a["iterations"]
    assert df <= 1e-12 and du <= 1e-12
    # a 2-rank checkpoint is refused on 1 rank
    from dolfinx_nnqem.cli import main

    assert main(["-q", "run", str(p), "--out", str(out), "--restart"]) == EXIT_BAD_INPUT


def test_ctrl_c_on_two_ranks(tmp_path):
    """Ctrl-C in a terminal signals mpiexec and both ranks: one message, exit 130, files intact."""
    import signal

    from dolfinx_nnqem.cli import EXIT_INTERRUPTED

    p = problem_file(tmp_path, increments=30)
    out = tmp_path / "out"
    job = start(["-q", "run", str(p), "--out", str(out)], ranks=2)
    wait_for_checkpoint(out, 2, job)
    from mpi4py import MPI

    open_mpi = "Open MPI" in MPI.Get_library_version()
    t0 = time.perf_counter()
    if open_mpi:
        # OpenMPI's mpirun answers its own SIGINT by killing the ranks about 0.5 s later, which
        # a loaded machine's ranks may not outrun (documented in docs/reliability.md): the
        # ranks' side of the contract is tested with the signal sent to them alone
        assert signal_ranks(job, signal.SIGINT) == 2
    else:
        kill_session(job, signal.SIGINT)
    _, err = finish(job, LIMIT_S)
    wall = time.perf_counter() - t0
    lines = [line for line in err.splitlines() if line.startswith("dolfinx-nnqem")]
    summary = json.loads((out / "summary.json").read_text())
    print(f"\n  exit {job.returncode} {wall:.1f} s after SIGINT: {lines}; summary status {summary['status']}")
    assert not list(out.rglob(".*.tmp-*"))
    if "had not ended" in err:
        # the ranks met the signal at different collective calls: the watchdog ended the job
        # (collective.abort_unless_ended) with the interrupt's code; the summary could not be told
        assert job.returncode == EXIT_INTERRUPTED and summary["status"] == "running"
        return
    if "Timeout (0:" in err:
        # the last resort: one rank held Python's lock inside a collective library call the other
        # rank, interrupted, never made (seen: DOLFINx's collective HDF5 write of a field step, on
        # OpenMPI, in 2 of about 20 runs); faulthandler ended it 35 s later (exit 1, its traceback)
        assert job.returncode != 0 and wall < LIMIT_S and summary["status"] == "running", err[-4000:]
        return
    assert summary["status"] == "interrupted", err[-4000:]
    if open_mpi:
        return  # OpenMPI's mpirun ends a job whose ranks exited with an error with its own code (1)
    assert job.returncode == EXIT_INTERRUPTED and len(lines) == 1


@pytest.mark.parametrize("ranks", [1, 2])
def test_a_nearly_full_file_system(tmp_path, ranks):
    """Issue 31, item 1: the output folder on a nearly full file system (a real ENOSPC) ends with
    exit 4 and one message naming the file, on 1 and 2 ranks, wherever the disk runs out
    (fields, pair tables, summary, checkpoint); summary.json says "error"; no temporary and no
    lock file stays. Rank 0 used to segfault (VTK's file writer on ENOSPC) or abort (an HDF5
    file DOLFINx could not close after a failed write), with no message."""
    import shutil

    from reliability_helpers import fill, small_file_system

    p = problem_file(tmp_path, increments=10)
    outcomes = []
    with small_file_system(tmp_path / "disk", "1m") as disk:
        for free_kb in (60, 140, 200, 260, 330):
            out = disk / "out"
            shutil.rmtree(out, ignore_errors=True)
            fill(disk, free_kb * 1024)
            run, wall = _mpirun(_cli(["-q", "run", str(p), "--out", str(out)]), ranks=ranks)
            lines = [line for line in run.stderr.splitlines() if line.startswith("dolfinx-nnqem")]
            summary = out / "summary.json"
            status = json.loads(summary.read_text())["status"] if summary.exists() else None
            left = [f.name for f in out.rglob(".*") if ".tmp-" in f.name or f.name == ".nnqem.lock"]
            outcomes.append((free_kb, run.returncode, lines, status, left, wall))
    for free_kb, code, lines, status, left, wall in outcomes:
        print(f"\n  {ranks} rank(s), {free_kb} kB free: exit {code} after {wall:.1f} s, summary {status!r}, "
              f"left {left}: {lines}")
    for free_kb, code, lines, status, left, wall in outcomes:
        assert code == EXIT_IO and len(lines) == 1, (free_kb, code, lines)
        assert "No space left on device" in lines[0] and str(tmp_path / "disk" / "out") in lines[0]
        assert status == "error" and not left


def test_ranks_stuck_at_different_collective_calls_after_an_interrupt_are_aborted(tmp_path):
    """Each rank meets an interrupt where it is; when rank 0 then waits in one collective call and
    rank 1 in another, the watchdog armed by the interrupt (collective.abort_unless_ended) ends
    the job with the interrupt's exit code and a message, instead of a job that waits forever."""
    from dolfinx_nnqem.cli import EXIT_INTERRUPTED

    script = tmp_path / "stuck.py"
    script.write_text(
        "import dolfinx_nnqem\n"
        "from mpi4py import MPI\n"
        "from dolfinx_nnqem import collective\n"
        "comm = MPI.COMM_WORLD\n"
        "collective.abort_unless_ended(130, 'interrupted (a test)', timeout=2.0)\n"
        "if comm.rank == 0:\n"
        "    comm.barrier()\n"
        "else:\n"
        "    comm.recv(source=0, tag=7)\n")
    run, wall = _mpirun([str(script)])
    lines = [line for line in run.stderr.splitlines() if "had not ended" in line]
    print(f"\n  exit {run.returncode} after {wall:.1f} s: {lines}")
    assert run.returncode == EXIT_INTERRUPTED and lines and wall < 60
