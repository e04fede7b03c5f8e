"""Bodies, their free rigid modes, and the generalised inverse NNEQM1/NNEQM2 build on them."""

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.solvers.condensation import Condensation
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.cases.geometries import build_block_stack
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure


def stack(partial_supports: bool):
    mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [0.5] * 3, [(3, 2, 3)] * 3)
    dirichlet = [Dirichlet(T.bottom(1))]
    if partial_supports:
        dirichlet += [Dirichlet(face(k), 0.0, [2]) for k in (2, 3) for face in (T.zmin, T.zmax)]
    elastic = VonMises(E=1e9, nu=0.3)
    return ContactProblem(mesh, ct, ft, materials={k: elastic for k in (1, 2, 3)}, dirichlet=dirichlet,
                          tractions=[Pressure(T.top(3), 1e6)],
                          contact=[Contact(T.top(1), T.bottom(2), mu_f=0.3), Contact(T.top(2), T.bottom(3), mu_f=0.3)])


def test_bodies_and_their_free_rigid_modes():
    free = stack(partial_supports=False)
    partial = stack(partial_supports=True)
    names = [free.bodies.name(b) for b in range(free.bodies.count)]
    print(f"\n  bodies: {names}")
    for label, problem in (("no support", free), ("u_z = 0 on the z faces", partial)):
        modes = problem.rigid_modes
        print(f"  blocks 2 and 3 with {label}: {[f'{names[b]}: {d}' for b, d in zip(modes.body, modes.description)]}")
    assert names == ["body 1 (cells tagged 1)", "body 2 (cells tagged 2)", "body 3 (cells tagged 3)"]
    assert free.rigid_modes.count == 12 and set(free.rigid_modes.body) == {1, 2}  # six each, body 1 clamped
    assert partial.rigid_modes.count == 6  # x, y translations and the rotation about z, for each
    for v in partial.rigid_modes.vectors:  # zero at every constrained dof, largest nodal value 1
        a = v.getArray(readonly=True)
        assert np.all(a[partial.owned_bc_dofs()] == 0.0)
        largest = np.linalg.norm(a.reshape(-1, 3), axis=1).max(initial=0.0)
        assert np.isclose(MPI.COMM_WORLD.allreduce(largest, op=MPI.MAX), 1.0)


def test_generalised_inverse_on_self_equilibrated_loads():
    """K (G f) = f at every free dof (fixing dofs included) for f with Nᵀf = 0, and K N = 0."""
    problem = stack(partial_supports=True)
    condensation = Condensation(problem, "test", {})
    condensation.factorise(problem.assemble_elastic_stiffness, "K_e")
    K = problem.assemble_elastic_stiffness()  # the Dirichlet conditions only
    N = condensation.mode_array()
    rng = np.random.default_rng(0)
    f = problem.u.x.petsc_vec.duplicate()
    a = rng.normal(size=f.getLocalSize())
    a[problem.owned_bc_dofs()] = 0.0
    Q = np.linalg.qr(np.concatenate(MPI.COMM_WORLD.allgather(N)))[0]  # orthonormal modes, all rows
    start = sum(MPI.COMM_WORLD.allgather(len(a))[:MPI.COMM_WORLD.rank])
    Q_local = Q[start:start + len(a)]
    a -= Q_local @ MPI.COMM_WORLD.allreduce(Q_local.T @ a, op=MPI.SUM)  # self-equilibrated
    f.getArray()[:] = a
    x = condensation.solve(f)
    y = K.createVecLeft()
    K.mult(x, y)
    residual = y.getArray() - a
    residual[problem.owned_bc_dofs()] = 0.0
    err = MPI.COMM_WORLD.allreduce(np.abs(residual).max(), op=MPI.MAX) / MPI.COMM_WORLD.allreduce(np.abs(a).max(), op=MPI.MAX)
    kn = []
    for v in condensation.modes.vectors:
        K.mult(v, y)
        out = y.getArray().copy()
        out[problem.owned_bc_dofs()] = 0.0
        kn.append(MPI.COMM_WORLD.allreduce(np.abs(out).max(), op=MPI.MAX))
    diag = K.getDiagonal().max()[1]
    print(f"\n  fixing dofs {condensation.fixing_dofs.tolist()}; max |K G f − f| / max |f| = {err:.1e}; "
          f"max |K N| / max diag K = {max(kn) / diag:.1e} (tolerance 1e-12)")
    assert err < 1e-12 and max(kn) < 1e-12 * diag
    assert len(condensation.fixing_dofs) == condensation.num_modes == 6
