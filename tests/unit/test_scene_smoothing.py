"""The 3D scenes' edges are smoothed (``io/vtk_scene.py``, issue 43): since the scenes are drawn
without multisampling (its CPU with Mesa's software OpenGL), FXAA smooths the meshes' and lines'
edges and the legend's discs are images with soft edges. A guard that the pictures did not come
out jagged: a jagged edge has only the two colours it separates, a smoothed one blends them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dolfinx_nnqem.io import vtk_scene


def _pixels(path: Path) -> np.ndarray:
    """The RGB pixels of the PNG file ``path`` (rows from the top), through VTK's reader."""
    from vtkmodules.vtkIOImage import vtkPNGReader

    reader = vtkPNGReader()
    reader.SetFileName(str(path))
    reader.Update()
    image = reader.GetOutput()
    width, height, _ = image.GetDimensions()
    values = vtk_scene.vtk_modules().vtk_to_numpy(image.GetPointData().GetScalars())
    return values.reshape(height, width, -1)[::-1, :, :3].astype(int)


def _blended(pixels: np.ndarray, colour: str, background: str = "white") -> int:
    """How many pixels lie strictly between ``colour`` and ``background`` (a blend of the two,
    at least 10 % from either end)."""
    ink, paper = (np.round(255 * np.asarray(vtk_scene.rgb(c))) for c in (colour, background))
    span = ink - paper
    weight = ((pixels - paper) * span).sum(axis=2) / (span * span).sum()  # where along paper → ink
    off_line = np.abs(pixels - (paper + weight[..., None] * span)).max(axis=2)
    return int(((weight > 0.1) & (weight < 0.9) & (off_line < 12)).sum())


@pytest.fixture
def renders():
    from dolfinx_nnqem import pyvista_compat

    if pyvista_compat.vtk_render_problem() is not None:
        pytest.skip("VTK cannot render in this process")


def test_a_sloping_line_is_drawn_with_smoothed_edges(tmp_path, renders):
    """The plastic zone's outline is a wide line: drawn sloping across the picture, its edges blend
    into the background along the whole line, not only at a few pixels."""
    scene = vtk_scene.Scene((300, 200))
    try:
        scene.add_mesh("line", vtk_scene.line_data(np.array([[0.0, 0.0, 0.0], [1.0, 0.3, 0.0]])),
                       colour="darkorange", line_width=4)
        scene.view_vector((0.0, 0.0, 1.0), viewup=(0.0, 1.0, 0.0))
        scene.screenshot(tmp_path / "line.png")
    finally:
        scene.close()
    pixels = _pixels(tmp_path / "line.png")
    inked = int((np.abs(pixels - 255).max(axis=2) > 0).sum())
    blended = _blended(pixels, "darkorange")
    print(f"\n  line: {inked} pixels drawn, {blended} of them a blend of orange and white")
    assert inked > 500 and blended > 0.15 * inked


def test_the_legend_discs_have_soft_edges(tmp_path, renders):
    """The legend is drawn after the scene's FXAA pass: its discs are images whose edge pixels blend
    the disc's colour into the legend's background (where VTK draws a legend's images quietly)."""
    from dolfinx_nnqem.pyvista_compat import legend_takes_images

    version = vtk_scene.vtk_modules().vtkVersion.GetVTKVersion()
    if not legend_takes_images(version):
        pytest.skip(f"VTK {version} prints a line for every legend entry drawn as an image: polygon discs there")
    disc = vtk_scene.vtk_modules().vtk_to_numpy(vtk_scene.legend_disc("crimson").GetPointData().GetScalars())
    alpha = disc[:, 3]
    assert alpha.max() == 255 and alpha.min() == 0 and ((alpha > 0) & (alpha < 255)).any()
    scene = vtk_scene.Scene((400, 300))
    try:
        scene.add_mesh("points", vtk_scene.point_data(np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]])),
                       colour="crimson", label="slip (2)")
        scene.add_legend(size=(0.4, 0.2), background="white")
        scene.view_vector((0.0, 0.0, 1.0), viewup=(0.0, 1.0, 0.0))
        scene.screenshot(tmp_path / "legend.png")
    finally:
        scene.close()
    legend = _pixels(tmp_path / "legend.png")[-int(0.25 * 300):]  # the legend's rows
    inked = np.flatnonzero(np.abs(legend - 255).max(axis=(0, 2)) > 0)  # its columns with ink
    gap = np.flatnonzero(np.diff(inked) > 1)
    disc = legend[:, inked[0]: inked[gap[0]] + 1]  # the first run of inked columns: the disc
    full = int((np.abs(disc - np.round(255 * np.asarray(vtk_scene.rgb("crimson")))).max(axis=2) < 12).sum())
    blended = _blended(disc, "crimson")
    print(f"\n  legend disc: {full} pixels of its colour, {blended} blended into the background")
    assert full > 10 and blended > 0.15 * full  # a disc of 17 pixels: 230 inside, 53 around
