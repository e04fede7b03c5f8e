"""The ironing case as a CalculiX 2.20 model: an independent reference for its force history.

``cases.large_sliding.ironing(nx)`` presses a rigid cylinder into an elastoplastic strip and drags
it along x with friction (``docs/tutorials/ironing.md``). This script writes the same model for
CalculiX and compares the punch force histories of the two programs:

* the strip: the nodes and hexahedra of the package's own mesh (``build_block_stack`` as the case
  builds it), as C3D8 elements (full integration, like the package's 2×2×2 Gauss points);
* the material: elastic, von Mises with linear isotropic hardening. The package's ``H`` is the
  plastic modulus, σ_y = σ_y0 + H p with p the equivalent plastic strain (``VonMises``:
  Δp = f/(3μ + H)), so CalculiX's ``*PLASTIC`` table of (von Mises stress, equivalent plastic
  strain) is the straight line through (σ_y0, 0) and (σ_y0 + H p_max, p_max), p_max far beyond
  any strain reached (CalculiX holds the last stress beyond the table);
* the supports: the bottom clamped, u_z = 0 on the two z faces;
* the punch: a ring sector of C3D8 elements whose outer face is the cylinder (its nodes on the
  cylinder, its facets chords of it), tied by ``*RIGID BODY`` to a reference node on the axis;
  the reference node follows the case's own path d(ℓ) (``*AMPLITUDE`` tables of its points),
  the rotation node is held, and the reference node's reaction is the punch's force on the strip;
* the contact: penalty, ``PRESSURE-OVERCLOSURE=LINEAR`` with slope ``--penalty`` × E / h
  (h the strip's element edge along x) and Coulomb friction μ_f with the same stick slope; the
  strip's top is the slave, the punch's face the master; ``--contact`` chooses CalculiX's
  node-to-surface (the package's discretisation: one pair per slave node) or surface-to-surface;
* the load: the case's equal increments (``2.5 nx``, the tutorial's): CalculiX's automatic
  incrementation, its increments no longer than those and output at their ends (``*TIME
  POINTS``); small strain (no ``NLGEOM``: the package is small strain too; both search the
  contact in the deformed configuration).

With ``--ours`` the package solves its case on the same mesh and increments (monolithic, the
tutorial's options) and the two histories are printed side by side with the steady-ironing
means (punch at 1 ≤ x < 1.5), F_t / F_n, the peaks and the differences. ``--penalty`` takes several
factors: CalculiX is run once per factor, so the convergence of its answer as the penalty grows
shows what of the difference the penalty explains; ``--punch-facets`` does the same for the
faceting of CalculiX's punch, ``--increments`` for the load path's discretisation (both programs
integrate plasticity and friction by backward Euler, CalculiX over its own sub-increments), and
``--mu-f 0`` separates the normal contact from friction.

Usage::

    python benchmarks/calculix_ironing.py OUTDIR [--nx 16] [--penalty 50 500 5000]
        [--contact node-to-surface surface-to-surface] [--punch-facets 120] [--increments N]
        [--mu-f MU] [--ours]

Each CalculiX run writes ``OUTDIR/ironing_nx{nx}_{contact}_k{factor}_f{facets}[_mu{mu}].inp``
(and CalculiX's outputs next to it), and ``OUTDIR/ironing_nx{nx}[_mu{mu}].json`` holds every
history and measure. A run CalculiX cannot finish (it stops when its increment falls below
10⁻⁶ of the package's) is reported and left out.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from dolfinx_nnqem.cases.large_sliding import IRONING_MATERIAL

#: C3D8 node order from DOLFINx's hexahedron order (tensor-product: x fastest, then y, then z)
DOLFINX_TO_C3D8 = np.array([0, 1, 3, 2, 4, 5, 7, 6])
#: CalculiX's C3D8 faces S1..S6 (0-based node positions in the element)
C3D8_FACES = ((0, 1, 2, 3), (4, 7, 6, 5), (0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0))
PUNCH_ANGLE = np.deg2rad(30.0)  # the punch sector spans ± this about its lowest line
PUNCH_FACETS = 120  # facets over the sector: 0.5° each, sagitta 9.5e-6 R (1e-3 of the depth at R = 0.5)
PUNCH_THICKNESS = 0.1  # radial depth of the punch's elements, in radii (any value: the body is rigid)
PUNCH_OVERHANG = 0.05  # the punch's extent beyond each z face of the strip, in strip widths
P_MAX = 10.0  # the plastic strain at the end of the *PLASTIC table (far beyond any reached)
STEADY_FROM = 1.0  # steady ironing: punch axis at x ≥ this, up to (not at) the end of the drag
CONTACT_TYPES = {"node-to-surface": "NODE TO SURFACE", "surface-to-surface": "SURFACE TO SURFACE"}


# -- the model -------------------------------------------------------------------------------
def strip_elements(problem) -> tuple[np.ndarray, np.ndarray]:
    """The strip's node coordinates (n, 3) and C3D8 connectivity (m, 8), 0-based, from the mesh.

    Elements whose DOLFINx-to-C3D8 reordering comes out inside-out (negative volume) get their
    two z layers swapped, so that CalculiX's faces S1..S6 all face outwards.
    """
    from dolfinx_nnqem import compat

    coords = np.asarray(problem.mesh.geometry.x[:, :3], dtype=np.float64)
    cells = np.asarray(compat.geometry_dofmap(problem.mesh))[:, DOLFINX_TO_C3D8]
    return coords, outward(coords, cells)


def outward(coords: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """C3D8 connectivity with every element right-handed (positive Jacobian at its centre)."""
    x = coords[cells]
    a = x[:, 1] + x[:, 2] + x[:, 5] + x[:, 6] - x[:, 0] - x[:, 3] - x[:, 4] - x[:, 7]  # ∂x/∂ξ
    b = x[:, 2] + x[:, 3] + x[:, 6] + x[:, 7] - x[:, 0] - x[:, 1] - x[:, 4] - x[:, 5]  # ∂x/∂η
    c = x[:, 4:].sum(axis=1) - x[:, :4].sum(axis=1)  # ∂x/∂ζ
    flipped = np.einsum("ij,ij->i", np.cross(a, b), c) < 0.0
    cells = cells.copy()
    cells[flipped] = cells[flipped][:, [4, 5, 6, 7, 0, 1, 2, 3]]
    return cells


def faces_on(cells: np.ndarray, on: np.ndarray) -> list[tuple[int, int]]:
    """(element, face number 1..6) of the C3D8 faces whose four nodes all satisfy ``on`` (n,) bool."""
    return [(e, f + 1) for e in range(len(cells)) for f, face in enumerate(C3D8_FACES) if on[cells[e, list(face)]].all()]


def punch_elements(centre: np.ndarray, radius: float, z_range: tuple[float, float],
                   facets: int = PUNCH_FACETS) -> tuple[np.ndarray, np.ndarray]:
    """The punch's ring sector about its lowest line: coordinates and C3D8 connectivity (0-based).

    ``facets`` elements along the arc, one through the thickness and one along z; the
    outer nodes lie on the cylinder of ``radius`` about the axis through ``centre`` along z.
    """
    theta = -np.pi / 2 + np.linspace(-PUNCH_ANGLE, PUNCH_ANGLE, facets + 1)
    r = radius * np.array([1.0 - PUNCH_THICKNESS, 1.0])
    z = np.array(z_range)
    it, ir, iz = np.meshgrid(np.arange(len(theta)), np.arange(2), np.arange(2), indexing="ij")
    coords = np.column_stack([centre[0] + r[ir.ravel()] * np.cos(theta[it.ravel()]),
                              centre[1] + r[ir.ravel()] * np.sin(theta[it.ravel()]), z[iz.ravel()]])

    def node(i, j, k):
        return (i * 2 + j) * 2 + k

    cells = [[node(i, 0, 0), node(i + 1, 0, 0), node(i + 1, 1, 0), node(i, 1, 0),
              node(i, 0, 1), node(i + 1, 0, 1), node(i + 1, 1, 1), node(i, 1, 1)] for i in range(facets)]
    return coords, outward(coords, np.array(cells))


def plastic_table(sigma_y0: float, H: float) -> list[tuple[float, float]]:
    """CalculiX's ``*PLASTIC`` rows (von Mises stress, equivalent plastic strain) of σ_y0 + H p."""
    return [(sigma_y0, 0.0), (sigma_y0 + H * P_MAX, P_MAX)]


