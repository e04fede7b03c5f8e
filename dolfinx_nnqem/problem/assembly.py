"""Assembly of the problem's vectors and matrices into PETSc objects laid out like the displacement space."""

from __future__ import annotations

from collections.abc import Sequence

import dolfinx.fem
import dolfinx.fem.petsc
from petsc4py import PETSc

from dolfinx_nnqem import compat

__all__ = ["assemble_matrix", "assemble_vector"]


def assemble_vector(form: dolfinx.fem.Form, V: dolfinx.fem.FunctionSpace, F: PETSc.Vec | None = None) -> PETSc.Vec:
    """Assemble the linear ``form`` into ``F`` (a new ghosted vector of ``V`` if None), owned
    entries summed over ranks."""
    if F is None:
        F = compat.create_vector(V)
    with F.localForm() as local:
        local.set(0.0)
    dolfinx.fem.petsc.assemble_vector(F, form)
    F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return F


def assemble_matrix(form: dolfinx.fem.Form, bcs: Sequence, A: PETSc.Mat | None = None) -> PETSc.Mat:
    """Assemble the bilinear ``form`` with identity rows and columns at the dofs of ``bcs``, into
    ``A`` (zeroed first) or a new matrix.

    Parameters
    ----------
    form
        A compiled bilinear form.
    bcs
        The Dirichlet conditions whose rows and columns are replaced by the identity.
    A
        A matrix of the form's sparsity to refill, or None for a new one.
    """
    bcs = list(bcs)
    if A is None:
        A = compat.assemble_matrix(form, bcs, diagonal=1.0)
    else:
        A.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(A, form, bcs=bcs)
    A.assemble()
    return A
