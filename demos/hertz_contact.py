# ---
# jupyter:
#   jupytext:
#     formats: py:percent
# ---

# %% [markdown]
# # Hertz contact and Cattaneo–Mindlin partial slip with node-to-node pairs
#
# Two identical elastic blocks touch on the plane y = 0. Their matching interface nodes are
# joined by node-to-node pairs whose initial gap is that of a sphere of radius R on a flat,
#
# $$ g_0(x, z) = \frac{x^2 + z^2}{2R}. $$
#
# Pressed together by a force F they touch on a disc of radius a with Hertz's elliptical
# pressure (both bodies elastic half-spaces, identical materials: E* = E / (2(1 − ν²))):
#
# $$ a = \left(\frac{3FR}{4E^*}\right)^{1/3}, \qquad p(r) = p_0\sqrt{1 - r^2/a^2},
#    \qquad p_0 = \frac{3F}{2\pi a^2}. $$
#
# A tangential force Q < μ_f P applied afterwards, with the normal force P held, makes an
# annulus c < r < a slip while the centre sticks (Cattaneo 1938, Mindlin 1949):
#
# $$ c = a \left(1 - \frac{Q}{\mu_f P}\right)^{1/3}, \qquad
#    q(r) = \mu_f p_0 \sqrt{1 - r^2/a^2} - [r < c]\, \mu_f p_0 \frac{c}{a}\sqrt{1 - r^2/c^2}. $$
#
# Both results assume elastically similar bodies (no coupling of normal and tangential
# displacements), which identical materials give. These are verification cases V6 and V7
# (`tests/integration/test_hertz.py`; the choices are explained in `docs/verification-hertz.md`).
#
# Outputs, in `--out` (default `results/hertz`):
#
# - `pressure_profile.png`: the pair pressures p_n / A against r with Hertz's profile, and the
#   friction tractions at the last increment with Mindlin's;
# - `stick_slip_map.png`: open / stick / slip pairs on the contact face at every tangential
#   increment, with Mindlin's stick circle;
# - `summary.json`: the numbers printed below.
#
# Run: `python demos/hertz_contact.py [--out DIR] [--elements-per-a 4] [--increments 6]`.

# %%
import argparse
import json
import math
import time
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (before dolfinx: the PyPI wheel needs it)
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.cases.hertz import NodalLoads, hertz_contact, measure_hertz
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.cases.geometries import StackedBlocksTags as T
from dolfinx_nnqem.cases.geometries import build_graded_contact_blocks
from dolfinx_nnqem.solvers.monolithic import MonolithicSolver
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet
from dolfinx_nnqem.solvers import SolverOptions
from dolfinx_nnqem.io import pair_table, reactions
from dolfinx_nnqem.solvers import solve_load_steps

parser = argparse.ArgumentParser(description="V6 Hertz contact and V7 Cattaneo–Mindlin partial slip")
parser.add_argument("--out", default="results/hertz")
parser.add_argument("--elements-per-a", type=int, default=4, help="fine element size h = a / this")
parser.add_argument("--increments", type=int, default=6, help="tangential increments")
parser.add_argument("--drag", type=float, default=0.0055, help="final tangential displacement of the top (mm)")
args, _ = parser.parse_known_args()
comm = MPI.COMM_WORLD
out = Path(args.out)
if comm.rank == 0:
    out.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# ## Geometry, material and mesh
# Units: mm, N, MPa. Steel-like blocks, E = 210 GPa, ν = 0.3, R = 50 mm; the approach
# δ = 0.0185 mm gives a ≈ 1 mm. By symmetry about the plane z = 0 (which the tangential load
# along x respects) we model half of the contact: x in [−6, 6] mm, z in [0, 6] mm, each block
# 6 mm high, so the blocks are 12 a wide — half-spaces to a few tenths of a per cent.
#
# `build_graded_contact_blocks` maps the unit-element blocks of `build_stacked_blocks` onto a
# graded grid: elements of size h = a/4 over
# |x|, z ≤ 1.25 a and 0.5 a deep on both sides of the interface, growing by 1.3 per element
# beyond. The same map for both bodies keeps the interface nodes coincident.

# %%
E, NU, R_SPHERE = 210e3, 0.3, 50.0
E_STAR = E / (2.0 * (1.0 - NU**2))
MU_F = 0.3
DELTA = 0.0185
A_NOMINAL, BLOCK = 1.0, 6.0
h = A_NOMINAL / args.elements_per_a


mesh, cell_tags, facet_tags = build_graded_contact_blocks(
    comm, h, fine_width=1.25 * A_NOMINAL, fine_depth=0.5 * A_NOMINAL, block=BLOCK, half=True)

