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

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import dolfinx.fem as fem
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.problem.bodies import check_rigid_modes, find_bodies, free_rigid_modes, friction_held_motions
from dolfinx_nnqem.contact.model import ContactModel
from dolfinx_nnqem.contact.specification import Contact
from dolfinx_nnqem.contact.obstacles import Cylinder, Plane, Sphere  # noqa: F401  (the user's imports)
from dolfinx_nnqem.material.interface import GaussPointValues, Material
from dolfinx_nnqem.problem.assembly import assemble_matrix, assemble_vector
from dolfinx_nnqem.problem.loads import BodyForce, ExternalLoads, Gravity, Pressure, Traction
from dolfinx_nnqem.problem.kinematics_choice import checked_kinematics, material_state_of
from dolfinx_nnqem.problem.interfaces import build_contact_model, interface_moduli, largest_modulus
from dolfinx_nnqem.problem.mesh_quality import check_cells
from dolfinx_nnqem.problem.parameter_study import reset_state, update_parameters
from dolfinx_nnqem.problem.predictor import SecantPredictor
from dolfinx_nnqem.problem.supports import Dirichlet, Supports, check_facet_tags
from dolfinx_nnqem.problem.validation import check_mesh, check_one_contact_per_pair
from dolfinx_nnqem.numerics.linalg import vec_norm

FORCE_FLOOR_STRAIN = 1e-6
"""The force scale F is never below the force this strain sets up over one cell face (E_max h²)."""


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
    kinematics: str = "small"  #: "small" or "finite" (:mod:`~dolfinx_nnqem.problem.kinematics_choice`)


