r"""The limit load of a rigid strip footing on a weightless soil, in plane strain.

A half model: the soil occupies x ∈ [0, ``width``], y ∈ [−``depth``, 0] (in footing half widths
b = 1), one element thick in z with u_z = 0 on both z faces (plane strain); the footing, a rigid
flat body of half width b, is pressed into the top over x ∈ [0, b]. x = 0 is the symmetry plane
(u_x = 0), the far side x = ``width`` and the bottom clamped. The footing is

* ``route = "contact"`` (the default): a rigid plane obstacle (:class:`~dolfinx_nnqem.contact.obstacles.Plane`)
  moved down, in contact with the footing's part of the top only (the tag :data:`FOOTING`; the
  rest of the top, :data:`FREE`, is a free surface): frictionless for a ``"smooth"`` footing,
  with friction :data:`ROUGH_MU_F` (enough to stick everywhere) for a ``"rough"`` one;
* ``route = "prescribed"``: the classical alternative without contact, u_y = −d on the footing's
  nodes (and u_x = 0 for a rough footing).

The settlement d rises linearly with ℓ to ``settlement`` (displacement control: past the limit
load no equilibrium exists under a prescribed force). :func:`footing_pressure` gives the mean
pressure q = F / (b t) under the footing (t the slab's thickness).

Soils (:func:`von_mises_soil`, :func:`drucker_prager_soil`): cohesion c = :data:`COHESION`,
E = :data:`E_SOIL`, ν = 0.3, perfectly plastic (E/c = 10⁶: the limit load of small-strain perfect
plasticity does not depend on E, the settlement that reaches it scales with c/E, and a stiff
soil keeps the strains at the footing's edge, where the settlement is a jump of the
displacement, within the independent check's small-strain limits); von Mises with σ_y = √3 c (its
cohesion in plane strain: the shear strength), Drucker–Prager matched to Mohr–Coulomb in plane
strain with associated flow (ψ = φ). The limit pressures (weightless soil, no surcharge) are
Prandtl's q = (2 + π) c and Prandtl–Reissner's q = c N_c, N_c = (N_q − 1) cot φ,
N_q = e^{π tan φ} tan²(45° + φ/2) (:func:`prandtl_reissner`): the same for a smooth and a rough
footing when the soil is weightless. ``docs/verification-materials.md`` gives the measured
limit loads, the meshes and the rule that reads the plateau (:func:`limit_pressure`).

The mesh (:func:`footing_mesh`): elements of size b/``n`` over x ≤ 2b and y ≥ −2b, growing by
:data:`GROWTH` beyond. 27-node hexahedra (Q2) with 2 × 2 × 2 Gauss points (reduced integration,
the default): trilinear elements, and Q2 with its full 3 × 3 × 3 points, lock under the
isochoric flow of von Mises plasticity and overestimate the limit load. The reduced rule leaves
each horizontal row of elements a zero-energy mode (the u_y of its mid-height nodes); a support
at the row's end that holds u_y removes it, hence the clamped far side (with a roller there the
stiffness matrix of n = 1 has 15 zero eigenvalues, with the clamp none).
"""

from __future__ import annotations

import math

import dolfinx
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.contact.obstacles import Plane
from dolfinx_nnqem.material import DruckerPrager, VonMises
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet
from dolfinx_nnqem.cases.geometries import graded_nodes
from dolfinx_nnqem.problem.meshing import MeshAndTags

__all__ = ["BOTTOM", "COHESION", "E_SOIL", "FAR", "FOOTING", "FREE", "GROWTH", "NU_SOIL", "ROUGH_MU_F", "SOIL",
           "SYMMETRY", "ZFACES", "drucker_prager_soil", "footing_mesh", "footing_pressure", "limit_pressure",
           "prandtl", "prandtl_reissner", "problem_file_text", "strip_footing_problem", "von_mises_soil"]

SOIL = 1  #: cell tag
BOTTOM, SYMMETRY, FAR, ZFACES, FOOTING, FREE = 1, 2, 3, 4, 5, 6  #: facet tags
COHESION, E_SOIL, NU_SOIL = 1.0e4, 1.0e10, 0.3  # Pa; E/c = 10⁶: see the module docstring
ROUGH_MU_F = 5.0  # no pair of a rough footing slips (checked in the tests)
GROWTH = 1.2  # element sizes grow by this factor away from the footing
FINE = 2.0  # the fine zone: x ≤ FINE and y ≥ −FINE, in half widths


def prandtl(cohesion: float = COHESION) -> float:
    """Prandtl's limit pressure (2 + π) c of a strip footing on a weightless von Mises / Tresca soil."""
    return (2.0 + math.pi) * cohesion


def prandtl_reissner(friction_angle: float, cohesion: float = COHESION) -> float:
    """c N_c, N_c = (N_q − 1) cot φ, N_q = e^{π tan φ} tan²(45° + φ/2) (φ in degrees, > 0)."""
    phi = math.radians(friction_angle)
    n_q = math.exp(math.pi * math.tan(phi)) * math.tan(math.pi / 4 + phi / 2) ** 2
    return cohesion * (n_q - 1.0) / math.tan(phi)