# %% [markdown]
# ## Supports, loads and contact
# Body 1's bottom is clamped. Body 2's top is displacement-controlled: u_y = −δ reached in the
# first increment and then held, u_x = the drag, zero in the first increment and growing in the
# next ones, u_z = 0. At the start body 2 touches body 1 in one point only; with a prescribed top
# displacement its stiffness is never singular. The plane z = 0 is a symmetry plane (u_z = 0).
# The pairs on it have the friction direction t2 = −z fixed at both nodes: the package pins
# that component (`problem.constrained_directions`).

# %%
n_steps = 1 + args.increments
material = VonMises(E=E, nu=NU)  # σ_y0 = inf: elastic
problem = ContactProblem(
    mesh, cell_tags, facet_tags, materials={T.BODY1: material, T.BODY2: material},
    dirichlet=[
        Dirichlet(T.BOTTOM),
        Dirichlet(T.TOP, -DELTA, [1], amplitude=lambda ell: min(n_steps * ell, 1.0)),
        Dirichlet(T.TOP, args.drag, [0], amplitude=lambda ell: max(n_steps * ell - 1.0, 0.0) / args.increments),
        Dirichlet(T.TOP, 0.0, [2]),
        Dirichlet(T.BODY1_ZMIN, 0.0, [2]), Dirichlet(T.BODY2_ZMIN, 0.0, [2]),
    ],
    contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=MU_F,
                    initial_gap=lambda x: (x[0] ** 2 + x[2] ** 2) / (2.0 * R_SPHERE)),
)
if comm.rank == 0:
    print(f"h = a/{args.elements_per_a}: {mesh.topology.index_map(3).size_global} hexahedra, "
          f"{3 * problem.V.dofmap.index_map.size_global} displacement dofs, {problem.num_pairs} pairs")

# %% [markdown]
# ## From pair forces to pressures
# A pair carries a force, not a pressure. With linear elements the pair force is the tributary
# integral of the contact pressure, f_a = ∫ p N_a dA (N_a the hat function of node a on body
# 1's contact face), so
#
# - the **nodal pressure** is p_n / A_a with the tributary area A_a = ∫ N_a dA; at the centre
#   this is p0 (up to an O(h²/a²) averaging of the curved profile);
# - near the edge r = a the pressure falls like a square root within one element: an edge
#   pair's p_n / A is a smeared average, and the outermost closed pair can lie up to about half
#   an element outside a. So a is measured with the whole distribution instead: it is the
#   radius of the Hertz pressure (for the measured F) whose consistent nodal forces ∫ p N_a dA
#   best fit the pair forces (least squares).

# %%
pairs = problem.contact.interfaces[0].pairs  # node-to-node: the body-1 nodes a_i
loads = NodalLoads(problem, T.CONTACT1, pairs.gather(pairs.dofs_a.astype(np.int64)))
area = loads.area


def hertz(F):
    """Hertz's (a, p0) for the full force F."""
    return hertz_contact(F, R_SPHERE, E_STAR)


# %% [markdown]
# ## Solve
# The monolithic semismooth Newton solver, one increment for the normal load and
# `--increments` for the drag. Each converged increment's pair table is kept.

# %%
solver = MonolithicSolver(problem, SolverOptions(rtol=1e-12, max_iterations=30))
history = []


def record(result):
    history.append({"load_factor": result.load_factor, "iterations": result.iterations,
                    "time": result.wall_time_s, "table": pair_table(problem),
                    "reactions": reactions(problem)})


t0 = time.perf_counter()
solve_load_steps(problem, solver, n_steps, callbacks=[record])
wall = time.perf_counter() - t0

# %% [markdown]
# ## V6: Hertz
# The half model carries half the force: F = 2 Σ p_n. Equilibrium: Σ p_n equals the reaction
# of body 2's top. The frictional pairs transmit no friction under the normal load (identical
# materials, a configuration symmetric in y), so this is Hertz's frictionless contact.

