"""dolfinx_nnqem: elastoplastic frictional contact in DOLFINx by nonsmooth equations (NNEQM).

``compat`` is imported first: with the PyPI wheel, ``dolfinx_solver`` must be loaded before
``dolfinx`` and ``petsc4py``. The layers, each a subpackage importing only those below it
(``docs/architecture.md``): ``numerics``; ``material`` and ``contact``; ``problem``; ``solvers``;
``io`` and ``cases``; the front end ``cli`` and ``problem_file``. Old module paths of release 0.1
still import, with a deprecation warning (:mod:`dolfinx_nnqem._moved`).
"""

from dolfinx_nnqem import compat  # noqa: F401  (must come first)
from dolfinx_nnqem import _moved

__version__ = "0.1.0"

_moved.install()