def model_text(problem, nx: int, increments: int, *, penalty_factor: float, contact: str,
               punch_facets: int = PUNCH_FACETS) -> str:
    """The whole ``.inp`` text of the case ``problem`` (``cases.large_sliding.ironing(nx)``)."""
    interface = problem.contact.interfaces[0].contact
    punch, mu_f = interface.obstacle, float(interface.mu_f)
    material = IRONING_MATERIAL  # the case gives this one material to the whole strip
    coords, cells = strip_elements(problem)
    lo, hi = coords.min(axis=0), coords.max(axis=0)
    h = (hi[0] - lo[0]) / nx
    width = hi[2] - lo[2]
    centre = np.asarray(punch.point, dtype=np.float64)
    p_coords, p_cells = punch_elements(centre, float(punch.radius),
                                       (lo[2] - PUNCH_OVERHANG * width, hi[2] + PUNCH_OVERHANG * width), punch_facets)
    n_strip = len(coords)
    all_coords = np.vstack([coords, p_coords, [centre[0], centre[1], 0.5 * (lo[2] + hi[2])], centre])
    ref, rot = n_strip + len(p_coords) + 1, n_strip + len(p_coords) + 2  # 1-based ids
    all_cells = np.vstack([cells, p_cells + n_strip])
    n_el = len(cells)
    top = faces_on(cells, np.isclose(coords[:, 1], hi[1]))
    p_radius = np.linalg.norm(p_coords[:, :2] - centre[:2], axis=1)
    face = faces_on(p_cells, np.isclose(p_radius, punch.radius))

    lines = ["*HEADING", f"dolfinx_nnqem ironing, nx = {nx}: rigid cylinder dragged along an elastoplastic strip",
             "*NODE"]
    lines += [f"{i + 1}, {x:.12e}, {y:.12e}, {z:.12e}" for i, (x, y, z) in enumerate(all_coords)]
    lines.append("*ELEMENT, TYPE=C3D8, ELSET=STRIP")
    lines += [f"{e + 1}, " + ", ".join(str(n + 1) for n in all_cells[e]) for e in range(n_el)]
    lines.append("*ELEMENT, TYPE=C3D8, ELSET=PUNCH")
    lines += [f"{e + 1}, " + ", ".join(str(n + 1) for n in all_cells[e]) for e in range(n_el, len(all_cells))]
    lines += node_set("BOTTOM", np.flatnonzero(np.isclose(coords[:, 1], lo[1])) + 1)
    lines += node_set("ZFACES", np.flatnonzero(np.isclose(coords[:, 2], lo[2]) | np.isclose(coords[:, 2], hi[2])) + 1)
    lines += node_set("REF", [ref]) + node_set("ROT", [rot])
    lines += ["*SURFACE, NAME=STRIPTOP, TYPE=ELEMENT"] + [f"{e + 1}, S{f}" for e, f in top]
    lines += ["*SURFACE, NAME=PUNCHFACE, TYPE=ELEMENT"] + [f"{e + 1 + n_el}, S{f}" for e, f in face]
    stiffness = penalty_factor * material.E / h
    lines += material_lines(material)
    lines += [f"*RIGID BODY, ELSET=PUNCH, REF NODE={ref}, ROT NODE={rot}"]
    lines += contact_lines(contact, stiffness, mu_f, material.sigma_y0)
    lines += amplitudes(punch.motion.points)
    lines += ["*BOUNDARY", "BOTTOM, 1, 3", "ZFACES, 3, 3", "ROT, 1, 3", f"{ref}, 3, 3"]
    lines += step_lines(ref, increments)
    return "\n".join(lines) + "\n"


