"""The gmsh model builders of dolfinx_nnqem.problem.meshing: cell counts, tags, duplicated interfaces."""

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import gmsh
import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem import compat
from dolfinx_nnqem.cases import geometries as meshing
from dolfinx_nnqem.cases.geometries import StackedBlocksTags, ThickCylinderTags, TwoBeamsTags

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]


def tag_counts(mesh, tags) -> dict[int, int]:
    """Number of OWNED entities per tag value, summed over all ranks."""
    mesh.topology.create_entities(tags.dim)
    owned = tags.indices < mesh.topology.index_map(tags.dim).size_local
    local = {int(v): int(np.sum(tags.values[owned] == v)) for v in np.unique(tags.values)}
    total: dict[int, int] = {}
    for part in mesh.comm.allgather(local):
        for v, n in part.items():
            total[v] = total.get(v, 0) + n
    return dict(sorted(total.items()))


def body_nodes(mesh, cell_tags, body: int) -> np.ndarray:
    """Coordinates of the nodes of the cells tagged ``body`` (all ranks, duplicates removed)."""
    cells = cell_tags.indices[cell_tags.values == body]
    x = mesh.geometry.x[np.unique(compat.geometry_dofmap(mesh)[cells])]
    return np.unique(np.concatenate(mesh.comm.allgather(x)).round(12), axis=0)


