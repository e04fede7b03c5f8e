r"""Node-to-surface geometry: closest-point projection onto a surface of tri3 / quad4 facets.

``formulation.md`` §2b (node-to-surface): a slave point X_s is projected onto the master
surface at local coordinates ξ of master facet f; with N_k the facet's shape functions,

    x(ξ) = Σ_k N_k(ξ) X_k,   n = the master's outward unit normal at ξ,   g0 = n · (X_s − x(ξ)).

This module is pure numpy / numba: it receives coordinates and connectivity that are identical
on every rank (:mod:`dolfinx_nnqem.contact.surfaces` gathers them), so its results are too.

Facets and their vertex order
-----------------------------
A surface is an array ``x`` of shape ``(m, k, 3)``: m facets of k = 3 (linear triangles) or
k = 4 (bilinear quadrilaterals, possibly slightly warped) vertices, in ANY order. DOLFINx/basix
give the vertices of a hexahedron's facet in tensor-product order ((0,0), (1,0), (0,1), (1,1)),
which is not cyclic, and :class:`~dolfinx_nnqem.contact.surfaces.Facets` keeps that order.
:func:`cyclic_order` therefore reorders every facet's vertices by angle about the facet
centroid in the plane normal to its outward area vector (as ``_outward_area_vectors`` in
``surfaces.py`` does), starting at the caller's vertex 0 and turning counter-clockwise seen
from outside. The local coordinates ξ of this module always refer to that CYCLIC order:

* tri3 on the unit triangle: N = (1 − ξ − η, ξ, η), cyclic vertices at (0,0), (1,0), (0,1);
* quad4 on [−1, 1]²: N_a = ¼ (1 + s_a ξ)(1 + t_a η), cyclic vertices at (−1,−1), (1,−1),
  (1,1), (−1,1).

With this order ∂x/∂ξ × ∂x/∂η points outward. Shape-function VALUES returned to callers
(:attr:`Projection.N`) are put back in the caller's vertex order, so they pair with the
caller's node arrays directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

from dolfinx_nnqem.chatter import apply_numba_options

apply_numba_options()  # numba's warnings as the command line asked (imported here, not at start-up)

__all__ = [
    "TIE_TOLERANCE",
    "Projection",
    "cyclic_order",
    "facet_normals",
    "newell_area_vectors",
    "project_onto_facets",
    "project_points",
    "reference_vertices",
    "shape_derivatives",
    "shape_functions",
]

TIE_TOLERANCE = 1e-10
"""Two candidate facets whose distances to a point differ by less than this times the master
surface's bounding-box diagonal are a tie (a point facing a shared edge or corner); ties go to
the lowest facet index, so the caller's (coordinate-based) facet order decides."""

NEWTON_MAX_ITERATIONS = 30
"""Bound on the local Newton iterations for a quadrilateral (closest point and inverse map)."""

# Cyclic reference corners of the quad4 (signs s_a, t_a) and of the tri3.
_QUAD_CORNERS = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
_TRI_CORNERS = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])


# --------------------------------------------------------------------------------------------
# Shape functions (vectorised numpy versions for callers; numba versions for the kernels)
# --------------------------------------------------------------------------------------------


def reference_vertices(k: int) -> np.ndarray:
    """The (k, 2) reference coordinates of the cyclic vertices of a tri3 (k = 3) or quad4 (k = 4)."""
    if k == 3:
        return _TRI_CORNERS.copy()
    if k == 4:
        return _QUAD_CORNERS.copy()
    raise ValueError(f"facets must have 3 or 4 vertices, got {k}")


def shape_functions(k: int, xi: npt.ArrayLike) -> np.ndarray:
    """Shape functions N_k(ξ) of a tri3 or quad4 in cyclic vertex order.

    Parameters
    ----------
    k
        3 (tri3 on the unit triangle) or 4 (quad4 on [−1, 1]²).
    xi
        Local coordinates, shape ``(n, 2)`` (or ``(2,)``).

    Returns
    -------
    np.ndarray
        N, shape ``(n, k)``.
    """
    xi = np.atleast_2d(np.asarray(xi, dtype=np.float64))
    s, t = xi[:, 0], xi[:, 1]
    if k == 3:
        return np.column_stack([1.0 - s - t, s, t])
    c = reference_vertices(k)
    return 0.25 * (1.0 + s[:, None] * c[:, 0]) * (1.0 + t[:, None] * c[:, 1])