def material_lines(material) -> list[str]:
    """The strip's von Mises material, and a stiff elastic one for the punch (rigid anyway)."""
    lines = ["*MATERIAL, NAME=STRIP", "*ELASTIC", f"{material.E:.12e}, {material.nu}", "*PLASTIC"]
    lines += [f"{s:.12e}, {p:.12e}" for s, p in plastic_table(material.sigma_y0, material.H)]
    return lines + ["*MATERIAL, NAME=PUNCH", "*ELASTIC", f"{1e3 * material.E:.6e}, 0.3",
                    "*SOLID SECTION, ELSET=STRIP, MATERIAL=STRIP", "*SOLID SECTION, ELSET=PUNCH, MATERIAL=PUNCH"]


def contact_lines(contact: str, stiffness: float, mu_f: float, sigma_y0: float) -> list[str]:
    """The penalty contact of the strip's top (slave) on the punch's face (master).

    ``stiffness``: the pressure-overclosure slope, and the stick slope of the friction.
    """
    behaviour = f"{stiffness:.6e}"
    if contact == "node-to-surface":  # its tension at large clearances: a thousandth of σ_y0 (default E/70000)
        behaviour += f", {1e-3 * sigma_y0:.6e}"
    return ["*SURFACE INTERACTION, NAME=IRONING", "*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=LINEAR", behaviour,
            *(["*FRICTION", f"{mu_f}, {stiffness:.6e}"] if mu_f > 0 else []),  # ccx refuses μ = 0
            f"*CONTACT PAIR, INTERACTION=IRONING, TYPE={CONTACT_TYPES[contact]}", "STRIPTOP, PUNCHFACE"]


