"""The ``sot-apps`` command.

Each subcommand lives in its own module in this package and exposes
``register(subparsers) -> argparse.ArgumentParser`` that sets ``func`` (``args -> int | None``).
Modules are discovered automatically; one that fails to import is reported, never hidden.
"""

from __future__ import annotations

import os
import signal
import sys

# A worker process that multiprocessing spawned from this program (a Dask worker, a pool worker) imports this
# module again first: Ctrl-C is its parent's to handle (the parent stops its workers), so the worker ignores it
# from here on and never prints its own traceback or line.
if "--multiprocessing-fork" in getattr(sys, "orig_argv", ()):
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _interrupted_while_starting(signum, frame) -> None:
    # Nothing has been written yet, so leave at once: an exception raised here could land inside importlib's
    # module-lock callbacks, where Python prints it as "Exception ignored ..." instead of exiting.
    sys.stderr.write("interrupted\n")
    sys.stderr.flush()
    os._exit(130)


_INTERRUPT_PENDING = False
_OTHER_UNRAISABLE_HOOK = sys.unraisablehook   # the hook main() replaced, for every other unraisable exception
_CAN_REDELIVER = hasattr(signal, "setitimer") and hasattr(signal, "SIGALRM")   # not on Windows


def _inside_an_import(frame) -> bool:
    """Whether ``frame`` runs inside an import: importlib's own code or a module body (or what it calls) that
    importlib is executing."""
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            return True
        frame = frame.f_back
    return False


def _raise_interrupt(signum, frame) -> None:
    """Ctrl-C (SIGINT), or its re-delivery (SIGALRM, below) -> KeyboardInterrupt, handled in main().

    Never inside an import: it is delivered again 10 ms later, until the import is over. Raised in importlib's own
    code (between taking the interpreter's import lock, or a module's lock, and the ``try`` that releases it) it
    can leave the lock held, and every other thread's next import waits for it for ever (seen: the thread that
    starts a Dask LocalCluster, while the main thread, interrupted in an import, waited for that thread); raised in
    a module body that a C extension imports (numpy importing ``datetime``), it becomes an ImportError that says
    nothing of the Ctrl-C (seen: exit 1 with numpy's "bad install" message). A Ctrl-C waits at most for the
    slowest import in progress (Dask's, ~1 s)."""
    global _INTERRUPT_PENDING
    if _CAN_REDELIVER and _inside_an_import(frame):
        _INTERRUPT_PENDING = True
        signal.setitimer(signal.ITIMER_REAL, 0.01)
        return
    _INTERRUPT_PENDING = False
    if _CAN_REDELIVER:
        signal.setitimer(signal.ITIMER_REAL, 0.0)   # one KeyboardInterrupt per Ctrl-C, never a second one later
    raise KeyboardInterrupt


def _redeliver_swallowed_interrupt(unraisable) -> None:
    """``sys.unraisablehook`` while a command runs. A Ctrl-C whose handler runs inside code where Python cannot
    raise (a finalizer such as ``ZipFile.__del__``, a weakref callback such as importlib's module locks, a gc
    callback) is printed as "Exception ignored ..." and lost: the command would go on and exit 0. Here it is
    printed as nothing and delivered again 10 ms later (SIGALRM -> ``_raise_interrupt``), in ordinary code; if it
    lands in such a place again, it comes back here. Any other unraisable exception goes to the hook it replaced."""
    global _INTERRUPT_PENDING
    if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
        _INTERRUPT_PENDING = True
        if _CAN_REDELIVER:
            signal.setitimer(signal.ITIMER_REAL, 0.01)
        return
    _OTHER_UNRAISABLE_HOOK(unraisable)


# As the program (not imported by a test or a library): Ctrl-C during the imports below, before main() handles
# it, exits quietly instead of printing a traceback
# (a worker process spawned by it runs the console script again as "__mp_main__", with the parent's sys.argv: that
# is not the program; multiprocessing itself makes "__mp_main__" an alias of "__main__" in every process)
_AS_PROGRAM = __name__ == "__main__" or (sys.argv[0].endswith("sot-apps")
                                         and sys.modules.get("__mp_main__", sys.modules["__main__"])
                                         is sys.modules["__main__"])
if _AS_PROGRAM:
    signal.signal(signal.SIGINT, _interrupted_while_starting)