def shape_derivatives(k: int, xi: npt.ArrayLike) -> np.ndarray:
    """Derivatives ∂N_a/∂ξ_b, shape ``(n, k, 2)``, in cyclic vertex order (see :func:`shape_functions`)."""
    xi = np.atleast_2d(np.asarray(xi, dtype=np.float64))
    n = len(xi)
    if k == 3:
        return np.broadcast_to(np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]]), (n, 3, 2)).copy()
    c = reference_vertices(k)
    s, t = xi[:, 0, None], xi[:, 1, None]
    return np.stack([0.25 * c[:, 0] * (1.0 + t * c[:, 1]), 0.25 * c[:, 1] * (1.0 + s * c[:, 0])], axis=2)


@numba.njit(cache=True)
def _shape(k, s, t, N, dN):
    """Fill N (k,) and dN (k, 2) at (s, t); cyclic order."""
    if k == 3:
        N[0] = 1.0 - s - t
        N[1] = s
        N[2] = t
        dN[0, 0] = -1.0
        dN[0, 1] = -1.0
        dN[1, 0] = 1.0
        dN[1, 1] = 0.0
        dN[2, 0] = 0.0
        dN[2, 1] = 1.0
    else:
        for a in range(4):
            sa = _QUAD_CORNERS[a, 0]
            ta = _QUAD_CORNERS[a, 1]
            N[a] = 0.25 * (1.0 + sa * s) * (1.0 + ta * t)
            dN[a, 0] = 0.25 * sa * (1.0 + ta * t)
            dN[a, 1] = 0.25 * ta * (1.0 + sa * s)


# --------------------------------------------------------------------------------------------
# Vertex order, area vectors, normals
# --------------------------------------------------------------------------------------------


def newell_area_vectors(x: npt.ArrayLike) -> np.ndarray:
    """Area vectors of polygons whose vertices are in CYCLIC order (Newell's sum about vertex 0).

    Parameters
    ----------
    x
        Vertices, shape ``(m, k, 3)``, cyclic.

    Returns
    -------
    np.ndarray
        (m, 3): exact for planar polygons, the mean plane's for warped quadrilaterals; it follows
        the vertex order by the right-hand rule.
    """
    x = np.asarray(x, dtype=np.float64)
    d = x - x[:, :1, :]
    return 0.5 * np.cross(d, np.roll(d, -1, axis=1)).sum(axis=1)


def cyclic_order(x: npt.ArrayLike, outward: npt.ArrayLike) -> np.ndarray:
    """The permutation that puts each facet's vertices in cyclic, outward-oriented order.

    Vertices are sorted by angle about the facet centroid in the plane normal to ``outward``,
    starting at the caller's vertex 0 and turning counter-clockwise about ``outward`` (seen
    from outside). Any input order works, e.g. DOLFINx's tensor-product order of a
    hexahedron's facet; a triangle is only reoriented if needed.

    Parameters
    ----------
    x
        Vertices, shape ``(m, k, 3)``, any order.
    outward
        (m, 3) the facets' outward area vectors (or any vectors on the outer side, e.g. normals).

    Returns
    -------
    np.ndarray
        perm, shape ``(m, k)``: ``np.take_along_axis(x, perm[:, :, None], axis=1)`` is cyclic,
        and ``perm[:, 0] == 0``.
    """
    x = np.asarray(x, dtype=np.float64)
    n = np.asarray(outward, dtype=np.float64).reshape(-1, 3)
    n = n / np.linalg.norm(n, axis=1)[:, None]
    d = x - x.mean(axis=1)[:, None, :]
    e1 = d[:, 0] - np.sum(d[:, 0] * n, axis=1)[:, None] * n
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(n, e1)
    angle = np.arctan2(np.einsum("mkj,mj->mk", d, e2), np.einsum("mkj,mj->mk", d, e1)) % (2.0 * np.pi)
    angle[:, 0] = -1.0  # vertex 0 first, whatever its round-off angle (≈ 0 or ≈ 2π)
    return np.argsort(angle, axis=1, kind="stable")


