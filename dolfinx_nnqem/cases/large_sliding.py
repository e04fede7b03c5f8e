"""Large-sliding verification problems (issue 27): a sphere slid over a block, a block slid over another.

* :func:`sliding_sphere`: the issue's set-up. A frictionless (by default) rigid sphere of radius
  0.6 is pressed 0.01 into an elastic unit cube (n × n × n hexahedra, bottom clamped) at
  x = ``start`` over ℓ ≤ ¼, then moved along x to ``end``; with ``end = start`` it is a press made
  in place.
* :func:`sliding_blocks`: an upper block (6 × 2 × 6, the node-to-surface slave) pressed 0.01 onto
  a lower one (4 × 2 × 4, the master, bottom clamped) by its top over ℓ ≤ ¼, then slid along x by
  ``slide`` (0.4: 1.6 master facets; part of the upper block then overhangs and its pairs go);
  ``offset`` moves the upper block's mesh along x before anything is solved (a press in place).

* :func:`sliding_patch`: the contact patch test after a slide: a block under a uniform pressure
  slid 2.4 facets along a much stiffer one, dual mortar in the current geometry, frictionless.
* :func:`long_slide`: a short block (0.25 long, 40 × 4 × 3 hexahedra, the slave) pressed 0.002
  onto a long one (2 long, 16 × 2 × 2, the master, bottom clamped) by its top over ℓ ≤ 0.1, then
  slid 1.0 along x: four times its own length, eight master facets; u_z = 0 on the z faces;
  the long block of the slider's material or another (:data:`LONG_SLIDE_STIFF_MASTER`).
* :func:`ironing`: a rigid cylinder (R = 0.5, axis along z) pressed ``depth`` into an elastoplastic
  strip (2 × 0.5 × 0.25, nx × nx/4 × 2 hexahedra, bottom clamped, u_z = 0 on the z faces) over
  ℓ ≤ 0.2, then dragged 1.0 along x (8 facets at nx = 16) with friction: an ironing-type problem.

:func:`obstacle_force` and :func:`slave_force` give the resultant contact force on the block.
"""

from __future__ import annotations

from dolfinx_nnqem import compat  # noqa: I001  (first: loads MPI/PETSc for the PyPI wheel)

from dataclasses import replace

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.contact.obstacles import Cylinder, RigidObstacle, Sphere
from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, PiecewiseLinearPath, Pressure
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.cases.geometries import build_block_stack

__all__ = ["LONG_SLIDE_PRESSED_AT", "LONG_SLIDE_STIFF_MASTER", "ironing", "long_slide", "obstacle_force", "slave_force", "sliding_blocks", "sliding_patch", "sliding_sphere"]

RADIUS = 0.6
DEPTH = 0.01
PRESSED_AT = 0.25  #: the load factor at which the press ends and the slide begins
MATERIAL = VonMises(E=1.0e3, nu=0.3)


def sliding_sphere(n: int, *, start: float = 0.3, end: float = 0.7, geometry: str = "current",
                   law: str = "alart-curnier", mu_f: float = 0.0, comm: MPI.Comm = MPI.COMM_WORLD,
                   shape: str = "sphere", degree: int = 1, ny: int | None = None,
                   cell_type: str = "hexahedron") -> ContactProblem:
    """The issue's sliding sphere on an n³ unit cube (module docstring); ``shape="cylinder"``: a
    cylinder of the same radius with its axis along z instead; ``degree``: of the displacements
    (2: Q2 hexahedra or P2 tetrahedra, every node of the top face a slave node); ``ny``: the layers of
    cells along y (default n); ``cell_type``: "hexahedron" or "tetrahedron" (``build_block_stack``)."""
    mesh, ct, ft = build_block_stack(comm, 1.0, 1.0, [1.0], [(n, n if ny is None else ny, n)], cell_type=cell_type)
    path = PiecewiseLinearPath([[0.0, 0.0, 0.0, 0.0], [PRESSED_AT, 0.0, -DEPTH, 0.0], [1.0, end - start, -DEPTH, 0.0]])
    centre = (start, 1.0 + RADIUS, 0.5)
    obstacle: RigidObstacle
    if shape == "sphere":
        obstacle = Sphere(centre=centre, radius=RADIUS, motion=path)
    else:
        obstacle = Cylinder(point=centre, axis=(0.0, 0.0, 1.0), radius=RADIUS, motion=path)
    return ContactProblem(mesh, ct, ft, materials=MATERIAL, dirichlet=[Dirichlet(T.bottom(1))], degree=degree,
                          contact=Contact(obstacle, T.top(1), mu_f=mu_f, law=law, geometry=geometry))


