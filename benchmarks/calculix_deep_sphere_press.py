"""A rigid sphere pressed deep (to 20 % of its radius) into an elastoplastic block at finite strain,
as a CalculiX 2.20 ``NLGEOM`` model: the force–indentation curve of the two programs (issue 41).

The case (:func:`deep_press_problem`): a quarter model of a block x, z ∈ [0, ``BLOCK``],
y ∈ [−``BLOCK``, 0] (the planes x = 0 and z = 0 symmetry planes, the bottom clamped), graded
towards the point x = z = 0 of its top (``build_graded_block``: hexahedra of size h over
x, z ≤ ``FINE_WIDTH`` and ``FINE_DEPTH`` below the top); a rigid sphere of radius ``R_SPHERE``
touching the top at the origin is pressed ``DEPTH`` = 0.2 R down in equal increments. The
block is von Mises with linear isotropic hardening (E = 200 GPa, ν = 0.3, σ_y0 = 200 MPa,
H = 1 GPa), frictionless or with Coulomb friction μ_f. The package solves it with
``kinematics = "finite"`` (total Lagrangian, Hencky's law in the logarithmic strain, the return
map on the Kirchhoff stress) and the contact in the current geometry (``geometry = "current"``).

CalculiX's model, on the same mesh:

* the block: the package's nodes and hexahedra as C3D8 elements (2×2×2 Gauss points, like the
  package's);
* the material: ``*ELASTIC`` and ``*PLASTIC`` with the rows (σ_y0, 0), (σ_y0 + H p_max, p_max):
  CalculiX holds the last row's stress beyond it, so it is σ_y0 + H p for every p reached;
* the kinematics: ``NLGEOM``. CalculiX's finite-strain plasticity (``incplas.f``, the manual's
  "Incremental (visco)plasticity: multiplicative decomposition") is Simo's (1988) model: F = F_e F_p,
  the Kirchhoff stress τ = K (J² − 1)/2 I + μ dev b̄_e (b̄_e = J^(−2/3) b_e, a Neo-Hookean-type
  stored energy), von Mises on τ with the table's (Cauchy) stress multiplied by J, isochoric flow.
  The package's is Hencky's τ = K ln J I + 2μ dev ε_e (ε_e = ½ ln b_e) and σ_y on τ, by the
  exponential map. They differ by the volumetric law (CalculiX's pressure is J times the package's
  at the same J), by the factor J on the yield stress, and by CalculiX's return map, whose error
  depends on the increment (``--material-point`` measures each; ``--ccx-substeps`` refines
  CalculiX's increments);
* the sphere: a cap of C3D8 elements whose outer nodes lie on the sphere, on a grid of equal angles
  ``--facet`` (degrees) in the planes x = 0 and z = 0 up to ``CAP_ANGLE`` from the pole (a
  gnomonic grid: direction (tan φ_x, −1, tan φ_z)), tied by ``*RIGID BODY`` to a reference node at
  the centre, which is moved down by the depth; its reaction is the force;
* the contact: node-to-surface penalty, ``PRESSURE-OVERCLOSURE=LINEAR`` with slope ``--penalty``
  × E / h, the block's top the slave; friction by ``*FRICTION`` with μ_f and the same stick slope;
* the increments: the package's equal increments as the longest and the output points of CalculiX's
  automatic incrementation (``*TIME POINTS``).

The measures at every increment: the whole sphere's force (4 × the quarter model's), the largest
equivalent plastic strain p of the fine zone's Gauss points; at the end: p point by point (the
package's Gauss points matched to CalculiX's by their reference positions: CalculiX 2.20 prints
``COORD`` undeformed with ``NLGEOM`` too), the contact radius (the largest distance from the axis,
in the deformed configuration, of a top node in contact) and the contact pressure at the top's
nodes on the plane z = 0 (CalculiX's penalty pressure ``CSTR``; the package's normal force over
the node's reference tributary area and over its deformed one).

Usage::

    python benchmarks/calculix_deep_sphere_press.py OUTDIR [--h 8] [--increments 20] [--penalty 100 ...]
        [--facet 1.5 ...] [--mu-f 0.0] [--ccx-substeps 1] [--ours] [--tag T]
    python benchmarks/calculix_deep_sphere_press.py OUTDIR --material-point   # one point, both laws
    python benchmarks/calculix_deep_sphere_press.py OUTDIR --plot STEM   # force and p from STEM.json

Each CalculiX run writes ``OUTDIR/deep_h{1/h}_n{increments}_mu{mu_f}_k{factor}_f{facet}.inp`` (and its
outputs next to it); ``OUTDIR/deep_h{1/h}_n{increments}_mu{mu_f}{tag}.json`` holds every history and measure.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from calculix_ironing import C3D8_FACES, faces_on, node_set, outward, run_ccx, strip_elements
from calculix_sphere_press import press_mesh_lines, read_dat

R_SPHERE = 1.0  # mm
DEPTH = 0.2 * R_SPHERE  # mm: the sphere's travel below first touch
E, NU, SIGMA_Y0, H_LIN = 200e3, 0.3, 200.0, 1000.0  # MPa
FINE_WIDTH, FINE_DEPTH, BLOCK = 1.0, 0.75, 4.0  # mm: the fine zone (elements of size h) and the block
SYMMETRY = 4  # quarter model
P_MAX = 10.0  # the plastic strain at the end of CalculiX's table (far beyond any reached)
CAP_ANGLE = 45.0  # degrees: the sphere's cap reaches this far from its pole in the planes x = 0 and z = 0
CAP_THICKNESS = 0.1  # radial depth of the cap's elements, in radii (any value: the body is rigid)


# -- the case --------------------------------------------------------------------------------
def deep_press_problem(h: float, mu_f: float = 0.0, *, comm: MPI.Comm = MPI.COMM_SELF, kinematics: str = "finite"):
    """The quarter model (module docstring) at finite strain, elements of size ``h`` (mm) at the contact
    (``kinematics="small"``: the same problem at small strain, ``benchmarks/small_strain_limit.py``)."""
    from dolfinx_nnqem.cases.geometries import BlockStackTags as T
    from dolfinx_nnqem.cases.geometries import build_graded_block
    from dolfinx_nnqem.contact.obstacles import Sphere
    from dolfinx_nnqem.material import VonMises
    from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet

    mesh, cell_tags, facet_tags = build_graded_block(comm, h, fine_width=FINE_WIDTH, fine_depth=FINE_DEPTH,
                                                     block=BLOCK)
    sphere = Sphere(centre=(0.0, R_SPHERE, 0.0), radius=R_SPHERE, motion=(0.0, -DEPTH, 0.0))
    dirichlet = [Dirichlet(T.bottom(1)), Dirichlet(T.xmin(1), 0.0, [0]), Dirichlet(T.zmin(1), 0.0, [2])]
    return ContactProblem(mesh, cell_tags, facet_tags, materials=VonMises(E=E, nu=NU, sigma_y0=SIGMA_Y0, H=H_LIN),
                          dirichlet=dirichlet, kinematics=kinematics,
                          contact=Contact(sphere, T.top(1), mu_f=mu_f, geometry="current"))


# -- the model -------------------------------------------------------------------------------
def cap_elements(radius: float, facet: float) -> tuple[np.ndarray, np.ndarray]:
    """The sphere's cap: coordinates and C3D8 connectivity (0-based), the sphere centred at (0, radius, 0).

    Its outer nodes lie on the sphere in the directions (tan φ_x, −1, tan φ_z) for angles φ_x, φ_z
    from −``facet`` to ``CAP_ANGLE`` in steps of ``facet`` (degrees): one facet beyond the symmetry
    planes, so that the block's nodes on them lie inside the surface; its inner ones on the same
    radii, ``CAP_THICKNESS`` radii inwards.
    """
    n = int(np.ceil(CAP_ANGLE / facet))
    t = np.tan(np.deg2rad(facet * np.arange(-1, n + 1)))
    ix, iz = np.meshgrid(np.arange(len(t)), np.arange(len(t)), indexing="ij")
    d = np.column_stack([t[ix.ravel()], -np.ones(ix.size), t[iz.ravel()]])
    d /= np.linalg.norm(d, axis=1)[:, None]
    centre = np.array([0.0, radius, 0.0])
    coords = np.vstack([centre + radius * d, centre + radius * (1.0 - CAP_THICKNESS) * d])
    m, k = len(t), ix.size

    def node(i, j):
        return i * m + j

    cells = [[node(i, j), node(i + 1, j), node(i + 1, j + 1), node(i, j + 1),
              node(i, j) + k, node(i + 1, j) + k, node(i + 1, j + 1) + k, node(i, j + 1) + k]
             for i in range(m - 1) for j in range(m - 1)]
    return coords, outward(coords, np.array(cells))


def model_text(problem, increments: int, *, h: float, penalty_factor: float, facet: float, mu_f: float,
               substeps: int = 1) -> str:
    """The whole ``.inp`` text of ``deep_press_problem(h, mu_f)`` pressed in ``increments`` increments.

    CalculiX's increments are at most 1/``substeps`` of those (its plasticity's error depends on the
    increment: ``docs/verification-materials.md``); its output is at their ends.
    """
    coords, cells = strip_elements(problem)
    c_coords, c_cells = cap_elements(R_SPHERE, facet)
    on_top = np.isclose(coords[:, 1], coords[:, 1].max())
    lines, ref = press_mesh_lines(f"dolfinx_nnqem deep sphere press, h = {h:g} mm, mu_f = {mu_f:g}", coords, cells,
                                  c_coords, c_cells, R_SPHERE, FINE_WIDTH, FINE_DEPTH,
                                  node_set("TOP", np.flatnonzero(on_top) + 1))
    rot = ref + 1
    lines += ["*MATERIAL, NAME=BLOCK", "*ELASTIC", f"{E:.12e}, {NU}", "*PLASTIC",
              f"{SIGMA_Y0:.12e}, 0.0", f"{SIGMA_Y0 + H_LIN * P_MAX:.12e}, {P_MAX:.12e}",
              "*MATERIAL, NAME=RIGID", "*ELASTIC", f"{1e3 * E:.6e}, 0.3",
              "*SOLID SECTION, ELSET=BLOCK, MATERIAL=BLOCK", "*SOLID SECTION, ELSET=SPHERE, MATERIAL=RIGID",
              f"*RIGID BODY, ELSET=SPHERE, REF NODE={ref}, ROT NODE={rot}"]
    stiffness = penalty_factor * E / h
    # node-to-surface's tension at large clearances: a thousandth of σ_y0 (the default is E/70000)
    lines += ["*SURFACE INTERACTION, NAME=PRESS", "*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=LINEAR",
              f"{stiffness:.6e}, {1e-3 * SIGMA_Y0:.6e}",
              *(["*FRICTION", f"{mu_f}, {stiffness:.6e}"] if mu_f > 0 else []),  # ccx refuses μ = 0
              "*CONTACT PAIR, INTERACTION=PRESS, TYPE=NODE TO SURFACE", "BLOCKTOP, SPHEREFACE"]
    lines += ["*BOUNDARY", "BOTTOM, 1, 3", "XSYM, 1, 1", "ZSYM, 3, 3", "ROT, 1, 3", f"{ref}, 1, 1", f"{ref}, 3, 3"]
    ends = [f"{k / increments:.12g}" for k in range(1, increments + 1)]
    lines += ["*TIME POINTS, NAME=INCREMENTS"] + [", ".join(ends[k:k + 8]) for k in range(0, len(ends), 8)]
    dt = 1.0 / (increments * substeps)
    lines += [f"*STEP, INC={1000 * increments * substeps}, NLGEOM", "*STATIC",
              f"{dt:.12g}, 1.0, {1e-6 * dt:.6g}, {dt:.12g}",
              "*BOUNDARY", f"{ref}, 2, 2, {-DEPTH:.12e}",
              "*NODE PRINT, NSET=REF, TIME POINTS=INCREMENTS", "RF",
              "*EL PRINT, ELSET=FINE, TIME POINTS=INCREMENTS", "PEEQ",
              "*NODE PRINT, NSET=TOP, TIME POINTS=INCREMENTS", "U", "*EL PRINT, ELSET=FINE, TIME POINTS=INCREMENTS", "COORD",
              "*CONTACT PRINT, TIME POINTS=INCREMENTS", "CSTR", "*END STEP"]
    return "\n".join(lines) + "\n"


# -- reading ---------------------------------------------------------------------------------
def read_contact_stress(dat: Path) -> np.ndarray:
    """The last ``contact stress`` block of CalculiX's ``.dat``: rows (node id, pressure, τ_1, τ_2)."""
    rows: list[list[float]] = []
    inside = False
    for line in dat.read_text().splitlines():
        if re.match(r"^\s*contact stress", line):
            inside, rows = True, []
        elif re.match(r"^\s*[a-z]", line):
            inside = False
        elif inside and line.split() and line.split()[0].isdigit():
            rows.append([float(w) for w in line.split()])
    return np.array(rows)


