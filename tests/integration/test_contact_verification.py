"""Contact verification: V4 patch test, V5 sliding block (and V10 polar vs Cartesian on V5)."""

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.cases.geometries import StackedBlocksTags as T
from dolfinx_nnqem.cases.geometries import build_stacked_blocks
from dolfinx_nnqem.solvers.monolithic import MonolithicSolver
from dolfinx_nnqem.material import von_mises_stress  # noqa: F401  (keeps the import surface tested)
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure
from dolfinx_nnqem.solvers import SolverOptions
from dolfinx_nnqem.io import pair_table
from dolfinx_nnqem.solvers import solve_load_steps

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


def sliding_block(law="alart-curnier", mu_f=0.3, drag=1.0e-2):
    """Body 2 on a clamped foundation: pressure P (ramped over ℓ ∈ [0, 0.2], then held) and a
    drag u_x = drag · (ℓ − 0.2)/0.8 on its top face; u_z = 0 on the z faces (plane strain)."""
    Lx, Lz, nx, nz = 1.0, 0.5, 4, 2
    mesh, ct, ft = build_stacked_blocks(MPI.COMM_WORLD, Lx, 0.5, 0.5, Lz, nx, 2, 2, nz)
    pressure = lambda ell: min(ell / 0.2, 1.0)  # noqa: E731
    dragging = lambda ell: max(ell - 0.2, 0.0) / 0.8  # noqa: E731
    problem = ContactProblem(
        mesh, ct, ft, materials={T.BODY1: ELASTIC, T.BODY2: ELASTIC},
        dirichlet=[Dirichlet(T.BOTTOM),
                   Dirichlet(T.TOP, drag, [0], amplitude=dragging),
                   Dirichlet(T.BODY1_ZMIN, 0.0, [2]), Dirichlet(T.BODY1_ZMAX, 0.0, [2]),
                   Dirichlet(T.BODY2_ZMIN, 0.0, [2]), Dirichlet(T.BODY2_ZMAX, 0.0, [2])],
        tractions=[Pressure(T.TOP, P, amplitude=pressure)],
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=mu_f, law=law),
    )
    return problem, P * Lx * Lz


def run_sliding_block(law, increments=10, solver_class=MonolithicSolver):
    problem, force = sliding_block(law)
    solver = solver_class(problem, SolverOptions(rtol=1e-12, max_iterations=40))
    history = []

    def record(result):
        t = pair_table(problem)
        history.append((result.load_factor, t["force_on_body1"].sum(axis=0), t["state_name"].copy(),
                        t["force_on_body1"].copy(), result.iterations))

    solve_load_steps(problem, solver, increments, callbacks=[record])
    return problem, force, history


def test_v5_sliding_block_saturates_at_coulomb_limit():
    mu_f = 0.3
    problem, force, history = run_sliding_block("alart-curnier")
    limit = mu_f * force
    print(f"\n  μ_f p A = {limit:.6e} N")
    for ell, total, states, _, its in history:
        counts = {s: int(np.sum(states == s)) for s in ("open", "stick", "slip")}
        print(f"  ℓ = {ell:.2f}: friction on body 1 = {total[0]: .10e} N, normal = {total[1]: .6e} N, "
              f"states {counts}, {its} iterations")
    frictions = np.array([h[1][0] for h in history])
    # rises while the drag grows, then saturates: all pairs slip at μ_f p A
    assert np.all(np.diff(frictions[1:]) >= -1e-9 * limit)
    assert abs(frictions[0]) < 1e-8 * limit  # pressure only: no friction
    last_ell, last_total, last_states, _, _ = history[-1]
    err = abs(last_total[0] - limit) / limit
    print(f"  saturation: |F_t − μ_f p A| / μ_f p A = {err:.2e} (tolerance 1e-8)")
    assert err < 1e-8
    assert np.all(last_states == "slip")
    assert any(np.any(h[2] == "stick") for h in history[1:-1])  # a stick phase before sliding
    assert abs(last_total[1] + force) < 1e-10 * force  # normal force on body 1 = −p A


def test_v10_polar_law_on_the_sliding_block_where_it_converges():
    """V10 on V5: the polar law agrees with the Cartesian one on every increment it converges;
    it needs the regularised step once friction starts from q = 0 (p_r = 0 makes ∂q/∂θ = 0)."""
    from dolfinx_nnqem.solvers import ConvergenceError

    _, force, cartesian = run_sliding_block("alart-curnier")
    polar = []
    problem, _ = sliding_block("polar")
    solver = MonolithicSolver(problem, SolverOptions(rtol=1e-12, max_iterations=40))

    def record(result):
        polar.append((result.load_factor, pair_table(problem)["force_on_body1"].copy(), result.report))

    try:
        solve_load_steps(problem, solver, 10, callbacks=[record], max_cutbacks=2)
        stopped = None
    except ConvergenceError as error:
        stopped = str(error).splitlines()[0]
    assert len(polar) >= 2  # the pressure stage at least
    worst = 0.0
    for (ell, f_p, rep), (ell_c, _, _, f_c, _) in zip(polar, cartesian):
        assert ell == pytest.approx(ell_c)
        lm = sum(1 for h in rep.history if h.kind == "lm")
        diff = np.max(np.abs(f_p - f_c)) / force
        worst = max(worst, diff)
        print(f"  ℓ = {ell:.2f}: max |Δ pair force| / pA = {diff:.2e}, polar iterations {rep.iterations} "
              f"({lm} Levenberg–Marquardt)")
    print(f"  polar law converged on {len(polar)} of {len(cartesian)} increments; worst difference "
          f"{worst:.2e} (tolerance 1e-8)" + (f"; stopped: {stopped}" if stopped else ""))
    assert worst < 1e-8


def test_reactions_count_a_dof_on_two_tagged_faces_once():
    """Global equilibrium closes when supports share edges (regression: double-counted reactions)."""
    from dolfinx_nnqem.io import equilibrium_check

    mesh, ct, ft = build_stacked_blocks(MPI.COMM_WORLD, 1.0, 0.5, 0.5, 1.0, 2, 1, 1, 2)
    problem = ContactProblem(
        mesh, ct, ft, materials={T.BODY1: ELASTIC, T.BODY2: ELASTIC},
        dirichlet=[Dirichlet(T.BOTTOM), Dirichlet(T.BODY1_ZMIN, 0.0, [2]),
                   Dirichlet(T.BODY2_XMIN, 0.0, [0]), Dirichlet(T.BODY2_ZMIN, 0.0, [2])],
        tractions=[Pressure(T.TOP, P)], contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=0.3))
    solve_load_steps(problem, MonolithicSolver(problem, SolverOptions(rtol=1e-12)), 1)
    check = equilibrium_check(problem)
    print(f"\n  global imbalance {check['global_imbalance']:.2e}, free-dof residual {check['residual_norm']:.2e}")
    assert check["global_imbalance"] < 1e-10
