"""The commit point's renames cannot be cut half-way by Ctrl-C or SIGTERM (interrupts.held).

Found by the two-beam signal test: a SIGINT that arrived between two renames of a commit point
left a staged ``.summary.json.tmp-PID-staged`` behind (1 run of the default suite).
"""

import os
import signal

import pytest

from dolfinx_nnqem import interrupts
from dolfinx_nnqem.io.safe_io import StagedFiles


@pytest.fixture(autouse=True)
def python_sigint_handler():
    """Python's own Ctrl-C handler during the test: an earlier in-process ``cli.main`` leaves its
    handler, which records the signal in ``interrupts.received``, and a later test's
    ResultsWriter would then take its run for an interrupted one."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def test_a_signal_inside_held_is_raised_when_the_block_ends():
    reached_the_end = False
    with pytest.raises(KeyboardInterrupt):
        with interrupts.held():
            os.kill(os.getpid(), signal.SIGINT)
            reached_the_end = True
    assert reached_the_end
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the handler in place before


def test_an_interrupt_during_the_renames_leaves_every_file_renamed(tmp_path, monkeypatch):
    staged = StagedFiles()
    for name in ("fields.xdmf", "pairs.pvd", "summary.json"):
        staged.stage(tmp_path / name, f"new {name}")
    real_replace = os.replace
    calls = []

    def replace_then_interrupt(src, dst):
        real_replace(src, dst)
        calls.append(dst)
        if len(calls) == 1:
            os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C after the first rename

    monkeypatch.setattr(os, "replace", replace_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        staged.replace_all()
    names = sorted(p.name for p in tmp_path.iterdir())
    print(f"\n  renames before the interrupt was raised: {len(calls)}; files: {names}")
    assert len(calls) == 3 and names == ["fields.xdmf", "pairs.pvd", "summary.json"]
    assert (tmp_path / "summary.json").read_text() == "new summary.json"


def test_an_interrupt_during_a_checkpoints_sync_leaves_no_staged_latest(tmp_path, monkeypatch):
    """Found by the SIGTERM test of the command line (1 run of CI in about 10): a signal during
    the checkpoint's sync left ``checkpoints/.latest.json.tmp-PID-staged``, which no writer ended."""
    from dolfinx_nnqem.cases.two_beams import two_beams_problem
    from dolfinx_nnqem.io import checkpoint, safe_io
    from dolfinx_nnqem.solvers.stepping import StepperState

    problem = two_beams_problem(law="alart-curnier")
    checkpointer = checkpoint.Checkpointer(tmp_path)
    checkpointer.save(problem, StepperState(start=0.0, step=0.1, cutbacks=0, index=1))
    latest = (tmp_path / "checkpoints" / "latest.json").read_text()

    def sync_then_interrupt(folder):
        os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C while the file system is synced

    monkeypatch.setattr(safe_io, "sync_file_system", sync_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        checkpointer.save(problem, StepperState(start=0.0, step=0.1, cutbacks=0, index=2))
    left = sorted(p.name for p in tmp_path.rglob(".*.tmp-*"))
    print(f"\n  temporaries left: {left}; latest.json {(tmp_path / 'checkpoints' / 'latest.json').read_text()}")
    assert not left
    assert (tmp_path / "checkpoints" / "latest.json").read_text() == latest  # the previous checkpoint