def ccx_results(dat: Path, problem) -> dict:
    """CalculiX's histories (force, largest p per increment) and its final state (p at the points and
    their reference positions, the top's deformed positions and contact pressures)."""
    blocks = read_dat(dat)
    force = np.array([[t, -SYMMETRY * r[0, 2]] for t, r in blocks["forces"]])
    peeq = [r for _, r in blocks["peeq"]]
    coords = blocks["coords"][-1][1]
    order = np.lexsort((coords[:, 1], coords[:, 0]))  # (element, point)
    last = peeq[-1][np.lexsort((peeq[-1][:, 1], peeq[-1][:, 0]))]
    X, _ = strip_elements(problem)
    u_top = blocks["displacements"][-1][1]
    top_ids = u_top[:, 0].astype(int)
    stress = read_contact_stress(dat)
    pressure = np.zeros(len(X))
    if len(stress):
        pressure[stress[:, 0].astype(int) - 1] = stress[:, 1]
    return {"load_factor": force[:, 0], "force": force[:, 1], "max_p": np.array([v[:, 2].max() for v in peeq]),
            "points": coords[order, 2:5], "p": last[:, 2],
            "top": X[top_ids - 1] + u_top[:, 1:4], "pressure": pressure[top_ids - 1]}


# -- the package -----------------------------------------------------------------------------
def run_ours(problem, increments: int) -> dict:
    """The package's histories and final state, as :func:`ccx_results`'s (monolithic, rtol 1e-10)."""
    import ufl

    from dolfinx_nnqem.io.results import pair_table
    from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

    rows = []
    n = problem.state.p_n.function_space.dofmap.index_map.size_local

    def record(result):
        (reaction,) = problem.contact.obstacle_reactions().values()
        rows.append([result.load_factor, -SYMMETRY * float(reaction[1]), problem.state.p_n.x.array[:n].max()])

    t0 = time.perf_counter()
    with make_solver("monolithic", problem, SolverOptions(rtol=1e-10, max_iterations=40)) as solver:
        results = solve_load_steps(problem, solver, increments, callbacks=[record])
    seconds = time.perf_counter() - t0
    X = ufl.SpatialCoordinate(problem.mesh)  # CalculiX's COORD are the reference points too
    points = np.column_stack([problem.state.values_at_points(X[i]) for i in range(3)])
    J = problem.state.values_at_points(ufl.det(ufl.Identity(3) + ufl.grad(problem.u)))
    plastic = problem.state.p_n.x.array[:n] > 0.0
    table = pair_table(problem)
    top = table["position_b"] + table["u_body2"]
    history = np.array(rows)
    return {"load_factor": history[:, 0], "force": history[:, 1], "max_p": history[:, 2], "points": points,
            "p": problem.state.p_n.x.array[:n].copy(), "top": top, "pressure": table["pressure"],
            "true pressure": table["pressure"] * table["area"] / current_areas(problem, table["position_b"], top),
            "seconds": seconds, "iterations": [int(r.iterations) for r in results],
            "1 - J at plastic points": {"mean": float(np.mean(1.0 - J[plastic])), "max": float(np.max(1.0 - J[plastic]))}}


