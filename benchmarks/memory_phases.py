"""Where the pressed blocks' run peaks in memory: the resident size of each phase of the load path.

    mpiexec -n 2 python benchmarks/memory_phases.py --level 10
    mpiexec -n 2 python benchmarks/memory_phases.py --level 8 --json phases.json

The run of ``benchmarks/scaling.py`` (6 increments, the monolithic solver, the iterative linear
solver by default) with its phases wrapped: the increment's solve, the tangent and internal-force
assemblies, the augmented system, the linear solve (split by a Krylov monitor into the set-up
before the first iteration, the AMG set-up among it, and the iterations), the Gauss-point
values to commit, the independent check and its parts, the commit. At every phase boundary the
process's resident high-water mark (``VmHWM``) is read and reset (``/proc/self/clear_refs``),
so a phase's peak is the highest resident size while it was open. Per rank it prints, for each
phase, its calls, its peak, the resident size when the call that peaked began, and its largest
rise over its start; then the phases open at the run's peak, and glibc's heap after each
increment (in use, free but resident, mmapped; ``mallinfo2``). Linux only; asserts nothing.
PETSc's own memory is not broken down here (``-malloc_view`` does that, slowly).
"""

from __future__ import annotations

import argparse
import ctypes
import functools
import json
import sys
import time
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
from mpi4py import MPI

from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
from dolfinx_nnqem.problem import contact_problem
from dolfinx_nnqem.solvers import MonolithicOptions, SolverOptions, checks, linear_solver, monolithic, stepping
from dolfinx_nnqem.solvers import solve_load_steps
from dolfinx_nnqem.solvers.monolithic import MonolithicSolver

MB = 1024.0


def resident() -> dict[str, float]:
    """VmRSS and VmHWM of this process, MB."""
    out = {}
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(("VmRSS", "VmHWM")):
            key, value = line.split(":")
            out[key] = int(value.split()[0]) / MB
    return out


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                                     "fsmblks", "uordblks", "fordblks", "keepcost")]


def heap() -> dict[str, float]:
    """glibc's main heap: in use, free but resident, mmapped blocks (MB); {} without glibc."""
    mallinfo2 = getattr(ctypes.CDLL(None), "mallinfo2", None)
    if mallinfo2 is None:
        return {}
    mallinfo2.restype = _MallInfo2
    info = mallinfo2()
    return {"in_use": info.uordblks / MB / MB, "free": info.fordblks / MB / MB, "mmapped": info.hblkhd / MB / MB}


class PhaseMemory:
    """The peak resident size of every wrapped phase (nested phases each see their own)."""

    def __init__(self):
        self.open: list[list] = []  # [name, peak so far, resident at entry]
        self.phases: dict[str, dict] = {}
        self.peak = {"MB": 0.0, "phases": []}

    def fold(self) -> None:
        """The high-water mark since the last boundary, into every open phase; then reset it."""
        hwm = resident()["VmHWM"]
        for entry in self.open:
            entry[1] = max(entry[1], hwm)
        if hwm > self.peak["MB"]:
            self.peak = {"MB": hwm, "phases": [entry[0] for entry in self.open]}
        Path("/proc/self/clear_refs").write_text("5")

    def enter(self, name: str) -> None:
        self.fold()
        rss = resident()["VmRSS"]
        self.open.append([name, rss, rss])

    def leave(self) -> None:
        self.fold()
        name, peak, start = self.open.pop()
        phase = self.phases.setdefault(name, {"calls": 0, "peak": 0.0, "start_at_peak": 0.0, "largest_rise": 0.0})
        phase["calls"] += 1
        phase["largest_rise"] = max(phase["largest_rise"], peak - start)
        if peak > phase["peak"]:
            phase.update(peak=peak, start_at_peak=start)

    def rename(self, name: str) -> None:
        """The innermost open phase goes on under another name (the set-up becomes the iterations)."""
        self.leave()
        rss = resident()["VmRSS"]
        self.open.append([name, rss, rss])

    def wrap(self, owner, attribute: str, name: str) -> None:
        function = getattr(owner, attribute)

        @functools.wraps(function)
        def wrapped(*args, **kwargs):
            self.enter(name)
            try:
                return function(*args, **kwargs)
            finally:
                self.leave()

        setattr(owner, attribute, wrapped)


