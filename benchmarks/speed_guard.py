"""Speed guard: the figures of issue 32 as ratios against a baseline measured in the same run.

A machine's speed varies from run to run (this shared development machine: 2.5x between a quiet
and a busy moment), so absolute times do not show a slowdown. Every figure here is divided by
a baseline of the same kind measured in the same run, interleaved with it (A B A B ...), and
the median of the pairwise ratios is printed with their spread:

* whole processes: ``dolfinx-nnqem run demos/two_beams.toml --no-pictures`` and ``--help``
  against ``python -c "import dolfinx_solver, dolfinx"`` (the import floor of any run), and
  against CalculiX on the same model when ``ccx`` is installed
  (``benchmarks/calculix_two_beams.py``);
* in this process: one Newton iteration of the pressed blocks (monolithic, iterative, level
  ``--level``), one outer iteration of NNEQM1 and one Newton step of NNEQM2 (level 2), against
  an assembly and MUMPS solve of linear elasticity on a cube of the same kind, with DOLFINx
  alone (no code of the package);
* in this process: the pressed blocks' whole load path with the iterative solver at level
  ``--proxy-level`` (the million-dof run's proxy), against the same baseline;
* in this process: NNEQM1 against the monolithic solver (direct) on the sphere slid over a block
  in the current geometry (``--slide-n``³ hexahedra, 10 increments; issue 43, "Speed, second round"),
  with both methods' outer/Newton iterations, solves per increment and NNEQM1's factorisations;
* counts that do not depend on the machine: Newton and Krylov iterations, AMG set-ups, and the
  Newton iterations per increment of the node-to-surface and mortar block slides (12 increments,
  μ_f = 0 and 0.3) against the rigid sphere's slide (``--slide-n``³, 10 increments) with the
  monolithic solver (issue 43: at most 1.5 times; ``benchmarks/large_sliding.py``'s cases);
* what the end-of-run pictures add (issue 43): ``dolfinx-nnqem run demos/two_beams.toml`` with its
  pictures against ``--no-pictures``, in turn: the median of the pairwise differences of CPU
  seconds (the process and the children it waited for: the picture worker too) and of wall
  seconds; absolute seconds, so compare them only at a like load (``docs/performance.md``).

Compare its output with the one in ``docs/performance.md`` (the last run of the issue's
closing note): a ratio that grew by more than its spread is a slowdown. Prints figures;
asserts nothing::

    python benchmarks/speed_guard.py [--runs 5] [--level 4] [--slide-n 8]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _time(cmd: list[str], cwd: str | None = None, env: dict | None = None) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    return time.perf_counter() - t0


def _ratios(a, b, runs: int) -> str:
    """A and B in turn ``runs`` times: 'median (min–max)' of A/B, and the medians of A and B."""
    pairs = []
    for _ in range(runs):
        pairs.append((a(), b()))
    r = sorted(x / y for x, y in pairs)
    return (f"{statistics.median(r):.2f} ({r[0]:.2f}–{r[-1]:.2f}); A median {statistics.median(x for x, _ in pairs):.3f} s,"
            f" B median {statistics.median(y for _, y in pairs):.3f} s")


def whole_processes(runs: int) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
           "OPENBLAS_NUM_THREADS": "1"}
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # a user's run has its bytecode cached
    py = sys.executable
    with tempfile.TemporaryDirectory() as tmp:
        run = [py, "-m", "dolfinx_nnqem", "-q", "run", str(ROOT / "demos" / "two_beams.toml"), "--out",
               f"{tmp}/out", "--overwrite", "--no-pictures"]
        floor = [py, "-c", "import dolfinx_solver, dolfinx"]
        _time(run, env=env)  # warm caches (FFCx, bytecode)
        print(f"two beams, whole process / import floor:   {_ratios(lambda: _time(run, env=env), lambda: _time(floor, env=env), runs)}")
        help_ = [py, "-m", "dolfinx_nnqem", "--help"]
        print(f"--help / python -c pass:                     "
              f"{_ratios(lambda: _time(help_, env=env), lambda: _time([py, '-c', 'pass'], env=env), runs)}")
        ccx = shutil.which("ccx")
        if ccx is None:
            print("CalculiX (ccx) not installed: no comparison with it")
            return
        subprocess.run([py, str(ROOT / "benchmarks" / "calculix_two_beams.py"), tmp], check=True,
                       stdout=subprocess.DEVNULL)
        print(f"two beams, whole process / CalculiX 2.20:   "
              f"{_ratios(lambda: _time(run, env=env), lambda: _time([ccx, '-i', 'two_beams'], cwd=tmp), runs)}")


def _wall_and_cpu(cmd: list[str], env: dict) -> tuple[float, float]:
    """(wall s, CPU s) of ``cmd``: user + system of the process and of the children it waited for."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def picture_cost(runs: int) -> None:
    """What the five pictures add to the seed run: with − without, CPU and wall seconds."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
           "OPENBLAS_NUM_THREADS": "1"}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env.pop("DOLFINX_NNQEM_PICTURES", None)  # (a test environment turns them off)
    with tempfile.TemporaryDirectory() as tmp:
        run = [sys.executable, "-m", "dolfinx_nnqem", "-q", "run", str(ROOT / "demos" / "two_beams.toml"), "--out",
               f"{tmp}/out", "--overwrite"]
        _wall_and_cpu(run, env)  # warm caches (FFCx, bytecode, fonts, shaders)
        pairs = [(_wall_and_cpu(run, env), _wall_and_cpu([*run, "--no-pictures"], env)) for _ in range(runs)]
    for k, what in ((1, "CPU"), (0, "wall")):
        added = sorted(a[k] - b[k] for a, b in pairs)
        print(f"two beams, pictures added ({what}): {statistics.median(added):.2f} s ({added[0]:.2f}–{added[-1]:.2f}); "
              f"with {statistics.median(a[k] for a, _ in pairs):.2f} s, without "
              f"{statistics.median(b[k] for _, b in pairs):.2f} s (medians)")


def baseline_solve(n: int = 12) -> float:
    """Seconds for DOLFINx alone: assemble linear elasticity on an n³ hexahedral cube and solve it
    with MUMPS (the kind of work the package's iterations do)."""
    import dolfinx
    import dolfinx.fem.petsc
    import numpy as np
    import ufl
    from mpi4py import MPI
    from petsc4py import PETSc

    t0 = time.perf_counter()
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, n, n, n, dolfinx.mesh.CellType.hexahedron)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    eps = lambda w: ufl.sym(ufl.grad(w))  # noqa: E731
    a = dolfinx.fem.form(2.0 * ufl.inner(eps(u), eps(v)) * ufl.dx + ufl.div(u) * ufl.div(v) * ufl.dx)
    L = dolfinx.fem.form(ufl.inner(dolfinx.fem.Constant(mesh, np.array([0.0, -1.0, 0.0])), v) * ufl.dx)
    facets = dolfinx.mesh.locate_entities_boundary(mesh, 2, lambda x: np.isclose(x[0], 0.0))
    bc = dolfinx.fem.dirichletbc(np.zeros(3), dolfinx.fem.locate_dofs_topological(V, 2, facets), V)
    t0 = time.perf_counter()
    A = dolfinx.fem.petsc.assemble_matrix(a, bcs=[bc])
    A.assemble()
    b = dolfinx.fem.petsc.assemble_vector(L)
    ksp = PETSc.KSP().create(MPI.COMM_SELF)
    ksp.setOperators(A)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType("mumps")
    x = b.duplicate()
    ksp.solve(b, x)
    elapsed = time.perf_counter() - t0
    for obj in (ksp, A, b, x):
        obj.destroy()
    return elapsed


