"""Small PETSc helpers shared by the solvers."""

from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

DIRECT_SOLVER_OPTIONS = {
    "ksp_type": "preonly",
    "pc_type": "lu",
    "pc_factor_mat_solver_type": "mumps",
}
"""Default: MUMPS LU. User ``petsc_options`` are merged over these."""


def create_ksp(comm, prefix: str, petsc_options: dict | None = None) -> PETSc.KSP:
    """A KSP configured from ``DIRECT_SOLVER_OPTIONS`` updated by ``petsc_options`` under ``prefix``."""
    opts = PETSc.Options()
    for key, value in {**DIRECT_SOLVER_OPTIONS, **(petsc_options or {})}.items():
        opts[prefix + key] = value
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    ksp.setFromOptions()
    return ksp


def global_norm(array: np.ndarray, comm) -> float:
    """2-norm of an array distributed over ``comm`` (each rank holds its own rows)."""
    return math.sqrt(comm.allreduce(float(np.sum(np.asarray(array) ** 2)), op=MPI.SUM))
