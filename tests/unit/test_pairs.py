"""Node-to-node contact pairs: detection, frames, the matrix B, errors, and MPI invariance."""

import json
import pathlib
import subprocess
import sys

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem import compat
from dolfinx_nnqem.cases import geometries as meshing
from dolfinx_nnqem.contact.pairs import ContactPairError, find_pairs, local_frames
from dolfinx_nnqem.cases.geometries import StackedBlocksTags as S
from dolfinx_nnqem.cases.geometries import TwoBeamsTags as T

SCRIPTS = pathlib.Path(__file__).resolve().parents[1] / "mpi_scripts"


def vector_p1(mesh):
    return dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))


@pytest.fixture(scope="module")
def two_beams():
    mesh, cell_tags, facet_tags = meshing.build_two_beams()
    V = vector_p1(mesh)
    return V, cell_tags, facet_tags, find_pairs(V, facet_tags, T.CONTACT1, T.CONTACT2)


def interpolated(V, field):
    u = dolfinx.fem.Function(V)
    u.interpolate(field)
    return u


def test_two_beam_pairs(two_beams):
    V, cell_tags, _, pairs = two_beams
    x = pairs.gather(pairs.positions)
    R = pairs.gather(pairs.R)
    g0 = pairs.gather(pairs.g0)
    dist = pairs.gather(np.linalg.norm(pairs.X_b - pairs.X_a, axis=1))
    print(f"\n  {pairs.num_global} pairs at (x, z) = {[tuple(p) for p in x[:, [0, 2]].round(12)]}")
    print(f"  frame of pair 0: n = {R[0, 0]}, t1 = {R[0, 1]}, t2 = {R[0, 2]}; "
          f"max |g0| = {np.abs(g0).max()}, max |X_b - X_a| = {dist.max():.1e}")
    assert pairs.num_global == 9
    assert pairs.comm.allreduce(pairs.num_local) == 9
    np.testing.assert_array_equal(R, np.broadcast_to([[0, 1, 0], [1, 0, 0], [0, 0, -1]], (9, 3, 3)))
    np.testing.assert_array_equal(g0, 0.0)
    assert dist.max() <= pairs.tolerance
    np.testing.assert_allclose(x[:, 1], 0.4, atol=1e-14)
    grid = {(px, pz) for px in (1.6, 1.8, 2.0) for pz in (0.0, 0.2, 0.4)}
    assert {tuple(p) for p in x[:, [0, 2]].round(12)} == grid

    # a_i belongs to beam 1 and b_i to beam 2 (dof blocks of their cells)
    def body_blocks(body):
        cells = cell_tags.indices[cell_tags.values == body]
        local = np.unique(V.dofmap.list[cells])
        return np.concatenate(V.mesh.comm.allgather(V.dofmap.index_map.local_to_global(local)))

    assert np.isin(pairs.gather(pairs.dofs_a), body_blocks(T.BODY1)).all()
    assert np.isin(pairs.gather(pairs.dofs_b), body_blocks(T.BODY2)).all()
    # b_i is owned by the rank holding the pair
    start, end = V.dofmap.index_map.local_range
    assert np.all((pairs.dofs_b >= start) & (pairs.dofs_b < end))


def test_B_annihilates_rigid_motions(two_beams):
    V, _, _, pairs = two_beams
    translation = interpolated(V, lambda x: np.vstack([1.0 + 0 * x[0], -2.0 + 0 * x[0], 0.5 + 0 * x[0]]))
    omega = np.array([0.3, -0.2, 0.7])  # infinitesimal rotation u = omega x X
    rotation = interpolated(V, lambda x: np.cross(omega, x.T).T)
    w_t = pairs.relative_displacement(translation)
    w_r = pairs.relative_displacement(rotation.x.petsc_vec)
    size = (np.abs(w_t).max(initial=0), np.abs(w_r).max(initial=0))
    print(f"\n  max |B u|: rigid translation {size[0]:.1e}, infinitesimal rotation {size[1]:.1e}")
    assert max(size) < 1e-14

    # a general field: w_i = R_i (u(X_b) - u(X_a))
    def field(x):
        return np.vstack([x[1] ** 2 + 3 * x[0], x[0] * x[2], np.sin(4 * x[0]) + x[2]])

    w = pairs.relative_displacement(interpolated(V, field))
    expected = np.einsum("nij,nj->ni", pairs.R, field(pairs.X_b.T).T - field(pairs.X_a.T).T)
    np.testing.assert_allclose(w, expected, atol=1e-14)


