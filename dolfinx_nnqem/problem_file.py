"""Problem files (TOML) for ``dolfinx-nnqem run PROBLEM.toml``.

A problem file names a mesh with physical tags and everything :class:`ContactProblem` takes::

    [mesh]
    file = "../meshes/two_beams.msh"      # gmsh .msh, or .xdmf (see below); relative to this file
    # degree = 2                          # the displacement's degree; default: the mesh's (2 for a
                                          # second-order mesh: 10-node tetrahedra, 27-node hexahedra)
    # quadrature_degree = 2               # the Gauss rule's degree; default 2 × degree
    # kinematics = "finite"               # "small" (default: ε = sym grad u) or "finite" (total
                                          # Lagrangian, F = I + grad u; not with NNEQM2)

    [materials.1]                         # cell tag → material
    # model = "von-mises"                 # or "elastic" (E, nu, density only), "neo-hooke" (E, nu,
                                          # density; kinematics = "finite" only), "drucker-prager"
    E = 2.0e10
    nu = 0.17
    sigma_y0 = 5.0e5                      # inf, or omit it, for an elastic material
    H = 2.0e10
    density = 2400.0
    # hardening = "voce"                  # "linear" (default: sigma_y0, H), "voce" (sigma_y0, Q, b, H)
    # Q = 1.0e5                           # or "table": table = [[sigma_y, p], ...] (CalculiX order)
    # b = 50.0

    [[contact]]                           # one table per interface ([contact] for a single one)
    surface1 = 21                         # facet tags: master (body 1) and slave (body 2) sides
    surface2 = 22
    mu_f = 0.5
    law = "alart-curnier"                 # or "polar"
    name = "beams"                        # optional: how tables and logs name it
    discretisation = "auto"               # or "node-to-node", "node-to-surface", "mortar"
                                          # (auto: node-to-node if the nodes coincide, else mortar)
    # slave = 22                          # optional: the slave side (default: surface2 for
                                          # node-to-node, the finer side otherwise)
    # geometry = "auto"                  # or "reference", "current": auto re-evaluates the pairs at
                                          # X + u once the surfaces slide 0.25 facet sizes (large
                                          # sliding; node-to-surface, mortar and obstacles only)

    [[contact]]                           # a rigid obstacle as the master side
    surface2 = 5
    mu_f = 0.2
    [contact.obstacle]
    type = "sphere"                       # "plane" (point, normal), "sphere" (centre, radius),
    centre = [0.0, 1.2, 0.0]              # "cylinder" (point, axis, radius)
    radius = 0.2
    motion = [[0.0, 0, 0, 0], [0.5, 0, -1e-3, 0], [1.0, 2e-3, -1e-3, 0]]   # d(ℓ): rows [ℓ, dx, dy, dz]
                                          # or motion = [dx, dy, dz] (times ℓ, or an amplitude)

    [[dirichlet]]
    tag = 11                              # u = 0 (all components) on facets tagged 11
    [[dirichlet]]
    tag = 31
    value = 0.001                         # u_x = ℓ · 1 mm ...
    components = [0]
    amplitude = [[0.0, 0.0], [0.5, 0.0], [1.0, 1.0]]   # ... or a(ℓ) · 1 mm: rows [ℓ, a], linear between

    [[traction]]
    tag = 13
    value = [1.0e5, -1.0e5, 0.5e5]        # Pa
    [[pressure]]
    tag = 5
    p = 1.0e6
    [[body_force]]
    value = [0.0, -1.0e4, 0.0]            # N/m³
    cell_tag = 2                          # optional
    [gravity]
    g = [0.0, -9.81, 0.0]                 # uses each material's density

    [solver]
    method = "monolithic"                 # "nneqm1", "nneqm2"
    increments = 15                       # or "auto": automatic incrementation, see [solver.auto]
    max_cutbacks = 5
    rtol = 1e-10
    max_iterations = 50
    linear_solver = "direct"              # monolithic: "iterative" (GAMG), "auto" (by size)
    [solver.petsc_options]
    pc_factor_mat_solver_type = "mumps"
    [solver.auto]                         # only with increments = "auto"; every key optional
    initial_step = 0.1                    # fractions of the load path
    max_step = 0.25
    load_factors = [0.5, 1.0]             # load factors every run stops at (output points)

    [checks]                              # the independent check of every converged state
    rtol = 1e-6                           # default: from [solver].rtol (1e-6 for rtol = 1e-10)
    max_strain = 0.1                      # small-strain limits (false: no limit)
    max_rotation = 0.1

    [output]
    folder = "results/my_run"             # relative to the current directory; not empty
    fields = true
    pictures = true                       # PNG pictures in folder/pictures at the end of the run
    checkpoint_every = 1                  # a restart checkpoint every N increments (0: none)
    [output.probes]
    "tip" = [2.0, 0.0, 0.0]

    [estimate]                            # discretisation-error estimates (off by default)
    enabled = true                        # value ± estimate of every contact resultant, reaction,
                                          # probe displacement and the largest plastic strain
    enrichment = "auto"                   # "degree-2", "refine" (tetrahedra): the enriched solve
    target_error = 0.01                   # adaptive refinement until every estimate is <= 1 %
                                          # (tetrahedra only; implies enabled)
    max_cycles = 6
    refine_fraction = 0.5                 # Dörfler: refine the cells holding 50 % of sum eta_K^2
    quantities = ["u", "contact"]         # what target_error applies to (default: all)

Every load ([[traction]], [[pressure]], [[body_force]], [gravity]) and [[dirichlet]] entry takes
an optional ``amplitude`` table like the one above (default a(ℓ) = ℓ).
An XDMF mesh takes ``file = "mesh.xdmf"``, ``mesh_name = "mesh"``, ``cell_tags = "cell_tags"``
and ``facet_tags = "facet_tags"`` (the names of the grids in the file; a gmsh file takes none of them).
Every key is checked: an unknown or malformed one raises :class:`ProblemFileError` naming it.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Set
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from dolfinx_nnqem.contact.obstacles import OBSTACLES, obstacle_parameters
from dolfinx_nnqem.names import LAW_ALIASES, LAW_NAMES, METHODS

if TYPE_CHECKING:  # the command line imports this module (and so MPI and DOLFINx) once it has read its arguments
    import dolfinx.mesh
    from mpi4py import MPI

    from dolfinx_nnqem.problem.contact_problem import ContactProblem
    from dolfinx_nnqem.solvers.checks import CheckOptions
    from dolfinx_nnqem.solvers.options import MonolithicOptions, SolverOptions

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib


class ProblemFileError(ValueError):
    """A problem file is malformed or inconsistent; the message names the key."""


OBSTACLE_KEYS = {kind: obstacle_parameters(kind) for kind in OBSTACLES}
KEYS: dict[str, frozenset[str]] = {
    "mesh": frozenset({"file", "mesh_name", "cell_tags", "facet_tags", "degree", "quadrature_degree",
                       "kinematics"}),
    "materials.TAG": frozenset({"model", "E", "nu", "sigma_y0", "H", "density", "hardening", "Q", "b", "table",
                                "kinematic", "cohesion", "friction_angle", "dilatancy_angle", "match"}),
    "contact": frozenset({"surface1", "surface2", "obstacle", "mu_f", "law", "r", "tolerance", "search_distance",
                          "name", "discretisation", "slave", "geometry"}),
    "contact.obstacle": frozenset({"type", "motion", "amplitude"}.union(*OBSTACLE_KEYS.values())),
    "dirichlet": frozenset({"tag", "value", "components", "amplitude"}),
    "traction": frozenset({"tag", "value", "amplitude"}),
    "pressure": frozenset({"tag", "p", "amplitude"}),
    "body_force": frozenset({"value", "cell_tag", "amplitude"}),
    "gravity": frozenset({"g", "amplitude"}),
    "solver": frozenset({"method", "increments", "auto", "max_cutbacks", "rtol", "atol", "max_iterations",
                         "linear_solver", "petsc_options"}),
    "solver.auto": frozenset({"initial_step", "max_step", "min_step", "easy_iterations", "hard_iterations", "grow",
                              "shrink", "load_factors"}),
    "checks": frozenset({"rtol", "max_strain", "max_rotation", "min_shape_ratio"}),
    "output": frozenset({"folder", "fields", "pictures", "probes", "checkpoint_every"}),
    "estimate": frozenset({"enabled", "enrichment", "target_error", "max_cycles", "refine_fraction", "quantities"}),
}
"""Every key a problem file may hold, by section (the one list the checks below use;
``docs/problem-file.md`` documents each, and ``tests/unit/test_problem_file_doc.py`` compares the two)."""
SECTIONS = {section.split(".")[0] for section in KEYS}
XDMF_KEYS = frozenset({"mesh_name", "cell_tags", "facet_tags"})
"""The [mesh] keys that name the grids of an XDMF file (refused with a gmsh .msh file)."""

@dataclass
class ProblemSpec:
    """The checked content of a problem file (paths resolved)."""

    path: Path
    mesh: dict
    materials: dict
    contact: list
    dirichlet: list
    traction: list
    pressure: list
    body_force: list
    gravity: dict | None
    solver: dict
    output: dict = field(default_factory=dict)
    checks: dict = field(default_factory=dict)
    estimate: dict = field(default_factory=dict)


def load_problem_file(path: str | Path) -> ProblemSpec:
    """Read and check a problem file; raises :class:`ProblemFileError` on the first problem."""
    path = Path(path)
    if not path.is_file():
        raise ProblemFileError(f"{path}: no such file")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as error:
        raise ProblemFileError(f"{path}: not valid TOML: {error}") from None
    unknown = sorted(set(data) - SECTIONS)
    if unknown:
        raise ProblemFileError(f"{path}: unknown section(s) {unknown}; expected some of {sorted(SECTIONS)}")
    where = str(path)
    mesh = _mesh_section(_table(data, "mesh", where, required=True), path.parent, where)
    materials = _materials_section(_table(data, "materials", where, required=True), where)
    contact = _contact_tables(data.get("contact"), where)
    dirichlet = [_dirichlet_entry(e, f"{where}: dirichlet[{i}]") for i, e in enumerate(_array(data, "dirichlet", where))]
    traction = [_traction_entry(e, f"{where}: traction[{i}]") for i, e in enumerate(_array(data, "traction", where))]
    pressure = [_pressure_entry(e, f"{where}: pressure[{i}]") for i, e in enumerate(_array(data, "pressure", where))]
    body_force = [_body_force_entry(e, f"{where}: body_force[{i}]")
                  for i, e in enumerate(_array(data, "body_force", where))]
    gravity = data.get("gravity")
    if gravity is not None:
        gravity = _checked_keys(gravity, KEYS["gravity"], {"g"}, f"{where}: [gravity]")
        gravity["g"] = _vector(gravity["g"], f"{where}: gravity.g")
        _amplitude_entry(gravity, f"{where}: gravity")
    solver = _solver_section(data.get("solver", {}), where)
    output = _output_section(data.get("output", {}), where)
    checks = _checks_section(data.get("checks", {}), where)
    estimate = _estimate_section(_table(data, "estimate", where), where)
    if not dirichlet:
        raise ProblemFileError(f"{where}: no [[dirichlet]] entry; a quasi-static problem needs supports")
    if solver["method"] != "monolithic" and not contact:
        raise ProblemFileError(f"{where}: solver.method = {solver['method']!r} needs a [contact] section")
    return ProblemSpec(path, mesh, materials, contact, dirichlet, traction, pressure, body_force,
                       gravity, solver, output, checks, estimate)


# -- sections ---------------------------------------------------------------------------------
def _table(data: dict, key: str, where: str, required: bool = False) -> dict:
    if key not in data:
        if required:
            raise ProblemFileError(f"{where}: missing section [{key}]")
        return {}
    if not isinstance(data[key], dict):
        raise ProblemFileError(f"{where}: [{key}] must be a table, got {type(data[key]).__name__}")
    return data[key]


def _array(data: dict, key: str, where: str) -> list:
    value = data.get(key, [])
    if not isinstance(value, list) or not all(isinstance(e, dict) for e in value):
        raise ProblemFileError(f"{where}: {key} must be an array of tables ([[{key}]] entries)")
    return value


def _checked_keys(table: dict, allowed: Set[str], required: Set[str], where: str) -> dict:
    if not isinstance(table, dict):
        raise ProblemFileError(f"{where}: must be a table")
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise ProblemFileError(f"{where}: unknown key(s) {unknown}; allowed: {sorted(allowed)}")
    missing = sorted(required - set(table))
    if missing:
        raise ProblemFileError(f"{where}: missing key(s) {missing}")
    return dict(table)


def _number(value, where: str, *, positive=False, nonnegative=False, integer=False, high=None,
            physical=False) -> float:
    """A checked number; ``physical``: a dimensional input, within ±MAX_MAGNITUDE (the supported
    range of docs/reliability.md)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ProblemFileError(f"{where} = {value!r}: expected a number")
    if integer and not isinstance(value, int):
        raise ProblemFileError(f"{where} = {value!r}: expected an integer")
    if not math.isfinite(value):
        raise ProblemFileError(f"{where} = {value!r}: expected a finite number")
    if positive and value <= 0:
        raise ProblemFileError(f"{where} = {value!r}: expected a value > 0")
    if nonnegative and value < 0:
        raise ProblemFileError(f"{where} = {value!r}: expected a value >= 0")
    if high is not None and value > high:
        raise ProblemFileError(f"{where} = {value!r}: expected a value <= {high:g}")
    if physical:
        from dolfinx_nnqem.numerics.ranges import MAX_MAGNITUDE

        if abs(value) > MAX_MAGNITUDE:
            raise ProblemFileError(f"{where} = {value!r}: beyond the supported magnitude {MAX_MAGNITUDE:g} "
                                   "(docs/reliability.md, 'Supported ranges')")
    return value


