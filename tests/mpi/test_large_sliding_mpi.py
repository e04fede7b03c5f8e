"""Large sliding on 2 and 3 ranks: the serial answer (issue 27).

The cases of tests/mpi_scripts/large_sliding.py (a sphere slid over a block; a frictional block slid
1.6 master facets over another, node-to-surface and dual mortar; a cylinder ironing an elastoplastic strip). Every rank evaluates the node-to-surface pairs
from the gathered surfaces, with the displacements of their nodes summed over the ranks, so a
slave node finds its master facet on whichever rank holds it. Pairs are owned by the rank of their
slave node, so they are compared after sorting by the slave node's position. NNEQM2 (current
geometry since issue 41) on the sphere and the block slide, on 2 ranks. The sphere slid over Q2
hexahedra (degree 2, issue 41) with every solver, on 2 ranks.
"""

import numpy as np
import pytest
from large_sliding_runs import compare, results, run_on_ranks, solve
from mpi4py import MPI

from large_sliding import DEGREE_1, METHODS  # (tests/mpi_scripts: large_sliding_runs puts it on the path)


@pytest.fixture(scope="module")
def serial():
    return {(case, method): solve(case, method, MPI.COMM_SELF) for case in DEGREE_1 for method in METHODS}


@pytest.mark.mpi
@pytest.mark.parametrize("ranks, cases", [(2, DEGREE_1), (3, ("sphere", "blocks"))])  # 3 ranks: time
def test_large_sliding_on_several_ranks_matches_serial(ranks, cases, serial, tmp_path):
    parallel = run_on_ranks(tmp_path / "out.npz", ranks, list(cases))
    for case in cases:
        for method in METHODS:
            s = serial[case, method]
            p = results(parallel, case, method)
            c = compare(p, s)
            print(f"\n  {case}/{method}, {ranks} ranks vs serial: {c.pairs[0]} pairs (per rank {p['pairs_per_rank'].tolist()}); "
                  f"{int(p['foreign_masters'])} with a master node on another rank; "
                  f"pair forces {c.force:.1e}, resultant {c.total:.1e} (tolerance 1e-8); iterations serial "
                  f"{s['iterations'].tolist()}, {ranks} ranks {p['iterations'].tolist()}")
            assert c.pairs[0] == c.pairs[1] and c.position < 1e-9
            if ranks == 2 or case == "blocks":
                assert np.count_nonzero(p["pairs_per_rank"]) >= 2  # the pairs are split
            assert c.force < 1e-8 and c.total < 1e-8
            assert p["following"].all() and s["following"].all()  # "auto" moved the ironing to the current geometry
            if case == "blocks":
                assert p["foreign_masters"] > 0  # the gathered surfaces found facets of the other rank


@pytest.mark.mpi
def test_nneqm2_large_sliding_on_two_ranks_matches_serial(tmp_path):
    """NNEQM2 in the current geometry (issue 41) on 2 ranks: the sphere slid over the block and the frictional
    block slid 1.6 master facets (node-to-surface, pairs on both ranks, master facets on the other rank):
    the serial pair forces and resultant to 1e-8."""
    runs = ("sphere", "blocks")
    parallel = run_on_ranks(tmp_path / "out.npz", 2, [f"{case}/nneqm2" for case in runs])
    for case in runs:
        s = solve(case, "nneqm2", MPI.COMM_SELF)
        p = results(parallel, case, "nneqm2")
        c = compare(p, s)
        print(f"\n  {case}/nneqm2, 2 ranks vs serial: {c.pairs[0]} pairs (per rank {p['pairs_per_rank'].tolist()}); "
              f"{int(p['foreign_masters'])} with a master node on another rank; pair forces {c.force:.1e}, resultant "
              f"{c.total:.1e} (tolerance 1e-8); iterations serial {s['iterations'].tolist()}, 2 ranks "
              f"{p['iterations'].tolist()}")
        assert c.pairs[0] == c.pairs[1] and c.position < 1e-9
        assert np.count_nonzero(p["pairs_per_rank"]) == 2  # the pairs are split
        assert c.force < 1e-8 and c.total < 1e-8
        assert p["following"].all() and s["following"].all()
        if case == "blocks":
            assert p["foreign_masters"] > 0


@pytest.mark.mpi
@pytest.mark.parametrize("case, num_pairs", [("sphere-q2", 81), ("sphere-p2", 65)])
def test_degree_2_obstacle_on_two_ranks_matches_serial(tmp_path, case, num_pairs):
    """The frictional sphere (μ_f = 0.3) slid in the current geometry (issue 41: every node of the top face a
    pair) over 4 × 1 × 4 Q2 hexahedra and over 3 × 2 × 3 × 6 P2 tetrahedra (pairs that combine the nodes of
    a 6-node triangle, some of them on the other rank), on 2 ranks, monolithic, NNEQM1 and NNEQM2 (P2: the
    monolithic solver with the iterative linear solver too): the serial pair forces and resultant to 1e-8;
    one solve per increment but with NNEQM2 (the geometric terms on the pairs' nodes, on either rank)."""
    methods = ("monolithic", "nneqm1", "nneqm2") + (("iterative",) if case == "sphere-p2" else ())
    parallel = run_on_ranks(tmp_path / "out.npz", 2, [f"{case}/{method}" for method in methods])
    for method in methods:
        s = solve(case, method, MPI.COMM_SELF)
        p = results(parallel, case, method)
        c = compare(p, s)
        print(f"\n  {case}/{method}, 2 ranks vs serial: {c.pairs[0]} pairs (per rank {p['pairs_per_rank'].tolist()}); "
              f"pair forces {c.force:.1e}, resultant {c.total:.1e} (tolerance 1e-8); iterations serial "
              f"{s['iterations'].tolist()}, 2 ranks {p['iterations'].tolist()}; solves serial {s['solves'].tolist()}, "
              f"2 ranks {p['solves'].tolist()}")
        assert c.pairs == (num_pairs, num_pairs) and c.position < 1e-9
        assert np.count_nonzero(p["pairs_per_rank"]) == 2  # the pairs are split
        assert bool((p["solves"] == 1).all()) == bool((s["solves"] == 1).all()) == (method != "nneqm2")
        assert c.force < 1e-8 and c.total < 1e-8
        assert p["following"].all() and s["following"].all()