def test_global_force_is_self_equilibrated(two_beams):
    V, _, _, pairs = two_beams
    rng = np.random.default_rng(7)
    lam = rng.normal(size=(pairs.num_local, 3))
    f = pairs.global_force(lam)
    blocks = f.getArray(readonly=True).reshape(-1, 3)
    x_owned = V.tabulate_dof_coordinates()[: V.dofmap.index_map.size_local]
    force = pairs.comm.allreduce(blocks.sum(axis=0))
    moment = pairs.comm.allreduce(np.cross(x_owned, blocks).sum(axis=0))
    # adjoint identity (Bᵀλ)·u = λ·(Bu) for a random u
    u = dolfinx.fem.Function(V)
    u.x.array[:] = rng.normal(size=u.x.array.shape)
    u.x.scatter_forward()
    lhs = f.dot(u.x.petsc_vec)
    rhs = pairs.comm.allreduce(float(np.sum(lam * pairs.relative_displacement(u))))
    total = pairs.comm.allreduce(float(np.abs(lam).sum()))
    print(f"\n  |sum Bᵀλ| = {np.linalg.norm(force):.1e}, |sum X x Bᵀλ| = {np.linalg.norm(moment):.1e} "
          f"(sum |λ| = {total:.2f}); (Bᵀλ)·u = {lhs:.12f}, λ·(Bu) = {rhs:.12f}")
    assert np.linalg.norm(force) < 1e-13 * total
    assert np.linalg.norm(moment) < 1e-12 * total
    assert lhs == pytest.approx(rhs, rel=1e-13, abs=1e-13)
    # Bᵀλ at b_i is R_iᵀ λ_i (one pair per body-2 node)
    start = V.dofmap.index_map.local_range[0]
    np.testing.assert_allclose(blocks[pairs.dofs_b - start], np.einsum("nji,nj->ni", pairs.R, lam), atol=1e-15)
    # into an existing vector
    out = compat.create_vector(V)
    assert pairs.global_force(lam, out=out) is out
    np.testing.assert_array_equal(out.getArray(readonly=True), f.getArray(readonly=True))


def test_B_layout_lambda_vector_and_gather(two_beams):
    V, _, _, pairs = two_beams
    (rows_local, rows), (cols_local, cols) = pairs.B.getSizes()
    lam = pairs.create_lambda_vector()
    g = pairs.gather(np.arange(pairs.num_local) + pairs.offset)
    print(f"\n  B: {rows} x {cols} (local {rows_local} x {cols_local}), nonzeros "
          f"{int(pairs.B.getInfo()[ 'nz_used'])}; λ vector size {lam.getSize()}; gathered indices {g}")
    assert (rows_local, rows) == (3 * pairs.num_local, 27)
    assert (cols_local, cols) == (3 * V.dofmap.index_map.size_local, 3 * V.dofmap.index_map.size_global)
    assert pairs.B.getInfo()["nz_used"] == 6 * 3 * pairs.num_local
    assert lam.getSize() == 27 and lam.getLocalSize() == 3 * pairs.num_local and lam.norm() == 0.0
    np.testing.assert_array_equal(g, np.arange(9))
    np.testing.assert_array_equal(pairs.global_indices, np.arange(pairs.num_local) + pairs.offset)


def test_scaled_B(two_beams):
    """blockdiag(D_i) B from B's pair rows (PairRows.scaled), in B's sparsity."""
    from dolfinx_nnqem.contact.pairset import rows_matrix

    V, _, _, pairs = two_beams
    rng = np.random.default_rng(3)
    D = rng.normal(size=(pairs.num_local, 3, 3))
    A = rows_matrix(pairs.comm, pairs.rows, pairs.num_global, V.dofmap.index_map, pairs.rows.scaled(D))
    u = interpolated(V, lambda x: np.vstack([x[0] * x[1], x[2] ** 2, x[0] - x[1]]))
    y = A.createVecLeft()
    A.mult(u.x.petsc_vec, y)
    expected = np.einsum("nij,nj->ni", D, pairs.relative_displacement(u))
    same_pattern = all(
        np.array_equal(A.getRow(r)[0], pairs.B.getRow(r)[0]) for r in range(*A.getOwnershipRange())
    )
    print(f"\n  |blockdiag(D) B u - D w| = {np.abs(y.getArray().reshape(-1, 3) - expected).max():.1e}; "
          f"same sparsity as B: {same_pattern}")
    np.testing.assert_allclose(y.getArray().reshape(-1, 3), expected, atol=1e-13)
    assert same_pattern
    with pytest.raises(ValueError, match="shape"):
        pairs.rows.scaled(D[:, :2])


