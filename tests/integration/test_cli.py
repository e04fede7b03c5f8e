"""The command line and problem files: a real run, every malformed field named, exit codes."""

import json
from pathlib import Path

import pytest
from problem_files import two_beams_demo, two_beams_minimal

from dolfinx_nnqem.cli import EXIT_BAD_INPUT, EXIT_OK, EXIT_USAGE, main
from dolfinx_nnqem.problem_file import ProblemFileError, load_problem_file

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "demos" / "two_beams.toml"


def test_run_two_beams_problem_file(tmp_path):
    assert main(["-q", "run", str(EXAMPLE), "--out", str(tmp_path)]) == EXIT_OK
    summary = json.loads((tmp_path / "summary.json").read_text())
    print(f"\n  iterations {summary['iterations']}; equilibrium {summary['equilibrium_residual']:.2e}; "
          f"states {[p['state'] for p in summary['pairs']]}")
    assert summary["converged"] and len(summary["pairs"]) == 9
    assert summary["equilibrium_residual"] < 1e-8
    assert (tmp_path / "fields.xdmf").is_file() and (tmp_path / "pairs.pvd").is_file()
    assert len(list((tmp_path / "pairs").glob("pairs_*.csv"))) == 15


def _write(tmp_path, text):
    mesh = (ROOT / "meshes" / "two_beams.msh").as_posix()
    path = tmp_path / "p.toml"
    path.write_text(text.replace("MESH", mesh))
    return path


GOOD = two_beams_minimal("MESH")


@pytest.mark.parametrize("change, named", [
    (("[mesh]\nfile = \"MESH\"", "[mesh]\nfile = \"nope.msh\""), "mesh.file"),
    (("nu = 0.3", "nu = 0.6"), "nu"),
    (("E = 1.0e9", "E = \"stiff\""), "E"),
    (("mu_f = 0.3", "mu_f = -0.1"), "mu_f"),
    (("surface2 = 22", "surface2 = 21"), "surface1 and surface2"),
    (("[[dirichlet]]\ntag = 11", "[[dirichlet]]\ntag = 11\ncomponents = [3]"), "components"),
    (("[contact]", "[solver]\nmethod = \"newton\"\n[contact]"), "method"),
    (("[contact]", "[typo]\nx = 1\n[contact]"), "unknown section"),
    (("[contact]", "[solver]\nlinear_solver = \"gmres\"\n[contact]"), "linear_solver"),
    (("[contact]", "[solver]\nmethod = \"nneqm1\"\nlinear_solver = \"iterative\"\n[contact]"), "linear_solver"),
    (("mu_f = 0.3", "mu_f = 0.3\nfriction = 1"), "unknown key"),
    (("[materials.1]", "[materials.one]"), "cell tag"),
])
def test_malformed_problem_files_name_the_key(tmp_path, change, named):
    old, new = change
    assert old in GOOD
    path = _write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(ProblemFileError) as error:
        load_problem_file(path)
    print(f"\n  {error.value}")
    assert named in str(error.value)


