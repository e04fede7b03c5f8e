"""A rigid sphere pressed into a block and lifted off, as a CalculiX 2.20 model: the hardening laws checked.

``cases.sphere_press.sphere_press_problem(h, material, cycles)`` presses a frictionless rigid sphere
(R = 400 mm) 5 µm into an annealed-copper block and lifts it back, ``cycles`` times; the block
hardens by a table (isotropic), by Prager's linear kinematic rule, or by both
(``docs/verification-materials.md``). This script writes the same model for CalculiX and compares
the sphere's force at the peaks, the block's residual depth at the first point of contact after
each lift, and the equivalent plastic strain at every Gauss point of the fine zone:

* the block: the package's own mesh (:func:`~dolfinx_nnqem.cases.geometries.build_graded_block`) as
  C3D8 elements (2×2×2 Gauss points, like the package's);
* the materials (the parameters mapped exactly, ``CalculiX.tex``, ``*PLASTIC`` and
  ``incplas.f``): ``"table"`` is ``*PLASTIC`` with the table's rows; ``"kinematic"`` is
  ``*PLASTIC, HARDENING=KINEMATIC`` with the rows (σ_y0, 0), (σ_y0 + C p_max, p_max): CalculiX
  keeps the first row's stress as the yield stress and moves the centre of the yield surface by
  the table's increase, Δq(α) = Δσ_kin = C Δp, which is Prager's α̇ = (2/3) C ε̇_p;
  ``"combined"`` is ``HARDENING=COMBINED`` with that kinematic line and the combined law's
  isotropic table as ``*CYCLIC HARDENING``;
* the supports: the bottom clamped, u_x = 0 on x = 0 and u_z = 0 on z = 0 (symmetry);
* the sphere: a cap of C3D8 elements whose outer nodes lie on the sphere (a grid of
  ``--facet`` mm in x and z over the contact zone, chords of the sphere), tied by ``*RIGID
  BODY`` to a reference node at its centre; that node goes down and up by the case's path (one
  ``*STEP`` per press or lift, the boundary ramped in each) and its reaction is the force;
* the contact: node-to-surface penalty, ``PRESSURE-OVERCLOSURE=LINEAR`` with slope ``--penalty``
  × E / h (h the block's finest element), the block's top the slave; frictionless (the case's);
* the increments: CalculiX's automatic incrementation, never longer than the package's equal
  increments and output at their ends (``*TIME POINTS``);
* ``NLGEOM`` by default: CalculiX's kinematic and combined hardening are right only in its
  finite-strain model (``incplas.f``); ``--small-strain`` drops it (isotropic hardening is right
  in both, so the table's run with and without shows what the finite-strain model changes).

With ``--ours`` the package solves its case on the same mesh and increments (monolithic,
rtol 1e-10) and the measures are printed side by side with their differences. ``--penalty``
takes several factors (CalculiX run once per factor), ``--facet`` several facet sizes.

Usage::

    python benchmarks/calculix_sphere_press.py OUTDIR [--material table kinematic combined]
        [--cycles 1] [--h 6] [--increments 10] [--penalty 500] [--facet 0.05] [--small-strain] [--ours] [--tag T]
    python benchmarks/calculix_sphere_press.py OUTDIR --plot STEM [STEM ...]   # the force histories

Each CalculiX run writes ``OUTDIR/sphere_{material}_c{cycles}_h{1/h}_n{increments}_k{factor}_f{facet}[_lin].inp``
(and CalculiX's outputs next to it); ``OUTDIR/sphere_{material}_c{cycles}_h{1/h}_n{increments}{tag}.json`` holds every
history and measure.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path

import numpy as np

from calculix_ironing import faces_on, node_set, outward, run_ccx, strip_elements
from dolfinx_nnqem.cases import sphere_press as case

P_MAX = 10.0  # the plastic strain at the end of the kinematic line (far beyond any reached)
CAP_THICKNESS = 0.2  # mm: the radial depth of the sphere's elements (any value: the body is rigid)
CAP_EXTENT = 2.5  # mm: the cap covers x, z ≤ this (the contact radius stays below 2)


# -- the model -------------------------------------------------------------------------------
def cap_elements(radius: float, facet: float) -> tuple[np.ndarray, np.ndarray]:
    """The sphere's cap over x, z ∈ [−facet, CAP_EXTENT]: coordinates and C3D8 connectivity (0-based).

    Its outer nodes lie on the sphere of ``radius`` about (0, radius, 0) above a square grid of
    spacing ``facet``; its inner ones on the radii through them, ``CAP_THICKNESS`` inwards. One
    facet beyond the symmetry planes, so that the block's nodes on them lie inside the surface.
    """
    n = int(np.ceil(CAP_EXTENT / facet))
    s = facet * np.arange(-1, n + 1)
    ix, iz = np.meshgrid(np.arange(len(s)), np.arange(len(s)), indexing="ij")
    x, z = s[ix.ravel()], s[iz.ravel()]
    centre = np.array([0.0, radius, 0.0])
    outer = np.column_stack([x, radius - np.sqrt(radius ** 2 - x ** 2 - z ** 2), z])
    inner = centre + (outer - centre) * (radius - CAP_THICKNESS) / radius
    coords = np.vstack([outer, inner])
    m, k = len(s), len(outer)

    def node(i, j):
        return i * m + j

    cells = [[node(i, j), node(i + 1, j), node(i + 1, j + 1), node(i, j + 1),
              node(i, j) + k, node(i + 1, j) + k, node(i + 1, j + 1) + k, node(i, j + 1) + k]
             for i in range(m - 1) for j in range(m - 1)]
    return coords, outward(coords, np.array(cells))


def plastic_lines(material: str) -> list[str]:
    """The ``*PLASTIC`` (and ``*CYCLIC HARDENING``) cards of one of the case's materials."""
    table = [f"{s:.12e}, {p:.12e}" for s, p in case.TABLE]
    sigma_y0, c = case.TABLE[0][0], case.C_KINEMATIC  # the kinematic and the combined law start there too
    kinematic = [f"{sigma_y0:.12e}, 0.0", f"{sigma_y0 + c * P_MAX:.12e}, {P_MAX:.12e}"]
    if material == "table":
        return ["*PLASTIC"] + table
    if material == "kinematic":
        return ["*PLASTIC, HARDENING=KINEMATIC"] + kinematic
    if material == "combined":
        return (["*PLASTIC, HARDENING=COMBINED"] + kinematic + ["*CYCLIC HARDENING"]
                + [f"{s:.12e}, {p:.12e}" for s, p in case.TABLE_COMBINED])
    raise ValueError(f"material = {material!r}; expected one of {list(case.MATERIALS)}")


