r"""Hertz contact on non-matching meshes: an elastic sphere pressed on an elastic block.

A quarter of a steel hemisphere (radius R, E = 210 GPa, ν = 0.3) rests with its pole on the top
of a quarter aluminium block (E = 70 GPa, ν = 0.33, half width and height 10 a); each body is
meshed with tetrahedra on its own (:func:`~dolfinx_nnqem.cases.geometries.build_sphere_on_block`), so
the contact surfaces do not match and the interface is discretised by dual mortar, the sphere's
cap as slave. The block's bottom is clamped, the planes x = 0 and z = 0 are symmetry planes, and
the sphere's flat equatorial face is pushed down by the approach δ (u_y = −δ, the other
components free): no body is held by contact alone. Frictionless by default, as Hertz assumes
for dissimilar materials.

Hertz's solution for two elastic bodies, 1/E* = (1 − ν1²)/E1 + (1 − ν2²)/E2, is compared at the
computed force F (the sum of the pair forces, × 4): a = (3FR/(4E*))^(1/3), p0 = 3F/(2πa²).
Units: mm, N, MPa. ``docs/nonmatching-hertz.md`` gives the measured figures.
"""

from __future__ import annotations

from typing import Any

from mpi4py import MPI

from dolfinx_nnqem.cases.hertz import NodalLoads, effective_modulus, fit_hertz_profile, measure_hertz
from dolfinx_nnqem.contact.surface_pairs import SurfacePairs
from dolfinx_nnqem.material.von_mises import VonMises
from dolfinx_nnqem.cases.geometries import SphereOnBlockTags as T
from dolfinx_nnqem.cases.geometries import build_sphere_on_block
from dolfinx_nnqem.problem.contact_problem import Contact, ContactProblem, Dirichlet
from dolfinx_nnqem.io.results import equilibrium_check, pair_table
from dolfinx_nnqem.solvers.contract import contact_model

__all__ = ["A_NOMINAL", "APPROACH", "BLOCK", "BLOCK_MATERIAL", "E_STAR", "R_SPHERE", "SPHERE_MATERIAL",
           "measure_sphere_on_block", "sphere_on_block_problem"]

R_SPHERE = 20.0  # mm
A_NOMINAL = 1.0  # mm: about the contact radius the approach gives
APPROACH = 0.046  # mm: the equatorial face's prescribed approach (a ≈ A_NOMINAL)
BLOCK = 10.0  # mm: the block's half width and height, 10 a: a half-space to about a per cent
SPHERE_MATERIAL = VonMises(E=210e3, nu=0.3)  # steel (σ_y0 = inf: elastic)
BLOCK_MATERIAL = VonMises(E=70e3, nu=0.33)  # aluminium
E_STAR = effective_modulus(BLOCK_MATERIAL.E, BLOCK_MATERIAL.nu, SPHERE_MATERIAL.E, SPHERE_MATERIAL.nu)
SYMMETRY = 4  # quarter model


def sphere_on_block_problem(h: float, comm: MPI.Comm = MPI.COMM_WORLD, *, mu_f: float = 0.0,
                            law: str = "alart-curnier", approach: float = APPROACH, R: float = R_SPHERE,
                            block: float = BLOCK, **mesh_options: Any) -> ContactProblem:
    """The quarter model with the element size ``h`` at the contact (see the module).

    ``mesh_options`` go to :func:`~dolfinx_nnqem.cases.geometries.build_sphere_on_block` (``h_max``,
    ``growth``, ``fine_radius``, ``contact_radius``); the defaults suit R = 20 a.
    """
    mesh, cell_tags, facet_tags = build_sphere_on_block(comm, R, block, h, **mesh_options)
    return ContactProblem(
        mesh, cell_tags, facet_tags, materials={T.BLOCK: BLOCK_MATERIAL, T.SPHERE: SPHERE_MATERIAL},
        dirichlet=[
            Dirichlet(T.BOTTOM),
            Dirichlet(T.LOAD, -approach, [1]),
            Dirichlet(T.BLOCK_XMIN, 0.0, [0]), Dirichlet(T.SPHERE_XMIN, 0.0, [0]),  # symmetry x = 0
            Dirichlet(T.BLOCK_ZMIN, 0.0, [2]), Dirichlet(T.SPHERE_ZMIN, 0.0, [2]),  # symmetry z = 0
        ],
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=mu_f, law=law, discretisation="mortar"),
    )


def measure_sphere_on_block(problem: ContactProblem, R: float = R_SPHERE) -> dict:
    """F, a and p0 against Hertz, from the mortar pair table (collective).

    Keys of :func:`~dolfinx_nnqem.cases.hertz.measure_hertz` (``a``: the radius of the Hertz pressure
    for the measured F whose nodal forces best fit the pair forces; ``p0``: the centre node's
    pressure), plus ``a_fit``/``p0_fit`` and their errors (both parameters fitted, F free: p0
    measured with every pair, not the centre node alone), ``pairs``, ``slave`` (the slave
    surface's tag), ``imbalance`` (global equilibrium) and ``table`` (the pair table).
    """
    table = pair_table(problem)
    pairs = contact_model(problem).interfaces[0].pairs
    if not isinstance(pairs, SurfacePairs):
        raise TypeError(f"measure_sphere_on_block: the pairs of a slave surface against a master one, got {type(pairs).__name__}")
    slave = pairs.slave
    loads = NodalLoads(problem, slave, table["slave_block"])
    forces = table["pressure"] * table["area"]  # the normal pair forces p_n
    m = measure_hertz(loads, forces, table["position_b"], table["state"] != 0, SYMMETRY, R, E_STAR)
    a_fit, p0_fit = fit_hertz_profile(loads, forces, m["a_hertz"])
    m.update(a_fit=a_fit, p0_fit=p0_fit, err_a_fit=a_fit / m["a_hertz"] - 1.0,
             err_p0_fit=p0_fit / m["p0_hertz"] - 1.0, pairs=len(forces), slave=slave,
             imbalance=equilibrium_check(problem)["global_imbalance"], table=table)
    return m