def coincident(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Points of x1 that also appear in x2 (both rounded to 12 decimals)."""
    s2 = {tuple(p) for p in x2}
    return np.array([p for p in x1 if tuple(p) in s2]).reshape(-1, 3)


def num_cells(mesh) -> int:
    return mesh.topology.index_map(mesh.topology.dim).size_global


def test_two_beams_mesh():
    mesh, cell_tags, facet_tags = meshing.build_two_beams()
    T = TwoBeamsTags
    cells = tag_counts(mesh, cell_tags)
    facets = tag_counts(mesh, facet_tags)
    x1, x2 = body_nodes(mesh, cell_tags, T.BODY1), body_nodes(mesh, cell_tags, T.BODY2)
    shared = coincident(x1, x2)
    lo = mesh.comm.allreduce(mesh.geometry.x.min(axis=0), op=MPI.MIN)
    hi = mesh.comm.allreduce(mesh.geometry.x.max(axis=0), op=MPI.MAX)
    print(f"\n  two beams: {num_cells(mesh)} cells {cells}, facets per tag {facets}, "
          f"nodes per beam {len(x1)}, {len(x2)}; coincident nodes {len(shared)}; box {lo} - {hi}")
    assert mesh.topology.cell_type == __import__("dolfinx").mesh.CellType.hexahedron
    assert num_cells(mesh) == 80
    assert cells == {T.BODY1: 40, T.BODY2: 40}
    assert facets == {T.CLAMP1: 4, T.CLAMP2: 4, T.LOAD: 20, T.CONTACT1: 4, T.CONTACT2: 4}
    assert len(x1) == len(x2) == 11 * 3 * 3  # 10 x 2 x 2 hexahedra each
    # no node is shared: the beams' node sets are disjoint in the mesh, and exactly the 9
    # interface nodes coincide geometrically
    assert mesh.comm.allreduce(mesh.geometry.index_map().size_local) == 2 * 99
    assert len(shared) == 9
    np.testing.assert_allclose(shared[:, 1], 0.4)
    assert sorted(set(shared[:, 0])) == [1.6, 1.8, 2.0] and sorted(set(shared[:, 2])) == [0.0, 0.2, 0.4]
    np.testing.assert_allclose(lo, [0, 0, 0], atol=1e-14)
    np.testing.assert_allclose(hi, [3.6, 0.8, 0.4], atol=1e-14)
    # contact facets lie on y = 0.4 within x in [1.6, 2.0]
    mesh.topology.create_connectivity(2, 0)
    for tag in (T.CONTACT1, T.CONTACT2):
        facets_x = mesh.geometry.x[
            __import__("dolfinx").mesh.entities_to_geometry(mesh, 2, facet_tags.find(tag))
        ].reshape(-1, 3)
        assert np.allclose(facets_x[:, 1], 0.4) and facets_x[:, 0].min() >= 1.6 - 1e-12
        assert facets_x[:, 0].max() <= 2.0 + 1e-12


def test_two_beams_refined():
    mesh, cell_tags, facet_tags = meshing.build_two_beams(refine=2)
    T = TwoBeamsTags
    facets = tag_counts(mesh, facet_tags)
    shared = coincident(body_nodes(mesh, cell_tags, T.BODY1), body_nodes(mesh, cell_tags, T.BODY2))
    print(f"\n  refine 2: {num_cells(mesh)} cells, facets {facets}, coincident nodes {len(shared)}")
    assert num_cells(mesh) == 640
    assert facets == {T.CLAMP1: 16, T.CLAMP2: 16, T.LOAD: 80, T.CONTACT1: 16, T.CONTACT2: 16}
    assert len(shared) == 25
    with pytest.raises(ValueError, match="refine"):
        meshing.build_two_beams(refine=0)


def test_two_beams_with_beam_2_meshed_finer():
    """refine2: beam 2 at edge 0.1 m, beam 1 at 0.2 m; the contact surfaces share only their 4 corners."""
    mesh, cell_tags, facet_tags = meshing.build_two_beams(refine2=2)
    T = TwoBeamsTags
    facets = tag_counts(mesh, facet_tags)
    shared = coincident(body_nodes(mesh, cell_tags, T.BODY1), body_nodes(mesh, cell_tags, T.BODY2))
    print(f"\n  refine2 = 2: {num_cells(mesh)} cells, facets {facets}, coincident nodes {len(shared)}")
    assert num_cells(mesh) == 40 + 320
    assert facets == {T.CLAMP1: 4, T.CLAMP2: 16, T.LOAD: 80, T.CONTACT1: 4, T.CONTACT2: 16}
    assert len(shared) == 9  # beam 1's 3 x 3 interface nodes all lie on beam 2's 5 x 5 grid
    with pytest.raises(ValueError, match="refine2"):
        meshing.build_two_beams(refine2=0)


def test_two_beams_msh_file_round_trip(tmp_path):
    path = tmp_path / "beams.msh"
    meshing.build_two_beams(MPI.COMM_SELF, msh_file=path)
    mesh, cell_tags, facet_tags = compat.read_from_msh(str(path), MPI.COMM_SELF)
    cells, facets = tag_counts(mesh, cell_tags), tag_counts(mesh, facet_tags)
    print(f"\n  read back {path.name}: {num_cells(mesh)} cells {cells}, facets {facets}")
    assert num_cells(mesh) == 80 and cells == {1: 40, 2: 40}
    assert facets == {11: 4, 12: 4, 13: 20, 21: 4, 22: 4}
    assert mesh.geometry.x.shape[0] == 198  # duplicated interface nodes survive the file


def test_committed_two_beams_msh_matches_builder():
    """meshes/two_beams.msh (written by meshes/generate.py) is the builder's mesh."""
    path = ROOT / "meshes" / "two_beams.msh"
    mesh, cell_tags, facet_tags = compat.read_from_msh(str(path), MPI.COMM_SELF)
    built, _, _ = meshing.build_two_beams(MPI.COMM_SELF)
    a = np.unique(mesh.geometry.x.round(12), axis=0)
    b = np.unique(built.geometry.x.round(12), axis=0)
    print(f"\n  {path.name}: {num_cells(mesh)} cells, {mesh.geometry.x.shape[0]} nodes "
          f"({len(a)} distinct positions); builder: {built.geometry.x.shape[0]} nodes")
    assert num_cells(mesh) == 80 and mesh.geometry.x.shape[0] == 198
    assert tag_counts(mesh, facet_tags) == {11: 4, 12: 4, 13: 20, 21: 4, 22: 4}
    np.testing.assert_array_equal(a, b)


def test_committed_die_on_slab_msh_is_the_ironing_mesh():
    """meshes/die_on_slab.msh (what demos/neo_hooke_ironing.toml reads) read back is the mesh the
    Neo-Hookean ironing builds at r = 1, to the bit: its nodes (the die's moved to 0.25 <= x <= 0.5),
    cells and tags, in the same order."""
    from dolfinx_nnqem.cases.geometries import build_die_on_slab
    from dolfinx_nnqem.cases.neo_hooke_ironing import DIE_X

    read = compat.read_from_msh(str(ROOT / "meshes" / "die_on_slab.msh"), MPI.COMM_SELF, 0, gdim=3)
    built = build_die_on_slab(MPI.COMM_SELF, 1, DIE_X)
    die = np.unique(compat.geometry_dofmap(read[0])[read[1].indices[read[1].values == 2]])
    die_x = (read[0].geometry.x[die, 0].min(), read[0].geometry.x[die, 0].max())
    print(f"\n  die_on_slab.msh: {num_cells(read[0])} cells, {read[0].geometry.x.shape[0]} nodes, the die's x in "
          f"{die_x}; facets {tag_counts(read[0], read[2])}")
    np.testing.assert_array_equal(read[0].geometry.x, built.mesh.geometry.x)
    np.testing.assert_array_equal(compat.geometry_dofmap(read[0]), compat.geometry_dofmap(built.mesh))
    for a, b in ((read[1], built.cell_tags), (read[2], built.facet_tags)):
        np.testing.assert_array_equal(a.indices, b.indices)
        np.testing.assert_array_equal(a.values, b.values)
    assert die_x == DIE_X


def _cells_by_tag(mesh, tags) -> dict[int, list]:
    """Per tag value, each tagged entity as its sorted node positions: tags compared by geometry,
    whatever the numbering of the nodes and cells."""
    out = {}
    for value in np.unique(tags.values):
        nodes = compat.entities_to_geometry(mesh, tags.dim, tags.indices[tags.values == value])
        out[int(value)] = sorted(tuple(sorted(map(tuple, mesh.geometry.x[row].round(12)))) for row in nodes)
    return out


def test_committed_two_beams_xdmf_is_the_msh():
    """meshes/two_beams.xdmf (what demos/two_beams.toml reads) is meshes/two_beams.msh: the same
    nodes, cells and tagged cells and facets."""
    from dolfinx.io import XDMFFile

    msh, msh_cells, msh_facets = compat.read_from_msh(str(ROOT / "meshes" / "two_beams.msh"), MPI.COMM_SELF)
    with XDMFFile(MPI.COMM_SELF, str(ROOT / "meshes" / "two_beams.xdmf"), "r") as xdmf:
        mesh = xdmf.read_mesh(name="mesh")
        mesh.topology.create_connectivity(2, 3)
        cells = xdmf.read_meshtags(mesh, name="cell_tags")
        facets = xdmf.read_meshtags(mesh, name="facet_tags")
    print(f"\n  two_beams.xdmf: {num_cells(mesh)} cells, {mesh.geometry.x.shape[0]} nodes, facets "
          f"{tag_counts(mesh, facets)}")
    np.testing.assert_array_equal(np.unique(mesh.geometry.x, axis=0), np.unique(msh.geometry.x, axis=0))
    for a, b in ((cells, msh_cells), (facets, msh_facets)):
        tagged, tagged_msh = _cells_by_tag(mesh, a), _cells_by_tag(msh, b)
        assert sorted(tagged) == sorted(tagged_msh)
        for value in tagged:
            assert tagged[value] == tagged_msh[value]


def test_generate_script(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("generate", ROOT / "meshes" / "generate.py")
    generate = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(generate)
    written = generate.main(["--output-dir", str(tmp_path)])
    names = sorted(p.name for p in written)
    print(f"\n  generate.py wrote {names}")
    assert names == ["die_on_slab.msh", "indenter_block.msh", "stacked_blocks.msh", "thick_cylinder.msh",
                     "three_blocks.msh", "two_beams.msh", "two_beams.xdmf"]
    assert all((tmp_path / n).stat().st_size > 0 for n in names)
    # the graded block is written with its graded nodes: it reads back as the builder's mesh
    from dolfinx_nnqem import compat
    from dolfinx_nnqem.cases.geometries import build_graded_block

    read = compat.read_from_msh(str(tmp_path / "indenter_block.msh"), MPI.COMM_SELF, 0, gdim=3)
    built = build_graded_block(MPI.COMM_SELF, 0.25, half=True)
    order = lambda x: x[np.lexsort((x[:, 2], x[:, 1], x[:, 0]))]  # noqa: E731
    diff = np.abs(order(read[0].geometry.x) - order(built.mesh.geometry.x)).max()
    print(f"  indenter_block.msh against build_graded_block: max node distance {diff:.1e}; facet tags "
          f"{sorted(set(read[2].values.tolist()))}")
    assert diff < 1e-12 and sorted(set(read[2].values.tolist())) == [101, 201, 301, 401, 501, 601]
    with pytest.raises(SystemExit):
        generate.main(["no_such_model", "--output-dir", str(tmp_path)])


def test_existing_gmsh_session_is_left_alone():
    """A caller's gmsh session stays initialised, with its current model, after a build
    (on MPI.COMM_SELF, so gmsh builds on every rank)."""
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("callers_model")
        gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        gmsh.model.occ.synchronize()
        mesh, _, _ = meshing.build_stacked_blocks(MPI.COMM_SELF)
        state = (gmsh.isInitialized(), gmsh.model.getCurrent(), gmsh.model.getEntities(3))
        print(f"\n  after the build: initialised {state[0]}, current model {state[1]!r}, "
              f"volumes {state[2]}, models {gmsh.model.list()}")
        assert state == (1, "callers_model", [(3, 1)])
        assert "stacked_blocks" not in gmsh.model.list()
        assert num_cells(mesh) == 64
    finally:
        gmsh.finalize()


def test_stacked_blocks_tags():
    T = StackedBlocksTags
    mesh, cell_tags, facet_tags = meshing.build_stacked_blocks(
        MPI.COMM_WORLD, Lx=2.0, Ly1=0.5, Ly2=0.75, Lz=1.0, nx=4, ny1=2, ny2=3, nz=2
    )
    cells, facets = tag_counts(mesh, cell_tags), tag_counts(mesh, facet_tags)
    shared = coincident(body_nodes(mesh, cell_tags, T.BODY1), body_nodes(mesh, cell_tags, T.BODY2))
    print(f"\n  stacked blocks: cells {cells}, facets {facets}, coincident nodes {len(shared)}")
    assert cells == {T.BODY1: 16, T.BODY2: 24}
    assert facets == {
        T.BOTTOM: 8, T.TOP: 8, T.CONTACT1: 8, T.CONTACT2: 8,
        T.BODY1_XMIN: 4, T.BODY1_XMAX: 4, T.BODY1_ZMIN: 8, T.BODY1_ZMAX: 8,
        T.BODY2_XMIN: 6, T.BODY2_XMAX: 6, T.BODY2_ZMIN: 12, T.BODY2_ZMAX: 12,
    }  # fmt: skip
    assert len(shared) == 5 * 3 and np.allclose(shared[:, 1], 0.5)

    # faces are where their names say
    import dolfinx

    for tag, axis, value in [(T.BOTTOM, 1, 0.0), (T.TOP, 1, 1.25), (T.CONTACT1, 1, 0.5),
                             (T.CONTACT2, 1, 0.5), (T.BODY1_XMAX, 0, 2.0), (T.BODY2_ZMIN, 2, 0.0)]:
        x = mesh.geometry.x[dolfinx.mesh.entities_to_geometry(mesh, 2, facet_tags.find(tag))]
        assert np.allclose(x[..., axis], value), tag


def test_stacked_blocks_centred_with_gap_and_finer_top():
    T = StackedBlocksTags
    mesh, cell_tags, facet_tags = meshing.build_stacked_blocks(
        MPI.COMM_WORLD, 1.0, 0.5, 0.5, 1.0, 4, 2, 2, 4, y_interface=0.0, centred=True, gap=0.1, nx2=8
    )
    lo = mesh.comm.allreduce(mesh.geometry.x.min(axis=0), op=MPI.MIN)
    hi = mesh.comm.allreduce(mesh.geometry.x.max(axis=0), op=MPI.MAX)
    cells, facets = tag_counts(mesh, cell_tags), tag_counts(mesh, facet_tags)
    print(f"\n  centred, gap 0.1, nx2 = 8: box {lo} - {hi}, cells {cells}, contact facets "
          f"{facets[T.CONTACT1]}, {facets[T.CONTACT2]}")
    np.testing.assert_allclose(lo, [-0.5, -0.5, -0.5], atol=1e-14)
    np.testing.assert_allclose(hi, [0.5, 0.6, 0.5], atol=1e-14)
    assert cells == {T.BODY1: 32, T.BODY2: 64}
    assert facets[T.CONTACT1] == 16 and facets[T.CONTACT2] == 32
    with pytest.raises(ValueError, match="nx"):
        meshing.build_stacked_blocks(nx=0)


@pytest.mark.parametrize("progression", [1.0, 1.25])
def test_thick_cylinder(progression):
    T = ThickCylinderTags
    a, b, t, nr, nc = 1.0, 2.0, 0.1, 6, 10
    mesh, cell_tags, facet_tags = meshing.build_thick_cylinder(
        MPI.COMM_WORLD, a, b, t, nr, nc, radial_progression=progression
    )
    cells, facets = tag_counts(mesh, cell_tags), tag_counts(mesh, facet_tags)
    import dolfinx

    def facet_points(tag):
        x = mesh.geometry.x[dolfinx.mesh.entities_to_geometry(mesh, 2, facet_tags.find(tag))]
        return np.concatenate(mesh.comm.allgather(x.reshape(-1, 3)))

    r_inner = np.linalg.norm(facet_points(T.INNER)[:, :2], axis=1)
    r_outer = np.linalg.norm(facet_points(T.OUTER)[:, :2], axis=1)
    # radial node positions on the symmetry line y = 0
    radii = np.unique(facet_points(T.SYMMETRY_Y)[:, 0].round(12))
    sizes = np.diff(radii)
    ratios = sizes[1:] / sizes[:-1]
    print(f"\n  thick cylinder (progression {progression}): cells {cells}, facets {facets}; inner r in "
          f"[{r_inner.min():.15f}, {r_inner.max():.15f}], outer r in [{r_outer.min():.15f}, "
          f"{r_outer.max():.15f}]; radial sizes {np.round(sizes, 4)}")
    assert cells == {T.BODY: nr * nc}
    assert facets == {T.INNER: nc, T.OUTER: nc, T.SYMMETRY_X: nr, T.SYMMETRY_Y: nr, T.FACES_Z: 2 * nr * nc}
    np.testing.assert_allclose(r_inner, a, atol=1e-12)
    np.testing.assert_allclose(r_outer, b, atol=1e-12)
    np.testing.assert_allclose(facet_points(T.SYMMETRY_X)[:, 0], 0.0, atol=1e-12)
    assert set(np.unique(facet_points(T.FACES_Z)[:, 2].round(12))) == {0.0, t}
    assert len(radii) == nr + 1
    np.testing.assert_allclose(ratios, progression, rtol=1e-6)  # gmsh solves for the sizes
