"""The stack differences of ``compat``: detected by capability, each path exercised where it can be."""

from dolfinx_nnqem import compat  # noqa: I001  (first: loads MPI/PETSc for the PyPI wheel)

import dolfinx.mesh
import gmsh
import numpy as np
import pyvista
from mpi4py import MPI


def test_gmsh_optimizer_is_chosen_by_what_gmsh_was_built_with():
    """Netgen where gmsh lists it in its build options (PyPI), gmsh's own optimizer otherwise
    (Debian 13), and either one leaves a valid tetrahedral mesh."""
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("box")
        gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.4)
        gmsh.model.mesh.generate(3)
        listed = "Netgen" in gmsh.option.getString("General.BuildOptions").split()
        used = compat.optimize_tetrahedra()
        assert used == ("Netgen" if listed else "gmsh") and compat.gmsh_has_netgen() == listed
        types, tags, _ = gmsh.model.mesh.getElements(3)
        assert list(types) == [4] and len(tags[0]) > 0  # linear tetrahedra only
    finally:
        gmsh.finalize()


class _OldDataSet:
    """pyvista 0.44's signature: extract_surface without ``algorithm``."""

    def extract_surface(self, pass_pointid=True, pass_cellid=True, nonlinear_subdivision=1, progress_bar=False):
        return "old"


class _NewDataSet:
    """pyvista 0.49's signature: ``algorithm`` chooses the filter."""

    def extract_surface(self, pass_pointid=True, pass_cellid=True, nonlinear_subdivision=None, algorithm=None,
                        progress_bar=False):
        return f"new:{algorithm}"


def test_outer_surface_with_either_pyvista_signature():
    assert compat.extract_outer_surface(_OldDataSet()) == "old"
    assert compat.extract_outer_surface(_NewDataSet()) == "new:dataset_surface"
    grid = pyvista.ImageData(dimensions=(3, 3, 3)).cast_to_unstructured_grid()
    surface = compat.extract_outer_surface(grid)  # the installed pyvista
    assert surface.n_cells == 6 * 4  # the cube's 6 faces, 2 × 2 quadrilaterals each


def test_entities_to_geometry_of_no_entities():
    """DOLFINx 0.9 divides by zero when asked for no entities (a rank that owns none of a surface)."""
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1)
    mesh.topology.create_connectivity(2, 3)
    assert compat.entities_to_geometry(mesh, 2, np.zeros(0, dtype=np.int32)).shape == (0, 0)
    nodes = compat.entities_to_geometry(mesh, 2, np.array([0, 1], dtype=np.int32))
    assert nodes.shape == (2, 3) and np.all(nodes >= 0)


def test_parallel_mumps_ordering_is_chosen_by_what_petsc_has():
    """Issue 39, item 13: on several ranks the monolithic solver's MUMPS factorisation takes METIS
    where PETSc has it and PORD where it has not (Debian 13: MUMPS's automatic choice returned
    residuals of order one for the pressed blocks); one rank, another package and the user's own
    ordering are left alone."""
    from petsc4py import PETSc

    from dolfinx_nnqem.numerics.linalg import direct_options

    expected = 5 if PETSc.Sys.hasExternalPackage("metis") else 4
    print(f"\n  METIS in PETSc: {PETSc.Sys.hasExternalPackage('metis')}; ICNTL(7) on 2 ranks: "
          f"{direct_options({}, 2).get('mat_mumps_icntl_7')}")
    assert compat.parallel_mumps_ordering() == {"mat_mumps_icntl_7": expected}
    assert direct_options({}, 2)["mat_mumps_icntl_7"] == expected
    assert "mat_mumps_icntl_7" not in direct_options({}, 1)
    assert direct_options({"mat_mumps_icntl_7": 0}, 2)["mat_mumps_icntl_7"] == 0
    assert "mat_mumps_icntl_7" not in direct_options({"pc_factor_mat_solver_type": "superlu_dist"}, 2)


class _OldPlot:
    """A chart plot of a VTK whose ``SetColor`` takes the floats (no ``SetColorF``)."""

    def __init__(self):
        self.colour = None

    def SetColor(self, red, green, blue):  # noqa: N802  (VTK's name)
        self.colour = (red, green, blue)


def test_a_plot_colour_with_either_vtk_signature():
    """``set_plot_colour``: ``SetColorF`` where VTK has it (the installed one), ``SetColor`` with
    the floats where it does not."""
    from vtkmodules.vtkChartsCore import vtkPlotLine

    old = _OldPlot()
    compat.set_plot_colour(old, 0.25, 0.5, 1.0)
    assert old.colour == (0.25, 0.5, 1.0)
    line = vtkPlotLine()
    compat.set_plot_colour(line, 0.25, 0.5, 1.0)
    colour = [0.0, 0.0, 0.0]
    line.GetColorF(colour) if hasattr(line, "GetColorF") else line.GetColor(colour)
    assert np.allclose(colour, (0.25, 0.5, 1.0), atol=1 / 255)  # (kept as bytes)
