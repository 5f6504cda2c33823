"""Issue 16 defect 4 and "Faults to survive": Ctrl-C (SIGINT to the process group) at random times into run
(2 worker processes), demo, convert, flow and synth. No traceback, exit 130 with one line, and the rerun ends
byte-identical to a clean run. The suite runs 2-3 trials per command (11 in all, about 2-3 min on a loaded
2-core machine); ``python tests/faults/interrupt_driver.py --trials 20`` runs the issue's 20 per command."""

from __future__ import annotations

import random

import pytest

from .interrupt_driver import tiny_world, trials_for

TRIALS = {"run": 3, "demo": 2, "convert": 2, "flow": 2, "synth": 2}


@pytest.fixture(scope="module")
def interrupt_world(tmp_path_factory):
    return tiny_world(tmp_path_factory.mktemp("interrupt_world"))


@pytest.mark.parametrize("command", sorted(TRIALS))
def test_interrupts_print_no_traceback_and_resume_byte_identical(command, interrupt_world, tmp_path):
    result = trials_for(command, TRIALS[command], random.Random(f"{command}-16"), interrupt_world, tmp_path)
    assert not result.problems, "\n".join(result.problems)
    assert result.exit_codes and 130 in result.exit_codes, result.line()


def test_ctrl_c_inside_an_import_is_delivered_again_after_it():
    """A KeyboardInterrupt raised in importlib's module-lock callbacks is printed as "Exception ignored" and lost
    (seen once in CI: exit 0 with that text). The handler defers it there and raises it elsewhere."""
    import signal
    import types

    from sot_apps.cli.main import _raise_interrupt

    def frame(filename, back=None):
        return types.SimpleNamespace(f_code=types.SimpleNamespace(co_filename=filename), f_back=back)

    with pytest.raises(KeyboardInterrupt):
        _raise_interrupt(signal.SIGINT, frame("/work/sot_apps/cli/run.py", frame("<string>")))
    before = signal.getsignal(signal.SIGALRM)
    try:
        inside_import = frame("<frozen importlib._bootstrap>", frame("/work/sot_apps/cli/run.py"))
        assert _raise_interrupt(signal.SIGINT, inside_import) is None     # not raised here ...
        assert signal.getsignal(signal.SIGALRM) is _raise_interrupt
        assert 0.0 < signal.getitimer(signal.ITIMER_REAL)[0] <= 0.01    # ... but again in 10 ms
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, before)
