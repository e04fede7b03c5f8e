r"""Geometry tracking: where the pairs of each interface of a contact model come from, and when they move.

An interface's pairs are computed once in the reference configuration, or re-evaluated where the
bodies are by a tracker (:mod:`~dolfinx_nnqem.contact.current_geometry`): from the start
(``geometry = "current"``), or from the increment where its surfaces slid past the slip limit
(``geometry = "auto"``, :mod:`~dolfinx_nnqem.contact.slip_check`).

:class:`ContactGeometry` is all of it for one model (``ContactModel.geometry``): the trackers, the
slip check, and the re-evaluations, which hand the model its interfaces' new pair sets
(:class:`TrackedModel`: what the geometry reads of its model and does to it). Solvers, load
stepping and the checkpoints use its public members only; nothing outside ``contact/`` touches a
tracker.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Protocol

from dolfinx_nnqem import compat  # noqa: F401, I001  (first: loads MPI/PETSc for the PyPI wheel)

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.contact.current_geometry import (EDGE_ALLOWANCE, CombinedObstacleTracker, MortarTracker,
                                                     ObstacleTracker, SurfaceTracker,
                                                     displacement_at, moved_surfaces, surface_tracker,
                                                     with_moved_normals)
from dolfinx_nnqem.contact.combined_stiffness import combined_terms
from dolfinx_nnqem.contact.discretisation import discretise
from dolfinx_nnqem.contact.mortar_linearisation import MortarPoints, mortar_terms, remortared_pairs
from dolfinx_nnqem.contact.geometric_stiffness import GeometricTerms, no_terms, obstacle_terms
from dolfinx_nnqem.contact.obstacles import ObstaclePairs, RigidObstacle, obstacle_pairs
from dolfinx_nnqem.contact.pairset import PairSet
from dolfinx_nnqem.contact.slip_check import Slip, facet_size_of, slipped_interfaces
from dolfinx_nnqem.contact.surface_pairs import InterferenceError, SurfacePairs, facet_size
from dolfinx_nnqem.contact.surface_stiffness import (ClosestPoints, Supports, SurfaceTerms, reprojected_pairs,
                                                     surface_terms)
from dolfinx_nnqem.contact.symmetry_planes import IN_PLANE, supports_of
from dolfinx_nnqem.contact.specification import Contact
from dolfinx_nnqem.contact.surfaces import ContactPairError, NoPairsError, mesh_tolerance

if TYPE_CHECKING:
    import dolfinx

__all__ = ["ContactGeometry", "GeometryTracker", "LostContactError", "DeepPenetrationError", "GeometryStepError", "Remap", "TrackedInterface", "TrackedModel",
           "reference_pairs", "starting_pairs", "tracker_of", "zero_displacement"]

GeometryTracker = ObstacleTracker | CombinedObstacleTracker | SurfaceTracker | MortarTracker

Remap = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``remap(old, fill)``: per-pair rows laid out like the pairs before a re-evaluation, in the new
layout (:func:`~dolfinx_nnqem.contact.current_geometry.remapper`)."""


class GeometryStepError(ContactPairError):
    """A re-evaluation of the current geometry between solves cannot go on from the state reached:
    load stepping takes it as a failed solve and cuts the increment back."""


class LostContactError(GeometryStepError):
    """A re-evaluation of the current geometry found no pair on an interface (the slave nodes left the
    master surface)."""


class DeepPenetrationError(GeometryStepError):
    """A re-evaluation of the current geometry found a slave node deeper behind the master than
    :data:`~dolfinx_nnqem.contact.surface_pairs.RUN_INTERFERENCE` × its facet size."""


def zero_displacement(V: dolfinx.fem.FunctionSpace) -> dolfinx.fem.Function:
    """A zero displacement on V (the reference configuration)."""
    import dolfinx

    return dolfinx.fem.Function(V)


