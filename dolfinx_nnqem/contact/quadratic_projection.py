r"""Closest-point projection onto a surface of quadratic facets (tri6, quad9), curved or not.

The quadratic counterpart of :func:`~dolfinx_nnqem.contact.projection.project_points`
(``formulation.md`` §2b, §2c "Quadratic facets"): a slave point X_s is projected onto the master
surface at local coordinates ξ of master facet f,

    x(ξ) = Σ_k N_k(ξ) X_k,   n = the master's outward unit normal at ξ,   g0 = n · (X_s − x(ξ)),

with the quadratic shape functions and node order of :mod:`~dolfinx_nnqem.contact.quadratic_facets`
(ξ in its reference coordinates). On a second-order mesh the facets are curved and so are their
edges; on a straight-sided mesh x(ξ) is the linear facet's map and the projection its closest
point, with quadratic N_k there.

On each candidate facet the closest point is the better of an interior stationary point of
½|x(ξ) − p|² (Newton with the exact Hessian JᵀJ + Σ_j r_j ∂²x_j/∂ξ², Gauss–Newton where that is
not positive definite, from the nearest of a few reference points) and the closest point of the
facet's boundary (each edge a quadratic curve x(ξ(t)), t ∈ [0, 1]: Newton in t from the nearest
of five points, clamped, and the end points). Like the linear projection, it returns a
:class:`~dolfinx_nnqem.contact.projection.Projection`, N in the facet's node order.
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

from dolfinx_nnqem.contact.projection import TIE_TOLERANCE, Projection, _candidates
from dolfinx_nnqem.contact.quadratic_facets import (facet_geometry, is_quadratic, outward_signs, shape_at,
                                                    shape_derivatives, shape_functions)

__all__ = ["project_onto_facets", "project_points_quadratic"]

NEWTON_MAX_ITERATIONS = 30
"""Bound on the local Newton iterations (interior point and each edge)."""

# the edges of each reference facet as (start, end) in reference coordinates (straight there)
_TRI_EDGES = np.array([[[0.0, 0.0], [1.0, 0.0]], [[1.0, 0.0], [0.0, 1.0]], [[0.0, 1.0], [0.0, 0.0]]])
_QUAD_EDGES = np.array([[[0.0, 0.0], [1.0, 0.0]], [[1.0, 0.0], [1.0, 1.0]], [[1.0, 1.0], [0.0, 1.0]],
                        [[0.0, 1.0], [0.0, 0.0]]])
_STARTS = np.array([[1.0 / 3.0, 1.0 / 3.0], [0.2, 0.2], [0.6, 0.2], [0.2, 0.6], [0.5, 0.5], [0.25, 0.25],
                    [0.75, 0.25], [0.25, 0.75], [0.75, 0.75]])


@numba.njit(cache=True)
def _evaluate(x, k, s, t, p, N, dN, d2N, r, xs, xt, h):
    """r = x(ξ) − p, xs = x_ξ, xt = x_η and h = (x_ξξ, x_ξη, x_ηη) (3, 3) at (s, t)."""
    shape_at(k, s, t, N, dN, d2N)
    for j in range(3):
        r[j] = -p[j]
        xs[j] = 0.0
        xt[j] = 0.0
        h[0, j] = 0.0
        h[1, j] = 0.0
        h[2, j] = 0.0
    for a in range(k):
        for j in range(3):
            r[j] += N[a] * x[a, j]
            xs[j] += dN[a, 0] * x[a, j]
            xt[j] += dN[a, 1] * x[a, j]
            h[0, j] += d2N[a, 0] * x[a, j]
            h[1, j] += d2N[a, 1] * x[a, j]
            h[2, j] += d2N[a, 2] * x[a, j]


@numba.njit(cache=True)
def _inside(k, s, t, tol):
    if k == 6:
        return s >= -tol and t >= -tol and s + t <= 1.0 + tol
    return -tol <= s <= 1.0 + tol and -tol <= t <= 1.0 + tol


@numba.njit(cache=True)
def _interior_point(x, k, p, xi, max_iterations):
    """A stationary point of ½|x(ξ) − p|² (written to xi); True if Newton converged inside the
    facet (within 1e-12), False otherwise (the caller uses the boundary)."""
    N = np.empty(k)
    dN = np.empty((k, 2))
    d2N = np.empty((k, 3))
    r = np.empty(3)
    xs = np.empty(3)
    xt = np.empty(3)
    h = np.empty((3, 3))
    best = np.inf
    for q in range(_STARTS.shape[0]):  # the start: the nearest of a few reference points inside
        if not _inside(k, _STARTS[q, 0], _STARTS[q, 1], 0.0):
            continue
        _evaluate(x, k, _STARTS[q, 0], _STARTS[q, 1], p, N, dN, d2N, r, xs, xt, h)
        d2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
        if d2 < best:
            best = d2
            xi[0] = _STARTS[q, 0]
            xi[1] = _STARTS[q, 1]
    size = np.inf
    for _ in range(max_iterations):
        _evaluate(x, k, xi[0], xi[1], p, N, dN, d2N, r, xs, xt, h)
        g0 = r[0] * xs[0] + r[1] * xs[1] + r[2] * xs[2]
        g1 = r[0] * xt[0] + r[1] * xt[1] + r[2] * xt[2]
        A00 = xs[0] * xs[0] + xs[1] * xs[1] + xs[2] * xs[2]
        A11 = xt[0] * xt[0] + xt[1] * xt[1] + xt[2] * xt[2]
        A01 = xs[0] * xt[0] + xs[1] * xt[1] + xs[2] * xt[2]
        H00 = A00 + r[0] * h[0, 0] + r[1] * h[0, 1] + r[2] * h[0, 2]
        H01 = A01 + r[0] * h[1, 0] + r[1] * h[1, 1] + r[2] * h[1, 2]
        H11 = A11 + r[0] * h[2, 0] + r[1] * h[2, 1] + r[2] * h[2, 2]
        det = H00 * H11 - H01 * H01
        if not (H00 > 0.0 and det > 1e-8 * A00 * A11):  # not positive definite: Gauss–Newton
            H00, H01, H11 = A00, A01, A11
            det = H00 * H11 - H01 * H01
            if det <= 1e-14 * A00 * A11:
                return False  # degenerate facet
        ds = -(H11 * g0 - H01 * g1) / det
        dt = -(-H01 * g0 + H00 * g1) / det
        size = max(abs(ds), abs(dt))
        if size > 0.5:
            ds *= 0.5 / size
            dt *= 0.5 / size
        xi[0] += ds
        xi[1] += dt
        if size < 1e-13:
            break
        if abs(xi[0]) > 4.0 or abs(xi[1]) > 4.0:
            return False  # far outside: the minimum is on the boundary
    # round-off in r (coordinates far larger than the facet) can keep the last steps above 1e-13
    return size < 1e-9 and _inside(k, xi[0], xi[1], 1e-12)


@numba.njit(cache=True)
def _closest_on_edges(x, k, p, xi, max_iterations):
    """Squared distance from p to the facet's boundary (curved edges), the point's ξ in xi."""
    edges = _TRI_EDGES if k == 6 else _QUAD_EDGES
    N = np.empty(k)
    dN = np.empty((k, 2))
    d2N = np.empty((k, 3))
    r = np.empty(3)
    xs = np.empty(3)
    xt = np.empty(3)
    h = np.empty((3, 3))
    best = np.inf
    for e in range(edges.shape[0]):
        a0, a1 = edges[e, 0, 0], edges[e, 0, 1]
        e0, e1 = edges[e, 1, 0] - a0, edges[e, 1, 1] - a1  # dξ/dt
        t_best, d_best = 0.0, np.inf
        for q in range(5):  # the nearest of five points starts Newton
            t = 0.25 * q
            _evaluate(x, k, a0 + t * e0, a1 + t * e1, p, N, dN, d2N, r, xs, xt, h)
            d2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
            if d2 < d_best:
                t_best, d_best = t, d2
        t = t_best
        for _ in range(max_iterations):
            _evaluate(x, k, a0 + t * e0, a1 + t * e1, p, N, dN, d2N, r, xs, xt, h)
            dx = np.empty(3)
            ddx = np.empty(3)
            for j in range(3):  # x(ξ(t))' and x(ξ(t))''
                dx[j] = xs[j] * e0 + xt[j] * e1
                ddx[j] = h[0, j] * e0 * e0 + 2.0 * h[1, j] * e0 * e1 + h[2, j] * e1 * e1
            g = r[0] * dx[0] + r[1] * dx[1] + r[2] * dx[2]
            H = dx[0] * dx[0] + dx[1] * dx[1] + dx[2] * dx[2]
            Hfull = H + r[0] * ddx[0] + r[1] * ddx[1] + r[2] * ddx[2]
            step = -g / (Hfull if Hfull > 1e-8 * H else H) if H > 0.0 else 0.0
            t_new = min(1.0, max(0.0, t + max(-0.5, min(0.5, step))))
            if abs(t_new - t) < 1e-14:
                t = t_new
                break
            t = t_new
        _evaluate(x, k, a0 + t * e0, a1 + t * e1, p, N, dN, d2N, r, xs, xt, h)
        d2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
        if d2 < best:  # strict: the first edge wins a tie at a shared corner
            best = d2
            xi[0] = a0 + t * e0
            xi[1] = a1 + t * e1
    return best


@numba.njit(cache=True)
def _closest_on_facet(x, k, p, xi, max_iterations):
    """Squared distance from p to the facet and the closest point's ξ (in xi)."""
    dist2 = _closest_on_edges(x, k, p, xi, max_iterations)
    inner = np.empty(2)
    if _interior_point(x, k, p, inner, max_iterations):
        N = np.empty(k)
        dN = np.empty((k, 2))
        d2N = np.empty((k, 3))
        r = np.empty(3)
        xs = np.empty(3)
        xt = np.empty(3)
        h = np.empty((3, 3))
        _evaluate(x, k, inner[0], inner[1], p, N, dN, d2N, r, xs, xt, h)
        d2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
        if d2 <= dist2:
            dist2 = d2
            xi[0] = inner[0]
            xi[1] = inner[1]
    return dist2


