# ---
# jupyter:
#   jupytext:
#     formats: py:percent
# ---

# %% [markdown]
# # Hertz contact on independent meshes: a sphere on a block
#
# A steel sphere (radius R = 20 mm, E = 210 GPa, ν = 0.3) is pressed on an aluminium block
# (E = 70 GPa, ν = 0.33). Unlike `demos/hertz_contact.py`, where two blocks with coincident
# interface nodes are given the sphere's gap as a formula, here the sphere is a real sphere:
# both bodies are meshed with tetrahedra **each on its own**, so the nodes of the two contact
# surfaces do not face each other, and the interface is discretised by **dual mortar**.
#
# Hertz's solution for two elastic bodies (frictionless; the contact radius small against R and
# against the block):
#
# $$ \frac{1}{E^*} = \frac{1 - \nu_1^2}{E_1} + \frac{1 - \nu_2^2}{E_2}, \qquad
#    a = \left(\frac{3FR}{4E^*}\right)^{1/3}, \qquad p(r) = p_0\sqrt{1 - r^2/a^2},
#    \qquad p_0 = \frac{3F}{2\pi a^2}. $$
#
# Outputs, in `--out` (default `results/sphere_on_block`): `fields.xdmf`, `pairs.pvd`,
# `summary.json` (the run), `hertz.json` (the comparison below), `contact_pressure.png`,
# `pressure_profile.png` and `deformed.png`.
#
# Run: `python demos/sphere_on_block.py [--out DIR] [--elements-per-a 7]` (serially or with
# `mpirun -n 2`). `docs/nonmatching-hertz.md` discusses the figures.

# %%
import argparse
import json
import time
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (before dolfinx: the PyPI wheel needs it)
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.io import ResultsWriter
from dolfinx_nnqem.io.plots import plot_contact_pressure, plot_deformed
from dolfinx_nnqem.solvers import SolverOptions, make_solver
from dolfinx_nnqem.cases.sphere_on_block import (A_NOMINAL, APPROACH, BLOCK, E_STAR, R_SPHERE, measure_sphere_on_block,
                                           sphere_on_block_problem)
from dolfinx_nnqem.solvers import solve_load_steps

parser = argparse.ArgumentParser(description="Hertz contact on independent meshes: a sphere on a block")
parser.add_argument("--out", default="results/sphere_on_block")
parser.add_argument("--elements-per-a", type=float, default=7, help="element size at the contact h = a / this")
args, _ = parser.parse_known_args()
out = Path(args.out)
comm = MPI.COMM_WORLD
h = A_NOMINAL / args.elements_per_a

# %% [markdown]
# ## Two meshes, made apart
# `build_sphere_on_block` makes a quarter of the model (x ≥ 0, z ≥ 0: the planes x = 0 and
# z = 0 are symmetry planes) with gmsh's OpenCASCADE kernel: the quarter block, x and z in
# [0, 10] mm, y in [−10, 0] mm, and the quarter hemisphere, centre (0, R, 0), whose pole touches
# the block's top at the origin with zero gap. The two solids are never fragmented together, so
# gmsh meshes each on its own: no node is shared, and the surface meshes of the block's top and
# of the sphere do not match. One gmsh size field, of the distance d from the contact point,
# grades both bodies alike: h within 1.5 mm, growing by 0.3 mm per mm beyond. The sphere's cap
# within 2 mm of the axis is a volume of its own, so that its curved surface is the contact
# surface (tag 22) and the block's top the other one (tag 21).
#
# The supports: the block's bottom is clamped, the symmetry planes carry u_x = 0 or u_z = 0,
# and the sphere's flat equatorial face is pushed down by δ = 0.046 mm (u_y prescribed, the
# other components free), which gives a ≈ 1 mm. The force follows from the solution.
#
# `Contact(21, 22, discretisation="mortar")` makes the dual mortar pairs: every slave node j
# gets one pair with the weighted gap and the weights c_jk = M_jk / D_jj of the master nodes it
# faces. The slave is the finer side by default (smaller mean facet area): here the sphere's
# cap. The contact pressure at slave node j is its pair force divided by D_jj = ∫ N_j dA.

# %%
t0 = time.perf_counter()
problem = sphere_on_block_problem(h, comm)
if comm.rank == 0:
    print(f"h = a/{args.elements_per_a:g} = {h:.4f} mm: {problem.mesh.topology.index_map(3).size_global} tetrahedra, "
          f"{3 * problem.V.dofmap.index_map.size_global} displacement dofs")
    for line in problem.contact.describe():
        print(line)

# %% [markdown]
# ## Solve
# The monolithic semismooth Newton solver, in one increment (the problem is elastic and
# frictionless; the active set is found by the Newton iteration itself).