def test_local_frames():
    rng = np.random.default_rng(11)
    n = rng.normal(size=(500, 3))
    special = np.array([[0, 1, 0], [0, -1, 0], [1, 0, 0], [-1, 0, 0], [0, 0, 1], [0, 0, -1],
                        [1, 1, 0], [1, 1, 1], [0.8, 0.6, 0]], dtype=float)  # fmt: skip
    n = np.vstack([special, n])
    n /= np.linalg.norm(n, axis=1)[:, None]
    R = local_frames(n)
    orth = np.abs(R @ np.transpose(R, (0, 2, 1)) - np.eye(3)).max()
    det = np.linalg.det(R)
    print(f"\n  {len(n)} frames: max |R Rᵀ - I| = {orth:.1e}, det in [{det.min():.15f}, {det.max():.15f}]; "
          f"n = +y -> t1 = {R[0, 1]}, t2 = {R[0, 2]}; n = -y -> t1 = {R[1, 1]}, t2 = {R[1, 2]}")
    assert orth < 1e-14
    np.testing.assert_allclose(det, 1.0, atol=1e-14)
    np.testing.assert_array_equal(R[:, 0], n)
    np.testing.assert_array_equal(R[0], [[0, 1, 0], [1, 0, 0], [0, 0, -1]])
    np.testing.assert_array_equal(R[1], [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    # near ±y (within 30 degrees) t1 stays close to +x: frames vary smoothly on a curved surface
    tilt = np.radians(rng.uniform(0, 30, 200))
    phi = rng.uniform(0, 2 * np.pi, 200)
    near_y = np.column_stack([np.sin(tilt) * np.cos(phi), np.cos(tilt), np.sin(tilt) * np.sin(phi)])
    assert local_frames(near_y)[:, 1, 0].min() > 0.85


def test_stacked_blocks_pairs():
    mesh, _, facet_tags = meshing.build_stacked_blocks(MPI.COMM_WORLD, 1.0, 0.5, 0.5, 1.0, 4, 2, 2, 3)
    pairs = find_pairs(vector_p1(mesh), facet_tags, S.CONTACT1, S.CONTACT2)
    print(f"\n  stacked blocks 4 x 3 interface elements: {pairs.num_global} pairs")
    assert pairs.num_global == 5 * 4
    np.testing.assert_array_equal(pairs.gather(pairs.g0), 0.0)


def test_search_distance_gap_and_swapped_surfaces():
    mesh, _, facet_tags = meshing.build_stacked_blocks(MPI.COMM_WORLD, 1.0, 0.5, 0.5, 1.0, 4, 2, 2, 4, gap=0.02)
    V = vector_p1(mesh)
    with pytest.raises(ContactPairError, match="no partner"):
        find_pairs(V, facet_tags, S.CONTACT1, S.CONTACT2)  # coincident nodes only
    pairs = find_pairs(V, facet_tags, S.CONTACT1, S.CONTACT2, search_distance=0.05)
    swapped = find_pairs(V, facet_tags, S.CONTACT2, S.CONTACT1, search_distance=0.05)
    g0, g0_swapped = pairs.gather(pairs.g0), swapped.gather(swapped.g0)
    n, n_swapped = pairs.gather(pairs.normals), swapped.gather(swapped.normals)
    print(f"\n  gap 0.02: {pairs.num_global} pairs, g0 in [{g0.min()}, {g0.max()}], n = {n[0]}; "
          f"swapped: g0 in [{g0_swapped.min()}, {g0_swapped.max()}], n = {n_swapped[0]}")
    assert pairs.num_global == swapped.num_global == 25
    np.testing.assert_allclose(g0, 0.02, rtol=1e-12)
    np.testing.assert_allclose(g0_swapped, 0.02, rtol=1e-12)
    np.testing.assert_array_equal(n, np.broadcast_to([0, 1, 0], (25, 3)))
    np.testing.assert_array_equal(n_swapped, np.broadcast_to([0, -1, 0], (25, 3)))
    # w_n of a rigid approach of body 2 by d: the gap closes, g0 + w_n = g0 - d
    d = 0.005

    def approach(x):
        return np.vstack([0 * x[0], np.where(x[1] > 0.51, -d, 0.0), 0 * x[0]])

    w = pairs.relative_displacement(interpolated(V, approach))
    np.testing.assert_allclose(pairs.g0 + w[:, 0], 0.02 - d, rtol=1e-12)


def test_initial_gap_override():
    mesh, _, facet_tags = meshing.build_stacked_blocks(
        MPI.COMM_WORLD, 1.0, 0.5, 0.5, 1.0, 4, 1, 1, 4, y_interface=0.0, centred=True
    )
    radius = 2.0

    def hertz_gap(x):
        return (x[0] ** 2 + x[2] ** 2) / (2 * radius)

    pairs = find_pairs(vector_p1(mesh), facet_tags, S.CONTACT1, S.CONTACT2, initial_gap=hertz_gap)
    x, g0 = pairs.gather(pairs.positions), pairs.gather(pairs.g0)
    print(f"\n  Hertz-type initial gap: {pairs.num_global} pairs, g0 from {g0.min()} to {g0.max()}")
    np.testing.assert_allclose(g0, hertz_gap(x.T), rtol=1e-15)
    assert g0.min() == 0.0 and g0.max() == pytest.approx(0.5 / (2 * radius) * 1.0)
    with pytest.raises(ContactPairError, match="initial_gap must return 25"):
        find_pairs(vector_p1(mesh), facet_tags, S.CONTACT1, S.CONTACT2, initial_gap=lambda x: x[0][:3])


# --- errors --------------------------------------------------------------------------------


def check_error(message_part, V, facet_tags, s1, s2, **kwargs):
    with pytest.raises(ContactPairError, match=message_part) as info:
        find_pairs(V, facet_tags, s1, s2, **kwargs)
    print(f"\n  {info.value}")
    return str(info.value)


def test_error_same_and_missing_tags(two_beams):
    V, _, facet_tags, _ = two_beams
    check_error("same tag 21", V, facet_tags, T.CONTACT1, T.CONTACT1)
    message = check_error("no facet is tagged 99", V, facet_tags, T.CONTACT1, 99)
    assert "[11, 12, 13, 21, 22]" in message and "surface2" in message
    check_error("no facet is tagged 98 \\(surface1\\)", V, facet_tags, 98, T.CONTACT2)


def test_error_not_vector_p1_or_p2(two_beams):
    V, _, facet_tags, _ = two_beams
    mesh = V.mesh
    check_error("block size 3, got block size 1", dolfinx.fem.functionspace(mesh, ("Lagrange", 1)),
                facet_tags, T.CONTACT1, T.CONTACT2)
    check_error("degree 1 or 2 .*64 dof blocks for 8 vertices", dolfinx.fem.functionspace(mesh, ("Lagrange", 3, (3,))),
                facet_tags, T.CONTACT1, T.CONTACT2)
    check_error("degree 1", dolfinx.fem.functionspace(mesh, ("DG", 1, (3,))), facet_tags, T.CONTACT1, T.CONTACT2)
    check_error("block size 3, got block size 2", dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,))),
                facet_tags, T.CONTACT1, T.CONTACT2)


