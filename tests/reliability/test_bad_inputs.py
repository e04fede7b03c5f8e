"""Bad inputs, table-driven, through BOTH the problem file (exit code 3, the key named) and the
Python API (ValueError/TypeError naming the value), before anything is solved."""

import math
import re
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from problem_files import two_beams_minimal

from dolfinx_nnqem.cli import EXIT_BAD_INPUT, EXIT_OK, main
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.cases.geometries import build_two_beams
from dolfinx_nnqem.problem import BodyForce, Contact, ContactProblem, Dirichlet, Gravity, Pressure, Traction
from dolfinx_nnqem.solvers import SolverOptions
from dolfinx_nnqem.solvers.step_control import AutomaticIncrements  # noqa: F401  (the "steps:" cases evaluate it)

ROOT = Path(__file__).resolve().parents[2]
MESH = (ROOT / "meshes" / "two_beams.msh").as_posix()
GOOD = two_beams_minimal(MESH, more='[solver]\nincrements = 2\n[output]\nfolder = "out"\n')
M = VonMises(E=1e9, nu=0.3)


@pytest.fixture(scope="module")
def beams():
    return build_two_beams(MPI.COMM_WORLD)


def _api(beams, **change):
    mesh, cell_tags, facet_tags = beams
    kwargs = dict(materials={1: M, 2: M}, dirichlet=[Dirichlet(11), Dirichlet(12)],
                  contact=Contact(21, 22, mu_f=0.3))
    kwargs.update(change)
    return ContactProblem(mesh, cell_tags, facet_tags, **kwargs)


def _square():
    import dolfinx.mesh as dm

    return dm.create_unit_square(MPI.COMM_WORLD, 2, 2)


