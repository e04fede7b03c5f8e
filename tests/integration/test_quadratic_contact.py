"""Contact with degree-2 displacements: P2 tetrahedra and Q2 hexahedra (issue 28).

* The quadratic facets: the transformed basis gives every tri6 node a positive weight (2A/15 at
  the corners, A/5 on the edges, α = 1/5), the quad9's own weights are A/36, A/9, 4A/9; the rows
  d̂ = T⁻ᵀ d represent the same displacement (Σ N_i d_i = Σ N̂_j d̂_j); the projection onto curved
  6-node triangles of a sphere finds its distance to the facets' own accuracy.
* Patch test on matching meshes (hexahedra; structured tetrahedra whose interface triangles
  coincide): a uniform pressure, and a pressure with a uniform shear, are transmitted exactly —
  the pressure λ_j / ∫N̂_j dA at every slave node (tri6 corners too), the traction and σ at every
  Gauss point, 1e-8 — by node-to-node and node-to-surface pairs, every method, both laws.
* Non-matching node-to-surface does not pass it (as with degree 1): the error is printed.
* A rigid plane pressed into a cube on rollers: the uniaxial force, elastic (E δ) and von Mises
  (its closed form), on tetrahedra and hexahedra, every method, both laws.
* Dual mortar on quadratic facets (the dual basis on the transformed basis): the patch test on
  non-matching hexahedra and tetrahedra, exact (1e-8), every method, both laws; ``auto`` takes it
  on non-matching meshes; from a problem file too. Contact on a mesh of geometry degree 3 is
  refused before solving.
* The solver variants (NNEQM1 modified, NNEQM2 frozen, monolithic iterative) take degree 2.
* A problem file with ``degree = 2``; 2 ranks give the serial answer.
* Second-order gmsh meshes (10-node tetrahedra, 27-node hexahedra) written by gmsh and read back
  with ``read_msh`` and from a problem file: degree 2 by default, the patch test exact; a
  hemisphere's curved cap keeps every slave node on the sphere; 20-node hexahedra and third-order
  tetrahedra are refused with the reason.
* ``fields_p2.pvd``: the quadratic displacement on VTK Lagrange cells, read back (pyvista) equal to
  u at every P2 node; a restart keeps the steps up to the checkpoint.
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import box_with_face_tags
from mpi4py import MPI
from problem_files import pressed_block_stack

from dolfinx_nnqem import compat
from dolfinx_nnqem.contact import quadratic_facets as qf
from dolfinx_nnqem.contact.obstacles import Plane
from dolfinx_nnqem.contact.quadratic_projection import project_points_quadratic
from dolfinx_nnqem.contact.surfaces import ContactPairError
from dolfinx_nnqem.io import equilibrium_check, pair_table
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure, Traction
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.cases.geometries import build_block_stack, build_sphere_on_block
from dolfinx_nnqem.problem.meshing import read_msh
from dolfinx_nnqem.solvers import METHODS, SolverOptions, make_solver, solve_load_steps
from dolfinx_nnqem.solvers.contract import contact_model

SCRIPTS = Path(__file__).resolve().parents[1] / "mpi_scripts"
P = 1.0e6
TAU = 0.2 * P
MU_F = 0.3


# -- the quadratic facets --------------------------------------------------------------------------
def flat_facet(k, corners):
    """A straight-sided quadratic facet from its vertices (midpoints, centre)."""
    corners = np.asarray(corners, dtype=float)
    extra = [0.5 * (corners[a] + corners[b]) for a, b in qf.EDGES[k]]
    if k == 9:
        extra.append(corners.mean(axis=0))
    return np.vstack([corners, extra])


def test_transformed_weights_are_positive_and_the_rows_keep_the_displacement():
    tri = flat_facet(6, [[0, 0, 0], [2, 0, 0], [0.5, 0, -1.5]])
    quad = flat_facet(9, [[0, 0, 0], [2, 0, 0], [0.5, 0, -1.5], [2.5, 0, -1.5]])  # a parallelogram
    for k, x, expected in ((6, tri, [2 / 15] * 3 + [1 / 5] * 3), (9, quad, [1 / 36] * 4 + [1 / 9] * 4 + [4 / 9])):
        area = np.linalg.norm(np.cross(x[1] - x[0], x[2] - x[0])) / (2 if k == 6 else 1)
        weights, moments = qf.nodal_integrals(x[None], np.array([[0.0, 1.0, 0.0]]))
        print(f"\n  k = {k}: ∫N̂_j dA / A = {np.round(weights[0] / area, 6).tolist()}")
        np.testing.assert_allclose(weights[0] / area, expected, rtol=1e-12)
        np.testing.assert_allclose(moments[0], weights[0][:, None] * [0.0, 1.0, 0.0], atol=1e-15)
        # u = Σ N_i d_i = Σ N̂_j d̂_j with d̂ = T⁻ᵀ d, for a random d, at random points
        d = np.random.default_rng(k).normal(size=k)
        rows = qf.node_combination(np.arange(k)[None], np.arange(k))
        xi = np.random.default_rng(1).uniform(0, 0.5, (7, 2))
        u = qf.shape_functions(k, xi) @ d
        np.testing.assert_allclose(qf.transformed_shape_functions(k, xi) @ rows.apply(d), u, atol=1e-13)
        assert np.allclose(np.bincount(np.repeat(np.arange(k), np.diff(rows.indptr)), rows.coefficients), 1.0)


def test_projection_on_curved_six_node_triangles():
    """Slave points above a sphere (R = 2) meshed by curved tri6 facets (h = 0.25): the gap is the
    distance to the sphere up to the facets' geometric error, O(h³/R²)."""
    R, n = 2.0, 4

    def on_sphere(xy):
        xy = np.asarray(xy, dtype=float)
        return np.column_stack([xy, np.sqrt(R ** 2 - (xy ** 2).sum(axis=-1))])

    g = np.linspace(-0.5, 0.5, n + 1)
    facets = []
    for i in range(n):
        for j in range(n):
            for tri in (((g[i], g[j]), (g[i + 1], g[j]), (g[i], g[j + 1])),
                        ((g[i + 1], g[j + 1]), (g[i], g[j + 1]), (g[i + 1], g[j]))):
                v = np.array(tri)
                facets.append(on_sphere(np.vstack([v, [(v[1] + v[2]) / 2, (v[0] + v[2]) / 2, (v[0] + v[1]) / 2]])))
    x = np.array(facets)
    outward = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    outward *= np.sign(outward[:, 2])[:, None]
    rng = np.random.default_rng(0)
    points = on_sphere(rng.uniform(-0.45, 0.45, (200, 2))) * (1.0 + rng.uniform(0.0, 0.01, (200, 1)))
    p = project_points_quadratic(points, x, outward)
    gap_error = np.abs(p.g0 - (np.linalg.norm(points, axis=1) - R)).max()
    normal_error = np.abs(p.normal - points / np.linalg.norm(points, axis=1)[:, None]).max()
    print(f"\n  200 points over a sphere R = 2 meshed by 32 curved tri6 facets (h = 0.25): max gap error "
          f"{gap_error:.1e}, normal {normal_error:.1e}, tangential offset {p.tangential_offset.max():.1e}")
    assert np.all(p.facet >= 0) and p.tangential_offset.max() < 1e-12
    assert gap_error < 2e-4 and normal_error < 3e-3  # the facets' own error (h³/R² ≈ 4e-3 h)


