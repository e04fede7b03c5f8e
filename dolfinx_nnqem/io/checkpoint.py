"""Checkpoint and restart: everything the next increment needs, written every N increments.

Format: one numpy ``.npz`` archive per rank (numpy's documented zip of ``.npy`` arrays),
chosen after measuring the alternatives (``docs/reliability.md``): adios4dolfinx needs the
``adios2`` Python module with MPI, which PyPI does not have (its wheel is serial; Debian 13 has
``python3-adios4dolfinx`` 0.9.3 with MPI); h5py cannot share a process with the PyPI DOLFINx
wheel, which loads its own HDF5 first (h5py then fails with "Not a datatype")::

    OUT/checkpoints/latest.json              the last COMPLETE checkpoint (replaced atomically)
    OUT/checkpoints/ckpt_K/rank_R.npz        rank R's part of the state after increment K
    OUT/checkpoints/ckpt_K/meta.json         load stepping, writers' state, fingerprint

Each rank's file holds its local arrays, ghosts included: the displacement u and u_n, the
Gauss-point state σ_n, p_n, Δp_n, Δε_p,n, the contact model's z, z_n, w_n, state_n, slip_n, the load
factors and the secant predictor's history (:attr:`ContactProblem.predictor_history`), plus a
fingerprint of the rank's layout (owned dofs and their coordinates, Gauss points, pairs). A
checkpoint is complete when every rank's file and ``meta.json`` are on disk; only then does
rank 0 replace ``latest.json`` (temporary + rename), so a kill at any moment leaves the previous
complete checkpoint in force. The checkpoint shares its increment's commit point with the
writers it was given (:func:`dolfinx_nnqem.io.safe_io.commit`): one sync makes every rank's
file, ``meta.json`` and the increment's result files durable, then the writers' index files
and ``latest.json`` are renamed into place. The last ``keep`` checkpoints are kept (at least
two on disk: the one ``latest.json`` named at the last sync stays until the new name is durable).

A restart needs the same problem on the same number of ranks (the same partition: DOLFINx
partitions a mesh deterministically for a given rank count); anything else is refused with a
message saying what differs. Restarted runs continue bit for bit: the test compares a killed and
restarted run with an uninterrupted one to 1e-12.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from dolfinx_nnqem.collective import agree, on_rank0
from dolfinx_nnqem.io.safe_io import StagedFiles, atomic_write, commit
from dolfinx_nnqem.problem.validation import check_integer
from dolfinx_nnqem.solvers.stepping import StepperState

if TYPE_CHECKING:
    from dolfinx_nnqem.problem.contact_problem import ContactProblem

__all__ = ["CheckpointError", "Checkpointer", "latest_checkpoint", "restore"]

FOLDER = "checkpoints"
FORMAT = 1


class CheckpointError(ValueError):
    """A checkpoint is missing, incomplete, or belongs to another problem or rank count."""


def _fingerprint(problem) -> dict:
    """What must match between the run that wrote a checkpoint and the one that reads it (this rank)."""
    imap = problem.V.dofmap.index_map
    x = problem.V.tabulate_dof_coordinates()[:imap.size_local]
    digest = hashlib.sha256(np.ascontiguousarray(np.round(x, 12)).tobytes()).hexdigest()[:16]
    return {
        "owned_nodes": int(imap.size_local), "ghost_nodes": int(imap.num_ghosts),
        "local_range": [int(v) for v in imap.local_range], "global_nodes": int(imap.size_global),
        "node_coordinates": digest,
        "gauss_points": int(problem.state.W_scalar.dofmap.index_map.size_local),
        "pairs": _pairs_fixed(problem, int(problem.contact.num_local) if problem.has_contact else 0),
    }


def _pairs_fixed(problem, pairs: int) -> int:
    """``pairs``, or −1 where the contact geometry follows (or may come to follow) the bodies (the pairs
    then depend on u and are evaluated again when the checkpoint is read, :func:`_read_contact`)."""
    return -1 if problem.has_contact and problem.contact.geometry.pairs_may_change else pairs


def _global_fingerprint(problem) -> dict:
    return {"ranks": int(problem.comm.size), "nodes": int(problem.V.dofmap.index_map.size_global),
            "gauss_points": int(problem.state.num_gauss_points()), "pairs": _pairs_fixed(problem, int(problem.num_pairs))}


def latest_checkpoint(folder: str | os.PathLike) -> dict | None:
    """The content of ``checkpoints/latest.json`` in an output folder, or None."""
    path = Path(folder) / FOLDER / "latest.json"
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as error:
        raise CheckpointError(f"{path}: unreadable ({error})") from None


class Checkpointer:
    """Writes a checkpoint every ``every`` increments (pass as ``checkpoint=`` to
    :func:`~dolfinx_nnqem.solvers.stepping.solve_load_steps`).

    Parameters
    ----------
    folder
        The run's output folder (checkpoints go to ``folder/checkpoints``).
    every
        Checkpoint every N converged increments (1: each).
    keep
        How many complete checkpoints to keep (older ones are removed).
    writers
        Objects with ``state() -> dict`` (JSON) whose state is saved with the checkpoint and
        handed back by :func:`restore` (e.g. the :class:`~dolfinx_nnqem.io.output.ResultsWriter`).
        A writer with ``staged`` files and ``checkpoint_every`` (the ``ResultsWriter``) leaves
        the commit of the increments this checkpointer saves to it.
    meta
        Further JSON data saved with every checkpoint (e.g. the problem file's hash); a restart
        may compare it.
    """

    def __init__(self, folder: str | os.PathLike, every: int = 1, keep: int = 2, writers=(), meta: dict | None = None):
        self.folder = Path(folder) / FOLDER
        self.every = check_integer("checkpoint every", every, low=1, high=10**9)
        self.keep = check_integer("checkpoint keep", keep, low=1, high=10**6)
        self.writers = list(writers)
        self.meta = dict(meta or {})
        self.written: list[int] = []
        self.staged = StagedFiles()  # latest.json, renamed at the commit point
        for w in self.writers:
            if hasattr(w, "staged") and hasattr(w, "checkpoint_every"):
                w.checkpoint_every = self.every

    def __call__(self, problem, stepper_state, result) -> None:
        if result.index % self.every == 0:
            self.save(problem, stepper_state)

    def save(self, problem: ContactProblem, stepper_state: StepperState) -> Path:
        """Write the checkpoint of the current (committed) state (collective)."""
        comm = problem.comm
        index = int(stepper_state.index)
        name = f"ckpt_{index:05d}"
        target = self.folder / name

        def fresh_folder() -> None:
            shutil.rmtree(target, ignore_errors=True)
            target.mkdir(parents=True)

        on_rank0(comm, fresh_folder)
        path = target / f"rank_{comm.rank:04d}.npz"
        agree(comm, atomic_write, path, lambda tmp: _write_rank(tmp, problem), durable=False)
        meta = {
            "format": FORMAT, "index": index, "load_factor": float(problem.load_factor_n),
            "stepper": {"start": float(stepper_state.start), "step": float(stepper_state.step),
                        "cutbacks": int(stepper_state.cutbacks), "index": index},
            "problem": _global_fingerprint(problem),
            "writers": [w.state() for w in self.writers],
            **self.meta,
        }

        def stage():
            text = _json(meta)  # now: the writers' state is theirs, not a copy
            atomic_write(target / "meta.json", lambda tmp: tmp.write_text(text), durable=False)
            self.staged.stage(self.folder / "latest.json", json.dumps(
                {"index": index, "path": name, "ranks": comm.size, "load_factor": meta["load_factor"]}))

        def tidy():
            self.written.append(index)
            kept = sorted(p for p in self.folder.glob("ckpt_*") if p.is_dir())
            for old in kept[:-max(self.keep, 2)]:
                shutil.rmtree(old, ignore_errors=True)

        folder = self.folder.parent
        try:
            on_rank0(comm, stage)
            commit(comm, folder, *[w.staged for w in self.writers if isinstance(getattr(w, "staged", None), StagedFiles)],
                   self.staged)
        except BaseException:
            # Ctrl-C, SIGTERM or an error before the renames (the sync takes up to 0.2 s): the
            # staged latest.json is dropped, so the previous checkpoint stays the latest one.
            # Nothing else ends this object's staged files (the run's writer ends only its own).
            self.staged.discard()
            raise
        on_rank0(comm, tidy)
        return target


def _json(value) -> str:
    """``value`` as JSON text through the C encoder; numpy values and non-finite floats, where
    there are any, first made JSON-ready (:func:`~dolfinx_nnqem.io.output.jsonable_copy`)."""
    try:
        return json.dumps(value, allow_nan=False)
    except (TypeError, ValueError):
        from dolfinx_nnqem.io.output import jsonable_copy

        return json.dumps(jsonable_copy(value))


def _write_rank(tmp: Path, problem) -> None:
    arrays = {"u": problem.u.x.array, **problem.state.checkpoint_arrays()}
    info = {"format": FORMAT, "fingerprint": _fingerprint(problem), "load_factor_n": float(problem.load_factor_n),
            "load_factor": float(problem.load_factor)}
    if problem.has_contact:
        c = problem.contact
        for name in ("z", "z_n", "w_n", "state_n", "slip_n"):
            arrays[f"contact_{name}"] = getattr(c, name)
        for k, facets in enumerate(c.geometry.state()):
            if facets is not None:
                arrays[f"contact_facets_{k}"] = facets
        arrays["contact_following"] = np.array(c.geometry.following, dtype=bool)
    history = problem.predictor_history
    if history is not None:
        ell, u_prev, z_prev = history
        info["previous_load_factor"] = float(ell)
        arrays["previous_u"] = u_prev
        if z_prev is not None:
            arrays["previous_z"] = z_prev
    arrays["info"] = np.frombuffer(json.dumps(info).encode(), dtype=np.uint8)
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)


def restore(problem: ContactProblem, folder: str | os.PathLike,
            expected_meta: dict | None = None) -> tuple[StepperState, dict]:
    """Load the last complete checkpoint of an output folder into ``problem`` (collective).

    Returns ``(stepper_state, meta)``: the :class:`~dolfinx_nnqem.solvers.stepping.StepperState` to pass
    as ``resume=`` to :func:`~dolfinx_nnqem.solvers.stepping.solve_load_steps`, and the checkpoint's
    meta data (``meta["writers"]``: the writers' saved states). ``expected_meta``: keys that
    must equal the saved ones (e.g. the problem file's hash).

    Raises :class:`CheckpointError` (on every rank) when there is no complete checkpoint, or it
    was written by another number of ranks or for another problem.
    """
    comm = problem.comm
    folder = Path(folder)

    def read_meta():
        latest = latest_checkpoint(folder)
        if latest is None:
            raise CheckpointError(f"{folder}: no complete checkpoint to restart from ({folder / FOLDER / 'latest.json'} "
                                  "is missing)")
        if latest["ranks"] != comm.size:
            raise CheckpointError(f"{folder}: the checkpoint was written by {latest['ranks']} MPI rank(s); restart "
                                  f"it on {latest['ranks']} (this run has {comm.size}): each rank's file holds "
                                  "its own part of the mesh")
        meta_path = folder / FOLDER / latest["path"] / "meta.json"
        try:
            meta = json.loads(meta_path.read_text())
        except (OSError, ValueError) as error:
            raise CheckpointError(f"{meta_path}: unreadable ({error})") from None
        if meta.get("format") != FORMAT:
            raise CheckpointError(f"{meta_path}: format {meta.get('format')} is not {FORMAT}")
        mine = _global_fingerprint(problem)
        if meta["problem"] != mine:
            raise CheckpointError(f"{folder}: the checkpoint belongs to another problem (saved {meta['problem']}, "
                                  f"this one {mine})")
        for key, value in (expected_meta or {}).items():
            if meta.get(key) != value:
                raise CheckpointError(f"{folder}: the checkpoint was written with {key} = {meta.get(key)!r}, "
                                      f"this run has {value!r}; restart with the same input (or start anew with "
                                      "--overwrite)")
        return latest, meta

    latest, meta = agree(comm, read_meta)
    path = folder / FOLDER / latest["path"] / f"rank_{comm.rank:04d}.npz"
    agree(comm, _read_rank, path, problem)
    s = meta["stepper"]
    return StepperState(float(s["start"]), float(s["step"]), int(s["cutbacks"]), int(s["index"])), meta


def _read_contact(data, path: Path, problem) -> None:
    """The pair unknowns; where the geometry follows the bodies, the pairs are first evaluated where
    the checkpoint's last increment ended (u, ℓ_n), with the master facets it had (collective)."""
    c = problem.contact
    if "contact_following" in data:  # interfaces that geometry = "auto" moved to the current geometry
        for k, following in enumerate(data["contact_following"]):
            if following:
                c.geometry.start_following(k)
    if c.geometry.follows_bodies:
        c.geometry.set_state([data[f"contact_facets_{k}"] if f"contact_facets_{k}" in data else None
                              for k in range(len(c.interfaces))])
        c.geometry.update(problem.u, problem.load_factor_n, problem.state.u_n, problem.load_factor_n)
    if len(data["contact_z"]) != c.num_local:
        raise CheckpointError(f"{path}: {len(data['contact_z'])} pairs saved, {c.num_local} evaluated from the "
                              "saved displacement")
    for name in ("z", "z_n", "w_n", "state_n", "slip_n"):
        setattr(c, name, np.array(data[f"contact_{name}"], dtype=getattr(c, name).dtype))


def _read_rank(path: Path, problem) -> None:
    try:
        data = np.load(path, allow_pickle=False)
        info = json.loads(data["info"].tobytes().decode())
    except (OSError, ValueError, KeyError) as error:
        raise CheckpointError(f"{path}: unreadable ({error})") from None
    with data:
        saved = info["fingerprint"]
        mine = _fingerprint(problem)
        if saved != mine:
            differs = sorted(k for k in mine if saved.get(k) != mine[k])
            raise CheckpointError(f"{path}: this rank's part of the mesh differs from the checkpoint's ({differs}); "
                                  "the problem or the partition changed")
        problem.u.x.array[:] = data["u"]
        try:  # an earlier checkpoint's "deps_p_n" (state no solver read) is not read
            problem.state.restore_arrays({name: data[name] for name in problem.state.checkpoint_arrays()})
        except KeyError as error:
            raise CheckpointError(f"{path}: no array {error} (the checkpoint is of another material)") from None
        problem.load_factor_n = float(info["load_factor_n"])
        problem.load_factor = float(info["load_factor"])
        if problem.has_contact:
            _read_contact(data, path, problem)
        if "previous_u" in data:
            problem.set_predictor_history((info["previous_load_factor"], data["previous_u"],
                                           data["previous_z"] if "previous_z" in data else None))
        else:
            problem.set_predictor_history(None)