# %%
table = history[0]["table"]
position = table["position"]
r = np.hypot(position[:, 0], position[:, 2])
f = -table["force_local_body1"]  # on body 2: (p_n, q along +x, q along −z)
P = f[:, 0].sum()
F = 2.0 * P
m = measure_hertz(loads, f[:, 0], position, table["state"] != 0, 2, R_SPHERE, E_STAR)
a_hertz, p0_hertz, a_fe, p0 = m["a_hertz"], m["p0_hertz"], m["a"], m["p0"]
closed = table["state"] != 0
v6 = {
    "F_N": F, "equilibrium": abs(P + history[0]["reactions"][T.TOP][1]) / P,
    "max_friction_over_max_pn": float(np.abs(f[:, 1:]).max() / f[:, 0].max()),
    "a_hertz_mm": a_hertz, "a_fe_mm": a_fe, "a_error": a_fe / a_hertz - 1.0,
    "p0_hertz_MPa": p0_hertz, "p0_fe_MPa": p0, "p0_error": p0 / p0_hertz - 1.0,
    "outermost_closed_r_mm": float(r[closed].max()), "innermost_open_r_mm": float(r[~closed].min()),
    "iterations": history[0]["iterations"],
}
if comm.rank == 0:
    print(f"V6 Hertz: F = {F:.3f} N, |Σp_n − reaction|/Σp_n = {v6['equilibrium']:.1e}, "
          f"max |q| / max p_n = {v6['max_friction_over_max_pn']:.1e}, {v6['iterations']} iterations")
    print(f"  a  = {a_fe:.4f} mm, Hertz {a_hertz:.4f} mm: {100 * v6['a_error']:+.2f} %  "
          f"(closed pairs out to r = {v6['outermost_closed_r_mm']:.4f}, first open at "
          f"{v6['innermost_open_r_mm']:.4f}, h = {h:.4f})")
    print(f"  p0 = {p0:.2f} MPa, Hertz {p0_hertz:.2f} MPa: {100 * v6['p0_error']:+.2f} %")

# %% [markdown]
# ## V7: Cattaneo–Mindlin
# Q = −Σ q_x (the friction on body 2 opposes the drag; it equals the x-reaction of the top).
# The FE stick radius is half way between the outermost sticking and the innermost slipping
# pair; Mindlin's c uses Hertz's a for the measured P.

# %%
v7 = []
for step in history[1:]:
    tab = step["table"]
    fs = -tab["force_local_body1"]
    P_k, Q_k = fs[:, 0].sum(), -fs[:, 1].sum()
    ratio = Q_k / (MU_F * P_k)
    a_k, _ = hertz(2.0 * P_k)
    c = a_k * (1.0 - ratio) ** (1.0 / 3.0)
    rk = np.hypot(tab["position"][:, 0], tab["position"][:, 2])
    stick, slip = tab["state"] == 1, tab["state"] == 2
    r_stick = float(rk[stick].max()) if stick.any() else 0.0
    r_slip = float(rk[slip].min()) if slip.any() else float("inf")
    v7.append({"load_factor": step["load_factor"], "Q_over_muP": ratio, "c_mindlin_mm": c,
               "c_fe_mm": 0.5 * (r_stick + r_slip), "outermost_stick_r_mm": r_stick,
               "innermost_slip_r_mm": r_slip, "stick": int(stick.sum()), "slip": int(slip.sum()),
               "Q_equilibrium": abs(Q_k - step["reactions"][T.TOP][0]) / P_k,
               "iterations": step["iterations"], "time_s": step["time"]})
if comm.rank == 0:
    print(f"V7 Cattaneo–Mindlin (μ_f = {MU_F}, h = {h:.4f} mm):")
    print(f"  {'Q/(μP)':>7s} {'c Mindlin':>9s} {'c FE':>7s} {'|Δc|/h':>7s} {'stick':>5s} {'slip':>5s} {'its':>4s}")
    for s7 in v7:
        print(f"  {s7['Q_over_muP']:7.4f} {s7['c_mindlin_mm']:9.4f} {s7['c_fe_mm']:7.4f} "
              f"{abs(s7['c_fe_mm'] - s7['c_mindlin_mm']) / h:7.3f} {s7['stick']:5d} {s7['slip']:5d} "
              f"{s7['iterations']:4d}")
    print(f"  wall time {wall:.1f} s")

# %% [markdown]
# ## Pictures
# Left: the pair pressures p_n / A against r (every pair of the half model) with Hertz's
# profile, and the Hertz pressure's own nodal averages ∫ p N_a dA / A_a (what a perfect
# solution would show at the nodes: the smearing at the edge is the post-processing, not an
# error). Right: the friction traction |q| / A at the last increment with Mindlin's profile.

