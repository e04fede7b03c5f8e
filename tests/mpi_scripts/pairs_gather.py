"""MPI helper of tests/unit/test_pairs.py: contact pairs of three models, gathered on every rank.

    mpiexec -n N python pairs_gather.py OUT.json

Rank 0 writes, for each model, the gathered pair data (positions, X_a, X_b, R, g0), w = B u
for a fixed smooth field u, scalar checks of Bᵀλ (total force, (Bᵀλ)·u, λ·w) and how the pairs
are spread over the ranks. The test compares the runs on 1, 2 and 3 ranks.
"""

import json
import sys

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import dolfinx
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.cases import geometries as meshing
from dolfinx_nnqem.contact.pairs import find_pairs


def u_field(x):
    """A smooth, non-rigid displacement field."""
    return np.vstack([0.1 * x[1] ** 2 + 0.02 * x[2], 0.3 * x[0] * x[2], np.sin(x[0]) + x[1] * x[2]])


def lam_field(x):
    """Pair forces λ_i as a function of the pair positions, shape (n, 3)."""
    return x @ np.array([[1.0, 2.0, 3.0], [0.5, -1.0, 2.0], [3.0, 1.0, -1.0]]) + 1.0


def case(mesh_and_tags, surface1, surface2, **kwargs):
    comm = MPI.COMM_WORLD
    mesh, _, facet_tags = mesh_and_tags
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    pairs = find_pairs(V, facet_tags, surface1, surface2, **kwargs)
    u = dolfinx.fem.Function(V)
    u.interpolate(u_field)
    w = pairs.relative_displacement(u)
    lam = lam_field(pairs.positions)
    f = pairs.global_force(lam)
    start, end = V.dofmap.index_map.local_range
    a_elsewhere = int(np.sum((pairs.dofs_a < start) | (pairs.dofs_a >= end)))
    result = {
        "num_global": pairs.num_global,
        "positions": pairs.gather(pairs.positions),
        "X_a": pairs.gather(pairs.X_a),
        "X_b": pairs.gather(pairs.X_b),
        "R": pairs.gather(pairs.R.reshape(-1, 9)),
        "g0": pairs.gather(pairs.g0),
        "w": pairs.gather(w),
        "total_force": comm.allreduce(f.getArray(readonly=True).reshape(-1, 3).sum(axis=0)),
        "force_dot_u": f.dot(u.x.petsc_vec),
        "lam_dot_w": comm.allreduce(float(np.sum(lam * w))),
        "pairs_per_rank": comm.allgather(pairs.num_local),
        "pairs_with_a_on_another_rank": comm.allreduce(a_elsewhere),
    }
    pairs.destroy()
    return {k: (np.asarray(v).tolist() if isinstance(v, np.ndarray) else v) for k, v in result.items()}


def main(out: str) -> None:
    comm = MPI.COMM_WORLD
    T = meshing.StackedBlocksTags
    results = {
        "two_beams": case(meshing.build_two_beams(comm), 21, 22),
        "blocks_gap": case(
            meshing.build_stacked_blocks(comm, 1.0, 0.5, 0.5, 1.0, 5, 2, 2, 5, gap=0.02),
            T.CONTACT1, T.CONTACT2, search_distance=0.05,
        ),
        "blocks_hertz_gap": case(
            meshing.build_stacked_blocks(comm, 1.0, 0.5, 0.5, 1.0, 6, 2, 2, 6, centred=True),
            T.CONTACT1, T.CONTACT2, initial_gap=lambda x: 0.5 * (x[0] ** 2 + x[2] ** 2),
        ),
    }
    if comm.rank == 0:
        with open(out, "w") as f:
            json.dump({"size": comm.size, "cases": results}, f)


if __name__ == "__main__":
    main(sys.argv[1])