PHASES = [
    (stepping, "_solve", "increment: solve"),
    (stepping, "values_to_commit", "increment: values to commit"),
    (stepping, "check_state", "increment: check"),
    (stepping, "_commit", "increment: commit"),
    (checks, "_equilibrium", "check: equilibrium"),
    (checks, "_law", "check: constitutive law"),
    (checks, "_contact_law", "check: contact law"),
    (checks, "_shape", "check: strain and rotation"),
    (monolithic.MonolithicSolver, "evaluate", "Newton: residual"),
    (monolithic.MonolithicSolver, "_augmented_system", "Newton: augmented system"),
    (contact_problem.ContactProblem, "assemble_tangent", "Newton: tangent assembly"),
    (linear_solver.IterativeSolver, "solve", "Newton: linear solve"),
]


def watch(memory: PhaseMemory) -> None:
    """Wrap the phases, and split each Krylov solve at its first iteration (a KSP monitor)."""
    for owner, attribute, name in PHASES:
        memory.wrap(owner, attribute, name)
    krylov_solve = linear_solver.IterativeSolver._krylov_solve

    def monitor(ksp, iteration, residual_norm):
        if iteration == 0:
            memory.rename("Krylov: iterations")

    def watched(self, b, x, pair_state):
        if not getattr(self, "_memory_monitor", False):
            self.ksp.setMonitor(monitor)
            self._memory_monitor = True
        memory.enter("Krylov: set-up (AMG) to the first iteration")
        try:
            return krylov_solve(self, b, x, pair_state)
        finally:
            memory.leave()

    linear_solver.IterativeSolver._krylov_solve = watched


def run(level: int, linear_solver_name: str, increments: int, comm) -> dict:
    """The load path at ``level`` with its phases watched; this rank's figures."""
    warm = pressed_blocks_problem(1, comm)  # JIT warm-up, as benchmarks/scaling.py does
    with MonolithicSolver(warm, monolithic=MonolithicOptions(linear_solver=linear_solver_name)) as solver:
        solve_load_steps(warm, solver, 1, final_load_factor=1.0 / increments)
    del warm
    memory = PhaseMemory()
    watch(memory)
    problem = pressed_blocks_problem(level, comm)
    built = resident()["VmRSS"]
    heaps: list[dict] = []
    solver = MonolithicSolver(problem, SolverOptions(max_iterations=40),
                              MonolithicOptions(linear_solver=linear_solver_name))
    t0 = time.perf_counter()
    results = solve_load_steps(problem, solver, increments,
                               callbacks=[lambda r: heaps.append({"rss": resident()["VmRSS"], **heap()})])
    memory.fold()
    return {"rank": comm.rank, "built_MB": built, "peak": memory.peak, "phases": memory.phases, "heap": heaps,
            "newton": [r.iterations for r in results], "krylov": solver.linear_iterations,
            "amg_setups": solver.amg_setups, "wall_s": time.perf_counter() - t0}


def report(figures: dict) -> None:
    print(f"rank {figures['rank']}: after the build {figures['built_MB']:.0f} MB; peak {figures['peak']['MB']:.0f} MB in "
          f"{' > '.join(figures['peak']['phases']) or '(between phases)'}; Newton {figures['newton']}, "
          f"Krylov {figures['krylov']}, AMG set-ups {figures['amg_setups']}")
    print(f"  {'phase':46s} {'calls':>5s} {'peak':>6s} {'start':>6s} {'rise':>6s}  (MB; start: of the call that peaked)")
    for name, p in sorted(figures["phases"].items(), key=lambda item: -item[1]["peak"]):
        print(f"  {name:46s} {p['calls']:5d} {p['peak']:6.0f} {p['start_at_peak']:6.0f} {p['largest_rise']:6.0f}")
    for k, h in enumerate(figures["heap"], start=1):
        print(f"  after increment {k}: resident {h['rss']:.0f} MB; heap in use {h.get('in_use', 0):.0f}, "
              f"free {h.get('free', 0):.0f}, mmapped {h.get('mmapped', 0):.0f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--level", type=int, default=8)
    parser.add_argument("--linear-solver", default="iterative", choices=("iterative", "direct"))
    parser.add_argument("--increments", type=int, default=6)
    parser.add_argument("--json", help="write every rank's figures to this file")
    args = parser.parse_args()
    if not Path("/proc/self/clear_refs").exists():
        sys.exit("memory_phases.py reads /proc/self/status and resets /proc/self/clear_refs: Linux only")
    comm = MPI.COMM_WORLD
    every = comm.gather(run(args.level, args.linear_solver, args.increments, comm))
    if comm.rank == 0:
        for figures in every:
            report(figures)
        if args.json:
            Path(args.json).write_text(json.dumps(every, indent=1))


if __name__ == "__main__":
    main()