# %%
writer = ResultsWriter(problem, "monolithic", out, 1)
with make_solver("monolithic", problem, SolverOptions(rtol=1e-10)) as solver:
    results = solve_load_steps(problem, solver, 1, callbacks=[writer])
writer.close()
wall = time.perf_counter() - t0

# %% [markdown]
# ## Against Hertz
# The quarter model carries a quarter of the force: F = 4 Σ p_n over the pairs. Hertz is
# evaluated at this F, with E* of both bodies. Three measurements:
#
# - **a**: the radius of the Hertz pressure (for the measured F) whose nodal forces ∫ p N_j dA
#   best fit the pair forces (least squares, `hertz.measure_hertz`): the outermost closed node
#   alone would be up to an element off;
# - **p0**: the pressure of the centre node (the sphere's pole), f / D;
# - **p0 (fit)**: a and p0 fitted together to all pair forces. On unstructured tetrahedra the
#   nodal pressures scatter by a few per cent from node to node, the centre node's included:
#   the fit uses every pair.

# %%
m = measure_sphere_on_block(problem)
hertz = {
    "h_mm": h, "elements_per_a": args.elements_per_a, "R_mm": R_SPHERE, "block_mm": BLOCK,
    "approach_mm": APPROACH, "E_star_MPa": E_STAR, "slave_nodes": m["pairs"], "closed": m["closed"],
    "F_N": m["F"], "a_hertz_mm": m["a_hertz"], "a_mm": m["a"], "a_error": m["err_a"],
    "p0_hertz_MPa": m["p0_hertz"], "p0_MPa": m["p0"], "p0_error": m["err_p0"],
    "a_fit_mm": m["a_fit"], "p0_fit_MPa": m["p0_fit"], "p0_fit_error": m["err_p0_fit"],
    "global_imbalance": m["imbalance"], "iterations": results[0].iterations, "wall_time_s": wall,
}
if comm.rank == 0:
    print(f"F = {m['F']:.1f} N ({m['closed']} of {m['pairs']} slave nodes closed, {results[0].iterations} Newton "
          f"iterations, global imbalance {m['imbalance']:.1e})")
    print(f"  a  = {m['a']:.4f} mm,  Hertz {m['a_hertz']:.4f} mm: {100 * m['err_a']:+.2f} %")
    print(f"  p0 = {m['p0']:.1f} MPa (centre node), Hertz {m['p0_hertz']:.1f} MPa: {100 * m['err_p0']:+.2f} %")
    print(f"  p0 = {m['p0_fit']:.1f} MPa (fitted, a = {m['a_fit']:.4f} mm): {100 * m['err_p0_fit']:+.2f} %")
    (out / "hertz.json").write_text(json.dumps(hertz, indent=1, default=float))

# %% [markdown]
# ## Pictures
# The contact pressure on the slave surface, seen from below through the block (the nodal
# pressures interpolated over the sphere's facets; white: Hertz's contact circle), the nodal
# pressures against r with Hertz's profile, and the deformed bodies near the contact (von Mises
# stress, in MPa as the whole model: its maximum lies below the surface, as Hertz's does).

# %%
table = m["table"]
plot_contact_pressure(problem, out / "contact_pressure.png", circle=m["a_hertz"],
                      title=f"contact pressure, h = a/{args.elements_per_a:g}: p0 = {m['p0']:.0f} MPa "
                            f"(Hertz {m['p0_hertz']:.0f}), a = {m['a']:.3f} mm (Hertz {m['a_hertz']:.3f})")
plot_deformed(problem, out / "deformed.png", title="sphere on block", camera=(-1.0, 0.4, -0.8),
              focus=(0.0, 0.0, 0.0), zoom=3.0)
if comm.rank == 0:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = m["r"]
    rr = np.linspace(0.0, 1.6 * m["a_hertz"], 400)
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    ax.plot(rr, m["p0_hertz"] * np.sqrt(np.clip(1 - rr**2 / m["a_hertz"]**2, 0, None)), "k-", label="Hertz")
    ax.plot(rr, m["p0_fit"] * np.sqrt(np.clip(1 - rr**2 / m["a_fit"]**2, 0, None)), "--", color="tab:orange",
            label="fitted Hertz profile")
    ax.plot(r, table["pressure"], "o", ms=3, color="tab:blue", label="slave nodes: f / D")
    ax.set_xlim(0.0, 1.6 * m["a_hertz"])
    ax.set_xlabel("r (mm)")
    ax.set_ylabel("contact pressure (MPa)")
    ax.set_title(f"sphere on block, dual mortar, h = a/{args.elements_per_a:g}", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "pressure_profile.png", dpi=120)
    plt.close(fig)
    print(f"wrote {out}/contact_pressure.png, pressure_profile.png, deformed.png, hertz.json, fields.xdmf, "
          "pairs.pvd, summary.json")
