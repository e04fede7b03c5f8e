"""The package's own reader of a run's output folder (also of a run that was killed).

:func:`read_results` returns what the folder holds for the increments a run completed:
``summary.json``, the pair tables (``pairs.pvd`` → CSV files) and the fields (``fields.xdmf``
→ HDF5 files, read with h5py). Nothing here needs MPI.

h5py and the PyPI DOLFINx wheel bring two different HDF5 libraries; h5py works in a process
only when it was imported before DOLFINx. :func:`read_fields` therefore reads in a child
process when DOLFINx is already loaded here and h5py was not imported first.
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["read_fields", "read_pairs", "read_results", "read_summary", "start_reading_fields"]

MPI_LAUNCHER_PREFIXES = ("PMI_", "PMIX_", "HYDRA_", "MPIR_", "MPI_LOCAL", "OMPI_", "PRTE_")


def read_summary(folder: str | os.PathLike) -> dict:
    """``summary.json`` (always complete: it is replaced atomically)."""
    return json.loads((Path(folder) / "summary.json").read_text())


def read_pairs(folder: str | os.PathLike) -> list[dict]:
    """The pair tables ``pairs.pvd`` lists: ``[{"load_factor", "rows": [dict per pair]}]``."""
    folder = Path(folder)
    pvd = folder / "pairs.pvd"
    if not pvd.exists():
        return []
    out = []
    for dataset in ET.parse(pvd).iter("DataSet"):
        csv_path = folder / Path(dataset.attrib["file"]).with_suffix(".csv")
        with open(csv_path, newline="") as fh:
            rows = list(csv.DictReader(fh))
        out.append({"load_factor": float(dataset.attrib["timestep"]), "file": str(csv_path), "rows": rows})
    return out


def _h5py_usable_here() -> bool:
    if sys.modules.get("dolfinx") is None:  # not loaded, or blocked (a picture worker, which
        return True  # cannot import compat: it imports DOLFINx)
    from dolfinx_nnqem import compat

    return compat.H5PY_BEFORE_DOLFINX


def read_fields(folder: str | os.PathLike, last_only: bool = False, index: str = "fields.xdmf") -> list[dict]:
    """The increments ``fields.xdmf`` lists (see :func:`dolfinx_nnqem.io.xdmf_steps.read_field_index`);
    with ``last_only`` the last one only; ``index="fields_deformed.xdmf"``: on the deformed mesh."""
    return start_reading_fields(folder, last_only, index)()


def start_reading_fields(folder: str | os.PathLike, last_only: bool = False,
                         index: str = "fields.xdmf") -> Callable[[], list[dict]]:
    """Start reading the fields; returns the function that waits for them (:func:`read_fields`).

    Where h5py cannot be used in this process, a child process reads them, and this process
    can go on meanwhile (the run's pictures draw their curves). The child loads
    :mod:`dolfinx_nnqem.io.xdmf_steps` by its file: through the package it would load DOLFINx.
    """
    if _h5py_usable_here():
        from dolfinx_nnqem.io.xdmf_steps import read_field_index

        steps = read_field_index(folder, last_only, index)
        return lambda: steps
    tmp = tempfile.TemporaryDirectory()
    out = Path(tmp.name) / "fields.npz"
    code = ("import h5py, sys, importlib.util, numpy as np\n"
            "spec = importlib.util.spec_from_file_location('_nnqem_xdmf_steps', sys.argv[1])\n"
            "module = importlib.util.module_from_spec(spec)\n"
            "spec.loader.exec_module(module)\n"
            "steps = module.read_field_index(sys.argv[2], sys.argv[4] == '1', sys.argv[5])\n"
            "arrays = {f'{i}/{k}': np.asarray(v) for i, s in enumerate(steps) for k, v in s.items()}\n"
            "np.savez(sys.argv[3], **arrays)\n")
    # a child of an MPI rank (mpirun) must not take the launcher's variables: it would try to
    # join the parallel job (MPICH: "PMI_Init returned -1") and fail to start
    env = {k: v for k, v in os.environ.items() if not k.startswith(MPI_LAUNCHER_PREFIXES)}
    module = Path(__file__).resolve().with_name("xdmf_steps.py")
    child = subprocess.Popen([sys.executable, "-c", code, str(module), str(folder), str(out), "1" if last_only else "0",
                              index],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)

    def wait() -> list[dict]:
        with tmp:
            try:
                _, stderr = child.communicate(timeout=600)
            except subprocess.TimeoutExpired:
                child.kill()
                child.communicate()
                raise OSError(f"cannot read the fields of {folder}: the reading process took over 600 s") from None
            if child.returncode != 0:
                last = (stderr.strip().splitlines() or ["?"])[-1]
                raise OSError(f"cannot read the fields of {folder}: {last}")
            steps: dict[int, dict] = {}
            with np.load(out) as data:
                for key in data.files:
                    i, name = key.split("/", 1)
                    value = data[key]
                    steps.setdefault(int(i), {})[name] = float(value) if name == "time" else value
            return [steps[i] for i in sorted(steps)]

    return wait


def read_results(folder: str | os.PathLike) -> dict:
    """Everything a run left: ``summary``, ``pairs`` (tables), ``fields`` (steps)."""
    folder = Path(folder)
    return {"summary": read_summary(folder), "pairs": read_pairs(folder),
            "fields": read_fields(folder) if (folder / "fields.xdmf").exists() else []}
