"""Necking of a cylindrical bar (Simo's benchmark, issue 41): the force–elongation curve and the neck's
radius at finite strain, on three meshes, and the same meshes in CalculiX 2.20 ``NLGEOM``.

The case (``docs/verification-materials.md``, "Necking of a cylindrical bar", gives the sources of the
figures): the eighth of the bar of ``meshes/necking_bar_mesh.py`` (radius 6.413 mm, length 53.334 mm, the
radius reduced linearly to 0.982 of it at mid-length), 10-node tetrahedra, P2 displacements. The
symmetry planes x = 0, y = 0 and the mid-length plane z = 0 on rollers; the end z = L/2 gripped:
u_x = u_y = 0 and u_z raised to 7 mm (the whole bar is stretched 14 mm). Von Mises with the
saturating-plus-linear hardening σ_y = σ_0 + (σ_∞ − σ_0)(1 − e^{−δ p}) + H p, E = 206.9 GPa, ν = 0.29,
σ_0 = 450 MPa, σ_∞ = 715 MPa, δ = 16.93, H = 129.24 MPa (``VoceHardening``). The package solves it with
``kinematics = "finite"`` (Hencky's law in the logarithmic strain, the return map on the Kirchhoff
stress, by the exponential map) and the monolithic solver, in equal increments. The Gauss rule is
the 4-point one (``quadrature_degree = 2``), CalculiX's for C3D10, unless ``--quadrature-degree``
says otherwise.

CalculiX's model on the same mesh: the same nodes, C3D10 elements (4 Gauss points), ``*ELASTIC``,
``*PLASTIC`` with the hardening tabulated (``TABLE_P``: linear interpolation between rows), ``NLGEOM``
(Simo's multiplicative plasticity: ``benchmarks/calculix_deep_sphere_press.py`` says how its law
differs from the package's), increments of the package's size at most, output at its increments.

The measures at every increment: the whole bar's axial force (4 × the reaction on the gripped end of
the quarter section), the neck's radius (the node at (0.982 R0, 0, 0)) over its initial radius, and
the radius at z = L/4 over its own.

Usage::

    python benchmarks/necking_bar.py OUTDIR [--meshes coarse medium fine] [--increments 56] [--ccx]
        [--ccx-substeps 1] [--ccx-reuse] [--quadrature-degree 2] [--min-shape-ratio 0.002] [--tag T]
    python benchmarks/necking_bar.py OUTDIR --plot   # necking_bar.png from OUTDIR/necking_{mesh}.json
    python benchmarks/necking_bar.py OUTDIR --summary   # the mesh convergence table from the same

Each mesh's run writes ``OUTDIR/necking_{mesh}{T}.json``; with ``--ccx`` also CalculiX's ``.inp`` and outputs.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "meshes"))
import necking_bar_mesh as geometry  # noqa: E402
from calculix_ironing import node_set, run_ccx  # noqa: E402
from calculix_sphere_press import read_dat  # noqa: E402

E, NU = 206.9e3, 0.29  # MPa
SIGMA_0, SIGMA_INF, DELTA, H_LIN = 450.0, 715.0, 16.93, 129.24  # MPa, MPa, -, MPa
MIN_SHAPE_RATIO = 0.002  # the check's bound on a deformed cell's shape (the default 0.05 stops the neck: docs)
STRETCH = 7.0  # mm: the end's axial displacement (the whole bar: 14 mm)
SYMMETRY = 4  # the quarter cross-section
#: the plastic strains of CalculiX's *PLASTIC rows, to 3 (far beyond reach), spaced as p = 3 s² for equal steps
#: of s: dense where the Voce term bends. CalculiX keeps at most 200 rows per temperature (its local table
#: ``plconloc(802)``: 200 pairs) and resamples a longer table, so 200 it is.
TABLE_P = 3.0 * np.linspace(0.0, 1.0, 200) ** 2
#: C3D10 node order from DOLFINx's P2 tetrahedron order (vertices, then the edges (2,3), (1,3), (1,2),
#: (0,3), (0,2), (0,1)); C3D10's: vertices, then (0,1), (1,2), (2,0), (0,3), (1,3), (2,3)
DOLFINX_TO_C3D10 = np.array([0, 1, 2, 3, 9, 6, 8, 7, 5, 4])


def hardening():
    """The benchmark's σ_y(p) (MPa)."""
    from dolfinx_nnqem.material import VoceHardening

    return VoceHardening(sigma_0=SIGMA_0, Q=SIGMA_INF - SIGMA_0, b=DELTA, H=H_LIN)


