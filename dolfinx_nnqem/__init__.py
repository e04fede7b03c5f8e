"""dolfinx_nnqem: elastoplastic frictional contact in DOLFINx by nonsmooth equations (NNEQM).

``compat`` is imported first: with the PyPI wheel, ``dolfinx_solver`` must be loaded before
``dolfinx`` and ``petsc4py``.
"""

from dolfinx_nnqem import compat  # noqa: F401  (must come first)

__version__ = "0.1.0"
