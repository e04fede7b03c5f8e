"""NNEQM2: one nonsmooth system of the pair laws and every Gauss point's yield condition (seed §4).

The solver (:mod:`.solver`, :class:`NNEQM2Solver`), where each increment starts (:mod:`.increment_start`:
the elastic predictor and what both variants share), the Gauss-point operators (:mod:`.gauss_points`)
and the two variants: the default return-map one (:mod:`.return_map`) and the seed's frozen flow
directions (:mod:`.frozen`).
"""

from dolfinx_nnqem.solvers.nneqm2.solver import NNEQM2Solver

__all__ = ["NNEQM2Solver"]
