"""V1 (uniaxial bar, load–unload–reload) and V2 (consistent tangent vs finite differences)."""

import dolfinx.fem as fem
import numpy as np
import pytest
import ufl
from conftest import box_with_face_tags

from dolfinx_nnqem.material import PlasticState, VonMises
from dolfinx_nnqem.solvers.monolithic import MonolithicSolver
from dolfinx_nnqem.problem import ContactProblem, Dirichlet
from dolfinx_nnqem.solvers import solve_load_steps

STEEL = VonMises(E=2.0e11, nu=0.3, sigma_y0=2.5e8, H=2.0e10)


def uniaxial_stress_closed_form(path_strain, material):
    """σ_xx along a monotone-piecewise strain path (1D plasticity with linear hardening)."""
    E, H = material.E, material.H
    E_t = E * H / (E + H)
    sigma, eps_prev, sigma_y = 0.0, 0.0, material.sigma_y0  # current yield stress in tension
    out = []
    for eps in path_strain:
        trial = sigma + E * (eps - eps_prev)
        if abs(trial) > sigma_y:
            # 1D return: hardening modulus H in terms of plastic strain, E_t overall
            excess = abs(trial) - sigma_y
            dp = excess / (E + H)
            sigma = np.sign(trial) * (sigma_y + H * dp)
            sigma_y = sigma_y + H * dp
        else:
            sigma = trial
        eps_prev = eps
        out.append(sigma)
    return np.array(out), E_t


@pytest.mark.parametrize("cell", ["hexahedron", "tetrahedron"])
def test_v1_uniaxial_bar_load_unload_reload(cell):
    mesh, ft = box_with_face_tags((2, 2, 2), cell=cell)
    delta_max = 4.0 * STEEL.sigma_y0 / STEEL.E  # end displacement at ℓ = 1 (4× the yield strain)
    problem = ContactProblem(
        mesh, None, ft, materials=STEEL,
        dirichlet=[Dirichlet(1, 0.0, components=[0]), Dirichlet(3, 0.0, components=[1]),
                   Dirichlet(5, 0.0, components=[2]), Dirichlet(2, delta_max, components=[0])],
    )
    solver = MonolithicSolver(problem)
    path = []

    def record(result):
        sigma = problem.state.sigma_n.x.array.reshape(-1, 3, 3)
        path.append((result.load_factor, sigma[:, 0, 0].copy(), sigma.copy()))

    solve_load_steps(problem, solver, 8, callbacks=[record], final_load_factor=1.0)      # load
    solve_load_steps(problem, solver, 4, callbacks=[record], final_load_factor=0.5)      # unload (elastic)
    solve_load_steps(problem, solver, 8, callbacks=[record], final_load_factor=1.5)      # reload
    eps = np.array([ell * delta_max for ell, _, _ in path])
    expected, _ = uniaxial_stress_closed_form(eps, STEEL)
    worst = 0.0
    print("\n  eps_xx        sigma_xx (FE)      closed form        rel. error")
    for (ell, sxx, sigma), e, s_ref in zip(path, eps, expected):
        err = np.max(np.abs(sxx - s_ref)) / STEEL.sigma_y0
        # the other stress components vanish (uniaxial stress)
        others = np.max(np.abs(sigma.reshape(-1, 9)[:, 1:])) / STEEL.sigma_y0
        worst = max(worst, err, others)
        print(f"  {e:.4e}   {sxx.mean(): .10e}   {s_ref: .10e}   {err:.2e}")
    print(f"  {cell}: worst relative error: {worst:.2e} (tolerance 1e-8)")
    assert worst < 1e-8
    # loading branch: σ = σ_y0 + E_t (ε − σ_y0/E) after yield
    E_t = STEEL.tangent_modulus
    for (ell, sxx, _), e in zip(path[:8], eps[:8]):
        ref = STEEL.E * e if e <= STEEL.sigma_y0 / STEEL.E else STEEL.sigma_y0 + E_t * (e - STEEL.sigma_y0 / STEEL.E)
        assert np.max(np.abs(sxx - ref)) < 1e-8 * STEEL.sigma_y0
    # unloading is elastic (slope E) and reloading yields again beyond the previous maximum
    sigma_max = expected[7]
    for (ell, sxx, _), e in zip(path[8:12], eps[8:12]):
        assert np.max(np.abs(sxx - (sigma_max - STEEL.E * (eps[7] - e)))) < 1e-8 * STEEL.sigma_y0
    assert expected[-1] > sigma_max > STEEL.sigma_y0


