"""Node-to-surface pairs of degree 2 in the current geometry on 2 ranks: the serial answer (issue 41).

The frictional block slid 1.6 master facets over another (μ_f = 0.3, tests/mpi_scripts/large_sliding.py)
with degree-2 displacements: on Q2 hexahedra (every slave node a pair, re-evaluated at every Newton
iterate by the monolithic solver with the quadratic facets' geometric terms, K assembled across the
ranks) and on P2 tetrahedra (pairs combining the nodes of 6-node triangles, each on its own master
facet, re-evaluated at every iterate by the monolithic solver with their geometric terms, between solves
by NNEQM1 and NNEQM2), monolithic, NNEQM1 and NNEQM2: the serial pair forces and resultant.
"""

import numpy as np
import pytest
from large_sliding_runs import compare, results, run_on_ranks, solve
from mpi4py import MPI


@pytest.mark.mpi
@pytest.mark.slow
@pytest.mark.parametrize("case", ["blocks-q2", "blocks-p2"])
def test_degree_2_node_to_surface_slide_on_two_ranks_matches_serial(tmp_path, case):
    methods = ("monolithic", "nneqm1", "nneqm2")
    parallel = run_on_ranks(tmp_path / "out.npz", 2, [f"{case}/{method}" for method in methods])
    for method in methods:
        s = solve(case, method, MPI.COMM_SELF)
        p = results(parallel, case, method)
        c = compare(p, s)
        print(f"\n  {case}/{method}, 2 ranks vs serial: {c.pairs[0]} pairs (per rank {p['pairs_per_rank'].tolist()}), "
              f"{int(p['foreign_masters'])} with a master node on the other rank; pair forces {c.force:.1e}, resultant "
              f"{c.total:.1e}; iterations serial {s['iterations'].tolist()}, 2 ranks {p['iterations'].tolist()}")
        assert c.pairs[0] == c.pairs[1] and c.position < 1e-9
        assert np.count_nonzero(p["pairs_per_rank"]) == 2 and p["foreign_masters"] > 0
        assert c.force < 1e-10 and c.total < 1e-10
        assert p["following"].all() and s["following"].all()
