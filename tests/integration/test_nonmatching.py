"""Non-matching interfaces: node-to-surface and dual mortar (issue "Non-matching meshes").

Two blocks meshed on their own (``build_block_stack``): body 1 with 4 × 4 facets on the
interface, body 2 with 3 × 3 (hexahedra), or both with unstructured tetrahedra (the faces meshed
independently). A DOLFINx mesh holds one cell type, so a tetrahedral side meets a tetrahedral side.

* Patch test, uniform pressure p on body 2 (floating in y, held by contact): dual mortar
  transmits it exactly, σ = −p e_y⊗e_y at every Gauss point and pressure p at every slave node
  (1e-8); node-to-surface does not (its error is printed and must be visible).
* The same with a drag τ = 0.2 p < μ_f p (μ_f = 0.3), a homogeneous shear state: ν = 0 so that
  u = (τ/G) y e_x − (p/E) y e_y is compatible with a clamped bottom; the x faces carry ±τ e_y.
* Sliding block, non-matching: friction saturates at μ_f p A (1e-8), every slave node slips.
"""

import numpy as np
import pytest
from mpi4py import MPI
from problem_files import pressed_block_stack

from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.cases.geometries import StackedBlocksTags as S
from dolfinx_nnqem.cases.geometries import build_block_stack, build_stacked_blocks
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure, Traction
from dolfinx_nnqem.io import equilibrium_check, pair_table
from dolfinx_nnqem.solvers import METHODS, SolverOptions, make_solver
from dolfinx_nnqem.solvers import solve_load_steps

P = 1.0e6
TAU = 0.2 * P
MU_F = 0.3
MESHES = {"hex 4x4 / 3x3": ("hexahedron", [(4, 1, 4), (3, 1, 3)]),
          "tet 4x4 / 3x3": ("tetrahedron", [(4, 2, 4), (3, 2, 3)])}

def two_blocks(mesh_name, discretisation, law="alart-curnier", drag=False, comm=MPI.COMM_WORLD):
    """Body 1 (y in [0, 0.5]) under body 2 (y in [0.5, 1]); pressure p (and the drag τ) on top."""
    cell_type, divisions = MESHES[mesh_name]
    mesh, ct, ft = build_block_stack(comm, 1.0, 1.0, [0.5, 0.5], divisions, cell_type=cell_type)
    nu = 0.0 if drag else 0.3
    material = VonMises(E=1.0e9, nu=nu)
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
                          tractions=tractions, contact=contact)


def exact_stress(drag):
    sigma = np.zeros((3, 3))
    sigma[1, 1] = -P
    if drag:
        sigma[0, 1] = sigma[1, 0] = TAU
    return sigma


def patch_errors(problem, drag):
    """Largest relative errors of the slave nodes' pressures, of their tractions and of σ.

    The pair table's body 1 is the master side, whichever block that is; its outward normal is
    the pair normal n, so the traction on it is σ n.
    """
    t = pair_table(problem)
    exact = exact_stress(drag)
    err_p = np.max(np.abs(t["pressure"] - P)) / P
    traction = t["force_on_body1"] / t["area"][:, None]
    err_t = np.max(np.abs(traction - t["frame"][:, 0, :] @ exact)) / P
    sigma = problem.state.sigma_n.x.array.reshape(-1, 3, 3)
    err_sigma = MPI.COMM_WORLD.allreduce(float(np.max(np.abs(sigma - exact))) / P, op=MPI.MAX)
    return t, err_p, err_t, err_sigma


@pytest.mark.parametrize("drag", [False, True], ids=["pressure", "pressure+drag"])
@pytest.mark.parametrize("law", ["alart-curnier", "polar"])
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("mesh_name", list(MESHES))
def test_mortar_patch_test(mesh_name, method, law, drag):
    problem = two_blocks(mesh_name, "mortar", law, drag)
    results = solve_load_steps(problem, make_solver(method, problem, SolverOptions(rtol=1e-12)), 1)
    t, err_p, err_t, err_sigma = patch_errors(problem, drag)
    imbalance = equilibrium_check(problem)["global_imbalance"]
    print(f"\n  {mesh_name}, {method}/{law}, {'drag' if drag else 'pressure'}: {problem.contact.describe()[0]}; "
          f"{results[0].iterations} iterations; max |pressure − p|/p = {err_p:.2e}, traction "
          f"{err_t:.2e}, max |σ − σ_exact|/p = {err_sigma:.2e}, global imbalance {imbalance:.1e} (tolerance 1e-8)")
    assert problem.num_pairs == len(t["state"]) > 0 and np.all(t["state_name"] == "stick")
    assert err_p < 1e-8 and err_t < 1e-8 and err_sigma < 1e-8 and imbalance < 1e-10