# -- the case --------------------------------------------------------------------------------
def necking_problem(h_neck: float, h_end: float, quadrature_degree: int | None = 2, *,
                    comm: MPI.Comm = MPI.COMM_SELF, kinematics: str = "finite"):
    """The eighth of the bar (module docstring) on :func:`necking_bar_mesh.build_necking_bar`'s mesh
    (``kinematics="small"``: the same problem at small strain, ``benchmarks/small_strain_limit.py``)."""
    from dolfinx_nnqem.material import VonMises
    from dolfinx_nnqem.problem import ContactProblem, Dirichlet

    T = geometry.NeckingBarTags
    mesh, cell_tags, facet_tags = geometry.build_necking_bar(comm, h_neck, h_end)
    dirichlet = [Dirichlet(T.END, (0.0, 0.0, STRETCH)), Dirichlet(T.SYMMETRY_X, 0.0, [0]),
                 Dirichlet(T.SYMMETRY_Y, 0.0, [1]), Dirichlet(T.MIDDLE, 0.0, [2])]
    return ContactProblem(mesh, cell_tags, facet_tags, materials=VonMises(E=E, nu=NU, hardening=hardening()),
                          dirichlet=dirichlet, kinematics=kinematics, degree=2, quadrature_degree=quadrature_degree)


def watched_nodes(X: np.ndarray) -> tuple[int, int]:
    """The rows of ``X`` (node coordinates) of the neck's outer node (0.982 R0, 0, 0) and of the
    outer node on y = 0 nearest z = L/4."""
    neck = int(np.argmin(np.linalg.norm(X - [geometry.radius_at(0.0), 0.0, 0.0], axis=1)))
    on_surface = np.flatnonzero((np.abs(X[:, 1]) < 1e-9) & (np.abs(X[:, 0] - geometry.radius_at(X[:, 2])) < 1e-6))
    quarter = int(on_surface[np.argmin(np.abs(X[on_surface, 2] - 0.25 * geometry.LENGTH))])
    if np.linalg.norm(X[neck] - [geometry.radius_at(0.0), 0.0, 0.0]) > 1e-9:
        raise RuntimeError(f"no node at the neck's surface point; nearest {X[neck]}")
    return neck, quarter


# -- the package -----------------------------------------------------------------------------
def run_ours(problem, increments: int, min_shape_ratio: float = MIN_SHAPE_RATIO, final: float = 1.0) -> dict:
    """The package's history: elongation (mm), force (N), the two radius ratios; times and iterations.
    ``increments`` equal increments to the full stretch, up to the fraction ``final`` of it. A run that
    stops early keeps the increments it converged and says why under ``"stopped"``."""
    from dolfinx_nnqem.io.results import reactions
    from dolfinx_nnqem.solvers import CheckOptions, ConvergenceError, SolverOptions, make_solver, solve_load_steps

    X = problem.V.tabulate_dof_coordinates()
    neck, quarter = watched_nodes(X)
    rows, iterations, shape = [], [], []
    end = geometry.NeckingBarTags.END

    def record(result):
        u = problem.u.x.array.reshape(-1, 3)
        rows.append([2.0 * STRETCH * result.load_factor, SYMMETRY * reactions(problem)[end][2],
                     1.0 + u[neck, 0] / X[neck, 0], 1.0 + u[quarter, 0] / X[quarter, 0]])
        iterations.append(int(result.iterations))
        shape.append(float(result.check.min_shape_ratio))

    wall, cpu = time.perf_counter(), time.process_time()
    stopped = None
    try:
        with make_solver("monolithic", problem, SolverOptions(rtol=1e-10, max_iterations=40)) as solver:
            solve_load_steps(problem, solver, round(increments * final), final_load_factor=final, callbacks=[record],
                             check=CheckOptions(min_shape_ratio=min_shape_ratio))
    except ConvergenceError as error:
        stopped = str(error).splitlines()[0]
    history = np.array(rows)
    J = np.linalg.det(problem.state.F_n.x.array.reshape(-1, 3, 3))  # at the Gauss points, at the end
    return {"stopped": stopped, "J range": [float(J.min()), float(J.max())], "elongation": history[:, 0].tolist(), "force": history[:, 1].tolist(),
            "neck ratio": history[:, 2].tolist(), "quarter ratio": history[:, 3].tolist(),
            "iterations": iterations, "min shape ratio": shape, "wall seconds": time.perf_counter() - wall,
            "cpu seconds": time.process_time() - cpu, "dofs": int(X.shape[0] * 3),
            "cells": int(problem.mesh.topology.index_map(3).size_global), "max p": float(problem.state.p_n.x.array.max())}