# -- patch tests -------------------------------------------------------------------------------------
MESHES = {"hex matching": ("hexahedron", [(3, 1, 3), (3, 1, 3)], True),
          "tet matching": ("tetrahedron", [(3, 2, 3), (3, 2, 3)], True),
          "hex 4x4 / 3x3": ("hexahedron", [(4, 1, 4), (3, 1, 3)], False),
          "tet 4x4 / 3x3": ("tetrahedron", [(4, 2, 4), (3, 2, 3)], False)}


def two_blocks(mesh_name, discretisation, law="alart-curnier", drag=False, comm=MPI.COMM_WORLD):
    """Body 1 (y in [0, 0.5]) under body 2 (y in [0.5, 1]), degree 2; pressure p (and the drag τ) on top."""
    cell_type, divisions, structured = MESHES[mesh_name]
    mesh, ct, ft = build_block_stack(comm, 1.0, 1.0, [0.5, 0.5], divisions, cell_type=cell_type,
                                     structured=structured)
    return stacked_problem(mesh, ct, ft, discretisation, law, drag, degree=2)


def stacked_problem(mesh, ct, ft, discretisation, law="alart-curnier", drag=False, degree=None):
    """The patch test on a :func:`build_block_stack` mesh of two blocks (``degree`` None: the mesh's)."""
    material = VonMises(E=1.0e9, nu=0.0 if drag else 0.3)
    if drag:  # σ = −p e_y⊗e_y + τ (e_x⊗e_y + e_y⊗e_x): clamped bottom, tractions on the other faces
        dirichlet = [Dirichlet(T.bottom(1))]
        tractions = [Traction(T.top(2), (TAU, -P, 0.0))]
        tractions += [Traction(T.xmax(k), (0.0, TAU, 0.0)) for k in (1, 2)]
        tractions += [Traction(T.xmin(k), (0.0, -TAU, 0.0)) for k in (1, 2)]
    else:  # rollers and symmetry planes
        dirichlet = [Dirichlet(T.bottom(1), 0.0, [1])]
        dirichlet += [Dirichlet(T.xmin(k), 0.0, [0]) for k in (1, 2)]
        dirichlet += [Dirichlet(T.zmin(k), 0.0, [2]) for k in (1, 2)]
        tractions = [Pressure(T.top(2), P)]
    contact = Contact(T.top(1), T.bottom(2), mu_f=MU_F, law=law, discretisation=discretisation)
    return ContactProblem(mesh, ct, ft, materials={1: material, 2: material}, dirichlet=dirichlet,
                          tractions=tractions, contact=contact, degree=degree)


