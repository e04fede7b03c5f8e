"""The limit load of a rigid strip footing (``cases.strip_footing``, ``benchmarks/strip_footing_limit.py``,
``docs/verification-materials.md``): the closed forms, the mesh and its tags, the contact route equal
to prescribed displacements, a coarse limit load, every solver and both pair laws (NNEQM2's stated
refusal of Drucker–Prager), 2 ranks equal to serial; the 2 % runs on the chosen mesh are slow."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem import compat
from dolfinx_nnqem.cases import strip_footing as case
from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import strip_footing_limit as bench  # noqa: E402

SCRIPTS = Path(__file__).resolve().parents[1] / "mpi_scripts"


def footing_run(material, n: int = 1, increments: int = 3, settlement: float = 2.0e-5, method: str = "monolithic",
                law: str = "alart-curnier", comm=MPI.COMM_SELF, **kwargs):
    """The pressure after each increment, and the problem."""
    problem = case.strip_footing_problem(material, n, settlement=settlement, law=law, comm=comm, **kwargs)
    pressures = []
    with make_solver(method, problem, SolverOptions(rtol=1e-11, max_iterations=60)) as solver:
        solve_load_steps(problem, solver, increments, callbacks=[lambda r: pressures.append(case.footing_pressure(problem))])
    return np.array(pressures), problem


def test_closed_forms():
    """Prandtl's 2 + π and Prandtl–Reissner's N_c (the tabulated 8.345, 14.835, 30.140; → 2 + π as φ → 0)."""
    assert case.prandtl(1.0) == pytest.approx(5.14159265, rel=1e-9)
    n_c = {phi: case.prandtl_reissner(phi, 1.0) for phi in (10.0, 20.0, 30.0)}
    print(f"\n  N_c: {n_c}")
    assert list(n_c.values()) == pytest.approx([8.345, 14.835, 30.140], abs=1e-3)
    assert case.prandtl_reissner(1e-6, 1.0) == pytest.approx(2.0 + math.pi, rel=1e-6)


def test_mesh_tags_the_footing_and_the_free_surface():
    """The footing's facets cover x ∈ [0, 1] of the top, the free surface the rest; plane strain by
    u_z = 0 on both z faces of a one-element slab."""
    import dolfinx
    import ufl

    mesh, cell_tags, facet_tags = case.footing_mesh(MPI.COMM_SELF, 2)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=facet_tags)
    one = dolfinx.fem.Constant(mesh, 1.0)
    x = ufl.SpatialCoordinate(mesh)
    area = {tag: dolfinx.fem.assemble_scalar(dolfinx.fem.form(one * ds(tag)))
            for tag in (case.FOOTING, case.FREE, case.BOTTOM, case.SYMMETRY, case.FAR, case.ZFACES)}
    edge = dolfinx.fem.assemble_scalar(dolfinx.fem.form(x[0] * ds(case.FOOTING)))
    t = 0.5  # the slab is one fine element thick
    print(f"\n  areas {area}")
    assert area[case.FOOTING] == pytest.approx(t, rel=1e-12) and edge == pytest.approx(t / 2, rel=1e-12)
    assert area[case.FREE] == pytest.approx(19.0 * t, rel=1e-12)
    assert area[case.BOTTOM] == pytest.approx(20.0 * t, rel=1e-12)
    assert area[case.SYMMETRY] == pytest.approx(12.0 * t, rel=1e-12) and area[case.FAR] == pytest.approx(12.0 * t, rel=1e-12)
    assert area[case.ZFACES] == pytest.approx(2 * 20.0 * 12.0, rel=1e-12)
    assert len(np.unique(facet_tags.indices)) == len(facet_tags.indices)  # one tag per facet
    assert np.all(cell_tags.values == case.SOIL)


@pytest.mark.parametrize("footing", ["smooth", "rough"])
def test_the_rigid_obstacle_equals_prescribed_displacements(footing):
    """The plane obstacle in contact with the footing's facets (frictionless, or μ_f = 5: every pair
    sticks) gives the pressures of the footing's nodes moved down (and held in x)."""
    from dolfinx_nnqem.io.results import pair_table

    material = case.drucker_prager_soil(20.0)
    contact, problem = footing_run(material, footing=footing)
    states = set(pair_table(problem)["state_name"])
    prescribed, _ = footing_run(material, footing=footing, route="prescribed")
    difference = np.abs(contact - prescribed).max() / prescribed.max()
    print(f"\n  {footing}: q/c contact {np.round(contact / case.COHESION, 6).tolist()}, prescribed "
          f"{np.round(prescribed / case.COHESION, 6).tolist()}; difference {difference:.1e}; pair states {states}")
    assert states == ({"slip"} if footing == "smooth" else {"stick"})
    assert difference < 1e-8


