"""The steps of a run's ``fields.xdmf``, read with h5py: this module imports nothing of the package.

The PyPI DOLFINx wheel and h5py bring two HDF5 libraries, and h5py works in a process only when
it was imported before DOLFINx (:mod:`dolfinx_nnqem.io.reader`). A run that draws its pictures
has DOLFINx loaded, so the fields are read in a child process; the child loads this file by its
path, not through the package, whose ``__init__`` would load DOLFINx (a third of a second, and
the reason the child process cost the pictures of a small run half a second).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

__all__ = ["child", "data_path", "read_field_index"]


def read_field_index(folder: str | os.PathLike, last_only: bool = False, index: str = "fields.xdmf") -> list[dict]:
    """The increments ``fields.xdmf`` lists, read with h5py (no DOLFINx, any number of ranks).

    Returns one dict per increment: ``time`` (the load factor), ``geometry`` (nodes, 3),
    ``topology`` (cells, nodes per cell) and every field by name (nodal or cell values); with
    ``last_only``, the last increment only. ``index``: another index of the folder of the same
    form (``fields_deformed.xdmf``: the geometry is the deformed mesh's). Raises
    :class:`OSError` naming the file that cannot be read.
    """
    import h5py

    folder = Path(folder)
    tree = ET.parse(folder / index)
    grids = [grid for grid in tree.iter("Grid") if grid.get("GridType") == "Uniform"]
    steps = []
    for grid in grids[-1:] if last_only else grids:
        step: dict[str, float | np.ndarray] = {"time": float(child(grid, "Time").attrib["Value"])}
        for tag, key in (("Topology", "topology"), ("Geometry", "geometry")):
            step[key] = _read_item(folder, child(child(grid, tag), "DataItem"), h5py)
        for attribute in grid.findall("Attribute"):
            step[attribute.attrib["Name"]] = _read_item(folder, child(attribute, "DataItem"), h5py)
        steps.append(step)
    return steps


def child(element: ET.Element, tag: str) -> ET.Element:
    """The first ``tag`` child of ``element``; a ValueError naming both in a damaged file."""
    found = element.find(tag)
    if found is None:
        raise ValueError(f"XDMF: a {element.tag} without {tag}")
    return found


def data_path(item: ET.Element) -> str:
    """The data a DataItem points to (``file.h5:/dataset``); a ValueError in a damaged file."""
    if item.text is None:
        raise ValueError("XDMF: an empty DataItem")
    return item.text.strip()


def _read_item(folder: Path, item: ET.Element, h5py) -> np.ndarray:
    file, dataset = data_path(item).split(":", 1)
    try:
        with h5py.File(folder / file, "r") as h5:
            return np.asarray(h5[dataset])
    except (OSError, KeyError) as error:
        raise OSError(f"cannot read {dataset} from {folder / file}: {error}") from error