def starting_pairs(contact: Contact, V: dolfinx.fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags,
                   supported: np.ndarray) -> tuple[PairSet, GeometryTracker | None]:
    """The interface's pairs where a run starts, and its tracker if it follows the bodies from there
    (``geometry = "current"``; collective).

    Parameters
    ----------
    contact
        The interface.
    V, facet_tags
        The displacement space and the facet tags naming the surfaces.
    supported
        V's local dofs, non-zero at prescribed ones (see
        :func:`~dolfinx_nnqem.contact.discretisation.discretise`).
    """
    if contact.geometry != "current":
        return reference_pairs(contact, V, facet_tags, supported), None
    tracker = tracker_of(contact, V, facet_tags, supported)
    return tracker.pairs_at(zero_displacement(V), 0.0), tracker


def reference_pairs(contact: Contact, V: dolfinx.fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags,
                    supported: np.ndarray | None = None) -> PairSet:
    """The interface's pairs in the reference configuration (collective); ``supported``: see
    :func:`~dolfinx_nnqem.contact.discretisation.discretise`."""
    if isinstance(contact.surface1, RigidObstacle):  # contact.obstacle, narrowed for the type checker
        return obstacle_pairs(V, facet_tags, int(contact.surface2), contact.surface1, tolerance=contact.tolerance)
    return discretise(V, facet_tags, int(contact.surface1), int(contact.surface2), contact.discretisation,
                      slave=contact.slave, tolerance=contact.tolerance, search_distance=contact.search_distance,
                      initial_gap=contact.initial_gap, supported=supported)


def tracker_of(contact: Contact, V: dolfinx.fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags, supported: np.ndarray | None = None, *,
               reference: PairSet | None = None) -> GeometryTracker:
    """What re-evaluates the pairs of the interface in the current configuration (collective).

    ``reference``: the interface's reference-geometry pairs, when ``geometry = "auto"`` moves it to
    the current geometry during a run: the tracker then keeps their discretisation (mortar where
    ``discretisation = "auto"`` chose mortar) and slave side, so that every pair keeps its slave
    node. Without it, ``discretisation = "auto"`` means node-to-surface.
    """
    if isinstance(contact.surface1, RigidObstacle):
        tolerance = mesh_tolerance(V.mesh) if contact.tolerance is None else float(contact.tolerance)
        pairs = obstacle_pairs(V, facet_tags, int(contact.surface2), contact.surface1, tolerance=tolerance)
        # the same kind on every rank: whether pairs combine nodes is a property of the gathered surface
        return ObstacleTracker(pairs) if pairs.combination is None else CombinedObstacleTracker(pairs)
    slave = contact.slave
    if reference is not None:
        discretisation = "mortar" if reference.kind == "mortar" else "node-to-surface"
        slave = getattr(reference, "slave", slave)  # node-to-surface and mortar pairs name their slave side
    else:
        discretisation = "mortar" if contact.discretisation == "mortar" else "node-to-surface"  # auto: node-to-surface
    return surface_tracker(V, facet_tags, (int(contact.surface1), int(contact.surface2)), slave=slave,
                           search_distance=contact.search_distance, supported=supported,
                           discretisation=discretisation)


class TrackedInterface(Protocol):
    """What the geometry reads of an interface of its model."""

    @property
    def contact(self) -> Contact:
        """The interface's specification."""
        ...

    @property
    def pairs(self) -> PairSet:
        """The interface's current pair set."""
        ...

    @property
    def local(self) -> slice:
        """The interface's rows among the model's local pairs."""
        ...


class TrackedModel(Protocol):
    """What the geometry reads of its contact model and does to it
    (:class:`~dolfinx_nnqem.contact.model.ContactModel`)."""

    @property
    def interfaces(self) -> Sequence[TrackedInterface]:
        """The model's interfaces, in the order of its local pairs."""
        ...

    def force(self, z: np.ndarray | None = None) -> np.ndarray:
        """λ(z) of the local pairs."""
        ...

    def replace_pairs(self, pairs: Sequence[PairSet], u_n: dolfinx.fem.Function, load_factor_n: float) -> Remap:
        """The model on new pair sets of its interfaces, one per interface; the remap of per-pair arrays."""
        ...

    def refill_pairs(self, pairs: Mapping[int, PairSet], u_n: dolfinx.fem.Function, load_factor_n: float) -> None:
        """New values of the pair sets of some interfaces, in place: the same pairs, B's pattern kept."""
        ...


