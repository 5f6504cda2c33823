"""A Ctrl-C that lands inside an import is delivered after it, never inside it.

Raised in importlib's own code, the KeyboardInterrupt can leave the interpreter's import lock (or a module's lock)
held: the next import of any other thread then waits for ever. Seen as a hang of ``sot-apps run --dask-local 2``
interrupted while it planned: the thread starting the LocalCluster waited for the import lock, the main thread for
that thread. Raised in a module body that a C extension imports, it became an ImportError (exit 1). The end-to-end
check is tests/faults/test_interrupts.py (``run_dask``: SIGINT at random times into the command).
"""

from __future__ import annotations

import signal
import sys

import pytest

from sot_apps.cli import main as cli_main

pytestmark = pytest.mark.skipif(not cli_main._CAN_REDELIVER, reason="re-delivery needs SIGALRM (POSIX)")


def _call_from(filename: str, fn):
    """``fn()`` called from a function whose code says it lives in ``filename``."""
    namespace: dict = {}
    exec(compile("def call(fn):\n    return fn()\n", filename, "exec"), namespace)
    return namespace["call"](fn)


def _handle_sigint_here():
    cli_main._raise_interrupt(signal.SIGINT, sys._getframe())


@pytest.fixture
def alarm_recorder(monkeypatch):
    previous = signal.signal(signal.SIGALRM, lambda signum, frame: None)
    yield
    signal.setitimer(signal.ITIMER_REAL, 0.0)
    signal.signal(signal.SIGALRM, previous)
    monkeypatch.setattr(cli_main, "_INTERRUPT_PENDING", False)


@pytest.mark.parametrize("where", ["importlib's code", "a module body importlib runs"])
def test_interrupt_inside_an_import_is_delivered_again_later(where, alarm_recorder):
    if where == "importlib's code":
        _call_from("<frozen importlib._bootstrap>", lambda: cli_main._raise_interrupt(signal.SIGINT,
                                                                                     sys._getframe(1)))
    else:   # the handler's frame is ordinary code, called (some frames up) by importlib
        _call_from("<frozen importlib._bootstrap>", lambda: _call_from("/some/module.py", _handle_sigint_here))
    assert cli_main._INTERRUPT_PENDING   # no exception: held
    assert 0.0 < signal.getitimer(signal.ITIMER_REAL)[0] <= 0.01   # armed: delivered again in 10 ms


def test_interrupt_in_ordinary_code_raises_and_disarms(alarm_recorder):
    signal.setitimer(signal.ITIMER_REAL, 0.01)   # as after a held Ctrl-C
    cli_main._INTERRUPT_PENDING = True
    with pytest.raises(KeyboardInterrupt):
        _call_from("/some/module.py", _handle_sigint_here)
    assert not cli_main._INTERRUPT_PENDING
    assert signal.getitimer(signal.ITIMER_REAL)[0] == 0.0   # one KeyboardInterrupt per Ctrl-C


@pytest.mark.parametrize("leave", [False, True])
def test_interrupt_line_starts_its_own_line_when_a_progress_bar_is_open(leave, monkeypatch, capsys):
    """Seen in CI: a Ctrl-C while a bar showed 0 % printed 'interrupted: ...' on the bar's line, with no newline."""
    import argparse

    from tqdm import tqdm

    def interrupted_in_a_loop(args):
        bar = tqdm(total=10, desc="work", file=sys.stderr, mininterval=0, leave=leave)   # e.g. the executors' bar
        bar.refresh()   # drawn at 0 %; the traceback keeps this frame, and the bar open, while main handles it
        raise KeyboardInterrupt

    def parser_of(command=None):
        parser = argparse.ArgumentParser()
        parser.add_argument("command")
        parser.set_defaults(func=interrupted_in_a_loop)
        return parser

    monkeypatch.setattr(cli_main, "build_parser", parser_of)
    previous_int = signal.getsignal(signal.SIGINT)
    try:
        assert cli_main.main(["loop"]) == 130
    finally:
        signal.signal(signal.SIGINT, previous_int)
    err = capsys.readouterr().err
    assert "work" in err   # the bar was drawn
    last_line = err.replace("\r", "\n").rstrip("\n").splitlines()[-1]
    assert last_line == "interrupted: finished outputs are kept; rerun to resume"


def test_nothing_is_logged_after_the_interrupt_line(monkeypatch, capsys):
    """Seen in CI: a Dask cluster still starting when the Ctrl-C came logged an INFO line after 'interrupted'."""
    import logging

    logger = logging.getLogger("sot_apps.test.after_interrupt")
    handler = logging.StreamHandler(sys.stderr)
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    monkeypatch.setattr(cli_main, "_AS_PROGRAM", True)
    try:
        logger.info("before")
        cli_main._report_interrupt()
        logger.warning("after")   # e.g. from another thread still stopping
    finally:
        logging.disable(logging.NOTSET)
        logger.removeHandler(handler)
    assert capsys.readouterr().err.splitlines() == ["before", "interrupted: finished outputs are kept; rerun to resume"]
