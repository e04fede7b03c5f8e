"""Hertz contact on independent meshes: a steel sphere on an aluminium block, dual mortar.

``dolfinx_nnqem/sphere_on_block.py`` sets the problem up: a quarter hemisphere (R = 20 mm) and a
quarter block (10 mm), each meshed with tetrahedra on its own and refined towards the contact
point, the sphere's cap the (finer) mortar slave surface, the equatorial face pushed down by
δ = 0.046 mm, frictionless. Compared with Hertz (two elastic bodies, E* from both) at the
computed force F (Σ pair forces × 4):

- a: the radius of the Hertz pressure for the measured F whose nodal forces best fit the
  pair forces (``hertz.measure_hertz``);
- p0: the centre (pole) node's pressure f / D (mortar: the nodal force over ∫ N dA), and
  p0_fit, a and p0 fitted together to all pair forces (``hertz.fit_hertz_profile``): on
  unstructured tetrahedra the nodal pressures scatter by a few per cent from node to node, the
  centre node's too, so the fitted peak shows the trend under refinement better.

Tolerances from the issue: a and p0 within 5 % of Hertz on the demo mesh (h = a/7), errors
falling under refinement (h = a/3, a/5, a/7; a/10 is slow). The solvers and laws are compared
with monolithic/Alart–Curnier on a small mesh (R = 5 mm), along the load path each method took
(friction: path dependent).

Quadratic elements (issue 28): P2 on a second-order mesh, node-to-surface, against Hertz by the
nodal pressures (``nodal_pressure_fit``); the table of both degrees is in docs/nonmatching-hertz.md.
"""

import subprocess
import sys
import time

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem import compat
from dolfinx_nnqem.cases.hertz import NodalLoads
from dolfinx_nnqem.cases.geometries import SphereOnBlockTags as T
from dolfinx_nnqem.cases.geometries import build_sphere_on_block
from dolfinx_nnqem.io import equilibrium_check, pair_table
from dolfinx_nnqem.solvers import SolverOptions, make_solver
from dolfinx_nnqem.cases.sphere_on_block import A_NOMINAL, measure_sphere_on_block, sphere_on_block_problem
from dolfinx_nnqem.solvers import solve_load_path, solve_load_steps
from dolfinx_nnqem.solvers.contract import contact_model

DEMO_H = A_NOMINAL / 7  # the demo's mesh
SMALL = dict(R=5.0, block=3.0, approach=0.1, h_max=1.0, fine_radius=0.8, contact_radius=1.5)  # h = 0.5


# -- the mesh -----------------------------------------------------------------------------------------
def test_sphere_on_block_mesh_is_two_independent_tetrahedral_bodies():
    mesh, cell_tags, facet_tags = build_sphere_on_block(MPI.COMM_WORLD, h_contact=0.5)
    assert mesh.topology.cell_type.name == "tetrahedron"
    x = mesh.geometry.x
    geometry_dofmap = mesh.geometry.dofmaps[0] if hasattr(mesh.geometry, "dofmaps") else mesh.geometry.dofmap
    nodes = {}
    for body in (T.BLOCK, T.SPHERE):
        cells = cell_tags.find(body)
        local = np.unique(geometry_dofmap[cells].reshape(-1))
        nodes[body] = local
        count = MPI.COMM_WORLD.allreduce(len(cells), op=MPI.SUM)
        print(f"\n  body {body}: {count} tetrahedra", end="")
        assert count > 0
    # no shared node (a node shared by two bodies would be in both cells' closures)
    assert len(np.intersect1d(nodes[T.BLOCK], nodes[T.SPHERE])) == 0
    # each body has a node at the contact point (gap zero at the pole)
    for body in (T.BLOCK, T.SPHERE):
        here = np.linalg.norm(x[nodes[body]], axis=1).min() if len(nodes[body]) else np.inf
        assert MPI.COMM_WORLD.allreduce(here, op=MPI.MIN) < 1e-12
    counts = {tag: MPI.COMM_WORLD.allreduce(len(facet_tags.find(tag)), op=MPI.SUM)
              for tag in (T.BOTTOM, T.LOAD, T.CONTACT1, T.CONTACT2, T.BLOCK_XMIN, T.BLOCK_XMAX, T.BLOCK_ZMIN,
                          T.BLOCK_ZMAX, T.SPHERE_XMIN, T.SPHERE_ZMIN, T.SPHERE_FREE)}
    print(f"\n  facets per tag: {counts}")
    assert all(n > 0 for n in counts.values())
    # the cap lies within the contact radius of the axis, and on the sphere
    from dolfinx.mesh import entities_to_geometry

    cap = facet_tags.find(T.CONTACT2)
    if len(cap):
        cap_x = x[np.asarray(entities_to_geometry(mesh, 2, cap)).reshape(-1)]
        assert np.hypot(cap_x[:, 0], cap_x[:, 2]).max() <= 2.0 + 1e-9
        assert np.abs(np.linalg.norm(cap_x - [0.0, 20.0, 0.0], axis=1) - 20.0).max() < 1e-6