def test_coarse_mesh_limit_load_of_von_mises():
    """n = 1 (h = b, Q2 with 2 × 2 × 2 Gauss points), smooth: the curve flattens (less than 0.5 %
    over the last 20 % of the settlement) within 10 % of Prandtl's (2 + π) c, above it as a coarse
    mesh is (measured +8.7 %; n = 2 gives +3.6 %, the 2 % on n = 8 is slow)."""
    result = bench.run("vm", "smooth", 1, 10)
    print(f"\n  q/c = {result['limit'] / case.COHESION:.4f}, Prandtl {case.prandtl(1.0):.4f}: {100 * result['error']:+.2f} %; "
          f"rise over the last 20 %: {100 * result['rise']:.3f} %")
    assert result["rise"] < 5e-3 and 0.0 < result["error"] < 0.10


def test_full_integration_locks():
    """Q2 with its full 3 × 3 × 3 Gauss points overestimates the limit load (volumetric locking under
    the isochoric flow of von Mises): above the reduced rule's on the same mesh and path."""
    material = case.von_mises_soil()
    reduced, _ = footing_run(material, increments=4, settlement=8e-5)
    full, _ = footing_run(material, increments=4, settlement=8e-5, quadrature_degree=4)
    print(f"\n  n = 1, q/c at d = 8e-5 b: reduced {reduced[-1] / case.COHESION:.4f}, full {full[-1] / case.COHESION:.4f}")
    assert full[-1] > 1.03 * reduced[-1]


def test_reduced_integration_leaves_no_zero_energy_mode():
    """2 × 2 × 2 Gauss points in Q2 elements: each horizontal row of elements has a zero-energy u_y
    mode unless a support holds u_y at the row's end; with the clamped far side the elastic stiffness
    (supports only, n = 1) has no zero eigenvalue, so NNEQM1 and NNEQM2 (which factorise it) work."""
    import scipy.linalg

    problem = case.strip_footing_problem(case.von_mises_soil(), 1, route="prescribed", comm=MPI.COMM_SELF)
    # getDenseArray is a view into the dense matrix's memory: keep the matrix until K is copied
    # (a view of a temporary read freed memory under petsc4py 3.22, Debian 13: a "negative eigenvalue")
    dense = problem.assemble_tangent().convert("dense")
    K = dense.getDenseArray().copy()
    dense.destroy()
    free = np.setdiff1d(np.arange(K.shape[0]), problem.bc_dofs)
    w = scipy.linalg.eigvalsh(K[np.ix_(free, free)])
    print(f"\n  {len(free)} free dofs: smallest eigenvalues / largest {np.round(w[:3] / w[-1], 9).tolist()}")
    assert w[0] > 1e-7 * w[-1]


@pytest.fixture(scope="module")
def monolithic_dp():
    return footing_run(case.drucker_prager_soil(20.0), footing="rough")[0]


@pytest.mark.parametrize("method, law", [("monolithic", "polar"), ("nneqm1", "alart-curnier"), ("nneqm1", "polar")])
def test_every_solver_and_law_gives_the_same_limit_state(monolithic_dp, method, law):
    """Drucker–Prager (φ = 20°), rough footing (every pair sticks), plastic from the second increment."""
    pressures, problem = footing_run(case.drucker_prager_soil(20.0), footing="rough", method=method, law=law)
    difference = np.abs(pressures - monolithic_dp).max() / monolithic_dp.max()
    print(f"\n  {method}/{law}: q/c {np.round(pressures / case.COHESION, 6).tolist()}, difference {difference:.1e}, "
          f"plastic points {problem.state.count_plastic_points()}")
    assert problem.state.count_plastic_points() > 0
    assert difference < 1e-8


@pytest.fixture(scope="module")
def monolithic_vm():
    return footing_run(case.von_mises_soil(), footing="rough", increments=2, settlement=1e-5)[0]