# name: (problem-file edit (old, new), API call raising, words the message must contain)
CASES = {
    "dirichlet tag missing": (("tag = 12", "tag = 99"),
                              lambda b: _api(b, dirichlet=[Dirichlet(11), Dirichlet(99)]), "99"),
    "traction tag missing": (("[solver]", "[[traction]]\ntag = 98\nvalue = [1.0, 0.0, 0.0]\n[solver]"),
                             lambda b: _api(b, tractions=[Traction(98, (1.0, 0.0, 0.0))]), "98"),
    "pressure tag missing": (("[solver]", "[[pressure]]\ntag = 97\np = 1.0\n[solver]"),
                             lambda b: _api(b, tractions=[Pressure(97, 1.0)]), "97"),
    "body force cell tag missing": (("[solver]", "[[body_force]]\nvalue = [0.0, -1.0, 0.0]\ncell_tag = 7\n[solver]"),
                                    lambda b: _api(b, body_forces=[BodyForce((0, -1, 0), cell_tag=7)]), "cell tag 7"),
    "material tag missing": (("[materials.2]", "[materials.5]\nE = 1.0e9\nnu = 0.3\n[materials.2]"),
                             lambda b: _api(b, materials={1: M, 2: M, 5: M}), "cell tag 5"),
    "contact tag missing": (("surface2 = 22", "surface2 = 96"),
                            lambda b: _api(b, contact=Contact(21, 96, mu_f=0.3)), "96"),
    "contact surfaces share nodes": (("surface1 = 21\nsurface2 = 22", "surface1 = 12\nsurface2 = 13"),
                                     lambda b: _api(b, contact=Contact(12, 13, mu_f=0.3)), "share"),
    "a body moves rigidly": (("[contact]\nsurface1 = 21\nsurface2 = 22\nmu_f = 0.3\n[[dirichlet]]\ntag = 11\n"
                              "[[dirichlet]]\ntag = 12\n", "[[dirichlet]]\ntag = 11\n"),
                             lambda b: _api(b, contact=None, dirichlet=[Dirichlet(11)]), "rigid"),
    "friction not finite": (("mu_f = 0.3", "mu_f = nan"),
                            lambda b: Contact(21, 22, mu_f=float("nan")), "mu_f"),
    "E infinite": (("E = 1.0e9", "E = inf"), lambda b: VonMises(E=math.inf, nu=0.3), "E"),
    "rtol too large": (("increments = 2", "increments = 2\nrtol = 0.5"), lambda b: SolverOptions(rtol=0.5), "rtol"),
    "rtol not a number": (("increments = 2", "increments = 2\nrtol = nan"),
                          lambda b: SolverOptions(rtol=float("nan")), "rtol"),
    "atol negative": (("increments = 2", "increments = 2\natol = -1.0"), lambda b: SolverOptions(atol=-1.0), "atol"),
    "increments zero": (("increments = 2", "increments = 0"), "steps:increments=0", "increments"),  # issue 31, 2
    "increments too many": (("increments = 2", "increments = 1000000"), "steps:increments=1000000", "increments"),
    "increments not an integer": (("increments = 2", "increments = 2.5"), "steps:increments=2.5", "increments"),
    "cutbacks too many": (("increments = 2", "increments = 2\nmax_cutbacks = 99"), "steps:max_cutbacks=99",
                          "max_cutbacks"),
    "output folder empty": (('folder = "out"', 'folder = ""'), "writer:", "folder"),
    "traction not finite": (("[solver]", "[[traction]]\ntag = 13\nvalue = [nan, 0.0, 0.0]\n[solver]"),
                            lambda b: _api(b, tractions=[Traction(13, (math.nan, 0.0, 0.0))]), "finite"),
    "2D mesh": (None, lambda b: ContactProblem(_square(), None, None, materials=M), "2D"),
    # issue 31, item 3: values that overflowed in the solvers are refused, with the limit
    "E huge": (("E = 1.0e9", "E = 1e300"), lambda b: VonMises(E=1e300, nu=0.3), "[1e-20, 1e+20]"),
    "E tiny": (("E = 1.0e9", "E = 1e-300"), lambda b: VonMises(E=1e-300, nu=0.3), "[1e-20, 1e+20]"),
    "nu nearly 0.5": (("nu = 0.3", "nu = 0.4999999"), lambda b: VonMises(E=1e9, nu=0.4999999), "0.4999]"),
    "density huge": (("nu = 0.3", "nu = 0.3\ndensity = 1e300"), lambda b: VonMises(E=1e9, nu=0.3, density=1e300),
                     "density = 1e+300"),
    "traction huge": (("[solver]", "[[traction]]\ntag = 13\nvalue = [1e300, 0.0, 0.0]\n[solver]"),
                      lambda b: _api(b, tractions=[Traction(13, (1e300, 0.0, 0.0))]), "magnitude 1e+20"),
    "prescribed value huge": (("tag = 12", "tag = 12\nvalue = 1e300"),
                              lambda b: _api(b, dirichlet=[Dirichlet(11), Dirichlet(12, 1e300)]), "magnitude 1e+20"),
    "r huge": (("mu_f = 0.3", "mu_f = 0.3\nr = 1e300"), lambda b: Contact(21, 22, mu_f=0.3, r=1e300), "1e+20"),
    # issue 31, item 4: r far from E h stalls the Newton iterations: refused with the range
    "r tiny": (("mu_f = 0.3", "mu_f = 0.3\nr = 1e-300"),
               lambda b: _api(b, contact=Contact(21, 22, mu_f=0.3, r=1e-300)),
               "supported range is [1e-06, 1000] × E h"),
    # issue 31, item 8: a load vector that is not numbers names the parameter, not numpy's words
    "gravity not a vector": (("[solver]", '[gravity]\ng = "down"\n[solver]'),
                             lambda b: _api(b, body_forces=[Gravity("down")]), ".g = 'down'"),
    # issue 39, item 9: keys that were accepted and then stalled, or silently dropped
    "two contacts on one pair of surfaces": (
        ("[contact]\nsurface1 = 21\nsurface2 = 22\nmu_f = 0.3",
         '[[contact]]\nname = "a"\nsurface1 = 21\nsurface2 = 22\nmu_f = 0.3\n'
         '[[contact]]\nname = "b"\nsurface1 = 21\nsurface2 = 22\nmu_f = 0.3'),
        lambda b: _api(b, contact=[Contact(21, 22, mu_f=0.3), Contact(22, 21, mu_f=0.3)]), "both join"),
    "dirichlet component twice": (("tag = 12", "tag = 12\ncomponents = [0, 0]"),
                                  lambda b: _api(b, dirichlet=[Dirichlet(11), Dirichlet(12, 0.0, [0, 0])]), "twice"),
    # a dof given two different displacements: which held depended on the order of the entries
    "dirichlet values in conflict": (("tag = 12\n", "tag = 12\n[[dirichlet]]\ntag = 12\nvalue = 0.001\ncomponents = [1]\n"),
                                     lambda b: _api(b, dirichlet=[Dirichlet(11), Dirichlet(12),
                                                                  Dirichlet(12, 0.001, [1])]),
                                     "prescribe different displacements to the same dof"),
    "load factor above 1": (("increments = 2", 'increments = "auto"\n[solver.auto]\nload_factors = [0.5, 1.5]'),
                            "steps:increments=AutomaticIncrements(load_factors=(0.5, 1.5))", "1.5"),
    "load factor below 0": (("increments = 2", 'increments = "auto"\n[solver.auto]\nload_factors = [-0.5]'),
                            "steps:increments=AutomaticIncrements(load_factors=(-0.5,))", "-0.5"),
}


