r"""A rigid sphere pressed into a tetrahedral block: Hertz (elastic) and deal.II's step-42 (elastoplastic).

Both are quarter models on tetrahedra (:func:`~dolfinx_nnqem.cases.geometries.build_block_stack`,
structured: every face triangulated alike), the meshes adaptive refinement starts from
(:mod:`dolfinx_nnqem.estimates.adaptive`).

**Hertz** (:func:`hertz_tetrahedra_problem`): a rigid sphere of radius R pressed by δ = a²/R on an
elastic block [0, L]² × [0, L] (L = 6 a), its bottom clamped, x = 0 and z = 0 symmetry planes,
the sphere's axis the y axis; Hertz's a and p0 at the computed force F (1/E* = (1 − ν²)/E).

**step-42** (:func:`step42_problem`): the unit cube of deal.II's step-42 (Frohne, Heister, Bangerth
2016) with its top pressed by a rigid ball of radius 0.6 centred 0.59 above the top's centre (an
indentation of 0.01), the bottom clamped, the sides held in their plane (u_x = u_z = 0, free
vertically; y is the vertical here), E = 200 000, ν = 0.3. Step-42's material is a projection of
the stress deviator onto the ball ‖dev σ‖ ≤ σ0 = 400 with hardening parameter γ = 0.01, solved in
one load step (a deformation, Hencky-type, law); here it is incremental von Mises plasticity with
the same yield surface, σ_y0 = √(3/2) σ0, and the linear hardening whose plastic deviatoric
stiffness is γ times the elastic one, H = 3μγ / (1 − γ), along a load path of a few increments: the
same yield and hardening under the monotone, nearly proportional loading of the indentation, not the
same law. The quarter x, z ∈ [0.5, 1] is modelled (symmetry planes x = 0.5 and z = 0.5); the contact
force is 4 × the quarter's.
"""

from __future__ import annotations

import math

from mpi4py import MPI

from dolfinx_nnqem.contact.obstacles import Sphere
from dolfinx_nnqem.material.von_mises import VonMises
from dolfinx_nnqem.problem.contact_problem import Contact, ContactProblem, Dirichlet
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.cases.geometries import build_block_stack

__all__ = ["HERTZ_MATERIAL", "STEP42_MATERIAL", "STEP42_PUBLISHED", "hertz_tetrahedra_problem", "step42_problem"]

HERTZ_MATERIAL = VonMises(E=210e3, nu=0.3)  # MPa, mm (elastic)
R_HERTZ = 50.0
A_HERTZ = 1.0
BLOCK_HERTZ = 6.0

_E, _NU, _SIGMA0, _GAMMA = 200000.0, 0.3, 400.0, 0.01
_MU = _E / (2 * (1 + _NU))
STEP42_MATERIAL = VonMises(E=_E, nu=_NU, sigma_y0=math.sqrt(1.5) * _SIGMA0, H=3 * _MU * _GAMMA / (1 - _GAMMA))
STEP42_PUBLISHED = ((0, 512, 2187, 37.3058), (3, 14652, 52497, 56.794))
"""(cycle, active cells, dofs, contact force) of step-42's published adaptive run with
``p1_adaptive.prm`` (degree 1, 3 initial global refinements, Kelly indicator, 30 % of the
cells refined and 3 % coarsened per cycle; its results page prints cycles 0 and 3 of the whole cube)."""


def hertz_tetrahedra_problem(divisions: int = 6, comm: MPI.Comm = MPI.COMM_WORLD, *, R: float = R_HERTZ,
                             a: float = A_HERTZ, block: float = BLOCK_HERTZ) -> ContactProblem:
    """The Hertz quarter model on ``divisions`` × ``divisions`` × ``divisions`` cubes of tetrahedra
    (see the module)."""
    mesh, cell_tags, facet_tags = build_block_stack(comm, block, block, [block], [(divisions,) * 3],
                                                    cell_type="tetrahedron", structured=True)
    sphere = Sphere(centre=(0.0, block + R, 0.0), radius=R, motion=(0.0, -a * a / R, 0.0))
    return ContactProblem(mesh, cell_tags, facet_tags, materials=HERTZ_MATERIAL,
                          dirichlet=[Dirichlet(T.bottom(1)), Dirichlet(T.xmin(1), 0.0, [0]),
                                     Dirichlet(T.zmin(1), 0.0, [2])],
                          contact=Contact(sphere, T.top(1), mu_f=0.0, name="sphere"))


def step42_problem(divisions: int = 4, comm: MPI.Comm = MPI.COMM_WORLD) -> ContactProblem:
    """The step-42 quarter model on ``divisions`` × ``divisions`` × ``divisions`` cubes of tetrahedra
    (see the module)."""
    mesh, cell_tags, facet_tags = build_block_stack(comm, 0.5, 0.5, [1.0], [(divisions,) * 3], y0=0.0,
                                                    cell_type="tetrahedron", structured=True)
    mesh.geometry.x[:, 0] += 0.5  # x, z in [0.5, 1]: the quarter next to the cube's corner (1, 1)
    mesh.geometry.x[:, 2] += 0.5
    ball = Sphere(centre=(0.5, 1.6, 0.5), radius=0.6, motion=(0.0, -0.01, 0.0))  # touching at ℓ = 0
    return ContactProblem(mesh, cell_tags, facet_tags, materials=STEP42_MATERIAL,
                          dirichlet=[Dirichlet(T.bottom(1)),
                                     Dirichlet(T.xmin(1), 0.0, [0]), Dirichlet(T.zmin(1), 0.0, [2]),  # symmetry
                                     Dirichlet(T.xmax(1), 0.0, [0, 2]), Dirichlet(T.zmax(1), 0.0, [0, 2])],
                          contact=Contact(ball, T.top(1), mu_f=0.0, name="ball"))
