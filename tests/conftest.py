"""Shared fixtures. ``dolfinx_nnqem`` is imported first (the PyPI wheel needs it before dolfinx)."""

import os
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (must precede dolfinx / petsc4py)
import numpy as np
import pytest
from mpi4py import MPI

TESTS = Path(__file__).resolve().parent
"""The test folder: ``unit/``, ``integration/``, ``reliability/`` and ``mpi/`` (``CONTRIBUTING.md``)."""

# the end-of-run pictures cost seconds per run: off for the suite's many runs, on (the users'
# default) in tests/integration/test_run_pictures.py, which removes this switch
os.environ.setdefault("DOLFINX_NNQEM_PICTURES", "0")


def box_with_face_tags(n=(2, 2, 2), L=(1.0, 1.0, 1.0), cell="hexahedron"):
    """A box [0,Lx]×[0,Ly]×[0,Lz] with facet tags 1..6 = x−, x+, y−, y+, z−, z+."""
    import dolfinx.mesh as dmesh

    cell_type = {"hexahedron": dmesh.CellType.hexahedron, "tetrahedron": dmesh.CellType.tetrahedron}[cell]
    mesh = dmesh.create_box(MPI.COMM_WORLD, [np.zeros(3), np.asarray(L, float)], list(n), cell_type)
    fdim = mesh.topology.dim - 1
    facets, values = [], []
    for tag, (axis, side) in enumerate([(0, 0), (0, 1), (1, 0), (1, 1), (2, 0), (2, 1)], start=1):
        coord = 0.0 if side == 0 else L[axis]
        f = dmesh.locate_entities_boundary(mesh, fdim, lambda x, a=axis, c=coord: np.isclose(x[a], c))
        facets.append(f)
        values.append(np.full(len(f), tag, dtype=np.int32))
    facets, values = np.concatenate(facets), np.concatenate(values)
    order = np.argsort(facets)
    facet_tags = dmesh.meshtags(mesh, fdim, facets[order], values[order])
    return mesh, facet_tags


@pytest.fixture
def box_factory():
    return box_with_face_tags


FAST_TIER = (
    "unit/test_api_coverage.py", "unit/test_compat.py", "unit/test_contracts.py", "unit/test_drucker_prager.py",
    "unit/test_dual_quadratic.py", "unit/test_function_sizes.py", "unit/test_kinematic_hardening.py",
    "unit/test_laws.py", "unit/test_material.py", "unit/test_mortar_geometry.py", "unit/test_nonsmooth.py",
    "unit/test_problem_file_doc.py",
)
"""The fast tier (``scripts/run-tests --fast``, under 2 minutes): the unit tests of the layers'
pieces — the pair laws and their Jacobians, the nonsmooth Newton driver, the return maps and
hardening laws against closed forms, the mortar geometry and quadratic facets — and the
contracts (layers, Protocols, moved names, sizes, docstrings). No test here solves a load path."""


LONG_RUNS = TESTS / "long_runs.txt"
"""The default run's long tests, one test id per line (``folder/file.py::test[param]``, relative to
this folder): marked ``slow`` here, so that the default suite stays within minutes (issue 42).
Chosen by measured time (the file's header says how); they run with ``-m slow`` or ``--all``."""


def pytest_addoption(parser):
    parser.addoption("--fast", action="store_true", default=False,
                     help="run only the fast tier (tests/conftest.py FAST_TIER): the edit-test loop")
    parser.addoption("--all", action="store_true", default=False,
                     help="run every test: the default tier and the slow one (-m slow runs the slow tier alone)")


def long_runs() -> set[str]:
    """The test ids of :data:`LONG_RUNS` (comments and blank lines left out)."""
    lines = (line.split("#", 1)[0].strip() for line in LONG_RUNS.read_text(encoding="utf-8").splitlines())
    return {line for line in lines if line}


def _test_id(item: pytest.Item) -> str:
    """``folder/file.py::name[param]`` relative to this folder (the form of :data:`LONG_RUNS`)."""
    return item.nodeid.split("tests/", 1)[-1] if item.nodeid.startswith("tests/") else item.nodeid


def _mark_long_runs(items: list[pytest.Item]) -> None:
    """Mark the tests of :data:`LONG_RUNS` ``slow``; a listed test of a collected file that no longer
    exists is an error (renamed or removed: the list must follow, or its run would silently join
    the default tier under a new name)."""
    listed = long_runs()
    collected = {_test_id(item): item for item in items}
    files = {test_id.split("::", 1)[0] for test_id in collected}
    stale = sorted(test_id for test_id in listed if test_id.split("::", 1)[0] in files and test_id not in collected)
    if stale:
        raise pytest.UsageError(f"{LONG_RUNS.name} lists tests that do not exist: {', '.join(stale)}")
    for test_id in listed & collected.keys():
        collected[test_id].add_marker(pytest.mark.slow)


@pytest.fixture(autouse=True)
def _one_mpi_job_at_a_time(request, tmp_path_factory):
    """A test marked ``mpi`` holds an exclusive lock while it runs: with pytest-xdist
    (``scripts/run-tests`` on several cores) two ``mpiexec`` jobs at once would put four or five
    busy-polling ranks on a 2-core machine (measured: a 3-rank job next to a 2-rank one made no
    progress in 10 minutes). The lock file is in the directory the workers' temporary folders
    share. (xdist's ``loadgroup`` cannot do it here: with pytest 9 its group suffix is not applied.)"""
    if "mpi" not in request.node.keywords:
        yield
        return
    import fcntl

    with open(tmp_path_factory.getbasetemp().parent / "dolfinx_nnqem-mpi.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


def _in_fast_tier(item: pytest.Item) -> bool:
    """Whether a test's file is in :data:`FAST_TIER` (paths relative to this folder)."""
    path = item.path.resolve()
    return path.is_relative_to(TESTS) and path.relative_to(TESTS).as_posix() in FAST_TIER


def pytest_collection_modifyitems(config, items):
    """Tests marked ``slow`` (and those of :data:`LONG_RUNS`) run only when asked for (``-m slow``
    alone, ``--all`` with the rest); the default run deselects them. With ``--fast``, only the
    files of :data:`FAST_TIER` run."""
    _mark_long_runs(items)
    if config.getoption("fast"):
        other = [item for item in items if not _in_fast_tier(item)]
        if other:
            config.hook.pytest_deselected(items=other)
            items[:] = [item for item in items if _in_fast_tier(item)]
    if config.getoption("all") or "slow" in (config.getoption("markexpr") or ""):
        return
    slow = [item for item in items if "slow" in item.keywords]
    if slow:
        config.hook.pytest_deselected(items=slow)
        items[:] = [item for item in items if "slow" not in item.keywords]