@pytest.mark.parametrize("name", list(CASES))
def test_bad_input_through_the_problem_file(tmp_path, capsys, name):
    edit, _, words = CASES[name]
    if edit is None:
        edit = (f'file = "{MESH}"', f'file = "{_square_msh(tmp_path)}"')
    old, new = edit
    assert old in GOOD
    path = tmp_path / "p.toml"
    path.write_text(GOOD.replace(old, new, 1))
    code = main(["-q", "run", str(path), "--check"])
    err = capsys.readouterr().err.strip()
    print(f"\n  exit {code}: {err}")
    assert code == EXIT_BAD_INPUT and words in err and "Traceback" not in err


@pytest.mark.parametrize("name", list(CASES))
def test_bad_input_through_the_api(tmp_path, beams, name):
    _, call, words = CASES[name]
    with pytest.raises((ValueError, TypeError)) as error:
        if isinstance(call, str):
            _api_call(call, beams, tmp_path)
        else:
            call(beams)
    print(f"\n  {type(error.value).__name__}: {error.value}")
    assert words in str(error.value)


def _api_call(spec, beams, tmp_path):
    from dolfinx_nnqem.io import ResultsWriter
    from dolfinx_nnqem.solvers import make_solver
    from dolfinx_nnqem.solvers import solve_load_steps

    kind, _, arg = spec.partition(":")
    problem = _api(beams)
    if kind == "writer":
        ResultsWriter(problem, "monolithic", "", 2)
    key, value = arg.split("=", 1)
    solve_load_steps(problem, make_solver("monolithic", problem), **{"increments": 2, key: eval(value)})


def _square_msh(tmp_path) -> str:
    import gmsh

    started = not gmsh.isInitialized()
    if started:
        gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("square")
    gmsh.model.occ.addRectangle(0, 0, 0, 1, 1)
    gmsh.model.occ.synchronize()
    gmsh.model.addPhysicalGroup(2, [1], 1)
    gmsh.model.mesh.generate(2)
    path = tmp_path / "square.msh"
    gmsh.write(str(path))
    gmsh.model.remove()
    if started:
        gmsh.finalize()
    return path.as_posix()


def test_numpy_scalars_are_accepted(tmp_path, beams):
    from dolfinx_nnqem.solvers import make_solver
    from dolfinx_nnqem.solvers import solve_load_steps

    m = VonMises(E=np.float64(1e9), nu=np.float32(0.3))
    problem = _api(beams, materials={np.int64(1): m, np.int32(2): m},
                   dirichlet=[Dirichlet(np.int64(11)), Dirichlet(np.int64(12))],
                   tractions=[Traction(np.int64(13), np.array([1e3, -1e3, 0.0]))],
                   contact=Contact(np.int64(21), np.int64(22), mu_f=np.float64(0.3)))
    solver = make_solver("monolithic", problem, SolverOptions(rtol=np.float64(1e-10), max_iterations=np.int64(30)))
    results = solve_load_steps(problem, solver, np.int64(2), max_cutbacks=np.int32(2),
                               final_load_factor=np.float64(1.0))
    print(f"\n  numpy scalars: {len(results)} increments, |R|/F = {results[-1].check.equilibrium:.1e}")
    assert len(results) == 2