def von_mises_soil(cohesion: float = COHESION) -> VonMises:
    """Perfectly plastic von Mises with σ_y = √3 c: its shear strength in plane strain is c."""
    return VonMises(E=E_SOIL, nu=NU_SOIL, sigma_y0=math.sqrt(3.0) * cohesion, H=0.0)


def drucker_prager_soil(friction_angle: float, cohesion: float = COHESION,
                        dilatancy_angle: float | None = None) -> DruckerPrager:
    """Perfectly plastic Drucker–Prager matched to Mohr–Coulomb in plane strain (associated by default)."""
    return DruckerPrager(E=E_SOIL, nu=NU_SOIL, cohesion=cohesion, friction_angle=friction_angle,
                         dilatancy_angle=dilatancy_angle, match="plane-strain")


def footing_mesh(comm: MPI.Comm = MPI.COMM_WORLD, n: int = 4, *, width: float = 20.0,
                 depth: float = 12.0) -> MeshAndTags:
    """The slab of hexahedra (module docstring), tagged: cells :data:`SOIL`; facets :data:`BOTTOM`,
    :data:`SYMMETRY` (x = 0), :data:`FAR` (x = width), :data:`ZFACES`, :data:`FOOTING` (top, x ≤ 1)
    and :data:`FREE` (top, x ≥ 1). One element thick, of the fine size 1/``n``."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"n = {n!r}; expected an integer >= 1 (elements per footing half width)")
    h = 1.0 / n
    xs = graded_nodes(h, round(FINE * n), width, GROWTH)
    ys = -graded_nodes(h, round(FINE * n), depth, GROWTH)[::-1]
    nx, ny = len(xs) - 1, len(ys) - 1
    mesh = dolfinx.mesh.create_box(comm, [np.zeros(3), np.array([nx, ny, 1.0])], [nx, ny, 1],
                                   dolfinx.mesh.CellType.hexahedron)
    x = mesh.geometry.x
    index = np.rint(x).astype(np.int64)
    x[:, 0], x[:, 1], x[:, 2] = xs[index[:, 0]], ys[index[:, 1]], h * index[:, 2]
    tdim = mesh.topology.dim
    cells = np.arange(mesh.topology.index_map(tdim).size_local + mesh.topology.index_map(tdim).num_ghosts,
                      dtype=np.int32)
    cell_tags = dolfinx.mesh.meshtags(mesh, tdim, cells, np.full(len(cells), SOIL, dtype=np.int32))
    return MeshAndTags(mesh, cell_tags, _facet_tags(mesh, xs[-1], ys[0], h))


def _facet_tags(mesh, width: float, bottom: float, thickness: float):
    """The boundary facets of the slab by where they lie (:func:`footing_mesh`)."""
    fdim = mesh.topology.dim - 1
    tol = 1e-9 * width
    where = [(BOTTOM, lambda x: np.isclose(x[1], bottom, atol=tol)),
             (SYMMETRY, lambda x: np.isclose(x[0], 0.0, atol=tol)),
             (FAR, lambda x: np.isclose(x[0], width, atol=tol)),
             (ZFACES, lambda x: np.isclose(x[2], 0.0, atol=tol)),  # every vertex of a facet on z = 0
             (ZFACES, lambda x: np.isclose(x[2], thickness, atol=tol)),  # or on z = t (not either: all are)
             (FOOTING, lambda x: np.isclose(x[1], 0.0, atol=tol) & (x[0] <= 1.0 + tol)),
             (FREE, lambda x: np.isclose(x[1], 0.0, atol=tol) & (x[0] >= 1.0 - tol))]
    facets, values = [], []
    for tag, marker in where:
        found = dolfinx.mesh.locate_entities_boundary(mesh, fdim, marker)
        facets.append(found)
        values.append(np.full(len(found), tag, dtype=np.int32))
    facets_all, values_all = np.concatenate(facets), np.concatenate(values)
    order = np.argsort(facets_all, kind="stable")
    return dolfinx.mesh.meshtags(mesh, fdim, facets_all[order].astype(np.int32), values_all[order])


def strip_footing_problem(material: VonMises | DruckerPrager | None = None, n: int = 4, *, footing: str = "smooth",
                          route: str = "contact", settlement: float = 0.05, degree: int = 2,
                          quadrature_degree: int = 2, law: str = "alart-curnier",
                          comm: MPI.Comm = MPI.COMM_WORLD, mesh_and_tags: MeshAndTags | None = None) -> ContactProblem:
    """The half model (module docstring) on :func:`footing_mesh` ``(comm, n)``.

    Parameters
    ----------
    material
        The soil (default :func:`von_mises_soil`).
    footing
        ``"smooth"`` or ``"rough"``.
    route
        ``"contact"`` (a rigid plane obstacle on the footing's facets) or ``"prescribed"``
        (the footing's nodes moved).
    settlement
        The footing's travel at ℓ = 1, in half widths.
    degree, quadrature_degree
        The displacement's degree and the Gauss rule's: the default, Q2 with 2 × 2 × 2 points
        (reduced integration), does not lock; Q2 with its full 3 × 3 × 3 points
        (``quadrature_degree = 4``) does.
    """
    if footing not in ("smooth", "rough"):
        raise ValueError(f"footing = {footing!r}; expected 'smooth' or 'rough'")
    if route not in ("contact", "prescribed"):
        raise ValueError(f"route = {route!r}; expected 'contact' or 'prescribed'")
    mesh, cell_tags, facet_tags = mesh_and_tags or footing_mesh(comm, n)
    # the far side clamped, not a roller: with 2 × 2 × 2 Gauss points a row of Q2 elements has a
    # zero-energy mode in u_y that only a u_y support at the row's end removes (module docstring)
    dirichlet = [Dirichlet(BOTTOM), Dirichlet(SYMMETRY, 0.0, [0]), Dirichlet(FAR), Dirichlet(ZFACES, 0.0, [2])]
    contact = None
    if route == "prescribed":
        moved = Dirichlet(FOOTING, [0.0, -settlement], [0, 1]) if footing == "rough" else \
            Dirichlet(FOOTING, -settlement, [1])
        dirichlet.insert(0, moved)  # first: the footing's reaction gets the dofs it shares with other faces
    else:
        plane = Plane(point=(0.0, 0.0, 0.0), normal=(0.0, -1.0, 0.0), motion=(0.0, -settlement, 0.0))
        contact = Contact(plane, FOOTING, mu_f=ROUGH_MU_F if footing == "rough" else 0.0, law=law)
    return ContactProblem(mesh, cell_tags, facet_tags, materials=material or von_mises_soil(),
                          dirichlet=dirichlet, contact=contact, degree=degree,
                          quadrature_degree=quadrature_degree)


def problem_file_text(soil: VonMises | DruckerPrager, mesh: str, *, footing: str = "smooth", settlement: float = 0.05,
                      increments: int = 20, folder: str = "results/strip_footing") -> str:
    """The contact route as a problem file (``dolfinx-nnqem run``) on ``mesh``, an XDMF file of
    :func:`footing_mesh` (:func:`~dolfinx_nnqem.problem.meshing.write_xdmf`): Q2 with 2 × 2 × 2 Gauss points."""
    if isinstance(soil, DruckerPrager):
        material = ['model = "drucker-prager"', f"cohesion = {soil.cohesion!r}",
                    f"friction_angle = {soil.friction_angle!r}", f"dilatancy_angle = {soil.dilatancy_angle!r}",
                    f'match = "{soil.match}"']
    else:
        material = [f"sigma_y0 = {soil.sigma_y0!r}", "H = 0.0"]
    lines = ["# A rigid strip footing on a weightless soil (dolfinx_nnqem.cases.strip_footing), plane strain",
             "[mesh]", f'file = "{mesh}"', "degree = 2", "quadrature_degree = 2", "",
             f"[materials.{SOIL}]", f"E = {soil.E!r}", f"nu = {soil.nu!r}", *material, "",
             "[contact]", f"surface2 = {FOOTING}", f"mu_f = {ROUGH_MU_F if footing == 'rough' else 0.0!r}",
             'name = "footing"', "[contact.obstacle]", 'type = "plane"', "point = [0.0, 0.0, 0.0]",
             "normal = [0.0, -1.0, 0.0]", f"motion = [0.0, {-settlement!r}, 0.0]", ""]
    for tag, components in ((BOTTOM, None), (SYMMETRY, [0]), (FAR, None), (ZFACES, [2])):
        lines += ["[[dirichlet]]", f"tag = {tag}"] + ([] if components is None else
                                                       ["value = 0.0", f"components = {components}"])
    lines += ["", "[solver]", 'method = "monolithic"', f"increments = {increments}", "rtol = 1e-11", "",
              "[output]", f'folder = "{folder}"', "pictures = false"]
    return "\n".join(lines) + "\n"


def footing_pressure(problem: ContactProblem) -> float:
    """The mean pressure q = F_y / (b t) under the footing (Pa; collective): the obstacle's force,
    or the prescribed nodes' reaction."""
    if problem.contact is not None:
        (force,) = problem.contact.obstacle_reactions().values()
    else:
        from dolfinx_nnqem.io.results import reactions

        force = reactions(problem)[FOOTING]
    thickness = problem.comm.allreduce(float(problem.mesh.geometry.x[:, 2].max()), op=MPI.MAX)
    return -float(force[1]) / thickness


def limit_pressure(settlements: np.ndarray, pressures: np.ndarray, window: float = 0.2) -> tuple[float, float]:
    """The plateau of a load–settlement curve: (q at the last increment, its relative rise over
    the last ``window`` of the settlement). The rise says whether the curve has flattened: the
    limit pressure is read where it is below a stated bound (``docs/verification-materials.md``)."""
    d, q = np.asarray(settlements, dtype=float), np.asarray(pressures, dtype=float)
    earlier = np.interp(d[-1] * (1.0 - window), d, q)
    return float(q[-1]), float((q[-1] - earlier) / q[-1])
