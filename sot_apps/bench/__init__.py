"""Benchmarks: ``sot-apps bench NAME ...``.

A benchmark is a module in this package with a ``register(registry)`` function that calls
``registry.add(name, help=..., add_arguments=fn(parser), run=fn(args) -> int)``; modules are discovered
automatically (:func:`discover`), so adding ``sot_apps/bench/foo.py`` adds ``sot-apps bench foo``.
A module that fails to import is reported by ``sot-apps bench`` (never hidden), the others still work.
Benchmarks print tables; README figures quote them. See also :func:`machine_description`.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import platform
import sys
from dataclasses import dataclass, field
from typing import Callable

__all__ = ["Benchmark", "BenchRegistry", "discover", "machine_description", "format_machine", "pin_one_core",
           "module_docstring"]


@dataclass(frozen=True)
class Benchmark:
    name: str
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int | None]
    description: str | None = None
    module: str = ""


@dataclass
class BenchRegistry:
    """Benchmarks by name, in registration order; ``errors`` maps module name to its import error."""

    benchmarks: dict[str, Benchmark] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)
    _module: str = ""

    def add(self, name: str, help: str, add_arguments: Callable[[argparse.ArgumentParser], None],
            run: Callable[[argparse.Namespace], int | None], description: str | None = None) -> None:
        if name in self.benchmarks:
            raise ValueError(f"benchmark {name!r} registered twice ({self.benchmarks[name].module}, {self._module})")
        self.benchmarks[name] = Benchmark(name, help, add_arguments, run, description, self._module)


def discover() -> BenchRegistry:
    """Import every ``sot_apps.bench.*`` module that defines a ``register`` hook and collect what it adds.
    Helper modules without one (e.g. ``benchmark_eval``, run by ``sot-apps eval --benchmark``) are not imported:
    they may import numpy at the top, which ``sot-apps --help`` must not pay for."""
    registry = BenchRegistry()
    package = importlib.import_module(__name__)
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module_name = f"{__name__}.{info.name}"
        if not _defines_register(module_name):
            continue
        try:
            module = importlib.import_module(module_name)
        except Exception as exc:  # noqa: BLE001 - reported by the CLI, never hidden
            registry.errors[module_name] = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
            continue
        register = getattr(module, "register", None)
        if register is not None:
            registry._module = module_name
            register(registry)
    registry._module = ""
    return registry


def _defines_register(name: str) -> bool:
    """Whether module ``name``'s source defines a top-level ``register`` (read, not imported; unreadable: True,
    so that importing it reports the problem)."""
    import importlib.util

    try:
        with open(importlib.util.find_spec(name).origin, encoding="utf-8") as handle:
            return "\ndef register(" in handle.read()
    except (OSError, TypeError, AttributeError, ImportError):
        return True


def module_docstring(name: str) -> str | None:
    """A module's docstring without importing it (a bench's description must not import scipy: CLI start-up)."""
    import ast
    import importlib.util

    with open(importlib.util.find_spec(name).origin, encoding="utf-8") as handle:
        return ast.get_docstring(ast.parse(handle.read()), clean=False)


def pin_one_core() -> str:
    """Pin this process to one CPU (Linux); returns a description for the report."""
    if hasattr(os, "sched_setaffinity"):
        cpu = sorted(os.sched_getaffinity(0))[0]
        os.sched_setaffinity(0, {cpu})
        return f"pinned to cpu {cpu}"
    return "not pinned (no sched_setaffinity)"


def machine_description() -> dict[str, str]:
    """CPU model, core count, load, Python and library versions, thread settings."""
    import numpy
    import scipy

    from ..provenance import cpu_model

    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {
        "cpu": cpu_model(),
        "cores": f"{os.cpu_count()} logical ({affinity} usable by this process)",
        "load_average": " ".join(f"{v:.2f}" for v in load) + " (1/5/15 min; other processes share the machine)",
        "python": sys.version.split()[0],
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "platform": platform.platform(),
        "threads": ", ".join(f"{k}={os.environ.get(k, 'unset')}" for k in
                             ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")),
    }


def format_machine(machine: dict[str, str]) -> str:
    return "\n".join(f"{k:>12}: {v}" for k, v in machine.items())