@pytest.mark.parametrize("drag", [False, True], ids=["pressure", "pressure+drag"])
@pytest.mark.parametrize("mesh_name", list(MESHES))
def test_node_to_surface_fails_the_patch_test(mesh_name, drag):
    """Documented behaviour: node-to-surface spreads the slave nodes' forces over the master with
    the master's shape functions, so a uniform pressure does not stay uniform."""
    problem = two_blocks(mesh_name, "node-to-surface", drag=drag)
    solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-12)), 1)
    _, err_p, err_t, err_sigma = patch_errors(problem, drag)
    imbalance = equilibrium_check(problem)["global_imbalance"]
    print(f"\n  {mesh_name}, node-to-surface, {'drag' if drag else 'pressure'}: max |pressure − p|/p = {err_p:.2e}, "
          f"traction {err_t:.2e}, max |σ − σ_exact|/p = {err_sigma:.2e}, global imbalance {imbalance:.1e}")
    assert imbalance < 1e-10  # still in equilibrium: the error is in the distribution
    assert err_sigma > 1e-3  # visibly not the exact state


def test_auto_picks_mortar_for_non_matching_and_node_to_node_for_matching():
    for divisions, kind in (([(4, 1, 4), (3, 1, 3)], "mortar"), ([(3, 1, 3), (3, 1, 3)], "node-to-node")):
        mesh, ct, ft = build_block_stack(MPI.COMM_WORLD, 1.0, 1.0, [0.5, 0.5], divisions)
        problem = ContactProblem(mesh, ct, ft, materials={1: VonMises(E=1e9, nu=0.3), 2: VonMises(E=1e9, nu=0.3)},
                                 dirichlet=[Dirichlet(T.bottom(1))], tractions=[Pressure(T.top(2), P)],
                                 contact=Contact(T.top(1), T.bottom(2), mu_f=0.3))
        line = problem.contact.describe()[0]
        print(f"\n  {divisions}: {line}")
        assert problem.contact.interfaces[0].pairs.kind == kind
        if kind == "mortar":  # body 1's 4 x 4 facets are the finer: body 1 (surface1) is the slave
            assert "slave surface 201 against master surface 102" in line and "the finer side" in line
            assert problem.num_pairs == 25


# -- sliding block -------------------------------------------------------------------------------------


def sliding_block(discretisation, law, comm=MPI.COMM_WORLD):
    """V5 on non-matching meshes: body 1 4 × 2 facets, body 2 3 × 3; pressure, then a drag u_x."""
    Lx, Lz = 1.0, 0.5
    mesh, ct, ft = build_stacked_blocks(comm, Lx, 0.5, 0.5, Lz, 4, 2, 2, 2, nx2=3, nz2=3)
    material = VonMises(E=1.0e9, nu=0.3)
    problem = ContactProblem(
        mesh, ct, ft, materials={S.BODY1: material, S.BODY2: material},
        dirichlet=[Dirichlet(S.BOTTOM),
                   Dirichlet(S.TOP, 1.0e-2, [0], amplitude=lambda ell: max(ell - 0.2, 0.0) / 0.8),
                   Dirichlet(S.BODY1_ZMIN, 0.0, [2]), Dirichlet(S.BODY1_ZMAX, 0.0, [2]),
                   Dirichlet(S.BODY2_ZMIN, 0.0, [2]), Dirichlet(S.BODY2_ZMAX, 0.0, [2])],
        tractions=[Pressure(S.TOP, P, amplitude=lambda ell: min(ell / 0.2, 1.0))],
        contact=Contact(S.CONTACT1, S.CONTACT2, mu_f=MU_F, law=law, discretisation=discretisation))
    return problem, P * Lx * Lz