# -- Hertz under refinement ---------------------------------------------------------------------------
def run_level(h: float) -> dict:
    t0 = time.perf_counter()
    problem = sphere_on_block_problem(h)
    results = solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-10)), 1)
    m = measure_sphere_on_block(problem)
    t = m["table"]
    loads = NodalLoads(problem, m["slave"], t["slave_block"])
    m.update(h=h, iterations=results[0].iterations, time=time.perf_counter() - t0,
             dofs=3 * problem.V.dofmap.index_map.size_global, describe=problem.contact.describe()[0],
             area_vs_D=np.abs(loads.area - t["area"]).max() / t["area"].max(),
             friction=np.abs(t["force_local_body1"][:, 1:]).max() / np.abs(t["force_local_body1"][:, 0]).max())
    return m


def print_levels(levels: list[dict]) -> None:
    print(f"\n  {levels[0]['describe']}")
    print("   h      dofs  slave nodes (closed)  its  time    F (N)   a err    p0 err (centre)  p0 err (fit)  "
          "imbalance")
    for m in levels:
        print(f"  a/{A_NOMINAL / m['h']:<4.0f} {m['dofs']:6d}  {m['pairs']:5d} ({m['closed']:4d})       "
              f"{m['iterations']:3d} {m['time']:5.1f}s  {m['F']:7.1f}  {100 * m['err_a']:+6.2f} %  "
              f"{100 * m['err_p0']:+6.2f} %         {100 * m['err_p0_fit']:+6.2f} %       {m['imbalance']:.1e}")


def check_level(m: dict) -> None:
    assert m["slave"] == T.CONTACT2  # the sphere's cap is the finer side
    assert m["imbalance"] < 1e-10
    assert m["friction"] < 1e-10  # frictionless
    assert m["area_vs_D"] < 1e-12  # the pair areas are the mortar D_jj = ∫ N_j dA
    # the FE contact zone ends between the last closed and the first open slave node
    assert m["r_closed"] - m["h"] < m["a"] < m["r_open"] + m["h"]


def test_hertz_nonmatching_refinement():
    """h = a/3, a/5, a/7 (the demo mesh): a and p0 within 5 %, the errors of a and of the fitted p0
    falling.

    The centre node's p0 is only held within 5 %: it is the pressure at one node, and which node
    sits at the centre, and how its neighbours are shaped, depends on the mesh generator. On
    Netgen-optimised meshes (gmsh 4.15, PyPI) it was −6.32, −3.77, −2.76 %; on gmsh's own
    optimiser (Debian's gmsh 4.13 has no Netgen) −2.29, −4.32, −2.48 %, and at a/14 −2.87 %: it
    does not fall steadily at these sizes, so no order is asserted of it.
    """
    levels = [run_level(A_NOMINAL / n) for n in (3, 5, 7)]
    print_levels(levels)
    for m in levels:
        check_level(m)
        assert abs(m["err_p0"]) < 0.07  # the centre node: within 7 % already at a/3
    demo = levels[-1]
    assert abs(demo["err_a"]) < 0.05 and abs(demo["err_p0"]) < 0.05 and abs(demo["err_p0_fit"]) < 0.05
    errors_a = [abs(m["err_a"]) for m in levels]
    errors_p0_fit = [abs(m["err_p0_fit"]) for m in levels]
    assert errors_a == sorted(errors_a, reverse=True) and errors_a[-1] < errors_a[0]
    assert errors_p0_fit == sorted(errors_p0_fit, reverse=True) and errors_p0_fit[-1] < errors_p0_fit[0]