# -- CalculiX --------------------------------------------------------------------------------
def c3d10_elements(problem) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's nodes (n, 3) and C3D10 connectivity (m, 10), 0-based; every element right-handed."""
    from dolfinx_nnqem import compat

    coords = np.asarray(problem.mesh.geometry.x[:, :3], dtype=np.float64)
    cells = np.asarray(compat.geometry_dofmap(problem.mesh))[:, DOLFINX_TO_C3D10].copy()
    x = coords[cells]
    volume = np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0])
    flipped = volume < 0.0  # swap vertices 1 and 2: the edges (0,1)↔(2,0) and (1,3)↔(2,3) follow
    cells[flipped] = cells[flipped][:, [0, 2, 1, 3, 6, 5, 4, 7, 9, 8]]
    x = coords[cells]
    midpoints = 0.5 * (x[:, [0, 1, 2, 0, 1, 2]] + x[:, [1, 2, 0, 3, 3, 3]])
    if np.abs(x[:, 4:] - midpoints).max() > 0.05 * geometry.R0:  # curved edges bow a little, never more
        raise RuntimeError("the C3D10 reordering does not put the edge nodes on their edges")
    return coords, cells


def model_text(problem, increments: int, final: float = 1.0, substeps: int = 1) -> str:
    """The whole ``.inp`` of the case on ``problem``'s mesh to the fraction ``final`` of the stretch,
    output at the package's ``increments`` (equal increments to the full stretch); CalculiX's own
    increments at most 1/``substeps`` of them (its return map's error depends on the increment)."""
    coords, cells = c3d10_elements(problem)
    neck, quarter = watched_nodes(coords)
    lines = ["*HEADING", "dolfinx_nnqem necking bar", "*NODE"]
    lines += [f"{i + 1}, {x:.12e}, {y:.12e}, {z:.12e}" for i, (x, y, z) in enumerate(coords)]
    lines.append("*ELEMENT, TYPE=C3D10, ELSET=BAR")
    lines += [f"{e + 1}, " + ", ".join(str(n + 1) for n in cells[e]) for e in range(len(cells))]
    half = 0.5 * geometry.LENGTH
    lines += node_set("XSYM", np.flatnonzero(np.abs(coords[:, 0]) < 1e-9) + 1)
    lines += node_set("YSYM", np.flatnonzero(np.abs(coords[:, 1]) < 1e-9) + 1)
    lines += node_set("MID", np.flatnonzero(np.abs(coords[:, 2]) < 1e-9) + 1)
    lines += node_set("GRIP", np.flatnonzero(np.abs(coords[:, 2] - half) < 1e-9) + 1)
    lines += node_set("WATCH", [neck + 1, quarter + 1])
    sigma = hardening().yield_stress(TABLE_P)
    lines += ["*MATERIAL, NAME=STEEL", "*ELASTIC", f"{E:.12e}, {NU}", "*PLASTIC"]
    lines += [f"{s:.12e}, {p:.12e}" for s, p in zip(sigma, TABLE_P)]
    lines += ["*SOLID SECTION, ELSET=BAR, MATERIAL=STEEL",
              "*BOUNDARY", "XSYM, 1, 1", "YSYM, 2, 2", "MID, 3, 3", "GRIP, 1, 2"]
    n = round(increments * final)  # CalculiX's time runs to 1 over the n increments: ℓ = final · time
    ends = [f"{k / n:.12g}" for k in range(1, n + 1)]
    lines += ["*TIME POINTS, NAME=INCREMENTS"] + [", ".join(ends[k:k + 8]) for k in range(0, len(ends), 8)]
    dt = 1.0 / (n * substeps)
    lines += [f"*STEP, INC={1000 * n * substeps}, NLGEOM", "*STATIC", f"{dt:.12g}, 1.0, {1e-6 * dt:.6g}, {dt:.12g}",
              "*BOUNDARY", f"GRIP, 3, 3, {final * STRETCH:.12e}",
              "*NODE PRINT, NSET=GRIP, TIME POINTS=INCREMENTS", "RF",
              "*NODE PRINT, NSET=WATCH, TIME POINTS=INCREMENTS", "U", "*END STEP"]
    return "\n".join(lines) + "\n"


