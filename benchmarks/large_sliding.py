"""What the current contact geometry costs (issue 27): Newton iterations, solves and seconds.

The cases (``dolfinx_nnqem.cases.large_sliding``):

* ``press``: the sphere pressed in place (``sliding_sphere`` with start = end, n³ hexahedra,
  ``increments`` increments), reference and current geometry;
* ``slide``: the issue's slide (0.3 -> 0.7, 5 × ``increments`` increments), current geometry (the
  reference one cannot finish it);
* ``blocks``, ``blocks-friction``: the upper block slid 1.6 master facets over the lower one
  (node-to-surface, 12 increments), μ_f = 0 and 0.3;
* ``mortar``, ``mortar-friction``: the same slide with dual mortar pairs;
* ``blocks-fine``, ``blocks-friction-fine``: the node-to-surface slides in the ``slide``'s load
  stepping (5 × ``increments`` increments, a quarter of them pressing): per increment the same
  steps of the load path as the rigid obstacle's slide it is compared with;
* ``ironing``: the cylinder dragged 8 facets over the elastoplastic strip (nx = 16, 40 increments,
  μ_f = 0.1).

``--methods`` takes monolithic, nneqm1 and nneqm2 (NNEQM2 follows the current geometry since
issue 41; its "Newton iterations" are those of its nonsmooth system of the pairs and the Gauss
points' rows). Prints Newton iterations, solves and seconds per case (and per increment), and at the end the Newton iterations per
increment of every case against the rigid obstacle's slide (``slide``) of the same method (issue 43:
node-to-surface and mortar slides at most 1.5 times as many); asserts nothing.
``--linearisations frozen,consistent`` runs the monolithic solver with the geometry frozen within a
solve (``consistent_geometry=False``: the earlier behaviour) and consistent (the default), in the
same run. With ``--save DIR`` every
case's displacements, pair forces and contact force go to ``DIR/<method>-<case>-<geometry>.npz``,
and ``--compare DIR`` prints the largest differences from such a saved run (before/after a change
of the solver: the converged states must agree to the solver's tolerance)::

    python benchmarks/large_sliding.py [--n 8] [--increments 4] [--methods monolithic,nneqm1,nneqm2]
                                       [--cases press,slide,blocks,blocks-friction,mortar,mortar-friction,
                                                blocks-fine,blocks-friction-fine,ironing]
                                       [--rtol 1e-10] [--linearisations consistent] [--frozen]
                                       [--save DIR] [--compare DIR]
"""

from __future__ import annotations

import argparse
import pathlib
import time
from collections.abc import Callable

import numpy as np

from dolfinx_nnqem.cases.large_sliding import (PRESSED_AT, ironing, obstacle_force, slave_force, sliding_blocks,
                                               sliding_sphere)
from dolfinx_nnqem.solvers import ConvergenceError, MonolithicOptions, SolverOptions, make_solver, solve_load_steps

CASES = ("press", "slide", "blocks", "blocks-friction", "mortar", "mortar-friction", "blocks-fine",
         "blocks-friction-fine", "ironing")


def _cases(n: int, increments: int) -> dict[str, tuple[Callable[[str], object], int, Callable]]:
    """Per case: (problem of a geometry, increments, the resultant contact force on the body)."""
    return {
        "press": (lambda g: sliding_sphere(n, start=0.3, end=0.3, geometry=g), increments, obstacle_force),
        "slide": (lambda g: sliding_sphere(n, start=0.3, end=0.7, geometry=g), 5 * increments, obstacle_force),
        "blocks": (lambda g: sliding_blocks(slide=0.4, geometry=g), 12, slave_force),
        "blocks-friction": (lambda g: sliding_blocks(slide=0.4, mu_f=0.3, geometry=g), 12, slave_force),
        "mortar": (lambda g: sliding_blocks(slide=0.4, geometry=g, discretisation="mortar"), 12, slave_force),
        "mortar-friction": (lambda g: sliding_blocks(slide=0.4, mu_f=0.3, geometry=g, discretisation="mortar"), 12,
                            slave_force),
        "blocks-fine": (lambda g: sliding_blocks(slide=0.4, geometry=g), 5 * increments, slave_force),
        "blocks-friction-fine": (lambda g: sliding_blocks(slide=0.4, mu_f=0.3, geometry=g), 5 * increments,
                                 slave_force),
        "ironing": (lambda g: ironing(16), 40, obstacle_force),
    }