def patch_errors(problem, drag):
    """Largest relative errors of the slave nodes' pressures, of their tractions and of σ."""
    t = pair_table(problem)
    exact = np.zeros((3, 3))
    exact[1, 1] = -P
    if drag:
        exact[0, 1] = exact[1, 0] = TAU
    err_p = np.max(np.abs(t["pressure"] - P)) / P
    traction = t["force_on_body1"] / t["area"][:, None]
    err_t = np.max(np.abs(traction - t["frame"][:, 0, :] @ exact)) / P
    sigma = problem.state.sigma_n.x.array.reshape(-1, 3, 3)
    err_sigma = MPI.COMM_WORLD.allreduce(float(np.max(np.abs(sigma - exact))) / P, op=MPI.MAX)
    return t, err_p, err_t, err_sigma


@pytest.mark.parametrize("drag", [False, True], ids=["pressure", "pressure+drag"])
@pytest.mark.parametrize("law", ["alart-curnier", "polar"])
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("discretisation", ["auto", "node-to-surface"])
@pytest.mark.parametrize("mesh_name", ["hex matching", "tet matching"])
def test_patch_test_on_matching_meshes(mesh_name, discretisation, method, law, drag):
    problem = two_blocks(mesh_name, discretisation, law, drag)
    results = solve_load_steps(problem, make_solver(method, problem, SolverOptions(rtol=1e-12)), 1)
    t, err_p, err_t, err_sigma = patch_errors(problem, drag)
    imbalance = equilibrium_check(problem)["global_imbalance"]
    print(f"\n  {mesh_name}, {method}/{law}, {'drag' if drag else 'pressure'}: {problem.contact.describe()[0]}; "
          f"{results[0].iterations} iterations; max |pressure − p|/p = {err_p:.2e}, traction {err_t:.2e}, "
          f"max |σ − σ_exact|/p = {err_sigma:.2e}, global imbalance {imbalance:.1e} (tolerance 1e-8)")
    kind = "node-to-node" if discretisation == "auto" else discretisation
    assert problem.contact.interfaces[0].pairs.kind == kind
    assert problem.num_pairs == len(t["state"]) == 49 and np.all(t["state_name"] == "stick")  # 7 × 7 nodes
    assert err_p < 1e-8 and err_t < 1e-8 and err_sigma < 1e-8 and imbalance < 1e-10


@pytest.mark.parametrize("mesh_name", ["hex 4x4 / 3x3", "tet 4x4 / 3x3"])
def test_node_to_surface_fails_the_patch_test_on_non_matching_meshes(mesh_name):
    """As with degree 1: the slave nodes' forces are spread over the master by its shape functions."""
    problem = two_blocks(mesh_name, "node-to-surface")
    solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-12)), 1)
    _, err_p, err_t, err_sigma = patch_errors(problem, False)
    imbalance = equilibrium_check(problem)["global_imbalance"]
    print(f"\n  {mesh_name}, node-to-surface, degree 2: {problem.contact.describe()[0]}; max |pressure − p|/p = "
          f"{err_p:.2e}, traction {err_t:.2e}, max |σ − σ_exact|/p = {err_sigma:.2e}, global imbalance {imbalance:.1e}")
    assert imbalance < 1e-10
    assert err_sigma > 1e-3


@pytest.mark.parametrize("drag", [False, True], ids=["pressure", "pressure+drag"])
@pytest.mark.parametrize("law", ["alart-curnier", "polar"])
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("mesh_name", ["hex 4x4 / 3x3", "tet 4x4 / 3x3"])
def test_mortar_patch_test_on_non_matching_meshes(mesh_name, method, law, drag):
    """Dual mortar on the transformed basis (contact/dual_quadratic.py): the uniform pressure, and
    the pressure with a uniform shear, exact on non-matching Q2 and P2 meshes, every slave node
    (vertices, edge nodes, quad9 centres) a pair, tri6 corners too."""
    problem = two_blocks(mesh_name, "mortar", law, drag)
    results = solve_load_steps(problem, make_solver(method, problem, SolverOptions(rtol=1e-12)), 1)
    t, err_p, err_t, err_sigma = patch_errors(problem, drag)
    imbalance = equilibrium_check(problem)["global_imbalance"]
    pairs = problem.contact.interfaces[0].pairs
    print(f"\n  {mesh_name}, {method}/{law}, {'drag' if drag else 'pressure'}: {problem.contact.describe()[0]}; "
          f"{results[0].iterations} iterations; max |pressure − p|/p = {err_p:.2e}, traction {err_t:.2e}, "
          f"max |σ − σ_exact|/p = {err_sigma:.2e}, global imbalance {imbalance:.1e} (tolerance 1e-8)")
    assert pairs.kind == "mortar" and pairs.num_global == pairs.num_slave_nodes  # every slave node is covered
    assert problem.num_pairs == len(t["state"]) == (81 if mesh_name.startswith("hex") else pairs.num_slave_nodes)
    assert np.all(t["state_name"] == "stick")
    assert err_p < 1e-8 and err_t < 1e-8 and err_sigma < 1e-8 and imbalance < 1e-10


def test_auto_takes_mortar_on_non_matching_quadratic_facets():
    """As with degree 1: ``auto`` is node-to-node on matching meshes and dual mortar otherwise."""
    for mesh_name, kind in (("hex 4x4 / 3x3", "mortar"), ("hex matching", "node-to-node")):
        assert two_blocks(mesh_name, "auto").contact.interfaces[0].pairs.kind == kind


