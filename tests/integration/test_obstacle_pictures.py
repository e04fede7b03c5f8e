"""The rigid obstacles in the pictures of the deformed shape (issue 41).

* each obstacle type's surface (:func:`~dolfinx_nnqem.io.obstacle_shapes.obstacle_surfaces`) lies on the
  obstacle moved by scale × its displacement, clipped to the view box;
* a finite-strain run pressing a rigid sphere into a block (``tests/mpi_scripts/deformed_outputs.py``):
  ``summary.json`` records the sphere and its displacement, ``deformed.png`` is drawn at the true scale
  with the sphere in its scene, where it stands at the last increment (its lowest point 0.05 into the
  block's top); the live problem's picture (``plots.plot_deformed``) draws it too.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from dolfinx_nnqem.io.obstacle_shapes import obstacle_surfaces, view_box

SCRIPTS = Path(__file__).resolve().parents[1] / "mpi_scripts"
sys.path.insert(0, str(SCRIPTS))

from deformed_outputs import write_run  # noqa: E402

BOX = (-1.0, 1.0, -1.0, 1.0, -1.0, 1.0)
CHORD = 1 - np.cos(np.pi / 64)  # how far a facet of the drawn sphere or cylinder lies inside it, per radius


def _points(surface) -> np.ndarray:
    """The points of a VTK PolyData."""
    from vtkmodules.util.numpy_support import vtk_to_numpy

    return vtk_to_numpy(surface.GetPoints().GetData()).astype(float)


def _triangles(surface) -> np.ndarray:
    """The corners of a VTK PolyData's triangles, (triangles, 3, 3)."""
    from vtkmodules.util.numpy_support import vtk_to_numpy

    triangles = vtk_to_numpy(surface.GetPolys().GetConnectivityArray()).reshape(-1, 3)
    return _points(surface)[triangles]


@pytest.mark.parametrize("scale", [1.0, 20.0])
def test_each_obstacle_is_drawn_where_it_stands(scale):
    d = np.array([0.0, -0.01, 0.0])
    # the ball sticks out of the view's top (y = 1) when scale = 1: it is cut there
    records = {"ball": {"type": "sphere", "centre": [0.0, 0.9, 0.0], "radius": 0.3, "displacement": d.tolist()},
               "roller": {"type": "cylinder", "point": [0.0, 0.5, 0.0], "axis": [0.0, 0.0, 2.0], "radius": 0.3,
                          "displacement": d.tolist()},
               "floor": {"type": "plane", "point": [0.0, -0.5, 0.0], "normal": [0.0, 1.0, 0.0],
                         "displacement": d.tolist()},
               "far": {"type": "sphere", "centre": [9.0, 9.0, 9.0], "radius": 0.3, "displacement": [0.0, 0.0, 0.0]}}
    surfaces = obstacle_surfaces(records, BOX, scale)
    assert sorted(surfaces) == ["ball", "floor", "roller"]  # "far" is outside the view
    shift = scale * d
    for name, surface in surfaces.items():
        x = _points(surface)
        assert np.all(x >= np.array(BOX[::2]) - 1e-9) and np.all(x <= np.array(BOX[1::2]) + 1e-9), name
    ball_points = _points(surfaces["ball"])
    ball = np.linalg.norm(ball_points - (np.array([0.0, 0.9, 0.0]) + shift), axis=1)[ball_points[:, 1] < 1.0 - 1e-6]
    assert ball_points[:, 1].max() == pytest.approx(min(1.0, 1.2 + shift[1]), abs=CHORD * 0.3 + 1e-6)
    roller = np.linalg.norm((_points(surfaces["roller"]) - (np.array([0.0, 0.5, 0.0]) + shift))[:, :2], axis=1)
    side = np.abs(np.abs(_points(surfaces["roller"])[:, 2]) - 0.999) > 1e-6  # not on an end face
    floor = _points(surfaces["floor"])[:, 1] - (-0.5 + shift[1])
    z = _points(surfaces["roller"])[:, 2]
    assert np.all(np.abs(ball - 0.3) <= CHORD * 0.3 + 1e-6) and np.all(np.abs(roller[side] - 0.3) <= CHORD * 0.3 + 1e-6)
    assert np.abs(floor).max() < 1e-6  # (VTK keeps single-precision points)
    assert np.isclose(z.min(), BOX[4], atol=3e-3) and np.isclose(z.max(), BOX[5], atol=3e-3)  # crosses the view
    corners = _triangles(surfaces["roller"])
    on_ends = np.all(np.abs(np.abs(corners[:, :, 2]) - 0.999) < 1e-6, axis=1) & (np.ptp(corners[:, :, 2], axis=1) < 1e-6)
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    polygon = 0.5 * 64 * 0.3**2 * np.sin(2 * np.pi / 64)  # the end face: a 64-gon in the circle of radius 0.3
    assert areas[on_ends].sum() == pytest.approx(2 * polygon, rel=1e-5)  # both ends closed
    assert np.ptp(_points(surfaces["floor"])[:, 0]) >= 2.0 - 1e-9  # the plane too


def test_a_finite_strain_run_draws_its_obstacle_at_true_scale(tmp_path, monkeypatch):
    from dolfinx_nnqem.io import deformed_picture, plots, run_pictures
    from dolfinx_nnqem.io import obstacle_shapes

    problem = write_run(tmp_path / "run")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["kinematics"] == "finite"
    sphere = summary["obstacles"]["sphere-201"]
    assert sphere["type"] == "sphere" and sphere["radius"] == 0.5
    assert np.allclose(sphere["displacement"], [0.0, -0.05, 0.0], rtol=0, atol=1e-15)

    scenes = []

    class Recorded(deformed_picture.DeformedScene):
        def draw(self, field, path):
            super().draw(field, path)
            scenes.append((self.options, dict(self.scene.actors)))
            return path

    monkeypatch.setattr(run_pictures, "DeformedScene", Recorded)
    done = run_pictures.draw_run_pictures(tmp_path / "run", names=("deformed.png",))
    assert isinstance(done["deformed.png"], Path), done
    kwargs, actors = scenes[-1]
    assert kwargs["scale"] == 1.0 and "obstacle:sphere-201" in actors
    drawn = actors["obstacle:sphere-201"].GetMapper().GetInput()
    lowest = float(_points(drawn)[:, 1].min())
    print(f"\n  deformed.png: scale {kwargs['scale']}, actors {sorted(actors)}; the sphere's lowest point drawn at "
          f"y = {lowest:.4f} (block top 0.5, pressed 0.05)")
    assert abs(lowest - 0.45) <= CHORD * 0.5 + 1e-6  # (the facets of the drawn sphere)

    added = []
    original = obstacle_shapes.add_obstacles
    monkeypatch.setattr(obstacle_shapes, "add_obstacles", lambda *a, **k: added.append(original(*a, **k)) or added[-1])
    plots.plot_deformed(problem, tmp_path / "live.png", scale=1.0, camera="xy")
    assert added == [["sphere-201"]] and (tmp_path / "live.png").stat().st_size > 10_000


def test_the_view_box_reaches_beyond_the_bodies():
    box = view_box(np.array([[0.0, 0.0, 0.0], [2.0, 1.0, 0.5]]))
    assert np.allclose(box, (-0.5, 2.5, -0.5, 1.5, -0.5, 1.0))
