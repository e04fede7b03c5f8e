"""The package's architecture and contracts, checked at run time (the type checker checks the
same statically: ``dolfinx_nnqem/solvers/conformance.py``, run by ``.ci/run``).

* every solver, pair set, material and the problem satisfy their Protocols;
* the layers: no import circle, at most 15 modules at the package root, no solver imports another,
  and the lower layers import nothing from the upper ones;
* old module paths, names and ContactModel members of release 0.1 still import (or read), as the same
  objects, with a DeprecationWarning;
* wrong argument types end in a TypeError that names the argument;
* solvers free their PETSc objects as context managers;
* every ``type: ignore`` of the package names its error code and says why.
"""

from __future__ import annotations

import ast
import importlib
import operator
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import box_with_face_tags
from mpi4py import MPI

import dolfinx_nnqem
from dolfinx_nnqem import _moved
from dolfinx_nnqem.contact.obstacles import Plane
from dolfinx_nnqem.contact.pairset import PairSet
from dolfinx_nnqem.material import Material, MaterialState, PointwisePlasticity, VonMises
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure
from dolfinx_nnqem.cases.geometries import StackedBlocksTags as T
from dolfinx_nnqem.cases.geometries import build_stacked_blocks
from dolfinx_nnqem.solvers import (METHODS, MonolithicOptions, NNEQM1Options, NNEQM2Options, SolverOptions,
                                   make_solver)
from dolfinx_nnqem.solvers import conformance
from dolfinx_nnqem.solvers.contract import CondensingSolver, SolvableProblem, Solver

PACKAGE = Path(dolfinx_nnqem.__file__).parent
STEEL = VonMises(E=2.0e10, nu=0.2, sigma_y0=2.0e7, H=2.0e9)


def blocks(discretisation: str = "node-to-node") -> ContactProblem:
    mesh, ct, ft = build_stacked_blocks(MPI.COMM_WORLD, 1.0, 0.5, 0.5, 1.0, 2, 1, 1, 2)
    return ContactProblem(mesh, ct, ft, materials={T.BODY1: STEEL, T.BODY2: STEEL},
                          dirichlet=[Dirichlet(T.BOTTOM), Dirichlet(T.TOP)], tractions=[Pressure(T.TOP, 1e6)],
                          contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=0.3, discretisation=discretisation))


# -- contracts ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_every_solver_satisfies_the_solver_contract(method):
    problem = blocks()
    assert isinstance(conformance.as_problem(problem), SolvableProblem)
    with make_solver(method, problem) as solver:
        assert isinstance(conformance.as_solver(solver), Solver)
        report = solver.solve_increment(0.5)
        assert report.converged and isinstance(solver.timings, dict)
        if method == "nneqm1":  # what the FCLIB export reads of it (issue 42: declared, not duck-typed)
            assert isinstance(conformance.as_condensing_solver(solver), CondensingSolver)
            assert solver.last_condensed is not None


@pytest.mark.parametrize("discretisation", ["node-to-node", "node-to-surface", "mortar", "obstacle"])
def test_every_pair_set_satisfies_the_pair_set_contract(discretisation):
    if discretisation == "obstacle":
        mesh, ft = box_with_face_tags((2, 2, 2))
        problem = ContactProblem(mesh, None, ft, materials=STEEL, dirichlet=[Dirichlet(3)],
                                 contact=Contact(Plane(point=(0, 1, 0), normal=(0, -1, 0)), 4, mu_f=0.0))
    else:
        problem = blocks(discretisation)
    pairs = problem.contact.interfaces[0].pairs
    assert isinstance(conformance.as_pair_set(pairs), PairSet)
    print(f"\n  {discretisation}: {type(pairs).__name__}, {pairs.describe()}")


def test_the_material_satisfies_the_material_contracts():
    problem = blocks()
    assert isinstance(conformance.as_material(STEEL), Material)
    assert isinstance(conformance.as_material_state(problem.state), MaterialState)
    points = conformance.as_pointwise_plasticity(problem.state.at_points())
    assert isinstance(points, PointwisePlasticity)
    # the pointwise return map is the UFL one's (the consistent tangent's derivative included)
    rng = np.random.default_rng(1)
    t = rng.standard_normal((points.mu.size, 5)) * 3.0 * STEEL.sigma_y0
    eps_p, dp = points.plastic_strain(t, {"p": np.zeros(points.mu.size)})
    assert np.all(dp > 0.0) and np.allclose(np.linalg.norm(eps_p, axis=1), np.sqrt(1.5) * dp)