@pytest.mark.parametrize("law", ["alart-curnier", "polar"])
def test_nneqm2_refuses_drucker_prager_and_takes_von_mises(monolithic_vm, law):
    with pytest.raises(ValueError, match="volumetric plastic strain"):
        footing_run(case.drucker_prager_soil(20.0), method="nneqm2", law=law)
    nneqm2, problem = footing_run(case.von_mises_soil(), footing="rough", increments=2, settlement=1e-5,
                                  method="nneqm2", law=law)
    difference = np.abs(nneqm2 - monolithic_vm).max() / monolithic_vm.max()
    print(f"\n  nneqm2/{law}, von Mises: difference {difference:.1e}, plastic points {problem.state.count_plastic_points()}")
    assert problem.state.count_plastic_points() > 0 and difference < 1e-8


def test_problem_file_gives_the_python_run(tmp_path, monolithic_dp):
    """The rough footing on Drucker–Prager as a problem file (an XDMF mesh, ``quadrature_degree = 2``)."""
    import json

    from dolfinx_nnqem.cli import EXIT_OK, main
    from dolfinx_nnqem.problem.meshing import write_xdmf

    write_xdmf(tmp_path / "footing.xdmf", *case.footing_mesh(MPI.COMM_SELF, 1))
    toml = tmp_path / "footing.toml"
    toml.write_text(case.problem_file_text(case.drucker_prager_soil(20.0), "footing.xdmf", footing="rough",
                                           settlement=2.0e-5, increments=3, folder=str(tmp_path / "out")))
    assert main(["-q", "run", str(toml)]) == EXIT_OK
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    pressures = np.array([-f["footing"][1] for f in summary["obstacle_force_history"]])  # the slab is 1 thick
    difference = np.abs(pressures - monolithic_dp).max() / monolithic_dp.max()
    print(f"\n  problem file: q/c {np.round(pressures / case.COHESION, 6).tolist()}, difference from Python {difference:.1e}")
    assert summary["converged"] and difference < 1e-9


@pytest.mark.parametrize("value, match", [("0", "expected a value > 0"), ("9", "expected a value <= 8"),
                                          ('"two"', "expected a number"), ("2.5", "expected an integer")])
def test_problem_file_refuses_a_bad_quadrature_degree(tmp_path, value, match):
    from dolfinx_nnqem.problem.meshing import write_xdmf
    from dolfinx_nnqem.problem_file import ProblemFileError, load_problem_file

    write_xdmf(tmp_path / "footing.xdmf", *case.footing_mesh(MPI.COMM_SELF, 1))
    text = case.problem_file_text(case.von_mises_soil(), "footing.xdmf")
    (tmp_path / "p.toml").write_text(text.replace("quadrature_degree = 2", f"quadrature_degree = {value}"))
    with pytest.raises(ProblemFileError, match=rf"mesh\.quadrature_degree = .*{match}"):
        load_problem_file(tmp_path / "p.toml")


@pytest.mark.mpi
def test_two_ranks_match_serial(tmp_path, monolithic_dp):
    out = tmp_path / "out.npz"
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(SCRIPTS / "strip_footing.py"), str(out)]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=compat.mpi_environment())
    assert result.returncode == 0, f"{' '.join(cmd)} failed:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    parallel = np.load(out)
    difference = np.abs(parallel["pressures"] - monolithic_dp).max() / monolithic_dp.max()
    print(f"\n  2 ranks (cells per rank {parallel['cells'].tolist()}): q/c "
          f"{np.round(parallel['pressures'] / case.COHESION, 6).tolist()}, difference from serial {difference:.1e}")
    assert min(parallel["cells"]) > 0 and difference < 1e-8


@pytest.mark.slow
@pytest.mark.parametrize("footing", ["smooth", "rough"])
@pytest.mark.parametrize("soil", ["vm", "dp10", "dp20", "dp30"])
def test_limit_load_within_two_percent(soil, footing):
    """n = 8 (h = b/8), 20 increments: within 2 % of the closed form, on a plateau (less than 0.1 %
    over the last 20 % of the settlement); ``docs/verification-materials.md`` has the trend."""
    result = bench.run(soil, footing, 8, 20)
    print(f"\n  {soil}, {footing}: q/c = {result['limit'] / case.COHESION:.4f}, closed form "
          f"{result['target'] / case.COHESION:.4f}: {100 * result['error']:+.2f} %; rise {100 * result['rise']:.3f} %")
    assert result["rise"] < 1e-3 and abs(result["error"]) < 0.02
