"""A parameter study of the seed's two beams in one process against as many CalculiX runs (issue 43).

Twenty variants: the friction coefficient μ_f from 0.0 to 0.5. Ours: the problem is built once
(mesh, forms, compiles), then for each variant ``problem.update(mu_f=μ)``, a new solver and the
15 increments, with every output of a command-line run written (summary, fields with the
recovery indicator, pair tables; no pictures) into a folder of its own. CalculiX 2.20: the model of
``benchmarks/calculix_two_beams.py`` with the variant's μ (no ``*FRICTION`` for μ = 0), one
``ccx`` process per variant, with its default outputs (.frd, .dat, .sta).

The two alternate, variant by variant, so that both see the same load of the machine. Prints the
wall time per variant of both, the ratio, their CPU time per variant (ours: the process's;
CalculiX's: the child's user and system time; on a shared machine the fairer comparison), our
set-up (import and build, once per study) and the compiles of the variants after the first
(counted in ``dolfinx_nnqem.jit``). The issue's
target: at most 0.3 × CalculiX per variant. Figures: ``docs/performance.md``.

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/parameter_study.py OUTDIR [--variants 20] [--method monolithic]
"""

from __future__ import annotations

import time

T_START = time.perf_counter()

import argparse  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import dolfinx_nnqem  # noqa: E402, F401  (before dolfinx)
from dolfinx_nnqem import jit  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calculix_two_beams as ccx_model  # noqa: E402


def calculix_text(mu_f: float) -> str:
    """The CalculiX model with friction coefficient ``mu_f`` (frictionless: no ``*FRICTION``)."""
    lines = ccx_model.model_text().splitlines()
    k = lines.index("*FRICTION")
    if mu_f == 0.0:
        del lines[k:k + 2]
    else:
        lines[k + 1] = f"{mu_f}, {ccx_model.STICK_SLOPE:.6e}"
    return "\n".join(lines) + "\n"


def children_cpu() -> float:
    """CPU seconds (user and system) of the finished child processes so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_calculix_variant(folder: Path, k: int, mu_f: float) -> tuple[float, float]:
    """Wall and CPU time of one ``ccx`` process on variant ``k`` (the whole process, its outputs written)."""
    ccx = shutil.which("ccx")
    if ccx is None:
        raise SystemExit("no ccx on PATH (Debian: apt-get install calculix-ccx)")
    work = folder / f"ccx_{k:02d}"
    work.mkdir(parents=True, exist_ok=True)
    (work / "two_beams.inp").write_text(calculix_text(mu_f))
    t0, c0 = time.perf_counter(), children_cpu()
    subprocess.run([ccx, "-i", "two_beams"], cwd=work, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0, children_cpu() - c0


class Study:
    """Our side: the problem built once, then one variant per :meth:`variant` call."""

    def __init__(self, folder: Path, method: str):
        from dolfinx_nnqem.cases.two_beams import DEFAULT_LAW, two_beams_problem
        from dolfinx_nnqem.estimates import RecoveryIndicator

        self.folder, self.method = folder, method
        self.count = [0]
        original = jit._compile

        def counting(make, expr):
            self.count[0] += 1
            return original(make, expr)

        jit._compile = counting  # every form and expression compile of the package goes through it
        self.problem = two_beams_problem(law=DEFAULT_LAW[method])
        self.indicator = RecoveryIndicator(self.problem)
        self.setup = time.perf_counter() - T_START

    def variant(self, k: int, mu_f: float) -> tuple[float, float, int, float]:
        """Wall and CPU time, compiles and total normal contact force of variant ``k`` (μ_f = ``mu_f``)."""
        from dolfinx_nnqem.cases.two_beams import FREE_END_CORNERS
        from dolfinx_nnqem.io.output import ResultsWriter
        from dolfinx_nnqem.solvers.registry import make_solver
        from dolfinx_nnqem.solvers.stepping import solve_load_steps

        problem = self.problem
        self.count[0] = 0
        t0, c0 = time.perf_counter(), time.process_time()
        problem.update(mu_f=mu_f)
        writer = ResultsWriter(problem, self.method, self.folder / f"ours_{k:02d}", 15, probes=FREE_END_CORNERS,
                               extra={"mu_f": mu_f}, pictures=False, cell_fields=[self.indicator])
        with make_solver(self.method, problem) as solver:
            solve_load_steps(problem, solver, 15, callbacks=[writer])
        writer.close()
        elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
        assert problem.contact is not None
        normal = float(problem.comm.allreduce(np.sum(problem.contact.force()[:, 0])))
        return elapsed, cpu, self.count[0], normal


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("outdir", help="where the variants' outputs go")
    parser.add_argument("--variants", type=int, default=20)
    parser.add_argument("--method", default="monolithic", choices=("monolithic", "nneqm1", "nneqm2"))
    args = parser.parse_args(argv)
    folder = Path(args.outdir)
    mu_values = np.linspace(0.0, 0.5, args.variants)
    study = Study(folder, args.method)
    ours, theirs, ours_cpu, theirs_cpu, compiles, normal = [], [], [], [], [], []
    for k, mu in enumerate(mu_values):  # alternated, so that both see the same load of the machine
        elapsed, cpu, count, force = study.variant(k, float(mu))
        ours.append(elapsed)
        ours_cpu.append(cpu)
        compiles.append(count)
        normal.append(force)
        wall, cpu = run_calculix_variant(folder, k, float(mu))
        theirs.append(wall)
        theirs_cpu.append(cpu)
    setup = study.setup
    n = args.variants
    print(f"{n} variants of the two beams, mu_f = {mu_values[0]:g} ... {mu_values[-1]:g}, method {args.method}")
    print(f"ours:     set-up {setup:.3f} s once (imports, mesh, forms, compiles), then per variant "
          f"median {np.median(ours):.3f} s (min {min(ours):.3f}, max {max(ours):.3f}); first {ours[0]:.3f} s")
    print(f"CalculiX: per variant median {np.median(theirs):.3f} s (min {min(theirs):.3f}, max {max(theirs):.3f})")
    print(f"ratio per variant (medians): {np.median(ours) / np.median(theirs):.3f}; with our set-up shared by the "
          f"{n} variants: {(setup + sum(ours)) / sum(theirs):.3f}")
    print(f"CPU per variant (medians): ours {np.median(ours_cpu):.3f} s, CalculiX {np.median(theirs_cpu):.3f} s, "
          f"ratio {np.median(ours_cpu) / np.median(theirs_cpu):.3f}")
    print(f"compiles per variant after the first: {compiles[1:]}")
    print("total normal contact force (N) per mu_f: "
          + ", ".join(f"{mu:.3f}: {f:.1f}" for mu, f in zip(mu_values, normal)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
