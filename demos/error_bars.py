# ---
# jupyter:
#   jupytext:
#     formats: py:percent
# ---

# %% [markdown]
# # Every answer with its error bar: the two beams
#
# The seed's two beams on its 0.2 m trilinear mesh (the [first tutorial](two_beams.md)) give a
# free-end deflection that looks as certain as any other number. This demo asks the package how
# wrong it is, then refines until the estimated error of the deflection is under 1 %.
#
# It writes, in `--out` (default `results/error_bars`): `estimates.md` (the tables below) and
# `error_bars.png` (the deflection of each mesh with its error bar). It takes about ten minutes
# on two cores (the last mesh has 20 000 dofs at degree 2).

# %%
import argparse
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (before dolfinx: the PyPI wheel needs it)
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.cases.two_beams import FREE_END_CORNERS, two_beams_problem
from dolfinx_nnqem.estimates import estimate_errors, probe_points
from dolfinx_nnqem.estimates.adaptive import solve_adaptively
from dolfinx_nnqem.estimates.report import format_estimates
from dolfinx_nnqem.solvers import make_solver, solve_load_steps

parser = argparse.ArgumentParser(description="The two beams with their error bars, refined to 1 %")
parser.add_argument("--out", default="results/error_bars")
parser.add_argument("--target", type=float, default=0.01, help="relative error of the deflection to reach")
args, _ = parser.parse_known_args()
out = Path(args.out)
rank0 = MPI.COMM_WORLD.rank == 0
if rank0:
    out.mkdir(parents=True, exist_ok=True)
TIP = "beam1 x=2.0 y=0.0 z=0.0"  # beam 1's free end, bottom corner
probes = probe_points({TIP: FREE_END_CORNERS[TIP]})


def solve(problem, increments=15):
    """The seed's load path: 15 equal increments; returns the converged load factors."""
    with make_solver("monolithic", problem) as solver:
        return [r.load_factor for r in solve_load_steps(problem, solver, increments)]


# %% [markdown]
# ## The seed mesh, with its error bars
# `estimate_errors` solves the same load path again with degree-2 elements on the same mesh and
# reports, for every quantity a user reads (contact resultant, reactions, the probe's
# displacement, the largest plastic strain), the value ± |value − enriched value| and the method
# (`docs/error-estimates.md`). From the command line: `dolfinx-nnqem run demos/two_beams.toml
# --estimate`.

# %%
seed = two_beams_problem()
factors = solve(seed)
estimates = estimate_errors(seed, "monolithic", factors, probes=probes)
if rank0:
    print(format_estimates(estimates))

# %% [markdown]
# The deflection is 16 % short and the estimate says so (the converged value, from the
# refinement study of `docs/error-estimates.md`, is −1.3927 mm: the estimate's effectivity is
# 0.94). The largest plastic strain sits at a clamp's corner, where the stress is singular: it
# grows with every refinement and its estimate stays large; it is a number not to read off any
# mesh.
#
# ## Adaptivity needs tetrahedra
# The adaptive loop (`solve_adaptively`, `run --target-error`) refines marked cells with
# DOLFINx's `refine`, which splits simplices only. The beams are hexahedra, so it refuses, naming
# the reason:

# %%
try:
    solve_adaptively(two_beams_problem(), lambda problem, cycle: solve(problem), "monolithic", args.target)
except ValueError as error:
    if rank0:
        print(f"refused: {error}")

# %% [markdown]
# ## Refining the hexahedra with the mesh generator
# So the beams are refined uniformly by their gmsh generator (`two_beams_problem(refine=k)`
# divides the 0.2 m elements by k) and by the degree. Each candidate's estimate comes from the
# next, richer one, solved along the same load path: degree 2 on the same mesh for the seed mesh,
# then the same degree on the mesh the generator refines (`estimate_errors(...,
# enriched=finer)`: a degree-2 run on hexahedra has no automatic enrichment). The first candidate
# whose deflection estimate is under the target is the answer.

# %%
candidates = [(1, 1, None), (2, 1, (2, 2)), (2, 2, (2, 3))]  # (degree, refine, enriched by (degree, refine))
rows = []
for degree, refine, finer in candidates:
    problem = two_beams_problem(degree=degree, refine=refine)
    factors = solve(problem)
    enriched = None if finer is None else two_beams_problem(degree=finer[0], refine=finer[1])
    est = estimate_errors(problem, "monolithic", factors, probes=probes, enriched=enriched)
    q = est[f"u:{TIP}"]
    rows.append((degree, refine, est.dofs, 1e3 * q.value[1], 1e3 * q.components[1],
                 q.components[1] / abs(q.enriched[1]), est.method))
    if rank0:
        print(f"degree {degree}, 0.2/{refine} m: {est.dofs} dofs, u_y = {rows[-1][3]:.4f} ± {rows[-1][4]:.4f} mm "
              f"({100 * rows[-1][5]:.2f} %), {est.method}", flush=True)
    if enriched is not None:
        enriched.destroy()
    if rows[-1][5] < args.target:
        break

# %% [markdown]
# ## The deflections with their error bars

# %%
if rank0:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    dofs = [r[2] for r in rows]
    ax.errorbar(dofs, [r[3] for r in rows], yerr=[r[4] for r in rows], fmt="o", capsize=5,
                label="u_y at beam 1's free end ± estimate")
    ax.axhline(-1.3927, color="k", ls="--", lw=1, label="converged (refinement study)")
    for r in rows:
        ax.annotate(f"degree {r[0]}, h = 0.2/{r[1]} m\n{100 * r[5]:.2g} %", (r[2], r[3]), textcoords="offset points",
                    xytext=(8, -4), fontsize=8)
    ax.set_xscale("log")
    ax.set_xlim(min(dofs) / 1.5, 4 * max(dofs))
    ax.set_xlabel("displacement dofs")
    ax.set_ylabel("u_y (mm)")
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "error_bars.png", dpi=120)
    lines = ["| degree | h (m) | dofs | u_y (mm) | estimate (mm) | relative | method |", "|---|---|---|---|---|---|---|"]
    lines += [f"| {d} | 0.2/{k} | {n} | {u:.4f} | {e:.4f} | {100 * rel:.2f} % | {m} |" for d, k, n, u, e, rel, m in rows]
    (out / "estimates.md").write_text(format_estimates(estimates) + "\n\n" + "\n".join(lines) + "\n")
    print("\n".join(lines))

# %% [markdown]
# The seed mesh's answer is 16 % off and its bar says so; degree 2 on the same mesh is within
# 1 % (its estimate, from the mesh the generator refines once, is 0.75 %), which is the answer
# at the target: 3 150 dofs. Trilinear elements need the 0.05 m mesh (20 000 dofs) for 1.4 %.