# %%
hertz_nodal = loads.hertz(a_hertz, p0_hertz)  # collective: outside the rank-0 block
if comm.rank == 0:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rr = np.linspace(0.0, 1.6 * a_hertz, 400)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    ax1.plot(rr, p0_hertz * np.sqrt(np.clip(1 - rr**2 / a_hertz**2, 0, None)), "k-", label="Hertz p(r)")
    ax1.plot(r, hertz_nodal / area, "s", mfc="none", mec="grey", ms=7,
             label="Hertz, nodal average ∫pN/A")
    ax1.plot(r, f[:, 0] / area, "o", ms=4, color="tab:blue", label="FE pairs p_n / A")
    ax1.set_xlim(0.0, 1.6 * a_hertz)
    ax1.set_xlabel("r (mm)")
    ax1.set_ylabel("contact pressure (MPa)")
    ax1.set_title(f"V6: a = {a_fe:.3f} (Hertz {a_hertz:.3f}) mm, p0 = {p0:.0f} (Hertz {p0_hertz:.0f}) MPa",
                  fontsize=9)
    ax1.legend(fontsize=8)
    ax1.grid(True, alpha=0.3)

    last = history[-1]["table"]
    fl = -last["force_local_body1"]
    rl = np.hypot(last["position"][:, 0], last["position"][:, 2])
    a_l, p0_l = hertz(2.0 * fl[:, 0].sum())
    c_l = v7[-1]["c_mindlin_mm"]
    q_ref = MU_F * p0_l * (np.sqrt(np.clip(1 - rr**2 / a_l**2, 0, None))
                           - (c_l / a_l) * np.sqrt(np.clip(1 - rr**2 / c_l**2, 0, None)))
    ax2.plot(rr, q_ref, "k-", label="Mindlin q(r)")
    ax2.plot(rr, MU_F * p0_l * np.sqrt(np.clip(1 - rr**2 / a_l**2, 0, None)), "k:", lw=1, label="μ_f p(r)")
    colours = {1: "royalblue", 2: "crimson"}
    for state, name in ((1, "stick"), (2, "slip")):
        sel = last["state"] == state
        ax2.plot(rl[sel], np.hypot(fl[sel, 1], fl[sel, 2]) / area[sel], "o", ms=4, color=colours[state],
                 label=f"FE {name} |q| / A")
    ax2.axvline(c_l, color="grey", ls="--", lw=1)
    ax2.set_xlim(0.0, 1.6 * a_hertz)
    ax2.set_xlabel("r (mm)")
    ax2.set_ylabel("friction traction (MPa)")
    ax2.set_title(f"V7, last increment: Q/(μP) = {v7[-1]['Q_over_muP']:.3f}, c = {c_l:.3f} mm", fontsize=9)
    ax2.legend(fontsize=8)
    ax2.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "pressure_profile.png", dpi=120)
    plt.close(fig)

# %% [markdown]
# The stick/slip map: the pairs of the contact face (z ≥ 0) at each tangential increment, open
# (white), stick (blue), slip (red), with Hertz's contact circle (black) and Mindlin's stick
# circle (dashed).

# %%
if comm.rank == 0:
    ncol = min(3, len(v7))
    nrow = math.ceil(len(v7) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4 * ncol, 2.4 * nrow + 0.4), squeeze=False)
    phi = np.linspace(0, math.pi, 200)
    lim = 1.5 * a_hertz
    for ax, step, s7 in zip(axes.flat, history[1:], v7):
        tab = step["table"]
        pos = tab["position"]
        near = (np.abs(pos[:, 0]) <= lim) & (pos[:, 2] <= lim)
        for state, colour in ((0, "white"), (1, "royalblue"), (2, "crimson")):
            sel = near & (tab["state"] == state)
            ax.scatter(pos[sel, 0], pos[sel, 2], s=30, c=colour, edgecolors="k", linewidths=0.5)
        ax.plot(a_hertz * np.cos(phi), a_hertz * np.sin(phi), "k-", lw=1)
        ax.plot(s7["c_mindlin_mm"] * np.cos(phi), s7["c_mindlin_mm"] * np.sin(phi), "k--", lw=1)
        ax.set_aspect("equal")
        ax.set_xlim(-lim, lim)
        ax.set_ylim(-0.05, lim)
        ax.set_title(f"Q/(μP) = {s7['Q_over_muP']:.3f}: c = {s7['c_mindlin_mm']:.3f} (FE {s7['c_fe_mm']:.3f})",
                     fontsize=8)
        ax.set_xlabel("x (mm, drag direction)", fontsize=8)
        ax.set_ylabel("z (mm)", fontsize=8)
    for ax in axes.flat[len(v7):]:
        ax.axis("off")
    fig.suptitle("V7 stick (blue) / slip (red) / open (white) pairs; — Hertz a, - - Mindlin c", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "stick_slip_map.png", dpi=120)
    plt.close(fig)
    summary = {"h_mm": h, "elements_per_a": args.elements_per_a, "mu_f": MU_F, "R_mm": R_SPHERE,
               "E_MPa": E, "nu": NU, "pairs": problem.num_pairs,
               "dofs": 3 * problem.V.dofmap.index_map.size_global, "wall_time_s": wall,
               "v6": v6, "v7": v7}
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    print(f"wrote {out}/pressure_profile.png, stick_slip_map.png, summary.json")
