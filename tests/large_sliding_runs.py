"""The large-sliding cases of tests/mpi_scripts/large_sliding.py run on several ranks and compared with
serial: what the MPI tests of large sliding share (``tests/mpi/test_large_sliding_mpi.py``,
``tests/mpi/test_consistent_slides_mpi.py``).

Pairs are owned by the rank of their slave node, so they are compared after sorting by the slave
node's position.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dolfinx_nnqem import compat

SCRIPTS = Path(__file__).resolve().parent / "mpi_scripts"
sys.path.insert(0, str(SCRIPTS))

from large_sliding import solve  # noqa: E402  (the serial runs, for the tests)

__all__ = ["Comparison", "compare", "results", "run_on_ranks", "solve"]


def run_on_ranks(out: Path, ranks: int, names: list[str]) -> dict[str, np.ndarray]:
    """large_sliding.py on ``ranks`` ranks for ``names`` (CASE or CASE/METHOD): what rank 0 wrote to
    ``out``; a failed job fails the test with its output."""
    cmd = [*compat.mpiexec(), "-n", str(ranks), sys.executable, str(SCRIPTS / "large_sliding.py"), str(out), *names]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=compat.mpi_environment())
    assert run.returncode == 0, f"{' '.join(cmd)} failed:\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}"
    return dict(np.load(out))


def results(parallel: dict[str, np.ndarray], case: str, method: str) -> dict[str, np.ndarray]:
    """The records of ``case``/``method`` in a run's output, by name ("position", "force", "total", ...)."""
    prefix = f"{case}/{method}/"
    return {key.rsplit("/", 1)[1]: value for key, value in parallel.items() if key.startswith(prefix)}


@dataclass(frozen=True)
class Comparison:
    """A run against the serial one, pairs sorted by their slave node's position."""

    pairs: tuple[int, int]  #: pairs of the run and of the serial run
    position: float  #: largest difference of the sorted pairs' slave positions (inf if the counts differ)
    force: float  #: largest difference of their forces / the largest serial pair force
    total: float  #: |resultant − serial resultant| / |serial resultant|


def _order(position: np.ndarray) -> np.ndarray:
    x = position.round(9)
    return np.lexsort((x[:, 2], x[:, 1], x[:, 0]))


def compare(p: dict[str, np.ndarray], s: dict[str, np.ndarray]) -> Comparison:
    """The run ``p`` against the serial run ``s`` (:func:`results` of each)."""
    i, j = _order(p["position"]), _order(s["position"])
    pairs = (len(i), len(j))
    if pairs[0] != pairs[1]:
        return Comparison(pairs, np.inf, np.inf, np.inf)
    position = float(np.abs(p["position"][i] - s["position"][j]).max())
    force = float(np.abs(p["force"][i] - s["force"][j]).max() / np.abs(s["force"]).max())
    total = float(np.linalg.norm(p["total"] - s["total"]) / np.linalg.norm(s["total"]))
    return Comparison(pairs, position, force, total)
