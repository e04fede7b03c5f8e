"""The ``dolfinx-nnqem`` command (also ``python -m dolfinx_nnqem``).

Exit codes (``docs/reliability.md``): 0 success; 1 an increment did not converge (the converged
ones are written, ``summary.json`` says which increment failed and why); 2 bad command line;
3 bad input (parameters, tags, mesh, checkpoint); 4 an input/output failure (a file that cannot
be written or read, a full disk, an output folder in use or holding an earlier run); 5 a PETSc
error (unknown solver package, failed factorisation); 70 an internal error (a bug);
130 interrupted (Ctrl-C, SIGINT), 143 terminated (SIGTERM). No traceback is shown unless -vv.
With MPI every rank ends with the same code and rank 0 prints the message once.
"""

from __future__ import annotations

import argparse
import gc
import json
import logging
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from dolfinx_nnqem import interrupts
from dolfinx_nnqem.names import LAW_NAMES, METHODS

if TYPE_CHECKING:
    from dolfinx_nnqem.io.picture_worker import PictureWorkers


EXIT_OK, EXIT_DIVERGED, EXIT_USAGE, EXIT_BAD_INPUT = 0, 1, 2, 3
EXIT_IO, EXIT_PETSC, EXIT_INTERNAL = 4, 5, 70
EXIT_INTERRUPTED, EXIT_TERMINATED = 130, 143
DOCS = "docs/problem-file.md (the format), docs/reliability.md (checks, exit codes, restart)"


