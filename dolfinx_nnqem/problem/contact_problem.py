"""The problem: mesh, tags, materials, supports, loads and contact — the one object every solver takes.

A user writes, in DOLFINx terms::

    problem = ContactProblem(
        mesh, cell_tags, facet_tags,
        materials={1: steel, 2: steel},
        dirichlet=[Dirichlet(11), Dirichlet(12)],
        tractions=[Traction(13, (1e5, -1e5, 0.5e5))],
        body_forces=[Gravity((0, -9.81, 0))],
        contact=Contact(surface1=21, surface2=22, mu_f=0.5),   # or a list of Contact
    )

All loads and prescribed displacements are multiplied by the load factor ℓ of the increment,
or by their own ``amplitude(ℓ)`` when one is given (e.g. a pressure held constant while a
drag grows); so is the motion of rigid obstacles.
The problem owns the displacement ``u``, the Gauss-point state, the contact model
(:class:`~dolfinx_nnqem.contact.model.ContactModel`: every interface, the pair unknowns z) and
the assembly of the pieces solvers combine: F_int(u), F_ext, K_t(u), K_e. It never solves
anything itself. Before any solve it checks that no body can move rigidly without resistance
(:mod:`dolfinx_nnqem.problem.bodies`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import dolfinx.fem as fem
import dolfinx.fem.petsc
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.problem.bodies import (check_rigid_modes, find_bodies, free_rigid_modes, friction_held_motions,
                                          tags_sharing_nodes)
from dolfinx_nnqem.contact.model import ContactModel
from dolfinx_nnqem.contact.specification import Contact
from dolfinx_nnqem.contact.surfaces import ContactPairError
from dolfinx_nnqem.contact.obstacles import Cylinder, Plane, Sphere  # noqa: F401  (the user's imports)
from dolfinx_nnqem.material.interface import GaussPointValues
from dolfinx_nnqem.material.state import material_state
from dolfinx_nnqem.problem.mesh_quality import check_cells
from dolfinx_nnqem.problem.validation import (check_cell_tag, check_components, check_magnitude, check_mesh,
                                              check_one_contact_per_pair)
from dolfinx_nnqem.numerics.linalg import vec_norm


# -- problem data ---------------------------------------------------------------------------
FORCE_FLOOR_STRAIN = 1e-6
"""The force scale F is never below the force this strain sets up over one cell face (E_max h²)."""


@dataclass(frozen=True)
class Dirichlet:
    """Prescribed displacement ``u_i = ℓ · value_i`` on the facets tagged ``tag``.

    ``components=None`` constrains all three components (``value`` a 3-vector or a scalar
    used for all); otherwise only the listed ones (``value`` one number per listed component).
    The default is a clamp (u = 0).
    """

    tag: int
    value: float | Sequence[float] = 0.0
    components: Sequence[int] | None = None
    amplitude: Callable[[float], float] | None = None  #: a(ℓ) replacing ℓ (non-proportional paths)


@dataclass(frozen=True)
class Traction:
    """Surface traction ``ℓ · value`` (Pa, global frame) on the facets tagged ``tag``."""

    tag: int
    value: Sequence[float]
    amplitude: Callable[[float], float] | None = None  #: a(ℓ) replacing ℓ


@dataclass(frozen=True)
class Pressure:
    """Pressure ``ℓ · p`` (Pa) on the facets tagged ``tag``: traction −p n (n the outward normal)."""

    tag: int
    p: float
    amplitude: Callable[[float], float] | None = None  #: a(ℓ) replacing ℓ


@dataclass(frozen=True)
class BodyForce:
    """Body force ``ℓ · value`` (N/m³) on the cells tagged ``cell_tag`` (all cells if None)."""

    value: Sequence[float]
    cell_tag: int | None = None
    amplitude: Callable[[float], float] | None = None  #: a(ℓ) replacing ℓ


@dataclass(frozen=True)
class Gravity:
    """Self-weight ``ℓ · ρ g`` with each body's density (from its material)."""

    g: Sequence[float] = (0.0, -9.81, 0.0)
    amplitude: Callable[[float], float] | None = None  #: a(ℓ) replacing ℓ


