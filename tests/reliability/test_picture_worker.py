"""The picture workers of a command-line run (issue 32): the same pictures as drawn in the run's
own process, pixel for pixel; what a dead worker leaves is drawn by the run; no worker without
pictures; none outlives its run; no DOLFINx, PETSc or MPI in a worker."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dolfinx_nnqem import cli
from dolfinx_nnqem.cli import EXIT_INTERRUPTED, EXIT_OK, main
from dolfinx_nnqem.io import picture_worker, run_pictures
from dolfinx_nnqem.io.picture_worker import BLOCKED, ROLES, PictureWorkers
from dolfinx_nnqem.io.run_pictures import CONTACT_PICTURE, ENV_SWITCH, PICTURES

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "demos" / "two_beams.toml"
ALL = (*PICTURES, CONTACT_PICTURE)


def _pictures_line(text: str) -> str:
    """The names of the printed ``pictures: ...`` line (its folder left out)."""
    lines = [line for line in text.splitlines() if line.startswith("pictures: ")]
    assert len(lines) == 1, text
    return lines[0].rsplit(" in ", 1)[0]


def _same_pixels(a: Path, b: Path) -> None:
    from matplotlib.image import imread

    drawn = [name for name in ALL if (a / "pictures" / name).exists()]  # error_estimates.png: with --estimate
    assert drawn == [name for name in ALL if (b / "pictures" / name).exists()]
    for name in drawn:
        first, second = imread(a / "pictures" / name), imread(b / "pictures" / name)
        assert first.shape == second.shape and np.array_equal(first, second), f"{name} differs"


def _run(out: Path, monkeypatch, capsys, workers: PictureWorkers | None) -> str:
    """``run`` in this process, its pictures drawn by ``workers`` (None: by this process)."""
    monkeypatch.setattr(cli, "_start_picture_workers", lambda args: workers)
    assert main(["run", str(EXAMPLE), "--increments", "3", "--out", str(out)]) == EXIT_OK
    return _pictures_line(capsys.readouterr().out)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The pictures of a run drawn in its own process, and its printed pictures line."""
    out = tmp_path_factory.mktemp("reference") / "out"
    env = dict(os.environ, **{ENV_SWITCH: "1"})
    code = ("import sys; from dolfinx_nnqem.cli import main; "
            f"sys.exit(main(['run', {str(EXAMPLE)!r}, '--increments', '3', '--out', {str(out)!r}]))")
    done = subprocess.run([sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    return out, _pictures_line(done.stdout)


def test_the_workers_draw_the_pictures_of_the_run_pixel_for_pixel(reference, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv(ENV_SWITCH, raising=False)
    here = []
    draw = run_pictures.draw_job
    monkeypatch.setattr(run_pictures, "draw_job", lambda job: (here.append(job), draw(job))[1])
    with PictureWorkers() as workers:
        started = workers.pids
        line = _run(tmp_path / "out", monkeypatch, capsys, workers)
    assert set(started) == set(ROLES) and workers.used and workers.pids == {}  # ended with the run
    print(f"\n  {line}; drawn in the run's process: {here}")
    assert here == [], "the run drew pictures itself"
    assert line == reference[1]
    _same_pixels(reference[0], tmp_path / "out")


@pytest.mark.parametrize("when", ["during the run", "while it draws"])
def test_a_dead_worker_leaves_its_pictures_to_the_run(reference, tmp_path, monkeypatch, capsys, when):
    monkeypatch.delenv(ENV_SWITCH, raising=False)
    here = []
    draw = run_pictures.draw_job
    monkeypatch.setattr(run_pictures, "draw_job", lambda job: (here.append(job), draw(job))[1])
    with PictureWorkers() as workers:
        fields = workers.pids["pictures"]
        if when == "during the run":
            os.kill(fields, signal.SIGKILL)  # (its own child: killed by its id)
        else:  # killed once it has its job: it answers nothing
            send = picture_worker._Worker.send

            def send_then_die(worker, job):
                sent = send(worker, job)
                if worker.role == "pictures":
                    os.kill(fields, signal.SIGKILL)
                return sent

            monkeypatch.setattr(picture_worker._Worker, "send", send_then_die)
        line = _run(tmp_path / "out", monkeypatch, capsys, workers)
    print(f"\n  {line}; drawn in the run's process: {[job['names'] for job in here]}")
    assert len(here) == 1 and {"deformed.png", "convergence.png"} <= set(here[0]["names"]) <= set(ROLES["pictures"][0])
    assert here[0]["contact"] is not None
    assert line == reference[1]
    _same_pixels(reference[0], tmp_path / "out")


def test_the_worker_imports_without_collections_and_draws_with_them(monkeypatch):
    """Issue 43 (the pictures' CPU): the worker's imports run with the cyclic garbage collector
    off (from the first line of its program), the drawing with it on, the imported objects frozen."""
    import gc

    boot = picture_worker._BOOT
    assert boot.index("gc.disable()") < boot.index("import types") < boot.index("from dolfinx_nnqem")
    seen = []
    monkeypatch.setattr(picture_worker, "_warm_up", lambda role: seen.append((role, gc.isenabled())))
    frozen = gc.get_freeze_count()
    gc.disable()
    try:
        picture_worker._warm_up_uncollected("pictures")
        assert seen == [("pictures", False)]  # imported with the collector off
        assert gc.isenabled() and gc.get_freeze_count() > frozen
    finally:
        gc.unfreeze()
        gc.enable()


def test_no_worker_without_pictures(monkeypatch):
    """--no-pictures, --check, DOLFINX_NNQEM_PICTURES=0, a rank other than 0, a job of several
    ranks, a user's program calling main(): no worker is started (nothing is spent)."""
    started = []
    monkeypatch.setattr("dolfinx_nnqem.io.picture_worker.PictureWorkers",
                        lambda *a, **k: started.append(1) or "workers")
    monkeypatch.delenv(ENV_SWITCH, raising=False)
    monkeypatch.setattr(picture_worker.os, "cpu_count", lambda: 2)  # the machine's own count aside
    for name in ("PMI_RANK", "PMI_SIZE", "PMIX_SIZE", "OMPI_COMM_WORLD_SIZE", "MV2_COMM_WORLD_SIZE", "SLURM_NTASKS"):
        monkeypatch.delenv(name, raising=False)

    def workers(*argv, command_line=True, **env):
        monkeypatch.setattr(cli.interrupts, "is_command_line", lambda: command_line)
        for name, value in env.items():
            monkeypatch.setenv(name, value)
        args = cli._parser().parse_args(["-q", *argv])
        args.verbose = 0
        return cli._start_picture_workers(args)

    assert workers("run", str(EXAMPLE)) == "workers" and started == [1]
    assert workers("run", str(EXAMPLE), "--no-pictures") is None
    assert workers("run", str(EXAMPLE), "--check") is None
    assert workers("run", str(EXAMPLE), command_line=False) is None
    assert workers("plot", "results") is None
    assert workers("run", str(EXAMPLE), PMI_RANK="1") is None
    monkeypatch.setenv("PMI_RANK", "0")
    assert workers("run", str(EXAMPLE), PMI_SIZE="2") is None  # a job of several ranks: no idle core
    monkeypatch.setenv("PMI_SIZE", "1")
    assert workers("run", str(EXAMPLE), **{ENV_SWITCH: "0"}) is None
    assert started == [1]


def test_a_ctrl_c_while_a_worker_starts_is_not_lost(monkeypatch):
    """Issue 39, item 4: the run ignored SIGINT in its own process while it started each worker,
    so a Ctrl-C then was lost (8 of 8 runs exited 0). A Ctrl-C that arrives while the worker's
    process is being made now reaches the run's handler once the worker has started."""
    received: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    popen = subprocess.Popen

    def interrupted_popen(*args, **kwargs):  # the Ctrl-C comes while the worker starts
        process = popen(*args, **kwargs)
        os.kill(os.getpid(), signal.SIGINT)
        return process

    monkeypatch.setattr(picture_worker.subprocess, "Popen", interrupted_popen)
    try:
        with PictureWorkers() as workers:
            started = workers.pids
    finally:
        signal.signal(signal.SIGINT, previous)
    print(f"\n  workers {started}: Ctrl-C received by the run's handler {len(received)} times of {len(ROLES)}")
    assert set(started) == set(ROLES) and received == [signal.SIGINT] * len(ROLES)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_ctrl_c_as_soon_as_a_worker_exists_ends_the_run(tmp_path):
    """Issue 39, item 4, as reported: SIGINT sent to the run as soon as it has a child process
    (the first worker being started) used to be lost, and the run ended with exit 0."""
    env = {k: v for k, v in os.environ.items() if k != ENV_SWITCH}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    run = subprocess.Popen([sys.executable, "-m", "dolfinx_nnqem", "run", str(EXAMPLE), "--out",
                            str(tmp_path / "out"), "--increments", "200"], cwd=ROOT, env=env,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 120
    while not _children(run.pid) and run.poll() is None and time.monotonic() < deadline:
        pass  # no sleep: the signal must come while the worker is being made
    child = _children(run.pid)
    assert child and run.poll() is None, run.communicate()  # (a reaped process's id may be another's)
    os.kill(run.pid, signal.SIGINT)
    try:
        out, err = run.communicate(timeout=300)
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)
            run.communicate()
    print(f"\n  SIGINT with child {child}: exit {run.returncode}; stderr {err!r}")
    assert child and run.returncode == EXIT_INTERRUPTED and "Traceback" not in err
    assert err.startswith("dolfinx-nnqem: interrupted (Ctrl-C)") and err.count("\n") == 1


def test_a_worker_imports_neither_dolfinx_nor_mpi():
    """The modules a worker uses import without DOLFINx, PETSc and MPI (blocked as in a worker)."""
    code = (f"import sys, types\nfor name in {BLOCKED!r}: sys.modules[name] = None\n"
            "package = types.ModuleType('dolfinx_nnqem')\n"
            f"package.__path__ = [{str(ROOT / 'dolfinx_nnqem')!r}]\n"
            "sys.modules['dolfinx_nnqem'] = package\n"
            "from dolfinx_nnqem.io import picture_worker, plots, run_pictures\n"
            "picture_worker._warm_up('curves'); picture_worker._warm_up('fields')\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('mpi4py', 'petsc4py', 'dolfinx', 'h5py') "
            "and sys.modules[m] is not None))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    print(f"\n  {done.stdout.strip()} {done.stderr[-2000:]}")
    assert done.returncode == 0 and done.stdout.strip().splitlines()[-1] == "[]"


class _Captured:
    """In place of a run's picture workers: keeps the end-of-run job, draws nothing."""

    used, pids, job = True, {}, None

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        pass

    def close(self):
        pass

    def draw(self, job):
        _Captured.job = dict(job)
        return {}


def test_a_worker_draws_without_pyvista_or_matplotlib(tmp_path, monkeypatch, capsys):
    """A run's end-of-run job (captured) drawn by a process set up as a worker is: every picture
    drawn, and neither pyvista nor matplotlib imported (half the worker's CPU, issue 43: the 3D
    pictures are drawn by VTK's own classes, the curves by VTK's charts)."""
    import pickle

    monkeypatch.delenv(ENV_SWITCH, raising=False)
    monkeypatch.setattr(cli, "_start_picture_workers", lambda args: _Captured())
    assert main(["-q", "run", str(EXAMPLE), "--increments", "2", "--out", str(tmp_path / "out")]) == EXIT_OK
    assert _Captured.job is not None
    job_file = tmp_path / "job.pickle"
    job_file.write_bytes(pickle.dumps(_Captured.job))
    code = (f"import pickle, sys, types\nfor name in {BLOCKED!r}: sys.modules[name] = None\n"
            "package = types.ModuleType('dolfinx_nnqem')\n"
            f"package.__path__ = [{str(ROOT / 'dolfinx_nnqem')!r}]\n"
            "sys.modules['dolfinx_nnqem'] = package\n"
            "from dolfinx_nnqem.io import picture_worker, run_pictures\n"
            "picture_worker._warm_up('pictures')\n"
            f"done = run_pictures.draw_job(pickle.load(open({str(job_file)!r}, 'rb')))\n"
            "print(sorted(name for name, path in done.items() if isinstance(path, str)))\n"
            "print(sorted(m for m in ('pyvista', 'matplotlib') if sys.modules.get(m) is not None))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    print(f"\n  not drawn, imported: {done.stdout.strip().splitlines()} {done.stderr[-2000:]}")
    assert done.returncode == 0 and done.stdout.strip().splitlines()[-2:] == ["[]", "[]"]
    drawn = sorted(p.name for p in (tmp_path / "out" / "pictures").glob("*.png"))
    assert set(drawn) == set(ALL) - {"error_estimates.png"}, drawn  # (no estimate in this run)


def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def _running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _start_run(tmp_path: Path, *extra: str) -> tuple[subprocess.Popen, list[int]]:
    """A command-line run (a process group of its own) and its workers' process ids."""
    env = {k: v for k, v in os.environ.items() if k != ENV_SWITCH}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    run = subprocess.Popen([sys.executable, "-m", "dolfinx_nnqem", "run", str(EXAMPLE), "--out",
                            str(tmp_path / "out"), *extra], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 60
    while len(_children(run.pid)) < len(ROLES) and time.monotonic() < deadline and run.poll() is None:
        time.sleep(0.01)
    return run, _children(run.pid)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_ctrl_c_ends_the_workers_with_the_run(tmp_path):
    """Ctrl-C (SIGINT to the process group) during a run: the run's one-line message and exit
    130, no traceback of a worker, no worker left."""
    run, workers = _start_run(tmp_path, "--increments", "200")
    time.sleep(1.0)
    assert run.poll() is None, run.communicate()  # (a reaped process's id may be another's)
    os.killpg(run.pid, signal.SIGINT)
    out, err = run.communicate(timeout=120)
    time.sleep(0.2)
    print(f"\n  workers {workers}; exit {run.returncode}; stderr {err!r}")
    assert len(workers) == len(ROLES)
    assert run.returncode == EXIT_INTERRUPTED and "Traceback" not in err and err.count("\n") == 1
    assert not any(_running(pid) for pid in workers)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_the_workers_die_with_a_killed_run(tmp_path):
    run, workers = _start_run(tmp_path, "--increments", "200")
    assert run.poll() is None, run.communicate()  # (a reaped process's id may be another's: SIGKILL)
    os.kill(run.pid, signal.SIGKILL)
    run.communicate(timeout=60)
    deadline = time.monotonic() + 10
    while any(_running(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    print(f"\n  workers {workers}: running after the run was killed: {[p for p in workers if _running(p)]}")
    assert len(workers) == len(ROLES) and not any(_running(pid) for pid in workers)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_no_worker_with_no_pictures_in_the_command_line(tmp_path):
    run, workers = _start_run(tmp_path, "--increments", "2", "--no-pictures")
    out, err = run.communicate(timeout=300)
    assert run.returncode == EXIT_OK and workers == [] and not (tmp_path / "out" / "pictures").exists()


def test_io_modules_stay_reachable_as_attributes():
    """``import dolfinx_nnqem.io`` imports its public names lazily; its modules stay reachable as
    attributes (``io.output``, ``io.plots``), as when the package imported them eagerly."""
    import dolfinx_nnqem.io as io

    assert io.output.ResultsWriter is io.ResultsWriter
    assert callable(io.plots.plot_contact_pressure) and callable(io.results.pair_table)
    with pytest.raises(AttributeError, match="no attribute 'no_such_module'"):
        io.no_such_module  # noqa: B018