class ContactGeometry:
    """Where a contact model's pairs come from, interface by interface, and when they move.

    Made by the model (``ContactModel.geometry``), which passes itself and the trackers of the
    interfaces that follow the bodies from the start. Its public members are all that solvers,
    load stepping and the checkpoints use of the geometry (the type checker holds them to it); the
    trackers stay inside. Every method that evaluates pairs is collective.

    Parameters
    ----------
    model
        The contact model whose pairs this geometry evaluates.
    V, facet_tags
        The displacement space and the facet tags naming the surfaces.
    trackers
        Per interface: its tracker, or None in the reference geometry.
    constrained_dofs
        The model's vector of constrained dofs (1 at prescribed ones): the supports of the trackers
        made later (:meth:`start_following`).

    Attributes
    ----------
    version
        Counts the re-evaluations that changed the pairs (:meth:`update`): the solvers rebuild
        what they built on B when it moves on.
    """

    def __init__(self, model: TrackedModel, V, facet_tags, trackers: list[GeometryTracker | None],
                 constrained_dofs: PETSc.Vec):
        self._model = model
        self._V = V
        self._comm = V.mesh.comm
        self._facet_tags = facet_tags
        self._trackers = trackers
        self._constrained_dofs = constrained_dofs
        self.version = 0
        self._refreshed_at: np.ndarray | None = None  # where refresh_obstacles last evaluated
        self._facet_sizes: list[float] | None = None  # of the interfaces' slave surfaces, at the first slip check
        self._supports: dict[int, tuple[np.ndarray, np.ndarray] | None] = {}  # per interface: its nodes' supports
        self._surfaces_at: np.ndarray | None = None  # where refresh_surfaces last evaluated
        self._closest_points: dict[int, ClosestPoints | MortarPoints] = {}  # of the interfaces refresh_surfaces evaluated

    # -- which interfaces follow the bodies ---------------------------------------------------------
    @property
    def follows_bodies(self) -> bool:
        """True if some interface re-evaluates its pairs in the current configuration."""
        return any(t is not None for t in self._trackers)

    @property
    def following(self) -> list[bool]:
        """Per interface: True where its pairs are re-evaluated in the current configuration."""
        return [t is not None for t in self._trackers]

    @property
    def obstacles_follow(self) -> bool:
        """True if some interface is a rigid obstacle in the current geometry whose pairs
        :meth:`refresh_obstacles` re-evaluates in place (one node per pair: degree 1, Q2 hexahedra; a
        combination of nodes per pair: P2 tetrahedra)."""
        return any(isinstance(t, (ObstacleTracker, CombinedObstacleTracker)) for t in self._trackers)

    @property
    def surfaces_follow(self) -> bool:
        """True if some interface is node-to-surface or mortar in the current geometry (its pairs may
        change; it is re-evaluated between solves, not within one)."""
        return any(isinstance(t, (SurfaceTracker, MortarTracker)) for t in self._trackers)

    @property
    def pairs_may_change(self) -> bool:
        """True if some interface's pairs depend on u: in the current geometry, or ``geometry = "auto"``
        and able to move there (:meth:`why_not_current`)."""
        return any(t is not None or self.why_not_current(k) is None for k, t in enumerate(self._trackers))

    def why_not_current(self, k: int) -> str | None:
        """None if interface ``k`` (in the reference geometry) can be re-evaluated in the current
        configuration from now on (``geometry = "auto"``); else the reason it cannot."""
        interface = self._model.interfaces[k]
        if interface.contact.geometry == "reference":
            return "geometry = 'reference' was chosen for it (use 'auto' or 'current' for large sliding)"
        if interface.pairs.kind == "node-to-node":
            return ("node-to-node pairs join nodes that faced each other in the reference configuration (use "
                    "discretisation = 'node-to-surface' or 'mortar' for large sliding)")
        return None  # every other kind follows the bodies, with degree-1 and degree-2 displacements

    def start_following(self, k: int) -> None:
        """Re-evaluate interface ``k`` in the current configuration from now on (collective): its tracker
        is made, and the next :meth:`update` evaluates its pairs where the bodies are.

        For ``geometry = "auto"`` past the slip limit (:meth:`why_not_current` must be None).
        """
        if self._trackers[k] is not None:
            return
        interface = self._model.interfaces[k]
        with self._constrained_dofs.localForm() as c:
            self._trackers[k] = tracker_of(interface.contact, self._V, self._facet_tags, supported=c.array.copy(),
                                           reference=interface.pairs)

    def slipped(self, w: np.ndarray) -> list[Slip]:
        """The reference-geometry interfaces whose surfaces slid past
        :data:`~dolfinx_nnqem.contact.slip_check.SLIP_LIMIT` × their facet size at the relative
        displacement ``w`` (collective; :func:`~dolfinx_nnqem.contact.slip_check.slipped_interfaces`)."""
        interfaces = self._model.interfaces
        if self._facet_sizes is None:  # a reference-geometry interface's areas never change: measured once
            self._facet_sizes = [facet_size_of(self._comm, i.pairs.area) for i in interfaces]
        sizes = [None if t is not None else size for size, t in zip(self._facet_sizes, self._trackers)]
        return slipped_interfaces(self._comm, interfaces, sizes, w)

    # -- re-evaluations -----------------------------------------------------------------------------
    def update(self, u: dolfinx.fem.Function, load_factor: float, u_n: dolfinx.fem.Function, load_factor_n: float) -> Remap:
        """Re-evaluate the current-geometry interfaces at (u, ℓ) (collective).

        The pair unknowns z, z_n and the states follow their slave node; new pairs start
        force-free. w_n is measured again with the new rows, w_n = B u_n + m(ℓ_n): the slip of an
        increment is the relative displacement increment of the slave node and the master point
        now under it, in the current tangent plane (``docs/theory.md``).

        Parameters
        ----------
        u, u_n
            DOLFINx functions: where the geometry is evaluated, and the last converged displacement.
        load_factor, load_factor_n
            ℓ of the obstacles' position, and of the last converged increment.

        Returns
        -------
        The remap of per-pair arrays: ``remap(old, fill)`` gives the rows of ``old`` (laid out like
        the pairs before the update) in the new layout, and for new pairs those of ``fill`` (one
        row, or an array in the new layout).

        Raises
        ------
        LostContactError
            An interface has no pair left; the model is then unchanged.
        """
        # every interface evaluated before anything changes: if one has lost its pairs, the model stays
        pairs = [i.pairs if t is None else _pairs_or_lost(i, t, u, load_factor)
                 for i, t in zip(self._model.interfaces, self._trackers)]
        self._refreshed_at = self._surfaces_at = None
        self._closest_points = {}
        remap = self._model.replace_pairs(pairs, u_n, load_factor_n)
        self.version += 1
        return remap

    def refresh_obstacles(self, u: dolfinx.fem.Function, load_factor: float, u_n: dolfinx.fem.Function, load_factor_n: float) -> None:
        """Re-evaluate the current-geometry obstacle interfaces at (u, ℓ) in place (collective).

        An obstacle keeps one pair per slave node and B keeps its pattern (the slave node's three
        columns): only the frames R, the gaps g0 (rebased as in :meth:`update`) and B's values
        change, and w_n is measured again with the new rows. The pairs, their unknowns and the
        solvers' matrices stay; this is what the monolithic solver calls at every Newton iterate
        (:mod:`~dolfinx_nnqem.contact.geometric_stiffness`). Nothing is done when the slave nodes,
        ℓ and u_n are where the last refresh had them.
        """
        key = self._refresh_key(u, load_factor, u_n, load_factor_n)
        same = (self._refreshed_at is not None and len(key) == len(self._refreshed_at)
                and bool(np.array_equal(key, self._refreshed_at)))
        # agreed by every rank: a rank whose own slave nodes did not move must still join B's
        # assembly and the measure of w_n (collective) when another rank's did
        if self._comm.allreduce(same, op=MPI.LAND):
            return
        pairs = {k: tracker.pairs_at(u, load_factor) for k, tracker in enumerate(self._trackers)
                 if isinstance(tracker, (ObstacleTracker, CombinedObstacleTracker))}
        self._model.refill_pairs(pairs, u_n, load_factor_n)
        self._refreshed_at = key

    def _refresh_key(self, u, load_factor: float, u_n, load_factor_n: float) -> np.ndarray:
        """What an obstacle refresh depends on: the slave nodes' u and u_n, ℓ and ℓ_n (pairs that combine
        nodes: the owned u and u_n, their nodes may be owned by another rank)."""
        start = u.function_space.dofmap.index_map.local_range[0]
        parts = [np.array([load_factor, load_factor_n])]
        if any(isinstance(t, CombinedObstacleTracker) for t in self._trackers):
            owned = 3 * u.function_space.dofmap.index_map.size_local
            parts += [u.x.array[:owned], u_n.x.array[:owned]]
        for interface, tracker in zip(self._model.interfaces, self._trackers):
            if isinstance(tracker, ObstacleTracker):
                blocks = interface.pairs.slave_blocks - start
                parts += [u.x.array.reshape(-1, 3)[blocks].ravel(), u_n.x.array.reshape(-1, 3)[blocks].ravel()]
        return np.concatenate(parts)

    def geometric_terms(self, u: dolfinx.fem.Function, load_factor: float, u_n: dolfinx.fem.Function, load_factor_n: float,
                        lam: np.ndarray | None = None) -> GeometricTerms:
        """The geometric blocks K_s, W_s of the current-geometry obstacle pairs at (u, ℓ) and the forces
        ``lam`` (default: the model's λ(z)), their geometry refreshed there first
        (:mod:`~dolfinx_nnqem.contact.geometric_stiffness`); those of pairs that combine nodes (P2
        tetrahedra) in ``combined`` (:mod:`~dolfinx_nnqem.contact.combined_stiffness`; collective)."""
        lam = self._model.force() if lam is None else lam
        start = u.function_space.dofmap.index_map.local_range[0]
        pairs_, blocks, Ks, Ws = [], [], [], []
        for interface, tracker in zip(self._model.interfaces, self._trackers):
            if not isinstance(tracker, ObstacleTracker):
                continue
            pairs = interface.pairs
            assert isinstance(pairs, ObstaclePairs)  # an obstacle tracker's pairs
            index = pairs.slave_blocks - start
            K, W = obstacle_terms(pairs, u.x.array.reshape(-1, 3)[index], u_n.x.array.reshape(-1, 3)[index],
                                  pairs.obstacle.displacement(load_factor), pairs.obstacle.displacement(load_factor_n),
                                  lam[interface.local])
            pairs_.append(np.arange(interface.local.start, interface.local.stop))
            blocks.append(pairs.slave_blocks)
            Ks.append(K)
            Ws.append(W)
        combined = combined_terms(self._model.interfaces, self._trackers, u, load_factor, u_n, load_factor_n, lam)
        if not pairs_:
            return no_terms() if combined is None else replace(no_terms(), combined=combined)
        return GeometricTerms(np.concatenate(pairs_), np.concatenate(blocks).astype(np.int64), np.concatenate(Ks),
                              np.concatenate(Ws), combined)

    @property
    def reprojecting(self) -> list[bool]:
        """Per interface: True if :meth:`refresh_surfaces` re-evaluates it (node-to-surface and mortar in
        the current geometry)."""
        return [isinstance(t, (MortarTracker, SurfaceTracker)) for t in self._trackers]

    def refresh_surfaces(self, u: dolfinx.fem.Function, u_n: dolfinx.fem.Function, load_factor_n: float) -> None:
        """Re-evaluate the node-to-surface and mortar interfaces of :attr:`reprojecting` at u, keeping their
        pairs (collective): every slave node is projected again onto the moved master (onto another
        facet if it slid there), or the mortar integrals are computed again on the moved surfaces; the
        frames, weights and gaps follow; w_n is measured again. Where B's pattern stays the model is
        refilled in place, else its pairs are replaced (the same pairs, in the same order: z stays) and
        :attr:`version` moves on. This is what the monolithic solver calls at every Newton iterate
        (:mod:`~dolfinx_nnqem.contact.surface_stiffness`, :mod:`~dolfinx_nnqem.contact.mortar_linearisation`);
        nothing is done when u and u_n are where the last refresh had them."""
        key = np.concatenate([u.x.array, u_n.x.array])
        same = (self._surfaces_at is not None and len(key) == len(self._surfaces_at)
                and bool(np.array_equal(key, self._surfaces_at)))
        if self._comm.allreduce(same, op=MPI.LAND):
            return
        interfaces, new = self._model.interfaces, {}
        for k, tracker in enumerate(self._trackers):
            if isinstance(tracker, SurfaceTracker):
                new[k], self._closest_points[k] = _reprojected(interfaces[k].pairs, tracker, u, u_n,
                                                               self._supports_of(k, tracker))
            elif isinstance(tracker, MortarTracker):
                new[k], self._closest_points[k] = _remortared(interfaces[k].pairs, tracker, u, u_n)
        kept = all(np.array_equal(p.rows.indptr, interfaces[k].pairs.rows.indptr)
                   and np.array_equal(p.rows.columns, interfaces[k].pairs.rows.columns) for k, p in new.items())
        if self._comm.allreduce(kept, op=MPI.LAND):
            self._model.refill_pairs(new, u_n, load_factor_n)
        else:
            self._model.replace_pairs([new.get(k, i.pairs) for k, i in enumerate(interfaces)], u_n, load_factor_n)
            self.version += 1
        for k, pairs in new.items():
            tracker = self._trackers[k]
            if isinstance(tracker, SurfaceTracker):
                tracker.facets = tracker.gathered_facets(pairs)
        self._surfaces_at = key

    def _supports_of(self, k: int, tracker: SurfaceTracker) -> tuple[np.ndarray, np.ndarray] | None:
        """The prescribed components of interface ``k``'s slave nodes (sorted blocks) and master facets'
        vertices (collective at the first call; None if no support is known)."""
        if k not in self._supports:
            master = tracker.surfaces.facets_of(0)
            self._supports[k] = None if tracker.supported is None else (
                supports_of(self._V, tracker.supported, tracker.surfaces.nodes[1].index),
                supports_of(self._V, tracker.supported, master.nodes.ravel()).reshape(master.x.shape))
        return self._supports[k]

    def surface_terms(self, lam: np.ndarray | None = None) -> list[SurfaceTerms]:
        """The geometric blocks of the pairs :meth:`refresh_surfaces` evaluated last, one per interface,
        at the forces ``lam`` (default: the model's λ(z))."""
        lam = self._model.force() if lam is None else lam
        out = []
        for k, points in sorted(self._closest_points.items()):
            local = self._model.interfaces[k].local
            if isinstance(points, MortarPoints):
                out += mortar_terms(points, lam[local], np.arange(local.start, local.stop))
            else:
                out.append(surface_terms(points, lam[local], np.arange(local.start, local.stop)))
        return out

    # -- checkpoints --------------------------------------------------------------------------------
    def state(self) -> list[np.ndarray | None]:
        """Per interface, what its next evaluation depends on besides u (for checkpoints): the master
        facet of every slave node (node-to-surface in current geometry), or None."""
        return [t.facets if isinstance(t, SurfaceTracker) else None for t in self._trackers]

    def set_state(self, state: Sequence[np.ndarray | None]) -> None:
        """Restore :meth:`state`."""
        for tracker, facets in zip(self._trackers, state):
            if isinstance(tracker, SurfaceTracker) and facets is not None:
                tracker.facets = np.asarray(facets, dtype=np.int64).copy()