def current_areas(problem, X_top: np.ndarray, x_top: np.ndarray) -> np.ndarray:
    """The tributary area of each top node (reference positions ``X_top``) in the deformed configuration
    (positions ``x_top``): a quarter of each deformed top face's area (Newell's vector) at each of its nodes."""
    from scipy.spatial import cKDTree

    coords, cells = strip_elements(problem)
    tree = cKDTree(X_top)
    areas = np.zeros(len(X_top))
    for e, f in faces_on(cells, np.isclose(coords[:, 1], coords[:, 1].max())):
        rows = tree.query(coords[cells[e, list(C3D8_FACES[f - 1])]])[1]
        x = x_top[rows]
        areas[rows] += 0.25 * np.linalg.norm(0.5 * np.cross(x, np.roll(x, -1, axis=0)).sum(axis=0))
    return areas


# -- the comparison --------------------------------------------------------------------------
def on_ours(theirs: dict, ours: dict) -> tuple[np.ndarray, float]:
    """For each of CalculiX's fine-zone points, the package's nearest Gauss point (reference positions),
    and the largest distance between the two over the smallest distance between the package's points."""
    from scipy.spatial import cKDTree

    tree = cKDTree(ours["points"])
    distance, index = tree.query(theirs["points"])
    spacing = tree.query(ours["points"], k=2)[0][:, 1].min()
    return index, float(distance.max() / spacing)