def step_lines(ref: int, increments: int) -> list[str]:
    """The step: the reference node on its path, output at the ends of the package's increments.

    Automatic incrementation, never longer than the package's increments and ending on each of
    them (the time points): with fixed increments the contact of a node crossing a punch facet
    can cycle between states and ccx stops.
    """
    ends = [f"{k / increments:.12g}" for k in range(1, increments + 1)]
    lines = ["*TIME POINTS, NAME=INCREMENTS"] + [", ".join(ends[k:k + 8]) for k in range(0, len(ends), 8)]
    dt = 1.0 / increments
    return lines + [f"*STEP, INC={100 * increments}", "*STATIC", f"{dt:.12g}, 1.0, {1e-6 * dt:.6g}, {dt:.12g}",
                    "*BOUNDARY, AMPLITUDE=DX", f"{ref}, 1, 1, 1.0", "*BOUNDARY, AMPLITUDE=DY", f"{ref}, 2, 2, 1.0",
                    "*NODE PRINT, NSET=REF, TIME POINTS=INCREMENTS", "RF",
                    "*NODE FILE, TIME POINTS=INCREMENTS", "U", "*EL FILE, TIME POINTS=INCREMENTS", "PEEQ",
                    "*END STEP"]


def amplitudes(path_points) -> list[str]:
    """``*AMPLITUDE`` tables DX and DY: the punch path's x and y displacements against ℓ."""
    table = np.asarray(path_points, dtype=np.float64)
    lines = []
    for name, column in (("DX", 1), ("DY", 2)):
        lines.append(f"*AMPLITUDE, NAME={name}")
        lines += [f"{ell:.12g}, {d:.12g}" for ell, d in table[:, [0, column]]]
    return lines


def node_set(name: str, ids) -> list[str]:
    ids = [str(int(i)) for i in ids]
    return [f"*NSET, NSET={name}"] + [", ".join(ids[k:k + 8]) for k in range(0, len(ids), 8)]


