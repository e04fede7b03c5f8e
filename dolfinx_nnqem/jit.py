"""Compilation of the package's forms and expressions (FFCx → C → cffi), with faster kernels.

FFCx writes a bilinear form on vector hexahedra as long chains ``A[i] += t_k[i] * φ[j]`` that
the C compiler may not reorder under strict IEEE semantics, so the chains stay scalar. Allowing
the reassociation of sums (``-fassociative-math``, which needs ``-fno-signed-zeros`` and
``-fno-trapping-math``) lets GCC vectorise them: the consistent tangent of the pressed blocks
assembles 3.6× faster (57.6 → 15.9 µs per hexahedron, ``-O2``; 13.9 with ``-O3``). The results
change only in the last bits (sums are added in another order). Deliberately NOT
``-ffast-math``: that would also assume there are no NaN or infinities (a NaN must still reach
the solvers' checks) and, linked into a shared library, could flush subnormals process-wide.
No ``-march``: the kernels land in the disk cache (``~/.cache/fenics``), which may be shared by
machines with different instruction sets.

Set :data:`KERNEL_COMPILE_ARGS` to ``None`` before building a problem to compile with
DOLFINx's own options instead (its defaults, or ``dolfinx_jit_options.json``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import dolfinx.fem as fem

if TYPE_CHECKING:
    import numpy as np
    import ufl

KERNEL_COMPILE_ARGS: list[str] | None = [
    "-O3", "-g0", "-fno-math-errno", "-fno-trapping-math", "-fno-signed-zeros", "-fassociative-math",
]
"""C compiler flags of the package's kernels (``cffi_extra_compile_args``); None: DOLFINx's."""


def jit_options() -> dict:
    """The ``jit_options`` passed to :func:`dolfinx.fem.form` and :class:`dolfinx.fem.Expression`."""
    if KERNEL_COMPILE_ARGS is None:
        return {}
    return {"cffi_extra_compile_args": list(KERNEL_COMPILE_ARGS)}


def form(ufl_form: ufl.Form) -> fem.Form:
    """``dolfinx.fem.form`` with the package's compiler flags (see :func:`_compile`)."""
    return _compile(lambda: fem.form(ufl_form, jit_options=jit_options()), ufl_form)


def expression(expr: ufl.core.expr.Expr, points: np.ndarray) -> fem.Expression:
    """``dolfinx.fem.Expression`` at reference ``points`` with the package's compiler flags."""
    return _compile(lambda: fem.Expression(expr, points, jit_options=jit_options()), expr)


# -- a disk cache that a killed compile cannot break ---------------------------------------------
STALE_AGE_S = 60.0
"""An unfinished cache entry (``X.c`` without ``X.c.cached``) untouched for this long, found
while this package's compile lock is held, belongs to a killed compile and is set aside."""
LOCK_NAME = ".dolfinx_nnqem-jit.lock"
_swept: set = set()


def _cache_dir():
    import dolfinx.jit
    from pathlib import Path

    return Path(dolfinx.jit.get_options(jit_options())["cache_dir"])


def _comm_of(expr):
    import ufl
    from mpi4py import MPI

    try:
        domain = ufl.domain.extract_unique_domain(expr) if not isinstance(expr, ufl.Form) else expr.ufl_domain()
        return domain.ufl_cargo().comm
    except Exception:
        return MPI.COMM_WORLD


def _set_aside(c_file) -> bool:
    """Rename an unfinished ``X.c`` to ``X.c.failed`` (what FFCx itself does after a failed
    compile), so that the next compile starts afresh instead of waiting for it."""
    import os

    try:
        os.replace(c_file, c_file.with_suffix(".c.failed"))
        return True
    except OSError:
        return False


def _sweep(cache) -> list:
    """Set aside every unfinished entry older than :data:`STALE_AGE_S` (under the lock)."""
    import time

    stale = []
    for c_file in cache.glob("libffcx_*.c"):
        try:
            if not c_file.with_suffix(".c.cached").exists() and time.time() - c_file.stat().st_mtime > STALE_AGE_S:
                if _set_aside(c_file):
                    stale.append(c_file)
        except OSError:
            pass
    return stale


def _compile(make, expr):
    """Run ``make()`` (a DOLFINx JIT compile) so that a killed earlier compile cannot break it.

    FFCx marks a module as being compiled by creating ``X.c`` and as finished by ``X.c.cached``;
    a process that waits for an ``X.c`` without ``X.c.cached`` gives up after ``timeout`` seconds
    ("JIT compilation timed out"). A compile killed between the two (Ctrl-C or a kill during a
    first run) therefore broke every later run. Here the compiling rank (rank 0) holds an
    exclusive ``flock`` on ``CACHE/.dolfinx_nnqem-jit.lock`` while it compiles: concurrent
    runs of the package wait for each other instead of timing out, and an unfinished entry seen
    under the lock is stale. Stale entries are set aside before the first compile of the
    process (those older than :data:`STALE_AGE_S`) and, if FFCx still times out on one, that
    entry is set aside and the compile retried once (every rank agrees on the retry).
    """
    import fcntl
    import logging
    import os
    import re

    comm = _comm_of(expr)
    root = comm.rank == 0
    fd = None
    if root:
        cache = _cache_dir()
        try:
            cache.mkdir(parents=True, exist_ok=True)
            fd = os.open(cache / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
            fcntl.flock(fd, fcntl.LOCK_EX)
            if str(cache) not in _swept:
                _swept.add(str(cache))
                for c_file in _sweep(cache):
                    logging.getLogger("dolfinx_nnqem").warning(f"JIT cache: set aside {c_file} (a killed compile)")
        except OSError:  # a read-only or odd cache: compile as DOLFINx would
            if fd is not None:
                os.close(fd)
            fd = None
    try:
        for attempt in (0, 1):
            try:
                return make()
            except (TimeoutError, RuntimeError) as error:
                stale = None
                if root and attempt == 0:
                    match = re.search(r"remove (\S+\.c)\)", str(error))
                    if match and "timed out" in str(error):
                        from pathlib import Path

                        stale = Path(match.group(1))
                retry = stale is not None and _set_aside(stale)
                if comm.size > 1:
                    retry = comm.bcast(retry, root=0)
                if not retry:
                    raise
                if root:
                    logging.getLogger("dolfinx_nnqem").warning(f"JIT cache: set aside {stale} (a killed compile); "
                                                               "compiling again")
    finally:
        if fd is not None:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