def press_mesh_lines(heading: str, coords: np.ndarray, cells: np.ndarray, c_coords: np.ndarray, c_cells: np.ndarray,
                     radius: float, fine_width: float, fine_depth: float, marked: list[str]) -> tuple[list[str], int]:
    """The mesh cards of a block (``coords``, ``cells``: its C3D8 elements) under a rigid sphere's cap
    (``c_coords``, ``c_cells``, :func:`cap_elements`; the sphere of ``radius`` about (0, radius, 0)),
    from ``*HEADING`` to the two contact surfaces; (lines, ref): the rigid body's reference node
    ``ref`` and rotation node ``ref + 1`` (1-based) follow the cap's nodes.

    Sets: BLOCK and SPHERE (elements), FINE (the block's elements with x, z < ``fine_width`` and
    within ``fine_depth`` of the top), BOTTOM, XSYM, ZSYM, the node-set lines ``marked``, REF, ROT;
    surfaces BLOCKTOP and SPHEREFACE (the cap's outer faces).
    """
    lo, hi = coords.min(axis=0), coords.max(axis=0)
    n_block, n_el = len(coords), len(cells)
    centre = [0.0, radius, 0.0]
    all_coords = np.vstack([coords, c_coords, centre, centre])
    ref, rot = n_block + len(c_coords) + 1, n_block + len(c_coords) + 2  # 1-based ids
    all_cells = np.vstack([cells, c_cells + n_block])
    top = faces_on(cells, np.isclose(coords[:, 1], hi[1]))
    face = faces_on(c_cells, np.isclose(np.linalg.norm(c_coords - centre, axis=1), radius))
    centroid = coords[cells].mean(axis=1)
    fine = np.flatnonzero((centroid[:, 0] < fine_width) & (centroid[:, 2] < fine_width)
                          & (centroid[:, 1] > -fine_depth))

    lines = ["*HEADING", heading, "*NODE"]
    lines += [f"{i + 1}, {x:.12e}, {y:.12e}, {z:.12e}" for i, (x, y, z) in enumerate(all_coords)]
    lines.append("*ELEMENT, TYPE=C3D8, ELSET=BLOCK")
    lines += [f"{e + 1}, " + ", ".join(str(n + 1) for n in all_cells[e]) for e in range(n_el)]
    lines.append("*ELEMENT, TYPE=C3D8, ELSET=SPHERE")
    lines += [f"{e + 1}, " + ", ".join(str(n + 1) for n in all_cells[e]) for e in range(n_el, len(all_cells))]
    lines += ["*ELSET, ELSET=FINE"] + [", ".join(str(e + 1) for e in fine[k:k + 8]) for k in range(0, len(fine), 8)]
    lines += node_set("BOTTOM", np.flatnonzero(np.isclose(coords[:, 1], lo[1])) + 1)
    lines += node_set("XSYM", np.flatnonzero(np.isclose(coords[:, 0], lo[0])) + 1)
    lines += node_set("ZSYM", np.flatnonzero(np.isclose(coords[:, 2], lo[2])) + 1)
    lines += marked + node_set("REF", [ref]) + node_set("ROT", [rot])
    lines += ["*SURFACE, NAME=BLOCKTOP, TYPE=ELEMENT"] + [f"{e + 1}, S{f}" for e, f in top]
    lines += ["*SURFACE, NAME=SPHEREFACE, TYPE=ELEMENT"] + [f"{e + 1 + n_el}, S{f}" for e, f in face]
    return lines, ref