# -- a rigid plane pressed into a cube -------------------------------------------------------------
STEEL = VonMises(E=200_000.0, nu=0.3, sigma_y0=400.0, H=20_000.0)
ELASTIC = VonMises(E=200_000.0, nu=0.3)
EPS_Y = STEEL.sigma_y0 / STEEL.E


def uniaxial_stress(material, eps):
    """|σ| of a bar compressed to ``eps`` (uniaxial stress, linear hardening)."""
    if material.sigma_y0 is None or eps <= material.sigma_y0 / material.E:
        return material.E * eps
    return material.sigma_y0 + material.E * material.H / (material.E + material.H) * (eps - material.sigma_y0 / material.E)


def pressed_cube(cell, material, delta, law):
    """The unit cube on a frictionless rigid plane at x = 0 (rollers on y = 0, z = 0), a second
    plane pressing x = 1 by δ; degree 2 (the box's facets: x− 1, x+ 2, y− 3, y+ 4, z− 5, z+ 6)."""
    mesh, ft = box_with_face_tags((2, 2, 2), cell=cell)
    support = Contact(Plane(point=(0.0, 0.0, 0.0), normal=(1.0, 0.0, 0.0)), 1, mu_f=0.0, name="support", law=law)
    press = Contact(Plane(point=(1.0, 0.0, 0.0), normal=(-1.0, 0.0, 0.0), motion=(-delta, 0.0, 0.0)), 2, mu_f=0.0,
                    name="press", law=law)
    return ContactProblem(mesh, None, ft, materials=material, dirichlet=[Dirichlet(3, 0.0, [1]), Dirichlet(5, 0.0, [2])],
                          contact=[support, press], degree=2)


@pytest.mark.parametrize("law", ["alart-curnier", "polar"])
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("material", ["elastic", "von Mises"])
@pytest.mark.parametrize("cell", ["tetrahedron", "hexahedron"])
def test_rigid_plane_pressed_into_a_cube_gives_the_uniaxial_force(cell, material, method, law):
    mat, delta = (ELASTIC, 0.5 * EPS_Y) if material == "elastic" else (STEEL, 3.0 * EPS_Y)
    problem = pressed_cube(cell, mat, delta, law)
    results = solve_load_steps(problem, make_solver(method, problem, SolverOptions(rtol=1e-12)), 1)
    forces = problem.contact.obstacle_reactions()
    exact = uniaxial_stress(mat, delta)  # × the unit area
    err = max(abs(abs(forces[name][0]) - exact) for name in ("support", "press")) / exact
    t = pair_table(problem)
    support = t["interface"] == 0
    err_p = np.abs(t["pressure"][support] - exact).max() / exact
    p_max = MPI.COMM_WORLD.allreduce(float(problem.state.p_n.x.array.max(initial=0.0)), op=MPI.MAX)
    print(f"\n  {cell}, {material}, {method}/{law}: {problem.num_pairs} pairs, {results[0].iterations} iterations; "
          f"force {abs(forces['support'][0]):.9f} against {exact:.9f} (relative {err:.1e}), max |pressure − σ|/σ "
          f"{err_p:.1e}, max p {p_max:.3e}")
    assert err < 1e-8 and err_p < 1e-8
    assert (p_max > 0) == (material == "von Mises")



@pytest.mark.parametrize("method, variant", [("nneqm1", {"modified": True}), ("nneqm2", {"flow_directions": "frozen"}),
                                             ("monolithic", {"linear_solver": "iterative"})],
                         ids=["nneqm1 modified", "nneqm2 frozen", "monolithic iterative"])
@pytest.mark.parametrize("cell", ["tetrahedron", "hexahedron"])
def test_solver_variants_take_degree_2(cell, method, variant):
    """The variants beside each method's default: nothing of degree 2 needs refusing there."""
    from dolfinx_nnqem.solvers.options import MonolithicOptions, NNEQM1Options, NNEQM2Options

    options = {"nneqm1": NNEQM1Options, "nneqm2": NNEQM2Options, "monolithic": MonolithicOptions}[method](**variant)
    delta = 3.0 * EPS_Y
    problem = pressed_cube(cell, STEEL, delta, "alart-curnier")
    results = solve_load_steps(problem, make_solver(method, problem, SolverOptions(rtol=1e-12), **{method: options}), 1)
    exact = uniaxial_stress(STEEL, delta)
    err = abs(abs(problem.contact.obstacle_reactions()["support"][0]) - exact) / exact
    print(f"\n  {cell}, {method} {variant}: force error {err:.1e}, {results[0].iterations} iterations")
    assert err < 1e-8

@pytest.mark.parametrize("method, variant", [("nneqm1", {"modified": True}), ("nneqm2", {"flow_directions": "frozen"}),
                                             ("monolithic", {"linear_solver": "iterative"})],
                         ids=["nneqm1 modified", "nneqm2 frozen", "monolithic iterative"])