def _press(load_factor: float) -> float:
    return min(1.0, load_factor / PRESSED_AT)


def _slide(load_factor: float) -> float:
    return max(0.0, (load_factor - PRESSED_AT) / (1.0 - PRESSED_AT))


def sliding_blocks(*, slide: float = 0.4, offset: float = 0.0, geometry: str = "current", law: str = "alart-curnier",
                   mu_f: float = 0.0, discretisation: str = "node-to-surface",
                   comm: MPI.Comm = MPI.COMM_WORLD, degree: int = 1, cell_type: str = "hexahedron",
                   divisions: tuple[tuple[int, int, int], tuple[int, int, int]] = ((4, 2, 4), (6, 2, 6)),
                   depth: float = DEPTH) -> ContactProblem:
    """The upper block pressed ``depth`` and slid ``slide`` over the lower one, node-to-surface or mortar
    (module docstring); ``degree`` of the displacements (2: Q2 hexahedra or P2 tetrahedra), ``cell_type``
    ("hexahedron" or "tetrahedron") and the ``divisions`` of the lower and upper blocks (``build_block_stack``)."""
    mesh, ct, ft = build_block_stack(comm, 1.0, 1.0, [0.5, 0.5], list(divisions), cell_type=cell_type)
    if offset:
        nodes = np.unique(compat.geometry_dofmap(mesh)[ct.indices[ct.values == T.body(2)]])
        mesh.geometry.x[nodes, 0] += offset
    dirichlet = [Dirichlet(T.bottom(1)), Dirichlet(T.top(2), -depth, [1], amplitude=_press),
                 Dirichlet(T.top(2), slide, [0], amplitude=_slide), Dirichlet(T.top(2), 0.0, [2])]
    return ContactProblem(mesh, ct, ft, materials=MATERIAL, dirichlet=dirichlet, degree=degree,
                          contact=Contact(T.top(1), T.bottom(2), mu_f=mu_f, law=law, discretisation=discretisation,
                                          geometry=geometry))


PATCH_PRESSURE = 1.0
STRUCTURED = False
PATCH_UPPER = VonMises(E=1.0e3, nu=0.0)
PATCH_LOWER = VonMises(E=1.0e12, nu=0.0)


def sliding_patch(*, slide: float = 0.6, cell_type: str = "hexahedron", law: str = "alart-curnier",
                  geometry: str = "current", comm: MPI.Comm = MPI.COMM_WORLD) -> ContactProblem:
    """The patch test after a slide (module docstring): dual mortar, frictionless.

    A block (x in [0.25, 0.75], 6 × 2 × 3 divisions, the mortar slave) under a uniform pressure
    p is slid by ``slide`` along a long block (x in [0, 2], 8 × 1 × 1, facets 0.25 long: 0.6 is 2.4
    facets), ν = 0 in both, the long block 10⁹ times stiffer and clamped at its bottom. The upper
    block is held by contact in y, by its top's prescribed x-displacement in x and by its z = 0
    face in z; with ν = 0 none of these disturbs the uniform state σ = −p e_y⊗e_y, which an exact
    discretisation transmits at every position: p at every slave node. The lower block, loaded on
    part of its top, deflects by about p/E_lower × its size, 10⁻⁹ of the upper block's strain.
    """
    mesh, ct, ft = build_block_stack(comm, 2.0, 0.25, [0.25, 0.25], [(8, 1, 1), (6, 2, 3)], cell_type=cell_type,
                                   structured=STRUCTURED)
    nodes = np.unique(compat.geometry_dofmap(mesh)[ct.indices[ct.values == T.body(2)]])
    mesh.geometry.x[nodes, 0] = 0.25 + 0.25 * mesh.geometry.x[nodes, 0]  # x in [0.25, 0.75]
    dirichlet = [Dirichlet(T.bottom(1)), Dirichlet(T.top(2), slide, [0], amplitude=_slide),
                 Dirichlet(T.zmin(2), 0.0, [2])]
    return ContactProblem(mesh, ct, ft, materials={1: PATCH_LOWER, 2: PATCH_UPPER}, dirichlet=dirichlet,
                          tractions=[Pressure(T.top(2), PATCH_PRESSURE, amplitude=_press)],
                          contact=Contact(T.top(1), T.bottom(2), mu_f=0.0, law=law, discretisation="mortar",
                                          geometry=geometry))