def model_text(problem, material: str, cycles: int, increments: int, *, h: float, penalty_factor: float,
               facet: float, nlgeom: bool = True) -> str:
    """The whole ``.inp`` text of ``case.sphere_press_problem(h, material, cycles)``.

    ``increments``: the package's equal increments per press and per lift.
    """
    coords, cells = strip_elements(problem)
    c_coords, c_cells = cap_elements(case.R_SPHERE, facet)
    centre = np.flatnonzero(np.linalg.norm(coords, axis=1) < 1e-9)
    lines, ref = press_mesh_lines(f"dolfinx_nnqem sphere press, {material} hardening, {cycles} cycle(s), h = {h:g} mm",
                                  coords, cells, c_coords, c_cells, case.R_SPHERE, case.FINE_WIDTH, case.FINE_DEPTH,
                                  node_set("CENTRE", centre + 1))
    rot = ref + 1
    lines += ["*MATERIAL, NAME=BLOCK", "*ELASTIC", f"{case.E:.12e}, {case.NU}"] + plastic_lines(material)
    lines += ["*MATERIAL, NAME=RIGID", "*ELASTIC", f"{1e3 * case.E:.6e}, 0.3",
              "*SOLID SECTION, ELSET=BLOCK, MATERIAL=BLOCK", "*SOLID SECTION, ELSET=SPHERE, MATERIAL=RIGID",
              f"*RIGID BODY, ELSET=SPHERE, REF NODE={ref}, ROT NODE={rot}"]
    # node-to-surface's tension at large clearances: a thousandth of σ_y0 (the default is E/70000)
    lines += ["*SURFACE INTERACTION, NAME=PRESS", "*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=LINEAR",
              f"{penalty_factor * case.E / h:.6e}, {1e-3 * case.TABLE[0][0]:.6e}",
              "*CONTACT PAIR, INTERACTION=PRESS, TYPE=NODE TO SURFACE", "BLOCKTOP, SPHEREFACE"]
    lines += ["*BOUNDARY", "BOTTOM, 1, 3", "XSYM, 1, 1", "ZSYM, 3, 3", "ROT, 1, 3", f"{ref}, 1, 1", f"{ref}, 3, 3"]
    ends = [f"{k / increments:.12g}" for k in range(1, increments + 1)]
    lines += ["*TIME POINTS, NAME=INCREMENTS"] + [", ".join(ends[k:k + 8]) for k in range(0, len(ends), 8)]
    for leg in range(2 * cycles):
        lines += step_lines(ref, increments, -case.DEPTH if leg % 2 == 0 else 0.0, nlgeom)
    return "\n".join(lines) + "\n"