@pytest.mark.parametrize("mesh_name", ["hex 4x4 / 3x3", "tet 4x4 / 3x3"])
def test_solver_variants_take_quadratic_mortar(mesh_name, method, variant):
    """The same variants on the non-matching mortar patch with shear: exact."""
    from dolfinx_nnqem.solvers.options import MonolithicOptions, NNEQM1Options, NNEQM2Options

    options = {"nneqm1": NNEQM1Options, "nneqm2": NNEQM2Options, "monolithic": MonolithicOptions}[method](**variant)
    problem = two_blocks(mesh_name, "mortar", drag=True)
    results = solve_load_steps(problem, make_solver(method, problem, SolverOptions(rtol=1e-12), **{method: options}), 1)
    _, err_p, err_t, err_sigma = patch_errors(problem, True)
    print(f"\n  {mesh_name}, {method} {variant}: {results[0].iterations} iterations, max |pressure − p|/p {err_p:.1e}, "
          f"max |σ − σ_exact|/p {err_sigma:.1e}")
    assert problem.contact.interfaces[0].pairs.kind == "mortar"
    assert err_p < 1e-8 and err_t < 1e-8 and err_sigma < 1e-8


# -- problem files and MPI ---------------------------------------------------------------------------
PATCH_FILE = pressed_block_stack(mesh_keys="degree = 2", contact_keys='discretisation = "{discretisation}"',
                                 solver_keys='method = "{method}"')


@pytest.mark.parametrize("method", METHODS)
def test_problem_file_with_degree_2(tmp_path, method):
    """The matching hexahedral patch test from a problem file (``[mesh] degree = 2``): 49 pairs, exact."""
    from dolfinx_nnqem.cli import EXIT_OK, main

    if MPI.COMM_WORLD.rank == 0:
        build_block_stack(MPI.COMM_SELF, 1.0, 1.0, [0.5, 0.5], MESHES["hex matching"][1], msh_file=tmp_path / "stack.msh")
    MPI.COMM_WORLD.barrier()
    (tmp_path / "p.toml").write_text(PATCH_FILE.format(discretisation="node-to-surface", method=method))
    assert main(["-q", "run", str(tmp_path / "p.toml"), "--out", str(tmp_path / "out")]) == EXIT_OK
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    pressure = np.array([p["pressure"] for p in summary["pairs"]])
    err = np.max(np.abs(pressure - P)) / P
    print(f"\n  {method}: {len(pressure)} node-to-surface pairs of degree 2, max |pressure − p|/p = {err:.2e}")
    assert summary["converged"] and len(pressure) == 49 and err < 1e-8


def test_problem_file_degree_is_checked(tmp_path):
    from dolfinx_nnqem.problem_file import ProblemFileError, load_problem_file

    (tmp_path / "stack.msh").write_text("")  # never read: the keys are checked first
    (tmp_path / "p.toml").write_text(PATCH_FILE.format(discretisation="auto", method="monolithic")
                                     .replace("degree = 2", "degree = 3"))
    with pytest.raises(ProblemFileError, match="mesh.degree = 3: the displacement is Lagrange of degree 1 or 2"):
        load_problem_file(tmp_path / "p.toml")


@pytest.mark.mpi
def test_two_ranks_equal_serial(tmp_path):
    """Node-to-surface and dual mortar pairs of degree 2 on tetrahedra, mortar on hexahedra
    (non-matching, pressed then dragged until part of the interface slips), a rigid plane, and a hemisphere on a block from a second-order gmsh
    mesh (curved cap): 2 ranks give the serial answer to 1e-8."""
    sys.path.insert(0, str(SCRIPTS))
    from petsc4py import PETSc
    from quadratic_blocks import CASES, compare, solve

    serial = {case: solve(case, MPI.COMM_SELF) for case in CASES}
    out = tmp_path / "out.npz"
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(SCRIPTS / "quadratic_blocks.py"), str(out)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=compat.mpi_environment())
    assert run.returncode == 0, f"{' '.join(cmd)} failed:\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}"
    parallel = dict(np.load(out))
    for case in CASES:
        figures = compare(serial[case], {k.rsplit("/", 1)[1]: v for k, v in parallel.items() if k.startswith(case + "/")})
        print(f"\n  {case}: 2 ranks vs serial: {figures}")
        assert figures["pairs_per_rank"][0] > 0 and figures["pairs_per_rank"][1] > 0
        assert figures["same_states"] and max(figures["force"], figures["u"]) < 1e-8
        if case.startswith("tet-mortar/monolithic") and PETSc.Sys.hasExternalPackage("metis"):  # (see linalg)
            # the serial iterations: with M_jk of round-off size kept (contact.mortar.ROUND_OFF) the first
            # 2-rank MUMPS factorisation failed and Levenberg–Marquardt took 22 (other cases may differ by
            # one where |H| ends near the tolerance: NNEQM2 took 3 or 2 in the last increment)
            assert figures["iterations"][0] == figures["iterations"][1]


# -- second-order gmsh meshes ------------------------------------------------------------------------
def second_order_stack(tmp_path, cell):
    """The matching two-block stack as a second-order .msh (27-node hexahedra, 10-node tetrahedra)
    written by gmsh on rank 0, then read back by every rank with :func:`read_msh`."""
    _, divisions, structured = MESHES["hex matching" if cell == "hexahedron" else "tet matching"]
    path = tmp_path / f"stack_{cell}.msh"
    if MPI.COMM_WORLD.rank == 0:
        build_block_stack(MPI.COMM_SELF, 1.0, 1.0, [0.5, 0.5], divisions, cell_type=cell, structured=structured,
                          order=2, msh_file=path)
    MPI.COMM_WORLD.barrier()
    return path