def _check_facets(x: np.ndarray, outward: np.ndarray, name: str = "facets") -> None:
    """Raise ValueError unless x is (m, 3 or 4, 3) with m ≥ 1 and outward is (m, 3)."""
    if x.ndim != 3 or x.shape[1] not in (3, 4) or x.shape[2] != 3 or len(x) == 0 or outward.shape != (len(x), 3):
        raise ValueError(f"{name}: expected vertices (m >= 1, 3 or 4, 3) and outward vectors (m, 3), "
                         f"got {x.shape} and {outward.shape}")


def _cyclic(x: np.ndarray, outward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(cyclic vertices, permutation) of facets given in any order."""
    perm = cyclic_order(x, outward)
    return np.ascontiguousarray(np.take_along_axis(x, perm[:, :, None], axis=1)), perm


def facet_normals(x_cyclic: npt.ArrayLike, xi: npt.ArrayLike, outward: npt.ArrayLike | None = None) -> np.ndarray:
    """Unit normals ∂x/∂ξ × ∂x/∂η / |…| of facets at local coordinates ξ.

    Parameters
    ----------
    x_cyclic
        (n, k, 3) vertices of the facet of each point, in cyclic order (:func:`cyclic_order`).
    xi
        (n, 2) local coordinates.
    outward
        Optional (n, 3) outward vectors: each normal is flipped to have a non-negative component
        along it (a safeguard; a facet in outward cyclic order needs no flip).

    Returns
    -------
    np.ndarray
        (n, 3) unit normals.
    """
    x_cyclic = np.asarray(x_cyclic, dtype=np.float64)
    dN = shape_derivatives(x_cyclic.shape[1], xi)
    J = np.einsum("nka,nkj->naj", dN, x_cyclic)  # rows ∂x/∂ξ, ∂x/∂η
    n = np.cross(J[:, 0], J[:, 1])
    n /= np.linalg.norm(n, axis=1)[:, None]
    if outward is not None:
        flip = np.einsum("nj,nj->n", n, np.asarray(outward, dtype=np.float64)) < 0
        n[flip] *= -1.0
    return n


# --------------------------------------------------------------------------------------------
# Closest point on one facet (numba)
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _closest_on_edges(x, k, p, xi):
    """Squared distance from p to the facet's boundary (k straight edges: the edges of a bilinear
    quad are straight too), the boundary point's local coordinates written to xi."""
    corners = _TRI_CORNERS if k == 3 else _QUAD_CORNERS
    best = np.inf
    for e in range(k):
        f = (e + 1) % k
        ab0 = x[f, 0] - x[e, 0]
        ab1 = x[f, 1] - x[e, 1]
        ab2 = x[f, 2] - x[e, 2]
        ap0 = p[0] - x[e, 0]
        ap1 = p[1] - x[e, 1]
        ap2 = p[2] - x[e, 2]
        L2 = ab0 * ab0 + ab1 * ab1 + ab2 * ab2
        t = (ap0 * ab0 + ap1 * ab1 + ap2 * ab2) / L2 if L2 > 0.0 else 0.0
        t = min(1.0, max(0.0, t))
        d0 = ap0 - t * ab0
        d1 = ap1 - t * ab1
        d2 = ap2 - t * ab2
        dist2 = d0 * d0 + d1 * d1 + d2 * d2
        if dist2 < best:  # strict: the first edge wins a tie at a shared corner
            best = dist2
            xi[0] = (1.0 - t) * corners[e, 0] + t * corners[f, 0]
            xi[1] = (1.0 - t) * corners[e, 1] + t * corners[f, 1]
    return best


