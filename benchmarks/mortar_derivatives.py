"""What the couple derivatives of the degree-1 mortar linearisation cost and change (issues 41 and 43):
the complex step against the central differences it replaced, in one process, alternated.

The case: the degree-1 mortar block slide of ``tests/integration/test_large_sliding_mortar_consistent.py``
(``cases.large_sliding.sliding_blocks(slide=0.4, mu_f=0.3, discretisation="mortar")``, the monolithic
solver with its direct linear solver, rtol 1e-10, 12 increments), with each law. The variants:

* ``complex-step``: :func:`~dolfinx_nnqem.contact.couple_complex_step.couple_derivatives` (what
  :mod:`~dolfinx_nnqem.contact.mortar_linearisation` takes);
* ``differences``: :func:`~dolfinx_nnqem.contact.mortar_linearisation.couple_differences`, the central
  differences with step ``DIFFERENCE_STEP`` × the facet size (what it took before).

Per law, round and variant it prints the CPU seconds of the load stepping (``time.process_time``; the
solver made before the clock starts; numba keeps its kernels on disk, so take the figures of a
second run after an edit of a kernel), the Newton iterations per increment, the mortar
re-evaluations at the iterates (count and CPU seconds each) and the CPU seconds inside the couple
derivatives; then the ratios complex-step / differences (sums over the rounds), the residual
sequence max(|R|, |H|)/F of the first solve of every sliding increment in both variants, and the
largest differences of the end states (u, the pair forces, the slave body's force)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/mortar_derivatives.py [--laws alart-curnier,polar] [--rounds 2]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
from dolfinx_nnqem.cases.large_sliding import PRESSED_AT, slave_force, sliding_blocks
from dolfinx_nnqem.contact import geometry_tracking, mortar_linearisation
from dolfinx_nnqem.contact.couple_complex_step import couple_derivatives
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

VARIANTS = ("differences", "complex-step")


def _differences(xs, xm, ci, cj, step, *args):
    """The central differences with the step the linearisation took before (``step`` is the complex step's)."""
    return mortar_linearisation.couple_differences(
        xs, xm, ci, cj, step / mortar_linearisation.STEP * mortar_linearisation.DIFFERENCE_STEP, *args)


class Clock:
    """Calls and CPU seconds of the wrapped functions, by name."""

    def __init__(self) -> None:
        self.calls: dict[str, int] = {}
        self.seconds: dict[str, float] = {}

    def timed(self, name: str, function: Callable) -> Callable:
        def wrapper(*args, **kwargs):
            t0 = time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                self.calls[name] = self.calls.get(name, 0) + 1
                self.seconds[name] = self.seconds.get(name, 0.0) + time.process_time() - t0
        return wrapper


def run(law: str, variant: str, clock: Clock) -> dict:
    """One slide with the couple derivatives of ``variant``; its figures and end state."""
    mortar_linearisation.couple_derivatives = clock.timed("derivatives", couple_derivatives if variant == "complex-step"
                                                          else _differences)
    clock.calls.clear()
    clock.seconds.clear()
    problem = sliding_blocks(slide=0.4, mu_f=0.3, law=law, discretisation="mortar")
    reports: list = []
    with make_solver("monolithic", problem, SolverOptions(rtol=1e-10, max_iterations=40)) as solver:
        solve_increment = solver.solve_increment

        def recording(load_factor):
            report = solve_increment(load_factor)
            reports.append((load_factor, report))
            return report

        solver.solve_increment = recording
        cpu = time.process_time()
        results = solve_load_steps(problem, solver, 12)
        cpu = time.process_time() - cpu
    iterations = [r.iterations for r in results]
    n = clock.calls.get("iterate", 0)
    print(f"{law:13s} {variant:13s} {cpu:6.2f} s CPU; Newton {sum(iterations)} {iterations}; re-evaluations at "
          f"iterates {n} × {clock.seconds.get('iterate', 0.0) / max(n, 1):.4f} s, of which the couple derivatives "
          f"{clock.seconds.get('derivatives', 0.0) / max(n, 1):.4f} s", flush=True)
    first: dict[float, list[float]] = {}
    for load_factor, report in reports:
        if load_factor > PRESSED_AT and load_factor not in first:
            first[load_factor] = [max(r.equilibrium, r.contact) for r in report.history]
    blocks = np.concatenate([interface.pairs.slave_blocks for interface in problem.contact.interfaces])
    order = np.argsort(blocks, kind="stable")
    return {"cpu": cpu, "iterate": clock.seconds.get("iterate", 0.0), "iterates": n,
            "derivatives": clock.seconds.get("derivatives", 0.0), "iterations": sum(iterations), "residuals": first,
            "u": problem.u.x.array.copy(), "lam": problem.contact.force()[order], "force": slave_force(problem)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--laws", default="alart-curnier,polar")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    clock = Clock()
    geometry_tracking._remortared = clock.timed("iterate", geometry_tracking._remortared)
    for law in args.laws.split(","):
        runs: dict[str, list[dict]] = {variant: [] for variant in VARIANTS}
        for r in range(args.rounds):
            for variant in (VARIANTS if r % 2 == 0 else VARIANTS[::-1]):
                runs[variant].append(run(law, variant, clock))
        new, old = runs["complex-step"], runs["differences"]

        def ratio(key: str) -> float:
            return sum(s[key] for s in new) / sum(s[key] for s in old)

        print(f"{law}: complex-step / differences (CPU, {args.rounds} rounds): slide {ratio('cpu'):.2f}, "
              f"re-evaluations at iterates {ratio('iterate'):.2f}, couple derivatives {ratio('derivatives'):.2f}; "
              f"re-evaluations per iterate {sum(s['iterate'] for s in new) / sum(s['iterates'] for s in new):.4f} s / "
              f"{sum(s['iterate'] for s in old) / sum(s['iterates'] for s in old):.4f} s; Newton iterations "
              f"{new[0]['iterations']} / {old[0]['iterations']}")
        for load_factor in new[0]["residuals"]:
            print(f"  ℓ = {load_factor:.4f}: max(|R|, |H|)/F complex step "
                  f"{', '.join(f'{e:.1e}' for e in new[0]['residuals'][load_factor])}; differences "
                  f"{', '.join(f'{e:.1e}' for e in old[0]['residuals'].get(load_factor, []))}")
        a, b = new[0], old[0]
        dlam = (np.abs(a["lam"] - b["lam"]).max() / np.abs(b["lam"]).max() if a["lam"].shape == b["lam"].shape
                else float("nan"))
        print(f"  end states: max|Δu|/max|u| = {np.abs(a['u'] - b['u']).max() / np.abs(b['u']).max():.1e}, "
              f"max|Δλ|/max|λ| = {dlam:.1e}, |ΔF|/|F| = "
              f"{np.linalg.norm(a['force'] - b['force']) / np.linalg.norm(b['force']):.1e}", flush=True)


if __name__ == "__main__":
    main()
