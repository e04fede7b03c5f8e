r"""Bodies of a mesh, and the rigid-body motions that no support removes.

A body is a connected part of the mesh: cells that share nodes, directly or through other
cells. Bodies in contact share no nodes, so one DOLFINx mesh holds several bodies.

For every body the six rigid-body motions (translations along x, y, z; rotations about the
body's centroid) are restricted to the dofs the Dirichlet conditions leave free; the
combinations that vanish at every constrained dof are the body's *free rigid modes* N: its
stiffness is singular along them. A free mode is harmless only if contact can hold it: some
pair's normal row (or, with friction, a tangential row) of B must see it (B N ≠ 0).
:func:`check_rigid_modes` says, before anything is solved, which bodies could drift and along
which motions. NNEQM1 and NNEQM2 factorise a stiffness of their own and handle the free modes
explicitly (:mod:`dolfinx_nnqem.solvers.condensation`); the monolithic solver holds them through its
contact rows.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from dolfinx_nnqem import compat  # noqa: I001  (first: loads MPI/PETSc for the PyPI wheel)

import dolfinx
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.contact.laws import STICK
from dolfinx_nnqem.numerics.graphs import connected_components

__all__ = ["Bodies", "FrictionHeld", "RigidModes", "check_rigid_modes", "find_bodies", "free_rigid_modes",
           "friction_held_motions"]

MODE_NAMES = ("translation x", "translation y", "translation z", "rotation about x", "rotation about y",
              "rotation about z")
FREE_MODE_TOLERANCE = 1e-10
"""A combination of unit rigid motions is free when its squared values at the constrained dofs
sum to less than this (the motions are O(1) at every node)."""


@dataclass(frozen=True)
class Bodies:
    """The connected bodies of a mesh (the same numbering on every rank).

    Attributes
    ----------
    count
        Number of bodies.
    block_body
        (local dof blocks of V, ghosts included,) the body of every dof block.
    cell_tags
        For every body, the cell tags of its cells (empty without cell tags).
    """

    count: int
    block_body: np.ndarray
    cell_tags: tuple[tuple[int, ...], ...]

    def name(self, body: int) -> str:
        """``"body 2 (cells tagged 2)"``: how messages name a body."""
        tags = self.cell_tags[body]
        if not tags:
            return f"body {body + 1}"
        listed = ", ".join(str(t) for t in tags)
        return f"body {body + 1} (cells tagged {listed})"


def _local_components(V) -> tuple[int, np.ndarray]:
    """Connected components of this rank's cells (owned and ghost) through their dof blocks."""
    dofs = V.dofmap.list
    imap = V.dofmap.index_map
    n = imap.size_local + imap.num_ghosts
    k = dofs.shape[1]
    rows = dofs[:, :-1].reshape(-1) if k > 1 else np.zeros(0, dtype=np.int32)
    cols = dofs[:, 1:].reshape(-1) if k > 1 else np.zeros(0, dtype=np.int32)
    return connected_components(n, rows, cols)