def test_inconsistent_tags_are_reported_with_exit_code_3(tmp_path, capsys):
    path = _write(tmp_path, GOOD.replace("tag = 12", "tag = 99"))
    assert main(["run", str(path), "--check"]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    print(f"\n  {err.strip()}")
    assert "99" in err


def test_usage_errors_exit_with_code_2(capsys):
    assert main(["run", str(EXAMPLE), "--increments", "0"]) == EXIT_USAGE
    assert main(["plot", str(ROOT), "--scale", "nan"]) == EXIT_USAGE
    with pytest.raises(SystemExit) as error:
        main(["two-beams", "--method", "fastest"])
    assert error.value.code == EXIT_USAGE


def test_problem_file_with_an_xdmf_mesh(tmp_path):
    """An XDMF mesh with cell and facet tags works like the .msh (same pairs, same answer)."""
    from dolfinx.io import XDMFFile
    from mpi4py import MPI

    from dolfinx_nnqem.cases.geometries import build_two_beams

    mesh, cell_tags, facet_tags = build_two_beams(MPI.COMM_WORLD)
    cell_tags.name, facet_tags.name = "cell_tags", "facet_tags"
    with XDMFFile(MPI.COMM_WORLD, tmp_path / "beams.xdmf", "w") as xdmf:
        xdmf.write_mesh(mesh)
        mesh.topology.create_connectivity(2, 3)
        xdmf.write_meshtags(cell_tags, mesh.geometry)
        xdmf.write_meshtags(facet_tags, mesh.geometry)
    (tmp_path / "p.toml").write_text(two_beams_demo((tmp_path / "beams.xdmf").as_posix(), solver_lines="increments = 3"))
    assert main(["-q", "run", str(tmp_path / "p.toml"), "--out", str(tmp_path / "out")]) == EXIT_OK
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    print(f"\n  XDMF mesh: {summary['num_pairs']} pairs, iterations {summary['iterations']}, "
          f"equilibrium {summary['equilibrium_residual']:.1e}")
    assert summary["num_pairs"] == 9 and summary["converged"]


def test_three_blocks_problem_file(tmp_path):
    """Two [[contact]] tables and amplitude tables: the lower interface slides at μ_low p A."""
    assert main(["-q", "run", str(ROOT / "demos" / "three_blocks.toml"), "--out", str(tmp_path)]) == EXIT_OK
    summary = json.loads((tmp_path / "summary.json").read_text())
    pairs = summary["pairs"]
    friction = {name: sum(p["force_on_body1"][0] for p in pairs if p["interface"] == name) for name in ("lower", "upper")}
    states = {name: {p["state"] for p in pairs if p["interface"] == name} for name in ("lower", "upper")}
    err = abs(friction["lower"] - 0.2 * 1.0e6) / (0.2 * 1.0e6)
    print(f"\n  friction per interface {friction}, states {states}: |F_lower − μ_low p A| / μ_low p A = {err:.1e}")
    assert summary["converged"] and err < 1e-8 and abs(friction["upper"] - friction["lower"]) < 1e-8 * 2e5
    assert "stick" not in states["lower"] and "stick" in states["upper"]


def test_an_interrupt_inside_compiled_code_is_still_an_interrupt():
    """numba returns a SystemError caused by the KeyboardInterrupt when Ctrl-C lands in a kernel."""
    from dolfinx_nnqem.cli import Terminated, _interrupt_behind

    for signal_error in (KeyboardInterrupt(), Terminated()):
        try:
            try:
                raise signal_error
            except KeyboardInterrupt as interrupt:
                raise SystemError("CPUDispatcher(<function kernel>) returned a result with an exception set") from interrupt
        except SystemError as error:
            assert _interrupt_behind(error) is signal_error
    assert _interrupt_behind(ValueError("a bad value")) is None


def test_run_verbose_prints_a_line_per_increment(tmp_path, capsys):
    """Issue 31, item 9: ``run -v`` printed no line per increment although ``--help`` says so."""
    (tmp_path / "p.toml").write_text(two_beams_demo(solver_lines="increments = 3"))
    assert main(["-v", "run", str(tmp_path / "p.toml"), "--out", str(tmp_path / "out")]) == EXIT_OK
    lines = [line for line in capsys.readouterr().out.splitlines() if "] increment " in line]
    print("\n  " + "\n  ".join(lines))
    assert len(lines) == 3 and lines[-1].startswith("[monolithic] increment 3: load factor 1 converged in")


def test_two_beams_quiet_is_quiet_without_a_display(tmp_path):
    """Issue 31, item 9: ``two-beams -q`` without fields drew contact_pressure.png with VTK's log
    at its default level: "bad X server connection. DISPLAY=" on a machine without a display.
    Where VTK renders through X only (Debian 13's VTK 9.3), the process used to abort (SIGABRT)
    there: the pictures are skipped with the reason instead (the curves too since VTK's charts
    draw them, issue 43)."""
    import os
    import subprocess
    import sys

    from reliability_helpers import env

    e = {k: v for k, v in env().items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    e["DOLFINX_NNQEM_PICTURES"] = "1"
    probe = subprocess.run([sys.executable, "-c", "from dolfinx_nnqem import chatter, compat; "
                            "chatter.apply_vtk_options(); print(compat.vtk_render_problem())"],
                           env=e, capture_output=True, text=True, timeout=120)
    can_render = probe.stdout.strip().splitlines()[-1] == "None"
    run = subprocess.run([sys.executable, "-m", "dolfinx_nnqem", "two-beams", "-q", "--increments", "2", "--no-fields",
                          "--out", str(tmp_path / "out")], env=e, capture_output=True, text=True, timeout=300)
    drawn = sorted(os.listdir(tmp_path / "out" / "pictures"))
    print(f"\n  VTK renders without a display: {can_render}; exit {run.returncode}, stdout {run.stdout!r}, "
          f"stderr {run.stderr!r}, pictures {drawn}")
    assert run.returncode == EXIT_OK and run.stdout == "" and run.stderr == ""
    assert ("contact_pressure.png" in drawn) == can_render and ("load_curve.png" in drawn) == can_render


def test_a_picture_vtk_cannot_render_is_skipped_with_the_reason(tmp_path, monkeypatch):
    """Where VTK cannot render (no display, a VTK without off-screen rendering) the pictures name
    the reason and the run goes on: the 3D pictures and the curves (VTK's charts, issue 43)."""
    from dolfinx_nnqem import pyvista_compat
    from dolfinx_nnqem.io.run_pictures import draw_run_pictures

    monkeypatch.setattr(pyvista_compat, "vtk_render_problem", lambda: "no display (a test)")
    out = tmp_path / "out"
    assert main(["-q", "two-beams", "--increments", "1", "--out", str(out)]) == EXIT_OK
    drawn = draw_run_pictures(out, out=tmp_path / "pictures")
    print(f"\n  {drawn}")
    for name in ("deformed.png", "load_curve.png", "convergence.png", "pair_pressure.png"):
        assert drawn[name] == "not drawn: no display (a test)", name


def test_the_command_line_reads_its_arguments_before_the_heavy_imports():
    """Issue 32: ``--help`` and a bad command line import neither MPI nor PETSc nor DOLFINx (they
    took 1 s before). Issue 42: the command line's methods and laws are the solvers' and the laws'
    own list (``dolfinx_nnqem.names``), not a copy."""
    import subprocess
    import sys

    from reliability_helpers import env

    from dolfinx_nnqem import cli, names, problem_file
    from dolfinx_nnqem.contact import laws
    from dolfinx_nnqem.solvers import options

    assert cli.METHODS is options.METHODS is problem_file.METHODS is names.METHODS
    assert cli.LAW_NAMES is problem_file.LAW_NAMES is laws.LAW_NAMES is names.LAW_NAMES
    for args in (["--help"], ["run", "--help"], ["run", "--increments", "0", "p.toml"]):
        run = subprocess.run([sys.executable, "-X", "importtime", "-m", "dolfinx_nnqem", *args], env=env(),
                             capture_output=True, text=True, timeout=120)
        imported = {line.split("|")[-1].strip() for line in run.stderr.splitlines() if line.startswith("import time:")}
        heavy = sorted(imported & {"mpi4py", "petsc4py", "dolfinx", "dolfinx_solver", "numpy", "numba"})
        print(f"\n  {' '.join(args)}: exit {run.returncode}, {len(imported)} modules imported, of the heavy ones {heavy}")
        assert run.returncode == (EXIT_USAGE if "0" in args else EXIT_OK) and heavy == []


def test_a_small_run_does_not_import_numba(tmp_path):
    """Issue 32: the two-beam run evaluates its pair laws as Python (laws._CompiledWhenItPays) and
    keeps numba out of DOLFINx's import (cli._start_up): numba's import and start cost a run of
    this size a third of its CPU time."""
    import subprocess
    import sys

    from reliability_helpers import env, problem_file

    p = problem_file(tmp_path, increments=2)
    run = subprocess.run([sys.executable, "-X", "importtime", "-m", "dolfinx_nnqem", "-q", "run", str(p), "--out",
                          str(tmp_path / "out"), "--no-pictures"], env=env(), capture_output=True, text=True,
                         timeout=300)
    imported = {line.split("|")[-1].strip() for line in run.stderr.splitlines() if line.startswith("import time:")}
    numba = sorted(m for m in imported if m.startswith("numba."))
    print(f"\n  exit {run.returncode}; {len(imported)} modules imported; numba's modules among them: {numba[:5]}")
    assert run.returncode == EXIT_OK and numba == [] and "dolfinx.fem.petsc" in imported
