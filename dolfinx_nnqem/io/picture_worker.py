"""Picture workers: processes started with a run that draw its pictures when it ends.

The pictures of a run (:mod:`dolfinx_nnqem.io.run_pictures`) are drawn by VTK (the 3D scenes,
:mod:`dolfinx_nnqem.io.vtk_scene`, and the curves, :mod:`dolfinx_nnqem.io.vtk_charts`), whose
imports take about as long as the drawing itself (pyvista and matplotlib, which drew them before,
cost the worker more than the drawing: ``docs/performance.md``). A run uses one core; a worker started with
the run imports them on another core while the run solves, then draws what the run sends it at
its end. One worker, ``pictures``, draws them all (:data:`ROLES`): two workers (the matplotlib
figures and the VTK pictures drawn at the same time) saved 0.1–0.2 s of wall clock but cost
0.2–0.3 s more CPU, each importing NumPy and matplotlib again (``docs/performance.md``). A worker costs CPU (it imports NumPy again) and
saves wall clock time only where a core is idle.

A worker is a fresh Python process (``subprocess``, never a fork of the run: MPI and PETSc are
initialised there) that imports neither DOLFINx nor PETSc nor MPI: an MPI initialisation in a
child of an MPI process breaks under ``mpiexec``, and those modules are blocked in it. It is
given plain data only (:func:`~dolfinx_nnqem.io.run_pictures.draw_job`: the results folder,
the last increment's fields as NumPy arrays, the contact pressure's points and triangles) and
draws with the same functions as the run's own process, so the pictures are the same.

Its lifetime is the run's: it reads its jobs from a pipe and ends at the pipe's end of file; it
ignores Ctrl-C (the run handles it) and is killed with the run's process (Linux's parent-death
signal); a run that ends without pictures kills it (:meth:`PictureWorkers.close`). What a worker
cannot draw (it could not start, its imports failed, it died) is drawn in the run's process, as
without workers, with the same results and reasons.
"""

from __future__ import annotations

import gc
import logging
import os
import pickle
import signal
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import IO, Any

__all__ = ["ROLES", "PictureWorkers", "launcher_rank", "launcher_size", "serve", "worker_environment", "worth_starting"]

ROLES: dict[str, tuple[tuple[str, ...], bool]] = {
    "pictures": (("deformed.png", "pair_pressure.png", "load_curve.png", "convergence.png", "error_indicator.png",
                  "error_estimates.png"), True),
}
"""Worker role → (the pictures of :data:`~dolfinx_nnqem.io.run_pictures.PICTURES` it draws,
whether it draws ``contact_pressure.png``)."""

BLOCKED = ("mpi4py", "petsc4py", "dolfinx", "dolfinx_solver")
"""Modules a worker cannot import (an ImportError instead of an MPI initialisation)."""

_BOOT = """\
import gc, signal, sys
gc.disable()
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
root = sys.argv[1]
sys.path[0] = root
import types
package = types.ModuleType("dolfinx_nnqem")
package.__path__ = [root + "/dolfinx_nnqem"]
sys.modules["dolfinx_nnqem"] = package
from dolfinx_nnqem.io.picture_worker import serve
serve(sys.argv[2:])
"""
"""The worker's ``python -c`` program: the cyclic garbage collector off while it imports (until
:func:`serve` has warmed up), Ctrl-C ignored (and no longer blocked, as the run started it), the
package found where the run found it, and its ``__init__`` (which imports DOLFINx in a user's
program) left out."""

_log = logging.getLogger("dolfinx_nnqem")


def launcher_size() -> int | None:
    """The number of processes ``mpiexec`` (or ``srun``) announces for the job, before MPI is
    initialised; None where none is announced (a process without a launcher)."""
    for name in ("PMI_SIZE", "PMIX_SIZE", "OMPI_COMM_WORLD_SIZE", "MV2_COMM_WORLD_SIZE", "SLURM_NTASKS"):
        value = os.environ.get(name, "").strip()
        if value.isdigit():
            return int(value)
    return None


def worth_starting() -> bool:
    """Workers save wall-clock time only where a core is idle while the run solves: not in a job
    of several ranks (they take the cores; a worker also shifted where a Ctrl-C met the two ranks
    of an Open MPI job), nor on a single core."""
    return (launcher_size() or 1) == 1 and (os.cpu_count() or 1) >= 2


def launcher_rank() -> int | None:
    """This process's rank as ``mpiexec`` (or ``srun``) announces it in the environment, before
    MPI is initialised; None where none is announced (a process without a launcher: rank 0)."""
    for name in ("PMI_RANK", "PMIX_RANK", "OMPI_COMM_WORLD_RANK", "MV2_COMM_WORLD_RANK", "SLURM_PROCID"):
        value = os.environ.get(name, "").strip()
        if value.isdigit():
            return int(value)
    return None


def worker_environment(environment: Mapping[str, str]) -> dict[str, str]:
    """A worker's environment: the run's, with NumPy's OpenBLAS held to one thread. A worker does
    no linear algebra; OpenBLAS starts a thread a core when NumPy is imported, which took a
    sixth of the import's CPU (``docs/performance.md``, "The pictures' CPU")."""
    return {**environment, "OPENBLAS_NUM_THREADS": "1"}


