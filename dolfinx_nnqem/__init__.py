"""dolfinx_nnqem: elastoplastic frictional contact in DOLFINx by nonsmooth equations (NNEQM).

``compat`` is imported first in a user's program: with the PyPI wheel, ``dolfinx_solver`` must
be loaded before ``dolfinx`` and ``petsc4py`` (the command line does it in :func:`cli.main`). The layers, each a subpackage importing only those below it
(``docs/architecture.md``): ``numerics``; ``material`` and ``contact``; ``problem``; ``solvers``;
``io`` and ``cases``; the front end ``cli`` and ``problem_file``. Old module paths of release 0.1
still import, with a deprecation warning (:mod:`dolfinx_nnqem._moved`).
"""

# first: in the command line, importing interrupts holds Ctrl-C and SIGTERM (interrupts.py); the
# command line imports MPI, PETSc and DOLFINx itself once it has read its arguments (cli.main)
from dolfinx_nnqem import interrupts as _interrupts

if not _interrupts.is_command_line():
    from dolfinx_nnqem import compat  # noqa: F401  (before dolfinx / petsc4py in a user's program)
from dolfinx_nnqem import _moved  # noqa: E402

__version__ = "0.1.0"

_moved.install()
