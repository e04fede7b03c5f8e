"""The ``dolfinx-nnqem`` command (also ``python -m dolfinx_nnqem``).

Exit codes: 0 success; 1 an increment did not converge (the converged ones are written);
2 bad command line; 3 bad input (parameters, tags, mesh).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from dolfinx_nnqem.solver import METHODS

EXIT_OK, EXIT_DIVERGED, EXIT_USAGE, EXIT_BAD_INPUT = 0, 1, 2, 3


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="dolfinx-nnqem",
        description="Elastoplastic frictional contact in DOLFINx by nonsmooth equations (NNEQM).",
        epilog="Exit codes: 0 ok, 1 an increment did not converge, 2 bad command line, 3 bad input.",
    )
    # the logging flags work before or after the subcommand
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS,
                        help="more output (-v: a line per increment, -vv: a line per iteration)")
    common.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                        help="only errors")
    parser._add_container_actions(common)
    sub = parser.add_subparsers(dest="command", required=True)

    tb = sub.add_parser("two-beams", parents=[common], help="the seed benchmark: two overlapping cantilevers",
                        description="Solve the seed's two-beam benchmark and print its tables.")
    tb.add_argument("--method", default="monolithic", choices=(*METHODS, "all"),
                    help="solver (default monolithic); 'all' runs the three and compares them")
    tb.add_argument("--increments", type=int, default=15, help="equal load increments (default 15)")
    tb.add_argument("--law", choices=("polar", "alart-curnier"), default=None,
                    help="pair law (default: polar for nneqm1/nneqm2, alart-curnier for monolithic)")
    tb.add_argument("--refine", type=int, default=1, help="divide the 0.2 m elements by this factor")
    tb.add_argument("--out", default="results/two_beams", help="output folder (default results/two_beams)")
    tb.add_argument("--no-fields", action="store_true", help="skip the XDMF field output")

    run = sub.add_parser("run", parents=[common], help="solve a problem file (TOML)",
                         description="Solve the problem described in a TOML problem file "
                                     "(format: docs/problem-file.md; example: demos/two_beams.toml).")
    run.add_argument("problem", help="the problem file (.toml)")
    run.add_argument("--out", default=None, help="output folder (default: [output].folder of the file)")
    run.add_argument("--method", choices=METHODS, default=None, help="override [solver].method")
    run.add_argument("--increments", type=int, default=None, help="override [solver].increments")
    run.add_argument("--check", action="store_true", help="only check the file and build the problem")
    return parser


def _configure_logging(verbose: int, quiet: bool) -> None:
    from mpi4py import MPI

    level = logging.ERROR if quiet else (logging.INFO if verbose >= 2 else logging.WARNING)
    if MPI.COMM_WORLD.rank > 0:
        level = logging.ERROR
    logging.basicConfig(level=level, format="%(message)s")


def _two_beams(args) -> int:
    from mpi4py import MPI

    from dolfinx_nnqem.two_beams import format_differences, format_tables, run_two_beams

    rank0 = MPI.COMM_WORLD.rank == 0
    methods = [m for m in METHODS if _available(m)] if args.method == "all" else [args.method]
    summaries = []
    for method in methods:
        out = Path(args.out) / method if args.method == "all" else Path(args.out)

        def progress(result, method=method):
            if rank0 and args.verbose >= 1:
                print(f"[{method}] increment {result.index}: load factor {result.load_factor:.4f}, "
                      f"{result.iterations} iterations, {result.plastic_points} plastic Gauss points",
                      flush=True)

        summary = run_two_beams(method, args.increments, out, law=args.law, refine=args.refine,
                                fields=not args.no_fields, progress=progress)
        summaries.append(summary)
        if rank0 and not args.quiet:
            print(format_tables(summary), flush=True)
            print(f"results in {out}/", flush=True)
    if rank0 and not args.quiet and len(summaries) > 1:
        print(format_differences(summaries))
        (Path(args.out) / "comparison.json").write_text(json.dumps(
            {"methods": [s["method"] for s in summaries]}, indent=1))
    return EXIT_OK


def _progress_bar(total: int, method: str):
    """A one-line progress bar on stderr (only on a terminal, only on rank 0)."""
    from mpi4py import MPI

    if MPI.COMM_WORLD.rank != 0 or not sys.stderr.isatty():
        return None

    def show(result):
        width = 30
        done = min(result.load_factor, 1.0)
        bar = "#" * int(round(width * done)) + "." * (width - int(round(width * done)))
        sys.stderr.write(f"\r[{bar}] {method}: increment {result.index} (load factor {result.load_factor:.3f}),"
                         f" {result.iterations} iterations ")
        if done >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()

    return show


def _run(args) -> int:
    from mpi4py import MPI

    from dolfinx_nnqem.output import ResultsWriter
    from dolfinx_nnqem.problem_file import build_problem, load_problem_file, solver_options
    from dolfinx_nnqem.solver import make_solver
    from dolfinx_nnqem.stepping import solve_load_steps

    spec = load_problem_file(args.problem)
    solver_spec = spec.solver
    method = args.method or solver_spec["method"]
    increments = args.increments or solver_spec["increments"]
    comm = MPI.COMM_WORLD
    problem = build_problem(spec, comm)
    rank0 = comm.rank == 0
    if rank0 and not args.quiet:
        print(f"{args.problem}: {problem.V.dofmap.index_map.size_global * 3} displacement dofs, "
              f"{problem.num_pairs} contact pairs, {problem.state.num_gauss_points()} Gauss points, "
              f"method {method}, {increments} increments", flush=True)
        for line in problem.contact.describe() if problem.has_contact else []:
            print(f"  {line}", flush=True)
    if args.check:
        return EXIT_OK
    options, method_options = solver_options(spec, method)
    solver = make_solver(method, problem, options, **method_options)
    out = Path(args.out or spec.output["folder"])
    writer = ResultsWriter(problem, method, out, increments, probes=spec.output["probes"] or None,
                           fields=spec.output["fields"], extra={"problem_file": str(args.problem)})
    callbacks = [writer]
    bar = None if args.quiet else _progress_bar(increments, method)
    if bar is not None:
        callbacks.append(bar)
    try:
        solve_load_steps(problem, solver, increments, max_cutbacks=solver_spec["max_cutbacks"],
                         callbacks=callbacks)
    finally:
        writer.close()
    if rank0 and not args.quiet:
        s = writer.summary.data
        print(f"converged: {s['converged']}; iterations {s['iterations']}; global equilibrium "
              f"{s.get('equilibrium_residual', float('nan')):.2e}; results in {out}/", flush=True)
    return EXIT_OK


def _available(method: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(f"dolfinx_nnqem.{method}") is not None


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    args.verbose = getattr(args, "verbose", 0)
    args.quiet = getattr(args, "quiet", False)
    if getattr(args, "increments", None) is not None and args.increments < 1:
        print("dolfinx-nnqem: error: --increments must be >= 1", file=sys.stderr)
        return EXIT_USAGE
    _configure_logging(args.verbose, args.quiet)
    import dolfinx_nnqem  # noqa: F401  (loads the PyPI wheel's MPI/PETSc first)
    from dolfinx_nnqem.convergence import ConvergenceError

    try:
        if args.command == "two-beams":
            return _two_beams(args)
        if args.command == "run":
            return _run(args)
    except ConvergenceError as error:
        print(f"dolfinx-nnqem: {error}", file=sys.stderr)
        return EXIT_DIVERGED
    except (ValueError, TypeError, OSError) as error:
        print(f"dolfinx-nnqem: bad input: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
