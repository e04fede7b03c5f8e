"""The end-of-run pictures do no work twice (issue 43: "pictures ≤ 1 s of CPU"): each picture of
the deformed scene is rendered once, by its screenshot. Counted, not timed (the CPU is measured by
``benchmarks/pictures_profile.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from dolfinx_nnqem.io import deformed_picture, vtk_scene


def _hexahedra(n: int = 2) -> dict:
    """A field step of n³ unit hexahedra (VTK's node order) with von Mises, p and an error
    indicator per cell, some cells plastic (the outline of the plastic zone is drawn)."""
    ijk = np.stack(np.meshgrid(*[np.arange(n + 1)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    node = {tuple(p): k for k, p in enumerate(ijk)}
    corners = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
    cells = np.array([[node[(i + a, j + b, k + c)] for a, b, c in corners]
                      for i in range(n) for j in range(n) for k in range(n)])
    x = ijk.astype(float)
    ncells = len(cells)
    return {"time": 1.0, "geometry": x, "topology": cells, "u": 0.01 * x * x[:, :1],
            "von_mises": np.linspace(1.0, 2.0, ncells), "p": np.where(np.arange(ncells) < 3, 1e-3, 0.0),
            "error_indicator": np.linspace(2.0, 0.5, ncells)}


@pytest.fixture
def renders(monkeypatch) -> list[str]:
    """The renders of every scene the deformed picture makes (its render window's StartEvent)."""
    counted: list[str] = []

    class Counting(vtk_scene.Scene):
        def __init__(self, size):
            super().__init__(size)
            self.window.AddObserver("StartEvent", lambda *_: counted.append("render"))

    monkeypatch.setattr(vtk_scene, "Scene", Counting)
    return counted


def test_each_picture_of_the_scene_is_rendered_once(tmp_path, renders):
    """deformed.png, then error_indicator.png from the same scene recoloured: two renders, one per
    screenshot (pyvista, which drew it before, rendered the scene again at the actor removed and at
    the one added)."""
    scene = deformed_picture.DeformedScene(_hexahedra(), [], title="hexahedra")
    counts = []
    try:
        for field, name in (("von_mises", "deformed.png"), ("error_indicator", "error_indicator.png")):
            scene.draw(field, tmp_path / name)
            counts.append(len(renders) - sum(counts))
    finally:
        scene.close()
    print(f"\n  renders: {counts[0]} for deformed.png, {counts[1]} for error_indicator.png")
    assert counts == [1, 1]
    assert all((tmp_path / name).stat().st_size > 0 for name in ("deformed.png", "error_indicator.png"))