class Terminated(KeyboardInterrupt):
    """SIGTERM, turned into an exception so that files are closed and the run ends cleanly."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="dolfinx-nnqem",
        description="Elastoplastic frictional contact in DOLFINx by nonsmooth equations (NNEQM).",
        epilog="Exit codes: 0 ok, 1 an increment did not converge, 2 bad command line, 3 bad input, "
               "4 input/output failure, 5 PETSc error, 70 internal error, 130/143 interrupted/terminated "
               "(docs/reliability.md).",
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
    tb.add_argument("--law", choices=LAW_NAMES, default=None,
                    help="pair law (default: polar for nneqm1/nneqm2, alart-curnier for monolithic)")
    tb.add_argument("--refine", type=int, default=1, help="divide the 0.2 m elements by this factor")
    tb.add_argument("--out", default="results/two_beams",
                    help="output folder (default results/two_beams; an earlier run's outputs there are replaced)")
    tb.add_argument("--no-fields", action="store_true", help="skip the XDMF field output")

    run = sub.add_parser("run", parents=[common], help="solve a problem file (TOML)",
                         description="Solve the problem described in a TOML problem file "
                                     "(format: docs/problem-file.md; example: demos/two_beams.toml).",
                         epilog=f"Documentation: {DOCS}. Exit codes: 0 ok, 1 not converged, 2 bad command line, "
                                "3 bad input, 4 input/output failure, 5 PETSc error, 70 internal error, "
                                "130/143 interrupted/terminated.")
    run.add_argument("problem", help="the problem file (.toml)")
    run.add_argument("--out", default=None, help="output folder (default: [output].folder of the file)")
    run.add_argument("--method", choices=METHODS, default=None, help="override [solver].method")
    run.add_argument("--increments", type=int, default=None, help="override [solver].increments")
    run.add_argument("--check", action="store_true", help="only check the file and build the problem")
    run.add_argument("--no-pictures", action="store_true",
                     help="do not draw the PNG pictures into OUT/pictures at the end of the run")
    run.add_argument("--estimate", action="store_true",
                     help="estimate the discretisation error of the results (an enriched solve after the run; "
                          "docs/error-estimates.md)")
    run.add_argument("--target-error", type=float, default=None, metavar="REL",
                     help="refine the tetrahedral mesh adaptively until every estimate is at most REL "
                          "(e.g. 0.01; overrides [estimate].target_error)")
    mode = run.add_mutually_exclusive_group()
    mode.add_argument("--restart", action="store_true",
                      help="continue the run in the output folder from its last complete checkpoint")
    mode.add_argument("--overwrite", action="store_true",
                      help="replace the results of an earlier run in the output folder (otherwise refused)")

    plot = sub.add_parser("plot", parents=[common], help="(re)draw the pictures of a results folder",
                          description="Draw the pictures of a run from its results folder (summary.json, "
                                      "fields.xdmf, pair CSV files), without solving again: deformed.png, "
                                      "pair_pressure.png, load_curve.png, convergence.png (docs/outputs.md).")
    plot.add_argument("results", help="a run's output folder")
    plot.add_argument("--out", default=None, help="where the PNG files go (default RESULTS/pictures)")
    plot.add_argument("--scale", type=float, default=None,
                      help="displacement magnification of deformed.png (default: largest displacement "
                           "drawn as 10%% of the model size)")
    plot.add_argument("--field", choices=("von_mises", "p", "error_indicator"), default="von_mises",
                      help="colour of deformed.png: von Mises stress or equivalent plastic strain p")
    plot.add_argument("--camera", choices=("iso", "xy", "xz", "yz"), default="iso", help="view of deformed.png")
    return parser


def _configure_logging(verbose: int, quiet: bool) -> None:
    from mpi4py import MPI

    level = logging.ERROR if quiet else (logging.INFO if verbose >= 2 else logging.WARNING)
    if MPI.COMM_WORLD.rank > 0:
        level = logging.ERROR
    logging.basicConfig(level=level, format="%(message)s")
    from dolfinx_nnqem.chatter import show_third_party_output

    # gmsh, numba and other libraries' own lines and warnings: only with -v (and not with -q)
    show_third_party_output(verbose >= 1 and not quiet)


def _two_beams(args) -> int:
    from mpi4py import MPI

    from dolfinx_nnqem.cases.two_beams import format_differences, format_tables, run_two_beams

    rank0 = MPI.COMM_WORLD.rank == 0
    methods = [m for m in METHODS if _available(m)] if args.method == "all" else [args.method]
    summaries: list[dict] = []
    for method in methods:
        if summaries:  # the previous run's outcome is final; a signal held since ends this one
            interrupts.run_over = False
            _raise_held_signal()
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


def _increments_text(increments) -> str:
    """'15 increments' or 'automatic increments' (for the log and a checkpoint's identity)."""
    return f"{int(increments)} increments" if isinstance(increments, int) else "automatic increments"


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


def _increment_line(method: str):
    """``-v``: one line per converged increment, as ``--help`` promises (the stepping's own line
    is logged at the level of ``-vv`` with the iterations)."""
    def line(result):
        print(f"[{method}] increment {result.index}: load factor {result.load_factor:.6g} converged in "
              f"{result.iterations} iterations, {result.cutbacks} cutbacks, {result.plastic_points} plastic "
              "Gauss points", flush=True)

    return line


def _run(args, workers: PictureWorkers | None = None) -> int:
    from mpi4py import MPI

    from dolfinx_nnqem.collective import agree
    from dolfinx_nnqem.estimates.runs import EstimateSettings, check_settings
    from dolfinx_nnqem.problem_file import build_problem, load_problem_file, solver_options
    from dolfinx_nnqem.solvers.registry import make_solver

    comm = MPI.COMM_WORLD
    spec = agree(comm, load_problem_file, args.problem)
    method = args.method or spec.solver["method"]
    increments = args.increments or spec.solver["increments"]
    rank0 = comm.rank == 0
    if workers is not None and (not rank0 or not spec.output["pictures"]):  # (the launcher named no rank,
        workers.close()  # or no pictures after all)
        workers = None
    problem = build_problem(spec, comm)
    args.estimate_settings = settings = EstimateSettings.from_table(spec.estimate, estimate=args.estimate,
                                                                    target_error=args.target_error)
    check_settings(problem, settings)  # a refusal (no enrichment, adaptivity on hexahedra) before solving
    if settings.target_error is not None and args.restart:
        raise ValueError("--restart with a target error: an adaptive run solves every mesh from the start")
    if rank0 and not args.quiet:
        _print_header(args.problem, problem, method, increments)
    if args.check:
        return EXIT_OK
    options, method_options = solver_options(spec, method)
    if settings.target_error is not None:
        return _run_adaptive(args, spec, problem, method, increments, options, method_options)
    if method != "monolithic" or spec.solver["linear_solver"] == "direct":
        from dolfinx_nnqem.solvers.preflight import check_direct_solver

        check_direct_solver(comm, options.petsc_options)  # an unknown solver package is reported as such
    with make_solver(method, problem, options, **method_options) as solver:  # frees PETSc's objects
        writer = _solve_problem_file(args, spec, problem, solver, method, increments, workers,
                                     estimate=(options, method_options))
    if rank0 and not args.quiet:
        s = writer.summary.data
        print(f"converged: {s['converged']}; iterations {s['iterations']}; global equilibrium "
              f"{s.get('equilibrium_residual', float('nan')):.2e}; results in {writer.folder}/", flush=True)
        _print_pictures(writer.drawn)
        if args.restart and not writer.written and not writer.drawn:  # a restart of a completed run
            from dolfinx_nnqem.io.run_pictures import pictures_enabled

            print("nothing to do" + (f": every picture is in {writer.folder}/pictures/"
                                     if pictures_enabled(writer.pictures) else ""), flush=True)
    return EXIT_OK


def _run_adaptive(args, spec, problem, method: str, increments, options, method_options) -> int:
    """``run --target-error``: adaptive cycles, each solved into the output folder (the last one's
    results stay), the sequence in ``summary.json`` (``adaptivity``), the pictures at the end."""
    from dolfinx_nnqem.estimates.adaptive import solve_adaptively
    from dolfinx_nnqem.estimates.quantities import probe_points
    from dolfinx_nnqem.estimates.report import format_estimates, record_estimates
    from dolfinx_nnqem.io.run_pictures import draw_run_pictures
    from dolfinx_nnqem.problem_file import check_options
    from dolfinx_nnqem.solvers.registry import make_solver

    settings = args.estimate_settings
    pictures = spec.output["pictures"] and not args.no_pictures
    args.no_pictures, writers = True, []  # the pictures of the last cycle only, at the end
    rank0 = problem.comm.rank == 0

    def run_cycle(cycle_problem, index):
        args.overwrite = args.overwrite or index > 1  # each cycle replaces the one before
        with make_solver(method, cycle_problem, options, **method_options) as solver:
            writers.append(_solve_problem_file(args, spec, cycle_problem, solver, method, increments, None))
        return writers[-1].summary.data["load_factors"]

    def progress(cycle):
        if rank0 and not args.quiet:
            print(f"cycle {cycle.index}: {cycle.dofs} dofs, largest relative estimate "
                  f"{100 * cycle.relative_error:.3g} % (target {100 * settings.target_error:g} %)", flush=True)

    result = solve_adaptively(problem, run_cycle, method, settings.target_error, max_cycles=settings.max_cycles,
                              fraction=settings.refine_fraction, quantities=settings.quantities,
                              probes=probe_points(spec.output["probes"] or None), options=options,
                              method_options=method_options, on_cycle=progress, enrichment=settings.enrichment,
                              check=check_options(spec))
    summary = writers[-1].summary
    record_estimates(summary.data, result.cycles[-1].estimates)
    summary.data["adaptivity"] = result.as_dict(settings.target_error)
    summary.write()
    if rank0 and pictures:
        draw_run_pictures(writers[-1].folder)
    if rank0 and not args.quiet:
        print(format_estimates(result.cycles[-1].estimates), flush=True)
        print(f"target {'reached' if result.reached else 'NOT reached'} after {len(result.cycles)} cycles; "
              f"results of the last mesh in {writers[-1].folder}/", flush=True)
    return EXIT_OK


def _print_header(path: str, problem, method: str, increments) -> None:
    """What is about to be solved: the sizes, the contact interfaces, the motions friction holds."""
    print(f"{path}: {problem.V.dofmap.index_map.size_global * 3} displacement dofs, "
          f"{problem.num_pairs} contact pairs, {problem.state.num_gauss_points()} Gauss points, "
          f"method {method}, {_increments_text(increments)}", flush=True)
    for line in problem.contact.describe() if problem.has_contact else []:
        print(f"  {line}", flush=True)
    for motion in problem.friction_held.motions:  # fine while friction holds; named again if the run fails
        print(f"  held by friction only: {motion}", flush=True)


def _solve_problem_file(args, spec, problem, solver, method: str, increments, workers: PictureWorkers | None,
                        estimate: tuple | None = None):
    """Solve the load steps of ``run`` with its writers, checkpoints and progress lines; returns
    the :class:`~dolfinx_nnqem.io.output.ResultsWriter` (closed). ``summary.json`` records how a
    run that started solving ended. ``estimate``: (options, method_options) of the enriched solve
    when ``args.estimate_settings`` asks for the error estimates."""
    import hashlib

    from dolfinx_nnqem.estimates import RecoveryIndicator
    from dolfinx_nnqem.estimates.report import format_estimates
    from dolfinx_nnqem.estimates.runs import estimate_into_writer
    from dolfinx_nnqem.io import checkpoint
    from dolfinx_nnqem.io.output import ResultsWriter
    from dolfinx_nnqem.problem_file import check_options
    from dolfinx_nnqem.solvers.stepping import solve_load_steps

    out = Path(args.out or spec.output["folder"])
    identity = {"problem_sha256": hashlib.sha256(Path(args.problem).read_bytes()).hexdigest(),
                "method": method, "increments": int(increments) if isinstance(increments, int) else "auto"}
    _install_sigterm()  # again: gmsh and PETSc's set-up may have reset the signal handlers
    pictures = spec.output["pictures"] and not args.no_pictures
    writer = ResultsWriter(problem, method, out, increments, probes=spec.output["probes"] or None,
                           fields=spec.output["fields"], extra={"problem_file": str(args.problem)},
                           overwrite=args.overwrite, resume=args.restart, pictures=None if pictures else False,
                           picture_worker=workers, cell_fields=[RecoveryIndicator(problem)])
    args.writer, args.checkpoints = writer, bool(spec.output["checkpoint_every"])  # (for the restart hint)
    solving = False  # summary.json records how a run ended only once it has started solving (or resumed)
    try:
        resume = None
        if args.restart:
            resume, meta = checkpoint.restore(problem, out, expected_meta=identity)
            writer.resume(meta["writers"][0])  # a run that had completed: "completed", nothing to solve
            solving = args.solving = True
            if problem.comm.rank == 0 and not args.quiet:
                print(_restarting_line(writer, resume.index, problem.load_factor_n), flush=True)
        every = spec.output["checkpoint_every"]
        ckpt = checkpoint.Checkpointer(out, every, writers=[writer], meta=identity) if every else None
        solving = args.solving = True
        solve_load_steps(problem, solver, increments, max_cutbacks=spec.solver["max_cutbacks"],
                         callbacks=[writer] + _progress_callbacks(args, increments, method, problem.comm.rank),
                         check=check_options(spec), checkpoint=ckpt, resume=resume)
        settings = getattr(args, "estimate_settings", None)
        if estimate is not None and settings is not None and settings.enabled:
            found = estimate_into_writer(writer, problem, method, settings, probes=spec.output["probes"] or None,
                                         options=estimate[0], method_options=estimate[1], check=check_options(spec))
            if found is not None and problem.comm.rank == 0 and not args.quiet:
                print(format_estimates(found), flush=True)
    except BaseException as error:  # noqa: BLE001  (re-raised: the summary says how the run ended)
        if solving:
            writer.record_end(error)
        interrupt = _interrupt_behind(error)
        if interrupt is not None and interrupt is not error:  # a signal inside compiled code (numba wraps it)
            raise interrupt from None
        raise
    finally:
        writer.close()
        if problem.comm.rank == 0 and not args.quiet and writer.summary.data.get("status") == "not converged":
            _print_pictures(writer.drawn)  # the converged increments' pictures
    return writer


def _restarting_line(writer, index: int, load_factor: float) -> str:
    """What ``run --restart`` does: continue after the checkpoint, or nothing to solve."""
    if writer.summary.data.get("status") == "completed":
        return (f"{writer.folder}: the run had completed (increment {index}, load factor {load_factor:.6g}): "
                "nothing to solve")
    return f"restarting after increment {index} (load factor {load_factor:.6g}) from {writer.folder}/checkpoints"


def _raise_swallowed_interrupt(*_) -> None:
    """Raise the interrupt a signal handler acted on if its exception was lost (also a callback
    after each increment).

    Python runs a signal handler between any two byte-codes of the main thread, also inside a
    weak-reference callback or a finaliser, where an exception is printed as "Exception ignored"
    and dropped: a SIGTERM 0.4 s into a run met the import system's module-lock callback, and
    the run went on to exit 0 (measured once in a fresh-clone suite). :data:`interrupts.received`
    still records the signal."""
    interrupt = _interrupt_behind(None)
    if interrupt is not None:
        raise interrupt


def _quiet_about_lost_interrupts(hook):
    """``sys.unraisablehook`` that leaves out the interrupts whose exception Python dropped (they
    are recorded and raised again, :func:`_raise_swallowed_interrupt`): the run ends with its one
    line, not with an "Exception ignored" traceback too. Every other unraisable goes to ``hook``."""

    def quiet(unraisable) -> None:
        if issubclass(unraisable.exc_type, KeyboardInterrupt) and interrupts.received:
            return
        hook(unraisable)

    return quiet


def _progress_callbacks(args, increments, method: str, rank: int) -> list:
    """The progress bar, and with -v a line per increment (-vv: the log has it); first, the check
    for an interrupt whose exception was lost (:func:`_raise_swallowed_interrupt`)."""
    callbacks: list = [_raise_swallowed_interrupt]
    bar = None if args.quiet else _progress_bar(increments, method)
    if bar is not None:
        callbacks.append(bar)
    if args.verbose == 1 and not args.quiet and rank == 0:
        callbacks.append(_increment_line(method))
    return callbacks


def _print_pictures(drawn: dict) -> None:
    """One line naming the pictures drawn (the reasons of the others are logged as warnings)."""
    paths = [Path(p) for p in drawn.values() if not isinstance(p, str)]
    if paths:
        print(f"pictures: {', '.join(p.name for p in paths)} in {paths[0].parent}/", flush=True)


def _plot(args) -> int:
    """``dolfinx-nnqem plot RESULTS``: the run pictures from the folder, on rank 0."""
    from mpi4py import MPI

    from dolfinx_nnqem.io.run_pictures import draw_run_pictures

    if MPI.COMM_WORLD.rank != 0:
        return EXIT_OK
    folder = Path(args.results)
    if not (folder / "summary.json").is_file():
        raise FileNotFoundError(2, f"{folder} is not a results folder (no summary.json)", str(folder))
    drawn = draw_run_pictures(folder, out=args.out, scale=args.scale, field=args.field, camera=args.camera)
    for name, result in drawn.items():
        if isinstance(result, str):
            logging.getLogger("dolfinx_nnqem").warning(f"picture {name}: {result}")
    if not args.quiet:
        _print_pictures(drawn)
    return EXIT_OK if any(not isinstance(p, str) for p in drawn.values()) else EXIT_BAD_INPUT


def _available(method: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(f"dolfinx_nnqem.{method}") is not None


def _interrupt_behind(error: BaseException | None) -> KeyboardInterrupt | None:
    """The Ctrl-C or SIGTERM behind ``error``, if any.

    A KeyboardInterrupt raised while numba-compiled code runs comes back as a SystemError
    ("returned a result with an exception set") whose cause is the interrupt.
    """
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return error
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    import signal

    received = interrupts.received  # an error raised while handling an interrupt (a lazy
    if received:  # import that turned it into ImportError) is that interrupt
        return Terminated() if received[-1] == signal.SIGTERM else KeyboardInterrupt()
    return None


def _classify(error: BaseException, args) -> tuple[int, str]:
    """The exit code and the one-line message of an exception that ended the run."""
    from dolfinx_nnqem.solvers.convergence import ConvergenceError

    if isinstance(error, Terminated):
        return EXIT_TERMINATED, "dolfinx-nnqem: terminated (SIGTERM)" + _restart_hint(args)
    if isinstance(error, KeyboardInterrupt):
        return EXIT_INTERRUPTED, "dolfinx-nnqem: interrupted (Ctrl-C)" + _restart_hint(args)
    if isinstance(error, ConvergenceError):
        return EXIT_DIVERGED, f"dolfinx-nnqem: {error}"
    try:
        from petsc4py import PETSc

        if isinstance(error, PETSc.Error):
            return EXIT_PETSC, f"dolfinx-nnqem: PETSc error {error.ierr}: {_petsc_text(error)}"  # type: ignore[attr-defined]  # petsc4py's stub lacks Error.ierr
    except ImportError:
        pass
    if hasattr(error, "ierr"):  # preflight.PetscSetupError
        return EXIT_PETSC, f"dolfinx-nnqem: {error}: {_petsc_text(error)}"
    cause = error.__cause__
    if cause is not None and type(cause).__name__ == "Error" and hasattr(cause, "ierr"):
        return EXIT_PETSC, f"dolfinx-nnqem: {error} [PETSc error {cause.ierr}: {_petsc_text(cause)}]"
    if isinstance(error, OSError):
        return EXIT_IO, f"dolfinx-nnqem: input/output error: {_os_text(error)}"
    if isinstance(error, (ValueError, TypeError)):
        return EXIT_BAD_INPUT, f"dolfinx-nnqem: bad input: {error}"
    if isinstance(error, MemoryError):
        return EXIT_INTERNAL, "dolfinx-nnqem: out of memory"
    return EXIT_INTERNAL, (f"dolfinx-nnqem: internal error: {type(error).__name__}: {error} "
                           "(please report it; -vv shows the traceback)")


def _petsc_text(error) -> str:
    texts: dict[int | None, str] = {56: "no support for this operation (e.g. an unknown or unavailable solver package)",
             71: "zero pivot in the factorisation (a singular matrix: a body without supports?)",
             76: "error in an external library (e.g. MUMPS failed to factorise)",
             86: "unknown type (an unknown solver or preconditioner name in petsc_options)",
             92: "no such factorisation package in this PETSc (pc_factor_mat_solver_type)"}
    return texts.get(getattr(error, "ierr", None), "see PETSc's message above")


def _os_text(error: OSError) -> str:
    text = error.strerror or str(error) if error.errno is not None else str(error)
    if error.filename and str(error.filename) not in text:
        text += f" ({error.filename})"
    return text


def _restart_hint(args) -> str:
    """How an interrupted ``run`` goes on: nothing was written; or ``--restart`` continues from the
    last checkpoint (a run whose increments had all converged: it draws the missing pictures)."""
    if getattr(args, "command", None) != "run":
        return ""
    if not getattr(args, "solving", False):  # interrupted while starting: nothing to continue
        return "; before solving started (nothing written)"
    writer = getattr(args, "writer", None)
    converged = writer is not None and bool(writer.summary.data.get("converged"))
    folder = writer.folder if writer is not None else args.out
    written = ("; every increment is written, the pictures are not all drawn" if converged
               else "; the converged increments are written")
    out = f" --out {args.out}" if args.out else ""
    if not getattr(args, "checkpoints", True):  # checkpoint_every = 0: nothing to restart from
        return written + (f"; draw them with: dolfinx-nnqem plot {folder}" if converged
                          else " (no checkpoints: checkpoint_every = 0)")
    return written + f"; {'finish' if converged else 'continue'} with: dolfinx-nnqem run {args.problem} --restart{out}"


def _install_sigterm() -> None:
    import signal

    def on_term(signum, frame):
        if interrupts.run_over:  # the outcome is final: the exit code stays the run's
            return interrupts.defer(signum, frame)
        interrupts.received.append(signum)
        _abort_unless_ended(EXIT_TERMINATED, "terminated (SIGTERM)")
        raise Terminated()

    def on_int(signum, frame):
        if interrupts.run_over:
            return interrupts.defer(signum, frame)
        interrupts.received.append(signum)
        _abort_unless_ended(EXIT_INTERRUPTED, "interrupted (Ctrl-C)")
        raise KeyboardInterrupt()

    try:
        signal.signal(signal.SIGTERM, on_term)
        # MPI's start-up may leave SIGINT at its default (kill): make Ctrl-C a KeyboardInterrupt again
        signal.signal(signal.SIGINT, on_int)
    except ValueError:  # not the main thread (e.g. called from a test runner's worker)
        pass


def _abort_unless_ended(code: int, reason: str) -> None:
    """Under MPI, an interrupt that does not end the job in bounded time aborts it
    (:func:`dolfinx_nnqem.collective.abort_unless_ended`)."""
    if "mpi4py.MPI" in sys.modules:
        from dolfinx_nnqem import collective

        collective.abort_unless_ended(code, reason)


def main(argv: list[str] | None = None) -> int:
    """Run the command with the arguments ``argv`` (default: the process's own) and return its exit
    code (module docstring). Run as the command line, it ends the process with that code instead."""
    interrupts.received.clear()
    interrupts.run_over = False
    _hold_signals()  # start-up: an interrupt is recorded, and acted on once the run can end cleanly
    unraisable_hook = sys.unraisablehook
    sys.unraisablehook = _quiet_about_lost_interrupts(unraisable_hook)
    try:
        code = _main(argv)
    finally:
        interrupts.run_over = True  # the outcome is decided (argparse's SystemExit too)
        sys.unraisablehook = unraisable_hook
        _install_sigterm()  # never leave the start-up handlers behind (in-process callers)
        if argv is not None or not interrupts.is_command_line():  # an in-process caller goes on: the
            interrupts.run_over = False  # signals held after this run's outcome are dropped with it
            interrupts.deferred.clear()
            interrupts.received.clear()
        if "dolfinx_nnqem.collective" in sys.modules and not interrupts.is_command_line():
            sys.modules["dolfinx_nnqem.collective"].disarm_abort()  # (the command line's process ends)
    if argv is None and interrupts.is_command_line():
        _exit(code)
    return code


def _exit(code: int) -> None:
    """End the command line's process: PETSc and MPI finalised (collective: every rank ends
    here), the standard streams flushed, then ``os._exit`` without the interpreter's tear-down
    of its modules and objects, which cost 0.1 s, a tenth of a small run (measured from the
    end of :func:`main` to the process's end: 0.10-0.14 s, 0.02 s this way). Every file of the
    run is closed by now; in-process callers (``main([...])``) are not affected."""
    import os
    import signal

    try:  # the run has ended with ``code``: a signal now would only turn it into a crash
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # (its handlers use MPI, finalised below)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    except ValueError:  # not the main thread
        pass
    logging.shutdown()
    if "petsc4py.PETSc" in sys.modules:
        from petsc4py import PETSc

        if code != EXIT_OK:  # a run that stopped early left its solver's options unread: PETSc's
            PETSc.Options().setValue("options_left", "false")  # "options you set that were not used"
        PETSc._finalize()
    if "mpi4py.MPI" in sys.modules:
        from mpi4py import MPI

        if MPI.Is_initialized() and not MPI.Is_finalized():
            MPI.Finalize()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe (dolfinx-nnqem run ... | head): nothing to keep
            pass
    os._exit(code)


def _main(argv: list[str] | None) -> int:
    args = _parser().parse_args(argv)
    args.verbose = getattr(args, "verbose", 0)
    args.quiet = getattr(args, "quiet", False)
    if getattr(args, "increments", None) is not None and not 1 <= args.increments <= 100_000:
        print("dolfinx-nnqem: error: --increments must be in [1, 100000]", file=sys.stderr)
        return EXIT_USAGE
    if getattr(args, "out", None) is not None and args.out.strip() in ("", "."):
        print("dolfinx-nnqem: error: --out needs a folder name (not empty, not '.')", file=sys.stderr)
        return EXIT_USAGE
    scale = getattr(args, "scale", None)
    if scale is not None and not (math.isfinite(scale) and 0 < scale <= 1e20):  # nan drew a blank picture
        print(f"dolfinx-nnqem: error: --scale must be a number in (0, 1e20], got {scale}", file=sys.stderr)
        return EXIT_USAGE
    workers = _start_picture_workers(args)  # they import their libraries meanwhile
    try:
        _start_up()
        _configure_logging(args.verbose, args.quiet)
        from mpi4py import MPI

        from dolfinx_nnqem import collective

        collective.init()  # on every rank before any rank acts on an interrupt (it is collective)
        code, message = EXIT_OK, ""
        try:
            _install_sigterm()
            _raise_held_signal()
            if args.command == "two-beams":
                code = _two_beams(args)
            elif args.command == "run":
                code = _run(args, workers)
            elif args.command == "plot":
                code = _plot(args)
            else:
                code = EXIT_USAGE
            _raise_swallowed_interrupt()
            interrupts.end_of_run()  # (a run's writer said so already)
        except BaseException as error:  # noqa: BLE001  (every failure becomes a message and an exit code)
            interrupts.run_over = True  # first: a signal from here on cannot replace this outcome
            if isinstance(error, SystemExit):
                raise
            error = _interrupt_behind(error) or error
            code, message = _classify(error, args)
            if args.verbose >= 2:
                import traceback

                message += "\n" + "".join(traceback.format_exception(error))
    finally:  # a run that failed or was interrupted does not wait for them: they are killed
        if workers is not None:
            workers.close()
    code, message = collective.finish_collectively(code, message)
    if message and MPI.COMM_WORLD.rank == 0:
        print(message, file=sys.stderr, flush=True)
    from dolfinx_nnqem.io.field_series import hdf5_left_open

    if hdf5_left_open():  # HDF5's clean-up at exit would hang or abort on a file it cannot close
        collective.end_job(code)
    return code


def _start_picture_workers(args) -> PictureWorkers | None:
    """The picture workers of a command-line ``run`` that draws its pictures, on the rank that
    draws them (:mod:`dolfinx_nnqem.io.picture_worker`); None otherwise.

    Started before the imports of MPI, PETSc and DOLFINx, so that the workers import VTK
    while the run starts and solves; the rank is the launcher's (``mpiexec``) then.
    Not with ``--no-pictures``, ``--check``, ``DOLFINX_NNQEM_PICTURES=0``, in a job of several
    ranks or on one core (:func:`~dolfinx_nnqem.io.picture_worker.worth_starting`), nor in a
    user's program calling :func:`main`, which draws in its own process."""
    if args.command != "run" or args.no_pictures or args.check or not interrupts.is_command_line():
        return None
    from dolfinx_nnqem.io.picture_worker import PictureWorkers, launcher_rank, worth_starting

    if launcher_rank() not in (None, 0) or not worth_starting():
        return None
    from dolfinx_nnqem.io.run_pictures import pictures_enabled

    if not pictures_enabled():
        return None
    level = logging.ERROR if args.quiet else (logging.INFO if args.verbose >= 2 else logging.WARNING)
    return PictureWorkers(shown=args.verbose >= 1 and not args.quiet, level=level)


def _start_up() -> None:
    """The imports every command needs, once the command line has been read: MPI and PETSc (the
    PyPI wheel's ``dolfinx_solver`` first), with Ctrl-C and SIGTERM held again after PETSc's
    set-up (:func:`interrupts.hold_in_command_line`), then DOLFINx (:mod:`dolfinx_nnqem.compat`).

    numba is kept out of DOLFINx's import: FFCx (0.10 on) imports it, when it can, only for its
    helpers for user-written numba kernels, which this package does not use, and its import is
    0.1–0.2 s of CPU, a fifth of a small run. numba is imported where a pair-law kernel is
    compiled (:mod:`dolfinx_nnqem.contact.laws`), which a small run never needs. A caller that
    has DOLFINx already (a test calling :func:`main`) keeps its modules as they are.

    The command line's process makes these imports with Python's cyclic garbage collector off,
    then freezes what they made (:func:`gc.freeze`: never scanned again) and turns it back on.
    They create hundreds of thousands of long-lived objects and no garbage, and collecting while
    they grow scanned them again and again: 0.04–0.06 s of a 0.8 s run, 0.004–0.012 s this way
    (docs/performance.md). A user's program calling :func:`main` keeps its collector as it is.
    """
    if "dolfinx" in sys.modules:
        return
    interrupts.hold_in_command_line()
    keep_out = "numba" not in sys.modules
    if keep_out:
        sys.modules["numba"] = None  # type: ignore[assignment]  # None: importing it raises ImportError
    collecting = gc.isenabled() and interrupts.is_command_line()
    if collecting:
        gc.disable()
    try:
        import dolfinx_nnqem.compat  # noqa: F401
    finally:
        if keep_out and "numba" in sys.modules and sys.modules["numba"] is None:
            del sys.modules["numba"]
        if collecting:
            gc.freeze()
            gc.enable()


def _hold_signals() -> None:
    """Record Ctrl-C and SIGTERM (in ``interrupts.deferred``) instead of acting on
    them: during the imports and the MPI/PETSc set-up an exception would show a traceback, or
    PETSc's own SIGTERM handler its error dump (exit 15). ``dolfinx_nnqem/__init__.py`` holds them
    from the first import on in the command line (:mod:`dolfinx_nnqem.interrupts`)."""
    import signal

    try:
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, interrupts.defer)
    except ValueError:  # not the main thread (a test runner's worker): nothing to hold
        pass


def _raise_held_signal() -> None:
    """Act on an interrupt that arrived during the start-up: the contract's exception."""
    import signal

    if interrupts.deferred:
        first = interrupts.deferred[0]
        interrupts.deferred.clear()
        if first == signal.SIGTERM:
            _abort_unless_ended(EXIT_TERMINATED, "terminated (SIGTERM)")
            raise Terminated()
        _abort_unless_ended(EXIT_INTERRUPTED, "interrupted (Ctrl-C)")
        raise KeyboardInterrupt()


if __name__ == "__main__":
    sys.exit(main())
