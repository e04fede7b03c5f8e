r"""Rigid obstacles: an analytical rigid body (plane, sphere, cylinder) as the master side.

``formulation.md`` §2b: one pair per slave node s of the tagged surface, with

    w_s = R_s (u_s − d(ℓ)),   g0_s = signed distance of X_s from the obstacle,

n_s (the first row of R_s) the obstacle's outward unit normal at the point closest to X_s. B
has only the slave node's columns, and the obstacle's prescribed motion d(ℓ) enters w as the
known part m_s(ℓ) = −R_s d(ℓ): it moves the gap and the slip like a displacement of the
master side. Small displacements: the closest points, normals and gaps are computed once, in
the reference configuration (the obstacle translates; it does not rotate), unless the interface
follows the bodies (:mod:`~dolfinx_nnqem.contact.current_geometry`).

The obstacle's reaction is the opposite of the slave forces: −Σ_s R_sᵀ λ_s (it appears in the
global equilibrium check next to the support reactions).

Quadratic facets (degree-2 displacements): every node of the surface, vertex, edge or face node,
gets a pair. On a tri6 surface pair s acts on the transformed nodal displacement
d̂_s = Σ_i t_si u_i and its gap is Σ_i t_si g0_i, the transformed nodal distances
(:mod:`~dolfinx_nnqem.contact.quadratic_facets`: every weight ∫N̂_s dA positive).
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from dolfinx_nnqem import compat  # noqa: F401, I001  (first: loads MPI/PETSc for the PyPI wheel)

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from dolfinx_nnqem.contact.pairs import owned_by_slave
from dolfinx_nnqem.contact.pairset import PairRows
from dolfinx_nnqem.contact.surfaces import (ContactPairError, first_by_position, format_point,
                                            gather_surfaces, local_frames, mesh_tolerance)
from dolfinx_nnqem.numerics.ranges import check_magnitude, shown

__all__ = ["OBSTACLES", "CombinedNodes", "Cylinder", "ObstaclePairs", "Plane", "RigidObstacle", "Sphere", "obstacle_pairs",
           "obstacle_parameters", "obstacle_reaction"]


def _vector3(name: str, value, unit: bool = False) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {shown(value)}: expected 3 numbers") from None
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} = {shown(value)}: expected 3 finite numbers")
    check_magnitude(name, v)
    if unit:
        length = float(np.linalg.norm(v))
        if length == 0.0:
            raise ValueError(f"{name} = {shown(value)}: a direction must not be zero")
        v = v / length
    return v


def _positive(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {shown(value)}: expected a number") from None
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError(f"{name} = {shown(value)}: expected a finite value > 0")
    check_magnitude(name, v)
    return v


@dataclass(frozen=True, kw_only=True)
class RigidObstacle(ABC):
    """A rigid body with a prescribed translation d(ℓ).

    Parameters
    ----------
    motion
        The translation: a vector scaled by ``amplitude(ℓ)`` (by ℓ when no amplitude is given),
        or a function ℓ -> (3,) giving d(ℓ) itself (e.g. press, then slide).
    amplitude
        a(ℓ) for a vector ``motion``.
    """

    motion: Sequence[float] | Callable[[float], Sequence[float] | np.ndarray] = (0.0, 0.0, 0.0)
    amplitude: Callable[[float], float] | None = None

    def __post_init__(self):
        if not callable(self.motion):
            _vector3(f"{type(self).__name__}.motion", self.motion)
        elif self.amplitude is not None:
            raise ValueError(f"{type(self).__name__}: give a motion vector with an amplitude, or a "
                             "motion function d(ℓ) alone")

    def displacement(self, load_factor: float) -> np.ndarray:
        """d(ℓ), the obstacle's translation at the load factor ``load_factor``."""
        if callable(self.motion):
            d = _vector3(f"{type(self).__name__}.motion({load_factor})", self.motion(load_factor))
        else:
            a = load_factor if self.amplitude is None else float(self.amplitude(load_factor))
            if not math.isfinite(a):
                raise ValueError(f"{type(self).__name__}: the motion amplitude gave {a} at load factor {load_factor}")
            d = a * np.asarray(self.motion, dtype=np.float64)
        return d

    @abstractmethod
    def project(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest points of the obstacle's surface to the points ``x`` (m, 3).

        Returns the signed distances g (m,) (> 0 outside the obstacle), the outward unit
        normals n (m, 3) at the closest points, and the closest points p (m, 3) = x − g n.
        """

    @abstractmethod
    def normal_derivative(self, x: np.ndarray) -> np.ndarray:
        """∂n/∂x (m, 3, 3) of the outward normal at the closest point, as the point ``x`` (m, 3) moves.

        The curvature of the obstacle's surface: zero for a plane, (I − n nᵀ)/ρ for a sphere seen
        from a point at the distance ρ from its centre. It is what turns the contact force and the
        friction frame as a slave node slides (:mod:`~dolfinx_nnqem.contact.geometric_stiffness`).
        """

    @abstractmethod
    def describe(self) -> str:
        """The obstacle in words, for messages and logs."""


@dataclass(frozen=True, kw_only=True)
class Plane(RigidObstacle):
    """The half-space {x : n · (x − point) ≤ 0}; ``normal`` n points towards the deformable body."""

    point: Sequence[float]
    normal: Sequence[float]

    def __post_init__(self):
        super().__post_init__()
        _vector3("Plane.point", self.point)
        _vector3("Plane.normal", self.normal, unit=True)

    def project(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """g = n · (x − point), the normal n everywhere, p = x − g n."""
        n = _vector3("Plane.normal", self.normal, unit=True)
        g = (x - np.asarray(self.point, dtype=np.float64)) @ n
        normals = np.broadcast_to(n, x.shape).copy()
        return g, normals, x - g[:, None] * normals

    def normal_derivative(self, x: np.ndarray) -> np.ndarray:
        """Zero (m, 3, 3): a plane's normal does not turn."""
        return np.zeros((len(x), 3, 3))  # a plane's normal does not turn

    def describe(self) -> str:
        """The plane's point and normal, in words."""
        return f"rigid plane through {format_point(self.point)} with normal {format_point(self.normal)}"


@dataclass(frozen=True, kw_only=True)
class Sphere(RigidObstacle):
    """A rigid ball of centre ``centre`` and radius ``radius``."""

    centre: Sequence[float]
    radius: float

    def __post_init__(self):
        super().__post_init__()
        _vector3("Sphere.centre", self.centre)
        _positive("Sphere.radius", self.radius)

    def project(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """g = |x − centre| − radius, n the unit vector from the centre to x, p = centre + radius n."""
        d = x - np.asarray(self.centre, dtype=np.float64)
        distance = np.linalg.norm(d, axis=1)
        _check_off_axis(distance, x, "the centre of the sphere")
        n = d / distance[:, None]
        return distance - float(self.radius), n, np.asarray(self.centre) + float(self.radius) * n

    def normal_derivative(self, x: np.ndarray) -> np.ndarray:
        """(I − n nᵀ)/ρ, ρ = |x − centre| (m, 3, 3)."""
        d = x - np.asarray(self.centre, dtype=np.float64)
        rho = np.linalg.norm(d, axis=1)
        n = d / rho[:, None]
        return (np.eye(3) - n[:, :, None] * n[:, None, :]) / rho[:, None, None]

    def describe(self) -> str:
        """The sphere's radius and centre, in words."""
        return f"rigid sphere of radius {self.radius:g} centred at {format_point(self.centre)}"


@dataclass(frozen=True, kw_only=True)
class Cylinder(RigidObstacle):
    """An infinite rigid cylinder of radius ``radius`` about the axis through ``point`` along ``axis``."""

    point: Sequence[float]
    axis: Sequence[float]
    radius: float

    def __post_init__(self):
        super().__post_init__()
        _vector3("Cylinder.point", self.point)
        _vector3("Cylinder.axis", self.axis, unit=True)
        _positive("Cylinder.radius", self.radius)

    def project(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """g = ρ − radius with ρ the distance of x from the axis, n the unit radial vector of x,
        p = x − g n."""
        e = _vector3("Cylinder.axis", self.axis, unit=True)
        d = x - np.asarray(self.point, dtype=np.float64)
        radial = d - (d @ e)[:, None] * e
        distance = np.linalg.norm(radial, axis=1)
        _check_off_axis(distance, x, "the cylinder's axis")
        n = radial / distance[:, None]
        return distance - float(self.radius), n, x - (distance - float(self.radius))[:, None] * n

    def normal_derivative(self, x: np.ndarray) -> np.ndarray:
        """(I − e eᵀ − n nᵀ)/ρ (m, 3, 3), e the axis and ρ the distance of x from it."""
        e = _vector3("Cylinder.axis", self.axis, unit=True)
        d = x - np.asarray(self.point, dtype=np.float64)
        radial = d - (d @ e)[:, None] * e
        rho = np.linalg.norm(radial, axis=1)
        n = radial / rho[:, None]
        # the normal turns about the axis only: the radial projector I − e eᵀ less n nᵀ
        return (np.eye(3) - np.outer(e, e) - n[:, :, None] * n[:, None, :]) / rho[:, None, None]

    def describe(self) -> str:
        """The cylinder's radius and axis, in words."""
        return (f"rigid cylinder of radius {self.radius:g} about the axis through {format_point(self.point)} "
                f"along {format_point(self.axis)}")


OBSTACLES: dict[str, type[RigidObstacle]] = {"plane": Plane, "sphere": Sphere, "cylinder": Cylinder}
"""The obstacle types by the name a problem file gives them (``[contact.obstacle] type``): the one list."""


def obstacle_parameters(kind: str) -> frozenset[str]:
    """The parameters of the obstacle type ``kind`` of :data:`OBSTACLES` that place it (its
    dataclass fields besides the ``motion`` and ``amplitude`` every obstacle has)."""
    common = {"motion", "amplitude"}
    return frozenset(f.name for f in dataclasses.fields(OBSTACLES[kind]) if f.name not in common)


def _check_off_axis(distance: np.ndarray, x: np.ndarray, what: str) -> None:
    if np.any(distance == 0.0):
        i = int(np.flatnonzero(distance == 0.0)[0])
        raise ContactPairError(f"the slave node at {format_point(x[i])} lies on {what}: no closest point")


@dataclass(frozen=True)
class CombinedNodes:
    """The nodes of the local pairs of a surface of 6-node triangles: pair i acts on the transformed
    displacement d̂_i = Σ_k a_ik u(k) (:mod:`~dolfinx_nnqem.contact.quadratic_facets`).

    Attributes
    ----------
    indptr
        (n + 1,) pair i combines ``blocks[indptr[i]:indptr[i + 1]]``.
    blocks
        Global dof blocks of the combined nodes (a pair's may be owned by other ranks).
    coefficients
        a_ik, one per entry of ``blocks`` (they sum to 1 per pair).
    X
        (n, 3) X̂_i = Σ_k a_ik X(k), the reference position the pair's displacement d̂_i moves.
    """

    indptr: np.ndarray
    blocks: np.ndarray
    coefficients: np.ndarray
    X: np.ndarray


@dataclass(eq=False)
class ObstaclePairs:
    """The pairs between a tagged surface and a rigid obstacle owned by this rank (a PairSet).

    Pair i joins slave node ``slave_blocks[i]`` and the obstacle point ``X_master[i]`` closest
    to it. Global order: by the rank owning the slave node, then by its coordinates.
    """

    comm: MPI.Comm
    obstacle: RigidObstacle
    surface: int
    num_local: int
    num_global: int
    offset: int
    slave_blocks: np.ndarray
    X_slave: np.ndarray
    X_master: np.ndarray
    R: np.ndarray
    g0: np.ndarray
    area: np.ndarray
    rows: PairRows
    kind: str = "rigid obstacle"
    pins_supported_slave_tangents: bool = False  #: see contact.constrained_directions.supported_slave_tangents
    combination: CombinedNodes | None = None  #: tri6 facets: what each pair combines; None: the node alone

    def motion(self, load_factor: float) -> np.ndarray:
        """m(ℓ) = −R d(ℓ): the obstacle's translation seen in each pair's frame."""
        return -np.einsum("nij,j->ni", self.R, self.obstacle.displacement(load_factor))

    def motion_amplitudes(self, load_factor: float) -> np.ndarray:
        """The obstacle's translation d(ℓ) (3,)."""
        return self.obstacle.displacement(load_factor)

    def describe(self) -> str:
        """The obstacle, the surface and the number of pairs, in one line."""
        return f"{self.obstacle.describe()} against surface {self.surface}, {self.num_global} pairs"


def obstacle_pairs(V: dolfinx.fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags, surface: int,
                   obstacle: RigidObstacle, *, tolerance: float | None = None) -> ObstaclePairs:
    """One pair per node of the surface tagged ``surface`` against ``obstacle`` (collective).

    Raises
    ------
    ContactPairError
        (on every rank) if the surface is missing or malformed, a node lies inside the
        obstacle (deeper than ``tolerance``), or the surface faces away from the obstacle.
    """
    comm = V.mesh.comm
    if not isinstance(obstacle, RigidObstacle):
        raise TypeError(f"obstacle must be a Plane, Sphere or Cylinder, got {obstacle!r}")
    tolerance = mesh_tolerance(V.mesh) if tolerance is None else float(tolerance)
    nodes = gather_surfaces(V, facet_tags, [surface], roles=["the slave surface"]).nodes[0]
    order = np.lexsort((nodes.x[:, 2], nodes.x[:, 1], nodes.x[:, 0]))
    index, x, slave_normal, area = nodes.index[order], nodes.x[order], nodes.normal[order], nodes.area[order]
    g0, n, p = obstacle.project(x)
    inside = g0 < -tolerance
    if np.any(inside):
        i = first_by_position(x, inside)
        raise ContactPairError(
            f"the node at {format_point(x[i])} of surface {surface} lies inside the {obstacle.describe()} "
            f"(signed distance {g0[i]:.6g}); place the obstacle outside the body and move it with `motion`")
    away = np.einsum("ij,ij->i", n, slave_normal) > 0.0
    if np.any(away):
        i = first_by_position(x, away)
        raise ContactPairError(
            f"surface {surface} faces away from the {obstacle.describe()} at the node {format_point(x[i])} "
            f"(outward normal {format_point(slave_normal[i])}, obstacle normal {format_point(n[i])}): "
            "tag the side of the body that faces the obstacle")
    R = local_frames(n)
    mine, offset, num_global = owned_by_slave(comm, V.dofmap.index_map, index)
    combination = nodes.combination
    if len(combination.columns) == len(nodes.index):  # linear or quad9 facets: the node alone
        g0 = np.where(np.abs(g0) <= tolerance, 0.0, g0)  # touching within the tolerance: no gap
        rows = PairRows.from_blocks(3 * index[mine, None] + np.arange(3), R[mine])
        combined_nodes = None
    else:  # tri6 facets: pair j acts on d̂_j = Σ_i t_ji u_i (quadratic_facets), its gap is Σ_i t_ji g0_i
        combined = combination.take(order)  # rows in this order; columns: positions in `nodes`
        g0 = combined.apply(_in_node_order(g0, order))
        g0 = np.where(np.abs(g0) <= tolerance, 0.0, g0)
        local = combined.take(mine)
        rows = PairRows.from_weighted_nodes(R[mine], local.indptr, nodes.index[local.columns], local.coefficients)
        combined_nodes = CombinedNodes(local.indptr, nodes.index[local.columns], local.coefficients,
                                       local.apply(nodes.x))
    return ObstaclePairs(
        comm=comm, obstacle=obstacle, surface=int(surface), num_local=len(mine), num_global=num_global,
        offset=offset, slave_blocks=index[mine], X_slave=x[mine], X_master=p[mine], R=R[mine], g0=g0[mine],
        area=area[mine], rows=rows, combination=combined_nodes,
    )


def _in_node_order(values: np.ndarray, order: np.ndarray) -> np.ndarray:
    """Values given in the order ``order`` of the surface's nodes, back in the nodes' own order."""
    out = np.empty_like(values)
    out[order] = values
    return out


def obstacle_reaction(R: npt.ArrayLike, lam: npt.ArrayLike) -> np.ndarray:
    """Force (3,) the slave surface exerts on the obstacle, −Σ R_sᵀ λ_s, from local pairs."""
    return -np.einsum("nji,nj->i", np.asarray(R), np.asarray(lam))