import argparse  # noqa: E402
import importlib  # noqa: E402
import pkgutil  # noqa: E402
import re  # noqa: E402
import traceback  # noqa: E402
from typing import Sequence as Seq  # noqa: E402

from ..errors import InputError  # noqa: E402

# Options whose value may start with a minus sign (e.g. --init-box -12.3,4.0,...).
NEGATIVE_VALUE_OPTIONS = {"--init-box", "--pairs", "--origin", "--offset"}
_NEGATIVE_VALUE = re.compile(r"^-\d|^-\.\d")


class OneLineParser(argparse.ArgumentParser):
    """argparse that reports usage errors on one line (exit code 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        sys.stderr.write(f"error: {self.prog}: {message} (see {self.prog} --help)\n")
        raise SystemExit(2)


def _subcommand_modules() -> list[str]:
    package = importlib.import_module("sot_apps.cli")
    names = [m.name for m in pkgutil.iter_modules(package.__path__) if m.name not in ("main", "common")]
    return sorted(n for n in names if not n.startswith("_"))


def _invoked_command(argv: Seq[str]) -> str | None:
    """The subcommand named in ``argv`` (its first token that is not a top-level option), if any."""
    for token in argv:
        if token == "--":
            return None
        if not token.startswith("-"):
            return token
    return None


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``sot-apps`` parser. With ``command`` (the subcommand about to run) only that subcommand's module is
    imported and registered, when one is named after it (``motion-export`` -> ``motion_export.py``): start-up
    then costs one module, not all of them. Anything else (no command, a typo) builds every subcommand."""
    modules = _subcommand_modules()
    if command is not None and command.replace("-", "_") in modules:
        parser = _build_parser([command.replace("-", "_")])
        if command in _subcommand_choices(parser):
            return parser
    return _build_parser(modules)


def _subcommand_choices(parser: argparse.ArgumentParser) -> dict:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action.choices
    return {}


def listing_parser() -> argparse.ArgumentParser:
    """The parser of ``sot-apps`` without a subcommand (``--help``, ``--version``, nothing): every subcommand with
    its help line only (``common.add_subcommand`` stops each ``register`` there), so listing them costs their
    module imports, not their options."""
    return _build_parser(_subcommand_modules(), listing_only=True)