def test_error_body2_node_without_partner(two_beams):
    V, _, facet_tags, _ = two_beams
    message = check_error("has no partner", V, facet_tags, T.CONTACT1, T.LOAD)
    assert "(1.6, 0.8, 0)" in message and "surface 13 (body 2)" in message


def test_error_body1_node_matched_twice():
    mesh, _, facet_tags = meshing.build_stacked_blocks(MPI.COMM_WORLD, 1.0, 0.5, 0.5, 1.0, 4, 2, 2, 4, nx2=8)
    message = check_error("is the partner of 2 body-2 nodes", vector_p1(mesh), facet_tags,
                          S.CONTACT1, S.CONTACT2, search_distance=0.2)
    assert "(0, 0.5, 0)" in message and "(0.125, 0.5, 0)" in message


def test_error_body2_behind_body1():
    mesh, _, facet_tags = meshing.build_stacked_blocks(MPI.COMM_WORLD, 1.0, 0.5, 0.5, 1.0, 4, 2, 2, 4, gap=-0.05)
    message = check_error("lies behind surface 21", vector_p1(mesh), facet_tags,
                          S.CONTACT1, S.CONTACT2, search_distance=0.2)
    assert "initial gap -0.05" in message


def test_error_normals_point_the_same_way():
    mesh, _, facet_tags = meshing.build_stacked_blocks()
    check_error("do not face each other", vector_p1(mesh), facet_tags, S.CONTACT1, S.TOP, search_distance=0.6)