@numba.njit(cache=True)
def _project_kernel(points, x, offsets, candidates, tie, max_iterations):
    """For each point, the closest of its candidate facets (ascending; ties to the lowest index)."""
    n = points.shape[0]
    k = x.shape[1]
    facet = np.full(n, -1, np.int64)
    xi = np.full((n, 2), np.nan)
    dist = np.full(n, np.inf)
    local = np.empty(2)
    for i in range(n):
        start, stop = offsets[i], offsets[i + 1]
        if stop == start:
            continue
        d = np.empty(stop - start)
        xs = np.empty((stop - start, 2))
        for c in range(start, stop):
            d[c - start] = np.sqrt(_closest_on_facet(x[candidates[c]], k, points[i], local, max_iterations))
            xs[c - start, 0] = local[0]
            xs[c - start, 1] = local[1]
        best = d.min()
        for c in range(start, stop):
            if d[c - start] <= best + tie:
                facet[i] = candidates[c]
                xi[i, 0] = xs[c - start, 0]
                xi[i, 1] = xs[c - start, 1]
                dist[i] = d[c - start]
                break
    return facet, xi, dist


def _bounding_balls(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A point on each facet (its reference centre's image) and a radius about it holding the facet.

    The radius is 1.1 × the largest distance from the centre to the facet's nodes and to 9 points
    along each edge: a curved second-order facet may bulge beyond its nodes, by much less than that
    margin for any facet a mesh generator accepts.
    """
    k = x.shape[1]
    centre = np.array([[1.0 / 3.0, 1.0 / 3.0]]) if k == 6 else np.array([[0.5, 0.5]])
    c = facet_geometry(x, centre)[0][:, 0]
    edges = _TRI_EDGES if k == 6 else _QUAD_EDGES
    t = np.linspace(0.0, 1.0, 9)[:, None, None]
    samples = (edges[None, :, 0] + t * (edges[None, :, 1] - edges[None, :, 0])).reshape(-1, 2)
    on_edges = facet_geometry(x, samples)[0]
    reach = np.concatenate([on_edges, x], axis=1) - c[:, None, :]
    return c, 1.1 * np.linalg.norm(reach, axis=2).max(axis=1)


def project_points_quadratic(points: npt.ArrayLike, x: npt.ArrayLike, outward: npt.ArrayLike,
                             max_distance: float | None = None,
                             tie_tolerance: float = TIE_TOLERANCE) -> Projection:
    """Closest-point projection of points onto a surface of tri6 or quad9 facets.

    Parameters
    ----------
    points
        (n, 3) slave points X_s.
    x
        (m, k, 3) master facet nodes, k = 6 or 9, in :mod:`~dolfinx_nnqem.contact.quadratic_facets`'
        order (vertices in any order).
    outward
        (m, 3) the master facets' outward vectors (``Facets.area``).
    max_distance, tie_tolerance
        As for :func:`~dolfinx_nnqem.contact.projection.project_points`.

    Returns
    -------
    Projection
        ξ in the quadratic reference coordinates, N in the facets' node order.
    """
    points = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    x = np.ascontiguousarray(x, dtype=np.float64)
    outward = np.asarray(outward, dtype=np.float64)
    if x.ndim != 3 or not is_quadratic(x.shape[1]) or x.shape[2] != 3 or len(x) == 0 or outward.shape != (len(x), 3):
        raise ValueError(f"expected quadratic facets (m >= 1, 6 or 9, 3) and outward vectors (m, 3), got {x.shape} "
                         f"and {outward.shape}")
    centre, radius = _bounding_balls(x)
    diagonal = float(np.linalg.norm(x.reshape(-1, 3).max(axis=0) - x.reshape(-1, 3).min(axis=0)))
    tie = tie_tolerance * diagonal
    offsets, candidates = _candidates(points, centre, radius, max_distance, tie)
    facet, xi, dist = _project_kernel(points, x, offsets, candidates, tie, NEWTON_MAX_ITERATIONS)
    if max_distance is not None:
        facet[dist > max_distance] = -1
    return _projection(points, x, outward, facet, xi, dist)


def project_onto_facets(points: npt.ArrayLike, x: npt.ArrayLike, outward: npt.ArrayLike,
                        facets: npt.ArrayLike) -> Projection:
    """The closest point of each point on its own facet: point i onto facet ``facets[i]`` of the tri6 or
    quad9 facets (x, outward) of :func:`project_points_quadratic`, all in one call (what that function
    gives for the one point and the one facet)."""
    points = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    x = np.ascontiguousarray(x, dtype=np.float64)
    facets = np.ascontiguousarray(facets, dtype=np.int64)
    if facets.shape != (len(points),) or np.any((facets < 0) | (facets >= len(x))):
        raise ValueError(f"expected a facet in 0..{len(x) - 1} per point ({len(points)}), got {facets}")
    offsets = np.arange(len(points) + 1, dtype=np.int64)
    facet, xi, dist = _project_kernel(points, x, offsets, facets, 0.0, NEWTON_MAX_ITERATIONS)
    return _projection(points, x, np.asarray(outward, dtype=np.float64), facet, xi, dist)


def _projection(points: np.ndarray, x: np.ndarray, outward: np.ndarray, facet: np.ndarray, xi: np.ndarray,
                dist: np.ndarray) -> Projection:
    """The :class:`~dolfinx_nnqem.contact.projection.Projection` of ``points`` at the reference points ``xi``
    of their facets ``facet`` (−1: none)."""
    k = x.shape[1]
    n = len(points)
    found = facet >= 0
    xi[~found] = np.nan
    f = facet[found]
    N = np.full((n, k), np.nan)
    point = np.full((n, 3), np.nan)
    normal = np.full((n, 3), np.nan)
    if np.any(found):
        N[found] = shape_functions(k, xi[found])
        point[found] = np.einsum("nk,nkj->nj", N[found], x[f])
        J = np.einsum("nab,naj->nbj", shape_derivatives(k, xi[found]), x[f])  # rows x_ξ, x_η at each ξ
        area = np.cross(J[:, 0], J[:, 1]) * outward_signs(x[f], outward[f])[:, None]
        normal[found] = area / np.linalg.norm(area, axis=1)[:, None]
    d = points - point
    g0 = np.einsum("nj,nj->n", normal, d)
    tangential = np.linalg.norm(d - g0[:, None] * normal, axis=1)
    dist = np.where(found, dist, np.nan)
    return Projection(facet, xi, N, point, normal, g0, dist, tangential)