def read_p2_series(out):
    """The steps of ``fields_p2.pvd`` as pyvista grids, with their load factors."""
    import pyvista

    reader = pyvista.get_reader(str(out / "fields_p2.pvd"))
    grids = []
    for t in reader.time_values:
        reader.set_active_time_value(t)
        grids.append(reader.read()[0])
    return list(reader.time_values), grids


@pytest.mark.parametrize("cell", ["hexahedron", "tetrahedron"])
def test_second_order_gmsh_mesh_in_contact_written_and_read_back(tmp_path, cell):
    """A second-order .msh read from Python takes degree 2 by default and passes the patch test; the
    run's ``fields_p2.pvd`` holds the quadratic displacement on VTK Lagrange cells, read back
    (pyvista, as ParaView) equal to u at every P2 node, at each increment."""
    from scipy.spatial import cKDTree

    from dolfinx_nnqem.io.output import ResultsWriter

    mesh, ct, ft = read_msh(second_order_stack(tmp_path, cell))
    nodes = {"hexahedron": 27, "tetrahedron": 10}[cell]
    assert compat.coordinate_element(mesh).degree == 2 and compat.geometry_dofmap(mesh).shape[1] == nodes
    problem = stacked_problem(mesh, ct, ft, "auto")
    assert problem.V.ufl_element().embedded_superdegree == 2  # the mesh's order
    out = tmp_path / "out"
    with ResultsWriter(problem, "monolithic", out, 2) as writer:
        solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-12)), 2, callbacks=[writer])
    _, err_p, err_t, err_sigma = patch_errors(problem, False)
    times, grids = read_p2_series(out)
    print(f"\n  second-order {cell} .msh ({nodes}-node cells): {problem.contact.describe()[0]}; max |pressure − p|/p "
          f"= {err_p:.1e}, traction {err_t:.1e}, σ {err_sigma:.1e}; fields_p2.pvd: steps {times}, "
          f"{grids[-1].n_points} points, VTK cell types {sorted(set(grids[-1].celltypes))}")
    assert problem.num_pairs == 49 and max(err_p, err_t, err_sigma) < 1e-8
    assert times == [0.5, 1.0]
    assert set(grids[-1].celltypes) == {72 if cell == "hexahedron" else 71}  # VTK_LAGRANGE_HEXAHEDRON / _TETRAHEDRON
    if MPI.COMM_WORLD.size == 1:
        x = problem.V.tabulate_dof_coordinates()
        distance, node = cKDTree(x).query(grids[-1].points)
        u = problem.u.x.array.reshape(-1, 3)
        err_u = np.abs(grids[-1].point_data["u"] - u[node]).max() / np.abs(u).max()
        print(f"  read back: {len(x)} P2 nodes, max |u_file − u|/max|u| = {err_u:.1e}")
        assert grids[-1].n_points == len(x) and distance.max() < 1e-12 and err_u < 1e-12
        assert np.abs(grids[0].point_data["u"] - 0.5 * u[node]).max() < 1e-12 * np.abs(u).max()  # linear: half
        # fields.xdmf: the mesh's own nodes, here the P2 ones too (quadratic VTK cells from XDMF),
        # where VTK has its XDMF reader (Debian 13's VTK 9.3 is built without vtkIOXdmf2)
        import importlib.util

        if importlib.util.find_spec("vtkmodules.vtkIOXdmf2") is None:
            print("  (this VTK has no XDMF reader: fields.xdmf not read back)")
            return
        import pyvista

        reader = pyvista.get_reader(str(out / "fields.xdmf"))
        reader.set_active_time_value(1.0)
        xdmf = reader.read()
        xdmf = xdmf[0] if isinstance(xdmf, pyvista.MultiBlock) else xdmf
        assert xdmf.n_points == len(x) and set(xdmf.celltypes) == {29 if cell == "hexahedron" else 24}
        _, node = cKDTree(x).query(xdmf.points)  # VTK's XDMF reader gives float32
        assert np.abs(xdmf.point_data["u"] - u[node]).max() < 1e-6 * np.abs(u).max()


SPHERE = dict(R=5.0, block=3.0, h_contact=0.5, h_max=1.0, fine_radius=0.8, contact_radius=1.5)  # h = 0.5


def sphere_problem(path, degree=None):
    from dolfinx_nnqem.cases.sphere_on_block import BLOCK_MATERIAL, SPHERE_MATERIAL
    from dolfinx_nnqem.cases.geometries import SphereOnBlockTags as S

    mesh, ct, ft = read_msh(path)
    return ContactProblem(mesh, ct, ft, materials={S.BLOCK: BLOCK_MATERIAL, S.SPHERE: SPHERE_MATERIAL},
                          dirichlet=[Dirichlet(S.BOTTOM), Dirichlet(S.LOAD, -0.1, [1]),
                                     Dirichlet(S.BLOCK_XMIN, 0.0, [0]), Dirichlet(S.SPHERE_XMIN, 0.0, [0]),
                                     Dirichlet(S.BLOCK_ZMIN, 0.0, [2]), Dirichlet(S.SPHERE_ZMIN, 0.0, [2])],
                          contact=Contact(S.CONTACT1, S.CONTACT2, mu_f=0.0, discretisation="node-to-surface"),
                          degree=degree)


