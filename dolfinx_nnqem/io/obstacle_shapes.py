"""The rigid obstacles in the pictures: each drawn as a translucent surface where it stands.

A run's ``summary.json`` holds, per interface with a rigid obstacle (:mod:`dolfinx_nnqem.contact.obstacles`),
the obstacle's placement and its translation d(ℓ) at the last converged increment
(:func:`obstacle_records`). The pictures of the deformed shape draw each obstacle moved by the
same scale as the bodies' displacements (``scale`` × d(ℓ)): at the true scale (finite strain)
where it stands, magnified with the displacements otherwise, so that a punch sits in the dent it
made. The surfaces are clipped to a box around the drawn bodies (:func:`view_box`): a plane or a
cylinder is infinite, and a large sphere would hide the bodies.

This module imports neither DOLFINx nor MPI at its top (a picture worker draws with it); the
surfaces are VTK's own PolyData (:mod:`dolfinx_nnqem.io.vtk_scene`), made by VTK's sources.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

import dolfinx_nnqem.io.vtk_scene as vtk_scene

if TYPE_CHECKING:
    from dolfinx_nnqem.io.vtk_scene import Scene

__all__ = ["OBSTACLE_COLOUR", "OBSTACLE_OPACITY", "add_obstacles", "obstacle_records", "obstacle_surfaces",
           "view_box"]

OBSTACLE_COLOUR = "steelblue"
OBSTACLE_OPACITY = 0.35
MARGIN = 0.25
"""How far the view box reaches beyond the drawn bodies, as a fraction of their largest extent."""
RESOLUTION = 64
"""Facets around a sphere or cylinder."""


def obstacle_records(problem, load_factor: float) -> dict[str, dict[str, Any]]:
    """Per interface with a rigid obstacle (by its name): the obstacle's ``type`` (``plane``,
    ``sphere``, ``cylinder``), its placement parameters (``point``, ``normal``, ``centre``,
    ``radius``, ``axis``) and its ``displacement`` d(ℓ) at ``load_factor``: plain JSON data for
    ``summary.json``. Empty without contact or obstacles. Not collective."""
    if not problem.has_contact:
        return {}
    from dolfinx_nnqem.contact.obstacles import OBSTACLES

    kinds = {cls: name for name, cls in OBSTACLES.items()}
    records = {}
    for interface in problem.contact.interfaces:
        obstacle = interface.contact.obstacle
        if obstacle is None:
            continue
        record: dict[str, Any] = {"type": kinds[type(obstacle)]}
        for field in dataclasses.fields(obstacle):
            if field.name not in ("motion", "amplitude"):
                value = getattr(obstacle, field.name)
                record[field.name] = float(value) if np.ndim(value) == 0 else np.asarray(value, float).tolist()
        record["displacement"] = obstacle.displacement(load_factor).tolist()
        records[interface.contact.label] = record
    return records


def view_box(points: np.ndarray, margin: float = MARGIN) -> tuple[float, float, float, float, float, float]:
    """The bounds (x_min, x_max, y_min, y_max, z_min, z_max) of ``points`` widened on every side
    by ``margin`` × their largest extent."""
    low, high = points.min(axis=0), points.max(axis=0)
    pad = margin * max(float(np.ptp(points, axis=0).max()), 1e-300)
    return (low[0] - pad, high[0] + pad, low[1] - pad, high[1] + pad, low[2] - pad, high[2] + pad)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _turned(source: Any, axis_from: tuple[float, float, float], axis_to: np.ndarray, centre: np.ndarray) -> Any:
    """The output of the VTK ``source`` (made about the origin) turned so that its ``axis_from``
    points along ``axis_to``, then moved to ``centre``, in triangles (their normals left to the
    scene, which shades it smoothly)."""
    vtk = vtk_scene.vtk_modules()
    source.Update()
    data = source.GetOutput()
    a, b = _unit(axis_from), _unit(axis_to)
    # Rodrigues' rotation taking a to b (a half turn about any axis normal to a where b = -a)
    v, c = np.cross(a, b), float(a @ b)
    if c < -1.0 + 1e-12:
        normal = _unit(np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0]))
        rotation = 2.0 * np.outer(normal, normal) - np.eye(3)
    else:
        k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
        rotation = np.eye(3) + k + k @ k / (1.0 + c)
    points = vtk.vtk_to_numpy(data.GetPoints().GetData()) @ rotation.T + centre
    triangles = vtk.vtkTriangleFilter()
    triangles.SetInputData(data)
    triangles.Update()
    surface = triangles.GetOutput()
    surface.GetPointData().Initialize()  # the source's normals point the unturned way
    moved = vtk.vtkPoints()
    moved.SetData(vtk.numpy_to_vtk(np.ascontiguousarray(points), deep=True))
    surface.SetPoints(moved)
    return surface


def _surface(record: Mapping[str, Any], shift: np.ndarray, box: tuple[float, ...]) -> Any:
    """The obstacle's whole surface (a VTK PolyData of triangles) moved by ``shift``, large enough
    to cross ``box``."""
    vtk = vtk_scene.vtk_modules()
    centre = 0.5 * np.array(box[::2]) + 0.5 * np.array(box[1::2])
    reach = 2.0 * float(np.linalg.norm(np.array(box[1::2]) - np.array(box[::2])))  # beyond the box from anywhere in it
    kind = record["type"]
    if kind == "sphere":
        sphere = vtk.vtkSphereSource()
        sphere.SetRadius(float(record["radius"]))
        sphere.SetThetaResolution(RESOLUTION)
        sphere.SetPhiResolution(RESOLUTION)
        return _turned(sphere, (0.0, 0.0, 1.0), np.array([0.0, 0.0, 1.0]), np.asarray(record["centre"], float) + shift)
    if kind == "cylinder":
        axis = _unit(record["axis"])
        point = np.asarray(record["point"], float) + shift
        # along its axis the cylinder spans the box (a hair less: its capped ends stay inside the
        # clip), so that a view along the axis shows its end face, not the inside of a tube
        corners = np.array(np.meshgrid(box[0:2], box[2:4], box[4:6])).reshape(3, -1).T
        along = (corners - point) @ axis
        middle = point + 0.5 * (along.min() + along.max()) * axis
        cylinder = vtk.vtkCylinderSource()  # about the y axis
        cylinder.SetRadius(float(record["radius"]))
        cylinder.SetHeight(0.999 * float(np.ptp(along)))
        cylinder.SetResolution(RESOLUTION)
        cylinder.CappingOn()
        return _turned(cylinder, (0.0, 1.0, 0.0), axis, middle)
    if kind == "plane":
        normal = _unit(record["normal"])
        point = np.asarray(record["point"], float) + shift
        foot = centre - ((centre - point) @ normal) * normal  # the plane's point nearest the box's centre
        plane = vtk.vtkPlaneSource()  # a square of side reach about the origin, normal to z
        plane.SetOrigin(-reach / 2, -reach / 2, 0.0)
        plane.SetPoint1(reach / 2, -reach / 2, 0.0)
        plane.SetPoint2(-reach / 2, reach / 2, 0.0)
        plane.SetResolution(8, 8)
        return _turned(plane, (0.0, 0.0, 1.0), normal, foot)
    raise ValueError(f"obstacle type {kind!r}: expected 'plane', 'sphere' or 'cylinder'")


def obstacle_surfaces(records: Mapping[str, Mapping[str, Any]], box: tuple[float, ...],
                      scale: float = 1.0) -> dict[str, Any]:
    """Each obstacle of ``records`` (:func:`obstacle_records`) at its placement moved by ``scale`` ×
    its displacement, clipped to ``box`` (a VTK PolyData of triangles); an obstacle wholly outside
    the box is left out."""
    surfaces = {}
    for name, record in records.items():
        shift = scale * np.asarray(record.get("displacement", (0.0, 0.0, 0.0)), dtype=float)
        clipped = _clipped(_surface(record, shift, box), box)
        if clipped.GetNumberOfCells():
            surfaces[name] = clipped
    return surfaces


def _clipped(surface: Any, box: tuple[float, ...]) -> Any:
    """The part of ``surface`` inside ``box``, cut exactly along its six faces: one
    vtkClipPolyData per face, each with the face's plane (a linear function: a cut along a
    triangle's edge is exact, where one cut by the box's function, piecewise linear, lost most of
    a cylinder's end face; and ``clip_box``'s vtkBoxClipDataSet left a plane's triangles whole,
    outside the box, with Debian's VTK 9.3)."""
    vtk = vtk_scene.vtk_modules()
    data = surface
    for axis in range(3):
        for side, bound in ((-1.0, box[2 * axis]), (1.0, box[2 * axis + 1])):
            face = vtk.vtkPlane()
            face.SetOrigin(*[bound if k == axis else 0.0 for k in range(3)])
            face.SetNormal(*[side if k == axis else 0.0 for k in range(3)])  # outward
            clip = vtk.vtkClipPolyData()
            clip.SetInputData(data)
            clip.SetClipFunction(face)
            clip.InsideOutOn()  # keep the side the normal points away from: inside the box
            clip.Update()
            data = clip.GetOutput()
    return data


def add_obstacles(scene: Scene, records: Mapping[str, Mapping[str, Any]], box: tuple[float, ...],
                  scale: float = 1.0) -> list[str]:
    """Draw the obstacles of ``records`` into ``scene`` (a :class:`~dolfinx_nnqem.io.vtk_scene.Scene`:
    translucent, smoothly shaded, clipped to ``box``, labelled for the legend, actor
    ``obstacle:NAME``); returns the names drawn."""
    surfaces = obstacle_surfaces(records, box, scale)
    for name, surface in surfaces.items():
        scene.add_mesh(f"obstacle:{name}", surface, colour=OBSTACLE_COLOUR, opacity=OBSTACLE_OPACITY, smooth=True,
                       label=f"{name} (rigid)")
    return list(surfaces)