def contact_radius(run: dict) -> float:
    """The largest distance from the axis (deformed) of a top node with a positive contact pressure."""
    top, pressure = run["top"], run["pressure"]
    touching = pressure > 0.0
    return float(np.hypot(top[touching, 0], top[touching, 2]).max())


def pressure_profile(run: dict, key: str = "pressure") -> np.ndarray:
    """(deformed x, ``run[key]``) of the top's nodes on the plane z = 0 in contact, by x."""
    top, pressure = run["top"], run[key]
    on_plane = (np.abs(top[:, 2]) < 1e-9) & (pressure > 0.0)
    order = np.argsort(top[on_plane, 0])
    return np.column_stack([top[on_plane, 0][order], pressure[on_plane][order]])


def measures(theirs: dict, ours: dict) -> dict:
    """The force and largest p at every increment, p point by point, the contact radius and the
    pressure on the plane z = 0 at the end: each program's and the differences (CalculiX − package)."""
    index, match = on_ours(theirs, ours)
    p_ours = ours["p"][index]
    prof_t, prof_o, prof_true = pressure_profile(theirs), pressure_profile(ours), pressure_profile(ours, "true pressure")
    common = min(len(prof_t), len(prof_o))
    return {
        "force": {"ccx": theirs["force"].tolist(), "ours": ours["force"].tolist(),
                  "difference": ((theirs["force"] - ours["force"]) / ours["force"]).tolist()},
        "max p": {"ccx": theirs["max_p"].tolist(), "ours": ours["max_p"].tolist(),
                  "difference": ((theirs["max_p"] - ours["max_p"]) / ours["max_p"]).tolist()},
        "p at the points": {"largest |difference| / max p": float(np.abs(theirs["p"] - p_ours).max() / p_ours.max()),
                            "match distance / point spacing": match},
        "contact radius": {"ccx": contact_radius(theirs), "ours": contact_radius(ours)},
        "pressure on z = 0": {"ccx": prof_t.tolist(), "ours": prof_o.tolist(), "ours, current area": prof_true.tolist(),
                              "difference at common nodes": ((prof_t[:common, 1] - prof_true[:common, 1])
                                                             / prof_true[:common, 1].max()).tolist()},
    }


