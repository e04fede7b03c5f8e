"""Dual mortar in the current geometry (issue 27): segments, D, M, gaps and normals of the moved surfaces.

* Patch test after a slide: a block under a uniform pressure slid 2.4 facets along a much stiffer
  one (``cases.large_sliding.sliding_patch``, ν = 0): the pressure stays p at every slave node
  (1e-8), hexahedra and unstructured tetrahedra, monolithic and NNEQM1, both laws.
* A block slid 1.6 master facets, part of it then overhanging (pairs go): the force of a press
  made in place there, in the same (current) geometry.
* μ_f = 0.3: every closed pair on the Coulomb cone; the same slide from a problem file.
"""

import json

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem.cases.large_sliding import PATCH_PRESSURE, slave_force, sliding_blocks, sliding_patch
from dolfinx_nnqem.io import pair_table
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

CASES = [("monolithic", "alart-curnier"), ("monolithic", "polar"), ("nneqm1", "alart-curnier"),
         ("nneqm1", "polar")]
OPTIONS = SolverOptions(rtol=1e-10, max_iterations=40)


def _run(problem, method, increments):
    with make_solver(method, problem, OPTIONS) as solver:
        return solve_load_steps(problem, solver, increments)


def _upper_block_stress(problem) -> np.ndarray:
    """σ at the Gauss points of this rank's cells of the upper block, (n, 3, 3)."""
    cells = problem.cell_tags.indices[problem.cell_tags.values == T.body(2)]
    points = problem.state.W_scalar.dofmap.list[cells].ravel()
    return problem.state.sigma_n.x.array.reshape(-1, 3, 3)[points]


@pytest.mark.parametrize("cell_type", ["hexahedron", "tetrahedron"])
@pytest.mark.parametrize("method, law", CASES)
def test_mortar_patch_test_after_sliding(cell_type, method, law):
    problem = sliding_patch(cell_type=cell_type, law=law)
    results = _run(problem, method, 6)
    t = pair_table(problem)
    err_p = np.max(np.abs(t["pressure"] - PATCH_PRESSURE)) / PATCH_PRESSURE
    exact = np.zeros((3, 3))
    exact[1, 1] = -PATCH_PRESSURE
    err_sigma = MPI.COMM_WORLD.allreduce(float(np.abs(_upper_block_stress(problem) - exact).max(initial=0.0)),
                                         op=MPI.MAX) / PATCH_PRESSURE
    print(f"\n  {cell_type}, {method}/{law}: slid 0.6 (2.4 master facets): {problem.contact.describe()[0]}; "
          f"max |pressure − p|/p = {err_p:.1e}, upper block max |σ − σ_exact|/p = {err_sigma:.1e} (tolerance "
          f"1e-8); iterations {[r.iterations for r in results]}, solves {[r.report.geometry_passes for r in results]}")
    assert problem.num_pairs == len(t["pressure"]) > 0 and np.all(t["state_name"] == "slip")
    assert err_p < 1e-8 and err_sigma < 1e-8


@pytest.mark.parametrize("method, law", CASES)
def test_mortar_block_slid_equals_press_in_place(method, law):
    """Frictionless: the block slid 1.6 master facets ends with the force of a press made in place
    there (both in the current geometry: the reference geometry's press differs by 2 %, the
    geometry change of a 2 % strain); a third of the pairs go as the block overhangs."""
    slid = sliding_blocks(slide=0.4, law=law, discretisation="mortar")
    pairs_before = slid.num_pairs
    results = _run(slid, method, 12)
    in_place = sliding_blocks(slide=0.0, offset=0.4, law=law, discretisation="mortar")
    _run(in_place, method, 4)
    f_slid, f_place = slave_force(slid), slave_force(in_place)
    error = np.linalg.norm(f_slid - f_place) / np.linalg.norm(f_place)
    print(f"\n  {method}/{law}: mortar, slid 0.4: pairs {pairs_before} -> {slid.num_pairs}; F = {f_slid}, in place "
          f"{f_place}: |ΔF|/|F| = {error:.1e} (tolerance 1e-6); iterations {[r.iterations for r in results]}")
    assert pairs_before == 49 and slid.num_pairs == in_place.num_pairs == 28
    assert error < 1e-6