def step_lines(ref: int, increments: int, y: float, nlgeom: bool) -> list[str]:
    """One press or lift: the reference node ramped to ``y``, output at the package's increments.

    Automatic incrementation, never longer than the package's increments and ending on each
    of them (the time points).
    """
    dt = 1.0 / increments
    return [f"*STEP, INC={1000 * increments}" + (", NLGEOM" if nlgeom else ""), "*STATIC",
            f"{dt:.12g}, 1.0, {1e-6 * dt:.6g}, {dt:.12g}", "*BOUNDARY", f"{ref}, 2, 2, {y:.12e}",
            "*NODE PRINT, NSET=REF, TIME POINTS=INCREMENTS", "RF",
            "*NODE PRINT, NSET=CENTRE, TIME POINTS=INCREMENTS", "U",
            "*EL PRINT, ELSET=FINE, TIME POINTS=INCREMENTS", "PEEQ, COORD", "*END STEP"]


# -- reading ---------------------------------------------------------------------------------
def read_dat(dat: Path) -> dict[str, list]:
    """CalculiX's ``.dat`` blocks by kind: ``forces`` (time, F (3,)), ``displacements`` (time, u (3,))
    and ``peeq`` (time, elements, points, values), ``coords`` (time, elements, points, x (n, 3))."""
    kinds = {"forces": "forces", "displacements": "displacements", "equivalent plastic strain": "peeq",
             "global coordinates": "coords"}
    out: dict[str, list] = {k: [] for k in kinds.values()}
    kind, t, rows = None, 0.0, []

    def close():
        if kind is not None:
            out[kind].append((t, np.array(rows)))

    for line in dat.read_text().splitlines():
        head = re.match(r"^\s*([a-z ]+?)\s*\(.*time\s+(\S+)\s*$", line)
        if head:
            close()
            kind = next((v for k, v in kinds.items() if head.group(1).startswith(k)), None)
            t, rows = float(head.group(2)), []
        elif kind is not None and line.split() and line.split()[0].isdigit():
            rows.append([float(w) for w in line.split()])
    close()
    return out


def ccx_results(dat: Path, increments: int, cycles: int) -> dict:
    """The CalculiX run's histories at the package's load factors ℓ = total time / (2 cycles)."""
    blocks = read_dat(dat)
    legs = 2 * cycles
    force = np.array([[t / legs, -case.SYMMETRY * r[0, 2]] for t, r in blocks["forces"]])
    depth = np.array([-r[0, 2] for _, r in blocks["displacements"]])
    peeq = [r for _, r in blocks["peeq"]]
    coords = blocks["coords"][0][1]
    points = coords[:, 2:5]
    order = np.lexsort((coords[:, 1], coords[:, 0]))
    return {"load_factor": force[:, 0], "force": force[:, 1], "depth": depth,
            "points": points[order], "p": np.array([v[np.lexsort((v[:, 1], v[:, 0])), 2] for v in peeq])}


# -- the package -----------------------------------------------------------------------------
def gauss_points(problem) -> np.ndarray:
    """The Gauss points' coordinates (n, 3), in the order of ``problem.state.p_n``'s owned values."""
    import ufl

    x = ufl.SpatialCoordinate(problem.mesh)
    return np.column_stack([problem.state.values_at_points(x[i]) for i in range(3)])


