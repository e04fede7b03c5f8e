# ---
# jupyter:
#   jupytext:
#     formats: py:percent
# ---

# %% [markdown]
# # A friction sweep: one problem, solved again for each μ_f
#
# The seed's two overlapping cantilevers (`dolfinx_nnqem.cases.two_beams`), loaded on beam 2's top
# by the traction (1e5, −1e5, 0.5e5) Pa and their self-weight, touch over 9 node pairs. How much of
# the load goes through the contact, and how much of it is friction, depends on μ_f. Instead of
# building the problem again for each μ_f (mesh, forms, compiles), the problem is built once and
# `problem.update(mu_f=...)` changes the friction coefficient and returns it to its initial state:
# the second and every later solve compile nothing.
#
# Run: `python demos/friction_sweep.py [--out DIR] [--method monolithic|nneqm1|nneqm2]`.
# Writes, in `--out` (default `results/friction_sweep`): `contact_force.png` and
# `contact_force.csv` (μ_f, total normal and tangential contact force).

# %%
import argparse
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (before dolfinx: the PyPI wheel needs it)
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402

from dolfinx_nnqem.cases.two_beams import DEFAULT_LAW, two_beams_problem  # noqa: E402
from dolfinx_nnqem.solvers import METHODS, make_solver, solve_load_steps  # noqa: E402

parser = argparse.ArgumentParser(description="The two beams solved for friction coefficients 0 to 0.5")
parser.add_argument("--out", default="results/friction_sweep")
parser.add_argument("--method", default="monolithic", choices=METHODS)
args, _ = parser.parse_known_args()
out = Path(args.out)
comm = MPI.COMM_WORLD

# %% [markdown]
# ## The problem, built once
# `two_beams_problem` meshes the beams with gmsh and builds the `ContactProblem`: this compiles
# the forms (the slow part of a first run).

# %%
problem = two_beams_problem(comm, law=DEFAULT_LAW[args.method])

# %% [markdown]
# ## The sweep
# For each μ_f: `update` sets it on the interface (a list of coefficients per pair, no form holds
# it) and resets u, the Gauss-point state and the pair unknowns; a solver is built on the updated
# problem (it reads the problem's parameters when it is built) and drives the 15 increments. The
# contact force λ of each pair is in the pair's frame: normal first, then the two tangents.

# %%
mu_values = np.linspace(0.0, 0.5, 11)
normal, tangential = [], []
for mu in mu_values:
    problem.update(mu_f=float(mu))
    with make_solver(args.method, problem) as solver:
        solve_load_steps(problem, solver, 15)
    lam = problem.contact.force()
    normal.append(comm.allreduce(float(np.sum(lam[:, 0])), op=MPI.SUM))
    tangential.append(float(np.linalg.norm(comm.allreduce(np.sum(lam[:, 1:], axis=0), op=MPI.SUM))))
    if comm.rank == 0:
        print(f"mu_f = {mu:.2f}: normal {normal[-1]:10.1f} N, tangential {tangential[-1]:9.1f} N")

# %% [markdown]
# ## The contact force against μ_f
# Without friction the interface carries normal force only; with friction it takes part of the
# horizontal load too, and the beams share the vertical load slightly differently.

# %%
if comm.rank == 0:
    out.mkdir(parents=True, exist_ok=True)
    np.savetxt(out / "contact_force.csv", np.column_stack([mu_values, normal, tangential]), delimiter=",",
               header="mu_f,normal_N,tangential_N", comments="")
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(mu_values, normal, "o-", label="normal")
    ax.plot(mu_values, tangential, "s-", label="tangential (|sum|)")
    ax.set_xlabel("friction coefficient μ_f")
    ax.set_ylabel("total contact force on beam 2 (N)")
    ax.set_title("Two beams: contact force against μ_f")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "contact_force.png", dpi=120)
    print(f"wrote {out / 'contact_force.png'} and {out / 'contact_force.csv'}")
problem.destroy()
