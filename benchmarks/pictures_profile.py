"""Where the end-of-run pictures spend their time: one run of a problem file, its picture step
timed stage by stage (wall and CPU seconds).

    python benchmarks/pictures_profile.py [demos/two_beams.toml] [--repeat 3]

Each repeat is a whole run in this process (``cli.main``), so later repeats find the libraries
imported already: only the first repeat shows the import costs a command-line run pays. A run
here draws in this process; the command line has picture workers draw them
(``dolfinx_nnqem/io/picture_worker.py``). For the whole-process figure (a run with against one
without pictures) time the command line from outside.
Prints figures; asserts nothing.
"""

import argparse
import functools
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _timed(log: list, owner, name: str, label: str) -> None:
    """Wrap ``owner.name`` so that each call appends (label, wall s, CPU s) to ``log``; a stage
    this version of the package does not have is left out (the script also times older ones)."""
    function = getattr(owner, name, None)
    if function is None:
        return

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        wall, cpu = time.perf_counter(), time.process_time()
        try:
            return function(*args, **kwargs)
        finally:
            log.append((label, time.perf_counter() - wall, time.process_time() - cpu))

    setattr(owner, name, wrapper)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("problem", nargs="?", default=str(ROOT / "demos" / "two_beams.toml"))
    parser.add_argument("--repeat", type=int, default=1)
    args = parser.parse_args()

    started = time.perf_counter()
    from dolfinx_nnqem import cli
    from dolfinx_nnqem.io import deformed_picture, output, plots, run_pictures

    log: list[tuple[str, float, float]] = []
    # the stages, innermost first: each label's time includes the stages nested in it
    _timed(log, output.ResultsWriter, "_last_field_step", "fields gathered from memory")
    _timed(log, run_pictures, "_matplotlib", "curves: matplotlib (first: imported)")
    _timed(log, run_pictures, "draw_pair_pressure", "pair_pressure.png")
    _timed(log, run_pictures, "draw_load_curve", "load_curve.png")
    _timed(log, run_pictures, "draw_convergence", "convergence.png")
    _timed(log, deformed_picture, "_field_grid", "deformed: grid (first: pyvista imported)")
    _timed(log, deformed_picture, "offscreen_plotter", "deformed: plotter (first: pyvista.plotting, VTK)")
    _timed(log, run_pictures, "draw_deformed", "deformed.png in all")
    _timed(log, plots, "plot_contact_pressure", "contact_pressure.png")  # (older versions)
    _timed(log, plots, "draw_contact_pressure", "contact_pressure.png")
    _timed(log, output.ResultsWriter, "_draw_pictures", "picture step in all")
    print(f"{sys.argv[0]}: {args.problem}, Python {sys.version.split()[0]}")
    for repeat in range(args.repeat):
        log.clear()
        with tempfile.TemporaryDirectory() as folder:
            cli.main(["-q", "run", args.problem, "--out", folder, "--overwrite"])
        print(f"\nrun {repeat + 1}{' (imports included)' if repeat == 0 else ''}:")
        for label, wall, cpu in log:
            print(f"  {label:50s} wall {wall:6.3f} s   CPU {cpu:6.3f} s")
    print(f"\nthis process: {time.perf_counter() - started:.2f} s")


if __name__ == "__main__":
    main()