def print_measures(m: dict, depths: np.ndarray) -> None:
    print(f"{'depth/R':>8} {'F ours (N)':>14} {'F CalculiX':>14} {'diff':>9} {'max p ours':>11} {'max p ccx':>11} {'diff':>9}")
    f, p = m["force"], m["max p"]
    for k, d in enumerate(depths):
        print(f"{d:8.3f} {f['ours'][k]:14.6g} {f['ccx'][k]:14.6g} {f['difference'][k]:+9.3%} "
              f"{p['ours'][k]:11.5g} {p['ccx'][k]:11.5g} {p['difference'][k]:+9.3%}")
    pts = m["p at the points"]
    print(f"p at every fine-zone point at the end: largest |difference| / max p = {pts['largest |difference| / max p']:.3%} "
          f"(points matched within {pts['match distance / point spacing']:.2g} of their spacing)")
    r = m["contact radius"]
    print(f"contact radius (mm): ours {r['ours']:.5g}, CalculiX {r['ccx']:.5g}")
    pr = m["pressure on z = 0"]
    print("pressure on z = 0 (MPa): deformed x, ours (normal force / reference area), ours (/ deformed area); "
          "CalculiX's x, its CSTR")
    for (x, po), (_, ptrue), (xt, pt) in zip(pr["ours"], pr["ours, current area"], pr["ccx"]):
        print(f"  {x:8.4f} {po:10.2f} {ptrue:10.2f}   {xt:8.4f} {pt:10.2f}")


