# ---
# jupyter:
#   jupytext:
#     formats: py:percent
# ---

# %% [markdown]
# # Thick-walled cylinder under internal pressure (plane strain, perfect plasticity)
#
# A tube a = 1 ≤ r ≤ b = 2 under internal pressure p, in plane strain, made of a von Mises
# material without hardening. The wall yields from the inside out; the limit pressure is
#
# $$ p_\mathrm{lim} = \frac{2}{\sqrt 3}\, \sigma_{y0} \ln\frac{b}{a}. $$
#
# We load past p_lim in equal increments; the load stepping halves the increment when Newton
# fails or when the displacement leaves the small-displacement range (5 % of a: past the limit
# load a small-displacement model keeps finding equilibria with ever larger displacements),
# and stops when it can no longer advance, which brackets the limit load.
#
# Quadratic hexahedra (Q2, 3×3×3 Gauss points) are the default: trilinear hexahedra lock in
# the isochoric plastic flow and keep a residual stiffness past p_lim (try `--degree 1`). Outputs, in
# `--out` (default `results/thick_cylinder`):
#
# - `fields.xdmf`: displacement, von Mises stress, plastic strain per increment (ParaView);
# - `pressure_displacement.png`: p against the inner radial displacement, with p_lim drawn;
# - `plastic_zone.png`: the equivalent plastic strain on the deformed quarter tube;
# - `convergence.png`: the Newton residuals of every increment;
# - `summary.json`.
#
# Run: `python demos/thick_cylinder.py [--out DIR] [--nr 8] [--nt 16]`.

# %%
import argparse
import logging
import math
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (before dolfinx: the PyPI wheel needs it)
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.solvers import ConvergenceError
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.cases.geometries import ThickCylinderTags as T
from dolfinx_nnqem.cases.geometries import build_thick_cylinder
from dolfinx_nnqem.solvers.monolithic import MonolithicSolver
from dolfinx_nnqem.io import ResultsWriter
from dolfinx_nnqem.io.plots import plot_convergence, plot_curve, plot_deformed
from dolfinx_nnqem.problem import ContactProblem, Dirichlet, Pressure
from dolfinx_nnqem.solvers import SolverOptions
from dolfinx_nnqem.io.results import node_blocks_at_points, values_at_blocks
from dolfinx_nnqem.solvers import solve_load_steps

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out", default="results/thick_cylinder")
parser.add_argument("--nr", type=int, default=4, help="elements through the wall")
parser.add_argument("--nt", type=int, default=12, help="elements around the quarter")
parser.add_argument("--degree", type=int, default=2, help="displacement degree (1: Q1, 2: Q2)")
parser.add_argument("--increments", type=int, default=12)
args, _ = parser.parse_known_args()
logging.basicConfig(level=logging.WARNING, format="%(message)s")
out = Path(args.out)

# %% [markdown]
# ## Geometry, material and loads
# A quarter of the tube, one hexahedron layer thick; plane strain is u_z = 0 on both z faces,
# and symmetry fixes u_x on x = 0 and u_y on y = 0.

# %%
a, b = 1.0, 2.0
material = VonMises(E=70e3, nu=0.3, sigma_y0=250.0, H=0.0)
p_lim = 2.0 / math.sqrt(3.0) * material.sigma_y0 * math.log(b / a)
p_max = 1.05 * p_lim

mesh, cell_tags, facet_tags = build_thick_cylinder(MPI.COMM_WORLD, a, b, 0.1, args.nr, args.nt)
problem = ContactProblem(
    mesh, cell_tags, facet_tags, materials=material, degree=args.degree,
    dirichlet=[Dirichlet(T.SYMMETRY_X, 0.0, [0]), Dirichlet(T.SYMMETRY_Y, 0.0, [1]),
               Dirichlet(T.FACES_Z, 0.0, [2])],
    tractions=[Pressure(T.INNER, p_max)],
)

# %% [markdown]
# ## Solve
# The monolithic solver without contact is Newton–Raphson with the consistent tangent.

# %%
solver = MonolithicSolver(problem, SolverOptions(max_iterations=20))
writer = ResultsWriter(problem, solver.name, out, args.increments,
                       probes={"inner": np.array([a, 0.0, 0.0]), "outer": np.array([b, 0.0, 0.0])})
inner = node_blocks_at_points(problem, np.array([[a, 0.0, 0.0]]))
curve = [(0.0, 0.0)]
histories, labels = [], []


def record(result):
    u_a = values_at_blocks(problem, inner)[0, 0]
    curve.append((u_a, result.load_factor * p_max))
    histories.append([h.equilibrium for h in result.report.history])
    labels.append(f"p = {result.load_factor * p_max:.1f}")


try:
    solve_load_steps(problem, solver, args.increments, max_cutbacks=6, callbacks=[writer, record],
                     max_displacement=0.05 * a)
except ConvergenceError as error:
    if MPI.COMM_WORLD.rank == 0:
        print("load stepping stopped near the limit load:", str(error).splitlines()[0])
writer.close()

# %% [markdown]
# ## Results

# %%
p_last = curve[-1][1]
if MPI.COMM_WORLD.rank == 0:
    print(f"last converged pressure {p_last:.2f}; p_lim = {p_lim:.2f}; ratio {p_last / p_lim:.4f}")
    u, p = np.array(curve).T
    plot_curve(u * 1e3, p, out / "pressure_displacement.png", xlabel="u_r(a) (10⁻³)",
               ylabel="internal pressure p", reference={"p_lim (analytical)": p_lim},
               title="Thick cylinder, plane strain, perfect plasticity")
    plot_convergence(histories, out / "convergence.png", labels, title="Newton residuals per increment")
plot_deformed(problem, out / "plastic_zone.png", field="p", show_pairs=False,
              title=f"equivalent plastic strain at p = {p_last:.1f}", camera="xy")
if MPI.COMM_WORLD.rank == 0:
    print(f"wrote {out}/fields.xdmf, pressure_displacement.png, plastic_zone.png, convergence.png, summary.json")
