"""The supports of a problem: prescribed displacements ``u_i = a(ℓ) · value_i`` on tagged facets.

The constrained dofs are collected once, with the value each takes at a unit amplitude; the
solvers impose them by identity rows and columns (zero-valued DOLFINx Dirichlet conditions that
only name the dofs) and by setting ``u`` at those dofs (:meth:`Supports.prescribed`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import dolfinx.fem as fem
import dolfinx.mesh
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem import compat
from dolfinx_nnqem.problem.loads import check_finite, load_amplitude
from dolfinx_nnqem.problem.validation import check_components

__all__ = ["Dirichlet", "Supports", "check_facet_tags", "check_no_conflicts"]


@dataclass(frozen=True)
class Dirichlet:
    """Prescribed displacement ``u_i = ℓ · value_i`` on the facets tagged ``tag``.

    ``components=None`` constrains all three components (``value`` a 3-vector or a scalar
    used for all); otherwise only the listed ones (``value`` one number per listed component).
    The default is a clamp (u = 0). A dof that several conditions constrain must get the same
    displacement from each (:func:`check_no_conflicts`).
    """

    tag: int
    value: float | Sequence[float] = 0.0
    components: Sequence[int] | None = None
    amplitude: Callable[[float], float] | None = None  #: a(ℓ) replacing ℓ (non-proportional paths)


def check_facet_tags(facet_tags: dolfinx.mesh.MeshTags | None, comm: MPI.Comm, tags: Sequence[int]) -> None:
    """Every tag of ``tags`` names facets on some rank (collective).

    Raises
    ------
    ValueError
        Naming the tag without facets and the tags the mesh has, or if there are no facet tags.
    """
    if not tags:
        return
    if facet_tags is None:
        raise ValueError(f"facet tags {sorted(set(tags))} are used but no facet_tags were given")
    for tag in sorted(set(tags)):
        n = comm.allreduce(int(np.count_nonzero(facet_tags.values == tag)), op=MPI.SUM)
        if n == 0:
            present = sorted(set(np.concatenate(comm.allgather(np.unique(facet_tags.values))).tolist()))
            raise ValueError(f"facet tag {tag} has no facets; the mesh's facet tags are {present}")


class Supports:
    """The constrained dofs of a problem and the values they take.

    Parameters
    ----------
    V
        The displacement space.
    facet_tags
        The facet tags the conditions name.
    dirichlet
        The conditions.

    Attributes
    ----------
    conditions
        The conditions (:class:`Dirichlet`).
    dofs, values
        Unrolled local dof indices (owned and ghost) and their values at a unit amplitude.
    bcs
        Zero-valued DOLFINx Dirichlet conditions on those dofs (identity rows in the matrices).
    dofs_by_tag
        The constrained dofs of each tag (reactions per support).
    amplitudes
        ``[(amplitude, number of dofs)]`` in the order of :attr:`dofs` (amplitude None: ℓ).
    """

    def __init__(self, V: fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags | None,
                 dirichlet: Sequence[Dirichlet]):
        self.V = V
        self.conditions = list(dirichlet)
        fdim = V.mesh.topology.dim - 1
        dofs_all: list[np.ndarray] = []
        values_all: list[np.ndarray] = []
        self.bcs: list = []
        self.amplitudes: list[tuple[Callable[[float], float] | None, int]] = []
        self.dofs_by_tag: dict[int, np.ndarray] = {}
        for d in dirichlet:
            facets = facet_tags.find(d.tag)  # type: ignore[union-attr]  # check_facet_tags ran: tags exist
            for c, val in zip(*_components_and_values(d)):
                Vc = V.sub(c)
                dofs = fem.locate_dofs_topological(Vc, fdim, facets)
                self.bcs.append(fem.dirichletbc(PETSc.ScalarType(0.0), dofs, Vc))  # type: ignore[operator]  # petsc4py's stub types ScalarType as a dtype; it is np.float64
                unrolled = self.bcs[-1].dof_indices()[0]
                dofs_all.append(np.asarray(unrolled, dtype=np.int32))
                values_all.append(np.full(len(unrolled), val))
                self.amplitudes.append((d.amplitude, len(unrolled)))
                previous = self.dofs_by_tag.get(d.tag, np.zeros(0, np.int32))
                self.dofs_by_tag[d.tag] = np.union1d(previous, dofs_all[-1]).astype(np.int32)
        if dofs_all:
            self.dofs, self.values = np.concatenate(dofs_all), np.concatenate(values_all)
        else:
            self.dofs, self.values = np.zeros(0, np.int32), np.zeros(0)
        check_no_conflicts(V.mesh.comm, self.dofs, self.values, self.amplitudes, self._labels())

    def revalue(self, dirichlet: Sequence[Dirichlet]) -> None:
        """New values and amplitudes of the same conditions (the same tags and components, in order):
        the constrained dofs stay, :attr:`values` (in place) and :attr:`amplitudes` follow.

        Raises
        ------
        ValueError
            If a condition has another tag or other components than the one it replaces.
        """
        values, self.amplitudes = self.revalued(dirichlet)
        self.values[:] = values
        self.conditions = list(dirichlet)

    def revalued(self, dirichlet: Sequence[Dirichlet]) -> tuple[np.ndarray, list]:
        """The :attr:`values` and :attr:`amplitudes` of :meth:`revalue` (checked; nothing changes)."""
        if len(dirichlet) != len(self.conditions):
            raise ValueError(f"dirichlet: {len(dirichlet)} conditions given for the {len(self.conditions)} the "
                             "problem was built with; only their values and amplitudes may change")
        values, amplitudes = [], []
        counts = iter([n for _, n in self.amplitudes])
        for old, new in zip(self.conditions, dirichlet):
            components, new_values = _components_and_values(new)
            if new.tag != old.tag or components != _components_and_values(old)[0]:
                raise ValueError(f"dirichlet: Dirichlet(tag={new.tag}, components={new.components}) replaces "
                                 f"Dirichlet(tag={old.tag}, components={old.components}); the constrained dofs "
                                 "are fixed when the problem is built: only values and amplitudes may change")
            for val in new_values:
                n = next(counts)
                values.append(np.full(n, val))
                amplitudes.append((new.amplitude, n))
        values_all = np.concatenate(values) if values else np.zeros(0)
        check_no_conflicts(self.V.mesh.comm, self.dofs, values_all, amplitudes, self._labels(dirichlet))
        return values_all, amplitudes

    def _labels(self, dirichlet: Sequence[Dirichlet] | None = None) -> list[str]:
        """"Dirichlet(tag=…, component …)" of every constrained component, in the order of :attr:`amplitudes`."""
        return [f"Dirichlet(tag={d.tag}, component {c})"
                for d in (self.conditions if dirichlet is None else dirichlet) for c in _components_and_values(d)[0]]

    def prescribed(self, load_factor: float) -> np.ndarray:
        """The values a(ℓ) · value of the constrained dofs at ``load_factor``."""
        factors = np.concatenate([np.full(n, load_amplitude(a, load_factor)) for a, n in self.amplitudes]
                                 or [np.zeros(0)])
        return factors * self.values

    def amplitude_values(self, load_factor: float) -> list[float]:
        """a(ℓ) of every constrained component of every condition."""
        return [load_amplitude(a, load_factor) for a, _ in self.amplitudes]

    def owned_dofs(self) -> np.ndarray:
        """The constrained dofs this rank owns (indices into the owned part of a vector)."""
        n_owned = self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs
        return self.dofs[self.dofs < n_owned]

    def flags(self) -> PETSc.Vec:
        """A vector laid out like V: 1 at the constrained dofs (owned and ghost), 0 elsewhere."""
        flags = compat.create_vector(self.V)
        with flags.localForm() as local:
            local.set(0.0)
            local.array[self.dofs] = 1.0
        return flags


def check_no_conflicts(comm: MPI.Comm, dofs: np.ndarray, values: np.ndarray,
                       amplitudes: Sequence[tuple[Callable[[float], float] | None, int]], labels: Sequence[str]) -> None:
    """No dof is prescribed two different displacements (collective).

    A dof constrained by several conditions (facets of two tags sharing an edge, two entries of
    one tag) must get the same value from each at every load factor: a zero from all of them (a
    clamp and a symmetry plane meeting at an edge), or the same value with the same amplitude.
    Otherwise which one holds would depend on the order of the conditions.

    Parameters
    ----------
    dofs, values
        The constrained dofs (local, unrolled) and their values at a unit amplitude, in the order of
        ``amplitudes``.
    amplitudes
        ``[(amplitude, number of dofs)]``: each constrained component of each condition, in order.
    labels
        The name of each entry of ``amplitudes``, for the message.

    Raises
    ------
    ValueError
        On every rank, naming the two conditions and the values of the first conflict found.
    """
    entry = np.repeat(np.arange(len(amplitudes)), [n for _, n in amplitudes]) if amplitudes else np.zeros(0, int)
    message = ""
    order = np.argsort(dofs, kind="stable")
    sorted_dofs = dofs[order]
    repeated = np.flatnonzero(sorted_dofs[1:] == sorted_dofs[:-1])
    first, second = order[repeated], order[repeated + 1]
    shared = ~((values[first] == 0.0) & (values[second] == 0.0))  # zero from both: no conflict
    first, second = first[shared], second[shared]
    # each condition's value is one number: one dof per pair of conditions tells all (the first, in dof order)
    _, representative = np.unique(np.column_stack([entry[first], entry[second]]), axis=0, return_index=True)
    for i, j in zip(first[np.sort(representative)], second[np.sort(representative)]):
        a_i, a_j = amplitudes[entry[i]][0], amplitudes[entry[j]][0]
        same_amplitude = _same_amplitude(a_i, a_j)
        if values[i] == values[j] and same_amplitude:
            continue
        message = (f"{labels[entry[i]]} and {labels[entry[j]]} prescribe different displacements to the same dof "
                   f"({values[i]:g} and {values[j]:g} at a unit amplitude"
                   f"{'' if same_amplitude else ', with different amplitudes'}); give each dof one condition")
        break
    messages = [m for m in comm.allgather(message) if m]
    if messages:
        raise ValueError(f"dirichlet: {messages[0]}")


def _same_amplitude(a, b) -> bool:
    """The same amplitude: one object, or equal ones (two tables of the same rows)."""
    if a is b:
        return True
    try:
        return bool(a == b)
    except (TypeError, ValueError):  # an object whose == is elementwise: not known to be the same
        return False


def _components_and_values(d: Dirichlet) -> tuple[tuple[int, ...], np.ndarray]:
    """The components ``d`` constrains and the value of each (checked)."""
    components = check_components(d.components, f"Dirichlet(tag={d.tag})")
    check_finite(f"Dirichlet(tag={d.tag}).value", d.value)
    return components, np.broadcast_to(np.asarray(d.value, dtype=float), (len(components),))