@pytest.mark.slow
def test_hertz_nonmatching_finer():
    """h = a/7 and a/10: within 5 %, the error of a still falling."""
    levels = [run_level(A_NOMINAL / n) for n in (7, 10)]
    print_levels(levels)
    for m in levels:
        check_level(m)
        assert abs(m["err_a"]) < 0.05 and abs(m["err_p0"]) < 0.05 and abs(m["err_p0_fit"]) < 0.05
    assert abs(levels[1]["err_a"]) < abs(levels[0]["err_a"])


# -- the solvers and laws agree -----------------------------------------------------------------------
_REFERENCE: dict[tuple, np.ndarray] = {}
# NNEQM1 (NNEQM2) at rtol = 1e-10 lands 8.7e-9 (6.5e-9, Alart–Curnier, μ_f = 0.1) from the reference, at the
# edge of the 1e-8 comparison; the polar law in the monolithic solver stalls near |H|/F = 4e-12,
# so it keeps 1e-10 (the reference, Alart–Curnier, converges to 1e-12)
RTOL = {"nneqm1": 1e-12, "nneqm2": 1e-12}


def solve_small(method: str, law: str, mu_f: float) -> tuple[dict, list]:
    """The small model in one increment (cutbacks allowed): pair table and the increments taken."""
    problem = sphere_on_block_problem(0.5, mu_f=mu_f, law=law, **SMALL)
    options = SolverOptions(rtol=RTOL.get(method, 1e-10), max_iterations=40)
    results = solve_load_steps(problem, make_solver(method, problem, options), 1)
    return pair_table(problem), results


def reference(mu_f: float, path: tuple[float, ...]) -> np.ndarray:
    """The monolithic solver with the Alart–Curnier law along the same load path: pair forces.

    With friction the solution depends on the path, so a method that cut an increment back is
    compared with the reference along the increments it took.
    """
    key = (mu_f, path)
    if key not in _REFERENCE:
        problem = sphere_on_block_problem(0.5, mu_f=mu_f, **SMALL)
        solve_load_path(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-12, max_iterations=40)),
                        path)
        _REFERENCE[key] = pair_table(problem)["force_on_body1"]
    return _REFERENCE[key]


@pytest.mark.parametrize("method, law, mu_f", [
    ("nneqm1", "alart-curnier", 0.0),
    ("nneqm1", "polar", 0.0),
    ("monolithic", "polar", 0.0),  # converges here (10 iterations); stopped on R = 20 mm, h = 0.33 mm (see docs)
    ("nneqm1", "alart-curnier", 0.1),
    ("monolithic", "polar", 0.1),
    ("nneqm1", "polar", 0.1),  # cuts the increment in two: compared along that path
    ("nneqm2", "alart-curnier", 0.0),
    ("nneqm2", "polar", 0.0),
    ("nneqm2", "alart-curnier", 0.1),
    ("nneqm2", "polar", 0.1),
])
def test_solvers_and_laws_agree_with_monolithic(method, law, mu_f):
    """Small mesh (R = 5 mm, h = 0.5 mm): the same pair forces as monolithic/Alart–Curnier along the
    same load path, to 1e-8."""
    t0 = time.perf_counter()
    table, results = solve_small(method, law, mu_f)
    elapsed = time.perf_counter() - t0
    path = tuple(round(r.load_factor, 12) for r in results)
    ref = reference(mu_f, path)
    diff = np.abs(table["force_on_body1"] - ref).max() / np.abs(ref).max()
    print(f"\n  {method}/{law}, μ_f = {mu_f}: {len(ref)} pairs, load path {list(path)}, iterations "
          f"{[r.iterations for r in results]}, {elapsed:.1f} s; max |Δ pair force| / max |f| = {diff:.1e} "
          "(tolerance 1e-8)")
    assert diff < 1e-8


