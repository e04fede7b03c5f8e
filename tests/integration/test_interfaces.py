"""Several contact interfaces (issue "One contact model under every solver").

Three blocks stacked along y (``build_block_stack``), two interfaces with their own μ_f, for
every method and both laws:

* patch test: a uniform pressure p on the top block; every pair of both interfaces carries p ×
  its tributary area and σ = −p e_y⊗e_y everywhere, 1e-10. Blocks 2 and 3 are held by contact
  alone (floating in y): NNEQM1 and NNEQM2 handle their free rigid modes explicitly;
* a drag on the top block (prescribed u_x) under the pressure: statics says both interfaces
  transmit the same tangential force, so the interface with the lower μ_f slides, its friction
  saturating at μ_low p A, while the other one does not (the drag tilts the stack: trailing
  pairs open and a few low-pressure edge pairs of the stronger interface slip locally, but it
  keeps sticking pairs).
"""

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.cases.geometries import build_block_stack
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure
from dolfinx_nnqem.io import equilibrium_check, pair_table
from dolfinx_nnqem.solvers import METHODS, SolverOptions, make_solver
from dolfinx_nnqem.solvers import solve_load_steps

ELASTIC = VonMises(E=1.0e9, nu=0.3)
P = 1.0e6
LX = LZ = 1.0
N = 3  # elements per side of each block's face


def tributary_areas(positions):
    """Nodal tributary areas of the uniform N × N grid on [0, LX] × [0, LZ]."""
    h = LX / N
    ax = np.where(np.isclose(positions[:, 0], 0) | np.isclose(positions[:, 0], LX), h / 2, h)
    az = np.where(np.isclose(positions[:, 2], 0) | np.isclose(positions[:, 2], LZ), h / 2, h)
    return ax * az


def three_blocks(mu_f=(0.3, 0.3), law="alart-curnier", drag=None, comm=MPI.COMM_WORLD):
    """The stack; ``drag``: the top face's final u_x (the pressure is ramped first, then held)."""
    mesh, ct, ft = build_block_stack(comm, LX, LZ, [0.5, 0.5, 0.5], [(N, 1, N)] * 3)
    contact = [Contact(T.top(1), T.bottom(2), mu_f=mu_f[0], law=law, name="lower"),
               Contact(T.top(2), T.bottom(3), mu_f=mu_f[1], law=law, name="upper")]
    if drag is None:  # rollers and symmetry planes: a homogeneous state
        dirichlet = [Dirichlet(T.bottom(1), 0.0, [1])]
        dirichlet += [Dirichlet(T.xmin(k), 0.0, [0]) for k in (1, 2, 3)]
        dirichlet += [Dirichlet(T.zmin(k), 0.0, [2]) for k in (1, 2, 3)]
        tractions = [Pressure(T.top(3), P)]
    else:
        dirichlet = [Dirichlet(T.bottom(1)),
                     Dirichlet(T.top(3), drag, [0], amplitude=lambda ell: max(ell - 0.2, 0.0) / 0.8)]
        dirichlet += [Dirichlet(face(k), 0.0, [2]) for k in (1, 2, 3) for face in (T.zmin, T.zmax)]
        tractions = [Pressure(T.top(3), P, amplitude=lambda ell: min(ell / 0.2, 1.0))]
    problem = ContactProblem(mesh, ct, ft, materials={k: ELASTIC for k in (1, 2, 3)}, dirichlet=dirichlet,
                             tractions=tractions, contact=contact)
    return problem


