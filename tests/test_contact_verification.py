"""Contact verification: V4 patch test, V5 sliding block (and V10 polar vs Cartesian on V5)."""

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.meshing import StackedBlocksTags as T
from dolfinx_nnqem.meshing import build_stacked_blocks
from dolfinx_nnqem.monolithic import MonolithicSolver
from dolfinx_nnqem.output import von_mises  # noqa: F401  (keeps the import surface tested)
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure, SolverOptions
from dolfinx_nnqem.results import pair_table
from dolfinx_nnqem.stepping import solve_load_steps

ELASTIC = VonMises(E=1.0e9, nu=0.3)  # σ_y0 = inf: elastic
P = 1.0e6


def tributary_areas(positions, Lx, Lz, nx, nz):
    """Nodal tributary areas of a uniform nx × nz grid on [0, Lx] × [0, Lz]."""
    hx, hz = Lx / nx, Lz / nz
    ax = np.where(np.isclose(positions[:, 0], 0) | np.isclose(positions[:, 0], Lx), hx / 2, hx)
    az = np.where(np.isclose(positions[:, 2], 0) | np.isclose(positions[:, 2], Lz), hz / 2, hz)
    return ax * az


@pytest.mark.parametrize("mu_f", [0.0, 0.3])
def test_v4_contact_patch_test(mu_f):
    Lx, Lz, nx, nz = 1.0, 1.0, 3, 3
    mesh, ct, ft = build_stacked_blocks(MPI.COMM_WORLD, Lx, 0.5, 0.5, Lz, nx, 2, 2, nz)
    problem = ContactProblem(
        mesh, ct, ft, materials={T.BODY1: ELASTIC, T.BODY2: ELASTIC},
        # body 1 on rollers; x−/z− faces of both bodies are symmetry planes; body 2 held by contact
        dirichlet=[Dirichlet(T.BOTTOM, 0.0, [1]),
                   Dirichlet(T.BODY1_XMIN, 0.0, [0]), Dirichlet(T.BODY2_XMIN, 0.0, [0]),
                   Dirichlet(T.BODY1_ZMIN, 0.0, [2]), Dirichlet(T.BODY2_ZMIN, 0.0, [2])],
        tractions=[Pressure(T.TOP, P)],
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=mu_f),
    )
    solver = MonolithicSolver(problem, SolverOptions(rtol=1e-13))
    solve_load_steps(problem, solver, 1)
    t = pair_table(problem)
    expected = P * tributary_areas(t["position"], Lx, Lz, nx, nz)
    p_n = -t["force_local_body1"][:, 0]
    err_pairs = np.max(np.abs(p_n - expected)) / np.max(expected)
    friction = np.max(np.abs(t["force_local_body1"][:, 1:])) / np.max(expected)
    sigma = problem.state.sigma_n.x.array.reshape(-1, 3, 3)
    err_sigma = np.max(np.abs(sigma[:, 1, 1] + P)) / P
    others = np.max(np.abs(sigma.reshape(-1, 9)[:, [0, 1, 2, 3, 5, 6, 7, 8]])) / P
    err_sigma = MPI.COMM_WORLD.allreduce(max(err_sigma, others), op=MPI.MAX)
    print(f"\n  mu_f = {mu_f}: {len(p_n)} pairs, max |p_n − p·A| / max(p·A) = {err_pairs:.2e}; "
          f"friction/p·A = {friction:.2e}; max |σ + p e_y⊗e_y| / p = {err_sigma:.2e} (tolerance 1e-10)")
    assert np.all(t["state_name"] != "open")
    assert err_pairs < 1e-10 and err_sigma < 1e-10 and friction < 1e-10
