"""Point clouds as VTK XML PolyData (``.vtp``) text, written without VTK.

The pair files of a run (:class:`dolfinx_nnqem.io.output.PairWriter`) are point clouds: one
vertex per pair with its arrays. Building them with pyvista and VTK's XML writer cost the run
the import of both (most of the output time of a small run, ``docs/performance.md``), and VTK's
file output crashed the process on a full disk (issue 31). The format is simple enough to write
here: each array is ``format="binary"``, i.e. base64 of an 8-byte length header (``header_type
="UInt64"``) followed by the raw values in the machine's byte order, which every VTK reader
(ParaView's included) reads back bit for bit.
"""

from __future__ import annotations

import base64
import sys
from collections.abc import Mapping

import numpy as np

__all__ = ["point_cloud_text"]

_TYPES = {np.dtype(np.float64): "Float64", np.dtype(np.int32): "Int32", np.dtype(np.int64): "Int64"}


def _data_array(name: str, values: np.ndarray, *, field_data: bool = False) -> str:
    """One ``<DataArray>`` element: float64, int32 or int64 values, one or more components."""
    values = np.ascontiguousarray(values)
    kind = _TYPES.get(values.dtype)
    if kind is None:
        raise TypeError(f"VTK array {name!r}: dtype {values.dtype} is not float64, int32 or int64")
    raw = values.tobytes()
    encoded = base64.b64encode(np.uint64(len(raw)).tobytes() + raw).decode("ascii")
    if field_data:
        shape = f'NumberOfTuples="{values.shape[0]}"'
    else:
        shape = f'NumberOfComponents="{values.shape[1] if values.ndim == 2 else 1}"'
    return f'        <DataArray type="{kind}" Name="{name}" {shape} format="binary">{encoded}</DataArray>'


def point_cloud_text(points: np.ndarray, point_data: Mapping[str, np.ndarray],
                     field_data: Mapping[str, np.ndarray] | None = None) -> str:
    """The ``.vtp`` text of a point cloud with one vertex cell per point.

    Parameters
    ----------
    points
        (n, 3) coordinates.
    point_data
        Arrays of n values or (n, k) components per point, float64 or int32.
    field_data
        Arrays attached to the whole data set (e.g. the load factor).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = points.shape[0]
    for name, values in point_data.items():
        if np.shape(values)[0] != n:
            raise ValueError(f"VTK array {name!r} has {np.shape(values)[0]} values for {n} points")
    byte_order = "LittleEndian" if sys.byteorder == "little" else "BigEndian"
    lines = ['<?xml version="1.0"?>',
             f'<VTKFile type="PolyData" version="1.0" byte_order="{byte_order}" header_type="UInt64">',
             "  <PolyData>"]
    if field_data:
        lines += ["    <FieldData>"]
        lines += [_data_array(k, np.atleast_1d(v), field_data=True) for k, v in field_data.items()]
        lines += ["    </FieldData>"]
    lines += [f'    <Piece NumberOfPoints="{n}" NumberOfVerts="{n}" NumberOfLines="0" NumberOfStrips="0" '
              'NumberOfPolys="0">', "      <PointData>"]
    lines += [_data_array(k, v) for k, v in point_data.items()]
    lines += ["      </PointData>", "      <Points>", _data_array("Points", points), "      </Points>",
              "      <Verts>", _data_array("connectivity", np.arange(n, dtype=np.int64)),
              _data_array("offsets", np.arange(1, n + 1, dtype=np.int64)), "      </Verts>",
              "    </Piece>", "  </PolyData>", "</VTKFile>"]
    return "\n".join(lines) + "\n"
