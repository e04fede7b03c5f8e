"""The deformed mesh in the field outputs (issue 41): ``fields_deformed.xdmf``.

A rigid sphere pressed into an elastoplastic block at finite strain (``tests/mpi_scripts/deformed_outputs.py``)
on 1 and 2 ranks: ``fields_deformed.xdmf`` lists the steps of ``fields.xdmf`` with the same topology
and fields, and its geometry at every step is X + u (the reference geometry and u of
``fields.xdmf``, read back with h5py); ``fields.xdmf`` is the same text as a run's without the
deformed mesh; a small-strain run writes it when asked, and not by default.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dolfinx_nnqem import compat
from dolfinx_nnqem.io.reader import read_fields

SCRIPTS = Path(__file__).resolve().parents[1] / "mpi_scripts"
sys.path.insert(0, str(SCRIPTS))

from deformed_outputs import INCREMENTS, write_run  # noqa: E402


def _check_deformed_index(folder: Path) -> float:
    """Every step of ``fields_deformed.xdmf`` is that of ``fields.xdmf`` on the geometry X + u;
    returns the largest |u| (so that a test sees the mesh moved)."""
    reference = read_fields(folder)
    deformed = read_fields(folder, index="fields_deformed.xdmf")
    assert [s["time"] for s in deformed] == [s["time"] for s in reference] and len(reference) == INCREMENTS
    for ref, moved in zip(reference, deformed):
        assert set(moved) == set(ref)
        for key in ref:
            if key != "geometry":
                assert np.array_equal(np.asarray(moved[key]), np.asarray(ref[key])), key
        X, u = np.asarray(ref["geometry"]), np.asarray(ref["u"]).reshape(len(ref["geometry"]), 3)
        assert np.abs(np.asarray(moved["geometry"]) - (X + u)).max() <= 1e-14 * np.abs(X).max()
    return float(np.abs(u).max())


def test_a_finite_strain_run_writes_its_deformed_mesh(tmp_path):
    """One rank: the deformed index holds X + u at every step; fields.xdmf is byte for byte the one
    written without the deformed mesh."""
    write_run(tmp_path / "finite")
    umax = _check_deformed_index(tmp_path / "finite")
    write_run(tmp_path / "without", deformed_mesh=False)
    assert not (tmp_path / "without" / "fields_deformed.xdmf").exists()
    same = (tmp_path / "finite" / "fields.xdmf").read_text() == (tmp_path / "without" / "fields.xdmf").read_text()
    print(f"\n  deformed mesh = X + u at {INCREMENTS} steps, largest |u| {umax:.3g}; fields.xdmf unchanged: {same}")
    assert umax > 0.04 and same  # the sphere went 0.05 in


def test_a_small_strain_run_writes_it_on_request_only(tmp_path):
    write_run(tmp_path / "asked", "small", deformed_mesh=True, depth=0.02)  # (deeper: over the small-strain limit)
    write_run(tmp_path / "default", "small", depth=0.02)
    assert _check_deformed_index(tmp_path / "asked") > 0.015
    assert not (tmp_path / "default" / "fields_deformed.xdmf").exists()


@pytest.mark.mpi
def test_the_deformed_mesh_on_two_ranks(tmp_path):
    """Two ranks: each writes its owned nodes moved by its u; read back, X + u at every step."""
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(SCRIPTS / "deformed_outputs.py"), str(tmp_path / "out")]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=compat.mpi_environment())
    assert run.returncode == 0, f"{' '.join(cmd)} failed:\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}"
    assert _check_deformed_index(tmp_path / "out") > 0.04