def _tag(value, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ProblemFileError(f"{where} = {value!r}: expected a non-negative integer tag")
    return value


def _vector(value, where: str, length: int = 3) -> list:
    if not isinstance(value, list) or len(value) != length:
        raise ProblemFileError(f"{where} = {value!r}: expected a list of {length} numbers")
    return [_number(v, f"{where}[{i}]", physical=True) for i, v in enumerate(value)]


def _mesh_section(mesh: dict, folder: Path, where: str) -> dict:
    mesh = _checked_keys(mesh, KEYS["mesh"], {"file"}, f"{where}: [mesh]")
    file = folder / mesh["file"]
    if not file.is_file():
        raise ProblemFileError(f"{where}: mesh.file = {mesh['file']!r}: no such file ({file})")
    if file.suffix not in (".msh", ".xdmf"):
        raise ProblemFileError(f"{where}: mesh.file = {mesh['file']!r}: expected a gmsh .msh or an .xdmf file")
    xdmf_only = sorted(XDMF_KEYS & set(mesh))
    if file.suffix == ".msh" and xdmf_only:
        key = xdmf_only[0]
        raise ProblemFileError(f"{where}: mesh.{key} = {mesh[key]!r} names a grid of an XDMF file; the gmsh file "
                               f"{mesh['file']!r} has none (its physical groups are the tags): remove the key")
    mesh["file"] = file
    mesh.setdefault("mesh_name", "mesh")
    mesh.setdefault("cell_tags", "cell_tags")
    mesh.setdefault("facet_tags", "facet_tags")
    if "degree" in mesh:
        mesh["degree"] = int(_number(mesh["degree"], f"{where}: mesh.degree", integer=True))
        if mesh["degree"] not in (1, 2):
            raise ProblemFileError(f"{where}: mesh.degree = {mesh['degree']}: the displacement is Lagrange of "
                                   "degree 1 or 2")
    if mesh.setdefault("kinematics", "small") not in ("small", "finite"):
        raise ProblemFileError(f"{where}: mesh.kinematics = {mesh['kinematics']!r}: expected \"small\" (ε = sym grad u) "
                               "or \"finite\" (total Lagrangian, F = I + grad u)")
    if "quadrature_degree" in mesh:  # e.g. 2 with degree 2: 2 × 2 × 2 Gauss points (no locking)
        mesh["quadrature_degree"] = int(_number(mesh["quadrature_degree"], f"{where}: mesh.quadrature_degree",
                                                integer=True, positive=True, high=8))
    return mesh


def _materials_section(materials: dict, where: str) -> dict:
    from dolfinx_nnqem.material.models import material_from_table

    if not materials:
        raise ProblemFileError(f"{where}: [materials] is empty; give [materials.TAG] per cell tag")
    out = {}
    for key, params in materials.items():
        w = f"{where}: [materials.{key}]"
        try:
            tag = int(key)
        except ValueError:
            raise ProblemFileError(f"{w}: the key must be a cell tag (an integer)") from None
        params = _checked_keys(params, KEYS["materials.TAG"], {"E", "nu"}, w)
        for name, value in params.items():
            if name in ("model", "hardening", "match"):
                if not isinstance(value, str):
                    raise ProblemFileError(f"{w}.{name} = {value!r}: expected a string")
            elif name == "table":
                params[name] = _hardening_table(value, f"{w}.table")
            elif name == "kinematic":
                params[name] = _back_stresses(value, f"{w}.kinematic")
            elif name == "sigma_y0" and isinstance(value, float) and not math.isfinite(value):
                if value != math.inf:
                    raise ProblemFileError(f"{w}.sigma_y0 = {value!r}: expected a yield stress > 0, or inf for an "
                                           "elastic material")
                # TOML's inf: an elastic material, as documented
            else:
                _number(value, f"{w}.{name}")
        try:
            out[tag] = material_from_table(params)
        except ValueError as error:
            raise ProblemFileError(f"{w}: {error}") from None
    return out


def _back_stresses(value, where: str) -> list:
    """Pairs [C, gamma] of numbers (their ranges: the back-stresses check them)."""
    if not isinstance(value, list) or not value or not all(isinstance(row, list) and len(row) == 2 for row in value):
        raise ProblemFileError(f"{where} = {value!r}: expected pairs [C, gamma], e.g. [[2.0e10, 200.0], [5.0e9, 0.0]]")
    return [[_number(v, f"{where}[{i}][{j}]") for j, v in enumerate(row)] for i, row in enumerate(value)]


def _hardening_table(value, where: str) -> list:
    """Rows [sigma_y, p] of numbers (their order and ranges: the hardening law checks them)."""
    if not isinstance(value, list) or not all(isinstance(row, list) and len(row) == 2 for row in value):
        raise ProblemFileError(f"{where} = {value!r}: expected rows [sigma_y, p], e.g. [[2.5e8, 0.0], [3.0e8, 0.05]]")
    return [[_number(v, f"{where}[{i}][{j}]") for j, v in enumerate(row)] for i, row in enumerate(value)]


def _contact_tables(contact, where: str) -> list:
    """[contact] (one interface) or [[contact]] (any number): a list of checked tables."""
    if contact is None:
        return []
    tables = [contact] if isinstance(contact, dict) else contact
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise ProblemFileError(f"{where}: contact must be a table [contact] or tables [[contact]]")
    out = [_contact_section(t, f"{where}: contact[{i}]" if len(tables) > 1 else f"{where}: [contact]")
           for i, t in enumerate(tables)]
    names = [c.get("name") for c in out if c.get("name") is not None]
    if len(set(names)) != len(names):
        raise ProblemFileError(f"{where}: contact names must differ, got {names}")
    _one_table_per_pair(out, where)
    return out


def _one_table_per_pair(contacts: list, where: str) -> None:
    """Refuse two tables on the same (unordered) pair of deformable surfaces: their pairs would hold
    the same nodes twice and no equilibrium splits the force between them (the solvers stalled)."""
    seen: dict[frozenset, int] = {}
    for i, c in enumerate(contacts):
        if "surface1" not in c:
            continue  # an obstacle: several obstacles may touch one surface
        pair = frozenset((c["surface1"], c["surface2"]))
        if pair in seen:
            a, b = sorted(pair)
            raise ProblemFileError(f"{where}: {_table_name(contacts, seen[pair])} and {_table_name(contacts, i)} both "
                                   f"join the surfaces {a} and {b}; give one [[contact]] table per pair of surfaces")
        seen[pair] = i


def _table_name(contacts: list, i: int) -> str:
    """``contact[1]``, with its name if it has one: ``contact[1] ("upper")``."""
    name = contacts[i].get("name")
    return f"contact[{i}]" if name is None else f'contact[{i}] ("{name}")'



def _contact_section(contact: dict, w: str) -> dict:
    contact = _checked_keys(contact, KEYS["contact"], {"surface2", "mu_f"}, w)
    contact["surface2"] = _tag(contact["surface2"], f"{w}.surface2")
    if ("surface1" in contact) == ("obstacle" in contact):
        raise ProblemFileError(f"{w}: give either surface1 (a facet tag) or an obstacle table, not "
                               f"{'both' if 'surface1' in contact else 'neither'}")
    if "surface1" in contact:
        contact["surface1"] = _tag(contact["surface1"], f"{w}.surface1")
        if contact["surface1"] == contact["surface2"]:
            raise ProblemFileError(f"{w}: surface1 and surface2 are both tag {contact['surface1']}")
    else:
        contact["obstacle"] = _obstacle_entry(contact["obstacle"], f"{w}.obstacle")
        if "search_distance" in contact:
            raise ProblemFileError(f"{w}.search_distance: applies to node-to-node contact, not to an obstacle")
    from dolfinx_nnqem.contact.discretisation import DISCRETISATIONS, OBSTACLE_DISCRETISATIONS

    allowed = DISCRETISATIONS if "surface1" in contact else OBSTACLE_DISCRETISATIONS
    if contact.get("discretisation", "auto") not in allowed:
        raise ProblemFileError(f"{w}.discretisation = {contact['discretisation']!r}: expected one of "
                               f"{', '.join(repr(d) for d in allowed)}")
    if "slave" in contact:
        contact["slave"] = _tag(contact["slave"], f"{w}.slave")
        sides = [contact[k] for k in ("surface1", "surface2") if k in contact]
        if contact["slave"] not in sides:
            raise ProblemFileError(f"{w}.slave = {contact['slave']}: expected one of the surfaces' tags {sides}")
    contact["mu_f"] = float(_number(contact["mu_f"], f"{w}.mu_f", nonnegative=True, physical=True))
    if contact.get("law", "alart-curnier") not in (*LAW_NAMES, *LAW_ALIASES):
        raise ProblemFileError(f"{w}.law = {contact['law']!r}: expected {' or '.join(map(repr, LAW_NAMES))}")
    for key in ("r", "tolerance", "search_distance"):
        if key in contact:
            contact[key] = float(_number(contact[key], f"{w}.{key}", positive=True, physical=True))
    if "name" in contact and not isinstance(contact["name"], str):
        raise ProblemFileError(f"{w}.name = {contact['name']!r}: expected a string")
    from dolfinx_nnqem.contact.current_geometry import GEOMETRIES

    if contact.get("geometry", "auto") not in GEOMETRIES:
        raise ProblemFileError(f"{w}.geometry = {contact['geometry']!r}: expected one of {', '.join(GEOMETRIES)}")
    return contact


def _obstacle_entry(entry, where: str) -> dict:
    if not isinstance(entry, dict):
        raise ProblemFileError(f"{where}: must be a table with a type (plane, sphere or cylinder)")
    kind = entry.get("type")
    if kind not in OBSTACLE_KEYS:
        raise ProblemFileError(f"{where}.type = {kind!r}: expected one of {sorted(OBSTACLE_KEYS)}")
    common = KEYS["contact.obstacle"] - set().union(*OBSTACLE_KEYS.values())  # type, motion, amplitude
    entry = _checked_keys(entry, common | OBSTACLE_KEYS[kind], {"type"} | OBSTACLE_KEYS[kind], where)
    for key in ("point", "normal", "centre", "axis"):
        if key in entry:
            entry[key] = _vector(entry[key], f"{where}.{key}")
    if "radius" in entry:
        entry["radius"] = float(_number(entry["radius"], f"{where}.radius", positive=True, physical=True))
    motion = entry.get("motion", [0.0, 0.0, 0.0])
    if isinstance(motion, list) and motion and all(isinstance(row, list) for row in motion):
        if "amplitude" in entry:
            raise ProblemFileError(f"{where}: a motion path [[ℓ, dx, dy, dz], ...] takes no amplitude")
        entry["motion"] = _path(motion, f"{where}.motion")
    else:
        entry["motion"] = _vector(motion, f"{where}.motion")
        _amplitude_entry(entry, where)
    return entry


def _amplitude_entry(entry: dict, where: str) -> None:
    """Check an optional ``amplitude`` table in place (rows [ℓ, a])."""
    if "amplitude" not in entry:
        return
    from dolfinx_nnqem.problem.amplitude import PiecewiseLinear

    # the numbers first: their errors name the row already (a ProblemFileError is a ValueError too, and
    # caught below it repeated the file and the key)
    rows = [[float(_number(v, f"{where}.amplitude[{i}]", physical=True)) for v in row]
            for i, row in enumerate(_rows(entry["amplitude"], f"{where}.amplitude"))]
    try:
        entry["amplitude"] = PiecewiseLinear(rows)
    except ValueError as error:  # the rows' shape and order: "amplitude: ..."
        raise ProblemFileError(f"{where}.{error}") from None


def _path(rows, where: str):
    from dolfinx_nnqem.problem.amplitude import PiecewiseLinearPath

    table = [[float(_number(v, f"{where}[{i}]", physical=True)) for v in row] for i, row in enumerate(_rows(rows, where))]
    try:
        return PiecewiseLinearPath(table)
    except ValueError as error:  # the rows' shape and order: "motion path: ..."
        raise ProblemFileError(f"{where}: {error}") from None


def _rows(value, where: str) -> list:
    if not isinstance(value, list) or not value or not all(isinstance(row, list) for row in value):
        raise ProblemFileError(f"{where} = {value!r}: expected a list of rows, e.g. [[0.0, 0.0], [1.0, 1.0]]")
    return value


def _dirichlet_entry(entry: dict, where: str) -> dict:
    entry = _checked_keys(entry, KEYS["dirichlet"], {"tag"}, where)
    _amplitude_entry(entry, where)
    entry["tag"] = _tag(entry["tag"], f"{where}.tag")
    components = entry.get("components")
    if components is not None:
        if (not isinstance(components, list) or not components
                or any(c not in (0, 1, 2) or isinstance(c, bool) for c in components)):
            raise ProblemFileError(f"{where}.components = {components!r}: expected a list of 0, 1, 2")
        if len(set(components)) != len(components):
            raise ProblemFileError(f"{where}.components = {components!r}: a component is listed twice; expected "
                                   "distinct components among 0, 1, 2")
    n = 3 if components is None else len(components)
    value = entry.get("value", 0.0)
    if isinstance(value, list):
        entry["value"] = _vector(value, f"{where}.value", n)
    else:
        entry["value"] = float(_number(value, f"{where}.value", physical=True))
    return entry


def _traction_entry(entry: dict, where: str) -> dict:
    entry = _checked_keys(entry, KEYS["traction"], {"tag", "value"}, where)
    _amplitude_entry(entry, where)
    entry["tag"] = _tag(entry["tag"], f"{where}.tag")
    entry["value"] = _vector(entry["value"], f"{where}.value")
    return entry


def _pressure_entry(entry: dict, where: str) -> dict:
    entry = _checked_keys(entry, KEYS["pressure"], {"tag", "p"}, where)
    _amplitude_entry(entry, where)
    entry["tag"] = _tag(entry["tag"], f"{where}.tag")
    entry["p"] = float(_number(entry["p"], f"{where}.p", physical=True))
    return entry


def _body_force_entry(entry: dict, where: str) -> dict:
    entry = _checked_keys(entry, KEYS["body_force"], {"value"}, where)
    _amplitude_entry(entry, where)
    entry["value"] = _vector(entry["value"], f"{where}.value")
    if "cell_tag" in entry:
        entry["cell_tag"] = _tag(entry["cell_tag"], f"{where}.cell_tag")
    return entry


def _solver_section(solver: dict, where: str) -> dict:
    w = f"{where}: [solver]"
    solver = _checked_keys(solver, KEYS["solver"], set(), w)
    solver.setdefault("method", "monolithic")
    if solver["method"] not in METHODS:
        raise ProblemFileError(f"{w}.method = {solver['method']!r}: expected one of {list(METHODS)}")
    from dolfinx_nnqem.problem.validation import MAX_CUTBACKS, MAX_INCREMENTS

    increments = solver.get("increments", 15)
    if isinstance(increments, str) and increments == "auto":
        solver["increments"] = _automatic_increments(solver.get("auto", {}), f"{w}.auto")
    else:
        solver["increments"] = int(_number(increments, f"{w}.increments", positive=True, integer=True,
                                           high=MAX_INCREMENTS))
        if "auto" in solver:
            raise ProblemFileError(f"{w}.auto is given but increments = {increments!r}; write increments = \"auto\"")
    solver["max_cutbacks"] = int(_number(solver.get("max_cutbacks", 5), f"{w}.max_cutbacks",
                                         nonnegative=True, integer=True, high=MAX_CUTBACKS))
    solver["max_iterations"] = int(_number(solver.get("max_iterations", 50), f"{w}.max_iterations",
                                           positive=True, integer=True, high=10_000))  # SolverOptions' default
    solver["rtol"] = float(_number(solver.get("rtol", 1e-10), f"{w}.rtol", positive=True, high=1e-2))
    solver["atol"] = float(_number(solver.get("atol", 1e-12), f"{w}.atol", nonnegative=True))
    solver.setdefault("linear_solver", "direct")
    if solver["linear_solver"] not in ("direct", "iterative", "auto"):
        raise ProblemFileError(f"{w}.linear_solver = {solver['linear_solver']!r}: expected \"direct\", "
                               "\"iterative\" or \"auto\"")
    if solver["linear_solver"] != "direct" and solver["method"] != "monolithic":
        raise ProblemFileError(f"{w}.linear_solver = {solver['linear_solver']!r} needs method = \"monolithic\" "
                               f"({solver['method']} factorises the stiffness)")
    options = solver.get("petsc_options", {})
    if not isinstance(options, dict) or not all(isinstance(v, (str, int, float, bool)) for v in options.values()):
        raise ProblemFileError(f"{w}.petsc_options must be a table of PETSc option = value")
    solver["petsc_options"] = {k: (str(v).lower() if isinstance(v, bool) else v) for k, v in options.items()}
    return solver


def _automatic_increments(table, where: str):
    """[solver.auto]: the settings of :class:`~dolfinx_nnqem.solvers.step_control.AutomaticIncrements`."""
    from dolfinx_nnqem.solvers.step_control import AutomaticIncrements

    if not isinstance(table, dict):
        raise ProblemFileError(f"{where} must be a table")
    table = _checked_keys(table, KEYS["solver.auto"], set(), where)
    if "load_factors" in table:
        table["load_factors"] = _load_factors(table["load_factors"], f"{where}.load_factors")
    try:
        return AutomaticIncrements(**table)
    except (TypeError, ValueError) as error:
        raise ProblemFileError(f"{where}: {error}") from None


def _load_factors(value, where: str) -> list[float]:
    """[solver.auto] load_factors: stops on the file's load path, ℓ from 0 to 1, increasing; a stop
    outside it would never be reached (one above 1 used to be dropped without a word)."""
    if not isinstance(value, list):
        raise ProblemFileError(f"{where} = {value!r}: expected a list of load factors, e.g. [0.5, 1.0]")
    stops = [float(_number(x, f"{where}[{i}]")) for i, x in enumerate(value)]
    for i, x in enumerate(stops):
        if not 0.0 < x <= 1.0:
            raise ProblemFileError(f"{where}[{i}] = {value[i]!r}: expected a load factor in (0, 1] (the load path "
                                   "runs from 0 to 1: a run never stops outside it)")
    if any(b <= a for a, b in zip(stops, stops[1:])):
        raise ProblemFileError(f"{where} = {value!r}: expected increasing load factors (each listed once)")
    return stops


def _output_section(output: dict, where: str) -> dict:
    w = f"{where}: [output]"
    output = _checked_keys(output, KEYS["output"], set(), w)
    output.setdefault("folder", "results/" + Path(where).stem)
    if not isinstance(output["folder"], str):
        raise ProblemFileError(f"{w}.folder must be a string")
    if output["folder"].strip() in ("", "."):
        raise ProblemFileError(f"{w}.folder = {output['folder']!r}: give a folder name (an empty name would mix the "
                               "results with the current directory)")
    output["checkpoint_every"] = int(_number(output.get("checkpoint_every", 1), f"{w}.checkpoint_every",
                                             nonnegative=True, integer=True))
    for key in ("fields", "pictures"):
        if not isinstance(output.setdefault(key, True), bool):
            raise ProblemFileError(f"{w}.{key} must be true or false")
    probes = output.setdefault("probes", {})
    if not isinstance(probes, dict):
        raise ProblemFileError(f"{w}.probes must be a table name = [x, y, z]")
    output["probes"] = {name: _vector(x, f"{w}.probes.{name}") for name, x in probes.items()}
    return output


def _estimate_section(estimate: dict, where: str) -> dict:
    """[estimate]: discretisation-error estimates (off by default) and adaptive refinement."""
    w = f"{where}: [estimate]"
    estimate = _checked_keys(estimate, KEYS["estimate"], set(), w)
    if not isinstance(estimate.setdefault("enabled", "target_error" in estimate), bool):
        raise ProblemFileError(f"{w}.enabled must be true or false")
    if estimate.setdefault("enrichment", "auto") not in ("auto", "degree-2", "refine"):
        raise ProblemFileError(f"{w}.enrichment = {estimate['enrichment']!r}: expected \"auto\", \"degree-2\" or "
                               "\"refine\"")
    if "target_error" in estimate:
        target = _number(estimate["target_error"], f"{w}.target_error", positive=True)
        if target >= 1.0:
            raise ProblemFileError(f"{w}.target_error = {target!r}: a relative error in (0, 1), e.g. 0.01 for 1 %")
        estimate["target_error"] = float(target)
    estimate["max_cycles"] = int(_number(estimate.get("max_cycles", 6), f"{w}.max_cycles", positive=True,
                                         integer=True))
    estimate["refine_fraction"] = float(_number(estimate.get("refine_fraction", 0.5), f"{w}.refine_fraction",
                                                positive=True, high=1.0))
    quantities = estimate.setdefault("quantities", None)
    if quantities is not None and (not isinstance(quantities, list) or not quantities
                                   or not all(isinstance(q, str) for q in quantities)):
        raise ProblemFileError(f"{w}.quantities = {quantities!r}: expected a list of quantity names or kinds "
                               "(\"contact\", \"reaction\", \"u\", \"max_p\", \"u:tip\", ...)")
    return estimate


def _checks_section(checks: dict, where: str) -> dict:
    """[checks]: rtol, max_strain, max_rotation (false disables a small-strain limit), min_shape_ratio
    (finite strain; false disables it)."""
    from dolfinx_nnqem.solvers.checks import DEFAULT_MAX_ROTATION, DEFAULT_MAX_STRAIN, DEFAULT_MIN_SHAPE_RATIO

    w = f"{where}: [checks]"
    checks = _checked_keys(checks, KEYS["checks"], set(), w)
    if "rtol" in checks:
        checks["rtol"] = float(_number(checks["rtol"], f"{w}.rtol", positive=True, high=1e-2))
    for key, default in (("max_strain", DEFAULT_MAX_STRAIN), ("max_rotation", DEFAULT_MAX_ROTATION),
                         ("min_shape_ratio", DEFAULT_MIN_SHAPE_RATIO)):
        value = checks.get(key, default)
        if value is False:
            checks[key] = None
        elif value is True:
            raise ProblemFileError(f"{w}.{key} = true: give a number, or false to disable the limit")
        else:
            checks[key] = float(_number(value, f"{w}.{key}", positive=True,
                                        high=1.0 if key == "min_shape_ratio" else None))
    return checks


def check_options(spec: ProblemSpec) -> CheckOptions:
    """The :class:`~dolfinx_nnqem.solvers.checks.CheckOptions` of the [checks] section."""
    from dolfinx_nnqem.solvers.checks import CheckOptions

    return CheckOptions(**spec.checks)


# -- building ---------------------------------------------------------------------------------
def read_mesh(spec: ProblemSpec, comm: MPI.Comm
              ) -> tuple[dolfinx.mesh.Mesh, dolfinx.mesh.MeshTags | None, dolfinx.mesh.MeshTags | None]:
    """The mesh and its tags from ``spec.mesh`` (gmsh .msh or XDMF)."""

    file = spec.mesh["file"]
    if file.suffix == ".msh":
        return _read_msh(file, comm)
    else:
        from dolfinx.io import XDMFFile

        from dolfinx_nnqem.collective import agree

        agree(comm, _check_xdmf, file, spec.mesh)  # names checked on every rank before the collective read
        with XDMFFile(comm, str(file), "r") as xdmf:
            mesh = xdmf.read_mesh(name=spec.mesh["mesh_name"])
            mesh.topology.create_connectivity(mesh.topology.dim - 1, mesh.topology.dim)
            cell_tags = xdmf.read_meshtags(mesh, name=spec.mesh["cell_tags"])
            facet_tags = xdmf.read_meshtags(mesh, name=spec.mesh["facet_tags"])
    return mesh, cell_tags, facet_tags


def _read_msh(file: Path, comm):
    """A gmsh file read on rank 0 and distributed; what rank 0 finds wrong is raised on every rank
    BEFORE the collective distribution starts (no rank is left waiting)."""
    import gmsh

    from dolfinx_nnqem import chatter, compat
    from dolfinx_nnqem.collective import on_rank0
    from dolfinx_nnqem.problem.meshing import restore_signal_handlers, unsupported_gmsh_cells

    started = [False]
    previous_options: dict = {}

    def open_model():
        if not gmsh.isInitialized():
            gmsh.initialize(interruptible=False)  # leave Ctrl-C to the command line
            restore_signal_handlers()  # and SIGTERM (gmsh takes it at the C level)
            started[0] = True
        previous_options.update(chatter.apply_gmsh_options())  # gmsh's "Info : Reading ..." lines only with -v
        gmsh.model.add("dolfinx_nnqem problem file")
        try:
            gmsh.merge(str(file))
        except Exception as error:
            raise ProblemFileError(f"{file}: gmsh cannot read it ({error})") from None
        types = gmsh.model.mesh.getElementTypes(3)
        if len(types) == 0:
            dims = sorted({d for d, _ in gmsh.model.getEntities() if len(gmsh.model.mesh.getElementTypes(d))})
            raise ProblemFileError(f"{file}: a {max(dims, default=0)}D mesh (no 3D cells; elements of dimension "
                                   f"{dims}); dolfinx_nnqem solves 3D solids: mesh the volumes")
        problem = unsupported_gmsh_cells(types)
        if problem is not None:
            raise ProblemFileError(f"{file}: {problem}")
        if len(types) > 1:
            names = [gmsh.model.mesh.getElementProperties(t)[0] for t in types]
            raise ProblemFileError(f"{file}: the volumes mix cell types {names}; use one (all tetrahedra or all "
                                   "hexahedra)")
        if not gmsh.model.getPhysicalGroups(3):
            raise ProblemFileError(f"{file}: no physical volume groups; tag every body (the cell tags name the "
                                   "materials)")

    def close_model():
        if gmsh.isInitialized():
            gmsh.model.remove()
            if started[0]:
                gmsh.finalize()
            else:  # the caller's session: its options as they were
                for option, value in previous_options.items():
                    gmsh.option.setNumber(option, value)

    try:
        on_rank0(comm, open_model)
        return compat.model_to_mesh(gmsh.model, comm, 0, gdim=3)
    finally:
        if comm.rank == 0:
            close_model()


def _check_xdmf(file: Path, names: dict) -> None:
    import xml.etree.ElementTree as ET

    try:
        tree = ET.parse(file)
    except (ET.ParseError, OSError) as error:
        raise ProblemFileError(f"{file}: not a readable XDMF file ({error})") from None
    grids = {g.attrib["Name"] for g in tree.iter("Grid") if "Name" in g.attrib}  # a Grid may have none
    for key in ("mesh_name", "cell_tags", "facet_tags"):
        if names[key] not in grids:
            raise ProblemFileError(f"{file}: no grid named {names[key]!r} (mesh.{key}); the file has {sorted(grids)}")
    for item in tree.iter("DataItem"):
        if item.get("Format") == "HDF" and item.text:
            h5 = file.parent / item.text.strip().split(":")[0]
            if not h5.is_file():
                raise ProblemFileError(f"{file}: its data file {h5} is missing")


def build_problem(spec: ProblemSpec, comm: MPI.Comm) -> ContactProblem:
    """The :class:`ContactProblem` of a checked problem file."""
    from dolfinx_nnqem.problem.contact_problem import (BodyForce, Contact, ContactProblem, Dirichlet, Gravity, Pressure,
                                       Traction)

    mesh, cell_tags, facet_tags = read_mesh(spec, comm)
    contact = []
    for entry in spec.contact:
        entry = dict(entry)
        obstacle = entry.pop("obstacle", None)
        if obstacle is not None:
            obstacle = dict(obstacle)
            entry["surface1"] = OBSTACLES[obstacle.pop("type")](**obstacle)
        contact.append(Contact(**entry))
    loads: list[Traction | Pressure] = [Traction(e["tag"], e["value"], e.get("amplitude")) for e in spec.traction]
    loads += [Pressure(e["tag"], e["p"], e.get("amplitude")) for e in spec.pressure]
    body: list[BodyForce | Gravity] = [BodyForce(e["value"], e.get("cell_tag"), e.get("amplitude"))
                                       for e in spec.body_force]
    if spec.gravity is not None:
        body.append(Gravity(spec.gravity["g"], spec.gravity.get("amplitude")))
    return ContactProblem(
        mesh, cell_tags, facet_tags, materials=spec.materials,
        dirichlet=[Dirichlet(e["tag"], e.get("value", 0.0), e.get("components"), e.get("amplitude"))
                   for e in spec.dirichlet],
        tractions=loads, body_forces=body, contact=contact or None, degree=spec.mesh.get("degree"),
        quadrature_degree=spec.mesh.get("quadrature_degree"), kinematics=spec.mesh.get("kinematics", "small"),
    )


def solver_options(spec: ProblemSpec, method: str | None = None
                   ) -> tuple[SolverOptions, dict[str, MonolithicOptions]]:
    """(SolverOptions, {method: its own options}) from the [solver] section (``method`` overrides its method)."""
    from dolfinx_nnqem.solvers.options import MonolithicOptions, SolverOptions

    s = spec.solver
    method = method or s["method"]
    if method != "monolithic" and s["linear_solver"] != "direct":
        raise ProblemFileError(f"{spec.path}: [solver].linear_solver = {s['linear_solver']!r} needs the monolithic "
                               f"method ({method} factorises the stiffness)")
    options = SolverOptions(rtol=s["rtol"], atol=s["atol"], max_iterations=s["max_iterations"],
                            petsc_options=s["petsc_options"])
    method_options = {}
    if method == "monolithic":
        method_options["monolithic"] = MonolithicOptions(linear_solver=s["linear_solver"])
    return options, method_options
