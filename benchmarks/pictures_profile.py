"""Where the end-of-run pictures spend their time: one run of a problem file, its picture step
timed stage by stage (wall and CPU seconds).

    python benchmarks/pictures_profile.py [demos/two_beams.toml] [--repeat 3]
    python benchmarks/pictures_profile.py [demos/two_beams.toml] --worker [--repeat 5]

Each repeat is a whole run in this process (``cli.main``), so later repeats find the libraries
imported already: only the first repeat shows the import costs a command-line run pays. A run
here draws in this process; the command line has a picture worker draw them
(``dolfinx_nnqem/io/picture_worker.py``).

With ``--worker``, what the command line does: the run's end-of-run job (``run_pictures.draw_job``:
the last increment's fields, the pair table, the contact surface) is captured once, then each
repeat draws it (1) with a real picture worker started from this process, whose CPU seconds
(user + system, its interpreter's start included) are those the run's process tree pays for the
pictures, and (2) in a fresh process set up as a worker is (the package without its ``__init__``,
no DOLFINx, no MPI), stage by stage. For the whole-process figure (a run with against one without
pictures) time the command line from outside (``benchmarks/speed_guard.py``).
Prints figures; asserts nothing.
"""

import argparse
import functools
import os
import pickle
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _timed(log: list, owner, name: str, label: str) -> None:
    """Wrap ``owner.name`` so that each call appends (label, wall s, CPU s) to ``log``; a stage
    this version of the package does not have is left out (the script also times older ones)."""
    function = getattr(owner, name, None)
    if function is None:
        return

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        wall, cpu = time.perf_counter(), time.process_time()
        try:
            return function(*args, **kwargs)
        finally:
            log.append((label, time.perf_counter() - wall, time.process_time() - cpu))

    setattr(owner, name, wrapper)


def _capture_job(problem: str, folder: Path) -> dict:
    """The end-of-run job of a run of ``problem`` into ``folder`` (drawn by no one)."""
    from dolfinx_nnqem import cli

    class Capture:
        """In place of the run's picture workers: keeps the job, draws nothing."""
        used, pids, job = True, {}, None

        def __enter__(self):
            return self

        def __exit__(self, *exc_info):
            pass

        def close(self):
            pass

        def draw(self, job):
            Capture.job = dict(job)
            return {}

    cli._start_picture_workers = lambda args: Capture()
    cli.main(["-q", "run", problem, "--out", str(folder), "--overwrite"])
    if Capture.job is None:
        raise SystemExit(f"{problem}: the run drew no pictures")
    return Capture.job


def _worker_cpu(job: dict) -> tuple[float, float]:
    """A picture worker started, warmed up and given ``job``: (its CPU seconds, wall seconds from
    its start to its answer)."""
    from dolfinx_nnqem.io.picture_worker import PictureWorkers

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    with PictureWorkers() as workers:
        if not workers.pids:
            raise SystemExit("no picture worker could start")
        done = workers.draw(job)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    failed = {name: why for name, why in done.items() if isinstance(why, str)}
    if failed:
        raise SystemExit(f"pictures not drawn: {failed}")
    return after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime, wall


_STAGES = """\
import time
cpu = [time.process_time()]
import gc, pickle, sys, types
root, job_file = sys.argv[1], sys.argv[2]
# the collector as the tree's worker has it (off for its imports since issue 43's second round)
uncollected = "gc.disable()" in open(root + "/dolfinx_nnqem/io/picture_worker.py").read()
if uncollected:
    gc.disable()
sys.path[0] = root
package = types.ModuleType("dolfinx_nnqem")
package.__path__ = [root + "/dolfinx_nnqem"]
sys.modules["dolfinx_nnqem"] = package
for name in ("mpi4py", "petsc4py", "dolfinx", "dolfinx_solver"):
    sys.modules[name] = None
stages = [("interpreter started (to its first line)", cpu[0])]
def stage(label):
    now = time.process_time()
    stages.append((label, now - cpu[0]))
    cpu[0] = now
import numpy
stage("NumPy")
from dolfinx_nnqem.io import deformed_picture, picture_worker, plots, run_pictures
stage("the package's picture modules")
from dolfinx_nnqem.io import vtk_scene, vtk_charts
vtk_scene.vtk_modules()
stage("VTK's modules of the 3D scenes (no pyvista)")
vtk_charts.chart_modules()
stage("VTK's charts (no matplotlib)")
picture_worker._warm_up("pictures")
stage("VTK's render window asked")
if uncollected:
    gc.freeze()
    gc.enable()
job = pickle.load(open(job_file, "rb"))
for owner, name in ((run_pictures, "draw_pair_pressure"), (run_pictures, "draw_load_curve"),
                    (run_pictures, "draw_convergence"), (deformed_picture.DeformedScene, "draw"),
                    (plots, "draw_contact_pressure")):
    def timed(*args, _function=getattr(owner, name), _name=name, **kwargs):
        stage("(between pictures)")
        result = _function(*args, **kwargs)
        label = f"{_name} {args[1]}" if _name == "draw" else _name
        stage(label.replace("draw_", "").replace("draw ", "scene: ").replace("error_indicator", "error indicator"))
        return result
    setattr(owner, name, timed)
run_pictures.draw_job(job)
stage("(the rest)")
for label, seconds in stages:
    print(f"{label}\t{seconds}")
"""
"""A fresh process set up as a picture worker: the CPU of each stage of its warm-up and job."""