def run_ours(problem, increments: int, cycles: int, method: str = "monolithic") -> dict:
    """The package's histories: force, depth and p at every Gauss point, at every increment."""
    from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

    rows, p = [], []
    n = problem.state.p_n.function_space.dofmap.index_map.size_local

    def record(result):
        rows.append([result.load_factor, case.indentation_force(problem), case.surface_depth(problem)])
        p.append(problem.state.p_n.x.array[:n].copy())

    t0 = time.perf_counter()
    with make_solver(method, problem, SolverOptions(rtol=1e-10, max_iterations=40)) as solver:
        solve_load_steps(problem, solver, 2 * cycles * increments, callbacks=[record])
    history = np.array(rows)
    return {"load_factor": history[:, 0], "force": history[:, 1], "depth": history[:, 2],
            "points": gauss_points(problem), "p": np.array(p), "seconds": time.perf_counter() - t0}


# -- the comparison --------------------------------------------------------------------------
def on_ours(theirs: dict, ours: dict) -> np.ndarray:
    """For each of CalculiX's fine-zone points, the index of the package's Gauss point at it."""
    from scipy.spatial import cKDTree

    distance, index = cKDTree(ours["points"]).query(theirs["points"])
    if distance.max() > 1e-3 * case.FINE_WIDTH:  # NLGEOM's COORD are the deformed points: µm off
        raise RuntimeError(f"CalculiX's integration points are {distance.max():.3g} mm from the package's")
    return index


def measures(run: dict, increments: int, cycles: int, index: np.ndarray | None = None) -> dict[str, list[float]]:
    """Per cycle: the force at the peak, the depth after the lift, max p at the peak and after it.

    ``index`` picks the fine zone's points out of the package's (CalculiX prints only those).
    """
    peaks = [(2 * k + 1) * increments - 1 for k in range(cycles)]
    lifts = [(2 * k + 2) * increments - 1 for k in range(cycles)]
    p = run["p"] if index is None else run["p"][:, index]
    return {"peak force": [float(run["force"][i]) for i in peaks],
            "residual depth": [float(run["depth"][i]) for i in lifts],
            "max p at peak": [float(p[i].max()) for i in peaks],
            "max p after lift": [float(p[i].max()) for i in lifts]}


def point_differences(theirs: dict, ours: dict, index: np.ndarray, increments: int, cycles: int) -> list[float]:
    """max |p_ccx − p_ours| / max p_ours over the fine zone's points at the end of each lift."""
    lifts = [(2 * k + 2) * increments - 1 for k in range(cycles)]
    return [float(np.abs(theirs["p"][i] - ours["p"][i][index]).max() / ours["p"][i][index].max()) for i in lifts]


def print_measures(table: dict[str, dict[str, list[float]]], reference: str | None) -> None:
    keys = list(next(iter(table.values())))
    for key in keys:
        print(f"{key}:")
        for name, m in table.items():
            text = "  ".join(f"{v:.6g}" for v in m[key])
            if reference is not None and name != reference:
                text += "   (" + ", ".join(f"{(v - r) / abs(r):+.3%}" for v, r in zip(m[key], table[reference][key])) + ")"
            print(f"  {name:36s} {text}")


