"""The names a user picks a solver and a pair law by: each listed once, here.

The command line reads them before any heavy import (this module imports nothing), the solvers'
registry (:mod:`~dolfinx_nnqem.solvers.options`), the pair laws (:mod:`~dolfinx_nnqem.contact.laws`)
and the problem files (:mod:`~dolfinx_nnqem.problem_file`) take them from here. The obstacle types
are named where they are defined (:data:`dolfinx_nnqem.contact.obstacles.OBSTACLES`).
"""

__all__ = ["LAW_ALIASES", "LAW_NAMES", "METHODS"]

METHODS = ("monolithic", "nneqm1", "nneqm2")
"""The solution methods (``make_solver``, ``--method``, ``[solver] method``)."""

LAW_NAMES = ("alart-curnier", "polar")
"""The pair laws (``get_law``, ``--law``, ``[[contact]] law``): the Cartesian Alart–Curnier form and
the seed's polar form."""

LAW_ALIASES = {"cartesian": "alart-curnier", "seed": "polar"}
"""Other names the pair laws answer to."""