class ContactProblem:
    """Quasi-static elastoplastic problem at small or finite strain, with or without contact.

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
    kinematics
        "small" (ε = sym ∇u, the default) or "finite" (total Lagrangian, F = I + ∇u;
        :mod:`~dolfinx_nnqem.problem.kinematics_choice`).

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
        kinematics: str = "small",
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
        self.kinematics = checked_kinematics(kinematics, materials)
        self.definition = ProblemDefinition(materials, tuple(dirichlet), tuple(tractions), tuple(body_forces),
                                            tuple(contacts), degree, quadrature_degree, self.kinematics)
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
        self.state = material_state_of(self.kinematics, self.V, materials, cell_tags, quadrature_degree)

        check_facet_tags(facet_tags, self.comm, [d.tag for d in dirichlet] + [t.tag for t in tractions])
        self.dirichlet = list(dirichlet)
        self.supports = Supports(self.V, facet_tags, self.dirichlet)
        """The constrained dofs and their values (:class:`~dolfinx_nnqem.problem.supports.Supports`)."""
        self.bc_dofs, self.bc_values, self.bcs = self.supports.dofs, self.supports.values, self.supports.bcs
        self.bc_dofs_by_tag = self.supports.dofs_by_tag

        v, du = ufl.TestFunction(self.V), ufl.TrialFunction(self.V)
        self.F_int_form = jit.form(self.state.internal_force_form(self.u, v))
        self.K_t_form = jit.form(self.state.tangent_form(self.u, du, v))
        self.K_e_form = jit.form(self.state.elastic_stiffness_form(du, v))
        self.loads = ExternalLoads(self.V, tractions, body_forces, self.state.density, facet_tags, cell_tags)
        """The loads' force vectors (:class:`~dolfinx_nnqem.problem.loads.ExternalLoads`)."""
        self.F_ext_parts = self.loads.parts

        self.load_factor = 0.0  # ℓ of the current iterate
        self.load_factor_n = 0.0  # ℓ of the last converged increment
        self.predictor = SecantPredictor()
        """The secant predictor and its history (:class:`~dolfinx_nnqem.problem.predictor.SecantPredictor`)."""
        self.warm_start = False
        """Start the next solve from the current iterate, not the secant predictor (set while an
        increment is solved again in a new contact geometry, :meth:`update_contact_geometry`)."""
        #: interfaces that slid past the slip limit and were moved to the current geometry (``geometry = "auto"``)
        self.slip_warnings: list[str] = []
        self.contact: ContactModel | None = None
        E_max = largest_modulus(self.state.E)
        self.force_floor = self.moduli_force_floor()
        """The smallest force scale F (N): what a strain of 1e-6 sets up over one cell face."""
        if contacts:
            self.contact = build_contact_model(self.V, cell_tags, facet_tags, contacts,
                                               self.interface_moduli(contacts, E_max), self.characteristic_length(),
                                               self.constrained_flags())

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
    def external_force(self, load_factor: float | None = None, out: PETSc.Vec | None = None) -> PETSc.Vec:
        """F_ext(ℓ) = Σ_k a_k(ℓ) F_k (a_k(ℓ) = ℓ unless the load has an amplitude): a new vector
        of V, or ``out`` (one, refilled by a solver every iteration) overwritten."""
        return self.loads.force(self.load_factor if load_factor is None else load_factor, out)

    def constrained_flags(self) -> PETSc.Vec:
        """A vector laid out like V: 1 at the constrained dofs (owned and ghost), 0 elsewhere."""
        return self.supports.flags()

    def interface_moduli(self, contacts: Sequence[Contact], default: float) -> list[float]:
        """Per interface, the smallest Young's modulus of the cells beside its deformable surfaces:
        the softer body's (collective). ``default`` where no rank has a tagged facet (the pair
        search then names the empty surface).

        See :func:`~dolfinx_nnqem.problem.interfaces.interface_moduli`.
        """
        return interface_moduli(self.state.E, self.facet_tags, contacts, default)

    def moduli_force_floor(self) -> float:
        """F_floor = :data:`FORCE_FLOOR_STRAIN` · E_max h², of the current moduli (collective)."""
        return FORCE_FLOOR_STRAIN * largest_modulus(self.state.E) * self.characteristic_length() ** 2

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
        return self.supports.owned_dofs()

    def apply_prescribed_displacements(self, load_factor: float) -> None:
        """Set ``u = a(ℓ) · value`` at the constrained dofs (owned and ghost); a(ℓ) = ℓ by default."""
        self.u.x.array[self.bc_dofs] = self.supports.prescribed(load_factor)
        self.load_factor = load_factor

    def assemble_internal_force(self, F: PETSc.Vec | None = None) -> PETSc.Vec:
        """F_int(u) = ∫ σ(u) : ε(v) dx with the return map from the converged state."""
        self.state.evaluate(self.u, tangent=False)
        return assemble_vector(self.F_int_form, self.V, F)

    def assemble_tangent(self, A: PETSc.Mat | None = None, extra_bcs: Sequence = ()) -> PETSc.Mat:
        """K_t(u), the consistent tangent, with identity rows and columns at constrained dofs
        (and at the dofs of ``extra_bcs``)."""
        self.state.evaluate(self.u)
        return assemble_matrix(self.K_t_form, self.bcs + list(extra_bcs), A)

    def assemble_elastic_stiffness(self, A: PETSc.Mat | None = None, extra_bcs: Sequence = ()) -> PETSc.Mat:
        """K_e, the elastic stiffness, with identity rows and columns at constrained dofs
        (and at the dofs of ``extra_bcs``)."""
        return assemble_matrix(self.K_e_form, self.bcs + list(extra_bcs), A)

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
            F_ext_norm = vec_norm(F_ext)
            F_ext.destroy()
        else:
            F_ext_norm = vec_norm(F_ext)
        scale = max(F_ext_norm, vec_norm(F_int), self.force_floor)
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
        values = self.loads.amplitudes(load_factor) + self.supports.amplitude_values(load_factor)
        motion = self.contact.motion_amplitudes(load_factor) if self.contact is not None else np.zeros(0)
        return np.concatenate([np.array(values), motion])

    def extrapolation_factor(self, load_factor: float) -> float | None:
        """β of the secant predictor to ``load_factor`` (:meth:`SecantPredictor.factor
        <dolfinx_nnqem.problem.predictor.SecantPredictor.factor>`): None before two increments exist
        or where the load path turns."""
        return self.predictor.factor(self.amplitudes, self.load_factor_n, load_factor)

    def extrapolate(self, load_factor: float) -> bool:
        """Secant predictor: u ← u_n + β (u_n − u_{n−1}), the contact force likewise, β from
        :meth:`extrapolation_factor`; True if it was applied (not while :attr:`warm_start`).

        Starts Newton from the linear extrapolation of the last two converged increments
        instead of from the last one (constrained dofs are set afterwards by
        :meth:`apply_prescribed_displacements`).
        """
        beta = None if self.warm_start else self.extrapolation_factor(load_factor)
        if beta is None:
            return False
        self.predictor.extrapolate(self.u.x.array, self.state.u_n.x.array, self.contact, beta)
        return True

    @property
    def predictor_history(self) -> tuple | None:
        """``(ℓ, u, z)`` of the increment before the last converged one (what :meth:`extrapolate`
        needs; None before two increments exist). u is the local array (ghosts included), z this
        rank's pair unknowns (None without contact). For checkpoints."""
        return self.predictor.history

    def set_predictor_history(self, history: tuple | None) -> None:
        """Restore :attr:`predictor_history` (from a checkpoint of the same problem and partition)."""
        self.predictor.restore(history, self.u.x.array.shape,
                               self.contact.num_local if self.contact is not None else None)

    def update_contact_geometry(self, load_factor: float) -> None:
        """Re-evaluate the current-geometry contact interfaces at u and ℓ (collective; see
        :meth:`~dolfinx_nnqem.contact.geometry_tracking.ContactGeometry.update`); the secant predictor's
        pair unknowns follow the pairs."""
        if self.contact is None or not self.contact.geometry.follows_bodies:
            return
        remap = self.contact.geometry.update(self.u, load_factor, self.state.u_n, self.load_factor_n)
        self.predictor.follow_pairs(remap, self.contact.z_n)

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
        self.predictor.record(self.load_factor_n, self.state.u_n.x.array,
                              self.contact.z_n if self.contact is not None else None)
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

    # -- a parameter study -------------------------------------------------------------------------
    def update(self, *, materials: Material | Mapping[int, Material] | None = None,
               mu_f: float | Mapping[str, float] | None = None, tractions: Sequence[Traction | Pressure] | None = None,
               body_forces: Sequence[BodyForce | Gravity] | None = None,
               dirichlet: Sequence[Dirichlet] | None = None) -> None:
        """Change parameters and start again from the initial state (:meth:`reset`): the same problem
        solved again without new forms or compiles. Build the solver again afterwards.

        ``materials`` as when built (one, or ``{cell_tag: material}`` for some bodies: E, ν, density;
        σ_y0 and H of a linear-hardening ``VonMises``); ``mu_f`` for every interface or ``{name: μ_f}``;
        ``tractions``, ``body_forces``, ``dirichlet``: the same loads and supports with other magnitudes,
        values or amplitudes. What else is refused and why: :mod:`~dolfinx_nnqem.problem.parameter_study`
        (a ValueError naming the parameter; the problem is then unchanged).
        """
        update_parameters(self, materials=materials, mu_f=mu_f, tractions=tractions, body_forces=body_forces,
                          dirichlet=dirichlet)

    def reset(self) -> None:
        """Back to the initial state: u = 0, the Gauss-point state and pair unknowns as built, load
        factor 0, no predictor history (:func:`~dolfinx_nnqem.problem.parameter_study.reset_state`)."""
        reset_state(self)

    def destroy(self) -> None:
        """Free the PETSc objects the problem holds (the contact model's, the rigid modes')."""
        if self.contact is not None:
            self.contact.destroy()
        self.rigid_modes.destroy()

