"""The necking bar (Simo's benchmark, issue 41): an eighth of a cylindrical bar with a tapered neck,
10-node tetrahedra, as a gmsh ``.msh`` (``docs/verification-materials.md``, "Necking of a cylindrical bar").

    python meshes/necking_bar_mesh.py                      # the three meshes of the benchmark, into meshes/
    python meshes/necking_bar_mesh.py --h-neck 1.2 --output-dir /tmp

The bar: radius ``R0`` = 6.413 mm, length ``LENGTH`` = 53.334 mm; the radius falls linearly from
R0 at the ends to ``NECK`` × R0 (= 0.982 R0) at mid-length, the imperfection that starts the neck.
The model is the eighth x ≥ 0, y ≥ 0, 0 ≤ z ≤ LENGTH/2 (z along the bar's axis, z = 0 its
mid-length): a quarter cone from OpenCASCADE. Elements of size ``h_neck`` up to z = ``FINE_TO``,
growing linearly to ``h_end`` at z = ``COARSE_FROM``; second order (10-node tetrahedra, the new nodes on
the curved surface). Tags: :class:`NeckingBarTags`.
"""

from __future__ import annotations

import argparse
import math
import pathlib

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import gmsh
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.problem.gmsh_tools import EPS, add_group, surfaces_of
from dolfinx_nnqem.problem.meshing import MeshAndTags, mesh_from_gmsh

R0 = 6.413  # mm: the bar's radius at its ends
LENGTH = 53.334  # mm: the bar's length
NECK = 0.982  # the radius at mid-length over R0 (a 1.8 % reduction)
FINE_TO, COARSE_FROM = 5.0, 16.0  # mm: elements of h_neck for z ≤ FINE_TO, of h_end for z ≥ COARSE_FROM
MESHES = {"coarse": (1.6, 3.2), "medium": (1.1, 2.6), "fine": (0.8, 2.0)}  # (h_neck, h_end), mm


class NeckingBarTags:
    """Tags of :func:`build_necking_bar`.

    Cells: ``BODY`` = 1. Facets: ``SYMMETRY_X`` = 1 (x = 0), ``SYMMETRY_Y`` = 2 (y = 0), ``MIDDLE`` = 3
    (z = 0, the mid-length plane), ``END`` = 4 (z = LENGTH/2, the gripped end), ``SURFACE`` = 5 (the
    lateral surface).
    """

    BODY = 1
    SYMMETRY_X = 1
    SYMMETRY_Y = 2
    MIDDLE = 3
    END = 4
    SURFACE = 5


def radius_at(z: float | np.ndarray) -> float | np.ndarray:
    """The bar's undeformed radius at the axial position ``z`` (0 ≤ z ≤ LENGTH/2): NECK·R0 at z = 0,
    R0 at the end, linear in between."""
    return R0 * (NECK + (1.0 - NECK) * np.asarray(z) / (0.5 * LENGTH))


def build_necking_bar(comm: MPI.Comm = MPI.COMM_WORLD, h_neck: float = 1.6, h_end: float = 3.2, *,
                      msh_file: str | pathlib.Path | None = None) -> MeshAndTags:
    """The eighth of the necking bar (module docstring), 10-node tetrahedra of size ``h_neck`` (mm)
    at the neck and ``h_end`` at the end; written to ``msh_file`` too if given."""
    if not 0 < h_neck <= h_end:
        raise ValueError(f"need 0 < h_neck <= h_end, got h_neck = {h_neck!r}, h_end = {h_end!r}")
    return mesh_from_gmsh(comm, "necking_bar", lambda: _build_model(h_neck, h_end), msh_file, order=2)


def _build_model(h_neck: float, h_end: float) -> None:
    """The gmsh model of :func:`build_necking_bar` on the current model: geometry, sizes, groups, mesh."""
    half = 0.5 * LENGTH
    volume = gmsh.model.occ.addCone(0, 0, 0, 0, 0, half, NECK * R0, R0, angle=0.5 * math.pi)
    gmsh.model.occ.synchronize()
    size = gmsh.model.mesh.field.add("MathEval")
    growth = (h_end - h_neck) / (COARSE_FROM - FINE_TO)
    gmsh.model.mesh.field.setString(
        size, "F", f"{h_neck} + {growth} * Min({COARSE_FROM - FINE_TO}, Max(0, z - {FINE_TO}))")
    gmsh.model.mesh.field.setAsBackgroundMesh(size)
    for option in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
        gmsh.option.setNumber(option, 0)
    T = NeckingBarTags
    names = {T.SYMMETRY_X: "symmetry_x", T.SYMMETRY_Y: "symmetry_y", T.MIDDLE: "middle", T.END: "end",
             T.SURFACE: "surface"}
    for tag, surfaces in _classify_surfaces([volume]).items():
        add_group(2, surfaces, tag, names[tag])
    add_group(3, [volume], T.BODY, "bar")
    gmsh.option.setNumber("Mesh.Optimize", 1)
    gmsh.model.mesh.generate(3)


def _classify_surfaces(volumes: list[int]) -> dict[int, list[int]]:
    """The bar's boundary surfaces by tag of :class:`NeckingBarTags` (by bounding boxes)."""
    T = NeckingBarTags
    groups: dict[int, list[int]] = {tag: [] for tag in (T.SYMMETRY_X, T.SYMMETRY_Y, T.MIDDLE, T.END, T.SURFACE)}
    tol = EPS * 10 * LENGTH
    for s in sorted(surfaces_of(volumes)):
        box = gmsh.model.getBoundingBox(2, s)
        lo, hi = np.array(box[:3]), np.array(box[3:])
        if hi[2] - lo[2] < tol:
            groups[T.MIDDLE if hi[2] < tol else T.END].append(s)
        elif hi[0] < tol:
            groups[T.SYMMETRY_X].append(s)
        elif hi[1] < tol:
            groups[T.SYMMETRY_Y].append(s)
        else:
            groups[T.SURFACE].append(s)
    for tag, surfaces in groups.items():
        if len(surfaces) != 1:
            raise RuntimeError(f"facet tag {tag}: expected one surface of the quarter cone, found {surfaces}")
    return groups


def main(argv: list[str] | None = None) -> list[pathlib.Path]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output-dir", type=pathlib.Path, default=pathlib.Path(__file__).parent)
    parser.add_argument("--h-neck", type=float, help="element size at the neck (mm); default: the three meshes")
    parser.add_argument("--h-end", type=float, help="element size at the end (mm; default 2 h_neck)")
    args = parser.parse_args(argv)
    sizes = MESHES if args.h_neck is None else {f"h{args.h_neck:g}": (args.h_neck, args.h_end or 2 * args.h_neck)}
    args.output_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, (h_neck, h_end) in sizes.items():
        path = args.output_dir / f"necking_bar_{name}.msh"
        mesh, _, _ = build_necking_bar(MPI.COMM_SELF, h_neck, h_end, msh_file=path)
        cells = mesh.topology.index_map(3).size_global
        print(f"{path}: {cells} 10-node tetrahedra, {mesh.geometry.x.shape[0]} nodes (h = {h_neck:g} to {h_end:g} mm)")
        written.append(path)
    return written


if __name__ == "__main__":
    main()