# -- symmetry planes ----------------------------------------------------------------------------------
def test_slave_normals_on_the_symmetry_planes_lie_in_the_planes():
    """The quarter model's slave nodes on x = 0 (u_x prescribed) and z = 0 (u_z prescribed): their
    pair normals have no x (z) component, so the frames hold e_x (e_z) exactly and the contact
    model pins that friction direction; the pole is on both planes: n = ±e_y, both tangents pinned.
    The averaged normals of the one-sided facets tilt out of the planes (printed)."""
    from dolfinx_nnqem.contact.surfaces import gather_surfaces

    problem = sphere_on_block_problem(0.5, mu_f=0.1, **SMALL)
    c = problem.contact
    pairs = c.interfaces[0].pairs
    X, R = pairs.X_slave, pairs.R
    surfaces = gather_surfaces(problem.V, problem.facet_tags, (T.CONTACT2,))
    tilt = {}
    for axis, name in ((0, "x"), (2, "z")):
        on = np.abs(X[:, axis]) < 1e-12
        assert on.sum() >= 3
        np.testing.assert_array_equal(R[on, 0, axis], 0.0)  # the normal lies in the plane
        e = np.eye(3)[axis]
        along = np.abs(np.abs(R[on][:, 1:, :] @ e) - 1.0) == 0.0  # which tangent is ±e exactly
        assert np.all(along.sum(axis=1) == 1)
        assert np.all(c.constrained[on][:, 1:][along])  # and it is pinned
        nodes = surfaces.nodes[0]
        averaged = nodes.normal[np.abs(nodes.x[:, axis]) < 1e-12]
        tilt[name] = np.abs(averaged[:, axis]).max()
    pole = np.linalg.norm(X, axis=1) < 1e-12
    assert pole.sum() == 1
    np.testing.assert_array_equal(np.abs(R[pole, 0]), [[0.0, 1.0, 0.0]])
    assert np.all(c.constrained[pole][:, 1:])
    print(f"\n  averaged slave normals on the planes: largest out-of-plane component x {tilt['x']:.2e}, "
          f"z {tilt['z']:.2e}; in the pair frames: 0")
    assert max(tilt.values()) > 1e-3  # the tilt the frames remove is there


def test_frictional_hertz_on_the_graded_demo_mesh_in_one_increment():
    """μ_f = 0.1 on the demo mesh (h = a/7) with the default r, monolithic/Alart–Curnier, one
    increment, no cutback allowed. With the averaged normals tilted out of the symmetry planes it
    cycled between stick and slip and failed after 3 cutbacks (docs/nonmatching-hertz.md)."""
    problem = sphere_on_block_problem(A_NOMINAL / 7, mu_f=0.1)
    t0 = time.perf_counter()
    results = solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions()), 1, max_cutbacks=0)
    check = equilibrium_check(problem)
    states = np.bincount(pair_table(problem)["state"].astype(int), minlength=3)
    print(f"\n  {problem.contact.num_global} pairs, {results[0].iterations} iterations, "
          f"{time.perf_counter() - t0:.1f} s; open/stick/slip {states.tolist()}; "
          f"global imbalance {check['global_imbalance']:.1e}, free residual {check['residual_norm']:.1e}")
    assert results[0].cutbacks == 0 and results[0].load_factor == 1.0
    assert check["global_imbalance"] < 1e-8 and check["residual_norm"] < 1e-9
    assert states[1] > 0 and states[2] > 0  # a stick zone and a slip annulus


