# ---
# jupyter:
#   jupytext:
#     formats: py:percent
# ---

# %% [markdown]
# # Rigid obstacles: a sphere on a block (Hertz), an elastoplastic indentation, a sliding indenter
#
# A rigid obstacle is the master side of a `Contact`: an analytical plane, sphere or cylinder
# with a prescribed motion d(ℓ). Every node of the tagged slave surface gets a pair; its gap is
# the exact distance to the obstacle and its normal the obstacle's outward normal at the closest
# point (small displacements: computed once). Units: mm, N, MPa.
#
# 1. **Hertz.** A rigid sphere (R = 50 mm) pressed δ = a²/R into an elastic steel block (quarter
#    model, graded to h = a/4 at the contact): contact radius and peak pressure against Hertz
#    with E* = E/(1 − ν²).
# 2. **Elastoplastic indentation** (as deal.II's step-42): the sphere pressed 3 δ into a von
#    Mises block (σ_y0 = 300 MPa): the plastic zone under the indenter.
# 3. **Press, then slide** (half model, μ_f = 0.3): the sphere presses by δ, then moves 2 δ
#    sideways; the obstacle's force history.
#
# Run: `python demos/rigid_indenter.py [--out DIR] [--elements-per-a 4]`. Writes, in `--out`
# (default `results/rigid_indenter`): `hertz_pressure.png`, `plastic_zone.png`,
# `slide_forces.png`, `summary.json`.

# %%
import argparse
import json
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (before dolfinx: the PyPI wheel needs it)
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.problem import PiecewiseLinearPath
from dolfinx_nnqem.contact.obstacles import Sphere
from dolfinx_nnqem.cases.hertz import NodalLoads, effective_modulus, measure_hertz
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.cases.geometries import build_graded_block
from dolfinx_nnqem.io.plots import plot_deformed
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet
from dolfinx_nnqem.io import equilibrium_check, pair_table
from dolfinx_nnqem.solvers import SolverOptions, make_solver
from dolfinx_nnqem.solvers import solve_load_steps

parser = argparse.ArgumentParser(description="A rigid sphere on a block: Hertz, plastic indentation, sliding")
parser.add_argument("--out", default="results/rigid_indenter")
parser.add_argument("--elements-per-a", type=int, default=4, help="Hertz mesh: fine element size h = a / this")
args, _ = parser.parse_known_args()
out = Path(args.out)
comm = MPI.COMM_WORLD
rank0 = comm.rank == 0
if rank0:
    out.mkdir(parents=True, exist_ok=True)

E, NU, R, A = 210e3, 0.3, 50.0, 1.0  # MPa, -, mm, mm (the nominal contact radius)
DELTA = A ** 2 / R  # Hertz: δ = a²/R
E_STAR = effective_modulus(E, NU)  # the sphere is rigid
summary = {}


def sphere_on_block(h, material, motion, half=False, mu_f=0.0):
    """The graded block under a rigid sphere touching its top at the origin."""
    mesh, cell_tags, facet_tags = build_graded_block(comm, h, fine_width=1.25 * A, fine_depth=0.5 * A, half=half)
    dirichlet = [Dirichlet(T.bottom(1)), Dirichlet(T.zmin(1), 0.0, [2])]  # base clamped; z = 0: symmetry
    if not half:
        dirichlet.append(Dirichlet(T.xmin(1), 0.0, [0]))  # x = 0: symmetry (quarter model)
    sphere = Sphere(centre=(0.0, R, 0.0), radius=R, motion=motion)
    return ContactProblem(mesh, cell_tags, facet_tags, materials=material, dirichlet=dirichlet,
                          contact=Contact(sphere, T.top(1), mu_f=mu_f))


# %% [markdown]
# ## 1. Hertz
# One increment. The pair forces are tributary integrals of the pressure, so the contact radius
# is measured with the whole distribution (`dolfinx_nnqem.cases.hertz.measure_hertz`: the Hertz
# pressure whose consistent nodal forces best fit the pair forces) and p0 at the centre pair.

# %%
h = A / args.elements_per_a
problem = sphere_on_block(h, VonMises(E=E, nu=NU), (0.0, -DELTA, 0.0))
with make_solver("monolithic", problem, SolverOptions(rtol=1e-12)) as solver:
    solve_load_steps(problem, solver, 1)
table = pair_table(problem)
loads = NodalLoads(problem, T.top(1), table["slave_block"])
p_n = -table["force_local_body1"][:, 0]
m = measure_hertz(loads, p_n, table["position_b"], table["state"] != 0, 4, R, E_STAR)
summary["hertz"] = {k: float(m[k]) for k in ("F", "a", "a_hertz", "err_a", "p0", "p0_hertz", "err_p0")}
summary["hertz"]["h_mm"] = h
summary["hertz"]["global_imbalance"] = equilibrium_check(problem)["global_imbalance"]
if rank0:
    print(f"Hertz, h = a/{args.elements_per_a}: F = {m['F']:.1f} N; a = {m['a']:.4f} mm (Hertz {m['a_hertz']:.4f}) "
          f"{100 * m['err_a']:+.2f} %, p0 = {m['p0']:.1f} MPa (Hertz {m['p0_hertz']:.1f}) {100 * m['err_p0']:+.2f} %; "
          f"global imbalance {summary['hertz']['global_imbalance']:.1e}")
