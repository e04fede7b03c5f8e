"""The benchmark geometries moved from ``problem/meshing.py`` to ``cases/geometries/`` (issue 42): their
old names still import from ``dolfinx_nnqem.problem.meshing`` until release 0.2, as the same objects,
with a DeprecationWarning naming the new path; what stays there imports without one."""

from __future__ import annotations

import importlib
import warnings

import pytest

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)

OLD_NAMES = ["BlockStackTags", "SphereOnBlockTags", "StackedBlocksTags", "ThickCylinderTags", "TwoBeamsTags",
             "build_block_stack", "build_graded_block", "build_graded_contact_blocks", "build_sphere_on_block",
             "build_stacked_blocks", "build_thick_cylinder", "build_two_beams", "graded_nodes"]
"""Every geometry name that ``dolfinx_nnqem.problem.meshing`` had in release 0.1."""


@pytest.mark.parametrize("name", OLD_NAMES)
def test_an_old_geometry_name_imports_from_meshing_as_the_same_object_with_a_warning(name):
    meshing = importlib.import_module("dolfinx_nnqem.problem.meshing")
    geometries = importlib.import_module("dolfinx_nnqem.cases.geometries")
    pattern = rf"dolfinx_nnqem\.problem\.meshing\.{name} is deprecated .* dolfinx_nnqem\.cases\.geometries"
    with pytest.warns(DeprecationWarning, match=pattern):
        old = getattr(meshing, name)
    assert old is getattr(geometries, name)


def test_the_old_import_statement_still_works_and_the_warning_points_at_it():
    geometries = importlib.import_module("dolfinx_nnqem.cases.geometries")
    with pytest.warns(DeprecationWarning, match="cases.geometries") as record:
        from dolfinx_nnqem.problem.meshing import TwoBeamsTags, build_two_beams
    assert build_two_beams is geometries.build_two_beams and TwoBeamsTags is geometries.TwoBeamsTags
    assert {w.filename for w in record} == {__file__}  # the user's line, not the package's


def test_every_geometry_of_release_0_1_is_still_there():
    """The old names (above) all live on in ``cases.geometries``; a geometry added since (e.g.
    ``build_die_on_slab``) has no old name to keep."""
    geometries = importlib.import_module("dolfinx_nnqem.cases.geometries")
    assert set(OLD_NAMES) <= set(geometries.__all__)


def test_mesh_reading_and_writing_stay_in_meshing_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        from dolfinx_nnqem.problem.meshing import (MeshAndTags, mesh_from_gmsh, read_msh, restore_signal_handlers,
                                                   unsupported_gmsh_cells, write_xdmf)
    assert all(callable(f) for f in (MeshAndTags, mesh_from_gmsh, read_msh, restore_signal_handlers,
                                     unsupported_gmsh_cells, write_xdmf))


def test_a_name_meshing_never_had_is_an_attribute_error():
    meshing = importlib.import_module("dolfinx_nnqem.problem.meshing")
    with pytest.raises(AttributeError, match="has no attribute 'build_pyramid'"):
        meshing.build_pyramid
