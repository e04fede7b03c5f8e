# ---
# jupyter:
#   jupytext:
#     formats: py:percent
# ---

# %% [markdown]
# # Several contact interfaces: three stacked blocks
#
# Three elastic blocks (E = 1 GPa, ν = 0.3), each x, z ∈ [0, 1] m and 0.5 m high, meshed on their
# own (no shared nodes), stand on each other: two contact interfaces, with their own friction
# coefficients (lower μ_f = 0.2, upper μ_f = 0.4). Block 1's base is clamped; blocks 2 and 3
# are held by contact alone. A pressure p = 1 MPa on the top rises over the first fifth of the
# load path and is held; then the top face is dragged 10 mm along x. Statics says both
# interfaces carry the same tangential force: the weaker one slides at μ_low p A = 0.2 MN while
# the stronger one keeps sticking.
#
# Run: `python demos/contact_interfaces.py [--out DIR] [--method monolithic|nneqm1|nneqm2]`.
# Writes, in `--out` (default `results/contact_interfaces`): `fields.xdmf`, `pairs.pvd` (both
# interfaces, with an `interface` column), `summary.json`, `friction.png` and `deformed.png`.

# %%
import argparse
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (before dolfinx: the PyPI wheel needs it)
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.cases.geometries import build_block_stack
from dolfinx_nnqem.io import ResultsWriter
from dolfinx_nnqem.io.plots import plot_deformed
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure
from dolfinx_nnqem.io import pair_table
from dolfinx_nnqem.solvers import METHODS, SolverOptions, make_solver
from dolfinx_nnqem.solvers import solve_load_steps

parser = argparse.ArgumentParser(description="Three stacked blocks: two interfaces, two friction coefficients")
parser.add_argument("--out", default="results/contact_interfaces")
parser.add_argument("--method", default="monolithic", choices=METHODS)
args, _ = parser.parse_known_args()
out = Path(args.out)
comm = MPI.COMM_WORLD

# %% [markdown]
# ## The model
# `build_block_stack` meshes each block on its own; `BlockStackTags` names the faces (block k:
# bottom 100 + k, top 200 + k, ...). Each interface is one `Contact`: the master side
# (`surface1`), the slave side (`surface2`), its friction coefficient and a name for the tables.

# %%
mesh, cell_tags, facet_tags = build_block_stack(comm, 1.0, 1.0, [0.5] * 3, [(4, 2, 4)] * 3)
elastic = VonMises(E=1.0e9, nu=0.3)
P, DRAG = 1.0e6, 1.0e-2
problem = ContactProblem(
    mesh, cell_tags, facet_tags, materials={k: elastic for k in (1, 2, 3)},
    dirichlet=[Dirichlet(T.bottom(1)),
               Dirichlet(T.top(3), DRAG, [0], amplitude=lambda ell: max(ell - 0.2, 0.0) / 0.8)]
              + [Dirichlet(face(k), 0.0, [2]) for k in (1, 2, 3) for face in (T.zmin, T.zmax)],
    tractions=[Pressure(T.top(3), P, amplitude=lambda ell: min(ell / 0.2, 1.0))],
    contact=[Contact(T.top(1), T.bottom(2), mu_f=0.2, name="lower"),
             Contact(T.top(2), T.bottom(3), mu_f=0.4, name="upper")],
)
if comm.rank == 0:
    for line in problem.contact.describe():
        print(line)
    print("free rigid modes (held by contact):",
          [f"block {b + 1}: {d}" for b, d in zip(problem.rigid_modes.body, problem.rigid_modes.description)])

# %% [markdown]
# ## Solve
# Ten equal increments; after each, the friction force carried by each interface.

# %%
writer = ResultsWriter(problem, args.method, out, 10)
history = []


def record(result):
    t = pair_table(problem)
    history.append((result.load_factor, [t["force_on_body1"][t["interface"] == k, 0].sum() for k in (0, 1)],
                    [t["state_name"][t["interface"] == k] for k in (0, 1)]))


# a solver frees its PETSc objects at the end of a with block
with make_solver(args.method, problem, SolverOptions(rtol=1e-12, max_iterations=40)) as solver:
    solve_load_steps(problem, solver, 10, callbacks=[writer, record])
writer.close()
if comm.rank == 0:
    for ell, friction, states in history:
        counts = [{s: int(np.sum(st == s)) for s in ("open", "stick", "slip")} for st in states]
        print(f"ℓ = {ell:.1f}: friction lower {friction[0]:10.1f} N, upper {friction[1]:10.1f} N; "
              f"lower {counts[0]}, upper {counts[1]}")
    print(f"μ_low p A = {0.2 * P:.1f} N")

# %% [markdown]
# ## Pictures
# The friction force of each interface against the load factor, and the deformed stack (von
# Mises stress; pairs drawn at their slave nodes: blue stick, red slip, white open).

# %%
plot_deformed(problem, out / "deformed.png", title="three blocks, end of the drag", camera="front")
if comm.rank == 0:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ell = [h[0] for h in history]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(ell, [h[1][0] for h in history], "o-", label="lower interface (μ_f = 0.2)")
    ax.plot(ell, [h[1][1] for h in history], "s--", label="upper interface (μ_f = 0.4)")
    ax.axhline(0.2 * P, color="grey", lw=0.8, label="μ_low p A")
    ax.set_xlabel("load factor ℓ")
    ax.set_ylabel("friction force on the lower block (N)")
    ax.legend()
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "friction.png", dpi=120)
    print(f"wrote {out}/friction.png, deformed.png, fields.xdmf, pairs.pvd, summary.json")
