"""What a run leaves and what reads it: the results writer (:mod:`.output`: fields, pair tables,
``summary.json``), crash-safe files (:mod:`.field_series`, :mod:`.safe_io`, :mod:`.locking`),
checkpoints (:mod:`.checkpoint`), readers (:mod:`.reader`), tables of a solved problem
(:mod:`.results`), pictures (:mod:`.plots`, :mod:`.run_pictures`) and FCLIB export
(:mod:`.fclib`). Writers are callbacks of load stepping; nothing here solves."""

from dolfinx_nnqem.io.checkpoint import Checkpointer, restore
from dolfinx_nnqem.io.output import ResultsWriter
from dolfinx_nnqem.io.reader import read_fields, read_pairs, read_results, read_summary
from dolfinx_nnqem.io.results import equilibrium_check, pair_table, reactions

__all__ = ["Checkpointer", "ResultsWriter", "equilibrium_check", "pair_table", "reactions", "read_fields",
           "read_pairs", "read_results", "read_summary", "restore"]
