# ---
# jupyter:
#   jupytext:
#     formats: py:percent
# ---

# %% [markdown]
# # Your own gmsh mesh: a punch pressed into a block
#
# A problem file needs a mesh whose physical groups name everything: physical **volumes** are
# the cell tags (one material each), physical **surfaces** the facet tags (supports, loads,
# contact surfaces). This demo builds such a mesh with gmsh's Python API, writes the problem
# file that refers to its tags, and solves it with `dolfinx-nnqem run` — what you would do
# with a mesh of your own (made in gmsh's GUI, or exported to `.msh` by another mesher).
#
# The model: an elastic base block 1 × 0.5 × 1 m and a punch 0.5 × 0.5 × 0.5 m standing on
# it. They are two separate volumes meshed with different element sizes, so the nodes of the
# two contact faces do not coincide: the contact's `discretisation = "auto"` then chooses dual
# mortar, with the finer side (the punch) as the slave. The punch's top is pushed down 2 mm
# with friction μ_f = 0.3 at the interface.
#
# With `--order 2` gmsh makes a **second-order mesh** (10-node tetrahedra) and the run uses
# quadratic elements (section "Second-order meshes" below).
#
# Writes, in `--out` (default `results/own_gmsh_mesh`): `punch.msh`, `punch.toml` and the run's
# results folder `results/` with its pictures.

# %%
import argparse
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (before dolfinx and gmsh's mesh transfer: the PyPI wheel needs it)
import gmsh
from mpi4py import MPI

from dolfinx_nnqem.cli import main

parser = argparse.ArgumentParser(description="A gmsh mesh of your own: a punch on a block")
parser.add_argument("--out", default="results/own_gmsh_mesh")
parser.add_argument("--size", type=float, default=0.25, help="element size of the block (the punch: 0.8 x)")
parser.add_argument("--order", type=int, choices=(1, 2), default=1,
                    help="2: a second-order mesh (10-node tetrahedra) and quadratic elements")
args, _ = parser.parse_known_args()
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# ## The geometry and its physical groups
#
# Two OpenCASCADE boxes. The faces are found by their centres; each physical group's tag is
# the number the problem file uses.

# %%
CELLS = {"block": 1, "punch": 2}
FACETS = {"block bottom": 11, "block top": 12, "punch bottom": 21, "punch top": 22}

if MPI.COMM_WORLD.rank == 0:  # gmsh builds the mesh on one process; the run distributes it
    gmsh.initialize(interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("punch")
    block = gmsh.model.occ.addBox(0.0, 0.0, 0.0, 1.0, 0.5, 1.0)
    punch = gmsh.model.occ.addBox(0.25, 0.5, 0.25, 0.5, 0.5, 0.5)
    gmsh.model.occ.synchronize()

    def face(volume: int, y: float) -> int:
        """The face of ``volume`` whose centre lies at height ``y``."""
        for dim, tag in gmsh.model.getBoundary([(3, volume)], oriented=False):
            if abs(gmsh.model.occ.getCenterOfMass(dim, tag)[1] - y) < 1e-9:
                return tag
        raise ValueError(f"volume {volume} has no face at y = {y}")

    gmsh.model.addPhysicalGroup(3, [block], CELLS["block"], name="block")
    gmsh.model.addPhysicalGroup(3, [punch], CELLS["punch"], name="punch")
    for (name, tag), (volume, y) in zip(FACETS.items(), [(block, 0.0), (block, 0.5), (punch, 0.5), (punch, 1.0)]):
        gmsh.model.addPhysicalGroup(2, [face(volume, y)], tag, name=name)

    # element sizes per volume: the punch finer than the block (non-matching contact faces)
    for volume, size in ((block, args.size), (punch, 0.8 * args.size)):
        points = gmsh.model.getBoundary([(3, volume)], combined=False, oriented=False, recursive=True)
        gmsh.model.mesh.setSize(points, size)
    gmsh.model.mesh.generate(3)
    if args.order == 2:
        gmsh.model.mesh.setOrder(2)  # 10-node tetrahedra, the new nodes on the geometry
    gmsh.write(str(out / "punch.msh"))
    gmsh.finalize()

# %% [markdown]
# ## Second-order meshes
#
# `gmsh.model.mesh.setOrder(2)` (or `Mesh.ElementOrder = 2` in a `.geo` file, or *Mesh > Set
# order 2* in the GUI) turns the mesh into 10-node tetrahedra (27-node hexahedra for a
# recombined, transfinite mesh), whose edge nodes lie on the geometry: a curved face stays curved.
# `dolfinx-nnqem` reads such a file as it is and solves with **quadratic elements** (P2; Q2 on
# hexahedra) unless `[mesh] degree = 1` says otherwise. Every node of a contact face, vertex or
# edge node, is then a slave node. Non-matching faces get dual mortar on the quadratic facets
# (curved ones included; `discretisation = "node-to-surface"` is the alternative); matching faces
# keep node-to-node. 20-node (serendipity) hexahedra, which DOLFINx has no element
# for, are refused with the reason: keep gmsh's default `Mesh.SecondOrderIncomplete = 0`.
#
# Besides `fields.xdmf`, a quadratic run writes `fields_p2.pvd`: the displacement at every node of
# the quadratic elements, which ParaView draws on curved (Lagrange) cells.

# %% [markdown]
# ## The problem file
#
# Every number refers to a physical group above; [the problem-file reference](../problem-file.md)
# lists every key.

# %%
problem = f"""
[mesh]
file = "punch.msh"

[materials.{CELLS["block"]}]
E = 1.0e9
nu = 0.3

[materials.{CELLS["punch"]}]
E = 1.0e9
nu = 0.3

[contact]
surface1 = {FACETS["block top"]}
surface2 = {FACETS["punch bottom"]}
mu_f = 0.3
discretisation = "auto"

[[dirichlet]]
tag = {FACETS["block bottom"]}

[[dirichlet]]
tag = {FACETS["punch top"]}
value = [0.0, -2.0e-3, 0.0]

[solver]
increments = 2
"""
if MPI.COMM_WORLD.rank == 0:
    (out / "punch.toml").write_text(problem)
MPI.COMM_WORLD.barrier()

# %% [markdown]
# ## The run
#
# The same as `dolfinx-nnqem run punch.toml --out results --overwrite` on the command line. The
# run prints the interface it built (mortar, its slave side; node-to-surface with `--order 2`) and
# draws its pictures into
# `results/pictures`: the deformed shape with the pair states, the pair pressures, the load
# curve and the Newton residuals.

# %%
code = main(["run", str(out / "punch.toml"), "--out", str(out / "results"), "--overwrite"])
if code != 0:
    raise SystemExit(code)
pictures = out / "results" / "pictures"
if MPI.COMM_WORLD.rank == 0:
    print(f"pictures: {pictures / 'deformed.png'}, {pictures / 'pair_pressure.png'}")
    if args.order == 2:
        print(f"quadratic displacement for ParaView: {out / 'results' / 'fields_p2.pvd'}")