def ccx_history(dat: Path, problem, final: float = 1.0) -> dict:
    """CalculiX's history, as :func:`run_ours`'s: the grip's summed reaction, the watched nodes' radii."""
    coords, _ = c3d10_elements(problem)
    neck, quarter = watched_nodes(coords)
    blocks = read_dat(dat)
    force = np.array([[t, SYMMETRY * r[:, 3].sum()] for t, r in blocks["forces"]])
    ratios = []
    for _, u in blocks["displacements"]:
        by_node = {int(row[0]) - 1: row[1:4] for row in u}
        ratios.append([1.0 + by_node[n][0] / coords[n, 0] for n in (neck, quarter)])
    ratios_arr = np.array(ratios)
    return {"elongation": (2.0 * STRETCH * final * force[:, 0]).tolist(), "force": force[:, 1].tolist(),
            "neck ratio": ratios_arr[:, 0].tolist(), "quarter ratio": ratios_arr[:, 1].tolist()}


def run_calculix(problem, increments: int, outdir: Path, job: str, final: float = 1.0, reuse: bool = False,
                 substeps: int = 1) -> dict:
    """Write and run CalculiX's model of ``problem`` (as :func:`model_text`); its history and wall time.
    ``reuse``: read the outputs of an earlier run of the very same ``.inp`` instead (no time then)."""
    text = model_text(problem, increments, final, substeps)
    inp = outdir / f"{job}.inp"
    if reuse and inp.exists() and inp.read_text() == text and (outdir / f"{job}.dat").exists():
        seconds = float("nan")
    else:
        inp.write_text(text)
        seconds = run_ccx(outdir, job)
    history = ccx_history(outdir / f"{job}.dat", problem, final)
    history["wall seconds"] = seconds
    return history


# -- reporting -------------------------------------------------------------------------------
def print_history(name: str, ours: dict, theirs: dict | None) -> None:
    """The curve, increment by increment, and CalculiX's with the differences if there."""
    print(f"== {name}: {ours['cells']} tetrahedra, {ours['dofs']} dofs, {ours['wall seconds']:.0f} s wall, "
          f"{ours['cpu seconds']:.0f} s CPU, Newton iterations {sum(ours['iterations'])}; largest p {ours['max p']:.3f}; "
          f"smallest deformed/undeformed cell shape {min(ours['min shape ratio'], default=float('nan')):.4f}; "
          f"J at the end {ours['J range'][0]:.5f} to {ours['J range'][1]:.5f}")
    head = f"{'Δl (mm)':>8} {'F (kN)':>9} {'a/a0':>7} {'a(L/4)':>7}"
    if theirs is not None:
        head += f" {'F ccx':>9} {'ΔF/F':>8} {'a/a0 ccx':>9}"
    print(head)
    for k, dl in enumerate(ours["elongation"]):
        line = f"{dl:8.3f} {ours['force'][k] / 1e3:9.3f} {ours['neck ratio'][k]:7.4f} {ours['quarter ratio'][k]:7.4f}"
        if theirs is not None and k < len(theirs["force"]):
            f_c = theirs["force"][k]
            line += f" {f_c / 1e3:9.3f} {(f_c - ours['force'][k]) / ours['force'][k]:+8.3%} {theirs['neck ratio'][k]:9.4f}"
        print(line)
    if ours["stopped"]:
        print(f"stopped: {ours['stopped']}")