# -- the problem ------------------------------------------------------------------------------
@dataclass(frozen=True)
class ProblemDefinition:
    """What a :class:`ContactProblem` was built from, apart from its mesh: the same problem can be
    built again on another mesh or degree (``dolfinx_nnqem.estimates``: the enriched solve, adaptive
    refinement). Tags name the bodies and surfaces, so they carry over to a refined mesh."""

    materials: object
    dirichlet: tuple
    tractions: tuple
    body_forces: tuple
    contact: tuple
    degree: int
    quadrature_degree: int | None  #: as given (None: 2·degree)


class ContactProblem:
    """Quasi-static small-strain elastoplastic problem, with or without contact.

    Parameters
    ----------
    mesh, cell_tags, facet_tags
        A DOLFINx mesh holding all bodies (no shared nodes between bodies in contact) and its tags.
    materials
        One material or ``{cell_tag: material}`` (:mod:`dolfinx_nnqem.material`: ``VonMises``,
        ``Elastic``, ...); the bodies may have materials of different kinds.
    dirichlet, tractions, body_forces
        Supports and loads; all scaled by the load factor.
    contact
        A :class:`Contact`, a list of them (several interfaces, rigid obstacles), or None.
    degree
        Lagrange degree of the displacement: 1 or 2 (P2 tetrahedra, Q2 hexahedra: no locking in
        isochoric plastic flow, far better in bending; every node of a contact surface, vertex,
        edge or face node, gets a pair, see ``docs/theory.md``, "Quadratic facets"). Default: the
        mesh's geometry degree (1 for a first-order mesh, 2 for a second-order one).
    quadrature_degree
        Degree of the Gauss rule; default 2·degree (2×2×2 points per Q1 hexahedron, 3×3×3
        per Q2).

    Raises
    ------
    ValueError
        For unphysical or inconsistent data, inverted cells (the message names them;
        :mod:`~dolfinx_nnqem.problem.mesh_quality`), and when a body can move rigidly without
        resistance (no support and no contact against some rigid motion; the message names the
        body and the motion).
    """

    _h: float  # the mean cell size, computed once by characteristic_length

    def __init__(
        self,
        mesh: dolfinx.mesh.Mesh,
        cell_tags=None,
        facet_tags=None,
        *,
        materials,
        dirichlet: Sequence[Dirichlet] = (),
        tractions: Sequence[Traction | Pressure] = (),
        body_forces: Sequence[BodyForce | Gravity] = (),
        contact: Contact | Sequence[Contact] | None = None,
        degree: int | None = None,
        quadrature_degree: int | None = None,
    ):
        check_mesh(mesh)  # a 3D mesh of 3D cells, one cell type
        if degree is None:  # a second-order mesh (10-node tetrahedra, 27-node hexahedra): quadratic elements
            degree = 2 if compat.coordinate_element(mesh).degree >= 2 else 1
        if degree not in (1, 2):
            raise ValueError(f"degree = {degree!r}: the displacement is Lagrange of degree 1 or 2")
        contacts = [] if contact is None else ([contact] if isinstance(contact, Contact) else list(contact))
        for c in contacts:
            if not isinstance(c, Contact):
                raise TypeError(f"contact: {c!r} is not a Contact")
        self.definition = ProblemDefinition(materials, tuple(dirichlet), tuple(tractions), tuple(body_forces),
                                            tuple(contacts), degree, quadrature_degree)
        check_one_contact_per_pair(contacts)
        if quadrature_degree is None:
            quadrature_degree = 2 * degree  # 2×2×2 Gauss points for Q1, 3×3×3 for Q2
        # before anything is built on the mesh: an inverted cell is named as such, not by its symptoms
        self.mesh_quality = check_cells(mesh, cell_tags, quadrature_degree)
        """The shape check of every cell (:class:`~dolfinx_nnqem.problem.mesh_quality.CellQuality`)."""
        self.mesh, self.cell_tags, self.facet_tags = mesh, cell_tags, facet_tags
        self.comm = mesh.comm
        self.V = fem.functionspace(mesh, ("Lagrange", degree, (3,)))
        self.u = fem.Function(self.V, name="u")
        self.state = material_state(self.V, materials, cell_tags, quadrature_degree)

        self._check_facet_tags([d.tag for d in dirichlet] + [t.tag for t in tractions])
        self.dirichlet = list(dirichlet)
        self.bc_dofs, self.bc_values, self.bcs = self._dirichlet_dofs(self.dirichlet)

        v, du = ufl.TestFunction(self.V), ufl.TrialFunction(self.V)
        self.F_int_form = jit.form(self.state.internal_force_form(self.u, v))
        self.K_t_form = jit.form(self.state.tangent_form(self.u, du, v))
        self.K_e_form = jit.form(self.state.elastic_stiffness_form(du, v))
        self.F_ext_parts = self._assemble_external_forces(tractions, body_forces, v)

        self.load_factor = 0.0  # ℓ of the current iterate
        self.load_factor_n = 0.0  # ℓ of the last converged increment
        # (ℓ, u, z) of the increment before the last: the secant predictor
        self._previous: tuple[float, np.ndarray, np.ndarray | None] | None = None
        self.warm_start = False
        """Start the next solve from the current iterate, not the secant predictor (set while an
        increment is solved again in a new contact geometry, :meth:`update_contact_geometry`)."""
        #: interfaces that slid past the slip limit and were moved to the current geometry (``geometry = "auto"``)
        self.slip_warnings: list[str] = []
        self.contact: ContactModel | None = None
        E_max = self.comm.allreduce(float(np.max(self.state.E.x.array, initial=0.0)), op=MPI.MAX)
        self.force_floor = FORCE_FLOOR_STRAIN * E_max * self.characteristic_length() ** 2
        """The smallest force scale F (N): what a strain of 1e-6 sets up over one cell face."""
        if contacts:
            try:
                self.contact = ContactModel(self.V, facet_tags, contacts, E=self.interface_moduli(contacts, E_max),
                                            h=self.characteristic_length(),
                                            constrained_dofs=self.constrained_flags())
            except ContactPairError as error:  # the cause may be bodies meshed as one: say so
                raise self._bodies_meshed_together(contacts) or error

        self.bodies = find_bodies(self.V, cell_tags)
        self.rigid_modes = free_rigid_modes(self.V, self.bodies, self.bc_dofs)
        check_rigid_modes(self.rigid_modes, self.contact)
        self.friction_held = friction_held_motions(self.rigid_modes, self.contact)
        """Rigid motions that only friction holds (:class:`~dolfinx_nnqem.problem.bodies.FrictionHeld`:
        named before solving and when a run fails)."""

    @property
    def petsc_comms(self) -> list:
        """The communicators the problem's PETSc objects live on (mesh, dof layout, pairs).

        DOLFINx gives index maps, hence vectors and matrices, their own duplicate of the mesh
        communicator; :func:`dolfinx_nnqem.numerics.linalg.free_dropped_objects` needs each of them.
        """
        if getattr(self, "_petsc_comms", None) is None:
            comms = [self.comm, self.u.x.petsc_vec.getComm()]  # the second: every vector of V
            if self.contact is not None:
                comms.append(self.contact.B.getComm())
            self._petsc_comms = comms
        return self._petsc_comms

    # -- set-up helpers ---------------------------------------------------------------------
    def _bodies_meshed_together(self, contacts) -> ValueError | None:
        """The error naming cell tags that share nodes across a contact surface, or None.

        A contact between volumes meshed together (common nodes) used to end with a symptom
        ("no facet is tagged 22": both surface tags sat on the same interior facets and one was
        lost) instead of the cause (issue 31)."""
        surfaces = [c.surface2 for c in contacts] + [c.surface1 for c in contacts if c.obstacle is None]
        shared = tags_sharing_nodes(self.V, self.cell_tags, self.facet_tags, surfaces)
        if not shared:
            return None
        pairs = "; ".join(f"the cells tagged {a} and {b} share {n} nodes" for a, b, n in shared)
        return ContactPairError(
            f"{pairs}: those bodies are meshed as one, so the contact surfaces between them (facet tags "
            f"{sorted(set(int(t) for t in surfaces))}) lie inside the mesh, not on a boundary. Bodies in contact "
            "must be meshed without common nodes (in gmsh: do not fragment or glue their volumes)")


    def _check_facet_tags(self, tags: Sequence[int]) -> None:
        if not tags:
            return
        if self.facet_tags is None:
            raise ValueError(f"facet tags {sorted(set(tags))} are used but no facet_tags were given")
        for tag in sorted(set(tags)):
            n = self.comm.allreduce(int(np.count_nonzero(self.facet_tags.values == tag)), op=MPI.SUM)
            if n == 0:
                present = sorted(set(np.concatenate(
                    self.comm.allgather(np.unique(self.facet_tags.values))).tolist()))
                raise ValueError(f"facet tag {tag} has no facets; the mesh's facet tags are {present}")

    def _dirichlet_dofs(self, dirichlet: Sequence[Dirichlet]):
        """Unrolled dof indices and their unit-load target values; zero-valued DirichletBCs."""
        fdim = self.mesh.topology.dim - 1
        dofs_all, values_all, bcs, amplitudes_all = [], [], [], []
        self.bc_dofs_by_tag: dict[int, np.ndarray] = {}
        for d in dirichlet:
            facets = self.facet_tags.find(d.tag)
            components = check_components(d.components, f"Dirichlet(tag={d.tag})")
            _check_finite(f"Dirichlet(tag={d.tag}).value", d.value)
            value = np.broadcast_to(np.asarray(d.value, dtype=float), (len(components),))
            for c, val in zip(components, value):
                Vc = self.V.sub(c)
                dofs = fem.locate_dofs_topological(Vc, fdim, facets)
                bcs.append(fem.dirichletbc(PETSc.ScalarType(0.0), dofs, Vc))  # type: ignore[operator]  # petsc4py's stub types ScalarType as a dtype; it is np.float64
                unrolled = bcs[-1].dof_indices()[0]
                dofs_all.append(np.asarray(unrolled, dtype=np.int32))
                values_all.append(np.full(len(unrolled), val))
                amplitudes_all.append((d.amplitude, len(unrolled)))
                previous = self.bc_dofs_by_tag.get(d.tag, np.zeros(0, np.int32))
                self.bc_dofs_by_tag[d.tag] = np.union1d(previous, dofs_all[-1]).astype(np.int32)
        self._bc_amplitudes = amplitudes_all  # [(amplitude, number of dofs)] in dof order
        if dofs_all:
            dofs = np.concatenate(dofs_all)
            values = np.concatenate(values_all)
        else:
            dofs, values = np.zeros(0, np.int32), np.zeros(0)
        return dofs, values, bcs

    def _assemble_external_forces(self, tractions, body_forces, v) -> list:
        """[(amplitude, F_k)]: each load's force vector for a unit amplitude, assembled once."""
        ds = ufl.Measure("ds", domain=self.mesh, subdomain_data=self.facet_tags)
        dx = ufl.Measure("dx", domain=self.mesh, subdomain_data=self.cell_tags)
        n = ufl.FacetNormal(self.mesh)
        parts = []
        for t in tractions:
            if isinstance(t, Pressure):
                _check_finite(f"Pressure(tag={t.tag}).p", [t.p])
                form = -float(t.p) * ufl.dot(n, v) * ds(t.tag)
            elif isinstance(t, Traction):
                _check_finite(f"Traction(tag={t.tag}).value", t.value, 3)
                form = ufl.dot(ufl.as_vector([float(c) for c in t.value]), v) * ds(t.tag)
            else:
                raise TypeError(f"tractions: {t!r} is neither a Traction nor a Pressure")
            parts.append((t.amplitude, form))
        for b in body_forces:
            if isinstance(b, Gravity):
                _check_finite("Gravity.g", b.g, 3)
                g = ufl.as_vector([float(c) for c in b.g])
                form = self.state.density * ufl.dot(g, v) * dx
            elif isinstance(b, BodyForce):
                _check_finite("BodyForce.value", b.value, 3)
                if b.cell_tag is not None:
                    check_cell_tag(b.cell_tag, self.cell_tags, self.comm, "BodyForce")
                f = ufl.as_vector([float(c) for c in b.value])
                form = ufl.dot(f, v) * (dx if b.cell_tag is None else dx(b.cell_tag))
            else:
                raise TypeError(f"body_forces: {b!r} is neither a BodyForce nor a Gravity")
            parts.append((b.amplitude, form))
        return [(amplitude, assemble_vector(jit.form(form), self.V)) for amplitude, form in parts]

    def external_force(self, load_factor: float | None = None, out: PETSc.Vec | None = None) -> PETSc.Vec:
        """F_ext(ℓ) = Σ_k a_k(ℓ) F_k (a_k(ℓ) = ℓ unless the load has an amplitude): a new vector
        of V, or ``out`` (one, refilled by a solver every iteration) overwritten."""
        ell = self.load_factor if load_factor is None else load_factor
        F = compat.create_vector(self.V) if out is None else out
        with F.localForm() as local:
            local.set(0.0)
        for amplitude, F_k in self.F_ext_parts:
            F.axpy(_amplitude(amplitude, ell), F_k)
        return F

    def constrained_flags(self) -> PETSc.Vec:
        """A vector laid out like V: 1 at the constrained dofs (owned and ghost), 0 elsewhere."""
        flags = compat.create_vector(self.V)
        with flags.localForm() as local:
            local.set(0.0)
            local.array[self.bc_dofs] = 1.0
        return flags

    def interface_moduli(self, contacts: Sequence[Contact], default: float) -> list[float]:
        """Per interface, the smallest Young's modulus of the cells beside its deformable surfaces:
        the softer body's (collective). ``default`` where no rank has a tagged facet (the pair
        search then names the empty surface).

        The default r = E h is the contact stiffness of a surface node; a pair's stiffness is the
        softer side's, so E is that side's. With the stiffer side's, r overweights the gap in the
        laws by the stiffness ratio (10⁴ stalled the Newton iterations at the slide onset of a
        block on a stiffer one, :func:`~dolfinx_nnqem.cases.large_sliding.long_slide`).
        """
        if self.facet_tags is None:
            return [default] * len(contacts)
        tdim = self.mesh.topology.dim
        self.mesh.topology.create_connectivity(tdim - 1, tdim)
        f2c = self.mesh.topology.connectivity(tdim - 1, tdim)
        E_cells = self.state.E.x.array[self.state.E.function_space.dofmap.list[:, 0]]
        moduli = []
        for contact in contacts:
            local = np.inf
            for tag in contact.deformable_surfaces:
                for facet in self.facet_tags.find(tag):
                    local = min(local, float(np.min(E_cells[f2c.links(facet)])))
            smallest = self.comm.allreduce(local, op=MPI.MIN)
            moduli.append(smallest if np.isfinite(smallest) else default)
        return moduli

    def characteristic_length(self) -> float:
        """Mean cell size h (cube root of the mean cell volume), over all ranks."""
        if getattr(self, "_h", None) is not None:
            return self._h
        tdim = self.mesh.topology.dim
        volume = fem.assemble_scalar(jit.form(fem.Constant(self.mesh, 1.0) * ufl.dx(domain=self.mesh)))
        volume = self.comm.allreduce(volume, op=MPI.SUM)
        ncells = self.mesh.topology.index_map(tdim).size_global
        self._h = (volume / ncells) ** (1.0 / 3.0)
        return self._h

    # -- quantities solvers combine --------------------------------------------------------------
    @property
    def has_contact(self) -> bool:
        """Whether the problem has contact interfaces (a contact model)."""
        return self.contact is not None

    @property
    def num_pairs(self) -> int:
        """The number of contact pairs over all ranks (0 without contact)."""
        return 0 if self.contact is None else self.contact.num_global

    def constrained_rows(self) -> np.ndarray:
        """Global (unrolled) PETSc row indices of the constrained dofs this rank owns."""
        start = self.V.dofmap.index_map.local_range[0] * 3
        return (start + self.owned_bc_dofs()).astype(PETSc.IntType)

    def owned_bc_dofs(self) -> np.ndarray:
        """Unrolled bc dofs owned by this rank (indices into the owned part of the vector)."""
        n_owned = self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs
        return self.bc_dofs[self.bc_dofs < n_owned]

    def apply_prescribed_displacements(self, load_factor: float) -> None:
        """Set ``u = a(ℓ) · value`` at the constrained dofs (owned and ghost); a(ℓ) = ℓ by default."""
        factors = np.concatenate([np.full(n, _amplitude(a, load_factor)) for a, n in self._bc_amplitudes]
                                 or [np.zeros(0)])
        self.u.x.array[self.bc_dofs] = factors * self.bc_values
        self.load_factor = load_factor

    def assemble_internal_force(self, F: PETSc.Vec | None = None) -> PETSc.Vec:
        """F_int(u) = ∫ σ(u) : ε(v) dx with the return map from the converged state."""
        self.state.evaluate(self.u)
        return assemble_vector(self.F_int_form, self.V, F)

    def assemble_tangent(self, A: PETSc.Mat | None = None, extra_bcs: Sequence = ()) -> PETSc.Mat:
        """K_t(u), the consistent tangent, with identity rows and columns at constrained dofs
        (and at the dofs of ``extra_bcs``)."""
        self.state.evaluate(self.u)
        return self._assemble_matrix(self.K_t_form, A, extra_bcs)

    def assemble_elastic_stiffness(self, A: PETSc.Mat | None = None, extra_bcs: Sequence = ()) -> PETSc.Mat:
        """K_e, the elastic stiffness, with identity rows and columns at constrained dofs
        (and at the dofs of ``extra_bcs``)."""
        return self._assemble_matrix(self.K_e_form, A, extra_bcs)

    def _assemble_matrix(self, form, A, extra_bcs):
        bcs = self.bcs + list(extra_bcs)
        if A is None:
            A = compat.assemble_matrix(form, bcs, diagonal=1.0)
        else:
            A.zeroEntries()
            dolfinx.fem.petsc.assemble_matrix(A, form, bcs=bcs)
        A.assemble()
        return A

    def relative_displacement(self, u: PETSc.Vec | None = None) -> np.ndarray:
        """w = B u + m(ℓ) of the local pairs, (num_local_pairs, 3) (default: the current u)."""
        if self.contact is None:
            raise ValueError("relative_displacement: the problem has no contact")
        return self.contact.relative_displacement(self.u.x.petsc_vec if u is None else u, self.load_factor)

    def residual(self, z: np.ndarray | None = None, F_int: PETSc.Vec | None = None, *,
                 F_ext: PETSc.Vec | None = None, contact_force: PETSc.Vec | None = None,
                 out: PETSc.Vec | None = None) -> PETSc.Vec:
        """Equilibrium residual R = F_int(u) − ℓ F_ext − Bᵀλ(z) (constrained rows NOT zeroed).

        At constrained dofs R holds the support reactions. A solver that has them passes F_ext(ℓ)
        and Bᵀλ(z) (:meth:`external_force`, ``contact.global_force``) and a vector ``out`` to
        overwrite (a new vector otherwise).
        """
        if F_int is None:
            R = self.assemble_internal_force(out)
        elif out is None:
            R = F_int.copy()
        else:
            F_int.copy(out)
            R = out
        R.axpy(-1.0, self.external_force() if F_ext is None else F_ext)
        if self.contact is not None:
            R.axpy(-1.0, self.contact.global_force(self.contact.force(z)) if contact_force is None else contact_force)
        return R

    def force_scale(self, F_int: PETSc.Vec, F_ext: PETSc.Vec | None = None,
                    contact_force: PETSc.Vec | None = None) -> float:
        """The problem's force scale F at the current iterate, for convergence tests: the one
        recipe every solver and the independent check use.

        F = max(‖F_ext(ℓ)‖, ‖F_int‖, ‖Bᵀλ(z)‖, r ‖Δm‖, F_floor): the applied loads, the internal
        forces (which carry the prescribed displacements), the contact forces, the forces a moving
        rigid obstacle sets up over the increment (``ContactModel.motion_force_scale``), and
        ``force_floor``: a state without forces (a body moved rigidly before it touches, every
        pair open) would otherwise be judged by its rounding errors against zero. ``F_ext``:
        F_ext(ℓ) if the caller has it (assembled otherwise); ``contact_force``: Bᵀλ at the
        current z if the caller has it.
        """
        if F_ext is None:
            F_ext = self.external_force()
            F_ext_norm = F_ext.norm()
            F_ext.destroy()
        else:
            F_ext_norm = F_ext.norm()
        scale = max(F_ext_norm, F_int.norm(), self.force_floor)
        if self.contact is not None:
            force = self.contact.global_force(self.contact.force()) if contact_force is None else contact_force
            scale = max(scale, vec_norm(force), self.contact.motion_force_scale(self.load_factor, self.load_factor_n))
            if contact_force is None:
                force.destroy()
        return scale

    def tangent_action(self, delta: np.ndarray) -> PETSc.Vec:
        """K_t(u) δ without any constrained row or column removed (δ: local array, ghosts included).

        The lifting of a prescribed-displacement increment: the Newton matrix has identity rows
        and columns at constrained dofs, so a step that moves them needs this product on the
        right-hand side. The form is compiled on first use.
        """
        if getattr(self, "_tangent_action", None) is None:
            self._delta = fem.Function(self.V)
            self._tangent_action = jit.form(self.state.tangent_form(self.u, self._delta, ufl.TestFunction(self.V)))
        self._delta.x.array[:] = delta
        self.state.evaluate(self.u)
        return assemble_vector(self._tangent_action, self.V)

    def free_residual(self, R: PETSc.Vec, out: PETSc.Vec | None = None) -> PETSc.Vec:
        """A copy of ``R`` (a new vector, or into ``out``) with the constrained rows zeroed (what
        equilibrium must satisfy)."""
        if out is None:
            Rf = R.copy()
        else:
            R.copy(out)
            Rf = out
        with Rf.localForm() as local:
            local.array[self.bc_dofs] = 0.0
        return Rf

    def amplitudes(self, load_factor: float) -> np.ndarray:
        """The amplitudes of every load, Dirichlet condition and obstacle motion at ``load_factor``."""
        values = ([_amplitude(a, load_factor) for a, _ in self.F_ext_parts]
                  + [_amplitude(a, load_factor) for a, _ in self._bc_amplitudes])
        motion = self.contact.motion_amplitudes(load_factor) if self.contact is not None else np.zeros(0)
        return np.concatenate([np.array(values), motion])

    def extrapolation_factor(self, load_factor: float) -> float | None:
        """β of the secant predictor to ``load_factor``: the ratio of this increment's change of the
        load amplitudes to the last one's (Δℓ / Δℓ_previous when every load follows ℓ); None before
        two increments exist, or where the load path turns (the changes of the amplitudes are not
        parallel: e.g. a pressure stops rising and a drag starts), since the last increment's
        response then says little about this one's."""
        if self._previous is None:
            return None
        ell_prev = self._previous[0]
        a_n = self.amplitudes(self.load_factor_n)
        d_prev = a_n - self.amplitudes(ell_prev)
        d_new = self.amplitudes(load_factor) - a_n
        norm_prev = float(d_prev @ d_prev)
        if norm_prev == 0.0:
            return None
        beta = float(d_new @ d_prev) / norm_prev
        if np.linalg.norm(d_new - beta * d_prev) > 1e-3 * np.linalg.norm(d_new):
            return None  # the load path turns here
        return beta

    def extrapolate(self, load_factor: float) -> bool:
        """Secant predictor: u ← u_n + β (u_n − u_{n−1}), the contact force likewise (see
        :meth:`ContactModel.extrapolate`), β from :meth:`extrapolation_factor`; True if it was
        applied.

        Starts Newton from the linear extrapolation of the last two converged increments
        instead of from the last one (constrained dofs are set afterwards by
        :meth:`apply_prescribed_displacements`).
        """
        beta = None if self.warm_start else self.extrapolation_factor(load_factor)
        if beta is None:
            return False
        assert self._previous is not None  # beta needs it
        _, u_prev, z_prev = self._previous
        u_n = self.state.u_n.x.array
        self.u.x.array[:] = u_n + beta * (u_n - u_prev)
        if self.contact is not None:
            assert z_prev is not None  # committed with contact
            self.contact.extrapolate(z_prev, beta)
        return True

    @property
    def predictor_history(self) -> tuple | None:
        """``(ℓ, u, z)`` of the increment before the last converged one (what :meth:`extrapolate`
        needs; None before two increments exist). u is the local array (ghosts included), z this
        rank's pair unknowns (None without contact). For checkpoints."""
        return self._previous

    def set_predictor_history(self, history: tuple | None) -> None:
        """Restore :attr:`predictor_history` (from a checkpoint of the same problem and partition)."""
        if history is not None:
            ell, u, z = history
            u = np.array(u, dtype=float)
            if u.shape != self.u.x.array.shape:
                raise ValueError(f"predictor history: u has shape {u.shape}, expected {self.u.x.array.shape}")
            if self.contact is not None:
                z = np.array(z, dtype=float).reshape(self.contact.num_local, 3)
            else:
                z = None
            history = (float(ell), u, z)
        self._previous = history

    def update_contact_geometry(self, load_factor: float) -> None:
        """Re-evaluate the current-geometry contact interfaces at u and ℓ (collective; see
        :meth:`~dolfinx_nnqem.contact.geometry_tracking.ContactGeometry.update`); the secant predictor's
        pair unknowns follow the pairs."""
        if self.contact is None or not self.contact.geometry.follows_bodies:
            return
        remap = self.contact.geometry.update(self.u, load_factor, self.state.u_n, self.load_factor_n)
        if self._previous is not None:
            ell, u_prev, z_prev = self._previous
            if z_prev is not None:  # a new pair: no change to extrapolate
                self._previous = (ell, u_prev, remap(z_prev, self.contact.z_n))

    def predict_contact(self) -> None:
        """Starting active set (see :meth:`ContactModel.predict`)."""
        if self.contact is not None:
            self.contact.predict(self.relative_displacement())

    # -- increments --------------------------------------------------------------------------------
    def commit(self, gauss_point_values: GaussPointValues | None = None) -> None:
        """Accept the current iterate as the converged end of the increment.

        The Gauss-point state is updated by the radial return at ``u``, unless the solver
        returned its own values for exactly this ``u`` (NNEQM2, whose flow directions are frozen
        within the increment, is not the radial return).
        """
        self._previous = (self.load_factor_n, self.state.u_n.x.array.copy(),
                          self.contact.z_n.copy() if self.contact is not None else None)
        if gauss_point_values is not None and np.array_equal(gauss_point_values.u, self.u.x.array):
            self.state.commit_values(self.u, gauss_point_values)
        else:
            self.state.commit(self.u)
        self.load_factor_n = self.load_factor
        if self.contact is not None:
            w = self.relative_displacement()
            self.contact.commit(w)

    def restore(self) -> None:
        """Return to the last converged increment (after a failed attempt)."""
        self.u.x.array[:] = self.state.u_n.x.array
        self.load_factor = self.load_factor_n
        if self.contact is not None:
            self.contact.restore()

    def destroy(self) -> None:
        """Free the PETSc objects the problem holds (the contact model's, the rigid modes')."""
        if self.contact is not None:
            self.contact.destroy()
        self.rigid_modes.destroy()