@numba.njit(cache=True)
def _stationary_point(x, k, p, xi, max_iterations):
    """Local coordinates of a stationary point of ½|x(ξ) − p|² (the foot of the normal from p).

    tri3: one linear solve. quad4: Newton from the centre with the exact Hessian
    JᵀJ + (r · x_ξη) [[0, 1], [1, 0]] (x_ξξ = x_ηη = 0 for a bilinear map), falling back to
    Gauss-Newton (JᵀJ) where that is not positive definite, steps bounded to 1 in max norm, and
    a bounded number of iterations. Returns True if it converged; ξ may lie outside the facet
    (the caller then uses the boundary).
    """
    N = np.empty(k)
    dN = np.empty((k, 2))
    r = np.empty(3)
    xs = np.empty(3)
    xt = np.empty(3)
    xst = np.empty(3)
    xi[0] = 1.0 / 3.0 if k == 3 else 0.0
    xi[1] = xi[0]
    iterations = 1 if k == 3 else max_iterations  # tri3: the map is affine, one step is exact
    size = np.inf
    for _ in range(iterations):
        _shape(k, xi[0], xi[1], N, dN)
        r[:] = 0.0
        xs[:] = 0.0
        xt[:] = 0.0
        xst[:] = 0.0
        for a in range(k):
            for j in range(3):
                r[j] += N[a] * x[a, j]
                xs[j] += dN[a, 0] * x[a, j]
                xt[j] += dN[a, 1] * x[a, j]
                if k == 4:
                    xst[j] += 0.25 * _QUAD_CORNERS[a, 0] * _QUAD_CORNERS[a, 1] * x[a, j]
        for j in range(3):
            r[j] -= p[j]
        g0 = r[0] * xs[0] + r[1] * xs[1] + r[2] * xs[2]
        g1 = r[0] * xt[0] + r[1] * xt[1] + r[2] * xt[2]
        H00 = xs[0] * xs[0] + xs[1] * xs[1] + xs[2] * xs[2]
        H11 = xt[0] * xt[0] + xt[1] * xt[1] + xt[2] * xt[2]
        H01 = xs[0] * xt[0] + xs[1] * xt[1] + xs[2] * xt[2]
        H01_full = H01 + r[0] * xst[0] + r[1] * xst[1] + r[2] * xst[2]
        det = H00 * H11 - H01_full * H01_full
        if det > 1e-8 * H00 * H11:
            H01 = H01_full
        else:
            det = H00 * H11 - H01 * H01
            if det <= 1e-14 * H00 * H11:
                return False  # degenerate facet
        ds = -(H11 * g0 - H01 * g1) / det
        dt = -(-H01 * g0 + H00 * g1) / det
        size = max(abs(ds), abs(dt))
        if size > 1.0:
            ds /= size
            dt /= size
        xi[0] += ds
        xi[1] += dt
        if k == 3 or size < 1e-13:
            return True
        if abs(xi[0]) > 4.0 or abs(xi[1]) > 4.0:
            return False  # far outside: the minimum is on the boundary
    # round-off in r = x(ξ) − p (coordinates far larger than the facet) can keep the last steps
    # above 1e-13 without any progress left: accept a small final step
    return size < 1e-9


@numba.njit(cache=True)
def _closest_on_facet(x, k, p, xi, max_iterations):
    """Squared distance from p to the facet and the closest point's local coordinates (in xi).

    The minimum of the distance over the closed facet is an interior stationary point or lies
    on the boundary; the boundary minimum is exact (straight edges), the interior one Newton's.
    """
    dist2 = _closest_on_edges(x, k, p, xi)
    inner = np.empty(2)
    if _stationary_point(x, k, p, inner, max_iterations):
        tol = 1e-12
        if k == 3:
            inside = inner[0] >= -tol and inner[1] >= -tol and inner[0] + inner[1] <= 1.0 + tol
        else:
            inside = abs(inner[0]) <= 1.0 + tol and abs(inner[1]) <= 1.0 + tol
        if inside:
            if k == 3:
                inner[0] = max(0.0, inner[0])
                inner[1] = max(0.0, inner[1])
                s = inner[0] + inner[1]
                if s > 1.0:
                    inner[0] /= s
                    inner[1] /= s
            else:
                inner[0] = min(1.0, max(-1.0, inner[0]))
                inner[1] = min(1.0, max(-1.0, inner[1]))
            N = np.empty(k)
            dN = np.empty((k, 2))
            _shape(k, inner[0], inner[1], N, dN)
            d2 = 0.0
            for j in range(3):
                q = 0.0
                for a in range(k):
                    q += N[a] * x[a, j]
                d2 += (p[j] - q) ** 2
            if d2 <= dist2:
                dist2 = d2
                xi[0] = inner[0]
                xi[1] = inner[1]
    return dist2