@pytest.mark.parametrize("law", ["alart-curnier", "polar"])
@pytest.mark.parametrize("method", METHODS)
def test_three_blocks_patch_test(method, law):
    problem = three_blocks(law=law)
    solver = make_solver(method, problem, SolverOptions(rtol=1e-13))
    results = solve_load_steps(problem, solver, 1)
    t = pair_table(problem)
    expected = P * tributary_areas(t["position"])
    p_n = -t["force_local_body1"][:, 0]
    err_pairs = np.max(np.abs(p_n - expected)) / np.max(expected)
    friction = np.max(np.abs(t["force_local_body1"][:, 1:])) / np.max(expected)
    sigma = problem.state.sigma_n.x.array.reshape(-1, 3, 3)
    others = sigma.reshape(-1, 9)[:, [0, 1, 2, 3, 5, 6, 7, 8]]
    err_sigma = max(np.max(np.abs(sigma[:, 1, 1] + P)) / P, np.max(np.abs(others)) / P)
    err_sigma = MPI.COMM_WORLD.allreduce(err_sigma, op=MPI.MAX)
    per_interface = [int(np.count_nonzero(t["interface"] == k)) for k in (0, 1)]
    modes = problem.rigid_modes
    print(f"\n  {method}/{law}: pairs per interface {per_interface}, free rigid modes "
          f"{[f'body {b + 1}: {d}' for b, d in zip(modes.body, modes.description)]}, "
          f"{results[0].iterations} iterations; max |p_n − p·A| / max(p·A) = {err_pairs:.2e}, "
          f"friction/p·A = {friction:.2e}, max |σ + p e_y⊗e_y| / p = {err_sigma:.2e} (tolerance 1e-10)")
    assert per_interface == [(N + 1) ** 2] * 2
    assert modes.count == 2  # blocks 2 and 3 float in y, held by contact alone
    assert np.all(t["state_name"] != "open")
    assert err_pairs < 1e-10 and err_sigma < 1e-10 and friction < 1e-10
    assert equilibrium_check(problem)["global_imbalance"] < 1e-10


@pytest.mark.parametrize("mu_f, slipping", [((0.2, 0.4), 0), ((0.4, 0.2), 1)])
@pytest.mark.parametrize("method", METHODS)
def test_the_interface_with_the_lower_friction_slips(method, mu_f, slipping):
    """Drag the top block: the lower-μ_f interface saturates at μ_low p A, the other one sticks."""
    drag = 1.0e-2
    problem = three_blocks(mu_f=mu_f, drag=drag)
    solver = make_solver(method, problem, SolverOptions(rtol=1e-12, max_iterations=40))
    history = []

    def record(result):
        t = pair_table(problem)
        friction = [t["force_on_body1"][t["interface"] == k, 0].sum() for k in (0, 1)]
        states = [t["state_name"][t["interface"] == k] for k in (0, 1)]
        history.append((result.load_factor, friction, states, result.iterations))

    solve_load_steps(problem, solver, 10, callbacks=[record])
    limit = min(mu_f) * P * LX * LZ
    print(f"\n  {method}, μ_f = {mu_f}: μ_low p A = {limit:.6e} N")
    for ell, friction, states, its in history:
        counts = [{s: int(np.sum(st == s)) for s in ("stick", "slip")} for st in states]
        print(f"  ℓ = {ell:.2f}: friction lower {friction[0]: .8e}, upper {friction[1]: .8e} N; "
              f"states lower {counts[0]}, upper {counts[1]}; {its} iterations")
    ell, friction, states, _ = history[-1]
    err = abs(abs(friction[slipping]) - limit) / limit
    balance = abs(friction[0] - friction[1]) / limit  # statics: both interfaces carry the same force
    print(f"  saturation |F_t − μ_low p A| / μ_low p A = {err:.2e}, |F_lower − F_upper| / μ_low p A = "
          f"{balance:.2e} (tolerance 1e-8)")
    assert err < 1e-8 and balance < 1e-8
    closed = states[slipping] != "open"
    assert closed.sum() > 0 and np.all(states[slipping][closed] == "slip")  # the weak interface slides
    assert all(np.any(h[2][1 - slipping] == "stick") for h in history)  # the strong one never does


def test_the_contact_scale_is_the_largest_r_of_the_interfaces():
    """ContactModel.r_max, what the solvers scale with (issue 42: one property instead of each solver's
    max over the law groups): the largest r of the interfaces, the same on the gathered laws the dense
    methods use; an interface without r takes E h."""
    mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, LX, LZ, [0.5, 0.5, 0.5], [(N, 1, N)] * 3)
    for r_lower in (2.0e9, 5.0e7):  # above E h, below it
        contact = [Contact(T.top(1), T.bottom(2), mu_f=0.3, r=r_lower, name="lower"),
                   Contact(T.top(2), T.bottom(3), mu_f=0.3, name="upper")]
        problem = ContactProblem(mesh, ct, ft, materials={k: ELASTIC for k in (1, 2, 3)},
                                 dirichlet=[Dirichlet(T.bottom(1))], contact=contact)
        model = problem.contact
        Eh = ELASTIC.E * model.h
        r = [interface.r for interface in model.interfaces]
        print(f"\n  r of the interfaces {r} (E h = {Eh:.4g}): r_max = {model.r_max:.4g}")
        assert r == [r_lower, Eh]
        assert model.r_max == max(r_lower, Eh) == model.gathered_laws().r_max
