"""The scalable benchmark family: two elastoplastic blocks pressed together, then dragged.

Body 1 (x, z ∈ [0, 1], y ∈ [0, 0.5], bottom clamped) carries body 2 (y ∈ [0.5, 1]). A
pressure of 1.5 σ_y0 on body 2's top rises over ℓ ∈ [0, ½] and yields both blocks; over
ℓ ∈ [½, 1] body 2's top is dragged by 2 mm in x (its x displacement prescribed): the blocks
yield again in shear and, with μ_f = 0.1, pairs start to slip near the end; u_z = 0 on the z
faces of both blocks. Body 2 is held in y by contact alone, which is
what makes the family a test of the iterative solver (its stiffness matrix alone is singular).

Level k has 4k × 2k × 4k hexahedra per block and (4k + 1)² node-to-node pairs:

    level   1     2      4       8        10       17
    dofs    450   2 430  15 606   111 078  211 806  999 810

With ``n2``, body 2 has n2 × 2k × n2 hexahedra instead (a non-matching interface when
n2 ≠ 4k; the contact is then discretised by dual mortar, body 2 the slave when it is the finer).
"""

from __future__ import annotations

import math

from mpi4py import MPI

from dolfinx_nnqem.material.von_mises import VonMises
from dolfinx_nnqem.cases.geometries import StackedBlocksTags as T
from dolfinx_nnqem.cases.geometries import build_stacked_blocks
from dolfinx_nnqem.problem.contact_problem import Contact, ContactProblem, Dirichlet, Pressure

MATERIAL = VonMises(E=2.0e10, nu=0.2, sigma_y0=2.0e7, H=2.0e9)
PRESSURE = 3.0e7
DRAG = 2.0e-3


def num_dofs(level: int) -> int:
    """Displacement dofs of level ``level`` (two blocks of (4k+1)(2k+1)(4k+1) nodes)."""
    return 2 * 3 * (4 * level + 1) * (2 * level + 1) * (4 * level + 1)


def pressure_amplitude(load_factor: float) -> float:
    """The pressure rises over the first half of the load path, then stays."""
    return min(2.0 * load_factor, 1.0)


def drag_amplitude(load_factor: float) -> float:
    """The drag starts at half the load path."""
    return max(2.0 * load_factor - 1.0, 0.0)


def pressed_blocks_problem(level: int, comm: MPI.Comm = MPI.COMM_WORLD, mu_f: float = 0.1, *,
                           n2: int | None = None, discretisation: str = "auto",
                           body1_stiffer: float = 1.0, law: str = "alart-curnier") -> ContactProblem:
    """The problem of level ``level`` (see the module docstring).

    Parameters
    ----------
    level
        Body 1 has 4 level × 2 level × 4 level hexahedra (so has body 2 by default).
    comm
        Communicator of the mesh.
    mu_f
        Friction coefficient.
    n2
        Body 2's element count in x and z (default ``4 level``: matching interface meshes).
    discretisation
        The contact's discretisation (see :class:`~dolfinx_nnqem.problem.contact_problem.Contact`); ``"auto"``
        takes node-to-node on matching meshes, mortar otherwise.
    body1_stiffer
        Body 1's E, σ_y0 and H are this many times body 2's (the same strains, stresses this many
        times larger): a stiffness contrast across the interface.
    law
        The pair law (``"alart-curnier"`` or ``"polar"``).
    """
    if isinstance(level, bool) or not isinstance(level, int) or level < 1:
        raise ValueError(f"level = {level!r}; expected an integer >= 1")
    if n2 is not None and (isinstance(n2, bool) or not isinstance(n2, int) or n2 < 1):
        raise ValueError(f"n2 = {n2!r}; expected an integer >= 1")
    if not (isinstance(body1_stiffer, (int, float)) and math.isfinite(body1_stiffer) and body1_stiffer > 0):
        raise ValueError(f"body1_stiffer = {body1_stiffer!r}; expected a positive number")
    body1 = VonMises(E=MATERIAL.E * body1_stiffer, nu=MATERIAL.nu, sigma_y0=MATERIAL.sigma_y0 * body1_stiffer,
                     H=MATERIAL.H * body1_stiffer)
    n = 4 * level
    mesh, cell_tags, facet_tags = build_stacked_blocks(comm, 1.0, 0.5, 0.5, 1.0, n, 2 * level, 2 * level, n,
                                                       nx2=n2, nz2=n2)
    return ContactProblem(
        mesh, cell_tags, facet_tags, materials={T.BODY1: body1, T.BODY2: MATERIAL},
        dirichlet=[
            Dirichlet(T.BOTTOM),
            Dirichlet(T.TOP, DRAG, [0], amplitude=drag_amplitude),
            Dirichlet(T.BODY1_ZMIN, 0.0, [2]), Dirichlet(T.BODY1_ZMAX, 0.0, [2]),
            Dirichlet(T.BODY2_ZMIN, 0.0, [2]), Dirichlet(T.BODY2_ZMAX, 0.0, [2]),
        ],
        tractions=[Pressure(T.TOP, PRESSURE, amplitude=pressure_amplitude)],
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=mu_f, discretisation=discretisation, law=law),
    )