def test_both_laws_agree_where_a_support_pins_a_friction_direction():
    """The demo mesh with μ_f = 0.1, NNEQM1, one increment: the Cartesian and the polar law give the
    same pair forces. At the sliding slave nodes on a symmetry plane (one friction direction pinned)
    the free direction carries μ_f p_n with either law: the pinned direction's relative motion takes
    no part in the law. Left in the Alart–Curnier law, it cut that force by 0.3 % (8.4e-5 of the
    largest pair force)."""
    tables = {}
    for law in ("alart-curnier", "polar"):
        problem = sphere_on_block_problem(A_NOMINAL / 7, mu_f=0.1, law=law)
        solve_load_steps(problem, make_solver("nneqm1", problem, SolverOptions(rtol=1e-12)), 1, max_cutbacks=0)
        tables[law] = pair_table(problem)
        pinned = problem.contact.constrained[:, 1:].any(axis=1)
    ac, polar = tables["alart-curnier"], tables["polar"]
    diff = np.abs(ac["force_on_body1"] - polar["force_on_body1"]).max() / np.abs(ac["force_on_body1"]).max()
    f = ac["force_local_body1"]
    sliding = pinned & (ac["state"] == 2)
    ratio = np.linalg.norm(f[sliding, 1:], axis=1) / np.abs(f[sliding, 0])
    print(f"\n  max |Δ pair force| / max |f| between the laws: {diff:.1e}; {sliding.sum()} sliding pairs with a "
          f"pinned direction, |q| / p_n from {ratio.min():.12f} to {ratio.max():.12f}")
    assert diff < 1e-12
    assert sliding.sum() >= 2
    np.testing.assert_allclose(ratio, 0.1, rtol=1e-10)


# -- the picture --------------------------------------------------------------------------------------
def test_plot_contact_pressure_writes_png(tmp_path):
    from dolfinx_nnqem.io.plots import plot_contact_pressure

    problem = sphere_on_block_problem(0.5, **SMALL)
    solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions()), 1)
    surface, points = tmp_path / "surface.png", tmp_path / "points.png"
    plot_contact_pressure(problem, surface, title="sphere on block", circle=0.7)
    plot_contact_pressure(pair_table(problem), points, problem=problem)
    if MPI.COMM_WORLD.rank == 0:
        for path in (surface, points):
            size = path.stat().st_size
            print(f"\n  {path.name}: {size} bytes")
            assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and size > 10_000


@pytest.mark.mpi
def test_measure_and_plot_on_two_ranks(tmp_path):
    """Two ranks: the same F, a and p0 as serially (1e-8), and the picture is written."""
    script = tmp_path / "run.py"
    script.write_text(
        "import sys, json\n"
        "import dolfinx_nnqem\n"
        "from mpi4py import MPI\n"
        "from dolfinx_nnqem.io.plots import plot_contact_pressure\n"
        "from dolfinx_nnqem.solvers import SolverOptions, make_solver\n"
        "from dolfinx_nnqem.cases.sphere_on_block import measure_sphere_on_block, sphere_on_block_problem\n"
        "from dolfinx_nnqem.solvers import solve_load_path, solve_load_steps\n"
        f"p = sphere_on_block_problem(0.5, **{SMALL!r})\n"
        "solve_load_steps(p, make_solver('monolithic', p, SolverOptions()), 1)\n"
        f"m = measure_sphere_on_block(p, R={SMALL['R']!r})\n"
        "plot_contact_pressure(p, sys.argv[1])\n"
        "if MPI.COMM_WORLD.rank == 0:\n"
        "    print(json.dumps({k: float(m[k]) for k in ('F', 'a', 'p0', 'pairs')}))\n")
    png = tmp_path / "pressure.png"
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(script), str(png)]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=compat.mpi_environment())
    assert result.returncode == 0, f"{' '.join(cmd)} failed:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    import json

    parallel = json.loads(result.stdout.strip().splitlines()[-1])
    problem = sphere_on_block_problem(0.5, comm=MPI.COMM_SELF, **SMALL)
    solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions()), 1)
    serial = measure_sphere_on_block(problem, R=SMALL["R"])
    errors = {k: abs(parallel[k] - serial[k]) / abs(serial[k]) for k in ("F", "a", "p0")}
    print(f"\n  2 ranks vs serial: {errors} (tolerance 1e-8); {int(parallel['pairs'])} pairs; "
          f"picture {png.stat().st_size} bytes")
    assert parallel["pairs"] == serial["pairs"] and max(errors.values()) < 1e-8
    assert png.stat().st_size > 10_000


