r"""The contact model: every interface of a problem as one set of pairs with its unknowns.

This is the contract between the problem and the solvers (``formulation.md`` §2–§3). The model
owns the interfaces (each a :class:`~dolfinx_nnqem.contact.pairset.PairSet` with its law, r and
μ_f), the pair unknowns z, the converged relative displacement w_n and the directions the
supports fix. Solvers use only what it exposes:

* w = B u + m(ℓ) (:meth:`ContactModel.relative_displacement`), B's action and Bᵀλ;
* H(w, z) with its generalized Jacobian blocks ∂H/∂w, ∂H/∂z (:meth:`ContactModel.evaluate`),
  the force λ(z) and ∂λ/∂z, the scale of the unknowns, the contact scale r
  (:attr:`ContactModel.r_max`);
* blockdiag(D) B in B's sparsity, refilled in place (:meth:`ContactModel.scaled_B`);
* the same laws on all pairs gathered on every rank, for the dense methods
  (:meth:`ContactModel.gathered_laws`);
* where the pairs come from and when they move (``model.geometry``, a
  :class:`~dolfinx_nnqem.contact.geometry_tracking.ContactGeometry`).

It composes the user's specification of each interface
(:class:`~dolfinx_nnqem.contact.specification.Contact`), the pair laws
(:class:`~dolfinx_nnqem.contact.pair_laws.PairLaws`: solvers never ask which law a pair follows,
everything law-specific is a method of the law) and the geometry tracking.

All interfaces' pairs are concatenated: this rank's pairs are those of interface 0, then of
interface 1, ...; the global pair order is by rank, then in that local order (for a single
interface, the pair set's own global order).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from dolfinx_nnqem import compat  # noqa: F401, I001  (first: loads MPI/PETSc for the PyPI wheel)
from dolfinx_nnqem import _moved

import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.contact.laws import ContactLaw, LawEvaluation, Linearisation, get_law
from dolfinx_nnqem.contact import pair_laws
from dolfinx_nnqem.contact.constrained_directions import constrained_directions
from dolfinx_nnqem.contact.pairset import PairRows, PairSet, rows_matrix
from dolfinx_nnqem.contact.surfaces import ContactPairError
from dolfinx_nnqem.contact.current_geometry import remapper
from dolfinx_nnqem.contact.geometry_tracking import ContactGeometry, Remap, starting_pairs
from dolfinx_nnqem.contact.specification import interface_r

if TYPE_CHECKING:
    import dolfinx

    from dolfinx_nnqem.contact.pair_laws import PairLaws
    from dolfinx_nnqem.contact.specification import Contact

__all__ = ["ContactModel", "Interface"]


PREDICTED_PRESSURE = 1e-12
"""Starting active set: touching pairs start with p_n = this × r h (see :meth:`ContactModel.predict`)."""


@dataclass(frozen=True, eq=False)
class Interface:
    """One interface of the model: its specification, pair set and law, and its local pairs."""

    contact: Contact
    pairs: PairSet
    law: ContactLaw
    r: float
    local: slice  #: this interface's rows among the model's local pairs


class ContactModel:
    """All contact interfaces of a problem as one set of pairs (collective construction).

    Parameters
    ----------
    V
        The displacement space (vector P1).
    facet_tags
        Facet tags naming the contact surfaces.
    contacts
        The interfaces.
    E, h
        Young's modulus at each interface (one per contact; a single value for all) and element
        size: the default r = E h and the reference of its supported range
        (:func:`~dolfinx_nnqem.contact.specification.interface_r`). The problem passes the softer
        body's modulus at each interface (:meth:`~dolfinx_nnqem.problem.ContactProblem.interface_moduli`).
    constrained_dofs
        A vector laid out like V, 1 at constrained dofs and 0 elsewhere: pair directions whose
        every involved dof is constrained are pinned (:meth:`ContactLaw.pin`).

    Attributes
    ----------
    interfaces
        The interfaces in pair order (:class:`Interface`).
    laws
        The pair laws of this rank's pairs (:class:`~dolfinx_nnqem.contact.pair_laws.PairLaws`).
    geometry
        Where the pairs come from (:class:`~dolfinx_nnqem.contact.geometry_tracking.ContactGeometry`).
    z, z_n
        (num_local, 3) the pair unknowns (current iterate, last converged increment).
    w_n
        (num_local, 3) w at the last converged increment (slip is measured from it).
    state_n, slip_n
        Pair states and tangential slip of the last converged increment (for reports).
    """

    def __init__(self, V, facet_tags, contacts: Sequence[Contact], *, E: float | Sequence[float], h: float,
                 constrained_dofs: PETSc.Vec):
        if not contacts:
            raise ValueError("ContactModel: no contact interface given")
        moduli = [float(e) for e in E] if isinstance(E, Sequence) else [float(E)] * len(contacts)
        if len(moduli) != len(contacts):
            raise ValueError(f"ContactModel: {len(moduli)} moduli E for {len(contacts)} interfaces")
        self.comm = V.mesh.comm
        self.V = V
        self.h = float(h)
        labels = [c.label for c in contacts]
        if len(set(labels)) != len(labels):
            raise ValueError(f"contact interfaces need distinct names, got {labels}")
        # kept for re-pinning the pairs of a new geometry (the caller may free its vector)
        self._constrained_dofs = constrained_dofs.copy()
        interfaces, trackers = [], []
        for contact, E_interface in zip(contacts, moduli):
            r = interface_r(contact, E_interface, h)
            with constrained_dofs.localForm() as c:
                pairs, tracker = starting_pairs(contact, V, facet_tags, c.array.copy())
            if pairs.num_global == 0:
                raise ContactPairError(f"contact {contact.label}: no pairs found")
            interfaces.append(Interface(contact, pairs, get_law(contact.law), r, slice(0, 0)))
            trackers.append(tracker)
        self._assemble(interfaces)
        self.geometry = ContactGeometry(self, V, facet_tags, trackers, self._constrained_dofs)

        n = self.num_local
        self.z = self.laws.initial_unknowns()
        self.z_n = self.z.copy()
        self.w_n = np.zeros((n, 3))
        self.state_n = np.zeros(n, dtype=np.int8)
        self.slip_n = np.zeros((n, 2))

    def _assemble(self, interfaces: list[Interface]) -> None:
        """B, the frames, gaps, areas and laws of the concatenated pairs of ``interfaces``."""
        start, placed = 0, []
        for interface in interfaces:
            placed.append(replace(interface, local=slice(start, start + interface.pairs.num_local)))
            start += interface.pairs.num_local
        self.interfaces: list[Interface] = placed
        interfaces = placed
        self.num_local = start
        counts = self.comm.allgather(self.num_local)
        self.num_global = int(sum(counts))
        self.offset = int(sum(counts[: self.comm.rank]))

        self.rows = PairRows.concatenate([i.pairs.rows for i in interfaces])
        self.B = rows_matrix(self.comm, self.rows, self.num_global, self.V.dofmap.index_map)
        self.R = np.concatenate([i.pairs.R for i in interfaces]).reshape(-1, 3, 3)
        self.g0 = np.concatenate([i.pairs.g0 for i in interfaces])
        self.area = np.concatenate([i.pairs.area for i in interfaces])  #: slave nodes' tributary areas
        self.interface_index = np.concatenate([np.full(i.pairs.num_local, k, dtype=np.int32)
                                               for k, i in enumerate(interfaces)])
        mu_f = np.concatenate([np.full(i.pairs.num_local, float(i.contact.mu_f)) for i in interfaces])
        self.laws = pair_laws.PairLaws(self._groups(self.interface_index), self.g0, mu_f,
                                       self._constrained_directions())
        self._gathered_laws: PairLaws | None = None  # gathered_laws(), at its first call
        self._w = self.B.createVecLeft()

    def _groups(self, interface_index: np.ndarray) -> tuple[pair_laws.LawGroup, ...]:
        """One law group per interface: the pairs whose ``interface_index`` names it."""
        return tuple(pair_laws.LawGroup(i.law, i.r, i.r * self.h, np.flatnonzero(interface_index == k))
                     for k, i in enumerate(self.interfaces))

    def _constrained_directions(self) -> np.ndarray:
        """The pair directions a support holds (:func:`constrained_directions`)."""
        return constrained_directions(self.rows, self.comm, self.num_global, self.V.dofmap.index_map,
                                      [(i.pairs, i.local) for i in self.interfaces], self._constrained_dofs)

    # -- sizes and parallel helpers ------------------------------------------------------------
    @property
    def constrained(self) -> np.ndarray:
        """(num_local, 3) bool: the local directions whose relative motion the supports fix."""
        return self.laws.constrained

    @property
    def mu_f(self) -> np.ndarray:
        """(num_local,) the friction coefficients of the local pairs."""
        return self.laws.mu_f

    @property
    def r_max(self) -> float:
        """The contact scale: the largest r of the interfaces (force/length;
        :attr:`PairLaws.r_max <dolfinx_nnqem.contact.pair_laws.PairLaws.r_max>`)."""
        return self.laws.r_max

    def gather(self, values: npt.ArrayLike) -> np.ndarray:
        """All pairs' values in global pair order, on every rank (collective)."""
        values = np.asarray(values)
        if values.shape[:1] != (self.num_local,):
            raise ValueError(f"values must have {self.num_local} rows, got shape {values.shape}")
        return np.concatenate(self.comm.allgather(values), axis=0)

    def local_rows(self, values_global: np.ndarray) -> np.ndarray:
        """This rank's rows of an array in global pair order."""
        return values_global[self.offset:self.offset + self.num_local]

    def gathered_laws(self) -> PairLaws:
        """The laws of all pairs in global pair order, on every rank (collective, then cached)."""
        if self._gathered_laws is None:
            index = self.gather(self.interface_index)
            self._gathered_laws = pair_laws.PairLaws(self._groups(index), self.gather(self.g0),
                                                     self.gather(self.mu_f), self.gather(self.constrained))
        return self._gathered_laws

    # -- kinematics and forces -------------------------------------------------------------------
    def motion(self, load_factor: float) -> np.ndarray:
        """(num_local, 3): m(ℓ), the known part of w (moving rigid obstacles)."""
        m = np.zeros((self.num_local, 3))
        for interface in self.interfaces:
            if interface.contact.obstacle is not None:
                m[interface.local] = interface.pairs.motion(load_factor)
        return m

    def motion_amplitudes(self, load_factor: float) -> np.ndarray:
        """The obstacles' translations at ``load_factor`` (the same on every rank)."""
        parts = [i.pairs.motion_amplitudes(load_factor) for i in self.interfaces]
        return np.concatenate(parts) if parts else np.zeros(0)

    def motion_force_scale(self, load_factor: float, load_factor_n: float) -> float:
        """r ‖m(ℓ) − m(ℓ_n)‖ over all pairs (collective): the forces an obstacle's motion over the
        increment sets up, in force units. 0 when no obstacle moves.

        Loads and prescribed displacements show in F_ext and F_int; a moving obstacle shows in
        neither until the pairs close, so a solver's force scale needs it explicitly.
        """
        local = 0.0
        for interface in self.interfaces:
            if interface.contact.obstacle is not None:
                dm = interface.pairs.motion(load_factor) - interface.pairs.motion(load_factor_n)
                local += float(np.sum((interface.r * dm) ** 2))
        return float(np.sqrt(self.comm.allreduce(local, op=MPI.SUM)))

    def B_times(self, x: PETSc.Vec) -> np.ndarray:
        """B x, (num_local, 3), for any vector laid out like V (only owned entries are read)."""
        self.B.mult(x, self._w)
        return self._w.getArray(readonly=True).reshape(-1, 3).copy()

    def relative_displacement(self, u: PETSc.Vec, load_factor: float) -> np.ndarray:
        """w = B u + m(ℓ), (num_local, 3)."""
        w = self.B_times(u)
        if any(i.contact.obstacle is not None for i in self.interfaces):
            w += self.motion(load_factor)
        return w

    def force(self, z: np.ndarray | None = None) -> np.ndarray:
        """λ(z) (num_local, 3), the local forces on the slave side (default: the current z)."""
        return self.laws.force(self.z if z is None else z)[0]

    def force_derivative(self, z: np.ndarray | None = None) -> np.ndarray:
        """∂λ/∂z (num_local, 3, 3)."""
        return self.laws.force(self.z if z is None else z)[1]

    def global_force(self, lam: npt.ArrayLike, out: PETSc.Vec | None = None) -> PETSc.Vec:
        """Bᵀλ laid out like V's owned dofs (a new vector, or ``out`` overwritten)."""
        lam = np.asarray(lam, dtype=PETSc.ScalarType)
        if lam.shape != (self.num_local, 3):
            raise ValueError(f"lam must have shape ({self.num_local}, 3), got {lam.shape}")
        self._w.getArray()[:] = lam.ravel()
        if out is None:
            out = self.B.createVecRight()
        self.B.multTranspose(self._w, out)
        return out

    def scaled_B(self, D: np.ndarray, out: PETSc.Mat | None = None, values: np.ndarray | None = None) -> PETSc.Mat:
        """blockdiag(D_i) B in B's sparsity: a new matrix, or ``out`` (made by this method) refilled;
        ``values``: another matrix's in B's layout instead of B's (B + W: a consistent linearisation)."""
        values = self.rows.scaled(D, values)
        if out is None:
            return rows_matrix(self.comm, self.rows, self.num_global, self.V.dofmap.index_map, values)
        out.setValuesCSR(self.rows.indptr, self.rows.columns, values)  # type: ignore[arg-type]  # petsc4py's stub asks Sequence; arrays are what it takes
        out.assemble()
        return out

    def create_lambda_vector(self) -> PETSc.Vec:
        """A PETSc vector with B's row layout (3 entries per local pair), set to zero."""
        lam = self.B.createVecLeft()
        lam.set(0.0)
        return lam

    # -- the laws -----------------------------------------------------------------------------------
    def evaluate(self, w: np.ndarray, z: np.ndarray | None = None) -> LawEvaluation:
        """H(w, z) of the local pairs with ∂H/∂w, ∂H/∂z and the states (default: the current z)."""
        return self.laws.evaluate(w, self.w_n, self.z if z is None else z)

    def linearise(self, evaluation: LawEvaluation, z: np.ndarray | None = None) -> Linearisation:
        """The Jacobian blocks of a Newton step in the laws' step coordinates (default: the current z).

        For the monolithic solver: sliding pairs keep their polar coordinates (stepping them in
        the force, as the dense solvers do, cost it cutbacks and iterations on the robustness
        suite: docs/robustness.md).
        """
        return self.laws.linearise(self.z if z is None else z, evaluation, sliding_in_force=False)

    def advance(self, z: np.ndarray, dy: np.ndarray, alpha: float, cartesian: np.ndarray | None) -> np.ndarray:
        """The unknowns after the step α dy from z (see :meth:`~dolfinx_nnqem.contact.pair_laws.PairLaws.advance`)."""
        return self.laws.advance(z, dy, alpha, cartesian)

    def extrapolate(self, z_prev: np.ndarray, beta: float) -> None:
        """Secant prediction of the unknowns from z_n and the previous increment's ``z_prev``
        (see :meth:`~dolfinx_nnqem.contact.pair_laws.PairLaws.extrapolate`)."""
        self.z = self.laws.extrapolate(self.z_n, z_prev, beta)

    @property
    def slip_following(self) -> bool:
        """True if some interface's law has unknowns :meth:`follow_slip` may move (the polar angle)."""
        return self.laws.slip_following

    def follow_slip(self, w: np.ndarray, sliding_too: bool = False) -> None:
        """Set the unknowns no force depends on (the polar angle of pairs without friction force)
        on the slip of the relative displacement ``w``, with ``sliding_too`` also the angle of
        sliding pairs (see :meth:`~dolfinx_nnqem.contact.pair_laws.PairLaws.follow_slip`)."""
        self.z = self.laws.follow_slip(self.z, w, self.w_n, sliding_too)

    def unknown_scale(self, force_scale: float) -> np.ndarray:
        """(num_local, 3): the scale of each local unknown when forces are of order ``force_scale``."""
        return self.laws.unknown_scale(force_scale)

    def predict(self, w: np.ndarray) -> None:
        """Starting active set: touching pairs (g ≤ 0) with p_n = 0 get a tiny p_n > 0.

        At the tie p_n = r·g = 0 the laws take the open branch, so a body held only by
        contact would have a singular first Jacobian. Starting on the closed branch is the
        usual initial active set of semismooth Newton; a pair that should open does so in
        the next iteration. The value (:data:`PREDICTED_PRESSURE` · r · h) is far below any
        tolerance.
        """
        tiny = np.zeros(self.num_local)
        for group in self.laws.groups:
            tiny[group.index] = PREDICTED_PRESSURE * group.force_unit
        gap = self.g0 + w[:, 0]
        touching = (gap <= 0.0) & (self.z[:, 0] <= 0.0)
        self.z[touching, 0] = tiny[touching]

    # -- increments ---------------------------------------------------------------------------------
    def commit(self, w: np.ndarray) -> None:
        """Accept the current z and ``w`` as the converged end of the increment."""
        # states and slip are read before w_n moves on (slip is measured from w_n)
        self.state_n = self.evaluate(w).state.copy()
        self.slip_n = w[:, 1:3] - self.w_n[:, 1:3]
        self.w_n = w.copy()
        self.z_n = self.z.copy()

    def restore(self) -> None:
        """Back to the last converged increment's unknowns."""
        self.z = self.z_n.copy()

    # -- a new geometry (geometry_tracking) ---------------------------------------------------------
    def pair_keys(self) -> np.ndarray:
        """(num_local,) what names a local pair across geometry updates: interface and slave node."""
        blocks = np.concatenate([i.pairs.slave_blocks for i in self.interfaces]).astype(np.int64)
        return self.interface_index.astype(np.int64) * (self.V.dofmap.index_map.size_global + 1) + blocks

    def replace_pairs(self, pairs: Sequence[PairSet], u_n: dolfinx.fem.Function, load_factor_n: float) -> Remap:
        """The model on new pair sets of its interfaces, one per interface (collective; what
        :meth:`~dolfinx_nnqem.contact.geometry_tracking.ContactGeometry.update` evaluated).

        B, the frames, gaps and laws are those of the new pairs. The pair unknowns z, z_n and the
        states follow their slave node (:meth:`pair_keys`); new pairs start force-free. w_n is
        measured again with the new rows, w_n = B u_n + m(ℓ_n). Returns the remap of per-pair arrays
        (:data:`~dolfinx_nnqem.contact.geometry_tracking.Remap`).
        """
        old_keys = self.pair_keys()
        for obj in (self.B, self._w):
            obj.destroy()
        self._assemble([replace(i, pairs=p) for i, p in zip(self.interfaces, pairs)])
        remap = remapper(old_keys, self.pair_keys())
        fresh = self.laws.initial_unknowns()
        self.z, self.z_n = remap(self.z, fresh), remap(self.z_n, fresh)
        self.state_n = remap(self.state_n, np.zeros((), dtype=np.int8))
        self.slip_n = remap(self.slip_n, np.zeros(2))
        self.w_n = self.relative_displacement(u_n.x.petsc_vec, load_factor_n)
        return remap

    def refill_pairs(self, pairs: Mapping[int, PairSet], u_n: dolfinx.fem.Function, load_factor_n: float) -> None:
        """New values of the pair sets of some interfaces (interface index → pairs), in place: the
        same pairs in the same order with B's pattern (what
        :meth:`~dolfinx_nnqem.contact.geometry_tracking.ContactGeometry.refresh_obstacles` evaluated).
        The frames, gaps, B's values and the pinned directions follow; w_n is measured again,
        w_n = B u_n + m(ℓ_n). The unknowns stay (collective)."""
        for k, new in pairs.items():
            interface = self.interfaces[k]
            local = interface.local
            self.interfaces[k] = replace(interface, pairs=new)
            self.R[local] = new.R
            self.g0[local] = new.g0  # the laws hold this array
            start = self.rows.indptr[3 * local.start]
            self.rows.values[start:start + len(new.rows.values)] = new.rows.values
        self.B.setValuesCSR(self.rows.indptr, self.rows.columns, self.rows.values)  # type: ignore[arg-type]  # as in scaled_B
        self.B.assemble()
        self.laws = replace(self.laws, constrained=self._constrained_directions())
        self._gathered_laws = None
        self.w_n = self.relative_displacement(u_n.x.petsc_vec, load_factor_n)

    # -- a parameter study ----------------------------------------------------------------------------
    def set_parameters(self, contacts: Sequence[Contact], E: Sequence[float]) -> None:
        """New friction coefficients and moduli of the same interfaces (one ``Contact`` and one E per
        interface, in order): μ_f of every pair and each interface's r = E h (or its own ``r``) follow.

        Only μ_f and r may differ: the pairs, their laws and unknowns stay (a parameter study,
        :meth:`~dolfinx_nnqem.problem.ContactProblem.update`).

        Raises
        ------
        ValueError
            If a contact differs from its interface's in anything but ``mu_f``.
        """
        if len(contacts) != len(self.interfaces) or len(E) != len(self.interfaces):
            raise ValueError(f"ContactModel.set_parameters: {len(contacts)} contacts and {len(E)} moduli for "
                             f"{len(self.interfaces)} interfaces")
        for interface, contact in zip(self.interfaces, contacts):
            if replace(contact, mu_f=interface.contact.mu_f) != interface.contact:
                raise ValueError(f"contact {interface.contact.label}: only mu_f may change in a parameter study")
        self.interfaces = [replace(i, contact=c, r=interface_r(c, float(e), self.h))
                           for i, c, e in zip(self.interfaces, contacts, E)]
        mu_f = np.concatenate([np.full(i.pairs.num_local, float(i.contact.mu_f)) for i in self.interfaces])
        self.laws = replace(self.laws, groups=self._groups(self.interface_index), mu_f=mu_f)
        self._gathered_laws = None

    def reset(self) -> None:
        """Back to the pair unknowns of a new model: force-free pairs, w_n = 0, no states or slip
        (the pairs themselves stay: those of the reference geometry)."""
        n = self.num_local
        self.z = self.laws.initial_unknowns()
        self.z_n = self.z.copy()
        self.w_n = np.zeros((n, 3))
        self.state_n = np.zeros(n, dtype=np.int8)
        self.slip_n = np.zeros((n, 2))

    # -- reporting ----------------------------------------------------------------------------------
    def obstacle_reactions(self, lam: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Force of each rigid obstacle on the body, Σ R_sᵀ λ_s (global frame), over all ranks."""
        lam = self.force() if lam is None else lam
        out = {}
        for interface in self.interfaces:
            if interface.contact.obstacle is None:
                continue
            local = np.einsum("nji,nj->i", self.R[interface.local], lam[interface.local])
            out[interface.contact.label] = np.asarray(self.comm.allreduce(local, op=MPI.SUM))
        return out

    def describe(self) -> list[str]:
        """One line per interface."""
        return [f"contact {i.contact.label}: {i.pairs.describe()}, law {i.law.name}, μ_f = {i.contact.mu_f:g}, "
                f"r = {i.r:.4g}" for i in self.interfaces]

    def destroy(self) -> None:
        """Free the PETSc objects of the model and of its pair sets."""
        self.B.destroy()
        self._constrained_dofs.destroy()
        self._w.destroy()
        for interface in self.interfaces:
            B = getattr(interface.pairs, "B", None)
            if B is not None:
                B.destroy()


if not TYPE_CHECKING:  # for the type checker the moved names are gone: the package imports their new paths
    def __getattr__(name: str):
        """The names that moved out of this module, with a DeprecationWarning naming where they went."""
        return _moved.moved_name(__name__, name)

    _moved.install_members(ContactModel)  # its old geometry members: now those of ContactModel.geometry
