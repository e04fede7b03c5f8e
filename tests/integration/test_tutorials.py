"""The tutorials: pages up to date with the demos, every figure there, the path in order, and the
new demo (a gmsh mesh of one's own) runs and draws its pictures, with a first- and a second-order
mesh."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import demos_to_docs  # noqa: E402


def test_pages_are_up_to_date_with_the_demos():
    stale = [p.name for p, text in demos_to_docs.pages().items() if not p.is_file() or p.read_text() != text]
    print(f"\n  {len(demos_to_docs.TUTORIALS)} tutorial pages, stale: {stale}")
    assert not stale, "run python scripts/demos_to_docs.py"


def test_every_figure_exists_and_the_path_is_in_order():
    index = (ROOT / "docs" / "tutorials.md").read_text()
    positions = []
    for step, demo, figures in demos_to_docs.TUTORIALS:
        page = ROOT / "docs" / "tutorials" / f"{Path(demo).stem}.md"
        for target in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", page.read_text()):
            assert (page.parent / target).is_file(), f"{page.name}: {target} missing"
        assert len(re.findall(r"!\[", page.read_text())) == len(figures)
        positions.append(index.index(f"(tutorials/{Path(demo).stem}.md)"))
    assert positions == sorted(positions), "docs/tutorials.md lists the demos out of the path's order"
    assert index.index("MPI and large meshes") > positions[-1]


def test_own_gmsh_mesh_demo_runs(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "DOLFINX_NNQEM_PICTURES"}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    run = subprocess.run([sys.executable, str(ROOT / "demos" / "own_gmsh_mesh.py"), "--out", str(tmp_path)],
                         capture_output=True, text=True, env=env, timeout=600, cwd=tmp_path)
    print("\n" + run.stdout + run.stderr[-2000:])
    assert run.returncode == 0
    summary = json.loads((tmp_path / "results" / "summary.json").read_text())
    assert summary["converged"] and summary["equilibrium_residual"] < 1e-8
    assert "mortar" in run.stdout  # non-matching faces: auto chose mortar
    assert (tmp_path / "results" / "pictures" / "deformed.png").is_file()


def test_own_gmsh_mesh_demo_runs_with_a_second_order_mesh(tmp_path):
    """``--order 2``: 10-node tetrahedra, quadratic elements, dual mortar pairs (auto), ``fields_p2.pvd``."""
    env = {k: v for k, v in os.environ.items() if k != "DOLFINX_NNQEM_PICTURES"}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    run = subprocess.run([sys.executable, str(ROOT / "demos" / "own_gmsh_mesh.py"), "--out", str(tmp_path),
                          "--order", "2"], capture_output=True, text=True, env=env, timeout=600, cwd=tmp_path)
    print("\n" + run.stdout + run.stderr[-2000:])
    assert run.returncode == 0
    from mpi4py import MPI

    from dolfinx_nnqem import compat
    from dolfinx_nnqem.problem.meshing import read_msh

    mesh = read_msh(tmp_path / "punch.msh", MPI.COMM_SELF).mesh
    assert compat.coordinate_element(mesh).degree == 2 and compat.geometry_dofmap(mesh).shape[1] == 10
    summary = json.loads((tmp_path / "results" / "summary.json").read_text())
    assert summary["converged"] and summary["equilibrium_residual"] < 1e-8
    assert "mortar" in run.stdout  # non-matching quadratic faces: auto chose mortar
    assert (tmp_path / "results" / "fields_p2.pvd").is_file()
    assert (tmp_path / "results" / "pictures" / "deformed.png").is_file()


def test_two_beams_concrete_demo_runs(tmp_path):
    """The Drucker–Prager concrete tutorial: the cone passes through C30/37's uniaxial strengths, the
    concrete beams yield later and less than the seed's von Mises ones, and the pictures are drawn."""
    env = {k: v for k, v in os.environ.items() if k != "DOLFINX_NNQEM_PICTURES"}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    run = subprocess.run([sys.executable, str(ROOT / "demos" / "two_beams_concrete.py"), "--out", str(tmp_path)],
                         capture_output=True, text=True, env=env, timeout=600, cwd=tmp_path)
    print("\n" + run.stdout + run.stderr[-2000:])
    assert run.returncode == 0
    assert "compression 30.000 MPa, tension 2.900 MPa" in run.stdout
    tables = (tmp_path / "tables.md").read_text()
    plastic = re.search(r"\| plastic Gauss points at the end \| (\d+) \| (\d+) \|", tables)
    first = re.search(r"\| first increment with a plastic point \| (\d+) \| (\d+) \|", tables)
    assert 0 < int(plastic.group(2)) < int(plastic.group(1)) and int(first.group(2)) > int(first.group(1))
    assert (tmp_path / "load_deflection.png").is_file() and (tmp_path / "plastic_zone.png").is_file()


def test_deep_ironing_demo_runs(tmp_path):
    """The finite-strain tutorial: the small-strain run is refused by max_strain, the deep ironing
    converges at finite strain with every state's figures in range (J > 0, the law in the logarithmic
    space, the shape ratio, p far past the small-strain range), the shallow answers of the two
    kinematics agree to the order of the strains, and the three pictures are drawn."""
    env = {k: v for k, v in os.environ.items() if k != "DOLFINX_NNQEM_PICTURES"}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    run = subprocess.run([sys.executable, str(ROOT / "demos" / "deep_ironing.py"), "--out", str(tmp_path)],
                         capture_output=True, text=True, env=env, timeout=900, cwd=tmp_path)
    print("\n" + run.stdout + run.stderr[-2000:])
    assert run.returncode == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert "exceeds max_strain = 0.1" in summary["small_strain_refusal"]
    deep = summary["deep_finite"]
    assert len(deep["load_factor"]) == 40 and abs(deep["load_factor"][-1] - 1.0) < 1e-12
    assert min(deep["min_J"]) > 0.5 and min(deep["min_shape_ratio"]) > 0.5
    assert max(deep["law_violation"]) < 1e-8 and max(deep["equilibrium"]) < 1e-8
    assert deep["max_p"][-1] > 0.3  # far past the small-strain range
    small, finite = (np.array([summary[k]["F_x"], summary[k]["F_y"]]) for k in ("shallow_small", "shallow_finite"))
    difference = np.abs(finite - small).max() / np.abs(small[1]).max()
    assert 1e-4 < difference < 0.05  # of the order of the strains (a few percent): close, not equal
    for name in ("forces.png", "plastic_strain.png", "cauchy_stress.png"):
        assert (tmp_path / name).is_file()
