"""Quantities reported for a converged increment: pair tables, reactions, nodal displacements.

Every function here is collective (call it on all ranks) and returns the same gathered,
global data on every rank, in global pair order or in the order of the points asked for.
Nothing here solves or writes files.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.contact.laws import STATE_NAMES

if TYPE_CHECKING:
    from petsc4py import PETSc


def values_at_blocks(problem, blocks: np.ndarray, vec=None) -> np.ndarray:
    """Values of a blocked (3 per node) vector at global dof-block indices, on every rank.

    Parameters
    ----------
    blocks
        Global dof-block indices (n,), the same on every rank.
    vec
        A PETSc vector laid out like ``problem.V`` (default: the displacement).
    """
    V = problem.V
    imap = V.dofmap.index_map
    start, end = imap.local_range
    array = (problem.u.x.petsc_vec if vec is None else vec).getArray(readonly=True)
    blocks = np.asarray(blocks, dtype=np.int64)
    out = np.zeros((len(blocks), 3))
    mine = (blocks >= start) & (blocks < end)
    local = blocks[mine] - start
    out[mine] = array.reshape(-1, 3)[local]
    total = np.zeros_like(out)
    problem.comm.Allreduce(out, total, op=MPI.SUM)
    return total


def node_blocks_at_points(problem, points: np.ndarray, cell_tag: int | None = None,
                          tol: float = 1e-8) -> np.ndarray:
    """Global dof-block indices of the mesh nodes at ``points`` (n,3).

    ``cell_tag`` restricts the search to the nodes of that body: bodies in contact have
    coincident nodes. Raises ValueError naming the points that are no node.
    """
    V = problem.V
    x = V.tabulate_dof_coordinates()
    imap = V.dofmap.index_map
    n_owned = imap.size_local
    candidates = np.arange(n_owned)
    if cell_tag is not None:
        cells = problem.cell_tags.find(cell_tag)
        body_nodes = np.unique(V.dofmap.list[cells].reshape(-1))
        candidates = body_nodes[body_nodes < n_owned]
    points = np.atleast_2d(np.asarray(points, dtype=float))
    scale = max(np.ptp(problem.mesh.geometry.x, axis=0).max(), 1.0)
    found = np.full(len(points), -1, dtype=np.int64)
    for i, p in enumerate(points):
        if len(candidates) == 0:
            break
        d = np.linalg.norm(x[candidates] - p, axis=1)
        j = int(np.argmin(d))
        if d[j] <= tol * scale:
            found[i] = imap.local_range[0] + candidates[j]
    result = np.zeros_like(found)
    problem.comm.Allreduce(found, result, op=MPI.MAX)
    missing = np.flatnonzero(result < 0)
    if len(missing):
        where = "" if cell_tag is None else f" of the cells tagged {cell_tag}"
        raise ValueError(f"no mesh node{where} at {points[missing].tolist()}")
    return result


def pair_table(problem) -> dict[str, np.ndarray]:
    """Gathered pair data in global pair order (same arrays on every rank).

    Body 1 is the master side of a pair (``surface1``, or a rigid obstacle), body 2 its slave
    side (``surface2``). Keys: ``interface`` (index into ``problem.contact.interfaces``),
    ``position`` (the master point, X_a for node-to-node), ``position_b`` (the slave node),
    ``frame`` (R), ``state`` (0/1/2), ``force_local_body1`` (−λ: normal, tangential 1,
    tangential 2 on body 1, N), ``force_on_body1`` (global frame, N), ``u_body1`` (the master
    point's displacement u_s − Rᵀw: node a's, or the obstacle's), ``u_body2`` (m), ``gap`` (m),
    ``slip`` (tangential slip of the last increment, m), ``z`` (the law's unknowns),
    ``slave_block`` (the slave node's global dof block), ``interface_name``, ``area`` (the slave
    node's tributary area, m²), ``pressure`` (contact pressure p_n / area, Pa) and ``weighted_gap``
    (area × gap, m³: mortar's weighted gap).
    """
    model = problem.contact
    lam = model.force()
    w = problem.relative_displacement()
    X_master = np.concatenate([i.pairs.X_master for i in model.interfaces]).reshape(-1, 3)
    X_slave = np.concatenate([i.pairs.X_slave for i in model.interfaces]).reshape(-1, 3)
    slave_blocks = np.concatenate([i.pairs.slave_blocks for i in model.interfaces]).astype(float)
    local = np.hstack([
        X_master, X_slave, model.R.reshape(-1, 9), model.state_n[:, None].astype(float),
        -lam, -np.einsum("nji,nj->ni", model.R, lam), (model.g0 + w[:, 0])[:, None],
        model.slip_n, model.z, slave_blocks[:, None], model.interface_index[:, None].astype(float),
        np.einsum("nji,nj->ni", model.R, w), model.area[:, None],
    ])
    g = model.gather(local)
    table = {
        "position": g[:, 0:3], "position_b": g[:, 3:6], "frame": g[:, 6:15].reshape(-1, 3, 3),
        "state": g[:, 15].astype(np.int8), "force_local_body1": g[:, 16:19],
        "force_on_body1": g[:, 19:22], "gap": g[:, 22], "slip": g[:, 23:25], "z": g[:, 25:28],
        "interface": g[:, 29].astype(np.int32), "slave_block": g[:, 28].astype(np.int64),
    }
    table["u_body2"] = values_at_blocks(problem, g[:, 28].astype(np.int64))
    table["u_body1"] = table["u_body2"] - g[:, 30:33]  # w = R (u_s − u_master)
    table["area"] = g[:, 33]
    table["pressure"] = -table["force_local_body1"][:, 0] / table["area"]
    table["weighted_gap"] = table["area"] * table["gap"]
    table["state_name"] = np.array([STATE_NAMES[s] for s in table["state"]])
    labels = [i.contact.label for i in model.interfaces]
    table["interface_name"] = np.array([labels[k] for k in table["interface"]])
    return table


def reactions(problem, R=None) -> dict[int, np.ndarray]:
    """Support reaction (force of the support on the body, N) summed per Dirichlet tag.

    At constrained dofs the residual R = F_int − F_ext(ℓ) − Bᵀλ is exactly the support force.
    Only constrained components are counted, each dof once: a dof on two tagged faces (an edge)
    belongs to the first Dirichlet condition that lists it.
    """
    if R is None:
        R = problem.residual()
    n_owned = problem.V.dofmap.index_map.size_local * 3
    arr = R.getArray(readonly=True)
    out = {}
    counted = np.zeros(0, dtype=np.int32)
    for tag, dofs in problem.bc_dofs_by_tag.items():
        # a dof on two tagged faces (an edge) is counted once, with the first tag listing it
        owned = np.setdiff1d(dofs[dofs < n_owned], counted)
        counted = np.union1d(counted, owned)
        local = np.zeros(3)
        np.add.at(local, owned % 3, arr[owned])
        total = np.zeros(3)
        problem.comm.Allreduce(local, total, op=MPI.SUM)
        out[int(tag)] = total
    return out


def applied_load(problem, F_ext: PETSc.Vec | None = None) -> np.ndarray:
    """Resultant of the applied loads F_ext(ℓ) (N), global frame (``F_ext``: if the caller has it)."""
    if F_ext is None:
        F_ext = problem.external_force()
    arr = F_ext.getArray(readonly=True).reshape(-1, 3)
    local = arr.sum(axis=0)
    total = np.zeros(3)
    problem.comm.Allreduce(local, total, op=MPI.SUM)
    return total


def equilibrium_check(problem) -> dict:
    """Global equilibrium: applied load + support reactions + obstacle forces = 0.

    Contact forces between deformable bodies are internal; a rigid obstacle is outside the
    model and its force on the body counts like a reaction. Returns the applied load, the
    reactions per tag, the obstacle forces per interface, their sum, the relative global
    imbalance ‖F_applied + Σ reactions + Σ obstacle forces‖ / max(‖F_applied‖, Σ‖reactions‖,
    Σ‖obstacle forces‖, F_floor), and the relative free-dof residual ‖R_free‖ / F with
    F = max(‖F_ext(ℓ)‖, ‖F_int‖, ‖Bᵀλ‖, F_floor) (meaningful also when only displacements are
    prescribed). F_floor is ``problem.force_floor``, the floor of the solvers' force scale: a
    state without loads (an obstacle that has left the body, every load back at zero) would
    otherwise be divided by its own rounding errors (0/0, which read 1.0).
    """
    # each vector assembled once: F_int(u), F_ext(ℓ), Bᵀλ(z), and R from them
    F_int = problem.assemble_internal_force()
    F_ext = problem.external_force()
    contact_force = problem.contact.global_force(problem.contact.force()) if problem.has_contact else None
    R = problem.residual(F_int=F_int, F_ext=F_ext, contact_force=contact_force)
    react = reactions(problem, R)
    obstacles = problem.contact.obstacle_reactions() if problem.has_contact else {}
    applied = applied_load(problem, F_ext)
    total_reaction = sum(react.values(), np.zeros(3)) + sum(obstacles.values(), np.zeros(3))
    imbalance = applied + total_reaction
    floor = max(problem.force_floor, 1e-300)
    scale = max(np.linalg.norm(applied), sum(np.linalg.norm(r) for r in react.values()),
                sum(np.linalg.norm(r) for r in obstacles.values()), floor)
    R_free = problem.free_residual(R)
    F_scale = max(F_ext.norm(), F_int.norm(), floor)
    if contact_force is not None:
        F_scale = max(F_scale, contact_force.norm())
    return {
        "applied_load": applied, "reactions": react, "obstacle_forces": obstacles, "reaction_sum": total_reaction,
        "global_imbalance": float(np.linalg.norm(imbalance) / scale),
        "residual_norm": float(R_free.norm() / F_scale),
    }