def _single_cell_state(material):
    import dolfinx.mesh as dmesh
    from mpi4py import MPI

    mesh = dmesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1, dmesh.CellType.hexahedron)
    V = fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    return PlasticState(V, material), V


def _homogeneous_displacement(V, eps):
    u = fem.Function(V)
    u.interpolate(lambda x: eps @ x)
    return u


@pytest.mark.parametrize("H", [0.0, 2.0e10])
def test_v2_consistent_tangent_matches_finite_differences(H):
    """C_alg (UFL) against central differences of the UFL stress update, plastic and elastic."""
    material = VonMises(E=2.0e11, nu=0.3, sigma_y0=2.5e8, H=H)
    state, V = _single_cell_state(material)
    rng = np.random.default_rng(1)
    # a converged state that is already plastic: σ_n on the yield surface, p_n > 0
    A = rng.standard_normal((3, 3))
    s = A + A.T - np.trace(A + A.T) / 3 * np.eye(3)
    p_n = 1e-3
    q_target = material.sigma_y0 + H * p_n
    s *= q_target / np.sqrt(1.5 * np.sum(s * s))
    sigma_n = s + 1e7 * np.eye(3)
    state.sigma_n.x.array[:] = np.tile(sigma_n.reshape(-1), state.sigma_n.x.array.size // 9)
    state.p_n.x.array[:] = p_n

    u = fem.Function(V)
    pts = state._points
    stress = fem.Expression(state.parts[0].ufl_return_map(u).sigma, pts)
    directions = [np.eye(3)[[i]].T @ np.eye(3)[[j]] for i in range(3) for j in range(3)]
    directions = [0.5 * (d + d.T) for d in directions]
    W = state.W_tensor

    def sigma_at(eps):
        u.interpolate(lambda x: eps @ x)
        f = fem.Function(W)
        f.interpolate(stress)
        return f.x.array.reshape(-1, 3, 3)[0]

    worst = 0.0
    for case, scale in [("plastic (loading along s_n)", 1.0), ("elastic (unloading)", -1.0)]:
        deps0 = scale * 2e-4 * s / np.linalg.norm(s) + 1e-5 * rng.standard_normal((3, 3))
        deps0 = 0.5 * (deps0 + deps0.T)
        u.interpolate(lambda x: deps0 @ x)
        dp_expr = fem.Function(state.W_scalar)
        dp_expr.interpolate(fem.Expression(state.parts[0].ufl_return_map(u).dp, pts))
        plastic = dp_expr.x.array[0] > 0
        assert plastic == (scale > 0), case
        h = 1e-7 * np.linalg.norm(deps0)
        for d in directions:
            fd = (sigma_at(deps0 + h * d) - sigma_at(deps0 - h * d)) / (2 * h)
            u.interpolate(lambda x: deps0 @ x)
            tangent = fem.Function(W)
            tangent.interpolate(fem.Expression(state.parts[0].tangent(u, ufl.as_matrix(d.tolist())), pts))
            Ct = tangent.x.array.reshape(-1, 3, 3)[0]
            err = np.linalg.norm(Ct - fd) / np.linalg.norm(fd)
            worst = max(worst, err)
        print(f"  H = {H:.1e}, {case}: worst relative difference C_alg vs central FD so far {worst:.2e}")
    assert worst < 1e-6


def test_material_parameters_are_validated():
    for kwargs, name in [(dict(E=-1.0, nu=0.3), "E"), (dict(E=1.0, nu=0.5), "nu"),
                         (dict(E=1.0, nu=0.3, sigma_y0=0.0), "sigma_y0"),
                         (dict(E=1.0, nu=0.3, sigma_y0=1.0, H=-1.0), "H"),
                         (dict(E=float("nan"), nu=0.3), "E"), (dict(E=1.0, nu=-1.0), "nu")]:
        with pytest.raises(ValueError, match=name):
            VonMises(**kwargs)


def test_vectorised_kernels_agree_with_dolfinx_default_flags(monkeypatch):
    """The package compiles its forms with reassociable sums (dolfinx_nnqem.jit); that may change
    only the last bits against DOLFINx's default flags, here on a plastic state of the pressed
    blocks (tangent, internal force, and the Gauss-point stresses of the state commit)."""
    from mpi4py import MPI

    from dolfinx_nnqem import jit
    from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem

    def plastic_fields(compile_args):
        monkeypatch.setattr(jit, "KERNEL_COMPILE_ARGS", compile_args)
        problem = pressed_blocks_problem(1, MPI.COMM_SELF)
        rng = np.random.default_rng(0)
        problem.u.x.array[:] = 1e-4 * rng.standard_normal(problem.u.x.array.size)  # 149 of 512 points yield
        K = problem.assemble_tangent()
        F = problem.assemble_internal_force()
        plastic = problem.state.count_trial_plastic_points(problem.u)
        problem.state.commit(problem.u)
        return K.convert("dense").getDenseArray(), F.getArray().copy(), problem.state.sigma_n.x.array.copy(), plastic

    fast, default = plastic_fields(jit.KERNEL_COMPILE_ARGS), plastic_fields(None)
    assert fast[3] == default[3] and 0 < fast[3] < 512  # the same Gauss points yield: some, not all
    for name, a, b in zip(("tangent", "internal force", "stress"), fast[:3], default[:3]):
        rel = np.abs(a - b).max() / np.abs(b).max()
        print(f"\n  {name}: max relative difference {rel:.1e}")
        assert rel < 1e-12, name


def test_numpy_return_map_agrees_with_ufl():
    """The numpy radial return and von Mises pieces NNEQM2 uses (material.py) against the UFL forms,
    on a non-homogeneous two-increment path where some Gauss points yield twice, some once, some never."""
    import dolfinx.mesh as dmesh
    from mpi4py import MPI

    from dolfinx_nnqem import compat, jit
    from dolfinx_nnqem.material.von_mises import (deviator_coordinates, deviator_tensors, equivalent_stress, flow_direction,
                                        radial_return, strain)

    material = VonMises(E=2.0e11, nu=0.3, sigma_y0=2.5e8, H=1.0e10)
    mesh = dmesh.create_box(MPI.COMM_SELF, [np.zeros(3), np.ones(3)], [2, 2, 2], dmesh.CellType.hexahedron)
    V = fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    state = PlasticState(V, material)
    u = fem.Function(V)
    rng = np.random.default_rng(4)
    points = compat.interpolation_points(state.W_tensor)
    eps_fn = fem.Function(state.W_tensor)
    eps_expr = jit.expression(strain(u), points)
    n = state.W_scalar.dofmap.index_map.size_local
    lmbda, mu = np.full(n, material.lmbda), np.full(n, material.mu)
    sy, H = np.full(n, material.sigma_y0), np.full(n, material.H)
    worst = 0.0
    eps_old = np.zeros((n, 3, 3))
    for scale in (4.0e-4, 9.0e-4):
        A = rng.normal(size=(3, 3, 3))
        u.interpolate(lambda x, A=A: scale * np.einsum("ijk,jn,kn->in", A, x, x))
        eps_fn.interpolate(eps_expr)
        eps = eps_fn.x.array.reshape(n, 3, 3).copy()
        sigma_n = state.sigma_n.x.array.reshape(n, 3, 3).copy()
        p_n = state.p_n.x.array.copy()
        sigma, dp = radial_return(sigma_n, eps - eps_old, p_n, lmbda, mu, sy, H)
        state.commit(u)  # the UFL return map
        err_sigma = np.abs(sigma - state.sigma_n.x.array.reshape(n, 3, 3)).max() / material.sigma_y0
        err_dp = np.abs(dp - state.dp_n.x.array).max() / max(dp.max(), 1e-300)
        worst = max(worst, err_sigma, err_dp)
        print(f"\n  increment to {scale:.1e}: {int(np.sum(dp > 0))} of {n} Gauss points yield; numpy vs UFL: "
              f"max |Δσ| / σ_y0 = {err_sigma:.1e}, max |ΔΔp| / max Δp = {err_dp:.1e}")
        eps_old = eps
    s = deviator_coordinates(state.sigma_n.x.array.reshape(n, 3, 3))
    dev = state.sigma_n.x.array.reshape(n, 3, 3) - np.trace(state.sigma_n.x.array.reshape(n, 3, 3), axis1=1,
                                                            axis2=2)[:, None, None] * np.eye(3) / 3
    q_direct = np.sqrt(1.5 * np.einsum("nij,nij->n", dev, dev))
    N = deviator_tensors(flow_direction(s, np.full(n, material.sigma_y0)))
    err_q = np.abs(equivalent_stress(s) - q_direct).max() / q_direct.max()
    err_N = np.abs(N - 1.5 * dev / q_direct[:, None, None]).max()
    print(f"  deviator coordinates: q {err_q:.1e}, N = 3s/(2q) {err_N:.1e} (tolerance 1e-12)")
    assert worst < 1e-12 and err_q < 1e-12 and err_N < 1e-12