def test_second_order_sphere_keeps_its_curved_contact_facets(tmp_path):
    """A hemisphere on a block meshed by gmsh with 10-node tetrahedra: every node of the cap's 6-node
    facets lies on the sphere, and so does every slave node of the node-to-surface pairs; P2 on the
    first-order mesh puts the edge nodes on the chords instead (h²/8R off), and the force moves."""
    from dolfinx.mesh import entities_to_geometry

    from dolfinx_nnqem.cases.geometries import SphereOnBlockTags as S

    R, centre = SPHERE["R"], np.array([0.0, SPHERE["R"], 0.0])
    paths = {order: tmp_path / f"sphere_{order}.msh" for order in (1, 2)}
    if MPI.COMM_WORLD.rank == 0:
        for order, path in paths.items():
            build_sphere_on_block(MPI.COMM_SELF, order=order, msh_file=path, **SPHERE)
    MPI.COMM_WORLD.barrier()
    figures = {}
    for order, path in paths.items():
        problem = sphere_problem(path, degree=2)
        mesh = problem.mesh
        cap = np.asarray(entities_to_geometry(mesh, 2, problem.facet_tags.find(S.CONTACT2)))
        assert cap.shape[1] == (6 if order == 2 else 3)
        off_geometry = np.abs(np.linalg.norm(mesh.geometry.x[cap.reshape(-1)] - centre, axis=1) - R).max(initial=0.0)
        results = solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-10)), 1)
        t = pair_table(problem)
        slave = contact_model(problem).interfaces[0].pairs.slave
        on_sphere = t["position_b"] if slave == S.CONTACT2 else t["position"]
        off_pairs = np.abs(np.linalg.norm(on_sphere - centre, axis=1) - R).max()
        force = -4.0 * t["force_on_body1"][:, 1].sum()  # quarter model
        figures[order] = (off_geometry, off_pairs, force)
        print(f"\n  order {order} mesh, P2: geometry nodes of the cap off the sphere by {off_geometry:.1e}, the "
              f"sphere's pair nodes by {off_pairs:.1e} (h²/8R = {0.25 / (8 * R):.1e}); {len(t['state'])} pairs, "
              f"{np.count_nonzero(t['state'])} closed, force {force:.1f} N, {results[0].iterations} iterations, "
              f"imbalance {equilibrium_check(problem)['global_imbalance']:.1e}")
        assert equilibrium_check(problem)["global_imbalance"] < 1e-10
    assert figures[2][0] < 1e-9 * R and figures[2][1] < 1e-9 * R  # curved: on the sphere
    assert figures[1][1] > 1e-3  # straight-sided: the edge nodes of the facets on the chords
    assert abs(figures[2][2] / figures[1][2] - 1.0) > 0.02  # the geometry changes the answer


def write_msh_of(tmp_path, name, cell_order, incomplete, recombine):
    """A unit box meshed by gmsh with elements of order ``cell_order`` (``incomplete``: serendipity)."""
    import gmsh

    path = tmp_path / f"{name}.msh"
    if MPI.COMM_WORLD.rank == 0:
        gmsh.initialize(interruptible=False)
        try:
            gmsh.option.setNumber("General.Verbosity", 0)
            gmsh.model.add(name)
            gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
            gmsh.model.occ.synchronize()
            gmsh.model.addPhysicalGroup(3, [1], 1)
            gmsh.model.addPhysicalGroup(2, [s for _, s in gmsh.model.getEntities(2)], 1)
            if recombine:  # hexahedra
                gmsh.model.mesh.setTransfiniteAutomatic()
                gmsh.option.setNumber("Mesh.RecombineAll", 1)
            gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
            gmsh.option.setNumber("Mesh.SecondOrderIncomplete", int(incomplete))
            gmsh.model.mesh.generate(3)
            gmsh.model.mesh.setOrder(cell_order)
            gmsh.write(str(path))
        finally:
            gmsh.finalize()
    MPI.COMM_WORLD.barrier()
    return path


@pytest.mark.parametrize("name, order, incomplete, recombine, reason", [
    ("hex20", 2, True, True, r"20-node \(serendipity\) hexahedra are not a DOLFINx element.*27-node hexahedra"),
    ("tet20", 3, False, False, r"gmsh elements 'Tetrahedron 20' are not supported.*10-node tetrahedra")])
def test_unsupported_gmsh_elements_are_refused_with_the_reason(tmp_path, name, order, incomplete, recombine, reason):
    """From Python and from a problem file, before any mesh is distributed."""
    from dolfinx_nnqem.problem_file import ProblemFileError, build_problem, load_problem_file

    path = write_msh_of(tmp_path, name, order, incomplete, recombine)
    with pytest.raises(ValueError, match=reason) as python:
        read_msh(path)
    (tmp_path / "p.toml").write_text(f'[mesh]\nfile = "{path.name}"\n[materials.1]\nE = 1.0e9\nnu = 0.3\n'
                                     '[[dirichlet]]\ntag = 1\n')
    with pytest.raises(ProblemFileError, match=reason) as problem_file:
        build_problem(load_problem_file(tmp_path / "p.toml"), MPI.COMM_WORLD)
    print(f"\n  {name}: {python.value}\n  problem file: {problem_file.value}")


