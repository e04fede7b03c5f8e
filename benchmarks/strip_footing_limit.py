"""Limit loads of a rigid strip footing (``cases.strip_footing``) against Prandtl and Prandtl–Reissner.

For each soil (von Mises, Drucker–Prager matched to Mohr–Coulomb in plane strain with φ = 10°,
20°, 30°), each footing (smooth, rough) and each mesh (``--n``: elements per footing half width),
the footing is pushed down in equal increments (displacement control) and the mean pressure under
it recorded; the limit pressure is the pressure at the last increment, with its rise over the
last 20 % of the settlement (:func:`~dolfinx_nnqem.cases.strip_footing.limit_pressure`; the
docs and the slow test accept a plateau below 0.1 %). Each run's curve and figures go to
``OUTDIR/footing_{soil}_{footing}_n{n}.json`` (``_psi{PSI}`` added with ``--dilatancy``); ``--plot`` draws the load–settlement curves and
the mesh convergence from every json in OUTDIR.

Usage::

    python benchmarks/strip_footing_limit.py OUTDIR [--soil vm dp10 dp20 dp30] [--footing smooth rough]
        [--n 2 4 8] [--increments 20] [--route contact] [--method monolithic] [--dilatancy PSI] [--plot]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from dolfinx_nnqem.cases import strip_footing as case

#: the settlement at ℓ = 1 (half widths) for each soil, E/c = 10⁶: past the plateau's start on every mesh
SETTLEMENTS = {"vm": 1.0e-4, "dp10": 1.5e-4, "dp20": 2.0e-4, "dp30": 3.5e-4}


def soil(name: str, dilatancy: float | None = None):
    """The material and its limit pressure: ``"vm"`` or ``"dp{φ}"`` (``dilatancy``: ψ, default φ)."""
    if name == "vm":
        return case.von_mises_soil(), case.prandtl()
    phi = float(name[2:])
    return case.drucker_prager_soil(phi, dilatancy_angle=dilatancy), case.prandtl_reissner(phi)


def run(name: str, footing: str, n: int, increments: int, route: str = "contact", method: str = "monolithic",
        law: str = "alart-curnier", dilatancy: float | None = None) -> dict:
    """One load–settlement curve and its limit pressure (``dilatancy``: ψ of a Drucker–Prager soil)."""
    from dolfinx_nnqem.io.results import pair_table
    from dolfinx_nnqem.solvers import SolverOptions, make_solver, solve_load_steps

    material, target = soil(name, dilatancy)
    settlement = SETTLEMENTS[name]
    problem = case.strip_footing_problem(material, n, footing=footing, route=route, settlement=settlement, law=law)
    rows, slipping = [], 0
    t0 = time.perf_counter()

    def record(result):
        nonlocal slipping
        rows.append((result.load_factor * settlement, case.footing_pressure(problem)))
        if problem.has_contact:
            slipping = max(slipping, int(np.sum(pair_table(problem)["state_name"] == "slip")))

    with make_solver(method, problem, SolverOptions(rtol=1e-9, max_iterations=60)) as solver:
        results = solve_load_steps(problem, solver, increments, callbacks=[record])
    d, q = np.array(rows).T
    limit, rise = case.limit_pressure(d, q)
    return {"soil": name, "footing": footing, "n": n, "increments": increments, "route": route, "method": method,
            "law": law, "dilatancy": dilatancy, "settlement": d.tolist(), "pressure": q.tolist(), "target": target, "limit": limit,
            "rise": rise, "error": limit / target - 1.0, "iterations": sum(r.iterations for r in results),
            "slipping_pairs": slipping, "dofs": problem.V.dofmap.index_map.size_global * 3,
            "seconds": time.perf_counter() - t0}


def plot(outdir: Path) -> None:
    """``footing_curves.png`` (q/c against the settlement, finest mesh) and ``footing_convergence.png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [r for r in (json.loads(p.read_text()) for p in sorted(outdir.glob("footing_*.json")))
            if r["route"] == "contact" and r.get("dilatancy") is None]
    soils = [s for s in SETTLEMENTS if any(r["soil"] == s for r in runs)]
    labels = {"vm": "von Mises", "dp10": "DP φ = 10°", "dp20": "DP φ = 20°", "dp30": "DP φ = 30°"}
    fig, axes = plt.subplots(1, len(soils), figsize=(3.6 * len(soils), 3.6), squeeze=False)
    for ax, s in zip(axes[0], soils):
        mine = [r for r in runs if r["soil"] == s]
        finest = max(r["n"] for r in mine)
        for r in sorted(mine, key=lambda r: (r["footing"], r["n"])):
            if r["n"] == finest:
                ax.plot(1e3 * np.array(r["settlement"]), np.array(r["pressure"]) / case.COHESION,
                        "o-" if r["footing"] == "smooth" else "s--", ms=3, label=f"{r['footing']}, n = {r['n']}")
        ax.axhline(mine[0]["target"] / case.COHESION, color="k", lw=0.8, label="Prandtl(–Reissner)")
        ax.set_title(labels[s])
        ax.set_xlabel("settlement d / b (×10⁻³)")
        ax.set_ylabel("q / c")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(outdir / "footing_curves.png", dpi=120)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for s in soils:
        for footing, style in (("smooth", "o-"), ("rough", "s--")):
            mine = sorted((r for r in runs if r["soil"] == s and r["footing"] == footing), key=lambda r: r["n"])
            if mine:
                ax.plot([r["n"] for r in mine], [100 * r["error"] for r in mine], style, label=f"{labels[s]}, {footing}")
    ax.axhspan(-2, 2, color="0.9", zorder=0)
    ax.set_xscale("log", base=2)
    ax.set_xlabel("elements per footing half width n (fine zone h = b/n)")
    ax.set_ylabel("limit pressure − closed form (%)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(outdir / "footing_convergence.png", dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("outdir")
    parser.add_argument("--soil", nargs="+", default=list(SETTLEMENTS), choices=list(SETTLEMENTS))
    parser.add_argument("--footing", nargs="+", default=["smooth", "rough"], choices=["smooth", "rough"])
    parser.add_argument("--n", type=int, nargs="+", default=[2, 4, 8])
    parser.add_argument("--increments", type=int, default=20)
    parser.add_argument("--route", default="contact", choices=["contact", "prescribed"])
    parser.add_argument("--method", default="monolithic")
    parser.add_argument("--dilatancy", type=float, default=None, help="ψ of the Drucker–Prager soils (default φ)")
    parser.add_argument("--plot", action="store_true", help="only draw the figures from OUTDIR's json files")
    args = parser.parse_args(argv)
    out = Path(args.outdir)
    out.mkdir(parents=True, exist_ok=True)
    if args.plot:
        plot(out)
        return 0
    for n in args.n:
        for name in args.soil:
            for footing in args.footing:
                r = run(name, footing, n, args.increments, args.route, args.method, dilatancy=args.dilatancy)
                suffix = ("" if args.route == "contact" else f"_{args.route}") + \
                    ("" if args.dilatancy is None else f"_psi{args.dilatancy:g}")
                (out / f"footing_{name}_{footing}_n{n}{suffix}.json").write_text(json.dumps(r, indent=1))
                print(f"{name:5s} {footing:6s} n = {n}: q/c = {r['limit'] / case.COHESION:.4f} (closed form "
                      f"{r['target'] / case.COHESION:.4f}, {100 * r['error']:+.2f} %), rise over the last 20 % "
                      f"{100 * r['rise']:.3f} %, {r['iterations']} iterations, {r['dofs']} dofs, slipping pairs "
                      f"{r['slipping_pairs']}, {r['seconds']:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