LONG_SLIDE_PRESSED_AT = 0.1
LONG_SLIDE_STIFF_MASTER = VonMises(E=1.0e8, nu=0.3)
"""A long block 10⁵ times stiffer than the slider: its surface stays flat to about 10⁻⁸ of the
slider's strain, so the resultant of a slip on the Coulomb cone is μ_f times the normal force
(with the slider's own modulus the deformed master's normals tilt, and the resultant differs)."""


def long_slide(*, law: str = "alart-curnier", mu_f: float = 0.3, discretisation: str = "node-to-surface",
               master: VonMises | None = None, comm: MPI.Comm = MPI.COMM_WORLD) -> ContactProblem:
    """A short block slid four times its length over a long one (module docstring); ``master``:
    the long block's material (default the short block's)."""
    mesh, ct, ft = build_block_stack(comm, 2.0, 0.25, [0.25, 0.25], [(16, 2, 2), (40, 4, 3)])
    nodes = np.unique(compat.geometry_dofmap(mesh)[ct.indices[ct.values == T.body(2)]])
    mesh.geometry.x[nodes, 0] = 0.25 + 0.125 * mesh.geometry.x[nodes, 0]  # the short block: x in [0.25, 0.5]

    def press(load_factor: float) -> float:
        return min(1.0, load_factor / LONG_SLIDE_PRESSED_AT)

    def slide(load_factor: float) -> float:
        return max(0.0, (load_factor - LONG_SLIDE_PRESSED_AT) / (1.0 - LONG_SLIDE_PRESSED_AT))

    dirichlet = [Dirichlet(T.bottom(1)), Dirichlet(T.top(2), -0.002, [1], amplitude=press),
                 Dirichlet(T.top(2), 1.0, [0], amplitude=slide)]
    dirichlet += [Dirichlet(face(k), 0.0, [2]) for k in (1, 2) for face in (T.zmin, T.zmax)]
    return ContactProblem(mesh, ct, ft, materials={1: master or MATERIAL, 2: MATERIAL}, dirichlet=dirichlet,
                          contact=Contact(T.top(1), T.bottom(2), mu_f=mu_f, law=law, discretisation=discretisation,
                                          geometry="current"))


IRONING_MATERIAL = VonMises(E=1.0e3, nu=0.3, sigma_y0=5.0, H=500.0)
IRONING_PRESSED_AT = 0.2


def ironing(nx: int = 16, *, law: str = "alart-curnier", mu_f: float = 0.1, depth: float = 0.005,
            geometry: str | None = "current", kinematics: str = "small",
            comm: MPI.Comm = MPI.COMM_WORLD) -> ContactProblem:
    """A cylinder pressed into an elastoplastic strip and dragged along it (module docstring);
    ``geometry=None``: the contact's default geometry; ``kinematics="finite"``: the strip at finite
    strain (a deep ironing, ``demos/deep_ironing.py``)."""
    mesh, ct, ft = build_block_stack(comm, 2.0, 0.25, [0.5], [(nx, max(nx // 4, 1), 2)])
    path = PiecewiseLinearPath([[0.0, 0.0, 0.0, 0.0], [IRONING_PRESSED_AT, 0.0, -depth, 0.0], [1.0, 1.0, -depth, 0.0]])
    radius = 0.5
    punch = Cylinder(point=(0.5, 0.5 + radius, 0.0), axis=(0.0, 0.0, 1.0), radius=radius, motion=path)
    dirichlet = [Dirichlet(T.bottom(1)), Dirichlet(T.zmin(1), 0.0, [2]), Dirichlet(T.zmax(1), 0.0, [2])]
    contact = Contact(punch, T.top(1), mu_f=mu_f, law=law)
    if geometry is not None:
        contact = replace(contact, geometry=geometry)
    return ContactProblem(mesh, ct, ft, materials=IRONING_MATERIAL, dirichlet=dirichlet, contact=contact,
                          kinematics=kinematics)


def obstacle_force(problem: ContactProblem) -> np.ndarray:
    """The obstacle's force on the block (3,), summed over the ranks."""
    assert problem.contact is not None  # these cases have contact
    (force,) = problem.contact.obstacle_reactions().values()
    return force


def slave_force(problem: ContactProblem) -> np.ndarray:
    """The contact force on the slave body, Σ R_jᵀ λ_j (3,), summed over the ranks."""
    model = problem.contact
    assert model is not None  # these cases have contact
    local = np.einsum("nji,nj->i", model.R, model.force())
    return np.asarray(model.comm.allreduce(local, op=MPI.SUM))