def plot(outdir: Path, figure: Path) -> None:
    """The force and the neck's radius ratio against the elongation, every mesh's (and CalculiX's)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(9.6, 3.8))
    for colour, name in enumerate(geometry.MESHES):
        path = outdir / f"necking_{name}.json"
        if not path.exists():
            continue
        run = json.loads(path.read_text())
        for ax, key, scale in ((left, "force", 1e-3), (right, "neck ratio", 1.0)):
            ours = run["ours"]
            ax.plot([0.0] + ours["elongation"], [0.0 if key == "force" else 1.0] + [v * scale for v in ours[key]],
                    "-", color=f"C{colour}", label=f"dolfinx_nnqem, {name} ({ours['dofs']} dofs)")
            if "ccx" in run:
                ccx = run["ccx"]
                ax.plot(ccx["elongation"], [v * scale for v in ccx[key]], "o", ms=3, mfc="none", color=f"C{colour}",
                        label=f"CalculiX 2.20 NLGEOM, {name}")
    left.set_ylabel("axial force (kN)")
    right.set_ylabel("neck radius / initial neck radius")
    for ax in (left, right):
        ax.set_xlabel("elongation (mm)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(figure, dpi=120)
    plt.close(fig)


def summary(outdir: Path, at: tuple[float, ...] = (3.5, 7.0, 10.5, 14.0)) -> None:
    """The mesh convergence and the agreement with CalculiX, from OUTDIR/necking_{mesh}.json: the peak
    force and where it is, the force and the neck's radius ratio at the elongations ``at``."""
    print(f"{'mesh':>11} {'dofs':>6} {'peak F (kN)':>11} {'at (mm)':>7} "
          + " ".join(f"{'F ' + format(a, 'g'):>8} {'a/a0 ' + format(a, 'g'):>9}" for a in at) + "   CPU (s)")
    for name in geometry.MESHES:
        path = outdir / f"necking_{name}.json"
        if not path.exists():
            continue
        run = json.loads(path.read_text())
        for label, h in (("", run["ours"]), (" ccx", run.get("ccx"))):
            if h is None:
                continue
            dl, force, ratio = np.array(h["elongation"]), np.array(h["force"]) / 1e3, np.array(h["neck ratio"])
            k = int(np.argmax(force))
            cells = " ".join(f"{force[np.argmin(abs(dl - a))]:8.3f} {ratio[np.argmin(abs(dl - a))]:9.4f}" for a in at)
            dofs = h.get("dofs", "")
            print(f"{name + label:>11} {dofs:>6} {force[k]:11.3f} {dl[k]:7.2f} {cells}   {h.get('cpu seconds', float('nan')):.0f}")
        if "ccx" in run:
            f_o, f_c = np.array(run["ours"]["force"]), np.array(run["ccx"]["force"])
            d = (f_c - f_o) / f_o
            print(f"{'':>11} CalculiX − package: force {d.min():+.3%} to {d.max():+.3%} (peak {f_c.max() / f_o.max() - 1:+.3%}), "
                  f"neck ratio {np.abs(np.array(run['ccx']['neck ratio']) - run['ours']['neck ratio']).max():.4f} at most")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("outdir", type=Path)
    parser.add_argument("--meshes", nargs="+", default=["coarse"], choices=sorted(geometry.MESHES))
    parser.add_argument("--increments", type=int, default=56, help="equal increments to the full 14 mm")
    parser.add_argument("--quadrature-degree", type=int, default=2, help="the package's Gauss rule (2: 4 points)")
    parser.add_argument("--ccx", action="store_true", help="run CalculiX on the same meshes too")
    parser.add_argument("--ccx-substeps", type=int, default=1, help="CalculiX's increments at most 1/this of ours")
    parser.add_argument("--ccx-reuse", action="store_true",
                        help="with --ccx: read CalculiX's outputs of an earlier run of the same .inp in OUTDIR")
    parser.add_argument("--min-shape-ratio", type=float, default=MIN_SHAPE_RATIO,
                        help="the check's smallest deformed/undeformed scaled Jacobian of a cell")
    parser.add_argument("--tag", default="", help="added to the json's name (the figure draws untagged runs)")
    parser.add_argument("--plot", action="store_true", help="only draw OUTDIR/necking_bar.png from the json files")
    parser.add_argument("--summary", action="store_true", help="only print the convergence table from the json files")
    args = parser.parse_args(argv)
    args.outdir.mkdir(parents=True, exist_ok=True)
    if args.plot:
        plot(args.outdir, args.outdir / "necking_bar.png")
        return 0
    if args.summary:
        summary(args.outdir)
        return 0
    for name in args.meshes:
        problem = necking_problem(*geometry.MESHES[name], quadrature_degree=args.quadrature_degree)
        record: dict = {"mesh": name, "h": geometry.MESHES[name], "increments": args.increments,
                        "quadrature_degree": args.quadrature_degree, "min_shape_ratio": args.min_shape_ratio}
        theirs = None
        if args.ccx:
            job = f"necking_{name}" + (f"_s{args.ccx_substeps}" if args.ccx_substeps > 1 else "")
            theirs = record["ccx"] = run_calculix(problem, args.increments, args.outdir, job, reuse=args.ccx_reuse,
                                                  substeps=args.ccx_substeps)
            record["ccx substeps"] = args.ccx_substeps
            print(f"CalculiX {name}: {theirs['wall seconds']:.0f} s", flush=True)
        record["ours"] = run_ours(problem, args.increments, args.min_shape_ratio)
        print_history(name, record["ours"], theirs)
        (args.outdir / f"necking_{name}{args.tag}.json").write_text(json.dumps(record, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
