"""What the degree-2 slides in the current geometry cost (issues 41 and 43): the monolithic solver
against NNEQM1 on the same slide, in one run.

The cases (``dolfinx_nnqem.cases.large_sliding.sliding_blocks``, Q2 hexahedra, slid 0.4):

* ``mortar-q2``: dual mortar of degree 2, μ_f = 0.3, 2 × 1 × 2 lower and 3 × 1 × 3 upper cells,
  pressed 0.01, 8 increments (``tests/integration/test_large_sliding_mortar_degree2.py``);
* ``nts-q2``: node-to-surface of degree 2, frictionless, 12 increments
  (``tests/integration/test_large_sliding_nts_degree2.py``).

Per case and method it prints the CPU and wall seconds of the load stepping (the solver made before
the clock starts; numba keeps its kernels on disk, so take the figures of a second run after an
edit of a kernel), the seconds per increment, the Newton iterations per
increment, the solves, and the re-evaluations of the surface pairs: at the Newton iterates
(``refresh_surfaces``: the monolithic solver, with the derivatives its Newton matrix takes) and
between solves (the trackers' ``pairs_at``), their count and CPU seconds each; then the ratios
monolithic / NNEQM1. CPU seconds are ``time.process_time`` (the machine may be shared: wall
seconds are printed too). With ``--save DIR`` every run's displacements and pair forces go to
``DIR/<case>-<method>.npz`` (the pair forces by slave node); ``--compare DIR`` prints the largest
differences from such a run::

    OPENBLAS_NUM_THREADS=1 python benchmarks/degree2_slides.py [--cases mortar-q2,nts-q2]
        [--methods monolithic,nneqm1] [--save DIR] [--compare DIR]
"""

from __future__ import annotations

import argparse
import pathlib
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
from dolfinx_nnqem.cases.large_sliding import slave_force, sliding_blocks
from dolfinx_nnqem.contact import current_geometry, geometry_tracking
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

CASES: dict[str, tuple[Callable[[], object], int]] = {
    "mortar-q2": (lambda: sliding_blocks(slide=0.4, mu_f=0.3, discretisation="mortar", degree=2,
                                         divisions=((2, 1, 2), (3, 1, 3)), geometry="current", depth=0.01), 8),
    "nts-q2": (lambda: sliding_blocks(slide=0.4, degree=2), 12),
}


@dataclass
class Clock:
    """Calls and CPU seconds of the functions :func:`timed` wraps, by name."""

    calls: dict[str, int] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)

    def line(self, name: str) -> str:
        n = self.calls.get(name, 0)
        return f"{n} × {self.seconds[name] / n:.3f} s" if n else "none"


def timed(clock: Clock, name: str, function: Callable) -> Callable:
    """``function`` counting its calls and CPU seconds in ``clock`` under ``name``."""
    def wrapper(*args, **kwargs):
        t0 = time.process_time()
        try:
            return function(*args, **kwargs)
        finally:
            clock.calls[name] = clock.calls.get(name, 0) + 1
            clock.seconds[name] = clock.seconds.get(name, 0.0) + time.process_time() - t0
    return wrapper


def instrument(clock: Clock) -> None:
    """Time the re-evaluations at the iterates (mortar and node-to-surface) and between solves."""
    geometry_tracking._remortared = timed(clock, "iterate", geometry_tracking._remortared)
    geometry_tracking._reprojected = timed(clock, "iterate", geometry_tracking._reprojected)
    for tracker in (current_geometry.MortarTracker, current_geometry.SurfaceTracker):
        tracker.pairs_at = timed(clock, "between", tracker.pairs_at)


def run(case: str, method: str, clock: Clock) -> dict:
    """One slide; its figures and end state."""
    make, increments = CASES[case]
    problem = make()
    clock.calls.clear()
    clock.seconds.clear()
    with make_solver(method, problem, SolverOptions(rtol=1e-10, max_iterations=40)) as solver:
        cpu, wall = time.process_time(), time.perf_counter()
        results = solve_load_steps(problem, solver, increments)
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    iterations = [r.iterations for r in results]
    print(f"{case:10s} {method:10s} {cpu:7.1f} s CPU ({wall:6.1f} s wall), {cpu / len(results):.2f} s per "
          f"increment; Newton {sum(iterations)} {iterations}; solves {sum(r.report.geometry_passes for r in results)}; "
          f"re-evaluations at iterates {clock.line('iterate')}, between solves {clock.line('between')}", flush=True)
    blocks = np.concatenate([interface.pairs.slave_blocks for interface in problem.contact.interfaces])
    order = np.argsort(blocks, kind="stable")  # pairs added between solves may come in another order
    return {"cpu": cpu, "iterations": sum(iterations), "u": problem.u.x.array.copy(),
            "lam": problem.contact.force()[order], "force": slave_force(problem),
            "iterate": clock.seconds.get("iterate", 0.0) / max(clock.calls.get("iterate", 0), 1)}


def differences(state: dict, before: dict) -> str:
    """The largest differences from a saved run, relative to the largest values."""
    du = np.abs(state["u"] - before["u"]).max() / np.abs(before["u"]).max()
    df = np.linalg.norm(state["force"] - before["force"]) / np.linalg.norm(before["force"])
    dlam = (np.abs(state["lam"] - before["lam"]).max() / np.abs(before["lam"]).max()
            if state["lam"].shape == before["lam"].shape else float("nan"))
    return f"max|Δu|/max|u| = {du:.1e}, |ΔF|/|F| = {df:.1e}, max|Δλ|/max|λ| = {dlam:.1e}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="mortar-q2,nts-q2")
    parser.add_argument("--methods", default="monolithic,nneqm1")
    parser.add_argument("--save", type=pathlib.Path)
    parser.add_argument("--compare", type=pathlib.Path)
    args = parser.parse_args()
    clock = Clock()
    instrument(clock)
    for case in args.cases.split(","):
        runs = {}
        for method in args.methods.split(","):
            runs[method] = state = run(case, method, clock)
            name = f"{case}-{method}.npz"
            if args.save is not None:
                args.save.mkdir(parents=True, exist_ok=True)
                np.savez(args.save / name, **{k: state[k] for k in ("u", "lam", "force")})
            if args.compare is not None and (args.compare / name).exists():
                print(f"  vs {args.compare / name}: {differences(state, dict(np.load(args.compare / name)))}")
        if {"monolithic", "nneqm1"} <= runs.keys():
            mono, nneqm1 = runs["monolithic"], runs["nneqm1"]
            print(f"{case}: monolithic / NNEQM1 = {mono['cpu'] / nneqm1['cpu']:.2f} (CPU), Newton iterations "
                  f"{mono['iterations']} / {nneqm1['iterations']}; a re-evaluation at an iterate (monolithic) "
                  f"{mono['iterate']:.3f} s", flush=True)


if __name__ == "__main__":
    main()
