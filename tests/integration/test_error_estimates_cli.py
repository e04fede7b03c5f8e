"""Error estimates and adaptivity from problem files and the command line (``[estimate]``,
``run --estimate``, ``run --target-error``): what the run prints and writes, and what it refuses."""

import json
import re

import pytest
from mpi4py import MPI
from problem_files import block_under_obstacle

from dolfinx_nnqem.cli import EXIT_BAD_INPUT, EXIT_OK, main
from dolfinx_nnqem.cases.geometries import build_block_stack
from dolfinx_nnqem.problem_file import ProblemFileError, load_problem_file

PROBLEM = block_under_obstacle('type = "sphere"\ncentre = [0.5, 1.5, 0.5]\nradius = 1.0\nmotion = [0.0, -0.02, 0.0]',
                               mu_f=0.0, increments=1,
                               more='[output]\npictures = false\n[output.probes]\n"top" = [0.5, 0.5, 0.5]\nESTIMATE\n')

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the command-line tests run serially")


def problem_file(tmp_path, *, cells="hexahedron", method="monolithic", estimate="", divisions=(4, 2, 4)):
    mesh = tmp_path / f"block_{cells}.msh"
    build_block_stack(MPI.COMM_SELF, 1.0, 1.0, [0.5], [divisions], cell_type=cells, structured=True, msh_file=mesh)
    path = tmp_path / "press.toml"
    path.write_text(PROBLEM.replace("MESH", mesh.as_posix()).replace("METHOD", method).replace("ESTIMATE", estimate))
    return path


@pytest.mark.parametrize("method", ["monolithic", "nneqm1"])
def test_run_estimate_prints_and_writes_every_quantity(tmp_path, capsys, method):
    path = problem_file(tmp_path, method=method)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--estimate"]) == EXIT_OK
    text = capsys.readouterr().out
    print("\n" + text)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    est = summary["error_estimates"]
    names = [q["name"] for q in est["quantities"]]
    assert names == ["contact:press", "reaction:101", "u:top", "max_p"]
    assert est["enrichment"] == "degree-2" and est["enriched_dofs"] > est["dofs"] and est["cost"] > 0
    assert "error estimates (enriched solve: degree 2 on the same mesh" in text and "u:top" in text and " ± " in text
    contact = est["quantities"][0]
    assert 0 < contact["relative"] < 0.5 and contact["estimate"] > 0


def test_the_estimate_is_off_by_default(tmp_path):
    path = problem_file(tmp_path)
    assert main(["-q", "run", str(path), "--out", str(tmp_path / "out")]) == EXIT_OK
    assert "error_estimates" not in json.loads((tmp_path / "out" / "summary.json").read_text())


def test_adaptivity_on_hexahedra_is_refused_before_solving(tmp_path, capsys):
    path = problem_file(tmp_path)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--target-error", "0.01"]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    print("\n" + err)
    assert "adaptive refinement needs a tetrahedral mesh" in err and "hexahedron" in err
    assert not (tmp_path / "out" / "summary.json").exists()


def test_adaptive_run_from_a_problem_file_refines_until_the_target(tmp_path, capsys):
    path = problem_file(tmp_path, cells="tetrahedron", divisions=(2, 1, 2),
                        estimate='[estimate]\ntarget_error = 0.02\nmax_cycles = 3\nquantities = ["contact"]\n'
                                 'enrichment = "refine"')
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == EXIT_OK
    text = capsys.readouterr().out
    print("\n" + text)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    cycles = summary["adaptivity"]["cycles"]
    dofs = [c["dofs"] for c in cycles]
    assert len(cycles) >= 2 and dofs == sorted(dofs) and len(set(dofs)) == len(dofs)
    assert summary["adaptivity"]["reached"] == (cycles[-1]["relative_error"] <= 0.02)
    assert summary["error_estimates"] == cycles[-1]["estimates"]
    assert summary["converged"] and "cycle 1:" in text


@pytest.mark.parametrize("table, message", [
    ("target_error = 1.5", re.escape("target_error = 1.5: a relative error in (0, 1)")),
    ("enrichment = 'p3'", "enrichment = 'p3'"),
    ("quantities = []", re.escape("quantities = []")),
    ("enabled = 1", "enabled must be true or false"),
    ("max_cycles = 0", "max_cycles = 0"),
    ("refine_fraction = 2.0", "refine_fraction = 2.0"),
    ("tolerance = 0.1", "unknown key"),
])
def test_bad_estimate_keys_are_named(tmp_path, table, message):
    path = problem_file(tmp_path, estimate=f"[estimate]\n{table}")
    with pytest.raises(ProblemFileError, match=message):
        load_problem_file(path)