def _reprojected(pairs: PairSet, tracker: SurfaceTracker, u, u_n, supports: tuple[np.ndarray, np.ndarray] | None
                 ) -> tuple[SurfacePairs, ClosestPoints | MortarPoints]:
    """The interface's pairs projected again at u, and where they project (collective); ``supports``:
    the prescribed components of its slave nodes and master vertices (:meth:`ContactGeometry._supports_of`).
    Pairs that combine slave nodes (P2 tetrahedra) get their geometry as a mortar pair's
    (:mod:`~dolfinx_nnqem.contact.combined_surface_stiffness`)."""
    assert isinstance(pairs, SurfacePairs)  # a node-to-surface tracker's pairs
    master = tracker.surfaces.facets_of(0)
    u_n_master = displacement_at(u_n, master.nodes.ravel()).reshape(master.x.shape)
    size = facet_size(master)
    known = None
    if supports is not None:
        slave = supports[0][np.searchsorted(tracker.surfaces.nodes[1].index, pairs.slave_blocks)]
        known = Supports(slave, supports[1], IN_PLANE * size)
    moved = moved_surfaces(tracker.surfaces, u)
    if tracker.combines_nodes:  # imported here: its numba kernels are compiled only where quadratic facets are
        from dolfinx_nnqem.contact.combined_surface_stiffness import combined_reprojected_pairs

        facets = tracker.gathered_facets(pairs) if tracker.facets is None else tracker.facets  # same on every rank
        nodes = tracker.surfaces.nodes[1]
        return combined_reprojected_pairs(pairs, nodes.combination, tracker.surfaces, moved, facets,
                                          displacement_at(u_n, nodes.index), u_n_master, tracker.gap_rounding,
                                          EDGE_ALLOWANCE * size, size, known)
    start = u.function_space.dofmap.index_map.local_range[0]
    u_n_slave = u_n.x.array.reshape(-1, 3)[pairs.slave_blocks - start]  # the pairs' slave nodes are owned
    return reprojected_pairs(pairs, tracker.surfaces, moved, u_n_slave, u_n_master, tracker.gap_rounding,
                             EDGE_ALLOWANCE * size, size, known)


