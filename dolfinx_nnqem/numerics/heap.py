"""The C heap's free pages given back to the operating system before the phases where a run peaks.

PETSc's matrices and vectors, DOLFINx's packed coefficients and NumPy's arrays come from the C
library's ``malloc``. glibc keeps what is freed inside the process: small blocks between live
ones, and blocks below its mmap threshold, which it raises (up to 32 MB) each time a larger block
is freed. Such free memory stays resident, and a later phase that needs fresh blocks of other
sizes (an AMG set-up, the Krylov basis filling up) adds to it instead of using it. On the pressed
blocks that is a tenth to a sixth of a rank's resident memory by the end of a run
(``docs/performance.md``, "Speed, second round: a million dofs", "6. The peak, per phase").

:func:`release_free_heap` is glibc's ``malloc_trim(0)``: every whole free page of the heap is
handed back (``madvise``), the live blocks are not touched, so no value changes. It costs a walk
over the heap's free blocks (milliseconds) and the page faults of the pages used again.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable

__all__ = ["release_free_heap"]


def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim``, or None where the C library has none (musl, macOS)."""
    try:
        libc = ctypes.CDLL(None)
    except OSError:  # pragma: no cover - a platform without a dynamic C library
        return None
    trim = getattr(libc, "malloc_trim", None)
    if trim is None:  # pragma: no cover - not glibc
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


_TRIM = _malloc_trim()


def release_free_heap() -> bool:
    """Give the C heap's whole free pages back to the operating system (this process only).

    Returns
    -------
    bool
        True if some memory was given back; False if there was none to give, or the C library
        has no ``malloc_trim`` (not glibc: nothing is done).
    """
    if _TRIM is None:  # pragma: no cover - not glibc
        return False
    return bool(_TRIM(0))
