"""Two runs into one folder, re-runs into a used folder, and a JIT cache left by a killed compile."""

import json
import os
import subprocess
import sys
import time

from dolfinx_nnqem.cli import EXIT_IO, EXIT_OK, main
from dolfinx_nnqem.io.locking import LOCK_NAME, OutputLock

from reliability_helpers import env, kill_session, problem_file, start, wait_for_checkpoint


def test_a_second_run_into_a_busy_folder_refuses(tmp_path, capsys):
    p = problem_file(tmp_path, increments=100)  # outlasts the second run's start-up on a loaded machine (30 did not)
    out = tmp_path / "out"
    first = start(["-q", "run", str(p), "--out", str(out)])
    wait_for_checkpoint(out, 1, first)
    code = main(["-q", "run", str(p), "--out", str(out), "--overwrite"])
    err = capsys.readouterr().err.strip()
    first_code = first.wait(timeout=300)
    summary = json.loads((out / "summary.json").read_text())
    print(f"\n  second run: exit {code}: {err}\n  first run: exit {first_code}, {len(summary['load_factors'])} increments, "
          f"status {summary['status']}")
    assert code == EXIT_IO and "in use by another run" in err and f"process {first.pid}" in err
    assert first_code == EXIT_OK and summary["status"] == "completed" and len(summary["load_factors"]) == 100
    assert not (out / LOCK_NAME).exists()


def test_a_killed_run_leaves_no_lock_behind(tmp_path):
    p = problem_file(tmp_path, increments=30)
    out = tmp_path / "out"
    run = start(["-q", "run", str(p), "--out", str(out)])
    wait_for_checkpoint(out, 1, run)
    kill_session(run)
    run.wait()
    print(f"\n  lock file left by the killed run: {(out / LOCK_NAME).exists()}; taken over: ", end="")
    with OutputLock(out):
        print("yes")
    assert main(["-q", "run", str(p), "--out", str(out), "--restart"]) == EXIT_OK


def test_a_used_folder_is_refused_or_cleared_with_overwrite(tmp_path, capsys):
    long, short = problem_file(tmp_path, increments=6), tmp_path / "short.toml"
    short.write_text(long.read_text().replace("increments = 6", "increments = 3"))
    out = tmp_path / "out"
    (tmp_path / "out").mkdir()
    (out / "notes.txt").write_text("the user's own file")
    assert main(["-q", "run", str(long), "--out", str(out)]) == EXIT_OK
    assert main(["-q", "run", str(short), "--out", str(out)]) == EXIT_IO
    err = capsys.readouterr().err.strip()
    assert main(["-q", "run", str(short), "--out", str(out), "--overwrite"]) == EXIT_OK
    csv = sorted(p.name for p in (out / "pairs").glob("*.csv"))
    steps = sorted(p.name for p in (out / "fields").glob("*.xdmf"))
    print(f"\n  without --overwrite: {err}\n  with --overwrite: pair tables {csv}, field steps {steps}, "
          f"user's file kept: {(out / 'notes.txt').exists()}")
    assert "earlier run" in err and len(csv) == 3 and len(steps) == 3 and (out / "notes.txt").exists()


PROBE = """
import sys, dolfinx_nnqem, ufl, dolfinx.mesh, dolfinx.fem
from mpi4py import MPI
from dolfinx_nnqem import jit
mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 1, 1, 1)
V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
jit.form(float(sys.argv[1]) * ufl.TestFunction(V) * ufl.dx)
print("compiled")
"""


def test_a_compile_killed_midway_does_not_break_later_runs(tmp_path):
    """Simulate the state a kill during the first compile leaves (X.c without X.c.cached, no
    library), once recent (FFCx times out, the entry is set aside, compiled again) and once old
    (set aside before compiling)."""
    e = {**env(), "XDG_CACHE_HOME": str(tmp_path / "cache")}
    cache = tmp_path / "cache" / "fenics"

    def compile_(value):
        t0 = time.perf_counter()
        run = subprocess.run([sys.executable, "-c", PROBE, value], env=e, capture_output=True, text=True, timeout=300)
        return run, time.perf_counter() - t0

    for value, age in (("1.5", 0.0), ("2.5", 3600.0)):
        run, _ = compile_(value)
        assert run.returncode == 0, run.stderr
        c_file = max(cache.glob("libffcx_*.c"), key=os.path.getmtime)
        for f in cache.glob(c_file.stem + "*"):
            if f != c_file:
                f.unlink()  # a compile killed after FFCx created X.c
        c_file.write_text("")
        os.utime(c_file, (time.time() - age, time.time() - age))
        run, wall = compile_(value)
        print(f"\n  unfinished entry {age:.0f} s old: exit {run.returncode} in {wall:.1f} s; "
              f"{[line for line in run.stderr.splitlines() if 'set aside' in line]}", end="")
        assert run.returncode == 0 and "compiled" in run.stdout, run.stderr
        assert (cache / (c_file.name + ".cached")).exists()
