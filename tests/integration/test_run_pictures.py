"""What a user sees after ``dolfinx-nnqem run``: the pictures, drawn without asking (also after a
failed increment), redrawn by ``dolfinx-nnqem plot``, and a default output of the package's own
lines only (gmsh's lines with -v)."""

import json
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from problem_files import TWO_BEAMS_MSH, two_beams_demo

from dolfinx_nnqem.cli import EXIT_DIVERGED, EXIT_IO, EXIT_OK, main
from dolfinx_nnqem.io.run_pictures import ENV_SWITCH, PICTURES

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "demos" / "two_beams.toml"
# every line `run` prints by default: the problem's size, its interfaces, the end, the pictures
OWN_LINE = re.compile(r"^(\S+\.toml: \d+ displacement dofs|  contact |converged: |pictures: )")


def _command(*args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != ENV_SWITCH}  # the user's default: pictures on
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.run([sys.executable, "-m", "dolfinx_nnqem", *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=600)


def _inked_fraction(path: Path) -> float:
    """The fraction of pixels that are not background white (0 for a blank picture)."""
    import matplotlib.image

    image = matplotlib.image.imread(path)[..., :3]
    return float(np.mean(np.any(image < 0.95, axis=-1)))


@pytest.fixture(scope="module")
def two_beam_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "two_beams"
    done = _command("run", str(EXAMPLE), "--increments", "2", "--out", str(out))
    assert done.returncode == 0, done.stderr
    return out, done


def test_run_draws_the_pictures_without_asking(two_beam_run):
    out, _ = two_beam_run
    assert not (out / "pictures" / "error_estimates.png").exists()  # drawn with --estimate only
    for name in (name for name in PICTURES if name != "error_estimates.png"):
        path = out / "pictures" / name
        inked = _inked_fraction(path)
        print(f"\n  {name}: {path.stat().st_size} bytes, {100 * inked:.1f} % of the pixels drawn", end="")
        assert inked > 0.02, f"{name} is blank"
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["reaction_history"]) == len(summary["load_factors"]) == 2
    assert len(summary["probe_history"]) == 2 and len(summary["probe_history"][0]) == len(summary["probes"])
    assert summary["reaction_history"][-1] == summary["reactions"]


def test_default_output_is_only_the_packages_lines(two_beam_run):
    _, done = two_beam_run
    lines = (done.stdout + done.stderr).splitlines()
    print("\n  " + "\n  ".join(lines))
    foreign = [line for line in lines if not OWN_LINE.match(line)]
    assert not foreign, f"lines that are not the package's: {foreign}"
    assert any(line.startswith("pictures: ") for line in lines)


def test_verbose_shows_gmsh(tmp_path, capfd):
    from dolfinx_nnqem.chatter import show_third_party_output

    # the .msh: the demo reads the same mesh as XDMF, without gmsh
    (tmp_path / "p.toml").write_text(two_beams_demo(TWO_BEAMS_MSH))
    try:  # in this process: capfd captures what gmsh writes to the C-level stdout
        assert main(["-v", "run", str(tmp_path / "p.toml"), "--check", "--out", str(tmp_path / "out")]) == EXIT_OK
    finally:
        show_third_party_output(False)
    gmsh_lines = [line for line in capfd.readouterr().out.splitlines() if line.startswith("Info")]
    print(f"\n  with -v, {len(gmsh_lines)} gmsh lines, e.g. {gmsh_lines[:1]}")
    assert any("Reading" in line for line in gmsh_lines)


def _failing_problem(tmp_path: Path) -> Path:
    """Two beams in 2 increments whose second multiplies the loads by 30: the strain check
    (max_strain 0.005) rejects it without cutbacks; increment 1 converges (strain ~4e-4)."""
    text = two_beams_demo()
    ramp = "amplitude = [[0.0, 0.0], [0.5, 1.0], [1.0, 30.0]]"
    text = text.replace("value = [1.0e5, -1.0e5, 0.5e5]", f"value = [1.0e5, -1.0e5, 0.5e5]\n{ramp}")
    text = text.replace("g = [0.0, -9.81, 0.0]", f"g = [0.0, -9.81, 0.0]\n{ramp}")
    text = text.replace("increments = 15", "increments = 2\nmax_cutbacks = 0")
    path = tmp_path / "failing.toml"
    path.write_text(text + "\n[checks]\nmax_strain = 0.005\n")
    return path


def test_a_failed_run_draws_its_converged_increments(tmp_path, monkeypatch):
    monkeypatch.delenv(ENV_SWITCH, raising=False)
    out = tmp_path / "out"
    assert main(["-q", "run", str(_failing_problem(tmp_path)), "--out", str(out)]) == EXIT_DIVERGED
    summary = json.loads((out / "summary.json").read_text())
    print(f"\n  status {summary['status']!r}, converged load factors {summary['load_factors']}")
    assert summary["status"] == "not converged" and summary["load_factors"] == [0.5]
    for name in (name for name in PICTURES if name != "error_estimates.png"):  # (drawn with --estimate)
        assert _inked_fraction(out / "pictures" / name) > 0.02, name


