"""The solvers' options: :class:`SolverOptions` (tolerances, iteration limit, PETSc options of the
displacement solves) for every solver, and one dataclass per solver for what only it has.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field

from dolfinx_nnqem.names import METHODS
from dolfinx_nnqem.numerics.newton import Globalisation
from dolfinx_nnqem.numerics.ranges import shown

__all__ = ["FLOW_DIRECTIONS", "FORCING_RULES", "METHODS", "STALL_WINDOW", "MonolithicOptions", "NNEQM1Options", "NNEQM2Options", "SolverOptions"]

FORCING_RULES = ("eisenstat-walker", "quadratic")
"""The inexact-Newton rules of the iterative linear solver's Krylov tolerances
(:class:`MonolithicOptions`, :meth:`~dolfinx_nnqem.solvers.linear_solver.IterativeSolver.set_forcing`)."""

FLOW_DIRECTIONS = ("return-map", "frozen")
"""NNEQM2's two variants (:class:`NNEQM2Options`)."""


def _check_integer(owner: str, name: str, value, lowest: int) -> None:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < lowest:
        raise ValueError(f"{owner}: {name} = {shown(value)}; expected an integer >= {lowest}")


def _check_real(owner: str, name: str, value, low: float, high: float) -> None:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)) \
            or not low < float(value) <= high:
        raise ValueError(f"{owner}: {name} = {shown(value)}; expected a finite number in ({low:g}, {high:g}]")


@dataclass
class SolverOptions:
    """Options every solver shares.

    Converged when ‖R‖ ≤ rtol · F + atol and ‖H‖ ≤ rtol · F + atol, R the equilibrium
    residual at the free dofs, H the pair laws (force units), F = max(‖ℓ F_ext‖, ‖F_int‖, ‖Bᵀλ‖)
    the problem's force scale; ``atol`` (force units) guards the unloaded start.

    Attributes
    ----------
    rtol, atol
        Tolerances (0 < rtol ≤ 1e-2; 0 ≤ atol).
    max_iterations
        Newton iterations per increment (NNEQM1: outer iterations). An attempt that stops making
        progress ends earlier (the stall test, :data:`STALL_WINDOW`), so the limit only bounds
        attempts that still converge, slowly (50: the monolithic polar law on the frictional
        sphere-on-block demo mesh converges at 32).
    petsc_options
        PETSc options of the displacement solves (the monolithic Newton system, or NNEQM1's and
        NNEQM2's stiffness), merged over the package's defaults (MUMPS LU).
    """

    rtol: float = 1e-10
    atol: float = 1e-12
    max_iterations: int = 50
    petsc_options: dict = field(default_factory=dict)

    def __post_init__(self):
        _check_real("SolverOptions", "rtol", self.rtol, 0.0, 1e-2)
        if isinstance(self.atol, bool) or not isinstance(self.atol, numbers.Real) \
                or not (math.isfinite(float(self.atol)) and self.atol >= 0):
            raise ValueError(f"SolverOptions: atol = {shown(self.atol)}; expected a finite number >= 0")
        _check_integer("SolverOptions", "max_iterations", self.max_iterations, 1)
        if not isinstance(self.petsc_options, dict):
            raise ValueError(f"SolverOptions: petsc_options = {self.petsc_options!r}; expected a dict")


STALL_WINDOW = 10
"""Every solver's Newton solves (monolithic, NNEQM1's and NNEQM2's dense ones) stop an attempt
whose lowest |H| has not fallen by a tenth in this many iterations
(:class:`~dolfinx_nnqem.numerics.newton.Globalisation`), so that the next attempt (the other damping,
sliding pairs aligned, NNEQM2's updated flow directions, a cutback) starts early instead of
after a crawl to the iteration limit."""