def test_mesh_order_is_checked():
    with pytest.raises(ValueError, match=r"order = 3: a mesh of first \(1\) or second \(2\) order"):
        build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [0.5, 0.5], [(1, 1, 1), (1, 1, 1)], order=3)


def test_problem_file_with_a_second_order_mesh(tmp_path):
    """No ``degree`` key: a second-order .msh gives degree 2; the patch test and ``fields_p2.pvd``."""
    from dolfinx_nnqem.cli import EXIT_OK, main

    path = second_order_stack(tmp_path, "tetrahedron")
    text = PATCH_FILE.format(discretisation="auto", method="nneqm2").replace("degree = 2\n", "")
    (tmp_path / "p.toml").write_text(text.replace("stack.msh", path.name))
    assert main(["-q", "run", str(tmp_path / "p.toml"), "--out", str(tmp_path / "out")]) == EXIT_OK
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    pressure = np.array([p["pressure"] for p in summary["pairs"]])
    times, grids = read_p2_series(tmp_path / "out")
    print(f"\n  problem file, 10-node tetrahedra: {len(pressure)} pairs, max |pressure − p|/p = "
          f"{np.max(np.abs(pressure - P)) / P:.1e}; fields_p2.pvd steps {times}")
    assert summary["converged"] and len(pressure) == 49 and np.max(np.abs(pressure - P)) / P < 1e-8
    assert times == [1.0] and set(grids[0].celltypes) == {71}


def test_quadratic_field_series_resumes_from_a_checkpoint(tmp_path):
    """After a restart the steps beyond the checkpoint are removed and the index lists the kept ones."""
    from types import SimpleNamespace

    from dolfinx_nnqem.io.quadratic_fields import QuadraticFieldWriter

    problem = pressed_cube("tetrahedron", ELASTIC, 0.0, "alart-curnier")
    writer = QuadraticFieldWriter(problem, tmp_path)
    for k in (1, 2, 3):
        problem.u.x.array[:] = k
        writer(SimpleNamespace(index=k, load_factor=k / 3))
        if k == 1:
            state = writer.state()
    assert read_p2_series(tmp_path)[0] == pytest.approx([1 / 3, 2 / 3, 1.0])
    again = QuadraticFieldWriter(problem, tmp_path)
    again.resume(state)
    left = sorted(p.name for p in (tmp_path / "fields").iterdir())
    problem.u.x.array[:] = 5.0
    again(SimpleNamespace(index=2, load_factor=0.5))
    times, grids = read_p2_series(tmp_path)
    print(f"\n  kept after resuming at increment 1: {left}; then steps {times}")
    assert all(name.startswith("u_p2_0001") for name in left)
    assert times == pytest.approx([1 / 3, 0.5])
    assert np.all(grids[0].point_data["u"] == 1.0) and np.all(grids[1].point_data["u"] == 5.0)


# -- what degree 2 does not support: refused before solving, with the reason -------------------------
@pytest.mark.parametrize("method", METHODS)
def test_problem_file_with_mortar_and_degree_2(tmp_path, method):
    """``discretisation = "mortar"`` with ``[mesh] degree = 2`` on the non-matching hexahedral patch
    (4 × 4 facets on 3 × 3): 81 mortar pairs, the pressure exact."""
    from dolfinx_nnqem.cli import EXIT_OK, main

    if MPI.COMM_WORLD.rank == 0:
        build_block_stack(MPI.COMM_SELF, 1.0, 1.0, [0.5, 0.5], MESHES["hex 4x4 / 3x3"][1], msh_file=tmp_path / "stack.msh")
    MPI.COMM_WORLD.barrier()
    (tmp_path / "p.toml").write_text(PATCH_FILE.format(discretisation="mortar", method=method))
    assert main(["-q", "run", str(tmp_path / "p.toml"), "--out", str(tmp_path / "out")]) == EXIT_OK
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    pressure = np.array([p["pressure"] for p in summary["pairs"]])
    err = np.max(np.abs(pressure - P)) / P
    print(f"\n  {method}: {len(pressure)} mortar pairs of degree 2 from a problem file, max |pressure − p|/p = {err:.2e}")
    assert summary["converged"] and len(pressure) == 81 and err < 1e-8


def test_contact_on_a_third_order_mesh_is_refused_before_solving(tmp_path):
    """A mesh of geometry degree 3 (DOLFINx reads gmsh's 20-node tetrahedra; ``read_msh`` does not):
    degree-2 contact facets need a straight-sided or a second-order geometry."""
    path = write_msh_of(tmp_path, "tet20", 3, False, False)
    mesh, ct, ft = compat.read_from_msh(str(path), MPI.COMM_WORLD, 0, gdim=3)
    assert compat.coordinate_element(mesh).degree == 3
    with pytest.raises(ContactPairError, match="geometry degree 3: quadratic contact facets need a straight-sided or "
                                               "a second-order mesh"):
        ContactProblem(mesh, ct, ft, materials=ELASTIC, degree=2,
                       contact=Contact(Plane(point=(0.0, 0.0, 0.0), normal=(1.0, 0.0, 0.0)), 1, mu_f=0.0))