def test_plot_redraws_from_the_folder(two_beam_run, tmp_path):
    out, _ = two_beam_run
    redrawn = tmp_path / "restyled"
    assert main(["-q", "plot", str(out), "--out", str(redrawn), "--field", "p", "--scale", "50",
                 "--camera", "xy"]) == EXIT_OK
    for name in (name for name in PICTURES if name != "error_estimates.png"):  # (drawn with --estimate)
        assert _inked_fraction(redrawn / name) > 0.02, name
    # another field and view: another deformed picture
    from matplotlib.image import imread

    assert not np.array_equal(imread(redrawn / "deformed.png"), imread(out / "pictures" / "deformed.png"))
    assert main(["-q", "plot", str(tmp_path / "no_such_run")]) == EXIT_IO


def test_pictures_can_be_turned_off(tmp_path, monkeypatch):
    monkeypatch.delenv(ENV_SWITCH, raising=False)
    out = tmp_path / "out"
    assert main(["-q", "run", str(EXAMPLE), "--increments", "1", "--out", str(out), "--no-pictures"]) == EXIT_OK
    assert (out / "summary.json").is_file() and not (out / "pictures").exists()
    from dolfinx_nnqem.problem_file import ProblemFileError, load_problem_file

    text = two_beams_demo().replace("[output]", "[output]\npictures = false")
    (tmp_path / "p.toml").write_text(text)
    assert load_problem_file(tmp_path / "p.toml").output["pictures"] is False
    (tmp_path / "p.toml").write_text(text.replace("pictures = false", 'pictures = "no"'))
    with pytest.raises(ProblemFileError, match="pictures"):
        load_problem_file(tmp_path / "p.toml")


def _degree_2_problem(tmp_path: Path) -> Path:
    """The two beams with a quadratic displacement (``degree = 2``) on their first-order mesh."""
    text = two_beams_demo(mesh_keys="degree = 2")
    path = tmp_path / "quadratic.toml"
    path.write_text(text)
    return path


def _nodes_and_displacements(points, u) -> np.ndarray:
    """Rows (x, y, z, ux, uy, uz) sorted: the same set of nodal values whatever their order."""
    rows = np.hstack([np.asarray(points, dtype=float), np.asarray(u, dtype=float).reshape(len(points), 3)])
    keys = np.round(rows[:, :3], 9) + 0.0  # by position; round-off (and -0.0) must not reorder
    return rows[np.lexsort(keys.T[::-1])]


def test_a_degree_2_run_draws_its_quadratic_displacement(tmp_path, monkeypatch):
    """deformed.png of a degree-2 run is drawn from u at every P2 node (fields_p2.pvd's values),
    at the end of the run (from memory) and when redrawn (from fields_p2.pvd), not from the
    vertex values of fields.xdmf."""
    import pyvista

    from dolfinx_nnqem.io import deformed_picture, run_pictures
    from dolfinx_nnqem.io.reader import read_fields

    monkeypatch.delenv(ENV_SWITCH, raising=False)
    drawn: list[dict] = []

    class Recorded(deformed_picture.DeformedScene):  # one scene for deformed.png and error_indicator.png
        def __init__(self, step, *args, **kwargs):
            drawn.append(step)
            super().__init__(step, *args, **kwargs)

    monkeypatch.setattr(run_pictures, "DeformedScene", Recorded)
    out = tmp_path / "out"
    assert main(["-q", "run", str(_degree_2_problem(tmp_path)), "--increments", "1", "--out", str(out)]) == EXIT_OK
    assert main(["-q", "plot", str(out), "--out", str(tmp_path / "redrawn")]) == EXIT_OK
    assert len(drawn) == 2, "deformed.png drawn at the end of the run and by plot"
    last = [d.attrib["file"] for d in ET.parse(out / "fields_p2.pvd").iter("DataSet")][-1]
    quadratic = pyvista.read(str(out / last))
    vertices = read_fields(out, last_only=True)[-1]["geometry"]
    expected = _nodes_and_displacements(quadratic.points, quadratic.point_data["u"])
    for where, step in zip(("end of the run", "plot"), drawn):
        grid, _ = deformed_picture._field_grid(step, 1.0)  # a VTK grid
        celltypes = np.array([grid.GetCellType(k) for k in range(grid.GetNumberOfCells())])
        print(f"\n  {where}: {grid.GetNumberOfPoints()} nodes, {grid.GetNumberOfCells()} cells of VTK type "
              f"{celltypes[0]} drawn (fields_p2.pvd: {quadratic.n_points} nodes; fields.xdmf: {len(vertices)} "
              "vertices)", end="")
        assert grid.GetNumberOfPoints() == quadratic.n_points > len(vertices)
        assert grid.GetNumberOfCells() == quadratic.n_cells and np.all(celltypes == quadratic.celltypes)
        np.testing.assert_allclose(_nodes_and_displacements(step["geometry"], step["u"]), expected, rtol=0, atol=1e-12)
        assert _inked_fraction(out / "pictures" / "deformed.png") > 0.02