# -- running and reading ---------------------------------------------------------------------
def run_ccx(outdir: Path, job: str) -> float:
    """Run ``ccx -i job`` in ``outdir`` on one thread; its wall time (s). Raises if it fails."""
    ccx = shutil.which("ccx")
    if ccx is None:
        raise FileNotFoundError("no ccx on PATH (Debian: apt-get install calculix-ccx)")
    env = dict(os.environ, OMP_NUM_THREADS="1", CCX_NPROC_EQUATION_SOLVER="1")
    t0 = time.perf_counter()
    done = subprocess.run([ccx, "-i", job], check=False, cwd=outdir, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    log = outdir / f"{job}.log"
    log.write_text(done.stdout + done.stderr)
    if done.returncode != 0 or "*ERROR" in done.stdout:
        raise RuntimeError(f"ccx failed on {job} (see {log}): " + _first_error(done.stdout + done.stderr))
    return seconds


def _first_error(text: str) -> str:
    errors = [line.strip() for line in text.splitlines() if "ERROR" in line]
    return errors[0] if errors else text.strip().splitlines()[-1] if text.strip() else "no output"


def read_reaction_history(dat: Path) -> np.ndarray:
    """(load factor, F_x, F_y, F_z) of every increment: the REF node's reaction in ``.dat``.

    The reaction holding the punch on its path balances the strip's force on the punch, so it
    is the punch's force on the strip, the package's ``obstacle_force``.
    """
    rows, current_time = [], None
    for line in dat.read_text().splitlines():
        words = line.split()
        if line.strip().startswith("forces") and "time" in words:
            current_time = float(words[-1])
        elif current_time is not None and len(words) == 4 and words[0].isdigit():
            rows.append([current_time, *(float(w) for w in words[1:])])
            current_time = None
    return np.array(rows)


def run_ours(problem, increments: int) -> tuple[np.ndarray, float]:
    """(load factor, F_x, F_y, F_z) of every increment of the package's solve, and its wall time."""
    from dolfinx_nnqem.cases.large_sliding import obstacle_force
    from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

    rows = []

    def record(result):
        rows.append([result.load_factor, *obstacle_force(problem)])

    t0 = time.perf_counter()
    with make_solver("monolithic", problem, SolverOptions(rtol=1e-10, max_iterations=40)) as solver:
        solve_load_steps(problem, solver, increments, callbacks=[record])
    return np.array(rows), time.perf_counter() - t0


# -- the comparison --------------------------------------------------------------------------
def punch_x(history: np.ndarray, punch) -> np.ndarray:
    """The punch axis's x at every row of a history (its rest position plus the path's x)."""
    table = np.asarray(punch.motion.points, dtype=np.float64)
    return punch.point[0] + np.interp(history[:, 0], table[:, 0], table[:, 1])


def measures(history: np.ndarray, x: np.ndarray) -> dict[str, float]:
    """Steady-ironing means, ratio, pulses and peaks of a history.

    F_n = −F_y (pressing down), F_t = F_x (dragged along +x). The means are over the increments
    ending with the punch at ``STEADY_FROM`` ≤ x < x_end: the force pulses with the period of
    one facet as the punch crosses nodes, and this half-open window holds whole periods when
    its length is a whole number of facets (0.5 = nx/4 facets), where a closed one would count
    one phase twice (on the coarse mesh it moves the mean by more than the differences sought).
    """
    steady = (x >= STEADY_FROM - 1e-9) & (x < x[-1] - 1e-9)
    fn, ft = -history[:, 2], history[:, 1]
    return {"mean F_n": float(fn[steady].mean()), "mean F_t": float(ft[steady].mean()),
            "F_t / F_n": float(ft[steady].mean() / fn[steady].mean()),
            "F_n pulse (peak to peak)": float(np.ptp(fn[steady])),
            "peak F_n": float(fn.max()), "peak F_t": float(ft.max()), "increments": len(history)}


def print_histories(histories: dict[str, np.ndarray], x: np.ndarray) -> None:
    """The histories side by side: F_n = −F_y and F_t = F_x of each run against the punch position."""
    for k, name in enumerate(histories, start=1):
        print(f"[{k}] {name}")
    print("   ell       x" + "".join(f"{f'F_n[{k}]':>11s}{f'F_t[{k}]':>11s}" for k in range(1, len(histories) + 1)))
    for i in range(len(x)):
        print(f"{next(iter(histories.values()))[i, 0]:6.4f} {x[i]:7.4f}"
              + "".join(f"{-h[i, 2]:11.6f}{h[i, 1]:11.6f}" for h in histories.values()))


def print_measures(table: dict[str, dict[str, float]], reference: str | None) -> None:
    """The measures of every history, and each one's difference from ``reference``."""
    keys = list(next(iter(table.values())))
    print(f"{'':30s}" + "".join(f"{k:>14s}" for k in keys[:-1]))
    for name, m in table.items():
        print(f"{name:30s}" + "".join(f"{m[k]:14.5f}" for k in keys[:-1]))
    if reference is None:
        return
    for name, m in table.items():
        if name != reference:
            rel = "".join(f"{(m[k] - table[reference][k]) / abs(table[reference][k]):+14.2%}"
                          if table[reference][k] else f"{'-':>14s}" for k in keys[:-1])
            print(f"{name + ' vs ' + reference:30s}{rel}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("outdir", help="where the .inp files, CalculiX's outputs and the json go")
    parser.add_argument("--nx", type=int, default=16, help="elements along the strip (the case's nx)")
    parser.add_argument("--penalty", type=float, nargs="+", default=[500.0],
                        help="CalculiX's normal (and stick) penalty slopes, in E / h")
    parser.add_argument("--contact", nargs="+", default=["node-to-surface"], choices=list(CONTACT_TYPES))
    parser.add_argument("--mu-f", type=float, default=None,
                        help="friction coefficient (default: the case's); 0 isolates the normal contact")
    parser.add_argument("--punch-facets", type=int, default=PUNCH_FACETS,
                        help="facets of CalculiX's punch over its sector (the faceting's share of the difference)")
    parser.add_argument("--increments", type=int, default=None,
                        help="equal increments of the package (CalculiX's longest increment): default 2.5 nx")
    parser.add_argument("--ours", action="store_true", help="solve the case with the package as well")
    parser.add_argument("--write-only", action="store_true", help="write the .inp files, run nothing")
    args = parser.parse_args(argv)
    from mpi4py import MPI

    from dolfinx_nnqem.cases.large_sliding import ironing

    out = Path(args.outdir)
    out.mkdir(parents=True, exist_ok=True)
    problem = ironing(args.nx, comm=MPI.COMM_SELF, **({} if args.mu_f is None else {"mu_f": args.mu_f}))
    # the tutorial's 2.5 nx: the punch moves 0.4 facets per increment
    increments = args.increments or int(2.5 * args.nx)
    punch = problem.contact.interfaces[0].contact.obstacle
    tag = "" if args.mu_f is None else f"_mu{args.mu_f:g}"
    histories: dict[str, np.ndarray] = {}
    seconds: dict[str, float] = {}
    for contact in args.contact:
        for factor in args.penalty:
            job = f"ironing_nx{args.nx}_{contact}_k{factor:g}_f{args.punch_facets}" + tag
            (out / f"{job}.inp").write_text(model_text(problem, args.nx, increments, penalty_factor=factor,
                                                       contact=contact, punch_facets=args.punch_facets))
            if args.write_only:
                print(f"wrote {out / job}.inp")
                continue
            name = f"ccx {contact} K={factor:g}E/h" + ("" if args.punch_facets == PUNCH_FACETS
                                                          else f" {args.punch_facets} facets")
            try:
                seconds[name] = run_ccx(out, job)
            except RuntimeError as error:  # a stiffer penalty may not converge: say so, go on
                print(f"{name}: {error}", flush=True)
                continue
            histories[name] = read_reaction_history(out / f"{job}.dat")
            print(f"{name}: {len(histories[name])} increments in {seconds[name]:.1f} s", flush=True)
    if args.write_only:
        return 0
    reference = None
    if args.ours:
        reference = "dolfinx_nnqem"
        histories[reference], seconds[reference] = run_ours(problem, increments)
        print(f"{reference}: {len(histories[reference])} increments in {seconds[reference]:.1f} s", flush=True)
    lengths = {len(h) for h in histories.values()}
    if len(lengths) != 1:
        raise RuntimeError(f"the histories have different lengths {lengths}: some run did not finish")
    x = punch_x(next(iter(histories.values())), punch)
    print_histories(histories, x)
    table = {name: measures(h, x) for name, h in histories.items()}
    print_measures(table, reference)
    (out / f"ironing_nx{args.nx}{tag}.json").write_text(json.dumps(
        {"nx": args.nx, "increments": increments, "measures": table, "seconds": seconds,
         "histories": {n: h.tolist() for n, h in histories.items()}}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