def iteration_costs(level: int, runs: int) -> None:
    """Seconds per Newton (outer) iteration of the three methods, against :func:`baseline_solve`."""
    import dolfinx_nnqem  # noqa: F401
    from mpi4py import MPI

    from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
    from dolfinx_nnqem.solvers import MonolithicOptions, SolverOptions, make_solver, solve_load_steps

    baseline_solve()  # JIT and caches
    cases = [("monolithic, iterative", level, {"monolithic": MonolithicOptions(linear_solver="iterative")}, 6),
             ("nneqm1", 2, {}, 6), ("nneqm2", 2, {}, 6)]
    for name, lvl, extra, increments in cases:
        counts = {}

        def one(lvl=lvl, extra=extra, name=name, increments=increments, counts=counts):
            problem = pressed_blocks_problem(lvl, MPI.COMM_WORLD)
            method = name.split(",")[0]
            with make_solver(method, problem, SolverOptions(max_iterations=40), **extra) as solver:
                t0 = time.perf_counter()
                results = solve_load_steps(problem, solver, increments)
                elapsed = time.perf_counter() - t0
                counts["newton"] = [r.iterations for r in results]
                counts["krylov"] = getattr(solver, "linear_iterations", None)
            return elapsed / max(sum(counts["newton"]), 1)

        ratio = _ratios(one, baseline_solve, runs)
        print(f"{name} (level {lvl}), s per iteration / baseline solve: {ratio}; iterations {counts['newton']}"
              + (f", Krylov {counts['krylov']}" if counts.get("krylov") else ""), flush=True)