# -- one material point ----------------------------------------------------------------------
def material_point_text(stretch: float, confined: bool, increments: int, substeps: int = 1) -> str:
    """One C3D8 cube [0, 1]³ on rollers at x, y, z = 0, its face y = 1 moved to y = ``stretch``; with
    ``confined`` the faces x = 1 and z = 1 held too (uniaxial strain), else free (uniaxial stress).
    Output at ``increments`` equal steps, each done in ``substeps`` fixed increments."""
    corners = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
    held = {1: [1, 4, 5, 8], 2: [1, 2, 5, 6], 3: [1, 2, 3, 4]}  # nodes on x = 0, y = 0, z = 0
    lines = ["*HEADING", "one material point", "*NODE"] + [f"{i + 1}, {x}, {y}, {z}" for i, (x, y, z) in enumerate(corners)]
    lines += ["*ELEMENT, TYPE=C3D8, ELSET=EALL", "1, 1, 2, 3, 4, 5, 6, 7, 8",
              "*MATERIAL, NAME=BLOCK", "*ELASTIC", f"{E:.12e}, {NU}", "*PLASTIC",
              f"{SIGMA_Y0:.12e}, 0.0", f"{SIGMA_Y0 + H_LIN * P_MAX:.12e}, {P_MAX:.12e}",
              "*SOLID SECTION, ELSET=EALL, MATERIAL=BLOCK", "*BOUNDARY"]
    lines += [f"{n}, {d}, {d}" for d, nodes in held.items() for n in nodes]
    if confined:
        lines += [f"{n}, 1, 1" for n in (2, 3, 6, 7)] + [f"{n}, 3, 3" for n in (5, 6, 7, 8)]
    ends = [f"{k / increments:.12g}" for k in range(1, increments + 1)]
    lines += ["*TIME POINTS, NAME=INCREMENTS"] + [", ".join(ends[k:k + 8]) for k in range(0, len(ends), 8)]
    dt = 1.0 / (increments * substeps)
    lines += ["*STEP, NLGEOM, INC=100000", "*STATIC", f"{dt:.12g}, 1.0, {dt:.12g}, {dt:.12g}", "*BOUNDARY"]
    lines += [f"{n}, 2, 2, {stretch - 1.0:.12e}" for n in (3, 4, 7, 8)]
    lines += ["*EL PRINT, ELSET=EALL, TIME POINTS=INCREMENTS", "S, PEEQ", "*END STEP"]
    return "\n".join(lines) + "\n"


def material_point_ccx(dat: Path) -> np.ndarray:
    """(σ_xx, σ_yy, p) of CalculiX's one element at each output, averaged over its 8 points."""
    out: dict[str, list[float]] = {"stresses": [], "equivalent plastic strain": []}
    kind, rows = None, []
    for line in dat.read_text().splitlines() + [" end"]:
        if re.match(r"^\s*[a-z]", line):
            if kind is not None:
                a = np.array(rows)
                out[kind].append(a[:, 2:4].mean(axis=0) if kind == "stresses" else a[:, 2].mean())
            kind = next((k for k in out if line.strip().startswith(k)), None)
            rows = []
        elif kind is not None and line.split():
            rows.append([float(w) for w in line.split()])
    return np.column_stack([np.array(out["stresses"]), out["equivalent plastic strain"]])


