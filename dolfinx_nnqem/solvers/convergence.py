"""What every solver reports about one increment, and the error raised when it gives up."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from dolfinx_nnqem.contact.laws import STATE_NAMES  # noqa: F401  (the pair states' names, kept here for old imports)
from dolfinx_nnqem.material.interface import GaussPointValues

if TYPE_CHECKING:
    from mpi4py import MPI

logger = logging.getLogger("dolfinx_nnqem")


@dataclass
class IterationRecord:
    """One nonlinear iteration: relative residuals and what the step did."""

    iteration: int
    equilibrium: float  #: ‖R‖ / load scale (constrained rows excluded)
    contact: float  #: ‖H‖ / load scale (0 without contact)
    step_length: float  #: line-search step α (1 = full Newton step); NaN before the first step
    kind: str  #: "newton", "lm" (Levenberg–Marquardt) or "" for the last, converged record
    states: tuple[int, int, int] = (0, 0, 0)  #: numbers of open, stick, slip pairs
    #: Gauss points on the plastic branch at this iterate; None: not counted (the count interpolates
    #: the return map at every Gauss point, so it is made only for the iteration log and a failure)
    plastic_points: int | None = None
    inner_iterations: int = 0  #: iterations of a nested nonsmooth solve (NNEQM1), else 0
    yield_residual: float = 0.0  #: ‖G̃‖ of NNEQM2's yield rows (relative to the stress unit), else 0

    def line(self, solver: str) -> str:
        """The record as one line of the iteration log, prefixed by ``[solver]``."""
        alpha = "   -  " if np.isnan(self.step_length) else f"{self.step_length:6.3f}"
        inner = f" inner {self.inner_iterations:3d}" if self.inner_iterations else ""
        inner += f"  |G|/σ_u {self.yield_residual:9.3e}" if self.yield_residual else ""
        return (
            f"[{solver}] it {self.iteration:3d}  |R|/F {self.equilibrium:9.3e}  |H|/F {self.contact:9.3e}"
            f"  step {alpha} {self.kind:6s} open/stick/slip {self.states[0]}/{self.states[1]}/{self.states[2]}"
            f"  plastic GP {'-' if self.plastic_points is None else self.plastic_points}{inner}"
        )


@dataclass
class SolveReport:
    """Outcome of one increment solve (what :meth:`Solver.solve_increment` returns)."""

    converged: bool
    iterations: int
    history: list[IterationRecord] = field(default_factory=list)
    message: str = ""
    system_order: int = 0  #: order of the (non)smooth system solved per iteration
    gauss_point_values: GaussPointValues | None = None  #: the solver's own state update (NNEQM2), or None
    geometry_passes: int = 1  #: solves of the increment, each in the contact geometry of the last (current geometry)
    geometry_consistent: bool = False  #: every iterate was evaluated in its own contact geometry (no second solve needed)
    #: open, stick, slip pairs at the last iterate of a nested solve that failed (NNEQM1's condensed
    #: contact solve), or None: the outer iterate the history ends on keeps the states it started from
    inner_states: tuple[int, int, int] | None = None

    @property
    def final(self) -> IterationRecord | None:
        """The last iteration's record (None if there was none)."""
        return self.history[-1] if self.history else None


class ConvergenceError(RuntimeError):
    """An increment did not converge even after the allowed cutbacks."""

    failure: dict  #: set by load stepping: increment, load factor, reason, the worst nodes and pairs


def iteration_log_on(comm: MPI.Comm) -> bool:
    """Whether some rank logs the iterations (the package's logger at INFO, e.g. ``-v``). What is
    counted for that log only is counted by every rank or none: the counts are collective, and a
    program may configure logging on rank 0 alone."""
    from mpi4py import MPI

    return bool(comm.allreduce(logger.isEnabledFor(logging.INFO), op=MPI.LOR))


def count_states(states_local: np.ndarray, comm: MPI.Comm) -> tuple[int, int, int]:
    """Global numbers of open (0), stick (1) and slip (2) pairs."""
    from mpi4py import MPI

    local = np.bincount(np.asarray(states_local, dtype=np.int64), minlength=3)[:3]
    total = np.zeros(3, dtype=np.int64)
    comm.Allreduce(local, total, op=MPI.SUM)
    return int(total[0]), int(total[1]), int(total[2])