def test_the_good_file_passes(tmp_path, capsys):
    path = tmp_path / "p.toml"
    path.write_text(GOOD)
    assert main(["-q", "run", str(path), "--check"]) == EXIT_OK


def _fused_blocks_msh(tmp_path) -> str:
    """Two boxes fragmented together (common nodes on y = 0.5), tagged as two bodies, the
    interface tagged 21 and 22 as if the bodies were apart."""
    import gmsh

    started = not gmsh.isInitialized()
    if started:
        gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("fused")
    a = gmsh.model.occ.addBox(0, 0, 0, 1, 0.5, 1)
    b = gmsh.model.occ.addBox(0, 0.5, 0, 1, 0.5, 1)
    gmsh.model.occ.fragment([(3, a)], [(3, b)])
    gmsh.model.occ.synchronize()

    def at(dim, y):
        return [t for _, t in gmsh.model.getEntities(dim) if abs(gmsh.model.occ.getCenterOfMass(dim, t)[1] - y) < 1e-6]

    gmsh.model.addPhysicalGroup(3, at(3, 0.25), 1)
    gmsh.model.addPhysicalGroup(3, at(3, 0.75), 2)
    gmsh.model.addPhysicalGroup(2, at(2, 0.0), 11)
    gmsh.model.addPhysicalGroup(2, at(2, 1.0), 12)
    gmsh.model.addPhysicalGroup(2, at(2, 0.5), 21)
    gmsh.model.addPhysicalGroup(2, at(2, 0.5), 22)
    gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
    gmsh.model.mesh.generate(3)
    path = tmp_path / "fused.msh"
    gmsh.write(str(path))
    gmsh.model.remove()
    if started:
        gmsh.finalize()
    return path.as_posix()


def test_bodies_meshed_together_are_named(tmp_path, capsys):
    """Issue 31, item 8: a contact between volumes that share nodes used to fail with the symptom
    ("no facet is tagged 22": both surface tags sat on the same interior facets, one was lost);
    now the cells' tags and the number of common nodes are named."""
    from dolfinx_nnqem import compat

    msh = _fused_blocks_msh(tmp_path)
    path = tmp_path / "p.toml"
    path.write_text(GOOD.replace(MESH, msh))
    code = main(["-q", "run", str(path), "--check"])
    err = capsys.readouterr().err.strip()
    mesh, cell_tags, facet_tags = compat.read_from_msh(msh, MPI.COMM_WORLD, 0, gdim=3)
    with pytest.raises(ValueError) as error:
        ContactProblem(mesh, cell_tags, facet_tags, materials={1: M, 2: M}, dirichlet=[Dirichlet(11), Dirichlet(12)],
                       contact=Contact(21, 22, mu_f=0.3))
    print(f"\n  exit {code}: {err}\n  API: {error.value}")
    assert code == EXIT_BAD_INPUT and "the cells tagged 1 and 2 share" in err and "no facet is tagged" not in err
    assert "the cells tagged 1 and 2 share" in str(error.value)


def test_effective_modulus_needs_both_or_neither():
    """E2 without nu2 is refused by name (it failed on None ** 2; found by the type checker)."""
    from dolfinx_nnqem.cases.hertz import effective_modulus

    assert effective_modulus(2.0, 0.0) == 2.0  # body 2 rigid
    assert effective_modulus(2.0, 0.0, 2.0, 0.0) == 1.0
    with pytest.raises(ValueError, match="E2 is given without nu2"):
        effective_modulus(2.0, 0.3, 1.0)


def test_xdmf_grid_without_a_name(tmp_path):
    """A Grid without a Name (XDMF allows one) is left out of the grids a missing name is listed
    against: sorting None with the names raised a TypeError instead of the file's error (found by
    the type checker)."""
    from dolfinx_nnqem.problem_file import ProblemFileError, _check_xdmf

    file = tmp_path / "unnamed.xdmf"
    file.write_text('<Xdmf><Domain><Grid Name="mesh"/><Grid GridType="Collection"/></Domain></Xdmf>')
    with pytest.raises(ProblemFileError, match=r"no grid named 'tags' \(mesh.cell_tags\); the file has \['mesh'\]"):
        _check_xdmf(file, {"mesh_name": "mesh", "cell_tags": "tags", "facet_tags": "tags"})