def _remortared(pairs: PairSet, tracker: MortarTracker, u, u_n) -> tuple[SurfacePairs, MortarPoints]:
    """The interface's mortar pairs integrated again at u, and their derivatives (collective;
    :mod:`~dolfinx_nnqem.contact.mortar_linearisation`)."""
    assert isinstance(pairs, SurfacePairs)  # a mortar tracker's pairs
    surfaces = tracker.surfaces
    u_n_nodes = (displacement_at(u_n, surfaces.nodes[0].index), displacement_at(u_n, surfaces.nodes[1].index))
    moved = with_moved_normals(moved_surfaces(surfaces, u))
    couples = None
    if moved.facets_of(1).degree == 2:  # imported here: its numba kernels are compiled only where quadratic facets are
        from dolfinx_nnqem.contact.quadratic_mortar_linearisation import quadratic_couples

        couples = quadratic_couples(moved, tracker.search_distance, pairs.slave_blocks)
    return remortared_pairs(pairs, surfaces, moved, u_n_nodes, tracker.gap_rounding, tracker.search_distance,
                            tracker.V, tracker.supported, couples=couples)


def _pairs_or_lost(interface: TrackedInterface, tracker: GeometryTracker, u, load_factor: float) -> PairSet:
    """The tracker's pairs at (u, ℓ); :class:`LostContactError` naming the interface if there are none,
    :class:`DeepPenetrationError` if a slave node lies too deep behind the master."""
    lost = (f"contact {interface.contact.label}: no pairs in the current geometry at load factor "
            f"{load_factor:.6g}: no slave node faces the master surface any more (the bodies slid apart)")
    try:
        pairs: PairSet = tracker.pairs_at(u, load_factor)
    except NoPairsError as error:  # node-to-surface and mortar alike: one outcome, one message
        raise LostContactError(lost) from error
    except InterferenceError as error:
        raise DeepPenetrationError(f"contact {interface.contact.label} at load factor {load_factor:.6g}: {error}; "
                                   "the increment is cut back") from error
    if pairs.num_global == 0:
        raise LostContactError(lost)
    return pairs