def load_path_cost(level: int, runs: int) -> None:
    """The pressed blocks' whole load path with the iterative solver (the million-dof run's
    proxy, ``docs/performance.md``), against :func:`baseline_solve`, with its counts."""
    import dolfinx_nnqem  # noqa: F401
    from mpi4py import MPI

    from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
    from dolfinx_nnqem.solvers import MonolithicOptions, SolverOptions, make_solver, solve_load_steps

    counts: dict = {}

    def one() -> float:
        problem = pressed_blocks_problem(level, MPI.COMM_WORLD)
        with make_solver("monolithic", problem, SolverOptions(max_iterations=40),
                         monolithic=MonolithicOptions(linear_solver="iterative")) as solver:
            t0 = time.perf_counter()
            results = solve_load_steps(problem, solver, 6)
            elapsed = time.perf_counter() - t0
            counts.update(newton=[r.iterations for r in results], krylov=solver.linear_iterations,
                          amg=solver.amg_setups)
        return elapsed

    ratio = _ratios(one, baseline_solve, runs)
    print(f"monolithic, iterative, whole load path (level {level}) / baseline solve: {ratio}; iterations "
          f"{counts['newton']}, Krylov {counts['krylov']}, AMG set-ups {counts['amg']}", flush=True)


def sliding_ratio(n: int, runs: int) -> None:
    """NNEQM1 / monolithic on the sphere slid over an n³ block in the current geometry (the case ``slide``
    of ``benchmarks/large_sliding.py``, 10 increments), the two interleaved, with their counts."""
    import dolfinx_nnqem  # noqa: F401

    from dolfinx_nnqem.cases.large_sliding import sliding_sphere
    from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

    counts: dict = {}

    def one(method: str) -> float:
        problem = sliding_sphere(n, start=0.3, end=0.7, geometry="current")
        with make_solver(method, problem, SolverOptions(rtol=1e-10, max_iterations=40)) as solver:
            t0 = time.perf_counter()
            results = solve_load_steps(problem, solver, 10)
            elapsed = time.perf_counter() - t0
            condensation = getattr(solver, "condensation", None)
            counts[method] = (sum(r.iterations for r in results), sum(r.report.geometry_passes for r in results),
                              None if condensation is None else condensation.factorisations)
        return elapsed

    one("nneqm1")  # JIT and caches
    ratio = _ratios(lambda: one("nneqm1"), lambda: one("monolithic"), runs)
    (it_1, passes_1, factorisations), (it_m, passes_m, _) = counts["nneqm1"], counts["monolithic"]
    print(f"sphere slide (n = {n}, 10 increments), NNEQM1 / monolithic: {ratio}; NNEQM1 {it_1} outer iterations "
          f"in {passes_1} solves, {factorisations} factorisation(s); monolithic {it_m} iterations in {passes_m} solves",
          flush=True)


def sliding_iterations(n: int) -> None:
    """Newton iterations per increment of the block slides (node-to-surface and mortar, μ_f = 0 and
    0.3) against the rigid sphere's slide, monolithic solver, current geometry (counts: no ratio
    of times; the cases of ``benchmarks/large_sliding.py``)."""
    from large_sliding import run

    per_increment = {}
    for case in ("slide", "blocks", "blocks-friction", "mortar", "mortar-friction"):
        _, iterations = run(case, n, 2, "current", "monolithic", None, None)
        per_increment[case] = sum(iterations) / len(iterations) if iterations else float("nan")
    base = per_increment.pop("slide")
    print(f"Newton iterations per increment against the sphere slide (n = {n}, {base:.2f} per increment): "
          + ", ".join(f"{case} {value / base:.2f}" for case, value in per_increment.items()), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=5, help="pairs of runs per ratio (default 5)")
    parser.add_argument("--level", type=int, default=4, help="pressed-blocks level of the monolithic figure")
    parser.add_argument("--skip-processes", action="store_true", help="only the in-process figures")
    parser.add_argument("--proxy-level", type=int, default=6,
                        help="pressed-blocks level of the whole-load-path figure (the million-dof run's proxy)")
    parser.add_argument("--slide-n", type=int, default=8, help="block divisions of the sliding-sphere figure")
    args = parser.parse_args()
    print(f"figure: median of A/B over {args.runs} pairs (min–max)")
    if not args.skip_processes:
        whole_processes(args.runs)
        picture_cost(args.runs)
    iteration_costs(args.level, max(1, args.runs // 2))
    load_path_cost(args.proxy_level, max(1, args.runs // 2))
    sliding_ratio(args.slide_n, max(1, args.runs // 2))
    sliding_iterations(args.slide_n)


if __name__ == "__main__":
    main()