def _lexicographically_smaller(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a < b in lexicographic (x, y, z) order, for (m, 3) arrays."""
    out = np.zeros(len(a), dtype=bool)
    undecided = np.ones(len(a), dtype=bool)
    for k in range(3):
        out |= undecided & (a[:, k] < b[:, k])
        undecided &= a[:, k] == b[:, k]
    return out


def find_bodies(V: dolfinx.fem.FunctionSpace, cell_tags=None) -> Bodies:
    """The connected bodies of V's mesh (collective).

    Components are found on each rank, then merged across ranks through the dof blocks that
    ranks share (each ghost block is joined to its owner's component); the merge graph is small
    (a few components per rank) and solved identically on every rank. Bodies are numbered by
    their lexicographically smallest node (x, then y, then z).
    """
    comm = V.mesh.comm
    imap = V.dofmap.index_map
    n_owned = imap.size_local
    count, label = _local_components(V)
    counts = np.array(comm.allgather(count), dtype=np.int64)
    first = np.concatenate([[0], np.cumsum(counts)])
    code = label + first[comm.rank]  # global component numbering before the merge
    # each ghost block learns the owner's component of the same block
    owner_code = dolfinx.la.vector(imap, 1)
    owner_code.array[:n_owned] = code[:n_owned]
    owner_code.scatter_forward()
    ghost_edges = np.column_stack([code[n_owned:], owner_code.array[n_owned:].astype(np.int64)])
    edges = np.unique(np.concatenate(comm.allgather(np.unique(ghost_edges, axis=0).reshape(-1, 2))), axis=0)
    total = int(first[-1])
    _, root = connected_components(total, edges[:, 0], edges[:, 1])
    # number the bodies by their lexicographically smallest node (the same for any partition)
    x = V.tabulate_dof_coordinates()[:n_owned]
    local = np.full((total, 3), np.inf)
    for c in np.unique(code[:n_owned]):
        xc = x[code[:n_owned] == c]
        local[c] = xc[np.lexsort((xc[:, 2], xc[:, 1], xc[:, 0]))[0]]
    smallest = np.full((total, 3), np.inf)
    for part in comm.allgather(local):  # every component is complete on some rank's list
        smaller = _lexicographically_smaller(part, smallest)
        smallest[smaller] = part[smaller]
    body_smallest = np.full((total, 3), np.inf)
    for c in range(total):
        if _lexicographically_smaller(smallest[c:c + 1], body_smallest[root[c]:root[c] + 1])[0]:
            body_smallest[root[c]] = smallest[c]
    roots = np.unique(root)
    keys = body_smallest[roots]
    order = roots[np.lexsort((keys[:, 2], keys[:, 1], keys[:, 0]))]
    body_of_root = np.empty(total, dtype=np.int64)
    body_of_root[order] = np.arange(len(order))
    block_body = body_of_root[root[code]]

    tags: list[set[int]] = [set() for _ in order]
    if cell_tags is not None:
        first_block = V.dofmap.list[cell_tags.indices, 0]
        pairs = np.unique(np.column_stack([block_body[first_block], cell_tags.values]), axis=0)
        for body, tag in np.concatenate(comm.allgather(pairs.reshape(-1, 2))):
            tags[int(body)].add(int(tag))
    return Bodies(len(order), block_body, tuple(tuple(sorted(t)) for t in tags))


@dataclass
class RigidModes:
    """The free rigid modes of every body (``bodies``), as vectors laid out like V.

    Attributes
    ----------
    vectors
        One PETSc vector per free mode: a rigid motion of one body, zero at constrained dofs
        and elsewhere, scaled to a largest nodal displacement of 1.
    body
        The body of each mode.
    description
        Each mode in words, e.g. ``"translation along (0, 1, 0)"``.
    coefficients
        Each mode as a combination of its body's six unit motions (translations along x, y, z;
        rotations about x, y, z through the body's centre, scaled by its size), with the mode's
        scaling: the vector is that combination of the unit motions. What a combination of modes
        moves is described from these (the one rigid motion each body makes).
    centres, sizes
        Every body's centre (bodies, 3) and size (bodies,): the rotations' centre and scale.
    """

    bodies: Bodies
    vectors: list[PETSc.Vec]
    body: list[int]
    description: list[str]
    coefficients: list[np.ndarray]
    centres: np.ndarray
    sizes: np.ndarray

    @property
    def count(self) -> int:
        return len(self.vectors)

    def local_array(self) -> np.ndarray:
        """(owned unrolled dofs, count): the modes' owned entries as columns."""
        if not self.vectors:
            return np.zeros((0, 0))
        return np.column_stack([v.getArray(readonly=True) for v in self.vectors])

    def destroy(self) -> None:
        for v in self.vectors:
            v.destroy()


def _describe(coefficients: np.ndarray, centre: np.ndarray, size: float) -> str:
    """A rigid motion t + ω × (x − centre) (coefficients of the unit motions) in words."""
    t, omega = coefficients[:3], coefficients[3:] / size
    if np.linalg.norm(omega) <= 1e-8 * np.linalg.norm(coefficients):
        return f"translation along {_direction(t)}"
    # the axis: the points p with t + ω × (p − centre) parallel to ω
    p = centre + np.cross(omega, t) / float(omega @ omega)
    text = f"rotation about the axis through {_point(p)} along {_direction(omega)}"
    if abs(t @ omega) > 1e-8 * np.linalg.norm(t) * np.linalg.norm(omega):
        text += " (with a translation along it)"
    return text


def _direction(v: np.ndarray) -> str:
    v = v / np.linalg.norm(v)
    v = v * np.sign(v[np.flatnonzero(np.abs(v) > 1e-12)[0]])  # first nonzero component positive
    return "(" + ", ".join(f"{c:.3g}" for c in v + 0.0) + ")"


def _point(x: np.ndarray) -> str:
    return "(" + ", ".join(f"{c:.6g}" for c in np.round(x, 12) + 0.0) + ")"


def _row_echelon(basis: np.ndarray) -> np.ndarray:
    """A basis of the same space in reduced row-echelon form (readable: pure modes where possible)."""
    A = basis.copy()
    rows, cols = A.shape
    r = 0
    for c in range(cols):
        if r == rows:
            break
        p = r + int(np.argmax(np.abs(A[r:, c])))
        if abs(A[p, c]) < 1e-10:
            continue
        A[[r, p]] = A[[p, r]]
        A[r] /= A[r, c]
        for i in range(rows):
            if i != r:
                A[i] -= A[i, c] * A[r]
        r += 1
    A[np.abs(A) < 1e-12] = 0.0
    return A / np.linalg.norm(A, axis=1)[:, None]


def free_rigid_modes(V: dolfinx.fem.FunctionSpace, bodies: Bodies, constrained_dofs: np.ndarray) -> RigidModes:
    """The rigid-body motions of every body that vanish at all constrained dofs (collective).

    Parameters
    ----------
    constrained_dofs
        Local unrolled indices (owned and ghost) of the dofs held by Dirichlet conditions.
    """
    comm = V.mesh.comm
    imap = V.dofmap.index_map
    n_owned = imap.size_local
    x = V.tabulate_dof_coordinates()[:n_owned]
    body = bodies.block_body[:n_owned]
    fixed = np.zeros(3 * n_owned, dtype=bool)
    fixed[constrained_dofs[constrained_dofs < 3 * n_owned]] = True
    fixed = fixed.reshape(-1, 3)

    # per body: node count, coordinate sums, then the size for scaling the rotations
    sums = np.zeros((bodies.count, 4))
    np.add.at(sums, body, np.column_stack([np.ones(n_owned), x]))
    comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    centre = sums[:, 1:] / np.maximum(sums[:, :1], 1.0)
    size = np.zeros(bodies.count)
    np.maximum.at(size, body, np.linalg.norm(x - centre[body], axis=1))
    comm.Allreduce(MPI.IN_PLACE, size, op=MPI.MAX)
    size = np.where(size > 0.0, size, 1.0)

    # the six unit motions at every owned node, (n_owned, 3 components, 6 modes)
    d = (x - centre[body]) / size[body][:, None]
    unit = np.zeros((n_owned, 3, 6))
    unit[:, 0, 0] = unit[:, 1, 1] = unit[:, 2, 2] = 1.0
    unit[:, 1, 3], unit[:, 2, 3] = -d[:, 2], d[:, 1]  # about x: (0, −z, y)
    unit[:, 0, 4], unit[:, 2, 4] = d[:, 2], -d[:, 0]  # about y: (z, 0, −x)
    unit[:, 0, 5], unit[:, 1, 5] = -d[:, 1], d[:, 0]  # about z: (−y, x, 0)
    gram = np.zeros((bodies.count, 6, 6))
    node, _ = np.nonzero(fixed)
    values = unit[fixed]  # (constrained owned dofs, 6)
    np.add.at(gram, body[node], values[:, :, None] * values[:, None, :])
    comm.Allreduce(MPI.IN_PLACE, gram, op=MPI.SUM)

    vectors, mode_body, description, coefficients = [], [], [], []
    for b in range(bodies.count):
        eigenvalues, eigenvectors = np.linalg.eigh(gram[b])
        free = eigenvectors[:, eigenvalues <= FREE_MODE_TOLERANCE].T
        if len(free) == 0:
            continue
        for c in _row_echelon(free):
            array = np.where((body == b)[:, None], unit @ c, 0.0)
            array[fixed] = 0.0
            largest = comm.allreduce(float(np.linalg.norm(array, axis=1).max(initial=0.0)), op=MPI.MAX)
            v = compat.create_vector(V)
            v.getArray()[:] = (array / largest).reshape(-1)
            vectors.append(v)
            mode_body.append(b)
            description.append(_describe(c, centre[b], size[b]))
            coefficients.append(c / largest)
    return RigidModes(bodies, vectors, mode_body, description, coefficients, centre, size)


def check_rigid_modes(modes: RigidModes, contact=None) -> None:
    """Raise ValueError naming every body that could drift: free modes no contact can hold.

    A mode is held when a pair's normal row of B sees it, or a tangential row of an interface
    with friction (μ_f > 0; friction then holds it while the pair is pressed). Combinations of
    modes of several bodies count too (two floating bodies touching only each other).
    """
    if modes.count == 0:
        return
    if contact is None or contact.num_global == 0:
        _raise_drifting(modes, np.eye(modes.count), "no support holds it and there is no contact")
    BN = contact.gather(np.stack([contact.B_times(v) for v in modes.vectors], axis=-1))  # (pairs, 3, modes)
    mu_f = contact.gather(contact.mu_f)
    rows = [BN[:, 0, :]] + [BN[mu_f > 0.0, k, :] for k in (1, 2)]
    A = np.concatenate(rows, axis=0)
    if A.shape[0] == 0:
        _raise_drifting(modes, np.eye(modes.count), "no contact pair sees it")
    rank, vt = _rank_and_null_space(A)
    if rank < modes.count:
        _raise_drifting(modes, vt[rank:], "no support holds it and no contact surface faces that motion "
                                          "(frictionless contact cannot hold a sliding motion)")


def _rank_and_null_space(A: np.ndarray) -> tuple[int, np.ndarray]:
    """The rank of A (modes as columns) and Vᵀ of its SVD: rows rank: span A's null space."""
    # Only s and vt are needed: full_matrices=True would also build U, (3 pairs)² numbers (7.5 GB
    # at 10⁴ pairs). Zero rows up to the number of modes keep vt square (the null space's rows
    # included) without changing AᵀA, hence s and vt.
    if A.shape[0] < A.shape[1]:
        A = np.vstack([A, np.zeros((A.shape[1] - A.shape[0], A.shape[1]))])
    _, s, vt = np.linalg.svd(A, full_matrices=False)
    scale = max(float(s.max(initial=0.0)), 1.0)
    return int(np.count_nonzero(s > 1e-10 * scale)), vt


@dataclass(frozen=True)
class FrictionHeld:
    """The free rigid motions that only friction holds (see :func:`friction_held_motions`).

    Attributes
    ----------
    motions
        Each motion in words, e.g. ``"body 2 (cells tagged 2): translation along (1, 0, 0)"``.
    pairs
        (pairs, in the contact model's gathered order) True where a pair's friction resists one
        of them.
    """

    motions: tuple[str, ...] = ()
    pairs: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def saturated(self, states: np.ndarray | None) -> bool:
        """Whether no pair holding these motions sticks (``states``: the gathered pair states):
        friction then carries all it can along them and a larger load makes the body slide."""
        if not self.motions or states is None or len(states) != len(self.pairs):
            return False
        return not bool(np.any(np.asarray(states)[self.pairs] == STICK))


def friction_held_motions(modes: RigidModes, contact=None) -> FrictionHeld:
    """The free rigid motions that only friction holds, and the pairs that hold them (collective).

    Such a motion meets no support and no contact normal (no pair's normal row of B sees it);
    pairs with friction resist it only up to μ_f p_n: once the load along it exceeds that, the
    body slides without resistance and no equilibrium exists. Call after
    :func:`check_rigid_modes` (every free mode is held by something).
    """
    if modes.count == 0 or contact is None or contact.num_global == 0:
        return FrictionHeld()
    BN = contact.gather(np.stack([contact.B_times(v) for v in modes.vectors], axis=-1))  # (pairs, 3, modes)
    rank, vt = _rank_and_null_space(BN[:, 0, :])
    if rank == modes.count:
        return FrictionHeld()
    combinations = _row_echelon(vt[rank:])
    tangential = np.linalg.norm(BN[:, 1:, :] @ combinations.T, axis=1)  # (pairs, motions)
    scale = max(float(np.abs(BN).max(initial=0.0)), 1e-300)
    held = np.any(tangential > 1e-10 * scale, axis=1) & (contact.gather(contact.mu_f) > 0.0)
    return FrictionHeld(tuple(_describe_combination(modes, c) for c in combinations), held)


def _describe_combination(modes: RigidModes, c: np.ndarray) -> str:
    """A combination of free modes in words, body by body: the one rigid motion it gives each body
    (a translation along the tangent of an incline, say), not the modes it is made of."""
    by_body: dict[int, np.ndarray] = {}
    for k in np.flatnonzero(np.abs(c) > 1e-8):
        b = modes.body[k]
        by_body[b] = by_body.get(b, np.zeros(6)) + c[k] * modes.coefficients[k]
    return "; ".join(f"{modes.bodies.name(b)}: {_describe(motion, modes.centres[b], modes.sizes[b])}"
                     for b, motion in by_body.items())


def _raise_drifting(modes: RigidModes, combinations: np.ndarray, why: str) -> None:
    lines = ["  - " + _describe_combination(modes, c) for c in _row_echelon(np.atleast_2d(combinations))]
    raise ValueError("a body can move rigidly without resistance (" + why + "):\n" + "\n".join(lines)
                     + "\nAdd a support (Dirichlet condition) against that motion, or contact that holds it.")


def tags_sharing_nodes(V: dolfinx.fem.FunctionSpace, cell_tags, facet_tags, surfaces) -> list[tuple[int, int, int]]:
    """The cell tags on either side of the facets tagged ``surfaces`` that share nodes, as
    (tag a, tag b, number of common nodes) (collective).

    Contact surfaces must be boundaries of bodies meshed apart. A facet tagged as a contact
    surface that lies between cells of two different tags which share nodes means those "bodies"
    were meshed as one (e.g. gmsh volumes fragmented together): the facet is inside the mesh, and
    a surface tag on it may even be lost (two physical surfaces on the same facets keep one tag).
    """
    comm = V.mesh.comm
    if cell_tags is None or facet_tags is None:
        return []
    mesh = V.mesh
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    f2c = mesh.topology.connectivity(tdim - 1, tdim)
    imap = mesh.topology.index_map(tdim)
    tag_of = np.full(imap.size_local + imap.num_ghosts, -1, dtype=np.int64)
    tag_of[cell_tags.indices] = cell_tags.values
    sides: set[tuple[int, int]] = set()  # this rank's
    for surface in surfaces:
        for facet in facet_tags.find(int(surface)):
            cells = f2c.links(facet)
            if len(cells) == 2:
                a, b = sorted(int(t) for t in tag_of[cells])
                if a >= 0 and a != b:
                    sides.add((a, b))
    all_sides = sorted(set().union(*comm.allgather(sides)))
    blocks = V.dofmap.index_map

    def nodes_of(tag: int) -> np.ndarray:
        local = np.unique(V.dofmap.list[cell_tags.find(tag)].reshape(-1))
        return np.unique(np.concatenate(comm.allgather(blocks.local_to_global(local.astype(np.int32)))))

    shared = []
    for a, b in all_sides:
        n = len(np.intersect1d(nodes_of(a), nodes_of(b)))
        if n:
            shared.append((a, b, n))
    return shared