# -- the run's side ------------------------------------------------------------------------------
class _Worker:
    """One worker process of a role, seen from the run (its pipes and its process)."""

    def __init__(self, role: str, process: subprocess.Popen):
        self.role = role
        self.process = process
        self.answered = False  #: it answered its job (it exits at the end of its pipe)
        self.pictures: Path | None = None  #: the folder its job draws into

    @classmethod
    def start(cls, role: str, *, shown: bool, level: int) -> _Worker | None:
        """Start a worker of ``role``; None where the process cannot be started.

        SIGINT is blocked in this thread while the worker starts, never ignored: a Ctrl-C that
        arrives meanwhile waits, and the run's handler acts on it once the worker has started
        (with SIGINT ignored for the start, 8 Ctrl-C of 8 sent as soon as the worker existed
        were lost: the run went on to exit 0). The worker inherits the blocked signal, so it
        cannot act on a Ctrl-C before its first line, which ignores it (:data:`_BOOT`).
        """
        root = str(Path(__file__).resolve().parents[2])
        command = [sys.executable, "-c", _BOOT, root, role, str(os.getpid()), "1" if shown else "0", str(level)]
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, close_fds=True,
                                       env=worker_environment(os.environ))
        except (OSError, ValueError, subprocess.SubprocessError) as error:  # no usable interpreter
            _log.info(f"picture worker {role}: not started ({error}); the pictures are drawn in the run")
            return None
        finally:  # a Ctrl-C received meanwhile is delivered now, to the run's handler
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        return cls(role, process)

    def send(self, job: Mapping[str, Any]) -> bool:
        """Give the worker a job; False where it is gone (it died, its imports failed)."""
        stdin = self.process.stdin
        if stdin is None or self.process.poll() is not None:
            return False
        from dolfinx_nnqem.io.run_pictures import PICTURE_FOLDER

        self.pictures = Path(job["folder"]) / PICTURE_FOLDER
        try:
            pickle.dump(dict(job), stdin, protocol=pickle.HIGHEST_PROTOCOL)
            stdin.flush()
        except (OSError, ValueError):  # BrokenPipeError: it ended meanwhile
            return False
        return True

    def receive(self) -> dict | None:
        """The worker's answer to its job (picture → path or reason); None where it ended without one."""
        stdout = self.process.stdout
        if stdout is None:
            return None
        try:
            answer = pickle.load(stdout)
        except (EOFError, OSError, pickle.UnpicklingError, ValueError, AttributeError, ImportError):
            return None
        self.answered = isinstance(answer, dict)
        return answer if self.answered else None

    def finish(self) -> None:
        """No more jobs: end of file on the worker's pipe (it exits)."""
        for stream in (self.process.stdin, self.process.stdout):
            if stream is not None:
                try:
                    stream.close()
                except OSError:  # a broken pipe: the worker is gone already
                    pass

    def stop(self) -> None:
        """End the worker and reap it (no zombie): one that answered exits at its end of file
        (waited for, a second at most); any other is killed at once (a run that failed, or was
        interrupted while the worker drew, does not wait for it), and the temporary of the
        picture it was drawing is removed (a picture is whole or absent)."""
        self.finish()
        try:
            self.process.wait(timeout=1.0 if self.answered else 0.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        if self.pictures is not None and not self.answered:
            from dolfinx_nnqem.io.safe_io import remove_temporaries_of

            remove_temporaries_of(self.pictures, self.process.pid)


class PictureWorkers:
    """The picture workers of a run (rank 0's): started with the run, given the pictures to
    draw at its end (:meth:`draw`), ended with it (:meth:`close`, or ``with``).

    Parameters
    ----------
    roles
        The workers: role → (pictures, draws ``contact_pressure.png``), :data:`ROLES` by default.
    shown
        Third-party output shown (``-v``), as :func:`dolfinx_nnqem.chatter.show_third_party_output`.
    level
        The logging level of the run's log (``dolfinx_nnqem``), the workers' too.
    """

    def __init__(self, roles: Mapping[str, tuple[Sequence[str], bool]] = ROLES, *, shown: bool = False,
                 level: int = logging.WARNING):
        self.roles = {role: (tuple(names), bool(contact)) for role, (names, contact) in roles.items()}
        self._workers: dict[str, _Worker] = {}
        for role in self.roles:
            worker = _Worker.start(role, shown=shown, level=level)
            if worker is not None:
                self._workers[role] = worker
        self.used = False  #: :meth:`draw` was called (the workers were given their jobs)

    def __enter__(self) -> PictureWorkers:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    @property
    def pids(self) -> dict[str, int]:
        """Role → process id of the workers started."""
        return {role: worker.process.pid for role, worker in self._workers.items()}

    def draw(self, job: Mapping[str, Any]) -> dict[str, Path | str]:
        """Draw ``job`` (:func:`~dolfinx_nnqem.io.run_pictures.draw_job`) with the workers: each
        its part; a part whose worker is gone, or dies, is drawn in this process.

        Returns the same as ``draw_job(job)`` would, in the same order.
        """
        from dolfinx_nnqem.io.run_pictures import CONTACT_PICTURE, PICTURES, draw_job

        self.used = True
        parts = self._parts(job)
        sent = [role for role, part in parts.items() if role in self._workers and self._workers[role].send(part)]
        for role in set(parts) - set(sent):
            _log.info(f"picture worker {role}: gone; its pictures are drawn in the run")
        if not sent:  # no worker: everything here, as a run without workers draws it
            self.close()
            return draw_job(job)
        done: dict[str, Path | str] = {}
        for role, part in parts.items():  # drawn here meanwhile: the parts of workers gone
            if role not in sent:
                done.update(draw_job(part))
        for role in sent:
            answer = self._workers[role].receive()
            self._workers[role].finish()
            if answer is None:
                _log.info(f"picture worker {role}: ended without its pictures; they are drawn in the run")
                answer = draw_job(parts[role])
            done.update(answer)
        order = [*PICTURES, CONTACT_PICTURE]
        return {name: done[name] for name in sorted(done, key=order.index)}

    def _parts(self, job: Mapping[str, Any]) -> dict[str, dict]:
        """``job`` split by role (the parts with nothing to draw left out)."""
        asked = set(job.get("names", ()))
        parts = {}
        for role, (names, contact) in self.roles.items():
            part = {"folder": job["folder"], "names": tuple(n for n in names if n in asked),
                    "step": job.get("step") if "deformed.png" in names else None,
                    "contact": job.get("contact") if contact else None}
            if part["names"] or part["contact"] is not None:
                parts[role] = part
        return parts

    def close(self) -> None:
        """End the workers (reaped: none outlives this call). Those that answered their jobs
        have ended or are ending; the others are killed at once."""
        workers, self._workers = self._workers, {}
        for worker in workers.values():
            worker.stop()


# -- the worker's side ---------------------------------------------------------------------------
def serve(argv: Sequence[str]) -> None:
    """The worker process: warm up, then draw each job read from stdin, answer on stdout; exit at
    the end of stdin (or when the run's process is gone). Never returns.

    ``argv``: role, the run's process id, third-party output shown (``1``/``0``), logging level.
    """
    role, parent, shown, level = argv[0], int(argv[1]), argv[2] == "1", int(argv[3])
    for name in BLOCKED:
        sys.modules[name] = None  # type: ignore[assignment]  # None: importing it raises ImportError
    _die_with(parent)
    answers = os.fdopen(os.dup(1), "wb")  # the answers' pipe: stray prints go to stderr instead
    os.dup2(2, 1)
    code = 0
    try:
        logging.basicConfig(level=level, format="%(message)s")
        from dolfinx_nnqem.chatter import show_third_party_output

        show_third_party_output(shown)
        _warm_up_uncollected(role)
        _answer_jobs(sys.stdin.buffer, answers)
    except BaseException:  # noqa: BLE001  (imports failed: the run draws the pictures itself)
        code = 1
    finally:
        try:
            answers.close()
        except OSError:
            pass
    os._exit(code)  # no interpreter tear-down (VTK and matplotlib have nothing left to write)


def _die_with(parent: int) -> None:
    """Have the kernel kill this process when the run's process ends (Linux); exit now if it has."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:
        os._exit(0)


def _warm_up(role: str) -> None:
    """Import what the pictures need (raises where an import fails): the VTK modules of the 3D
    scenes and of the charts (:func:`~dolfinx_nnqem.io.vtk_charts.chart_modules`; neither pyvista
    nor matplotlib), and whether VTK renders here asked once. ``role`` names the worker (one role
    draws everything, :data:`ROLES`); ``error_estimates.png`` imports matplotlib where a run has
    estimates."""
    from dolfinx_nnqem import pyvista_compat
    from dolfinx_nnqem.chatter import apply_vtk_options
    import dolfinx_nnqem.io.vtk_charts as vtk_charts

    vtk_charts.chart_modules()
    apply_vtk_options()
    pyvista_compat.vtk_render_problem()


def _warm_up_uncollected(role: str) -> None:
    """:func:`_warm_up` with the cyclic garbage collector off (:data:`_BOOT` turned it off), then
    the collector on again, the objects made so far frozen.

    The imports make a great many objects and no garbage; the collections they set off took a
    sixth of their CPU. Frozen, the modules' objects are left out of the collections made while
    the pictures are drawn (their garbage is collected as usual).
    """
    try:
        _warm_up(role)
    finally:
        gc.freeze()
        gc.enable()


def _answer_jobs(jobs: IO[bytes], answers: IO[bytes]) -> None:
    """Draw every job of ``jobs`` and write its answer; return at the end of ``jobs``."""
    from dolfinx_nnqem.io.run_pictures import draw_job

    while True:
        try:
            job = pickle.load(jobs)
        except EOFError:
            return
        pickle.dump(draw_job(job), answers, protocol=pickle.HIGHEST_PROTOCOL)
        answers.flush()
