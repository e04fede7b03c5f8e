"""V3: thick-walled cylinder under internal pressure, plane strain, perfect plasticity.

Also the second half of V2: the Newton residual sequence of a plastic increment converges
quadratically with the consistent tangent.
"""

import math

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.solvers import ConvergenceError
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.cases.geometries import ThickCylinderTags as T
from dolfinx_nnqem.cases.geometries import build_thick_cylinder
from dolfinx_nnqem.solvers.monolithic import MonolithicSolver
from dolfinx_nnqem.problem import ContactProblem, Dirichlet, Pressure
from dolfinx_nnqem.solvers import SolverOptions
from dolfinx_nnqem.io.results import node_blocks_at_points, values_at_blocks
from dolfinx_nnqem.solvers import solve_load_steps

A, B = 1.0, 2.0
MATERIAL = VonMises(E=70e3, nu=0.3, sigma_y0=250.0, H=0.0)


def lame_radial_displacement(r, p, material, a=A, b=B):
    """Plane-strain Lamé solution u_r(r) for internal pressure p."""
    E, nu = material.E, material.nu
    return (1 + nu) * p * a**2 / (E * (b**2 - a**2)) * ((1 - 2 * nu) * r + b**2 / r)


def limit_pressure(material, a=A, b=B):
    return 2.0 / math.sqrt(3.0) * material.sigma_y0 * math.log(b / a)


def cylinder_problem(p_max, degree=2, n_radial=4, n_circumferential=12):
    mesh, cell_tags, facet_tags = build_thick_cylinder(MPI.COMM_WORLD, A, B, 0.1, n_radial, n_circumferential)
    return ContactProblem(
        mesh, cell_tags, facet_tags, materials=MATERIAL, degree=degree,
        dirichlet=[Dirichlet(T.SYMMETRY_X, 0.0, [0]), Dirichlet(T.SYMMETRY_Y, 0.0, [1]),
                   Dirichlet(T.FACES_Z, 0.0, [2])],
        tractions=[Pressure(T.INNER, p_max)],
    )


def test_v3_thick_cylinder_elastic_range_and_limit_pressure():
    """Quadratic hexahedra (Q2, 3×3×3 Gauss points): trilinear ones lock in the isochoric
    plastic flow and keep a residual stiffness past p_lim. Collapse is declared when the
    displacement exceeds 5 % of the inner radius (max_displacement)."""
    p_lim = limit_pressure(MATERIAL)
    p_max = 1.05 * p_lim  # beyond the limit: the load stepping must stop near p_lim
    problem = cylinder_problem(p_max)
    solver = MonolithicSolver(problem, SolverOptions(max_iterations=15))
    probes = node_blocks_at_points(problem, np.array([[A, 0.0, 0.0], [B, 0.0, 0.0]]))
    history = []

    def record(result):
        u = values_at_blocks(problem, probes)
        history.append((result.load_factor * p_max, u[:, 0], result.report, result.plastic_points))

    try:
        solve_load_steps(problem, solver, 12, max_cutbacks=5, callbacks=[record],
                         max_displacement=0.05 * A)
        reached_end = True
    except ConvergenceError as error:
        reached_end = False
        print(f"\n  load stepping stopped: {str(error).splitlines()[0]}")

    # elastic range: first increment against Lamé
    p1, u1, _, plastic1 = history[0]
    assert plastic1 == 0
    ref = lame_radial_displacement(np.array([A, B]), p1, MATERIAL)
    err = np.abs(u1 - ref) / np.abs(ref)
    print(f"  elastic increment p = {p1:.3f}: u_r(a) = {u1[0]:.6e} (Lamé {ref[0]:.6e}, {err[0]:.2e}), "
          f"u_r(b) = {u1[1]:.6e} (Lamé {ref[1]:.6e}, {err[1]:.2e})")
    assert np.all(err < 5e-3)

    # limit pressure
    p_last = history[-1][0]
    print(f"  last converged pressure {p_last:.3f}, p_lim = {p_lim:.3f}, ratio {p_last / p_lim:.4f}")
    assert not reached_end, "converged beyond 1.05 p_lim: no limit load"
    assert abs(p_last / p_lim - 1.0) < 0.02

    # V2: quadratic convergence of Newton with the consistent tangent in a plastic increment
    plastic = [(p, rep) for p, _, rep, n_pl in history if n_pl > 0 and rep.iterations >= 4]
    p, rep = plastic[0]
    seq = [h.equilibrium for h in rep.history]
    print(f"  residual sequence at p = {p:.2f}: " + ", ".join(f"{e:.2e}" for e in seq))
    # order estimate log(e_{k+1}) / log(e_k) over the last steps above round-off
    tail = [e for e in seq if e > 1e-13]
    orders = [math.log(tail[k + 1]) / math.log(tail[k]) for k in range(len(tail) - 2, len(tail) - 1)]
    print(f"  convergence order estimate (last step above round-off): {orders}")
    assert orders[-1] > 1.8