# -- layers ---------------------------------------------------------------------------------------------
def _imports() -> dict[str, set[str]]:
    """Module -> the package modules it imports (module level and inside functions)."""
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        name = ".".join(("dolfinx_nnqem", *path.relative_to(PACKAGE).with_suffix("").parts))
        modules[name.removesuffix(".__init__")] = path
    edges: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text())):
            targets = []
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("dolfinx_nnqem"):
                targets = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names if a.name.startswith("dolfinx_nnqem")]
            edges[name] |= {t for t in targets if t in modules and t != name}
    return edges


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in edges:
        if v not in index:
            visit(v)
    return out


LAYERS = ["numerics", "material", "contact", "problem", "solvers", "io", "estimates", "cases"]
"""Lower to upper; a subpackage imports only from its own layer and those before it (the root's
ground modules compat, jit, collective, chatter, interrupts, names from anywhere; the front end cli and problem_file
from nowhere in the package but each other)."""


def test_the_layers_have_no_circle_and_import_only_downwards():
    edges = _imports()
    assert _cycles(edges) == [], "import circles"
    root = [p for p in PACKAGE.glob("*.py")]
    print(f"\n  {len(edges)} modules, {len(root)} at the root: {sorted(p.stem for p in root)}")
    assert len(root) <= 15
    upward = []
    for module, targets in edges.items():
        parts = module.split(".")
        if len(parts) < 3 or parts[1] not in LAYERS:
            continue
        for target in targets:
            tparts = target.split(".")
            if len(tparts) >= 2 and tparts[1] in ("cli", "problem_file"):
                upward.append((module, target))
            if len(tparts) >= 3 and tparts[1] in LAYERS and LAYERS.index(tparts[1]) > LAYERS.index(parts[1]):
                upward.append((module, target))
    assert upward == [], upward
    solvers = {f"dolfinx_nnqem.solvers.{m}" for m in ("monolithic", "nneqm1", "nneqm2")}
    for solver in solvers:
        assert not (edges[solver] & (solvers - {solver})), f"{solver} imports another solver"


CONTACT_INTERNALS = {"groups", "force_unit", "trackers", "_trackers"}
"""Attributes of the contact layer's insides: the law groups of the pair laws and the geometry
trackers. Solvers read the contact scale (``ContactModel.r_max``, ``PairLaws.r_max``) and the
geometry through ``ContactModel.geometry`` instead (issue 42)."""


def test_no_module_outside_contact_reads_the_law_groups_or_the_trackers():
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.relative_to(PACKAGE).parts[0] == "contact":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Attribute) and node.attr in CONTACT_INTERNALS:
                found.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: .{node.attr}")
    print(f"\n  reads of the contact layer's insides outside contact/: {found}")
    assert found == [], found


MATERIAL_DOOR = {"dolfinx_nnqem.material.interface", "dolfinx_nnqem.material.kinematics",
                 "dolfinx_nnqem.material.state", "dolfinx_nnqem.material.finite_strain.gauss_state",
                 "dolfinx_nnqem.material.conformance"}
"""What the package outside ``material/`` may import of it: the interface, the kinematics, the
mesh-wide states (small strain, and finite strain: issue 41), and the type checker's conformance functions."""
FRONT_END = ("dolfinx_nnqem.cli", "dolfinx_nnqem.problem_file", "dolfinx_nnqem.cases")


def _material_imports_outside_the_door() -> list[str]:
    """Imports of a concrete material (a module of material/ outside :data:`MATERIAL_DOOR`, or a name
    of the package defined in one) by modules outside material/ and the front end."""
    package = importlib.import_module("dolfinx_nnqem.material")
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        module = ".".join(("dolfinx_nnqem", *path.relative_to(PACKAGE).with_suffix("").parts)).removesuffix(".__init__")
        if module.startswith(("dolfinx_nnqem.material",) + FRONT_END):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            targets = []
            if isinstance(node, ast.ImportFrom) and node.module == "dolfinx_nnqem.material":
                targets = [getattr(package, a.name).__module__ if hasattr(getattr(package, a.name), "__module__")
                           else f"dolfinx_nnqem.material.{a.name}" for a in node.names]
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("dolfinx_nnqem.material."):
                targets = [node.module]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names if a.name.startswith("dolfinx_nnqem.material.")]
            found += [f"{module} imports {t}" for t in targets if t not in MATERIAL_DOOR]
    return found


def test_no_module_outside_material_imports_a_concrete_material():
    """The material interface is the only door: solvers, checks, stepping, IO and the problem
    layer reach materials through material.interface / kinematics / state (issue 40)."""
    found = _material_imports_outside_the_door()
    print(f"\n  imports of a concrete material outside material/, the front end and cases/: {found}")
    assert found == [], found