def _build_parser(modules: list[str], listing_only: bool = False) -> argparse.ArgumentParser:
    from .common import SubcommandListed

    parser = OneLineParser(
        prog="sot-apps",
        description="Model-free vehicle tracking (SOTracker) and data generation from LiDAR sequences.",
        epilog="Example: sot-apps info ../shared/data/pandaset_002",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--debug", action="store_true", help="show full tracebacks on errors")
    parser.add_argument("--version", action="version", version=f"sot-apps {_version()}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    subparsers.listing_only = listing_only
    for name in modules:
        module = importlib.import_module(f"sot_apps.cli.{name}")
        register = getattr(module, "register", None)
        if register is not None:
            try:
                _add_debug(register(subparsers))
            except SubcommandListed:
                continue
    return parser


def _add_debug(parser: argparse.ArgumentParser) -> None:
    """``--debug`` after a subcommand, and after a nested action (``bank build``, ``sensor fit``) too."""
    parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show full tracebacks on errors")
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in dict.fromkeys(action.choices.values()):
                _add_debug(child)


def _version() -> str:
    from .. import __version__

    return __version__


def _join_negative_values(argv: list[str]) -> list[str]:
    out: list[str] = []
    i = 0
    while i < len(argv):
        token = argv[i]
        if token in NEGATIVE_VALUE_OPTIONS and i + 1 < len(argv) and _NEGATIVE_VALUE.match(argv[i + 1]):
            out.append(f"{token}={argv[i + 1]}")
            i += 2
            continue
        out.append(token)
        i += 1
    return out


def main(argv: Seq[str] | None = None) -> int:
    global _INTERRUPT_PENDING, _OTHER_UNRAISABLE_HOOK
    signal.signal(signal.SIGINT, _raise_interrupt)   # Ctrl-C -> KeyboardInterrupt, handled below
    previous_alarm = signal.signal(signal.SIGALRM, _raise_interrupt) if _CAN_REDELIVER else None
    _OTHER_UNRAISABLE_HOOK, sys.unraisablehook = sys.unraisablehook, _redeliver_swallowed_interrupt
    _INTERRUPT_PENDING = False
    argv = _join_negative_values(list(sys.argv[1:] if argv is None else argv))
    debug = "--debug" in argv or os.environ.get("SOT_APPS_DEBUG") == "1"
    try:
        command = _invoked_command(argv)
        parser = build_parser(command) if command is not None else listing_parser()
        args = parser.parse_args(argv)
        if not getattr(args, "command", None):
            parser.print_help()
            return 2
        from .common import check_outputs, output_locks

        check_outputs(args)
        with output_locks(args):
            result = args.func(args)
        if _INTERRUPT_PENDING:   # swallowed, and the command ended before the re-delivery
            raise KeyboardInterrupt
        return int(result or 0)
    except InputError as exc:
        if debug:
            traceback.print_exc()
        sys.stderr.write(f"error: {exc.one_line()}\n")
        return 2
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)   # a second Ctrl-C while shutting down prints nothing more
        _report_interrupt()
        return 130
    except BrokenPipeError:
        return 0
    except OSError as exc:   # an environment fault outside the atomic writers (which name the final path)
        from ..io.atomic import is_environment_error

        if not is_environment_error(exc):
            return _unexpected(exc, debug)
        if debug:
            traceback.print_exc()
        where = f"{exc.filename}: " if exc.filename else ""
        sys.stderr.write(f"error: {where}{exc.strerror}\n")
        return 2
    except Exception as exc:  # noqa: BLE001 - last line of defence: one line unless --debug
        return _unexpected(exc, debug)
    finally:
        if _AS_PROGRAM:   # the command is over: a Ctrl-C during interpreter shutdown (atexit, pools) changes nothing
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            # and the interpreter's teardown need not search every object it holds for cycles (~0.1 s of CPU with the
            # pipeline loaded; from a run's end to its exit 1.2-4.3 s -> 0.2-0.4 s on the loaded 2-core VM); atexit
            # handlers and weakref.finalize callbacks still run
            import gc

            gc.freeze()
        if _CAN_REDELIVER:   # no re-delivery once the command is over
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            signal.signal(signal.SIGALRM, previous_alarm)
        sys.unraisablehook = _OTHER_UNRAISABLE_HOOK
        _INTERRUPT_PENDING = False


def _end_progress_lines() -> None:
    """Close every progress bar still open: a Ctrl-C inside a loop leaves its tqdm bar drawn on the current line.

    Closing a bar clears its line (``leave=False``) or ends it with a newline, so what is printed next starts a line
    of its own. A bar that cannot be closed (its stream gone) gets a newline instead.
    """
    tqdm_std = sys.modules.get("tqdm.std")   # no bar can be open if tqdm was never imported
    if tqdm_std is None:
        return
    for bar in list(getattr(tqdm_std.tqdm, "_instances", ())):
        try:
            bar.close()
        except Exception:  # noqa: BLE001 - the interrupt's line must still be printed
            sys.stderr.write("\n")


def _report_interrupt() -> None:
    """The command's last line. Run as the program, the process logs nothing after it: libraries stopping on other
    threads (a Dask cluster still starting when the Ctrl-C came, its scheduler registering plugins) would print
    their INFO lines below it."""
    if _AS_PROGRAM and "logging" in sys.modules:
        sys.modules["logging"].disable(sys.modules["logging"].CRITICAL)
    _end_progress_lines()
    sys.stderr.write("interrupted: finished outputs are kept; rerun to resume\n")


def _caused_by_interrupt(exc: BaseException | None) -> bool:
    """Some library code wraps a Ctrl-C in another exception (e.g. a RuntimeError from ``__set_name__``)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def _unexpected(exc: BaseException, debug: bool) -> int:
    if _caused_by_interrupt(exc):
        _report_interrupt()
        return 130
    if debug:
        traceback.print_exc()
    name = type(exc).__name__
    if name == "error":   # e.g. cv2.error: "error: error: ..." would say nothing
        name = f"{type(exc).__module__}.{name}"
    message = " ".join(str(exc).split()) or name
    sys.stderr.write(f"error: {name}: {message} (rerun with --debug for the traceback)\n")
    return 1


if __name__ == "__main__":
    sys.exit(main())