# -- quadratic elements (issue 28) ----------------------------------------------------------------------
def nodal_pressure_fit(table, R: float = 20.0) -> dict:
    """F = 4 Σ λ, Hertz's a and p0 at F, the pole node's pressure and the radius a whose Hertz
    profile (p0 = 3F/(2πa²)) best fits the nodal pressures λ_j / ∫N̂_j dA at the slave nodes'
    radii (least squares): a measure that needs no shape functions, the same for P1 and P2."""
    import math

    from scipy.optimize import minimize_scalar

    from dolfinx_nnqem.cases.hertz import hertz_contact
    from dolfinx_nnqem.cases.sphere_on_block import E_STAR

    p = table["pressure"]
    F = 4.0 * float(np.sum(p * table["area"]))
    a_hertz, p0_hertz = hertz_contact(F, R, E_STAR)
    r = np.hypot(table["position_b"][:, 0], table["position_b"][:, 2])
    centre = int(np.argmin(r))
    assert r[centre] < 1e-9  # the pole is a slave node

    def misfit(a: float) -> float:
        return float(np.sum((p - 3.0 * F / (2.0 * math.pi * a * a) * np.sqrt(np.maximum(1.0 - (r / a) ** 2, 0.0))) ** 2))

    a = minimize_scalar(misfit, bounds=(0.5 * a_hertz, 1.5 * a_hertz), method="bounded",
                        options={"xatol": 1e-7 * a_hertz}).x
    return {"F": F, "err_a": a / a_hertz - 1.0, "err_p0": p[centre] / p0_hertz - 1.0}


@pytest.mark.parametrize("discretisation", ["node-to-surface", "mortar"])
def test_hertz_with_quadratic_elements_on_a_second_order_mesh(discretisation):
    """P2 on 10-node tetrahedra (the cap's facets curved, the slave side), node-to-surface or dual
    mortar on the curved tri6 facets, h = a/3 at the contact and a coarser bulk (h_max 5 mm, growth
    0.6: quadratic elements need fewer cells away from the contact): 12 153 dofs. Measured: a +2.2 %,
    p0 (pole) −1.3 % (node-to-surface), a +1.5 %, p0 −1.2 % (mortar); the trilinear mortar mesh of the
    table in docs/nonmatching-hertz.md reaches p0 −1.1 % with 19 227 dofs (a/10)."""
    from dolfinx_nnqem.cases.sphere_on_block import APPROACH, BLOCK, BLOCK_MATERIAL, R_SPHERE, SPHERE_MATERIAL
    from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet

    t0 = time.perf_counter()
    mesh, ct, ft = build_sphere_on_block(MPI.COMM_WORLD, R_SPHERE, BLOCK, A_NOMINAL / 3, h_max=5.0, growth=0.6, order=2)
    problem = ContactProblem(
        mesh, ct, ft, materials={T.BLOCK: BLOCK_MATERIAL, T.SPHERE: SPHERE_MATERIAL},
        dirichlet=[Dirichlet(T.BOTTOM), Dirichlet(T.LOAD, -APPROACH, [1]),
                   Dirichlet(T.BLOCK_XMIN, 0.0, [0]), Dirichlet(T.SPHERE_XMIN, 0.0, [0]),
                   Dirichlet(T.BLOCK_ZMIN, 0.0, [2]), Dirichlet(T.SPHERE_ZMIN, 0.0, [2])],
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=0.0, discretisation=discretisation))
    assert problem.V.ufl_element().embedded_superdegree == 2  # the mesh's order
    assert contact_model(problem).interfaces[0].pairs.kind == discretisation
    results = solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-10)), 1)
    table = pair_table(problem)
    m = nodal_pressure_fit(table)
    dofs = 3 * problem.V.dofmap.index_map.size_global
    imbalance = equilibrium_check(problem)["global_imbalance"]
    print(f"\n  P2, {discretisation}, h = a/3, {dofs} dofs, {len(table['state'])} slave nodes ({np.count_nonzero(table['state'])} closed), "
          f"{results[0].iterations} iterations, {time.perf_counter() - t0:.1f} s: F {m['F']:.1f} N, a {m['err_a']:+.2%}, "
          f"p0 (pole) {m['err_p0']:+.2%}, imbalance {imbalance:.1e}")
    assert imbalance < 1e-10
    assert abs(m["err_a"]) < 0.03 and abs(m["err_p0"]) < 0.02