@dataclass
class MonolithicOptions:
    """Options of the monolithic semismooth Newton solver.

    Attributes
    ----------
    linear_solver
        "direct" (MUMPS LU), "iterative" (FGMRES + Schur fieldsplit + GAMG), or "auto"
        (iterative from ``auto_iterative_dofs`` displacement dofs on).
    extrapolate
        Start each increment from the secant extrapolation of the last two.
    augmentation
        Iterative solver only: the penalty added to the u block on closed pair directions, in
        units of r (:class:`dolfinx_nnqem.solvers.block_system.AugmentedSystem`). It changes the
        preconditioner, not the Newton step.
    lag_preconditioner
        Iterative solver with contact: keep the u block's AMG hierarchy while it works.
    forcing
        Iterative solver: how loosely each Newton step's Krylov solve may stop (inexact Newton),
        one of :data:`FORCING_RULES`. "quadratic": η = min(max(ε², 0.1 rtol/ε), ``max_forcing``),
        ε the relative residual; "eisenstat-walker" (default): η = 0.9 (ε/ε_prev)², from the last
        step's own reduction of the residual, at most ``max_forcing`` (``docs/theory.md``).
    max_forcing
        Iterative solver: the loosest Krylov tolerance of a Newton step, in (0, 0.9].
    lift_forcing
        Iterative solver: the Krylov tolerance of an increment's lifted predictor step (the step
        that carries the prescribed displacements' jump), in (0, 0.9]. It is tighter than
        ``max_forcing`` because that step sets the pairs' starting states: an inexact one can put a
        pair on the wrong branch (slip for stick), which the semismooth iterations leave only after
        many steps, and a frictional path then follows another history (``docs/theory.md``).
    consistent_geometry
        Current-geometry rigid obstacles, node-to-surface and dual mortar pairs: re-evaluate them at every
        Newton iterate and add the geometric terms (the normal's and the friction frame's rotation; for
        node-to-surface also the closest point's motion over the master facet, for mortar the motion of
        the weights M_jk / m_j and of the weighted gap) to the Newton matrix
        (:mod:`~dolfinx_nnqem.contact.geometric_stiffness`, :mod:`~dolfinx_nnqem.contact.combined_stiffness`,
        :mod:`~dolfinx_nnqem.contact.surface_stiffness`, :mod:`~dolfinx_nnqem.contact.mortar_linearisation`;
        with either linear solver);
        False freezes the geometry within a solve and leaves it to load stepping's repeated solves, as
        NNEQM1 does (``docs/theory.md``).
    globalisation
        The Newton driver's damping (:class:`~dolfinx_nnqem.numerics.newton.Globalisation`); the LM
        parameter is ν = lm_c · min(ε, 1)^lm_delta · mean diag(JᵀJ), ε the relative residual.
    """

    linear_solver: str = "direct"
    auto_iterative_dofs: int = 300_000
    extrapolate: bool = True
    augmentation: float = 1.0
    lag_preconditioner: bool = True
    forcing: str = "eisenstat-walker"
    max_forcing: float = 1e-2
    lift_forcing: float = 1e-4
    consistent_geometry: bool = True
    globalisation: Globalisation = field(default_factory=lambda: Globalisation(
        min_step=1.0 / 64, watchdog=6, watchdog_progress=0.5, watchdog_restarts=2,
        stall_window=STALL_WINDOW, stagnation=1e-2))

    def __post_init__(self):
        if self.linear_solver not in ("direct", "iterative", "auto"):
            raise ValueError(f"MonolithicOptions: linear_solver = {self.linear_solver!r}; expected 'direct', "
                             "'iterative' or 'auto'")
        _check_integer("MonolithicOptions", "auto_iterative_dofs", self.auto_iterative_dofs, 0)
        if self.forcing not in FORCING_RULES:
            raise ValueError(f"MonolithicOptions: forcing = {self.forcing!r}; expected one of {list(FORCING_RULES)}")
        _check_real("MonolithicOptions", "max_forcing", self.max_forcing, 0.0, 0.9)
        _check_real("MonolithicOptions", "lift_forcing", self.lift_forcing, 0.0, 0.9)
        if isinstance(self.augmentation, bool) or not isinstance(self.augmentation, numbers.Real) \
                or not (math.isfinite(float(self.augmentation)) and self.augmentation > 0):
            raise ValueError(f"MonolithicSolver: augmentation = {self.augmentation!r}; expected a finite value > 0 "
                             "(the u block's penalty on closed pair directions, in units of r)")


def _check_memory(owner: str, value) -> None:
    """``max_memory_gb``: None or a finite number > 0."""
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not (math.isfinite(value) and float(value) > 0):
        raise ValueError(f"{owner}: max_memory_gb = {shown(value)}; expected None or a number of GB > 0")


def _in_turn(inner: Globalisation, retry: Globalisation | None) -> tuple[Globalisation, ...]:
    """The damping rules a dense solve tries in turn: ``inner``, then ``retry`` if given."""
    return (inner,) if retry is None else (inner, retry)


