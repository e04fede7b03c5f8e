"""The contact interfaces of a problem: the contact model on the problem's bodies, with the moduli
that size each interface's r and the error that names bodies meshed as one."""

from __future__ import annotations

from collections.abc import Sequence

import dolfinx.fem as fem
import dolfinx.mesh
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.contact.model import ContactModel
from dolfinx_nnqem.contact.obstacles import RigidObstacle
from dolfinx_nnqem.contact.specification import Contact
from dolfinx_nnqem.contact.surfaces import ContactPairError
from dolfinx_nnqem.problem.bodies import tags_sharing_nodes

__all__ = ["bodies_meshed_together", "build_contact_model", "interface_moduli", "largest_modulus"]


def largest_modulus(E: fem.Function) -> float:
    """E_max: the largest Young's modulus of the mesh over all ranks (collective; 0 without cells)."""
    return E.function_space.mesh.comm.allreduce(float(np.max(E.x.array, initial=0.0)), op=MPI.MAX)


def interface_moduli(E: fem.Function, facet_tags: dolfinx.mesh.MeshTags | None, contacts: Sequence[Contact],
                     default: float) -> list[float]:
    """Per interface, the smallest Young's modulus of the cells beside its deformable surfaces:
    the softer body's (collective). ``default`` where no rank has a tagged facet (the pair
    search then names the empty surface).

    The default r = E h is the contact stiffness of a surface node; a pair's stiffness is the
    softer side's, so E is that side's. With the stiffer side's, r overweights the gap in the
    laws by the stiffness ratio (10⁴ stalled the Newton iterations at the slide onset of a
    block on a stiffer one, :func:`~dolfinx_nnqem.cases.large_sliding.long_slide`).

    Parameters
    ----------
    E
        The cell-wise (DG 0) Young's modulus.
    facet_tags
        The facet tags naming the contact surfaces.
    contacts
        The interfaces.
    default
        The modulus of an interface without tagged facets.
    """
    if facet_tags is None:
        return [default] * len(contacts)
    mesh = E.function_space.mesh
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    f2c = mesh.topology.connectivity(tdim - 1, tdim)
    E_cells = E.x.array[E.function_space.dofmap.list[:, 0]]
    moduli = []
    for contact in contacts:
        local = np.inf
        for tag in contact.deformable_surfaces:
            for facet in facet_tags.find(tag):
                local = min(local, float(np.min(E_cells[f2c.links(facet)])))
        smallest = mesh.comm.allreduce(local, op=MPI.MIN)
        moduli.append(smallest if np.isfinite(smallest) else default)
    return moduli


def bodies_meshed_together(V: fem.FunctionSpace, cell_tags: dolfinx.mesh.MeshTags | None,
                           facet_tags: dolfinx.mesh.MeshTags | None,
                           contacts: Sequence[Contact]) -> ContactPairError | None:
    """The error naming cell tags that share nodes across a contact surface, or None.

    A contact between volumes meshed together (common nodes) used to end with a symptom
    ("no facet is tagged 22": both surface tags sat on the same interior facets and one was
    lost) instead of the cause (issue 31)."""
    surfaces = [c.surface2 for c in contacts]
    surfaces += [c.surface1 for c in contacts if not isinstance(c.surface1, RigidObstacle)]
    shared = tags_sharing_nodes(V, cell_tags, facet_tags, surfaces)
    if not shared:
        return None
    pairs = "; ".join(f"the cells tagged {a} and {b} share {n} nodes" for a, b, n in shared)
    return ContactPairError(
        f"{pairs}: those bodies are meshed as one, so the contact surfaces between them (facet tags "
        f"{sorted(set(int(t) for t in surfaces))}) lie inside the mesh, not on a boundary. Bodies in contact "
        "must be meshed without common nodes (in gmsh: do not fragment or glue their volumes)")


def build_contact_model(V: fem.FunctionSpace, cell_tags: dolfinx.mesh.MeshTags | None,
                        facet_tags: dolfinx.mesh.MeshTags | None, contacts: Sequence[Contact],
                        moduli: list[float], h: float, constrained_flags: PETSc.Vec) -> ContactModel:
    """The contact model of ``contacts`` (collective; see :class:`~dolfinx_nnqem.contact.model.ContactModel`).

    Raises
    ------
    ContactPairError
        If the pairs cannot be found; naming the bodies meshed as one where that is the cause.
    """
    try:
        return ContactModel(V, facet_tags, contacts, E=moduli, h=h, constrained_dofs=constrained_flags)
    except ContactPairError as error:  # the cause may be bodies meshed as one: say so
        raise bodies_meshed_together(V, cell_tags, facet_tags, contacts) or error