def material_point_ours(stretch: float, confined: bool, increments: int) -> np.ndarray:
    """(σ_xx, σ_yy, p) of the package's one hexahedron (finite strain) at each increment, as CalculiX's."""
    from dolfinx_nnqem.cases.geometries import BlockStackTags as T
    from dolfinx_nnqem.cases.geometries import build_block_stack
    from dolfinx_nnqem.material import VonMises
    from dolfinx_nnqem.problem import ContactProblem, Dirichlet
    from dolfinx_nnqem.solvers import CheckOptions, SolverOptions, make_solver, solve_load_steps

    mesh, ct, ft = build_block_stack(MPI.COMM_SELF, 1.0, 1.0, [1.0], [(1, 1, 1)])
    dirichlet = [Dirichlet(T.xmin(1), 0.0, [0]), Dirichlet(T.bottom(1), 0.0, [1]), Dirichlet(T.zmin(1), 0.0, [2]),
                 Dirichlet(T.top(1), stretch - 1.0, [1])]
    if confined:
        dirichlet += [Dirichlet(T.xmax(1), 0.0, [0]), Dirichlet(T.zmax(1), 0.0, [2])]
    problem = ContactProblem(mesh, ct, ft, materials=VonMises(E=E, nu=NU, sigma_y0=SIGMA_Y0, H=H_LIN),
                             dirichlet=dirichlet, kinematics="finite")
    rows = []

    def record(_):
        sigma = problem.state.sigma_n.x.array.reshape(-1, 3, 3)
        rows.append([sigma[:, 0, 0].mean(), sigma[:, 1, 1].mean(), problem.state.p_n.x.array.mean()])

    solve_load_steps(problem, make_solver("monolithic", problem, SolverOptions(rtol=1e-10)), increments,
                     check=CheckOptions(max_strain=None, max_rotation=None), callbacks=[record])
    return np.array(rows)


def material_points(out: Path, increments: int = 10, substeps: tuple[int, ...] = (1, 4, 16)) -> dict:
    """The two programs' laws at one material point: uniaxial stress to λ = 0.7 (large plastic strain,
    J ≈ 1) and uniaxial strain to λ = 0.985 (J = 0.985, a pressure of a few σ_y: as under the sphere).
    The package in ``increments`` increments (its update is exact on these proportional paths),
    CalculiX in ``increments`` × each of ``substeps``."""
    results = {}
    for name, stretch, confined in (("uniaxial stress, λ = 0.7", 0.7, False), ("uniaxial strain, λ = 0.985", 0.985, True)):
        ours = material_point_ours(stretch, confined, increments)
        results[name] = {"ours": ours.tolist()}
        for k in substeps:
            job = ("point_confined" if confined else "point_free") + f"_s{k}"
            (out / f"{job}.inp").write_text(material_point_text(stretch, confined, increments, k))
            run_ccx(out, job)
            theirs = material_point_ccx(out / f"{job}.dat")
            results[name][f"ccx, {k} substeps"] = theirs.tolist()
            print(f"== {name}, CalculiX in {increments * k} increments: λ, σ_yy ours, CalculiX (MPa), difference; "
                  "p ours, CalculiX, difference")
            for i in range(increments):
                print(f"  {1 + (stretch - 1) * (i + 1) / increments:.4f} {ours[i, 1]:11.4f} {theirs[i, 1]:11.4f} "
                      f"{(theirs[i, 1] - ours[i, 1]) / abs(ours[i, 1]):+8.3%}   {ours[i, 2]:.6f} {theirs[i, 2]:.6f} "
                      f"{(theirs[i, 2] - ours[i, 2]) / max(ours[i, 2], 1e-300):+8.3%}")
    return results


