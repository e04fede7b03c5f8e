"""A slave node kept on its preferred master facet (``contact/node_to_surface.py``, ``keep_preferred``): on
quadratic master facets every changed node is projected onto its preferred facet in one call
(``quadratic_projection.project_onto_facets``), with the answers of projecting each node alone onto its one
facet (``project_points_quadratic``), which the rule did before, node by node.

A curved, distorted 3 × 3 patch of quad9 (or 18 tri6) master facets, slave points scattered above and
beside it; preferred facets: the facet a point projects onto, a neighbour, a far facet, none.
"""

import numpy as np
import pytest
from test_quadratic_mortar_linearisation import _area_vectors, _facets, _grid

from dolfinx_nnqem.contact.node_to_surface import keep_preferred
from dolfinx_nnqem.contact.projection import Projection
from dolfinx_nnqem.contact.quadratic_projection import project_onto_facets, project_points_quadratic
from dolfinx_nnqem.contact.surfaces import Facets

FIELDS = ("facet", "xi", "N", "point", "normal", "g0", "distance", "tangential_offset")


def _master(triangles: bool) -> Facets:
    rng = np.random.default_rng(11)
    ids, x = _grid(3, 0.0, 1.0, 0)
    x[:, 2] = 0.1 * np.sin(2.0 * x[:, 0]) + 0.01 * rng.standard_normal(len(x))
    x[:, :2] += 0.02 * rng.standard_normal((len(x), 2))
    nodes = _facets(3, ids, triangles)
    xf = x[nodes]
    return Facets(np.ones(len(nodes), dtype=np.int32), nodes, xf, _area_vectors(xf, True), np.ones(len(nodes)))


def _points(n: int) -> np.ndarray:
    rng = np.random.default_rng(5)
    return np.column_stack([rng.uniform(-0.1, 1.1, n), rng.uniform(-0.1, 1.1, n), rng.uniform(0.02, 0.15, n)])


def _one_by_one(p: Projection, x: np.ndarray, master: Facets, preferred: np.ndarray, allowance: float) -> Projection:
    """The rule as it was: each changed node projected alone onto its preferred facet."""
    out = Projection(*(np.array(getattr(p, name), copy=True) for name in FIELDS))
    for i in np.flatnonzero((preferred >= 0) & (p.facet != preferred)):
        f = int(preferred[i])
        q = project_points_quadratic(x[i:i + 1], master.x[f:f + 1], master.area[f:f + 1])
        best = p.distance[i] if p.facet[i] >= 0 else np.inf
        if q.tangential_offset[0] <= allowance and q.distance[0] <= best + allowance:
            for name in FIELDS[1:]:
                getattr(out, name)[i] = getattr(q, name)[0]
            out.facet[i] = f
    return out


@pytest.mark.parametrize("triangles", [False, True])
def test_projections_onto_given_facets_are_those_of_each_point_alone(triangles):
    master = _master(triangles)
    x = _points(40)
    facets = np.arange(40) % len(master.x)
    q = project_onto_facets(x, master.x, master.area, facets)
    for i, f in enumerate(facets):
        alone = project_points_quadratic(x[i:i + 1], master.x[f:f + 1], master.area[f:f + 1])
        assert q.facet[i] == f
        for name in FIELDS[1:]:
            assert np.array_equal(getattr(q, name)[i], getattr(alone, name)[0], equal_nan=True), name


@pytest.mark.parametrize("triangles", [False, True])
def test_keep_preferred_on_quadratic_facets_gives_the_node_by_node_answers(triangles):
    master = _master(triangles)
    x = _points(60)
    p = project_points_quadratic(x, master.x, master.area, max_distance=0.5)
    preferred = p.facet.copy()
    preferred[::4] = (p.facet[::4] + 1) % len(master.x)  # a neighbour (or the next row's first)
    preferred[1::7] = (p.facet[1::7] + len(master.x) // 2) % len(master.x)  # far
    preferred[2::9] = -1
    allowance = 0.2
    kept = keep_preferred(p, x, master, preferred, allowance)
    reference = _one_by_one(p, x, master, preferred, allowance)
    moved = kept.facet != p.facet
    assert moved.any() and (kept.facet[preferred >= 0] != preferred[preferred >= 0]).any()  # some kept, some not
    for name in FIELDS:
        assert np.array_equal(getattr(kept, name), getattr(reference, name), equal_nan=True), name


def test_a_facet_out_of_range_is_refused():
    master = _master(False)
    with pytest.raises(ValueError, match="expected a facet in 0..8 per point"):
        project_onto_facets(_points(2), master.x, master.area, [0, 9])