hertz_nodal = loads.hertz(m["a_hertz"], m["p0_hertz"])  # collective
if rank0:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rr = np.linspace(0.0, 1.6 * m["a_hertz"], 300)
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(rr, m["p0_hertz"] * np.sqrt(np.clip(1 - rr ** 2 / m["a_hertz"] ** 2, 0, None)), "k-", label="Hertz p(r)")
    ax.plot(m["r"], hertz_nodal / loads.area, "s", mfc="none", mec="grey", label="Hertz, nodal average ∫pN/A")
    ax.plot(m["r"], m["pressure"], "o", ms=4, label="FE pairs p_n / A")
    ax.set_xlim(0, 1.6 * m["a_hertz"])
    ax.set_xlabel("r (mm)")
    ax.set_ylabel("contact pressure (MPa)")
    ax.set_title(f"rigid sphere: a {100 * m['err_a']:+.1f} %, p0 {100 * m['err_p0']:+.1f} % (h = a/{args.elements_per_a})")
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "hertz_pressure.png", dpi=120)
    plt.close(fig)

# %% [markdown]
# ## 2. Elastoplastic indentation
# The sphere goes 3 δ deep in 8 increments into a block that yields at σ_y0 = 300 MPa (about a
# tenth of Hertz's p0): the plastic zone (the equivalent plastic strain p, cell means) grows
# below the surface, where the von Mises stress of Hertz's field peaks (about 0.5 a deep).

# %%
steel = VonMises(E=E, nu=NU, sigma_y0=300.0, H=2.0e3)
problem = sphere_on_block(A / 2, steel, (0.0, -3 * DELTA, 0.0))
with make_solver("monolithic", problem, SolverOptions(rtol=1e-11)) as solver:
    results = solve_load_steps(problem, solver, 8)
table = pair_table(problem)
force = 4 * float(-table["force_local_body1"][:, 0].sum())
plastic = int(comm.allreduce(np.count_nonzero(problem.state.p_n.x.array > 0), op=MPI.SUM))
summary["indentation"] = {"force_N": force, "plastic_gauss_points": plastic,
                          "iterations": [r.iterations for r in results],
                          "global_imbalance": equilibrium_check(problem)["global_imbalance"]}
if rank0:
    print(f"indentation 3δ: F = {force:.1f} N (4 × the quarter model), {plastic} Gauss points with p > 0, "
          f"iterations {summary['indentation']['iterations']}")
plot_deformed(problem, out / "plastic_zone.png", field="p", scale=5.0, show_pairs=False, camera=(-0.6, 0.4, -1.0),
              focus=(0.5, -0.5, 0.0), zoom=3.0, title="equivalent plastic strain p, seen on the symmetry planes")

# %% [markdown]
# ## 3. Press, then slide
# A half model (z ≥ 0): the sphere presses by δ over ℓ ≤ ½, then moves 2 δ along x with
# friction (μ_f = 0.3): the obstacle's force on the block at every increment; once it slides,
# the tangential force approaches μ_f times the normal force.

# %%
path = PiecewiseLinearPath([[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, -DELTA, 0.0], [1.0, 2 * DELTA, -DELTA, 0.0]])
problem = sphere_on_block(A / 2, VonMises(E=E, nu=NU), path, half=True, mu_f=0.3)
forces = []


def record(result):
    f = equilibrium_check(problem)["obstacle_forces"]["sphere-201"]
    states = pair_table(problem)["state_name"]
    forces.append((result.load_factor, 2 * f, int(np.sum(states == "stick")), int(np.sum(states == "slip"))))


with make_solver("monolithic", problem, SolverOptions(rtol=1e-12)) as solver:
    solve_load_steps(problem, solver, 8, callbacks=[record])
summary["slide"] = [{"load_factor": ell, "force_N": f.tolist(), "stick": st, "slip": sl} for ell, f, st, sl in forces]
if rank0:
    for ell, f, st, sl in forces:
        print(f"ℓ = {ell:.3f}: force on the block ({f[0]:9.2f}, {f[1]:9.2f}) N, |F_x|/(μ_f |F_y|) = "
              f"{abs(f[0]) / (0.3 * abs(f[1])):.4f}; stick {st}, slip {sl}")
    fig, ax = plt.subplots(figsize=(6, 4))
    ell = [x[0] for x in forces]
    ax.plot(ell, [-x[1][1] for x in forces], "o-", label="normal force −F_y")
    ax.plot(ell, [x[1][0] for x in forces], "s-", label="tangential force F_x")
    ax.plot(ell, [-0.3 * x[1][1] for x in forces], "k:", label="μ_f × normal force")
    ax.set_xlabel("load factor ℓ (press, then slide)")
    ax.set_ylabel("force of the sphere on the block (N)")
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "slide_forces.png", dpi=120)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(f"wrote {out}/hertz_pressure.png, plastic_zone.png, slide_forces.png, summary.json")