def assemble_vector(form: dolfinx.fem.Form, V: dolfinx.fem.FunctionSpace, F: PETSc.Vec | None = None) -> PETSc.Vec:
    """Assemble the linear ``form`` into ``F`` (a new ghosted vector of ``V`` if None), owned
    entries summed over ranks."""
    if F is None:
        F = compat.create_vector(V)
    with F.localForm() as local:
        local.set(0.0)
    dolfinx.fem.petsc.assemble_vector(F, form)
    F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return F


def _amplitude(amplitude: Callable[[float], float] | None, load_factor: float) -> float:
    value = load_factor if amplitude is None else float(amplitude(load_factor))
    if not math.isfinite(value):
        raise ValueError(f"a load amplitude gave {value} at load factor {load_factor}")
    return value


def _check_finite(name: str, values, length: int | None = None) -> None:
    """``values`` are ``length`` finite numbers within the supported magnitude (else an error
    naming ``name``: not numpy's "could not convert string to float")."""
    expected = f"{length} numbers" if length is not None else "numbers"
    try:
        array = np.atleast_1d(np.asarray(values, dtype=float))
    except (TypeError, ValueError):
        raise TypeError(f"{name} = {values!r}: expected {expected}"
                        + (", e.g. (0.0, -9.81, 0.0)" if length == 3 else "")) from None
    if length is not None and array.shape != (length,):
        raise ValueError(f"{name} = {array.tolist()}: expected {length} components")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} = {array.tolist()} is not finite")
    check_magnitude(name, array)
