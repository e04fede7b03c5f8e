"""Write the project's meshes (gmsh ``.msh``; the seed's also as XDMF) with the builders of ``dolfinx_nnqem.cases.geometries``.

    python meshes/generate.py                 # all models, default parameters, into meshes/
    python meshes/generate.py two_beams --refine 2 --output-dir /tmp

Written files: ``two_beams.msh`` (the seed benchmark, ``benchmark-two-beams.md``; with
``--refine n``: ``two_beams_refine{n}.msh``) and the same mesh as ``two_beams.xdmf`` + ``.h5``
(DOLFINx's format, which ``demos/two_beams.toml`` reads), ``stacked_blocks.msh``, ``thick_cylinder.msh``,
``three_blocks.msh`` (three unit blocks of height 0.5 stacked along y, 4 × 2 × 4 hexahedra
each: two contact interfaces), ``die_on_slab.msh`` (the Neo-Hookean ironing's mesh at r = 1: the
slab 2 × 0.25 × 0.25 in 16 × 2 × 2 hexahedra, the die over 0.25 ≤ x ≤ 0.5 on its top in 4 × 2 × 2,
which ``demos/neo_hooke_ironing.toml`` reads) and ``indenter_block.msh`` (the half block |x| ≤ 6 mm,
0 ≤ z ≤ 6 mm, −6 ≤ y ≤ 0 mm, graded to h = 0.25 mm at the top point x = z = 0, for a rigid
indenter). They hold the physical groups (tags) documented in ``TwoBeamsTags``,
``StackedBlocksTags``, ``ThickCylinderTags`` and ``BlockStackTags``; read them back with
``dolfinx_nnqem.compat.read_from_msh``.
"""

from __future__ import annotations

import argparse
import pathlib

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
from dolfinx_nnqem.cases import geometries
from dolfinx_nnqem.problem import meshing
from mpi4py import MPI

MODELS = ("two_beams", "stacked_blocks", "thick_cylinder", "three_blocks", "die_on_slab", "indenter_block")


def main(argv: list[str] | None = None) -> list[pathlib.Path]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="*", metavar="MODEL",
                        help=f"models to write, of {', '.join(MODELS)} (default: all)")
    parser.add_argument("--output-dir", type=pathlib.Path, default=pathlib.Path(__file__).parent,
                        help="directory of the .msh files (default: this script's directory)")
    parser.add_argument("--refine", type=int, default=1,
                        help="two beams: element edge 0.2/refine m (default 1)")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.models) - set(MODELS))
    if unknown:
        parser.error(f"unknown model(s) {', '.join(unknown)}; choose from {', '.join(MODELS)}")

    comm = MPI.COMM_SELF  # a file writer: no need to distribute the mesh
    args.output_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for model in args.models or MODELS:
        if model == "two_beams":
            name = "two_beams.msh" if args.refine == 1 else f"two_beams_refine{args.refine}.msh"
            path = args.output_dir / name
            geometries.build_two_beams(comm, refine=args.refine, msh_file=path)
            # and the same mesh, read back from the .msh, in DOLFINx's own format (what
            # demos/two_beams.toml reads: no gmsh library to load)
            mesh, cell_tags, facet_tags = meshing.read_msh(path, comm)
            meshing.write_xdmf(path.with_suffix(".xdmf"), mesh, cell_tags, facet_tags)
            written.append(path.with_suffix(".xdmf"))
        elif model == "stacked_blocks":
            path = args.output_dir / "stacked_blocks.msh"
            mesh, _, _ = geometries.build_stacked_blocks(comm, msh_file=path)
        elif model == "thick_cylinder":
            path = args.output_dir / "thick_cylinder.msh"
            mesh, _, _ = geometries.build_thick_cylinder(comm, msh_file=path)
        elif model == "three_blocks":
            path = args.output_dir / "three_blocks.msh"
            mesh, _, _ = geometries.build_block_stack(comm, 1.0, 1.0, [0.5] * 3, [(4, 2, 4)] * 3, msh_file=path)
        elif model == "die_on_slab":  # the die where the ironing case puts it (neo_hooke_ironing.DIE_X)
            from dolfinx_nnqem.cases.neo_hooke_ironing import DIE_X

            path = args.output_dir / "die_on_slab.msh"
            mesh, _, _ = geometries.build_die_on_slab(comm, 1, DIE_X, msh_file=path)
        else:
            path = args.output_dir / "indenter_block.msh"
            mesh, _, _ = geometries.build_graded_block(comm, 0.25, half=True, msh_file=path)
        num_cells = mesh.topology.index_map(mesh.topology.dim).size_global
        print(f"{path}: {num_cells} hexahedra, {mesh.geometry.x.shape[0]} nodes")
        written.append(path)
    return written


if __name__ == "__main__":
    main()