@pytest.mark.parametrize("method, law", [("monolithic", "alart-curnier"), ("nneqm1", "polar")])
def test_mortar_frictional_slide_on_the_cone(method, law):
    mu_f = 0.3
    problem = sliding_blocks(slide=0.4, law=law, mu_f=mu_f, discretisation="mortar")
    results = _run(problem, method, 12)
    t = pair_table(problem)
    local = -t["force_local_body1"]  # on the slave block: (p_n, q1, q2)
    closed = local[:, 0] > 0
    cone = np.abs(np.hypot(local[closed, 1], local[closed, 2]) - mu_f * local[closed, 0]).max() / (mu_f * local[:, 0].max())
    f = slave_force(problem)
    print(f"\n  {method}/{law}: {np.count_nonzero(closed)} closed pairs, max ||q| − μ_f p_n| / (μ_f max p_n) = "
          f"{cone:.1e} (tolerance 1e-8); F = {f}; iterations {[r.iterations for r in results]}")
    assert np.count_nonzero(closed) > 20 and np.all(t["state_name"][closed] == "slip") and cone < 1e-8
    assert f[0] < 0  # friction on the slave block opposes its slide along +x


def test_problem_file_mortar_in_current_geometry(tmp_path):
    """``discretisation = "mortar"`` with ``geometry = "current"`` from a problem file, through the CLI:
    the Python run's iterations."""
    from dolfinx_nnqem.cli import EXIT_OK, main
    from dolfinx_nnqem.cases.geometries import build_block_stack
    from test_large_sliding import BLOCKS_FILE

    if MPI.COMM_WORLD.size > 1:
        pytest.skip("the CLI test runs serially")
    build_block_stack(MPI.COMM_SELF, 1.0, 1.0, [0.5, 0.5], [(4, 2, 4), (6, 2, 6)], msh_file=tmp_path / "blocks.msh")
    text = (BLOCKS_FILE.replace("MESH", (tmp_path / "blocks.msh").as_posix()).replace("METHOD", "monolithic")
            .replace("LAW", "alart-curnier").replace('discretisation = "node-to-surface"', 'discretisation = "mortar"'))
    assert 'discretisation = "mortar"' in text
    path = tmp_path / "slide.toml"
    path.write_text(text)
    assert main(["-q", "run", str(path), "--out", str(tmp_path / "out")]) == EXIT_OK
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    python = [r.iterations for r in _run(sliding_blocks(slide=0.4, mu_f=0.3, discretisation="mortar"), "monolithic", 12)]
    print(f"\n  converged {summary['converged']}, iterations {summary['iterations']} (Python: {python})")
    assert summary["converged"] and summary["iterations"] == python


@pytest.mark.parametrize("discretisation", ["node-to-surface", "mortar"])
def test_slid_off_the_master_is_one_outcome(tmp_path, discretisation):
    """Issue 39, item 7: the upper block slid 1.2, off its master, in the current geometry. Node-to-surface
    and mortar end alike: the increment where no slave node faces the master is cut back, then the run
    stops with ConvergenceError naming the interface and the load factor; through the CLI exit code 1
    (not 3, "bad input") with ``failure`` in summary.json. Mortar used to end with exit 3 and no
    failure record."""
    from dolfinx_nnqem.cli import EXIT_DIVERGED, main
    from dolfinx_nnqem.cases.geometries import build_block_stack
    from dolfinx_nnqem.solvers import ConvergenceError, solve_load_steps
    from test_large_sliding import _blocks_file

    problem = sliding_blocks(slide=1.2, discretisation=discretisation)
    with make_solver("monolithic", problem, SolverOptions()) as solver:
        with pytest.raises(ConvergenceError) as error:
            solve_load_steps(problem, solver, 12)
    failure = error.value.failure
    print(f"\n  {discretisation}: {str(error.value).splitlines()[0]}")
    assert failure["cutbacks"] == 5 and 0.8 < failure["load_factor"] < 0.95
    assert failure["reason"] == (f"contact 201-102: no pairs in the current geometry at load factor "
                                 f"{failure['load_factor']:.6g}: no slave node faces the master surface any more "
                                 "(the bodies slid apart)")
    if MPI.COMM_WORLD.size > 1:
        return  # the CLI part runs serially
    build_block_stack(MPI.COMM_SELF, 1.0, 1.0, [0.5, 0.5], [(4, 2, 4), (6, 2, 6)], msh_file=tmp_path / "blocks.msh")
    text = (_blocks_file(E1=1.0e3, press=-0.01, pressed_at=0.25, slide=1.2, z_tags=[202], increments=12)
            .replace("MESH", (tmp_path / "blocks.msh").as_posix()).replace("METHOD", "monolithic")
            .replace("LAW", "alart-curnier").replace("mu_f = 0.3", "mu_f = 0.0")
            .replace('discretisation = "node-to-surface"', f'discretisation = "{discretisation}"'))
    (tmp_path / "off.toml").write_text(text)
    code = main(["-q", "run", str(tmp_path / "off.toml"), "--out", str(tmp_path / "out"), "--no-pictures"])
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    print(f"  CLI: exit {code}, status {summary['status']}, failure reason {summary['failure']['reason']}")
    assert code == EXIT_DIVERGED and summary["status"] == "not converged"
    assert "no pairs in the current geometry" in summary["failure"]["reason"]