def test_error_shared_nodes_and_interior_facets(box_factory):
    mesh, facet_tags = box_factory(n=(2, 2, 2))
    V = vector_p1(mesh)
    message = check_error("share 3 node\\(s\\)", V, facet_tags, 2, 4)  # faces x = 1 and y = 1
    assert "must be meshed without common nodes" in message
    fdim = mesh.topology.dim - 1
    interior = dolfinx.mesh.locate_entities(mesh, fdim, lambda x: np.isclose(x[1], 0.5))
    boundary = facet_tags.find(4)
    facets = np.concatenate([interior, boundary])
    values = np.concatenate([np.full(len(interior), 7, np.int32), np.full(len(boundary), 4, np.int32)])
    order = np.argsort(facets)
    tags = dolfinx.mesh.meshtags(mesh, fdim, facets[order], values[order])
    check_error("tagged 7 is inside a body", V, tags, 7, 4)


# --- MPI ---------------------------------------------------------------------------------------


def run_mpi(script: str, nprocs: int, *args: str) -> subprocess.CompletedProcess:
    cmd = [*compat.mpiexec(), "-n", str(nprocs), sys.executable, str(SCRIPTS / script), *args]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=240, env=compat.mpi_environment())
    assert result.returncode == 0, f"{' '.join(cmd)} failed:\n{result.stdout}\n{result.stderr}"
    return result


def sorted_by_position(case: dict) -> dict:
    """The per-pair arrays of a case in the order of the pair positions (x, y, z)."""
    x = np.asarray(case["positions"]).round(9)
    order = np.lexsort((x[:, 2], x[:, 1], x[:, 0]))
    return {k: np.asarray(v)[order] for k, v in case.items()
            if k in ("positions", "X_a", "X_b", "R", "g0", "w")}


@pytest.mark.mpi
def test_pairs_identical_on_1_2_3_ranks(tmp_path):
    results = {}
    for nprocs in (1, 2, 3):
        out = tmp_path / f"pairs_{nprocs}.json"
        run_mpi("pairs_gather.py", nprocs, str(out))
        results[nprocs] = json.loads(out.read_text())
        assert results[nprocs]["size"] == nprocs
    worst = 0.0
    for name, serial in results[1]["cases"].items():
        ref = sorted_by_position(serial)
        for nprocs in (2, 3):
            case = results[nprocs]["cases"][name]
            got = sorted_by_position(case)
            diff = max(float(np.abs(got[k] - ref[k]).max(initial=0.0)) for k in ref)
            worst = max(worst, diff)
            print(f"\n  {name} on {nprocs} ranks: {case['num_global']} pairs, per rank "
                  f"{case['pairs_per_rank']}, {case['pairs_with_a_on_another_rank']} with a_i on "
                  f"another rank; max difference to serial {diff:.1e}; total force "
                  f"{np.abs(case['total_force']).max():.1e}, (Bᵀλ)·u = {case['force_dot_u']:.12f} "
                  f"(serial {serial['force_dot_u']:.12f}), λ·Bu = {case['lam_dot_w']:.12f}")
            assert case["num_global"] == serial["num_global"]
            assert sum(case["pairs_per_rank"]) == serial["num_global"]
            for k in ref:
                np.testing.assert_allclose(got[k], ref[k], rtol=0, atol=1e-12, err_msg=f"{name}, {k}")
            assert abs(case["force_dot_u"] - serial["force_dot_u"]) < 1e-12
            assert abs(case["force_dot_u"] - case["lam_dot_w"]) < 1e-12
            assert np.abs(case["total_force"]).max() < 1e-12
    # the parallel paths were exercised: pairs spread over ranks, partners on other ranks
    three = results[3]["cases"]
    assert any(sum(n > 0 for n in c["pairs_per_rank"]) > 1 for c in three.values())
    assert all(c["pairs_with_a_on_another_rank"] > 0 for c in three.values())
    print(f"\n  largest difference between 2/3 ranks and serial: {worst:.1e}")


@pytest.mark.mpi
def test_errors_raised_on_every_rank():
    result = run_mpi("pairs_errors.py", 2)
    lines = [line for line in result.stdout.splitlines() if line.startswith("rank ")]
    print("\n  " + "\n  ".join(sorted(lines)))
    for case in ("missing_tag", "no_partner", "not_facing"):
        outcomes = {line.split(": ", 1)[1] for line in lines if f" case {case}:" in line}
        ranks = {line.split()[1] for line in lines if f" case {case}:" in line}
        assert ranks == {"0", "1"}, case
        assert len(outcomes) == 1 and next(iter(outcomes)).startswith("ContactPairError"), (case, outcomes)
    assert {line for line in lines if line.endswith("done")} == {"rank 0 done", "rank 1 done"}