@numba.njit(cache=True)
def _project_kernel(points, x, offsets, candidates, tie, max_iterations):
    """For each point i, the closest of the facets candidates[offsets[i]:offsets[i+1]] (sorted
    ascending). Ties within ``tie`` go to the lowest facet index. Returns facet (−1: none),
    ξ and distance."""
    n = points.shape[0]
    k = x.shape[1]
    facet = np.full(n, -1, np.int64)
    xi = np.full((n, 2), np.nan)
    dist = np.full(n, np.inf)
    local = np.empty(2)
    for i in range(n):
        start, stop = offsets[i], offsets[i + 1]
        d = np.empty(stop - start)
        xs = np.empty((stop - start, 2))
        for c in range(start, stop):
            d[c - start] = np.sqrt(_closest_on_facet(x[candidates[c]], k, points[i], local, max_iterations))
            xs[c - start, 0] = local[0]
            xs[c - start, 1] = local[1]
        if stop == start:
            continue
        best = d.min()
        for c in range(start, stop):  # candidates ascending: the first within the tie wins
            if d[c - start] <= best + tie:
                facet[i] = candidates[c]
                xi[i, 0] = xs[c - start, 0]
                xi[i, 1] = xs[c - start, 1]
                dist[i] = d[c - start]
                break
    return facet, xi, dist


# --------------------------------------------------------------------------------------------
# Public projection
# --------------------------------------------------------------------------------------------


@dataclass
class Projection:
    """Closest points of slave points on a master surface (one row per slave point).

    Attributes
    ----------
    facet
        (n,) master facet index (−1: no facet within ``max_distance``; the other rows are NaN).
    xi
        (n, 2) local coordinates on that facet, for its vertices in CYCLIC order (module doc).
    N
        (n, k) shape-function values N_k(ξ) in the CALLER's vertex order of the facet.
    point
        (n, 3) closest point x(ξ) = Σ_k N_k(ξ) X_k.
    normal
        (n, 3) the master's outward unit normal at ξ (∂x/∂ξ × ∂x/∂η, oriented like the facet's
        outward area vector).
    g0
        (n,) signed distance n · (X_s − x(ξ)): positive on the outer side of the master.
    distance
        (n,) |X_s − x(ξ)|.
    tangential_offset
        (n,) |X_s − x(ξ) − g0 n|: zero (round-off) when ξ is the foot of the normal from X_s;
        positive when the closest point had to be clamped to a facet edge or corner, e.g. a
        point beyond the master surface's boundary, or outside a convex edge of the master.
    """

    facet: np.ndarray
    xi: np.ndarray
    N: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    g0: np.ndarray
    distance: np.ndarray
    tangential_offset: np.ndarray


def _candidates(points: np.ndarray, centroid: np.ndarray, radius: np.ndarray,
                max_distance: float | None, tie: float) -> tuple[np.ndarray, np.ndarray]:
    """CSR candidate facets of each point: every facet that may hold the closest point (or tie).

    The linear or bilinear map at the reference centre is the vertex mean, which therefore lies
    on the facet: the nearest centroid, at distance δ, bounds the distance to the surface by δ.
    Every point of facet f lies in the convex hull of its vertices (N_a ≥ 0), hence within r_f
    (the largest centroid-to-vertex distance) of its centroid c_f, so f can be closer than
    δ + tie only if |X_s − c_f| ≤ δ + r_max + tie. Points with δ − r_max > max_distance are
    farther than max_distance from every facet and get no candidate.
    """
    from scipy.spatial import cKDTree  # imported when a projection is made, not by every run (0.18 s)

    tree = cKDTree(centroid)
    delta, _ = tree.query(points)
    r_max = float(radius.max())
    ball = delta + r_max * (1.0 + 1e-12) + tie
    if max_distance is not None:
        ball = np.where(delta - r_max > max_distance, -1.0, ball)
    lists = tree.query_ball_point(points, np.maximum(ball, 0.0), return_sorted=True)
    lists = [c if b >= 0 else [] for c, b in zip(lists, ball)]
    counts = np.fromiter((len(c) for c in lists), dtype=np.int64, count=len(lists))
    offsets = np.concatenate([[0], np.cumsum(counts)])
    flat = np.fromiter((f for c in lists for f in c), dtype=np.int64, count=int(offsets[-1]))
    return offsets, flat


