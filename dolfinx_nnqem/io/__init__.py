"""What a run leaves and what reads it: the results writer (:mod:`.output`: fields, pair tables,
``summary.json``), crash-safe files (:mod:`.field_series`, :mod:`.safe_io`, :mod:`.locking`),
checkpoints (:mod:`.checkpoint`), readers (:mod:`.reader`), tables of a solved problem
(:mod:`.results`), pictures (:mod:`.plots`, :mod:`.run_pictures`, drawn by
:mod:`.picture_worker` while the run solves) and FCLIB export (:mod:`.fclib`). Writers are
callbacks of load stepping; nothing here solves.

The public names below are imported when first used (:func:`__getattr__`), not with the
package: a module of it that needs no DOLFINx (the pictures, the readers) imports without it,
as the command line's picture worker does before DOLFINx is loaded.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from dolfinx_nnqem.io.checkpoint import Checkpointer, restore
    from dolfinx_nnqem.io.output import ResultsWriter
    from dolfinx_nnqem.io.reader import read_fields, read_pairs, read_results, read_summary
    from dolfinx_nnqem.io.results import equilibrium_check, pair_table, reactions

_HOMES = {"Checkpointer": "checkpoint", "restore": "checkpoint", "ResultsWriter": "output",
          "read_fields": "reader", "read_pairs": "reader", "read_results": "reader", "read_summary": "reader",
          "equilibrium_check": "results", "pair_table": "results", "reactions": "results"}
"""Public name → the module of this package that defines it."""

__all__ = ["Checkpointer", "ResultsWriter", "equilibrium_check", "pair_table", "reactions", "read_fields",
           "read_pairs", "read_results", "read_summary", "restore"]


def __getattr__(name: str) -> Any:
    """A public name of :data:`__all__`, imported from its module on first use (PEP 562); or a
    module of this package (``io.output``, ``io.plots``), imported as ``import`` would: the
    package imported its writer, checkpoint, reader and results modules eagerly before."""
    if name in _HOMES:
        value = getattr(importlib.import_module(f"{__name__}.{_HOMES[name]}"), name)
        globals()[name] = value
        return value
    try:
        return importlib.import_module(f"{__name__}.{name}")
    except ModuleNotFoundError as error:
        if error.name != f"{__name__}.{name}":  # the module exists; something it imports does not
            raise
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