@dataclass
class NNEQM1Options:
    """Options of NNEQM1 (nonsmooth Newton on the pair unknowns nested in Newton–Raphson).

    Attributes
    ----------
    modified
        Keep K, X and C from the first iteration of the increment (modified Newton).
    extrapolate
        Start each increment's outer iteration from the secant extrapolation of the last two
        increments (u and the pair unknowns, :meth:`ContactProblem.extrapolate`), as the
        monolithic solver does; where it does not apply (the first two increments, a turn of
        the load path), from the converged state with the prescribed jump lifted.
    inner_max_iterations
        Iteration limit of the dense nonsmooth solve.
    inner
        Damping of the dense nonsmooth solve (ν = lm_c |H̃|^lm_delta on its scaled rows). The
        default watchdog crosses the kinks and curved valleys of the merit function (the polar
        law's angle) where monotone steps shrink to nothing.
    inner_retry
        Tried from the same start when ``inner`` stops without converging (None: no retry).
        The default, monotone Armijo steps, breaks the stick ↔ slip cycles that full steps
        can fall into (:func:`~dolfinx_nnqem.numerics.nonsmooth.solve_dense`).
    max_memory_gb
        The memory (GB per node) the dense condensation may take: Bᵀ made dense, X = G Bᵀ and its
        copy (three arrays of displacement dofs × 3NC) and the dense contact system
        (:func:`~dolfinx_nnqem.solvers.condensation.dense_memory`). A problem that needs more is
        refused before anything is assembled, with the sizes. None (default): the memory the
        machine has available when the solver is made.
    consistent_geometry
        Current-geometry contact (no free rigid modes, not ``modified``): the contact flexibility
        from the unit loads of the dofs the pairs touch, computed once per factorisation and
        reused while the pairs' frames move, and the factorisation kept while the tangent does not
        change (:mod:`~dolfinx_nnqem.solvers.nodal_flexibility`); current-geometry rigid obstacles
        re-evaluated at every outer iterate, their geometric terms (the normal's and the friction
        frame's rotation) in the outer linearisation, as the monolithic solver's: a solve ends in
        its own geometry. False: the flexibility C = B G Bᵀ made anew at every outer iteration and
        the geometry frozen within a solve, left to load stepping's repeated solves (the earlier
        behaviour, ``docs/theory.md``).
    """

    modified: bool = False
    extrapolate: bool = True
    inner_max_iterations: int = 100
    inner: Globalisation = field(default_factory=lambda: Globalisation(min_step=1e-10, watchdog=6,
                                                                       stall_window=STALL_WINDOW))
    inner_retry: Globalisation | None = field(default_factory=lambda: Globalisation(min_step=1e-10, watchdog=0,
                                                                                    stall_window=STALL_WINDOW))
    max_memory_gb: float | None = None
    consistent_geometry: bool = True

    def __post_init__(self):
        _check_integer("NNEQM1Options", "inner_max_iterations", self.inner_max_iterations, 1)
        _check_memory("NNEQM1Options", self.max_memory_gb)

    @property
    def inner_globalisations(self) -> tuple[Globalisation, ...]:
        """The dense solve's damping rules in the order they are tried."""
        return _in_turn(self.inner, self.inner_retry)


@dataclass
class NNEQM2Options:
    """Options of NNEQM2 (one nonsmooth system of the pairs and every Gauss point's plastic flow).

    Attributes
    ----------
    flow_directions
        "return-map" (default): the flow directions are unknowns with the plastic strains, and the
        answer is the backward-Euler (radial return) state, the other methods' answer
        (:mod:`~dolfinx_nnqem.solvers.nneqm2.return_map`). "frozen": the seed's method, the
        directions frozen at the start of the increment and a dense system in the plastic
        multipliers (:mod:`~dolfinx_nnqem.solvers.nneqm2.frozen`): first-order accurate in the
        increment where the stress turns (``docs/theory.md`` measures its error).
    extrapolate
        Start each increment from the secant extrapolation of the last two increments (the pair
        forces, :meth:`ContactProblem.extrapolate`; "return-map": the plastic strains too).
    globalisation
        "return-map": the damping of its Newton iteration (as the monolithic solver's).
    inner_max_iterations, inner, inner_retry
        "frozen": the iteration limit and the damping rules of the dense nonsmooth solves, tried in
        turn (``inner_retry`` None: no retry).
    max_dense_order
        "frozen": the largest order 3 NC + NG of the dense system accepted (NG: the Gauss points
        of the materials that can yield). Its matrices grow as the order squared (8 bytes each
        entry; 20 000 is 3.2 GB per matrix); a larger problem is refused before anything is
        assembled. The default variant has no dense matrix over the Gauss points.
    max_memory_gb
        "return-map": the memory (GB per node) its dense condensation onto the pairs may take,
        as :attr:`NNEQM1Options.max_memory_gb` (None: what the machine has available).
    """

    flow_directions: str = "return-map"
    extrapolate: bool = True
    globalisation: Globalisation = field(default_factory=lambda: Globalisation(
        min_step=1.0 / 64, watchdog=6, watchdog_progress=0.5, watchdog_restarts=2,
        stall_window=STALL_WINDOW, stagnation=1e-2))
    inner_max_iterations: int = 100
    inner: Globalisation = field(default_factory=lambda: Globalisation(min_step=1e-10, watchdog=0,
                                                                       stall_window=STALL_WINDOW))
    inner_retry: Globalisation | None = field(default_factory=lambda: Globalisation(min_step=1e-10, watchdog=6,
                                                                                    stall_window=STALL_WINDOW))
    max_dense_order: int = 20_000
    max_memory_gb: float | None = None

    def __post_init__(self):
        if self.flow_directions not in FLOW_DIRECTIONS:
            raise ValueError(f"NNEQM2Options: flow_directions = {self.flow_directions!r}; expected one of "
                             f"{list(FLOW_DIRECTIONS)}")
        _check_integer("NNEQM2Options", "max_dense_order", self.max_dense_order, 1)
        _check_memory("NNEQM2Options", self.max_memory_gb)
        _check_integer("NNEQM2Options", "inner_max_iterations", self.inner_max_iterations, 1)
        for name in ("globalisation", "inner"):
            if not isinstance(getattr(self, name), Globalisation):
                raise TypeError(f"NNEQM2Options: {name} must be a Globalisation")

    @property
    def inner_globalisations(self) -> tuple[Globalisation, ...]:
        """The dense solves' damping rules in the order they are tried."""
        return _in_turn(self.inner, self.inner_retry)