def run(case: str, n: int, increments: int, geometry: str, method: str, save: pathlib.Path | None,
        compare: pathlib.Path | None, rtol: float = 1e-10, consistent: bool = True) -> tuple[str, list[int]]:
    """One case solved; its figures as a line (and its state saved or compared), and its Newton
    iterations per increment (empty if it failed)."""
    make, steps, force_of = _cases(n, increments)[case]
    problem = make(geometry)
    final = PRESSED_AT if case == "press" else 1.0
    t0 = time.perf_counter()
    try:
        settings = {"monolithic": MonolithicOptions(consistent_geometry=consistent)} if method == "monolithic" else {}
        with make_solver(method, problem, SolverOptions(rtol=rtol, max_iterations=40), **settings) as solver:
            results = solve_load_steps(problem, solver, steps, final_load_factor=final)
    except ConvergenceError as error:
        return f"failed: {str(error).splitlines()[0][:90]}... ({time.perf_counter() - t0:.2f} s)", []
    seconds = time.perf_counter() - t0
    model = problem.contact
    assert model is not None
    iterations = [r.iterations for r in results]
    solves = [r.report.geometry_passes for r in results]
    force = force_of(problem)
    line = (f"{len(results)} increments, {sum(iterations)} Newton iterations, {sum(solves)} solves, "
            f"{seconds:.2f} s ({seconds / len(results):.3f} s per increment); "
            f"F = {np.array2string(force, precision=9)}; per increment {iterations}")
    state = {"u": problem.u.x.array.copy(), "lam": model.force(), "force": force,
             "load_factors": np.array([r.load_factor for r in results])}
    name = f"{method}-{case}-{geometry}{'' if consistent else '-frozen'}.npz"
    if save is not None:
        save.mkdir(parents=True, exist_ok=True)
        np.savez(save / name, **state)
    if compare is not None and (compare / name).exists():
        line += "; " + _differences(state, dict(np.load(compare / name)))
    return line, iterations


def _differences(state: dict, before: dict) -> str:
    """The largest differences from a saved run, relative to the largest values."""
    if before["load_factors"].shape != state["load_factors"].shape or not np.allclose(
            before["load_factors"], state["load_factors"], rtol=0, atol=1e-14):
        return "another load path than the saved run"
    du = np.abs(state["u"] - before["u"]).max() / np.abs(before["u"]).max()
    df = np.linalg.norm(state["force"] - before["force"]) / np.linalg.norm(before["force"])
    dlam = (np.abs(state["lam"] - before["lam"]).max() / np.abs(before["lam"]).max()
            if state["lam"].shape == before["lam"].shape else float("nan"))
    return f"vs saved: max|Δu|/max|u| = {du:.1e}, |ΔF|/|F| = {df:.1e}, max|Δλ|/max|λ| = {dlam:.1e}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=8)
    parser.add_argument("--increments", type=int, default=4)
    parser.add_argument("--methods", default="monolithic,nneqm1")
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--rtol", type=float, default=1e-10)
    parser.add_argument("--linearisations", default="consistent",
                        help="monolithic: 'consistent' (the geometry re-evaluated at every Newton iterate, its "
                             "derivatives in J), 'frozen' (within a solve: consistent_geometry=False), or both")
    parser.add_argument("--frozen", action="store_true", help="the same as --linearisations frozen")
    parser.add_argument("--save", type=pathlib.Path)
    parser.add_argument("--compare", type=pathlib.Path)
    args = parser.parse_args()
    linearisations = ["frozen"] if args.frozen else args.linearisations.split(",")
    per_increment: dict[tuple[str, str, str], float] = {}
    for method in args.methods.split(","):
        for linearisation in (linearisations if method == "monolithic" else ["frozen"]):
            label = f"{method}/{linearisation}" if method == "monolithic" else method
            for case in args.cases.split(","):
                geometries = ("reference", "current") if case == "press" else ("current",)
                for geometry in geometries:
                    line, iterations = run(case, args.n, args.increments, geometry, method, args.save, args.compare,
                                           args.rtol, linearisation == "consistent")
                    print(f"{label:21s} {case:16s} {geometry:9s}: {line}", flush=True)
                    if iterations and geometry == "current":
                        per_increment[(label, case, geometry)] = sum(iterations) / len(iterations)
    _print_ratios(per_increment)


def _print_ratios(per_increment: dict[tuple[str, str, str], float]) -> None:
    """Newton iterations per increment of every case, and against the obstacle slide of the same solver."""
    print("\nNewton iterations per increment (current geometry), and the ratio to the rigid obstacle's slide:")
    for (label, case, _), mean in per_increment.items():
        slide = per_increment.get((label, "slide", "current"))
        ratio = f"{mean / slide:.2f} x the slide" if slide and case != "slide" else ""
        print(f"  {label:21s} {case:16s} {mean:5.2f}  {ratio}")


if __name__ == "__main__":
    np.set_printoptions(precision=6)
    main()