def test_every_type_ignore_names_its_code_and_why():
    """An ignore silences one error code where a third-party stub is wrong or missing, and a comment
    after it says why (mypy, run by .ci/run, checks the code: ignore-without-code; not the reason)."""
    ignore = re.compile(r"#\s*type:\s*ignore(\[[a-z, -]+\])?(.*)$")
    unexplained = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            found = ignore.search(line)
            if found and not (found.group(1) and found.group(2).strip().lstrip("#").strip()):
                unexplained.append(f"{path.relative_to(PACKAGE)}:{number}: {line.strip()}")
    assert unexplained == [], "\n".join(unexplained)


# -- old paths ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("old", sorted(_moved.MOVED))
def test_an_old_module_path_imports_the_same_module_with_a_warning(old):
    new = importlib.import_module(f"dolfinx_nnqem.{_moved.MOVED[old]}")
    with pytest.warns(DeprecationWarning, match=f"dolfinx_nnqem.{old} is deprecated.*{_moved.MOVED[old]}"):
        module = importlib.import_module(f"dolfinx_nnqem.{old}")
    assert module is new and module.__spec__.name == new.__name__


MOVED_NAMES = [(module, name) for module, names in sorted(_moved.MOVED_NAMES.items()) for name in sorted(names)]


@pytest.mark.parametrize("module, name", MOVED_NAMES)
def test_a_moved_name_imports_from_its_old_module_with_a_warning(module, name):
    """contact/model.py split by idea (issue 42): its old names import from it, as the same objects,
    with a DeprecationWarning naming the new path."""
    new = _moved.MOVED_NAMES[module][name]
    old_module = importlib.import_module(f"dolfinx_nnqem.{module}")
    with pytest.warns(DeprecationWarning, match=f"dolfinx_nnqem.{module}.{name} is deprecated.*dolfinx_nnqem.{new}"):
        old = getattr(old_module, name)
    assert old is getattr(importlib.import_module(f"dolfinx_nnqem.{new}"), name)
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        getattr(old_module, "no_such_name")


MOVED_MEMBERS = [(owner, old, new) for owner, members in sorted(_moved.MOVED_MEMBERS.items())
                 for old, new in sorted(members.items())]


@pytest.fixture(scope="module")
def sliding_contact():
    """A contact model in the current geometry (its trackers made), for the moved members."""
    from dolfinx_nnqem.cases.large_sliding import sliding_blocks
    return sliding_blocks(slide=0.4).contact


@pytest.mark.parametrize("owner, old, new", MOVED_MEMBERS)
def test_a_moved_member_reads_its_new_path_with_a_warning(sliding_contact, owner, old, new):
    """ContactModel's geometry moved to ContactModel.geometry (issue 42): its old members still read,
    as the new ones, with a DeprecationWarning naming the new path."""
    assert owner == "contact.model.ContactModel"
    name = old.removesuffix("()")
    with pytest.warns(DeprecationWarning, match=rf"ContactModel\.{name} is deprecated.*ContactModel\.{new} instead"):
        member = getattr(sliding_contact, name)
    value = member() if old.endswith("()") else member  # a method whose value is now an attribute
    assert value == operator.attrgetter(new)(sliding_contact)


def test_the_public_names_of_the_user_guide_import_from_their_packages():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        from dolfinx_nnqem.io import ResultsWriter  # noqa: F401
        from dolfinx_nnqem.material import VonMises  # noqa: F401
        from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Gravity, Traction  # noqa: F401
        from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps  # noqa: F401


# -- arguments --------------------------------------------------------------------------------------------
def test_wrong_argument_types_name_the_argument():
    problem = blocks()
    with pytest.raises(TypeError, match=r"options must be a SolverOptions.*monolithic=MonolithicOptions"):
        make_solver("monolithic", problem, MonolithicOptions())
    with pytest.raises(TypeError, match=r"nneqm1= must be a NNEQM1Options, got NNEQM2Options.*nneqm2="):
        make_solver("nneqm1", problem, nneqm1=NNEQM2Options())
    with pytest.raises(TypeError, match="problem must be a ContactProblem"):
        make_solver("nneqm2", "problem.toml")
    with pytest.raises(TypeError, match="method"):
        make_solver(NNEQM1Options(), problem)
    with pytest.raises(ValueError, match="belong to another method"):
        make_solver("monolithic", problem, SolverOptions(), nneqm2=NNEQM2Options())


# -- PETSc lifetime ---------------------------------------------------------------------------------------
def test_a_solver_as_a_context_manager_frees_its_petsc_objects():
    problem = blocks()
    with make_solver("nneqm1", problem) as solver:
        solver.solve_increment(0.5)
        ksp = solver.condensation.ksp
        assert ksp.handle != 0
    assert ksp.handle == 0  # destroyed on leaving the block
