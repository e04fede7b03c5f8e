r"""A rigid sphere pressed into an elastoplastic block and lifted off, once or several times.

The verification case of the hardening laws against CalculiX 2.20
(``benchmarks/calculix_sphere_press.py``, ``docs/verification-materials.md``). A quarter model:
the block occupies x, z ∈ [0, ``block``], y ∈ [−``block``, 0] (the planes x = 0 and z = 0 are
symmetry planes, the bottom is clamped), graded towards the point x = z = 0 of its top
(:func:`~dolfinx_nnqem.cases.geometries.build_graded_block`: hexahedra of size h over
x, z ≤ 1.5 and 1.0 below the top, growing by 1.3 beyond). A frictionless rigid sphere of radius
:data:`R_SPHERE` touches the top at the origin and is pressed :data:`DEPTH` down, then lifted back
to where it started, ``cycles`` times, at a constant rate in ℓ (each press and each lift takes
1/(2 cycles) of the load path).

The block is annealed copper (E = 120 GPa, ν = 0.34) with one of three hardening laws
(:data:`MATERIALS`):

* ``"table"``: isotropic hardening by the table :data:`TABLE` (σ_y against p, CalculiX's
  ``*PLASTIC`` order), eight rows with a kink every few 10⁻⁴ of p;
* ``"kinematic"``: Prager's linear kinematic hardening, C = :data:`C_KINEMATIC`, on the constant
  yield stress of the table's first row (CalculiX's ``HARDENING=KINEMATIC``);
* ``"combined"``: isotropic hardening by the gentler table :data:`TABLE_COMBINED` and the same
  back-stress (CalculiX's ``HARDENING=COMBINED`` with ``*CYCLIC HARDENING``).

Units: mm, N, MPa. The sphere's radius is large (a contact radius of about 1 mm against
R = 400 mm) and the yield stress low (σ_y0/E = 2.75 · 10⁻⁴): the strains and rotations stay of
order 10⁻³, where a small-strain model and CalculiX's finite-strain one (which it needs for
kinematic hardening) give the same answer (``docs/verification-materials.md`` measures it).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.contact.obstacles import Sphere
from dolfinx_nnqem.io.results import node_blocks_at_points, values_at_blocks
from dolfinx_nnqem.material import BackStress, TabulatedHardening, VonMises
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, PiecewiseLinearPath
from dolfinx_nnqem.cases.geometries import BlockStackTags as T
from dolfinx_nnqem.cases.geometries import build_graded_block

__all__ = ["C_KINEMATIC", "DEPTH", "E", "FINE_DEPTH", "FINE_WIDTH", "MATERIALS", "NU", "R_SPHERE", "SYMMETRY",
           "TABLE", "TABLE_COMBINED", "indentation_force", "press_path", "problem_file_text", "sphere_press_problem", "surface_depth"]

E, NU = 120e3, 0.34  # MPa: annealed copper
#: (σ_y, p) rows in CalculiX's order: σ_y0 = 33 MPa, hardening steeply at first as annealed copper does
TABLE = ((33.0, 0.0), (45.0, 2e-4), (56.0, 5e-4), (70.0, 1e-3), (88.0, 2e-3), (115.0, 5e-3),
         (140.0, 1e-2), (180.0, 3e-2))
C_KINEMATIC = 20e3  # MPa: Prager's modulus, the back-stress reaches C p (uniaxial)
#: the isotropic part of the combined law: a gentler table, the back-stress gives the rest
TABLE_COMBINED = ((33.0, 0.0), (36.0, 2e-4), (39.0, 5e-4), (42.0, 1e-3), (45.0, 2e-3), (50.0, 5e-3), (55.0, 1e-2))
MATERIALS = {
    "table": VonMises(E=E, nu=NU, hardening=TabulatedHardening(TABLE)),
    "kinematic": VonMises(E=E, nu=NU, sigma_y0=TABLE[0][0], kinematic=(BackStress(C_KINEMATIC, 0.0),)),
    "combined": VonMises(E=E, nu=NU, hardening=TabulatedHardening(TABLE_COMBINED),
                         kinematic=(BackStress(C_KINEMATIC, 0.0),)),
}
R_SPHERE = 400.0  # mm
DEPTH = 0.005  # mm: the sphere's travel below first touch
FINE_WIDTH, FINE_DEPTH, BLOCK = 1.5, 1.0, 10.0  # mm: the fine zone (elements of size h) and the block
SYMMETRY = 4  # quarter model: the whole sphere's force is 4 × the model's


def press_path(cycles: int = 1, depth: float = DEPTH) -> PiecewiseLinearPath:
    """The sphere's translation: down by ``depth`` and back to 0, ``cycles`` times over ℓ ∈ [0, 1]."""
    if isinstance(cycles, bool) or not isinstance(cycles, int) or cycles < 1:
        raise ValueError(f"cycles = {cycles!r}; expected an integer >= 1")
    legs = 2 * cycles
    return PiecewiseLinearPath([[k / legs, 0.0, -depth if k % 2 else 0.0, 0.0] for k in range(legs + 1)])