def plot(outdir: Path, stems: list[str]) -> None:
    """``sphere_press_forces.png``: force against the sphere's travel, the package's and CalculiX's
    (the first CalculiX run of each json), one panel per json stem."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(stems), figsize=(4.2 * len(stems), 3.8), squeeze=False)
    for ax, stem in zip(axes[0], stems):
        data = json.loads((outdir / f"{stem}.json").read_text())
        path = case.press_path(data["cycles"])
        runs = data["histories"]
        ccx_name = next(n for n in runs if n.startswith("ccx"))
        for name, style, label in (("dolfinx_nnqem", "-", "dolfinx_nnqem"), (ccx_name, "o", "CalculiX 2.20")):
            ell = np.concatenate([[0.0], runs[name]["load_factor"]])
            travel = [-1e3 * path(e)[1] for e in ell]
            ax.plot(travel, np.concatenate([[0.0], runs[name]["force"]]), style, ms=4, mfc="none", label=label)
        ax.set_title(f"{data['material']}, {data['cycles']} cycle(s)")
        ax.set_xlabel("sphere travel (µm)")
        ax.set_ylabel("force (N)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(outdir / "sphere_press_forces.png", dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("outdir", help="where the .inp files, CalculiX's outputs and the json go")
    parser.add_argument("--material", nargs="+", default=["table"], choices=list(case.MATERIALS))
    parser.add_argument("--cycles", type=int, default=1, help="presses and lifts")
    parser.add_argument("--h", type=int, default=6, help="the fine zone's element size is 1/this mm")
    parser.add_argument("--increments", type=int, default=10, help="the package's equal increments per press and per lift")
    parser.add_argument("--penalty", type=float, nargs="+", default=[500.0], help="CalculiX's penalty slopes, in E / h")
    parser.add_argument("--facet", type=float, nargs="+", default=[0.05], help="CalculiX's sphere facets (mm)")
    parser.add_argument("--small-strain", action="store_true", help="CalculiX without NLGEOM")
    parser.add_argument("--ours", action="store_true", help="solve the case with the package as well")
    parser.add_argument("--write-only", action="store_true", help="write the .inp files, run nothing")
    parser.add_argument("--tag", default="", help="added to the json's name (several studies in one OUTDIR)")
    parser.add_argument("--plot", nargs="+", metavar="STEM", help="only draw the forces of OUTDIR/STEM.json files")
    args = parser.parse_args(argv)
    from mpi4py import MPI

    out = Path(args.outdir)
    out.mkdir(parents=True, exist_ok=True)
    if args.plot:
        plot(out, args.plot)
        return 0
    h = 1.0 / args.h
    for material in args.material:
        problem = case.sphere_press_problem(h, material, args.cycles, comm=MPI.COMM_SELF)
        runs: dict[str, dict] = {}
        seconds: dict[str, float] = {}
        stem = f"sphere_{material}_c{args.cycles}_h{args.h}_n{args.increments}"
        for factor in args.penalty:
            for facet in args.facet:
                job = f"{stem}_k{factor:g}_f{facet:g}" + ("_lin" if args.small_strain else "")
                (out / f"{job}.inp").write_text(model_text(problem, material, args.cycles, args.increments, h=h,
                                                           penalty_factor=factor, facet=facet,
                                                           nlgeom=not args.small_strain))
                if args.write_only:
                    print(f"wrote {out / job}.inp")
                    continue
                name = f"ccx K={factor:g}E/h facet {facet:g}" + (" small strain" if args.small_strain else "")
                try:
                    seconds[name] = run_ccx(out, job)
                except RuntimeError as error:  # a stiffer penalty may not converge: say so, go on
                    print(f"{material}, {name}: {error}", flush=True)
                    continue
                runs[name] = ccx_results(out / f"{job}.dat", args.increments, args.cycles)
                print(f"{material}, {name}: {len(runs[name]['force'])} increments in {seconds[name]:.1f} s", flush=True)
        if args.write_only:
            continue
        reference, index = None, None
        if args.ours:
            reference = "dolfinx_nnqem"
            runs[reference] = run_ours(problem, args.increments, args.cycles)
            seconds[reference] = runs[reference].pop("seconds")
            print(f"{material}, {reference}: {len(runs[reference]['force'])} increments in {seconds[reference]:.1f} s")
            index = on_ours(next(iter(runs.values())), runs[reference]) if len(runs) > 1 else None
        table = {name: measures(r, args.increments, args.cycles, index if name == reference else None)
                 for name, r in runs.items()}
        print(f"== {material}, {args.cycles} cycle(s), h = 1/{args.h} mm, {args.increments} increments per leg")
        print_measures(table, reference)
        points = {}
        if index is not None:
            for name, r in runs.items():
                if name != reference:
                    points[name] = point_differences(r, runs[reference], index, args.increments, args.cycles)
                    print(f"  p at every fine-zone point after each lift, {name}: max |difference| / max p = "
                          + ", ".join(f"{v:.3%}" for v in points[name]))
        (out / f"{stem}{args.tag}.json").write_text(json.dumps(
            {"material": material, "cycles": args.cycles, "h": h, "increments": args.increments, "measures": table,
             "points": points, "seconds": seconds,
             "histories": {n: {k: np.asarray(r[k]).tolist() for k in ("load_factor", "force", "depth")}
                           for n, r in runs.items()}}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
