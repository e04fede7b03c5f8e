"""MPI helper of tests/unit/test_pairs.py: invalid contact input must raise on EVERY rank.

    mpiexec -n N python pairs_errors.py

Rank 0 prints one line ``rank R case C: ExceptionName: message`` per rank and case (or
``no error``), then ``rank R done`` per rank. A rank that did not raise would leave the others
waiting in a collective call: the run would hang instead of finishing.
"""

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import dolfinx
from mpi4py import MPI

from dolfinx_nnqem.cases import geometries as meshing
from dolfinx_nnqem.contact.pairs import ContactPairError, find_pairs


def main() -> None:
    comm = MPI.COMM_WORLD
    mesh, _, facet_tags = meshing.build_two_beams(comm)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    T = meshing.TwoBeamsTags
    blocks, _, block_tags = meshing.build_stacked_blocks(comm)
    W = dolfinx.fem.functionspace(blocks, ("Lagrange", 1, (3,)))
    S = meshing.StackedBlocksTags
    cases = {
        "missing_tag": (V, facet_tags, T.CONTACT1, 99, {}),
        "no_partner": (V, facet_tags, T.CONTACT1, T.LOAD, {}),
        "not_facing": (W, block_tags, S.CONTACT1, S.TOP, {"search_distance": 0.6}),
    }
    for name, (space, tags, s1, s2, kwargs) in cases.items():
        try:
            find_pairs(space, tags, s1, s2, **kwargs)
            outcome = "no error"
        except ContactPairError as exc:
            outcome = f"{type(exc).__name__}: {exc}"
        # collective: a rank that missed the error would be elsewhere and the run would hang
        outcomes = comm.gather(outcome, root=0)
        if comm.rank == 0:
            for rank, text in enumerate(outcomes):
                print(f"rank {rank} case {name}: {text}", flush=True)
    done = comm.gather("done", root=0)
    if comm.rank == 0:
        for rank, text in enumerate(done):
            print(f"rank {rank} {text}", flush=True)

if __name__ == "__main__":
    main()