def project_points(points: npt.ArrayLike, x: npt.ArrayLike, outward: npt.ArrayLike,
                   max_distance: float | None = None, tie_tolerance: float = TIE_TOLERANCE) -> Projection:
    """Closest-point projection of points onto a surface of tri3 or quad4 facets.

    For each point the candidate facets come from a KD-tree on the facet centroids (complete:
    see :func:`_candidates`); on each candidate the closest point is the better of the foot of
    the normal (exact for tri3, local Newton for quad4) and the closest point on the facet's
    boundary (edges and corners, exact). The facet with the smallest distance wins; distances
    within ``tie_tolerance`` × the surface's bounding-box diagonal tie and go to the lowest
    facet index, so order the facets by position (as ``surfaces.py`` does) for a choice that does
    not depend on the partition.

    Parameters
    ----------
    points
        (n, 3) slave points X_s.
    x
        (m, k, 3) master facet vertices, k = 3 or 4, in any order (reordered cyclically here).
    outward
        (m, 3) the master facets' outward area vectors (``Facets.area``).
    max_distance
        Points farther than this from the surface get ``facet = −1`` (and NaN elsewhere);
        None: every point is projected.
    tie_tolerance
        Relative tie tolerance (default :data:`TIE_TOLERANCE`).

    Returns
    -------
    Projection
    """
    points = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    x = np.asarray(x, dtype=np.float64)
    outward = np.asarray(outward, dtype=np.float64)
    _check_facets(x, outward)
    k = x.shape[1]
    xc, perm = _cyclic(x, outward)
    centroid = xc.mean(axis=1)
    radius = np.linalg.norm(xc - centroid[:, None, :], axis=2).max(axis=1)
    diagonal = float(np.linalg.norm(xc.reshape(-1, 3).max(axis=0) - xc.reshape(-1, 3).min(axis=0)))
    tie = tie_tolerance * diagonal
    offsets, candidates = _candidates(points, centroid, radius, max_distance, tie)
    facet, xi, dist = _project_kernel(points, xc, offsets, candidates, tie, NEWTON_MAX_ITERATIONS)
    if max_distance is not None:
        facet[dist > max_distance] = -1
    return _projection(points, xc, perm, outward, facet, xi, dist)


def project_onto_facets(points: npt.ArrayLike, x: npt.ArrayLike, outward: npt.ArrayLike,
                        facets: npt.ArrayLike) -> Projection:
    """Closest-point projection of every point onto one given facet: point i onto facet ``facets[i]``
    (clamped to its boundary where the foot of the normal lies outside), as :func:`project_points`
    finds it on that facet alone.

    Parameters
    ----------
    points
        (n, 3) points.
    x, outward
        (m, k, 3) the facets' vertices in any order and (m, 3) their outward area vectors.
    facets
        (n,) the facet of each point.
    """
    points = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    x = np.asarray(x, dtype=np.float64)
    outward = np.asarray(outward, dtype=np.float64)
    facets = np.asarray(facets, dtype=np.int64)
    xc, perm = _cyclic(x, outward)
    n = len(points)
    local, xi, dist = _project_kernel(points, np.ascontiguousarray(xc[facets]), np.arange(n + 1),
                                      np.arange(n), 0.0, NEWTON_MAX_ITERATIONS)
    facet = np.where(local >= 0, facets, -1)
    return _projection(points, xc, perm, outward, facet, xi, dist)


def _projection(points: np.ndarray, xc: np.ndarray, perm: np.ndarray, outward: np.ndarray, facet: np.ndarray,
                xi: np.ndarray, dist: np.ndarray) -> Projection:
    """The :class:`Projection` of ``points`` onto the facets ``facet`` (−1: none) at local coordinates
    ``xi`` (cyclic vertices ``xc``, their permutation ``perm`` from the caller's order)."""
    n = len(points)
    k = xc.shape[1]
    found = facet >= 0
    xi[~found] = np.nan
    f = facet[found]
    N = np.full((n, k), np.nan)
    Nc = shape_functions(k, xi[found])
    N_found = np.empty_like(Nc)
    np.put_along_axis(N_found, perm[f], Nc, axis=1)  # back to the caller's vertex order
    N[found] = N_found
    point = np.full((n, 3), np.nan)
    point[found] = np.einsum("nk,nkj->nj", Nc, xc[f])
    normal = np.full((n, 3), np.nan)
    normal[found] = facet_normals(xc[f], xi[found], outward[f])
    d = points - point
    g0 = np.einsum("nj,nj->n", normal, d)
    tangential = np.linalg.norm(d - g0[:, None] * normal, axis=1)
    dist = np.where(found, dist, np.nan)
    return Projection(facet, xi, N, point, normal, g0, dist, tangential)
