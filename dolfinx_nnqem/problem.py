"""The problem: mesh, tags, materials, supports, loads and contact — the one object every solver takes.

A user writes, in DOLFINx terms::

    problem = ContactProblem(
        mesh, cell_tags, facet_tags,
        materials={1: steel, 2: steel},
        dirichlet=[Dirichlet(11), Dirichlet(12)],
        tractions=[Traction(13, (1e5, -1e5, 0.5e5))],
        body_forces=[Gravity((0, -9.81, 0))],
        contact=Contact(surface1=21, surface2=22, mu_f=0.5),
    )

All loads and prescribed displacements are multiplied by the load factor ℓ of the increment,
or by their own ``amplitude(ℓ)`` when one is given (e.g. a pressure held constant while a
drag grows).
The problem owns the unknowns (displacement ``u`` and the pair unknowns ``z``), the converged
state, and the assembly of the pieces solvers combine: F_int(u), F_ext, K_t(u), K_e, B and the
pair law. It never solves anything itself.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import dolfinx.fem as fem
import dolfinx.fem.petsc
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem import compat, jit
from dolfinx_nnqem.material import PlasticState


# -- problem data ---------------------------------------------------------------------------
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
    """Self-weight ``ℓ · ρ g`` with each body's density (from its :class:`VonMises`)."""

    g: Sequence[float] = (0.0, -9.81, 0.0)
    amplitude: Callable[[float], float] | None = None  #: a(ℓ) replacing ℓ


@dataclass(frozen=True)
class Contact:
    """Node-to-node frictional contact between two tagged surfaces.

    Parameters
    ----------
    surface1, surface2
        Facet tags of body 1's and body 2's contact surfaces. The pair normal is body 1's
        outward normal; λ is the force on body 2.
    mu_f
        Coulomb friction coefficient (≥ 0).
    law
        ``"alart-curnier"`` (Cartesian, the robust default) or ``"polar"`` (the seed's form).
    r
        Scaling of the pair laws (force/length); default E·h (see :func:`contact.laws.default_r`).
    tolerance, search_distance, initial_gap
        Passed to :func:`dolfinx_nnqem.contact.pairs.find_pairs`.
    """

    surface1: int
    surface2: int
    mu_f: float
    law: str = "alart-curnier"
    r: float | None = None
    tolerance: float | None = None
    search_distance: float | None = None
    initial_gap: Callable | None = None

    def __post_init__(self):
        if not (isinstance(self.mu_f, (int, float)) and math.isfinite(self.mu_f) and self.mu_f >= 0):
            raise ValueError(f"Contact: mu_f = {self.mu_f!r}; expected a finite value >= 0")
        if self.r is not None and not (math.isfinite(self.r) and self.r > 0):
            raise ValueError(f"Contact: r = {self.r!r}; expected a finite value > 0 (force/length)")
        if self.surface1 == self.surface2:
            raise ValueError(f"Contact: surface1 and surface2 are both tag {self.surface1}")


@dataclass
class SolverOptions:
    """Tolerances shared by all solvers.

    Converged when ‖R‖ ≤ rtol · max(‖ℓ F_ext‖, ‖F_int‖, ‖Bᵀλ‖) and ‖H‖ ≤ rtol times the same
    scale (H is in force units); ``atol`` guards the unloaded start.
    """

    rtol: float = 1e-10
    atol: float = 1e-12
    max_iterations: int = 30
    petsc_options: dict = field(default_factory=dict)
    extrapolate: bool = True  #: start each increment from the secant extrapolation of the last two
    linear_solver: str = "direct"  #: "direct" (MUMPS LU), "iterative" (Krylov + GAMG), or "auto"
    auto_iterative_dofs: int = 300_000  #: with "auto": iterative from this many displacement dofs