def sphere_press_problem(h: float = 1.0 / 6.0, material: str = "table", cycles: int = 1, *,
                         depth: float = DEPTH, law: str = "alart-curnier", comm: MPI.Comm = MPI.COMM_WORLD,
                         msh_file=None) -> ContactProblem:
    """The quarter model (module docstring) with elements of size ``h`` (mm) at the contact.

    ``material`` is a key of :data:`MATERIALS`; ``msh_file`` also writes the mesh for a problem
    file (:func:`~dolfinx_nnqem.cases.geometries.build_graded_block`).
    """
    if material not in MATERIALS:
        raise ValueError(f"material = {material!r}; expected one of {list(MATERIALS)}")
    path = press_path(cycles, depth)  # refuses bad cycles before the mesh is built
    mesh, cell_tags, facet_tags = build_graded_block(comm, h, fine_width=FINE_WIDTH, fine_depth=FINE_DEPTH,
                                                     block=BLOCK, msh_file=msh_file)
    sphere = Sphere(centre=(0.0, R_SPHERE, 0.0), radius=R_SPHERE, motion=path)
    dirichlet = [Dirichlet(T.bottom(1)), Dirichlet(T.xmin(1), 0.0, [0]), Dirichlet(T.zmin(1), 0.0, [2])]
    return ContactProblem(mesh, cell_tags, facet_tags, materials=MATERIALS[material], dirichlet=dirichlet,
                          contact=Contact(sphere, T.top(1), mu_f=0.0, law=law))


def indentation_force(problem: ContactProblem) -> float:
    """The sphere's force on the block, downwards (N; the whole sphere: 4 × the quarter model's)."""
    assert problem.contact is not None
    (force,) = problem.contact.obstacle_reactions().values()
    return -SYMMETRY * float(force[1])


def surface_depth(problem: ContactProblem) -> float:
    """The depth −u_y of the block's top at the first point of contact x = z = 0 (mm; collective)."""
    block = node_blocks_at_points(problem, np.zeros((1, 3)))
    return -float(values_at_blocks(problem, block)[0, 1])


def problem_file_text(material: str = "table", cycles: int = 1, increments: int = 10, *, mesh: str = "sphere_press.msh",
                      depth: float = DEPTH, folder: str = "results/sphere_press") -> str:
    """The case as a problem file (``dolfinx-nnqem run``): the mesh ``mesh`` written by
    ``sphere_press_problem(..., msh_file=mesh)``, ``increments`` equal increments per press and per lift."""
    m = MATERIALS[material]
    lines = ["# A rigid sphere pressed into an annealed-copper block and lifted off (dolfinx_nnqem.cases.sphere_press)",
             "[mesh]", f'file = "{mesh}"', "", f"[materials.{T.body(1)}]", f"E = {m.E!r}", f"nu = {m.nu!r}"]
    if isinstance(m.hardening, TabulatedHardening):
        rows = m.hardening.table
        lines += ['hardening = "table"', "table = [" + ", ".join(f"[{s!r}, {p!r}]" for s, p in rows) + "]"]
    else:
        lines += [f"sigma_y0 = {m.sigma_y0!r}"]
    if m.kinematic:
        lines += ["kinematic = [" + ", ".join(f"[{b.C!r}, {b.gamma!r}]" for b in m.kinematic) + "]"]
    path = press_path(cycles, depth).points
    lines += ["", "[[contact]]", 'name = "sphere"', f"surface2 = {T.top(1)}", "mu_f = 0.0", "[contact.obstacle]",
              'type = "sphere"', f"centre = [0.0, {R_SPHERE!r}, 0.0]", f"radius = {R_SPHERE!r}",
              "motion = [" + ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in path) + "]", "",
              "[[dirichlet]]", f"tag = {T.bottom(1)}",
              "[[dirichlet]]", f"tag = {T.xmin(1)}", "value = 0.0", "components = [0]",
              "[[dirichlet]]", f"tag = {T.zmin(1)}", "value = 0.0", "components = [2]", "",
              "[solver]", 'method = "monolithic"', f"increments = {2 * cycles * increments}", "rtol = 1e-10", "",
              "[output]", f'folder = "{folder}"', "pictures = false"]
    return "\n".join(lines) + "\n"
