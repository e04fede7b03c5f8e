"""Dual mortar of degree 2 in the current geometry on 2 ranks: the serial answer (issue 41).

The frictional mortar block slide on Q2 hexahedra and P2 tetrahedra (``mortar-q2``, ``mortar-p2`` of
tests/mpi_scripts/large_sliding.py): every rank integrates the gathered, moved quadratic surfaces,
differences the couples of the pairs whose slave node it owns and keeps their rows; the geometric blocks
K (a pair's nodes × every node its geometry depends on, on either rank) are assembled across ranks. On
Q2 the monolithic solver (consistent, in its serial Newton iterations), NNEQM1 and NNEQM2 (the geometry
frozen within a solve), on P2 NNEQM1 (tri6 pairs on d̂_j), on 2 ranks give the serial pair forces.
"""

import numpy as np
import pytest
from large_sliding_runs import compare, results, run_on_ranks, solve
from mpi4py import MPI


@pytest.mark.mpi
@pytest.mark.parametrize("case, methods", [("mortar-q2", ("monolithic", "nneqm1", "nneqm2")),
                                           ("mortar-p2", ("nneqm1",))])
def test_degree_2_mortar_slide_on_two_ranks_matches_serial(tmp_path, case, methods):
    parallel = run_on_ranks(tmp_path / "out.npz", 2, [f"{case}/{method}" for method in methods])
    for method in methods:
        s = solve(case, method, MPI.COMM_SELF)
        p = results(parallel, case, method)
        c = compare(p, s)
        print(f"\n  {case}/{method}, 2 ranks vs serial: {c.pairs[0]} pairs (per rank {p['pairs_per_rank'].tolist()}), "
              f"{int(p['foreign_masters'])} with a master node on the other rank; pair forces {c.force:.1e}, "
              f"resultant {c.total:.1e}; iterations serial {s['iterations'].tolist()}, 2 ranks {p['iterations'].tolist()}")
        assert c.pairs[0] == c.pairs[1] and c.position < 1e-9
        assert np.count_nonzero(p["pairs_per_rank"]) == 2 and p["following"].tolist() == [True]
        assert c.force < 1e-10 and c.total < 1e-10
        if method == "monolithic":
            assert p["iterations"].tolist() == s["iterations"].tolist()