def _file_check(tmp_path, capsys, text: str) -> tuple[int, str]:
    path = tmp_path / "p.toml"
    path.write_text(text)
    code = main(["-q", "run", str(path), "--check"])
    err = capsys.readouterr().err.strip()
    print(f"\n  exit {code}: {err}")
    return code, err


def test_both_contacts_on_one_pair_are_named_from_python(beams):
    """Issue 39, item 9: two Contacts on the same surfaces, in either order, are refused with both
    names (they used to be accepted, and the solvers stalled)."""
    for first, second in ((Contact(21, 22, mu_f=0.3, name="upper"), Contact(21, 22, mu_f=0.3, name="lower")),
                          (Contact(21, 22, mu_f=0.3), Contact(22, 21, mu_f=0.1))):
        with pytest.raises(ValueError) as error:
            _api(beams, contact=[first, second])
        print(f"\n  {error.value}")
        assert f"{first.label!r} and {second.label!r} both join the facet tags 21 and 22" in str(error.value)


@pytest.mark.parametrize("key, value", [("mesh_name", '"mesh"'), ("cell_tags", '"cell_tags"'),
                                        ("facet_tags", '"tags"')])
def test_xdmf_keys_on_a_gmsh_mesh_are_refused(tmp_path, capsys, key, value):
    """Issue 39, item 9: mesh_name (and the other grid names) on a .msh mesh were ignored."""
    code, err = _file_check(tmp_path, capsys, GOOD.replace(f'file = "{MESH}"', f'file = "{MESH}"\n{key} = {value}'))
    assert code == EXIT_BAD_INPUT and f"mesh.{key} = {value.replace(chr(34), chr(39))}" in err and "XDMF" in err


@pytest.mark.parametrize("stops, words", [("[0.7, 0.5]", "increasing"), ("[0.5, 0.5]", "increasing"),
                                          ("[0.0]", "(0, 1]"), ("0.5", "expected a list")])
def test_load_factors_off_the_path_are_refused(tmp_path, capsys, stops, words):
    """Issue 39, item 9: [solver.auto] load_factors are stops on the path from 0 to 1, increasing."""
    text = GOOD.replace("increments = 2", f'increments = "auto"\n[solver.auto]\nload_factors = {stops}')
    code, err = _file_check(tmp_path, capsys, text)
    assert code == EXIT_BAD_INPUT and "solver].auto.load_factors" in err and words in err


def test_load_factors_on_the_path_are_honoured(tmp_path, capsys):
    from dolfinx_nnqem.problem_file import load_problem_file

    path = tmp_path / "p.toml"
    path.write_text(GOOD.replace("increments = 2", 'increments = "auto"\n[solver.auto]\nload_factors = [0.25, 1.0]'))
    assert load_problem_file(path).solver["increments"].load_factors == (0.25, 1.0)


def test_an_infinite_yield_stress_is_an_elastic_material(tmp_path, capsys):
    """Issue 39, item 9: sigma_y0 = inf (TOML's infinity; docs/problem-file.md: "∞ (elastic)") was
    refused as "expected a finite number"; -inf and nan still are."""
    from dolfinx_nnqem.problem_file import load_problem_file

    text = GOOD.replace("nu = 0.3", "nu = 0.3\nsigma_y0 = inf", 1)
    path = tmp_path / "p.toml"
    path.write_text(text)
    assert load_problem_file(path).materials[1].sigma_y0 == math.inf
    assert main(["-q", "run", str(path), "--check"]) == EXIT_OK
    for value in ("-inf", "nan"):
        code, err = _file_check(tmp_path, capsys, GOOD.replace("nu = 0.3", f"nu = 0.3\nsigma_y0 = {value}", 1))
        assert code == EXIT_BAD_INPUT and f"sigma_y0 = {value}" in err


