"""Large sliding on 2 and 3 ranks: the serial answer (issue 27).

The cases of tests/mpi_scripts/large_sliding.py (a sphere slid over a block; a frictional block slid
1.6 master facets over another, node-to-surface and dual mortar; a cylinder ironing an elastoplastic strip). Every rank evaluates the node-to-surface pairs
from the gathered surfaces, with the displacements of their nodes summed over the ranks, so a
slave node finds its master facet on whichever rank holds it. Pairs are owned by the rank of their
slave node, so they are compared after sorting by the slave node's position. NNEQM2 (current
geometry since issue 41) on the sphere and the block slide, on 2 ranks. The sphere slid over Q2
hexahedra (degree 2, issue 41) with every solver, on 2 ranks.
"""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem import compat

SCRIPTS = Path(__file__).resolve().parents[1] / "mpi_scripts"
sys.path.insert(0, str(SCRIPTS))

from large_sliding import DEGREE_1, METHODS, solve  # noqa: E402


def _order(position):
    x = position.round(9)
    return np.lexsort((x[:, 2], x[:, 1], x[:, 0]))


@pytest.fixture(scope="module")
def serial():
    return {(case, method): solve(case, method, MPI.COMM_SELF) for case in DEGREE_1 for method in METHODS}


@pytest.mark.mpi
@pytest.mark.parametrize("ranks, cases", [(2, DEGREE_1), (3, ("sphere", "blocks"))])  # 3 ranks: time
def test_large_sliding_on_several_ranks_matches_serial(ranks, cases, serial, tmp_path):
    out = tmp_path / "out.npz"
    cmd = [*compat.mpiexec(), "-n", str(ranks), sys.executable, str(SCRIPTS / "large_sliding.py"), str(out), *cases]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=compat.mpi_environment())
    assert run.returncode == 0, f"{' '.join(cmd)} failed:\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}"
    parallel = dict(np.load(out))
    for case in cases:
        for method in METHODS:
            s = serial[case, method]
            p = {key.rsplit("/", 1)[1]: value for key, value in parallel.items() if key.startswith(f"{case}/{method}/")}
            i, j = _order(p["position"]), _order(s["position"])
            df = np.abs(p["force"][i] - s["force"][j]).max() / np.abs(s["force"]).max()
            dF = np.linalg.norm(p["total"] - s["total"]) / np.linalg.norm(s["total"])
            print(f"\n  {case}/{method}, {ranks} ranks vs serial: {len(i)} pairs (per rank {p['pairs_per_rank'].tolist()}); "
                  f"{int(p['foreign_masters'])} with a master node on another rank; "
                  f"pair forces {df:.1e}, resultant {dF:.1e} (tolerance 1e-8); iterations serial "
                  f"{s['iterations'].tolist()}, {ranks} ranks {p['iterations'].tolist()}")
            assert len(i) == len(j) and np.abs(p["position"][i] - s["position"][j]).max() < 1e-9
            if ranks == 2 or case == "blocks":
                assert np.count_nonzero(p["pairs_per_rank"]) >= 2  # the pairs are split
            assert df < 1e-8 and dF < 1e-8
            assert p["following"].all() and s["following"].all()  # "auto" moved the ironing to the current geometry
            if case == "blocks":
                assert p["foreign_masters"] > 0  # the gathered surfaces found facets of the other rank


@pytest.mark.mpi
def test_nneqm2_large_sliding_on_two_ranks_matches_serial(tmp_path):
    """NNEQM2 in the current geometry (issue 41) on 2 ranks: the sphere slid over the block and the frictional
    block slid 1.6 master facets (node-to-surface, pairs on both ranks, master facets on the other rank):
    the serial pair forces and resultant to 1e-8."""
    out = tmp_path / "out.npz"
    runs = ("sphere", "blocks")
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(SCRIPTS / "large_sliding.py"), str(out),
           *(f"{case}/nneqm2" for case in runs)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=compat.mpi_environment())
    assert run.returncode == 0, f"{' '.join(cmd)} failed:\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}"
    parallel = dict(np.load(out))
    for case in runs:
        s = solve(case, "nneqm2", MPI.COMM_SELF)
        p = {key.rsplit("/", 1)[1]: value for key, value in parallel.items() if key.startswith(f"{case}/nneqm2/")}
        i, j = _order(p["position"]), _order(s["position"])
        df = np.abs(p["force"][i] - s["force"][j]).max() / np.abs(s["force"]).max()
        dF = np.linalg.norm(p["total"] - s["total"]) / np.linalg.norm(s["total"])
        print(f"\n  {case}/nneqm2, 2 ranks vs serial: {len(i)} pairs (per rank {p['pairs_per_rank'].tolist()}); "
              f"{int(p['foreign_masters'])} with a master node on another rank; pair forces {df:.1e}, resultant "
              f"{dF:.1e} (tolerance 1e-8); iterations serial {s['iterations'].tolist()}, 2 ranks "
              f"{p['iterations'].tolist()}")
        assert len(i) == len(j) and np.abs(p["position"][i] - s["position"][j]).max() < 1e-9
        assert np.count_nonzero(p["pairs_per_rank"]) == 2  # the pairs are split
        assert df < 1e-8 and dF < 1e-8
        assert p["following"].all() and s["following"].all()
        if case == "blocks":
            assert p["foreign_masters"] > 0


@pytest.mark.mpi
@pytest.mark.parametrize("case, num_pairs", [("sphere-q2", 81), ("sphere-p2", 65)])
def test_degree_2_obstacle_on_two_ranks_matches_serial(tmp_path, case, num_pairs):
    """The frictional sphere (μ_f = 0.3) slid in the current geometry (issue 41: every node of the top face a
    pair) over 4 × 1 × 4 Q2 hexahedra and over 3 × 2 × 3 × 6 P2 tetrahedra (pairs that combine the nodes of
    a 6-node triangle, some of them on the other rank), on 2 ranks, monolithic, NNEQM1 and NNEQM2: the
    serial pair forces and resultant to 1e-8."""
    out = tmp_path / "out.npz"
    methods = ("monolithic", "nneqm1", "nneqm2")
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(SCRIPTS / "large_sliding.py"), str(out),
           *(f"{case}/{method}" for method in methods)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=compat.mpi_environment())
    assert run.returncode == 0, f"{' '.join(cmd)} failed:\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}"
    parallel = dict(np.load(out))
    for method in methods:
        s = solve(case, method, MPI.COMM_SELF)
        p = {key.rsplit("/", 1)[1]: value for key, value in parallel.items() if key.startswith(f"{case}/{method}/")}
        i, j = _order(p["position"]), _order(s["position"])
        df = np.abs(p["force"][i] - s["force"][j]).max() / np.abs(s["force"]).max()
        dF = np.linalg.norm(p["total"] - s["total"]) / np.linalg.norm(s["total"])
        print(f"\n  {case}/{method}, 2 ranks vs serial: {len(i)} pairs (per rank {p['pairs_per_rank'].tolist()}); "
              f"pair forces {df:.1e}, resultant {dF:.1e} (tolerance 1e-8); iterations serial "
              f"{s['iterations'].tolist()}, 2 ranks {p['iterations'].tolist()}")
        assert len(i) == len(j) == num_pairs and np.abs(p["position"][i] - s["position"][j]).max() < 1e-9
        assert np.count_nonzero(p["pairs_per_rank"]) == 2  # the pairs are split
        assert df < 1e-8 and dF < 1e-8
        assert p["following"].all() and s["following"].all()
