"""The sphere press against CalculiX 2.20 (``benchmarks/calculix_sphere_press.py``,
``docs/verification-materials.md``): opt in with ``-m slow``; skipped where ``ccx`` is not on PATH.

On the same mesh (h = 1/4 mm) and increments (5 per press and per lift), CalculiX's node-to-surface
penalty contact (500 E/h, a sphere of 0.05 mm facets, NLGEOM: CalculiX's kinematic and combined
hardening are right only in its finite-strain model, and the strains stay of order 10⁻³) and the
package give, for each press, the same peak force, residual depth and largest equivalent plastic
strain within 0.5 %: the tabulated isotropic law pressed once, the linear kinematic and the
combined laws pressed three times. p at every Gauss point of the fine zone agrees within 1 % of its
largest value.
"""

import shutil
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

from dolfinx_nnqem.cases import sphere_press as case

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import calculix_sphere_press as ccx_sphere  # noqa: E402

H, INCREMENTS = 0.25, 5


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("ccx") is None, reason="CalculiX (ccx) is not on PATH")
@pytest.mark.parametrize("material, cycles", [("table", 1), ("kinematic", 3), ("combined", 3)])
def test_sphere_press_agrees_with_calculix(tmp_path, material, cycles):
    problem = case.sphere_press_problem(H, material, cycles, comm=MPI.COMM_SELF)
    job = f"sphere_{material}"
    (tmp_path / f"{job}.inp").write_text(ccx_sphere.model_text(problem, material, cycles, INCREMENTS, h=H,
                                                               penalty_factor=500.0, facet=0.05))
    ccx_sphere.run_ccx(tmp_path, job)
    theirs = ccx_sphere.ccx_results(tmp_path / f"{job}.dat", INCREMENTS, cycles)
    ours = ccx_sphere.run_ours(problem, INCREMENTS, cycles)
    assert len(theirs["force"]) == len(ours["force"]) == 2 * cycles * INCREMENTS
    index = ccx_sphere.on_ours(theirs, ours)
    m_theirs = ccx_sphere.measures(theirs, INCREMENTS, cycles)
    m_ours = ccx_sphere.measures(ours, INCREMENTS, cycles, index)
    points = ccx_sphere.point_differences(theirs, ours, index, INCREMENTS, cycles)
    print(f"\n  CalculiX {m_theirs}\n  ours     {m_ours}\n  p at the points: {points}")
    for key in m_ours:
        assert m_theirs[key] == pytest.approx(m_ours[key], rel=5e-3), key
    assert max(points) < 1e-2
