"""The benchmark geometries: gmsh model builders returning distributed DOLFINx meshes with cell and
facet tags, one module each: the seed's two beams (:mod:`.two_beams`), two stacked blocks
(:mod:`.stacked_blocks`), a stack of blocks (:mod:`.block_stack`), a die on a slab (:mod:`.die_on_slab`),
a thick-walled cylinder (:mod:`.thick_cylinder`), blocks graded towards a contact point
(:mod:`.graded_blocks`) and a sphere on a block (:mod:`.sphere_on_block`). The problems built on
them are the modules of :mod:`dolfinx_nnqem.cases`.

Every builder constructs its gmsh model on rank 0 only, optionally writes it to a ``.msh`` file,
and distributes it with :func:`dolfinx_nnqem.problem.meshing.mesh_from_gmsh`. The meshes are
structured 8-node hexahedra (transfinite curves, surfaces and volumes, recombined), because the
node-to-node contact pairs need coincident (or facing) nodes and the seed uses trilinear bricks;
the block stack may be tetrahedra, and the sphere on a block is unstructured tetrahedra. Bodies
that may come into contact share no nodes (:mod:`dolfinx_nnqem.problem.gmsh_tools`). The tag
numbers of each model are the class attributes of its ``*Tags`` class. The builders that take
``order = 2`` make complete second-order elements (27-node hexahedra, 10-node tetrahedra).
"""

from dolfinx_nnqem.cases.geometries.block_stack import BlockStackTags, build_block_stack
from dolfinx_nnqem.cases.geometries.die_on_slab import build_die_on_slab
from dolfinx_nnqem.cases.geometries.graded_blocks import build_graded_block, build_graded_contact_blocks, graded_nodes
from dolfinx_nnqem.cases.geometries.sphere_on_block import SphereOnBlockTags, build_sphere_on_block
from dolfinx_nnqem.cases.geometries.stacked_blocks import StackedBlocksTags, build_stacked_blocks
from dolfinx_nnqem.cases.geometries.thick_cylinder import ThickCylinderTags, build_thick_cylinder
from dolfinx_nnqem.cases.geometries.two_beams import TwoBeamsTags, build_two_beams

__all__ = ["BlockStackTags", "SphereOnBlockTags", "StackedBlocksTags", "ThickCylinderTags", "TwoBeamsTags",
           "build_block_stack", "build_die_on_slab", "build_graded_block", "build_graded_contact_blocks",
           "build_sphere_on_block", "build_stacked_blocks", "build_thick_cylinder", "build_two_beams", "graded_nodes"]
