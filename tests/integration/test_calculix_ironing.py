"""The ironing case against CalculiX 2.20 (``benchmarks/calculix_ironing.py``, docs/theory.md,
"Large sliding"): opt in with ``-m slow``; skipped where ``ccx`` is not on PATH.

On nx = 16, CalculiX's node-to-surface penalty contact (slope 500 E/h, a punch of 120 facets)
and the package's exact contact on the same mesh and increments give the same steady-ironing
means. The tolerances are those the penalty, the faceting and CalculiX's sub-increments leave
(each moves the means by at most 0.3 % in the measured study: 1 % for the normal force, 2 % for
the tangential one, a small difference of larger terms).
"""

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem.cases.large_sliding import ironing

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import calculix_ironing as ccx_ironing


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("ccx") is None, reason="CalculiX (ccx) is not on PATH")
def test_ironing_forces_agree_with_calculix(tmp_path):
    nx = 16
    increments = int(2.5 * nx)
    problem = ironing(nx, comm=MPI.COMM_SELF)
    punch = problem.contact.interfaces[0].contact.obstacle
    job = "ironing"
    (tmp_path / f"{job}.inp").write_text(
        ccx_ironing.model_text(problem, nx, increments, penalty_factor=500.0, contact="node-to-surface"))
    ccx_ironing.run_ccx(tmp_path, job)
    theirs = ccx_ironing.read_reaction_history(tmp_path / f"{job}.dat")
    ours, _ = ccx_ironing.run_ours(problem, increments)
    assert len(theirs) == len(ours) == increments
    np.testing.assert_allclose(theirs[:, 0], ours[:, 0], atol=1e-9)  # the same load factors
    x = ccx_ironing.punch_x(ours, punch)
    m_theirs, m_ours = ccx_ironing.measures(theirs, x), ccx_ironing.measures(ours, x)
    print(f"\n  CalculiX {m_theirs}\n  ours     {m_ours}")
    assert m_theirs["mean F_n"] == pytest.approx(m_ours["mean F_n"], rel=0.01)
    assert m_theirs["mean F_t"] == pytest.approx(m_ours["mean F_t"], rel=0.02)
    assert m_theirs["peak F_n"] == pytest.approx(m_ours["peak F_n"], rel=0.01)