def _worker_stages(job_file: Path) -> dict[str, float]:
    """Stage → CPU seconds of one fresh process drawing the job in ``job_file`` (:data:`_STAGES`)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    try:  # the worker's environment (OpenBLAS held to one thread), where this tree sets one
        from dolfinx_nnqem.io.picture_worker import worker_environment
    except ImportError:
        pass
    else:
        env = worker_environment(env)
    done = subprocess.run([sys.executable, "-c", _STAGES, str(ROOT), str(job_file)], env=env, check=True,
                          capture_output=True, text=True)
    stages: dict[str, float] = {}
    for line in done.stdout.splitlines():
        label, seconds = line.rsplit("\t", 1)
        stages[label] = stages.get(label, 0.0) + float(seconds)
    return stages


def profile_worker(problem: str, repeat: int) -> None:
    """The ``--worker`` figures: a worker's CPU for the captured job, and its stages."""
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        job = _capture_job(problem, run)
        job_file = Path(tmp) / "job.pickle"
        job_file.write_bytes(pickle.dumps(job))
        totals, walls, stages = [], [], []
        for k in range(repeat):  # a fresh copy of the results each time (the pictures are written there)
            folder = Path(tmp) / f"draw{k}"
            shutil.copytree(run, folder)
            cpu, wall = _worker_cpu({**job, "folder": folder})
            totals.append(cpu)
            walls.append(wall)
            job_file.write_bytes(pickle.dumps({**job, "folder": folder}))
            stages.append(_worker_stages(job_file))
    print(f"\nthe picture worker, {repeat} runs (median, min–max), load average {os.getloadavg()[0]:.1f}:")
    print(f"  {'CPU of the worker process (start to exit)':50s} {statistics.median(totals):6.3f} s "
          f"({min(totals):.3f}–{max(totals):.3f})")
    print(f"  {'wall, from its start to its answer':50s} {statistics.median(walls):6.3f} s")
    print("\nits stages in a fresh process set up as the worker is (CPU s, median):")
    for label in stages[0]:
        values = [s.get(label, 0.0) for s in stages]
        print(f"  {label:50s} {statistics.median(values):6.3f}   ({min(values):.3f}–{max(values):.3f})")
    print(f"  {'all':50s} {statistics.median(sum(s.values()) for s in stages):6.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("problem", nargs="?", default=str(ROOT / "demos" / "two_beams.toml"))
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--worker", action="store_true", help="the picture worker's CPU and stages (see above)")
    args = parser.parse_args()
    if args.worker:
        print(f"{sys.argv[0]}: {args.problem}, Python {sys.version.split()[0]}, the picture worker")
        profile_worker(args.problem, args.repeat)
        return

    started = time.perf_counter()
    from dolfinx_nnqem import cli
    from dolfinx_nnqem.io import deformed_picture, output, plots, run_pictures

    log: list[tuple[str, float, float]] = []
    # the stages, innermost first: each label's time includes the stages nested in it
    _timed(log, output.ResultsWriter, "_last_field_step", "fields gathered from memory")
    _timed(log, plots, "figure", "curves: a figure (first: matplotlib imported)")
    _timed(log, run_pictures, "draw_pair_pressure", "pair_pressure.png (first: VTK imported)")
    _timed(log, run_pictures, "draw_load_curve", "load_curve.png")
    _timed(log, run_pictures, "draw_convergence", "convergence.png")
    _timed(log, deformed_picture, "_field_grid", "deformed: grid")
    _timed(log, deformed_picture, "deformed_scene", "deformed: the scene")
    _timed(log, deformed_picture.DeformedScene, "draw", "deformed.png, error_indicator.png: each in all")
    _timed(log, plots, "plot_contact_pressure", "contact_pressure.png")  # (older versions)
    _timed(log, plots, "draw_contact_pressure", "contact_pressure.png")
    _timed(log, output.ResultsWriter, "_draw_pictures", "picture step in all")
    print(f"{sys.argv[0]}: {args.problem}, Python {sys.version.split()[0]}")
    for repeat in range(args.repeat):
        log.clear()
        with tempfile.TemporaryDirectory() as folder:
            cli.main(["-q", "run", args.problem, "--out", folder, "--overwrite"])
        print(f"\nrun {repeat + 1}{' (imports included)' if repeat == 0 else ''}:")
        for label, wall, cpu in log:
            print(f"  {label:50s} wall {wall:6.3f} s   CPU {cpu:6.3f} s")
    print(f"\nthis process: {time.perf_counter() - started:.2f} s")


if __name__ == "__main__":
    main()