def plot(outdir: Path, stem: str) -> None:
    """``deep_sphere_press.png``: the force and the largest p against the depth, the package's (lines)
    and each CalculiX run's (circles) of ``outdir/stem.json``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = json.loads((outdir / f"{stem}.json").read_text())
    fig, axes = plt.subplots(1, 2, figsize=(8.4, 3.6))
    for job, m in data["measures"].items():
        depth = DEPTH / R_SPHERE * np.arange(1, len(m["force"]["ours"]) + 1) / len(m["force"]["ours"])
        for ax, key in zip(axes, ("force", "max p")):
            ax.plot(np.concatenate([[0.0], depth]), np.concatenate([[0.0], m[key]["ours"]]), "-", label="dolfinx_nnqem")
            ax.plot(depth, m[key]["ccx"], "o", ms=4, mfc="none", label=f"CalculiX 2.20 NLGEOM ({job})")
    for ax, label in zip(axes, ("force (N)", "largest equivalent plastic strain")):
        ax.set_xlabel("depth / R")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(outdir / "deep_sphere_press.png", dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("outdir", help="where the .inp files, CalculiX's outputs and the json go")
    parser.add_argument("--h", type=int, default=8, help="the fine zone's element size is 1/this mm")
    parser.add_argument("--increments", type=int, default=20, help="the package's equal increments")
    parser.add_argument("--penalty", type=float, nargs="+", default=[100.0], help="CalculiX's penalty slopes, in E / h")
    parser.add_argument("--facet", type=float, nargs="+", default=[1.5], help="CalculiX's sphere facets (degrees)")
    parser.add_argument("--mu-f", type=float, default=0.0, help="Coulomb friction coefficient")
    parser.add_argument("--ours", action="store_true", help="solve the case with the package as well")
    parser.add_argument("--tag", default="", help="added to the json's name")
    parser.add_argument("--ccx-substeps", type=int, default=1, help="CalculiX's increments at most 1/this of ours")
    parser.add_argument("--material-point", action="store_true", help="only compare the two laws at one point")
    parser.add_argument("--plot", metavar="STEM", help="only draw the force and p of OUTDIR/STEM.json")
    args = parser.parse_args(argv)
    out = Path(args.outdir)
    out.mkdir(parents=True, exist_ok=True)
    if args.plot:
        plot(out, args.plot)
        return 0
    if args.material_point:
        (out / "material_points.json").write_text(json.dumps(material_points(out), indent=1))
        return 0
    h = 1.0 / args.h
    problem = deep_press_problem(h, args.mu_f)
    stem = f"deep_h{args.h}_n{args.increments}_mu{args.mu_f:g}"
    theirs, seconds = {}, {}
    for factor in args.penalty:
        for facet in args.facet:
            job = f"{stem}_k{factor:g}_f{facet:g}" + (f"_s{args.ccx_substeps}" if args.ccx_substeps > 1 else "")
            (out / f"{job}.inp").write_text(model_text(problem, args.increments, h=h, penalty_factor=factor,
                                                       facet=facet, mu_f=args.mu_f, substeps=args.ccx_substeps))
            seconds[job] = run_ccx(out, job)
            theirs[job] = ccx_results(out / f"{job}.dat", problem)
            print(f"CalculiX {job}: {len(theirs[job]['force'])} increments in {seconds[job]:.1f} s", flush=True)
    record: dict = {"h": h, "increments": args.increments, "mu_f": args.mu_f, "seconds": seconds,
                    "ccx": {job: {k: np.asarray(v).tolist() for k, v in r.items() if k in ("load_factor", "force", "max_p")}
                            for job, r in theirs.items()}}
    if args.ours:
        ours = run_ours(problem, args.increments)
        seconds["dolfinx_nnqem"] = ours["seconds"]
        print(f"dolfinx_nnqem: {len(ours['force'])} increments in {ours['seconds']:.1f} s, "
              f"Newton iterations {ours['iterations']}", flush=True)
        record["measures"] = {}
        for job, run in theirs.items():
            m = measures(run, ours)
            print(f"== {job}")
            print_measures(m, DEPTH / R_SPHERE * ours["load_factor"])
            record["measures"][job] = m
        record["iterations"] = ours["iterations"]
        record["1 - J at plastic points"] = ours["1 - J at plastic points"]
        print(f"1 − J at the package's plastic Gauss points at the end: {ours['1 - J at plastic points']}")
    (out / f"{stem}{args.tag}.json").write_text(json.dumps(record, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