@pytest.mark.parametrize("edit", [
    ("tag = 12", 'tag = 12\nvalue = 0.001\ncomponents = [0]\namplitude = [[0.0, 0.0], [1.0, "x"]]'),
    ("[solver]", '[gravity]\ng = [0.0, -9.81, 0.0]\namplitude = [[0.0, 0.0], [1.0, 1e300]]\n[solver]'),
    ("[solver]", "[[contact]]\nsurface2 = 13\nmu_f = 0.0\n[contact.obstacle]\ntype = \"plane\"\n"
                 "point = [0.0, 0.8, 0.0]\nnormal = [0.0, -1.0, 0.0]\nmotion = [[0.0, 0, 0, 0], [1.0, 0, \"x\", 0]]"
                 "\n[solver]"),
])
def test_amplitude_errors_name_the_file_once(tmp_path, capsys, edit):
    """Issue 39, item 12: an amplitude row's error repeated the file and the key inside the key
    ("p.toml: dirichlet[1]./…/p.toml: dirichlet[1].amplitude[1] = 'x'")."""
    text = GOOD.replace(*edit, 1)
    if "[[contact]]" in edit[1]:  # an obstacle table next to the [contact] table: all as [[contact]]
        text = text.replace("[contact]\nsurface1", "[[contact]]\nsurface1")
    code, err = _file_check(tmp_path, capsys, text)
    assert code == EXIT_BAD_INPUT and err.count("p.toml") == 1
    assert re.search(r"(amplitude|motion)\[1\] = ('x'|1e\+300)", err)


def test_numpy_values_are_shown_as_numbers():
    """Issue 39, item 12: a message printed "np.float64(nan)" (numpy 2's repr) for a numpy input."""
    from dolfinx_nnqem.contact.obstacles import Plane, Sphere
    from dolfinx_nnqem.solvers.options import MonolithicOptions

    nan = np.float64("nan")
    calls = [lambda: SolverOptions(rtol=nan), lambda: SolverOptions(atol=nan),
             lambda: SolverOptions(max_iterations=np.int64(0)), lambda: Contact(21, 22, mu_f=nan),
             lambda: Contact(21, 22, mu_f=0.3, r=nan), lambda: Plane(point=(0.0, 0.0, nan), normal=(0.0, 1.0, 0.0)),
             lambda: Sphere(centre=(0.0, 0.0, 0.0), radius=nan), lambda: AutomaticIncrements(initial_step=nan),
             lambda: MonolithicOptions(auto_iterative_dofs=np.int64(-1))]
    for call in calls:
        with pytest.raises((ValueError, TypeError)) as error:
            call()
        print(f"\n  {error.value}", end="")
        assert "np." not in str(error.value) and ("nan" in str(error.value) or "= 0" in str(error.value)
                                                 or "= -1" in str(error.value))


def test_conditions_that_agree_on_shared_dofs_are_accepted(beams):
    """A clamp and a zero displacement meeting on the same dofs, and one value given twice with the
    same amplitude, prescribe each dof one displacement: accepted."""
    from dolfinx_nnqem.problem import PiecewiseLinear

    ramp = lambda load_factor: load_factor  # noqa: E731  (one amplitude object for both entries)
    problem = _api(beams, dirichlet=[Dirichlet(11), Dirichlet(11, 0.0, [2]), Dirichlet(12),
                                     Dirichlet(12, 0.0, [1], amplitude=ramp)])
    assert problem.supports.dofs.size > 0
    # the same value with two equal tables (two entries of a problem file each get their own object)
    table = [[0.0, 0.0], [1.0, 2.0]]
    problem = _api(beams, dirichlet=[Dirichlet(11), Dirichlet(12, 1e-3, [1], PiecewiseLinear(table)),
                                     Dirichlet(12, 1e-3, [1], PiecewiseLinear([list(row) for row in table]))])
    assert problem.supports.dofs.size > 0


def test_a_new_value_in_conflict_is_refused_by_update(beams):
    """``revalued`` (what ``problem.update`` uses) checks the new values as the build does."""
    problem = _api(beams, dirichlet=[Dirichlet(11), Dirichlet(12), Dirichlet(12, 0.0, [1])])
    with pytest.raises(ValueError, match="prescribe different displacements to the same dof"):
        problem.supports.revalued([Dirichlet(11), Dirichlet(12), Dirichlet(12, 0.002, [1])])
