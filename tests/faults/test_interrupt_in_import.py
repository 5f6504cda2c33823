"""A Ctrl-C that lands inside importlib's own code is delivered after it, never inside it.

Raised there, the KeyboardInterrupt can leave the interpreter's import lock (or a module's lock) held: the next
import of any other thread then waits for ever. Seen as a hang of ``sot-apps run --dask-local 2`` interrupted while
it planned: the thread starting the LocalCluster waited for the import lock, the main thread for that thread.
The end-to-end check is tests/faults/test_interrupts.py (``run_dask``: SIGINT at random times into the command).
"""

from __future__ import annotations

import signal

import pytest

from sot_apps.cli import main as cli_main

pytestmark = pytest.mark.skipif(not cli_main._CAN_REDELIVER, reason="re-delivery needs SIGALRM (POSIX)")


def _frame_in(filename: str):
    namespace: dict = {}
    exec(compile("import sys\ndef here():\n    return sys._getframe()\n", filename, "exec"), namespace)
    return namespace["here"]()


def test_interrupt_inside_importlib_is_delivered_again_later(monkeypatch):
    alarms: list[int] = []
    previous = signal.signal(signal.SIGALRM, lambda signum, frame: alarms.append(signum))
    try:
        cli_main._raise_interrupt(signal.SIGINT, _frame_in("<frozen importlib._bootstrap>"))   # no exception
        assert cli_main._INTERRUPT_PENDING
        assert 0.0 < signal.getitimer(signal.ITIMER_REAL)[0] <= 0.01   # armed: delivered again in 10 ms
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        # the re-delivery, landing in ordinary code (a module body included), raises and disarms
        with pytest.raises(KeyboardInterrupt):
            cli_main._raise_interrupt(signal.SIGALRM, _frame_in("/some/module.py"))
        assert not cli_main._INTERRUPT_PENDING
        assert signal.getitimer(signal.ITIMER_REAL)[0] == 0.0
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)
        monkeypatch.setattr(cli_main, "_INTERRUPT_PENDING", False)
