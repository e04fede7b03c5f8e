"""Field steps written in memory and copied whole (``dolfinx_nnqem/io/memory_steps.py``, issue 43).

A serial run writes each step file of ``fields.xdmf`` in a tmpfs folder and copies it into the
output folder: DOLFINx's ``XDMFFile`` never opens a file in the output folder, the memory folders
are gone afterwards, and the outputs are those of the same run written in place (every array
equal, every XML file the same text). A failed copy (a full disk) names the file and leaves
no part of the step. Where the step is not written in memory: several ranks, a step too large,
no room in the tmpfs.
"""

from __future__ import annotations

import errno
import os
import time
from pathlib import Path

import numpy as np
import pytest

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
from dolfinx_nnqem.cases.two_beams import DEFAULT_LAW, FREE_END_CORNERS, two_beams_problem
from dolfinx_nnqem.io import field_series, memory_steps
from dolfinx_nnqem.io.output import ResultsWriter
from dolfinx_nnqem.io.reader import read_fields
from dolfinx_nnqem.io.safe_io import OutputError
from dolfinx_nnqem.solvers.registry import make_solver
from dolfinx_nnqem.solvers.stepping import solve_load_steps

INCREMENTS = 2


def _run(problem, folder: Path) -> None:
    problem.reset()
    writer = ResultsWriter(problem, "monolithic", folder, INCREMENTS, probes=FREE_END_CORNERS, pictures=False)
    with make_solver("monolithic", problem) as solver:
        solve_load_steps(problem, solver, INCREMENTS, callbacks=[writer])
    writer.close()


@pytest.fixture(scope="module")
def problem():
    return two_beams_problem(law=DEFAULT_LAW["monolithic"])


def test_a_serial_run_writes_its_steps_in_memory_and_the_same_outputs(problem, tmp_path, monkeypatch):
    folder = memory_steps.memory_folder(1, 1)
    if folder is None:
        pytest.skip(f"no writable tmpfs at {memory_steps.MEMORY_FOLDER}")
    memory_steps.remove_memory_folder(folder)
    opened: list[Path] = []
    xdmf_file = field_series.XDMFFile

    def recording(comm, path, mode):
        opened.append(Path(path))
        return xdmf_file(comm, path, mode)

    monkeypatch.setattr(field_series, "XDMFFile", recording)
    _run(problem, tmp_path / "memory")
    in_memory = list(opened)
    monkeypatch.setattr(field_series, "memory_folder", lambda ranks, needed: None)
    _run(problem, tmp_path / "in_place")
    print(f"\n  step files opened by XDMFFile: {[str(p) for p in in_memory]}")
    assert len(in_memory) == INCREMENTS
    assert all(p.parent.parent == memory_steps.MEMORY_FOLDER and not p.parent.exists() for p in in_memory)
    assert [p.parent for p in opened[INCREMENTS:]] == [tmp_path / "in_place" / "fields"] * INCREMENTS
    for name in ("fields.xdmf", "fields/fields_0001.xdmf", "fields/fields_0002.xdmf", "pairs.pvd"):
        assert (tmp_path / "memory" / name).read_text() == (tmp_path / "in_place" / name).read_text(), name
    written, in_place = read_fields(tmp_path / "memory"), read_fields(tmp_path / "in_place")
    assert len(written) == len(in_place) == INCREMENTS
    for a, b in zip(written, in_place):
        assert set(a) == set(b)
        for key in a:
            assert np.array_equal(np.asarray(a[key]), np.asarray(b[key])), key
    assert np.abs(np.asarray(written[-1]["u"])).max() > 0  # the beams moved


def test_a_failed_copy_names_the_file_and_leaves_no_part_of_the_step(tmp_path, monkeypatch):
    source, target = tmp_path / "memory" / "fields_0001.xdmf", tmp_path / "out" / "fields_0001.xdmf"
    source.parent.mkdir()
    target.parent.mkdir()
    source.with_suffix(".h5").write_bytes(b"h5")
    source.write_text("xml")
    copy = memory_steps.shutil.copyfile

    def full_on_xml(src, dst):
        if str(dst).endswith(".xdmf"):
            raise OSError(errno.ENOSPC, "No space left on device")
        return copy(src, dst)

    monkeypatch.setattr(memory_steps.shutil, "copyfile", full_on_xml)
    with pytest.raises(OutputError, match=f"cannot write {target}: No space left on device"):
        memory_steps.copy_step_files(source, target)
    assert not list(target.parent.iterdir())


def test_where_a_step_is_written_in_place(monkeypatch):
    assert memory_steps.memory_folder(2, 1000) is None  # an HDF5 file of several ranks
    assert memory_steps.memory_folder(1, memory_steps.LARGEST_STEP_BYTES + 1) is None
    monkeypatch.setattr(memory_steps, "MEMORY_FOLDER", Path("/nonexistent-tmpfs"))
    assert memory_steps.memory_folder(1, 1000) is None


def test_the_memory_folder_a_killed_process_left_is_removed(tmp_path, monkeypatch):
    """A SIGKILL while a step is written leaves its memory folder; the next process's first step removes
    it when it is ten minutes old, and not the folder of a process that lives, nor a recent one."""
    import subprocess
    import sys

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    monkeypatch.setattr(memory_steps, "MEMORY_FOLDER", tmp_path)
    left = tmp_path / f"{memory_steps.PREFIX}{int(dead.stdout)}-abc"
    living = tmp_path / f"{memory_steps.PREFIX}{os.getppid()}-abc"
    recent = tmp_path / f"{memory_steps.PREFIX}{int(dead.stdout)}-def"  # maybe of a process this one cannot see
    for folder in (left, living, recent):
        folder.mkdir()
        (folder / "fields_0001.h5").write_bytes(b"h5")
    old = time.time() - memory_steps.STALE_AFTER_S - 60
    for folder in (left, living):
        os.utime(folder, (old, old))
    memory_steps._remove_stale_memory_folders.cache_clear()
    made = memory_steps.memory_folder(1, 1000)
    assert made is not None and made.parent == tmp_path and made.name.startswith(f"{memory_steps.PREFIX}{os.getpid()}-")
    assert not left.exists() and living.exists() and recent.exists()