@pytest.mark.parametrize("discretisation", ["mortar", "node-to-surface"])
@pytest.mark.parametrize("law", ["alart-curnier", "polar"])
@pytest.mark.parametrize("method", METHODS)
def test_sliding_block_non_matching(method, law, discretisation):
    problem, force = sliding_block(discretisation, law)
    history = []

    def record(result):
        t = pair_table(problem)
        history.append((result.load_factor, t["force_on_body1"].sum(axis=0), t["state_name"].copy(), result.iterations))

    solver = make_solver(method, problem, SolverOptions(rtol=1e-12, max_iterations=40))
    solve_load_steps(problem, solver, 10, callbacks=[record], max_cutbacks=3)
    limit = MU_F * force
    ell, total, states, _ = history[-1]
    err = abs(abs(total[0]) - limit) / limit
    print(f"\n  {discretisation}, {method}/{law}: {problem.contact.describe()[0]}; iterations "
          f"{[h[3] for h in history]}; saturation |F_t − μ_f p A| / μ_f p A = {err:.2e}, normal force "
          f"{abs(total[1] + force) / force:.1e}; states at the end {dict(zip(*np.unique(states, return_counts=True)))}")
    assert err < 1e-8 and abs(total[1] + force) < 1e-10 * force
    assert np.all(states == "slip")


# -- problem files ---------------------------------------------------------------------------------------

PATCH_FILE = pressed_block_stack(contact_keys="{contact}")


@pytest.mark.parametrize("method", METHODS)
def test_mortar_from_a_problem_file(tmp_path, method):
    """The patch test (4 × 4 against 3 × 3) from a problem file, slave chosen in the file."""
    import json

    from dolfinx_nnqem.cli import EXIT_OK, main

    if MPI.COMM_WORLD.rank == 0:
        build_block_stack(MPI.COMM_SELF, 1.0, 1.0, [0.5, 0.5], MESHES["hex 4x4 / 3x3"][1], msh_file=tmp_path / "stack.msh")
    MPI.COMM_WORLD.barrier()
    (tmp_path / "p.toml").write_text(PATCH_FILE.format(contact='discretisation = "mortar"\nslave = 102'))
    assert main(["-q", "run", str(tmp_path / "p.toml"), "--out", str(tmp_path / "out"), "--method", method]) == EXIT_OK
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    pressure = np.array([p["pressure"] for p in summary["pairs"]])
    err = np.max(np.abs(pressure - P)) / P
    print(f"\n  {method}: {len(pressure)} mortar pairs (slave 102, the coarser side, by choice), "
          f"max |pressure − p|/p = {err:.2e}, global imbalance {summary['equilibrium_residual']:.1e}")
    assert summary["converged"] and len(pressure) == 16 and err < 1e-8


@pytest.mark.parametrize("contact, words", [
    ('discretisation = "segment"', "discretisation = 'segment'"),
    ("slave = 7", "slave = 7"),
])
def test_problem_file_discretisation_errors(tmp_path, contact, words):
    from dolfinx_nnqem.problem_file import ProblemFileError, load_problem_file

    (tmp_path / "stack.msh").write_text("")  # never read: the keys are checked first
    (tmp_path / "p.toml").write_text(PATCH_FILE.format(contact=contact))
    with pytest.raises(ProblemFileError, match=words):
        load_problem_file(tmp_path / "p.toml")


def test_contact_refuses_unsound_combinations():
    from dolfinx_nnqem.contact.obstacles import Plane

    plane = Plane(point=(0, 0, 0), normal=(0, 1, 0))
    with pytest.raises(ValueError, match="discretisation = 'mortar'.*exact surface"):
        Contact(plane, 5, mu_f=0.1, discretisation="mortar")
    with pytest.raises(ValueError, match="initial_gap applies to node-to-node"):
        Contact(1, 2, mu_f=0.1, discretisation="mortar", initial_gap=lambda x: x[0])
    with pytest.raises(ValueError, match="slave = 3"):
        Contact(1, 2, mu_f=0.1, slave=3)


def test_symmetry_normals_keep_normals_a_support_does_not_make_symmetric():
    """Moved into the plane of the free components: a normal tilted out of a symmetry plane. Kept:
    no support, all three components supported, and a support along the normal itself (which
    would leave less than half the normal: no symmetry plane across the surface)."""
    from dolfinx_nnqem.contact.surfaces import symmetry_normals

    tilted = np.array([0.05, 1.0, -0.02]) / np.linalg.norm([0.05, 1.0, -0.02])
    along_x = np.array([0.9, 0.3, 0.0]) / np.linalg.norm([0.9, 0.3, 0.0])
    normals = np.array([tilted, tilted, tilted, tilted, along_x])
    supported = np.array([[True, False, False], [True, False, True], [False, False, False],
                          [True, True, True], [True, False, False]])
    out = symmetry_normals(normals, supported)
    np.testing.assert_allclose(out[0], [0.0, 1.0, -0.02] / np.linalg.norm([1.0, 0.02]), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(out[1], [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(out[2:], normals[2:])
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0, rtol=0, atol=1e-15)
