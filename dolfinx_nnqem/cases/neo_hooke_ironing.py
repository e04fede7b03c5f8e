r"""Ironing with Neo-Hookean bodies at finite strain: a stiff die pressed into a soft slab and dragged.

Issue 41's third benchmark asks for a 3D ironing of Neo-Hookean bodies in the manner of Puso and
Laursen (2004) and Popp et al. (2010). Their dimensions, materials and force histories were not
found in any source reachable here, so this is the package's own set-up of the same kind, made to
be run by every method and checked against itself (``benchmarks/neo_hooke_ironing.py``,
``docs/verification-materials.md``):

* the slab: 2 × 0.25 × 0.25 (x, y up, z), 16r × 2r × 2r hexahedra, bottom clamped, Neo-Hooke
  E = :data:`E_SLAB`, ν = 0.3;
* the die: a block 0.25 × 0.25 × 0.25 over x ∈ [0.25, 0.5] on the slab's top, 4r × 2r × 2r
  hexahedra (so its facets are half the slab's), Neo-Hooke with ten times the slab's stiffness;
* its top is pressed ``depth`` down (0.05: a fifth of the slab's thickness) over
  ℓ ≤ :data:`PRESSED_AT`, then moved 1.0 along x (four times its own length, eight of the slab's
  facets at r = 1) with Coulomb friction μ_f between die and slab; u_z = 0 on the four z faces
  (a slice of a wide die and slab);
* one interface, the die's bottom the slave side (its finer facets), ``geometry = "current"``:
  the pairs follow the bodies at finite strain, ``kinematics = "finite"``.

The measures (:func:`die_force`): the contact force on the die, Σ R_jᵀ λ_j, along x (the drag)
and y (the press) at every increment. Sharp die edges, a slab sheared by a fifth of its thickness
and friction at the Coulomb limit make it a hard large-deformation case: no closed form exists,
so the benchmark compares the methods, the laws and the discretisations with each other and the
meshes r = 1, 2, 3 with each other. The mesh: :func:`~dolfinx_nnqem.cases.geometries.build_die_on_slab`;
the problem at r = 1 as a problem file: ``demos/neo_hooke_ironing.toml`` (``meshes/die_on_slab.msh``).
"""

from __future__ import annotations

from dolfinx_nnqem import compat  # noqa: I001  (first: loads MPI/PETSc for the PyPI wheel)

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.material import NeoHooke
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.cases.geometries import build_die_on_slab
from dolfinx_nnqem.cases.large_sliding import slave_force

__all__ = ["DEPTH", "E_DIE", "E_SLAB", "PRESSED_AT", "SLIDE", "die_force", "neo_hooke_ironing"]

E_SLAB = 1.0e3
E_DIE = 1.0e4
NU = 0.3
DEPTH = 0.05  #: the die's press below first touch: a fifth of the slab's thickness
SLIDE = 1.0  #: the die's travel along x after the press
PRESSED_AT = 0.2  #: the load factor at which the press ends and the drag begins
DIE_X = (0.25, 0.5)  #: where the die stands on the slab before the press


def _press(load_factor: float) -> float:
    return min(1.0, load_factor / PRESSED_AT)


def _drag(load_factor: float) -> float:
    return max(0.0, (load_factor - PRESSED_AT) / (1.0 - PRESSED_AT))


def neo_hooke_ironing(refine: int = 1, *, depth: float = DEPTH, law: str = "alart-curnier", mu_f: float = 0.3,
                      discretisation: str = "mortar", comm: MPI.Comm = MPI.COMM_WORLD) -> ContactProblem:
    """The Neo-Hookean ironing (module docstring) on the meshes of level ``refine`` (1, 2, 3, ...:
    the slab 16r × 2r × 2r hexahedra, the die 4r × 2r × 2r), the die pressed ``depth`` and dragged
    :data:`SLIDE`; ``discretisation``: "mortar" or "node-to-surface"."""
    if isinstance(refine, bool) or not isinstance(refine, int) or refine < 1:
        raise ValueError(f"neo_hooke_ironing: refine = {refine!r}; expected an integer >= 1")
    mesh, ct, ft = build_die_on_slab(comm, refine, DIE_X)  # also meshes/die_on_slab.msh at refine = 1
    dirichlet = [Dirichlet(T.bottom(1)), Dirichlet(T.top(2), -depth, [1], amplitude=_press),
                 Dirichlet(T.top(2), SLIDE, [0], amplitude=_drag)]
    dirichlet += [Dirichlet(face(body), 0.0, [2]) for body in (1, 2) for face in (T.zmin, T.zmax)]
    materials = {1: NeoHooke(E=E_SLAB, nu=NU), 2: NeoHooke(E=E_DIE, nu=NU)}
    contact = Contact(T.top(1), T.bottom(2), mu_f=mu_f, law=law, discretisation=discretisation, geometry="current",
                      slave=T.bottom(2))
    return ContactProblem(mesh, ct, ft, materials=materials, dirichlet=dirichlet, contact=contact,
                          kinematics="finite")


def die_force(problem: ContactProblem) -> np.ndarray:
    """The contact force on the die (the slave side), Σ R_jᵀ λ_j (3,), summed over the ranks."""
    return slave_force(problem)