# -- the problem ------------------------------------------------------------------------------
class ContactProblem:
    """Quasi-static small-strain elastoplastic problem, with or without contact.

    Parameters
    ----------
    mesh, cell_tags, facet_tags
        A DOLFINx mesh holding all bodies (no shared nodes between bodies in contact) and its tags.
    materials
        One :class:`VonMises` or ``{cell_tag: VonMises}``.
    dirichlet, tractions, body_forces
        Supports and loads; all scaled by the load factor.
    contact
        A :class:`Contact`, or None.
    degree
        Lagrange degree of the displacement: 1 (default; node-to-node contact needs it) or 2
        (quadratic elements do not lock in isochoric plastic flow; trilinear hexahedra do).
    quadrature_degree
        Degree of the Gauss rule; default 2·degree (2×2×2 points per Q1 hexahedron, 3×3×3
        per Q2).
    """

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
        contact: Contact | None = None,
        degree: int = 1,
        quadrature_degree: int | None = None,
    ):
        if mesh.geometry.dim != 3:
            raise ValueError(f"the mesh is {mesh.geometry.dim}D; dolfinx_nnqem solves 3D problems")
        if degree not in (1, 2):
            raise ValueError(f"degree = {degree!r}: the displacement is Lagrange of degree 1 or 2")
        if contact is not None and degree != 1:
            raise ValueError(f"degree = {degree}: node-to-node contact needs degree 1 (pairs are mesh vertices)")
        if quadrature_degree is None:
            quadrature_degree = 2 * degree  # 2×2×2 Gauss points for Q1, 3×3×3 for Q2
        self.mesh, self.cell_tags, self.facet_tags = mesh, cell_tags, facet_tags
        self.comm = mesh.comm
        self.V = fem.functionspace(mesh, ("Lagrange", degree, (3,)))
        self.u = fem.Function(self.V, name="u")
        self.state = PlasticState(self.V, materials, cell_tags, quadrature_degree)

        self._check_facet_tags([d.tag for d in dirichlet] + [t.tag for t in tractions])
        self.dirichlet = list(dirichlet)
        self.bc_dofs, self.bc_values, self.bcs = self._dirichlet_dofs(self.dirichlet)

        v, du = ufl.TestFunction(self.V), ufl.TrialFunction(self.V)
        self.F_int_form = jit.form(self.state.internal_force_form(self.u, v))
        self.K_t_form = jit.form(self.state.tangent_form(self.u, du, v))
        self.K_e_form = jit.form(self.state.elastic_stiffness_form(du, v))
        self.F_ext_parts = self._assemble_external_forces(tractions, body_forces, v)

        self.pending_gauss_values = None  # (u array, σ, Δp) a solver hands to the next commit
        self.load_factor = 0.0  # ℓ of the current iterate
        self.load_factor_n = 0.0  # ℓ of the last converged increment
        self.contact = contact
        self.pairs = None
        self.law = None
        if contact is not None:
            self._setup_contact(contact)

    @property
    def petsc_comms(self) -> list:
        """The communicators the problem's PETSc objects live on (mesh, dof layout, pairs).

        DOLFINx gives index maps, hence vectors and matrices, their own duplicate of the mesh
        communicator; :func:`dolfinx_nnqem.linalg.free_dropped_objects` needs each of them.
        """
        if getattr(self, "_petsc_comms", None) is None:
            comms = [self.comm, self.u.x.petsc_vec.getComm()]  # the second: every vector of V
            if self.pairs is not None:
                comms.append(self.pairs.B.getComm())
            self._petsc_comms = comms
        return self._petsc_comms

    # -- set-up helpers ---------------------------------------------------------------------
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
            components = (0, 1, 2) if d.components is None else tuple(d.components)
            if any(c not in (0, 1, 2) for c in components):
                raise ValueError(f"Dirichlet(tag={d.tag}): components {components} must be among 0, 1, 2")
            value = np.broadcast_to(np.asarray(d.value, dtype=float), (len(components),))
            if not np.all(np.isfinite(value)):
                raise ValueError(f"Dirichlet(tag={d.tag}): value {d.value} is not finite")
            for c, val in zip(components, value):
                Vc = self.V.sub(c)
                dofs = fem.locate_dofs_topological(Vc, fdim, facets)
                bcs.append(fem.dirichletbc(PETSc.ScalarType(0.0), dofs, Vc))
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
                f = ufl.as_vector([float(c) for c in b.value])
                form = ufl.dot(f, v) * (dx if b.cell_tag is None else dx(b.cell_tag))
            else:
                raise TypeError(f"body_forces: {b!r} is neither a BodyForce nor a Gravity")
            parts.append((b.amplitude, form))
        return [(amplitude, assemble_vector(jit.form(form), self.V)) for amplitude, form in parts]

    def external_force(self, load_factor: float | None = None) -> PETSc.Vec:
        """F_ext(ℓ) = Σ_k a_k(ℓ) F_k (a_k(ℓ) = ℓ unless the load has an amplitude)."""
        ell = self.load_factor if load_factor is None else load_factor
        F = compat.create_vector(self.V)
        with F.localForm() as local:
            local.set(0.0)
        for amplitude, F_k in self.F_ext_parts:
            F.axpy(_amplitude(amplitude, ell), F_k)
        return F

    def _setup_contact(self, contact: Contact) -> None:
        from dolfinx_nnqem.contact.laws import default_r, get_law
        from dolfinx_nnqem.contact.pairs import find_pairs

        if self.facet_tags is None:
            raise ValueError("Contact needs facet_tags naming the two contact surfaces")
        self.pairs = find_pairs(
            self.V, self.facet_tags, contact.surface1, contact.surface2,
            tolerance=contact.tolerance, search_distance=contact.search_distance,
            initial_gap=contact.initial_gap,
        )
        if self.pairs.num_global == 0:
            raise ValueError(
                f"Contact: no node pairs found between surfaces {contact.surface1} and {contact.surface2}")
        self.law = get_law(contact.law)
        nloc = self.pairs.num_local
        self.mu_f = np.full(nloc, float(contact.mu_f))
        if contact.r is None:
            E_max = self.comm.allreduce(float(np.max(self.state.E.x.array, initial=0.0)), op=MPI.MAX)
            self.r = float(default_r(E_max, self.characteristic_length()))
        else:
            self.r = float(contact.r)
        self.constrained_directions = self._constrained_directions()
        self.z = np.zeros((nloc, 3))  # the law's unknowns (p_n, q1, q2) or (p_n, p_r, θ)
        self.pair_states = np.zeros(nloc, dtype=np.int8)  # at the last converged increment
        self.slip_increment = np.zeros((nloc, 2))  # tangential slip of the last converged increment
        self.z_n = np.zeros((nloc, 3))
        self.w_n = np.zeros((nloc, 3))  # converged w at the start of the increment

    def _constrained_directions(self) -> np.ndarray:
        """(n_local_pairs, 3) bool: local directions whose relative motion the supports fix."""
        from dolfinx_nnqem.results import values_at_blocks

        flags = compat.create_vector(self.V)
        with flags.localForm() as local:
            local.set(0.0)
            local.array[self.bc_dofs] = 1.0
        blocks = self.pairs.gather(np.column_stack([self.pairs.dofs_a, self.pairs.dofs_b]).astype(float))
        fixed_a = values_at_blocks(self, blocks[:, 0].astype(np.int64), flags) > 0.5
        fixed_b = values_at_blocks(self, blocks[:, 1].astype(np.int64), flags) > 0.5
        lo, hi = self.pairs.offset, self.pairs.offset + self.pairs.num_local
        both = (fixed_a & fixed_b)[lo:hi]  # (n, 3) global components fixed at both nodes
        involved = np.abs(self.pairs.R) > 1e-12  # (n, k, c): direction k involves component c
        return np.all(~involved | both[:, None, :], axis=2)

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
        return self.pairs is not None

    @property
    def num_pairs(self) -> int:
        return 0 if self.pairs is None else self.pairs.num_global

    def constrained_rows(self) -> np.ndarray:
        """Global (unrolled) PETSc row indices of the constrained dofs this rank owns."""
        start = self.V.dofmap.index_map.local_range[0] * 3
        return (start + self.owned_bc_dofs()).astype(PETSc.IntType)

    def transposed_B(self) -> PETSc.Mat:
        """Bᵀ (a new matrix) with the rows of constrained dofs zeroed: du = 0 there."""
        Bt = self.pairs.B.transpose(PETSc.Mat())  # without an output matrix petsc4py transposes in place
        Bt.zeroRows(self.constrained_rows(), diag=0.0)
        return Bt

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
        return assemble_vector(self.F_int_form, self.V, F)

    def assemble_tangent(self, A: PETSc.Mat | None = None) -> PETSc.Mat:
        """K_t(u), the consistent tangent, with identity rows and columns at constrained dofs."""
        return self._assemble_matrix(self.K_t_form, A)

    def assemble_elastic_stiffness(self, A: PETSc.Mat | None = None) -> PETSc.Mat:
        """K_e, the elastic stiffness, with identity rows and columns at constrained dofs."""
        return self._assemble_matrix(self.K_e_form, A)

    def _assemble_matrix(self, form, A):
        if A is None:
            A = compat.assemble_matrix(form, self.bcs, diagonal=1.0)
        else:
            A.zeroEntries()
            dolfinx.fem.petsc.assemble_matrix(A, form, bcs=self.bcs)
        A.assemble()
        return A

    def contact_force(self, z: np.ndarray | None = None) -> np.ndarray:
        """Local contact forces λ = (p_n, q1, q2) on body 2, shape (num_local_pairs, 3)."""
        lam, _ = self.law.force(self.z if z is None else z)
        return lam

    def relative_displacement(self) -> np.ndarray:
        """w = B u for the owned pairs, shape (num_local_pairs, 3)."""
        return self.pairs.relative_displacement(self.u.x.petsc_vec)

    def residual(self, z: np.ndarray | None = None, F_int: PETSc.Vec | None = None) -> PETSc.Vec:
        """Equilibrium residual R = F_int(u) − ℓ F_ext − Bᵀλ (constrained rows NOT zeroed).

        At constrained dofs R holds the support reactions.
        """
        R = self.assemble_internal_force() if F_int is None else F_int.copy()
        R.axpy(-1.0, self.external_force())
        if self.has_contact:
            R.axpy(-1.0, self.pairs.global_force(self.contact_force(z)))
        return R

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
        return assemble_vector(self._tangent_action, self.V)

    def free_residual(self, R: PETSc.Vec) -> PETSc.Vec:
        """A copy of ``R`` with the constrained rows zeroed (what equilibrium must satisfy)."""
        Rf = R.copy()
        with Rf.localForm() as local:
            local.array[self.bc_dofs] = 0.0
        return Rf

    def evaluate_law(self, w: np.ndarray, z: np.ndarray):
        """The pair law at (w, z): ``LawEvaluation(H, dH_dw, dH_dz, state)`` for the owned pairs."""
        from dolfinx_nnqem.contact.laws import pin_constrained_directions

        evaluation = self.law.evaluate(w, self.w_n, z, self.pairs.g0, self.mu_f, self.r)
        return pin_constrained_directions(self.law, evaluation, z, self.constrained_directions,
                                          self.r * self.characteristic_length())

    def amplitudes(self, load_factor: float) -> np.ndarray:
        """The amplitudes of every load and every Dirichlet condition at ``load_factor``."""
        return np.array([_amplitude(a, load_factor) for a, _ in self.F_ext_parts]
                        + [_amplitude(a, load_factor) for a, _ in self._bc_amplitudes])

    def extrapolate(self, load_factor: float) -> bool:
        """Secant predictor: u ← u_n + β (u_n − u_{n−1}), z likewise; True if it was applied.

        Starts Newton from the linear extrapolation of the last two converged increments
        instead of from the last one (constrained dofs are set afterwards by
        :meth:`apply_prescribed_displacements`). β is the ratio of this increment's change of
        the load amplitudes to the last one's (Δℓ / Δℓ_previous when every load follows ℓ).
        Nothing happens before two increments exist, or where the load path turns (the
        changes of the amplitudes are not parallel: e.g. a pressure stops rising and a drag
        starts), since the last increment's response then says little about this one's.
        """
        previous = getattr(self, "_previous", None)
        if previous is None:
            return False
        ell_prev, u_prev, z_prev = previous
        a_n = self.amplitudes(self.load_factor_n)
        d_prev = a_n - self.amplitudes(ell_prev)
        d_new = self.amplitudes(load_factor) - a_n
        norm_prev = float(d_prev @ d_prev)
        if norm_prev == 0.0:
            return False
        beta = float(d_new @ d_prev) / norm_prev
        if np.linalg.norm(d_new - beta * d_prev) > 1e-3 * np.linalg.norm(d_new):
            return False  # the load path turns here
        u_n = self.state.u_n.x.array
        self.u.x.array[:] = u_n + beta * (u_n - u_prev)
        if self.has_contact:
            self.z = self.z_n + beta * (self.z_n - z_prev)
        return True

    def predict_contact(self) -> None:
        """Starting active set: touching pairs (g ≤ 0) with p_n = 0 get a tiny p_n > 0.

        At the tie p_n = r·g = 0 the laws take the open branch, so a body held only by
        contact would have a singular first Jacobian. Starting on the closed branch is the
        usual initial active set of semismooth Newton; a pair that should open does so in
        the next iteration. The value (1e-12 · r · h) is far below any tolerance.
        """
        if not self.has_contact:
            return
        tiny = 1e-12 * self.r * self.characteristic_length()
        gap = self.pairs.g0 + self.relative_displacement()[:, 0]
        touching = (gap <= 0.0) & (self.z[:, 0] <= 0.0)
        self.z[touching, 0] = tiny

    # -- increments --------------------------------------------------------------------------------
    def commit(self) -> None:
        """Accept the current iterate as the converged end of the increment.

        The Gauss-point state is updated by the radial return at ``u``, unless the solver left
        its own values in :attr:`pending_gauss_values` for exactly this ``u`` (NNEQM2, whose
        flow directions are frozen within the increment, is not the radial return).
        """
        self._previous = (self.load_factor_n, self.state.u_n.x.array.copy(),
                          self.z_n.copy() if self.has_contact else None)
        pending, self.pending_gauss_values = self.pending_gauss_values, None
        if pending is not None and np.array_equal(pending[0], self.u.x.array):
            # a solver that integrates the flow itself (NNEQM2) left its Gauss-point values
            self.state.commit_values(self.u, pending[1], pending[2])
        else:
            self.state.commit(self.u)
        self.load_factor_n = self.load_factor
        if self.has_contact:
            w = self.relative_displacement()
            # states and slip must be read before w_n moves on (slip is measured from w_n)
            self.pair_states = self.evaluate_law(w, self.z).state.copy()
            self.slip_increment = w[:, 1:3] - self.w_n[:, 1:3]
            self.w_n = w
            self.z_n = self.z.copy()

    def restore(self) -> None:
        """Return to the last converged increment (after a failed attempt)."""
        self.u.x.array[:] = self.state.u_n.x.array
        self.load_factor = self.load_factor_n
        self.pending_gauss_values = None
        if self.has_contact:
            self.z = self.z_n.copy()


def assemble_vector(form, V, F: PETSc.Vec | None = None) -> PETSc.Vec:
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
    values = np.atleast_1d(np.asarray(values, dtype=float))
    if length is not None and values.shape != (length,):
        raise ValueError(f"{name} = {values.tolist()}: expected {length} components")
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{name} = {values.tolist()} is not finite")
