"""Fingerprint of solver results, to show that a change that must not move any number moves none.

Runs a set of the robustness cases (``benchmarks/robustness.py``) with every method and law and
saves, per cell, the final displacement, the pair forces (not the unknowns: the polar angle of a
pair without force means nothing), the load factors and the iterations of every increment (``--save A.npz``); ``--compare A.npz B.npz`` prints each cell's largest
relative difference. Prints figures; asserts nothing::

    python benchmarks/fingerprint.py --save before.npz
    ... change the code ...
    python benchmarks/fingerprint.py --save after.npz
    python benchmarks/fingerprint.py --compare before.npz after.npz
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT))

DEFAULT_CASES = ("drag-0.2-hex", "two-beams-15", "cyclic", "gap-closes-reopens", "mindlin-v7", "sliding-block-v5",
                 "held-by-contact", "perfect-plasticity")


def run(cases, methods, laws) -> dict[str, np.ndarray]:
    warnings.simplefilter("ignore", DeprecationWarning)
    import robustness as rb  # noqa: E402  (the cases)

    out: dict[str, np.ndarray] = {}
    for case in [c for c in rb.CASES if c.name in cases]:
        for method in methods:
            for law in laws:
                if not case.contact and (method != "monolithic" or law != rb.LAWS[0]):
                    continue
                problem = case.build(law)
                key = f"{case.name}/{method}/{law}"
                try:
                    with rb.make_solver(method, problem, rb.SolverOptions()) as solver:
                        results = rb.solve_load_steps(problem, solver, case.increments,
                                                      max_displacement=case.max_displacement)
                except rb.ConvergenceError as error:
                    print(f"{key:45s} failed: {str(error).splitlines()[0][:100]}", flush=True)
                    continue
                n = problem.V.dofmap.index_map.size_local * 3
                out[key + "/u"] = problem.u.x.array[:n].copy()
                out[key + "/z"] = problem.contact.force() if problem.has_contact else np.zeros((0, 3))
                out[key + "/path"] = np.array([[r.load_factor, r.iterations] for r in results], dtype=float)
                print(f"{key:45s} {len(results)} increments, {sum(r.iterations for r in results)} iterations",
                      flush=True)
    return out


def compare(a: dict, b: dict) -> None:
    cells = sorted({k.rsplit("/", 1)[0] for k in a} | {k.rsplit("/", 1)[0] for k in b})
    worst = 0.0
    for cell in cells:
        if cell + "/u" not in a or cell + "/u" not in b:
            print(f"{cell:45s} only in {'the first' if cell + '/u' in a else 'the second'}")
            continue
        same_path = a[cell + "/path"].shape == b[cell + "/path"].shape and np.array_equal(a[cell + "/path"],
                                                                                          b[cell + "/path"])
        diffs = []
        for part in ("u", "z"):
            x, y = a[f"{cell}/{part}"], b[f"{cell}/{part}"]
            diffs.append(float(np.abs(x - y).max() / max(np.abs(x).max(), 1e-300)) if x.size else 0.0)
        worst = max(worst, *diffs)
        print(f"{cell:45s} u {diffs[0]:.1e}  z {diffs[1]:.1e}  path {'same' if same_path else 'DIFFERENT'}")
    print(f"largest relative difference: {worst:.1e}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--save", help="run and save the fingerprint to this .npz")
    parser.add_argument("--compare", nargs=2, metavar=("A", "B"), help="compare two saved fingerprints")
    parser.add_argument("--cases", nargs="*", default=list(DEFAULT_CASES))
    parser.add_argument("--methods", nargs="*", default=["monolithic", "nneqm1", "nneqm2"])
    parser.add_argument("--laws", nargs="*", default=["alart-curnier", "polar"])
    args = parser.parse_args(argv)
    if args.compare:
        compare(*(dict(np.load(f)) for f in args.compare))
        return 0
    if not args.save:
        parser.error("--save or --compare")
    np.savez(args.save, **run(args.cases, args.methods, args.laws))
    print(f"saved {args.save}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
