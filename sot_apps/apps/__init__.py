"""Plug-in apps: the :class:`App` protocol and the registry (entry-point group ``sot_apps.apps``).

Tracking is the core stage of a pipeline run; every later stage is an app. An app is an object with

- ``name``: its stage name in a pipeline file (``stages.<name>``) and its entry-point name;
- ``config_type``: a frozen dataclass, its configuration section (built from ``stages.<name>`` by
  :func:`build_config`; an unknown or mistyped field is an error naming ``stages.<name>.<field>``);
- ``description`` and ``outputs`` (the files it writes, relative to the run's output directory, for
  ``sot-apps apps`` and docs); ``needs``: the apps whose outputs it reads (they run in an earlier batch);
- ``plan(config, run)``: its units of work from the run's finished tracks (:class:`RunContext`), each a
  :class:`Unit` (or a :class:`Skip` with the reason);
- ``run(config, out, **unit.args)``: do one unit, write its files through ``sot_apps.io`` writers (atomic) and
  return a :class:`UnitOutput` (the files and a JSON-able summary);
- ``finish(config, out, results)``: after all its units, e.g. an index over them (optional).

The pipeline gives every app the same machinery: a unit whose completion marker is valid is skipped (resume),
a failed unit is recorded in ``failures.json`` and the run goes on, and ``manifest.json`` lists each unit with
its status, summary and output checksums. Apps are discovered through the entry-point group ``sot_apps.apps``
(``name = "package.module:AppClass"``); the built-in apps are registered there too (pyproject.toml).
"""

from __future__ import annotations

import dataclasses
import functools
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Protocol, runtime_checkable

from ..errors import InputError

__all__ = ["ENTRY_POINT_GROUP", "App", "AppBase", "SequenceTracks", "RunContext", "Unit", "Skip", "UnitOutput",
           "installed_apps", "get_app", "build_config", "config_fields", "describe", "track_dir", "V1_APPS"]

ENTRY_POINT_GROUP = "sot_apps.apps"

# The built-in apps, as pyproject.toml registers them. Used only for a name the installed metadata does not
# list (an editable install made before the entry points existed); tests/apps checks both lists agree.
BUILTIN_APPS = {
    "bank": "sot_apps.apps.bank:BankApp",
    "motion": "sot_apps.apps.motion:MotionApp",
    "flow": "sot_apps.apps.flow:FlowApp",
    "scans": "sot_apps.apps.scans:ScansApp",
    "autolabels": "sot_apps.apps.autolabels:AutoLabelsApp",
}


# Version 1 of the pipeline file: these apps run unless their section says "enabled": false; any other installed
# app runs when the file has a section for it.
V1_APPS = ("bank", "motion", "flow", "scans")


def track_dir(out: str | Path, sequence: str, object_id: str) -> Path:
    """Where the tracking stage writes one object: ``OUT/<sequence>/tracks/<object>/`` (track.json, shape.ply)."""
    return Path(out) / sequence / "tracks" / object_id


@dataclass(frozen=True)
class SequenceTracks:
    """One sequence of the run and its finished tracks (the objects the tracking stage wrote)."""

    name: str                          # output name: OUT/<name>/
    path: str
    format: str | None
    frames: tuple[int, int]
    cameras: tuple[str, ...]
    objects: tuple[str, ...]           # finished object ids, plan order
    checksums: dict[str, dict[str, str]] = field(default_factory=dict)   # object -> its track outputs' sha256
    detections: str | None = None      # the sequence's per-frame detections file, if the pipeline file gives one


@dataclass(frozen=True)
class RunContext:
    out: Path
    sequences: tuple[SequenceTracks, ...]


@dataclass(frozen=True)
class Unit:
    """One unit of work of an app. ``key`` names it (and its completion marker), e.g. ``"flow/seq/front_camera"``;
    ``inputs``: what its outputs depend on besides the app's config and the code (e.g. the track checksums);
    ``args``: keyword arguments of ``app.run`` (picklable: units may run in other processes)."""

    key: str
    inputs: dict
    args: dict
    sequence: str | None = None
    object: str | None = None


@dataclass(frozen=True)
class Skip:
    key: str
    reason: str
    sequence: str | None = None


@dataclass(frozen=True)
class UnitOutput:
    """What a unit wrote (absolute paths under OUT) and its JSON-able summary (kept in its marker and the manifest)."""

    files: list[Path]
    summary: dict


@runtime_checkable
class App(Protocol):
    name: str
    config_type: type
    description: str
    outputs: tuple[str, ...]
    needs: tuple[str, ...]

    def plan(self, config: Any, run: RunContext) -> Iterable[Unit | Skip]: ...

    def run(self, config: Any, out: Path, **args: Any) -> UnitOutput: ...

    def finish(self, config: Any, out: Path, results: list[dict]) -> None: ...


class AppBase:
    """Defaults for an app: no dependencies on other apps, nothing to do after the units."""

    name: str   # set by each app
    needs: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    description: str = ""

    def finish(self, config: Any, out: Path, results: list[dict]) -> None:
        return None

    def sequence_unit(self, s: SequenceTracks, **extra: Any) -> Unit:
        """The usual unit of an app that works on a whole sequence: key ``<app>/<sequence>``, digested with the
        sequence's track checksums and path, run with ``sequence, path, format, object_ids`` (+ ``extra``, which
        are digested too)."""
        return Unit(f"{self.name}/{s.name}", {"tracks": s.checksums, "seq": s.path, **extra},
                    {"sequence": s.name, "path": s.path, "format": s.format, "object_ids": list(s.objects), **extra},
                    s.name)

    def per_sequence(self, run: RunContext, make: Any) -> list[Unit | Skip]:
        """Helper: ``make(sequence)`` for every sequence with finished tracks; a :class:`Skip` for the others."""
        units: list[Unit | Skip] = []
        for s in run.sequences:
            if not s.objects:
                units.append(Skip(f"{self.name}/{s.name}", "no object of this sequence was tracked", s.name))
            else:
                units += make(s)
        return units


# ---------------------------------------------------------------------------------------------- registry

def _load(name: str, target: Any) -> App:
    app = target() if isinstance(target, type) else target
    missing = [a for a in ("name", "config_type", "plan", "run") if not hasattr(app, a)]
    if missing:
        raise InputError(None, f"app {name!r}: not an App (missing {', '.join(missing)})")
    if app.name != name:
        raise InputError(None, f"app {name!r}: its entry point is named {name!r} but the app calls itself {app.name!r}")
    if not (isinstance(app.config_type, type) and dataclasses.is_dataclass(app.config_type)):
        raise InputError(None, f"app {name!r}: config_type must be a (frozen) dataclass")
    return app


@functools.lru_cache(maxsize=1)
def _entry_points() -> dict[str, Any]:
    from importlib.metadata import entry_points

    found: dict[str, Any] = {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}
    for name, target in BUILTIN_APPS.items():
        found.setdefault(name, target)
    return found


def _resolve(target: Any) -> Any:
    if isinstance(target, str):
        import importlib

        module, _, attr = target.partition(":")
        return getattr(importlib.import_module(module), attr)
    return target.load()


@functools.lru_cache(maxsize=None)
def get_app(name: str) -> App:
    """The installed app called ``name`` (InputError naming the installed ones when there is none)."""
    points = _entry_points()
    if name not in points:
        raise InputError(None, f"no installed app named {name!r} (installed: {', '.join(sorted(points))}; "
                               f"an app registers in the entry-point group {ENTRY_POINT_GROUP!r})")
    try:
        return _load(name, _resolve(points[name]))
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - a broken plug-in is reported by name, not as a traceback
        raise InputError(None, f"app {name!r} does not load: {type(exc).__name__}: {exc}") from exc


def installed_apps() -> dict[str, App | InputError]:
    """Every registered app by name (sorted); an app that does not load maps to its error."""
    out: dict[str, App | InputError] = {}
    for name in sorted(_entry_points()):
        try:
            out[name] = get_app(name)
        except InputError as exc:
            out[name] = exc
    return out


# ------------------------------------------------------------------------------------------ config section

def config_fields(config_type: type) -> list[tuple[str, str, Any]]:
    """``(name, type as text, default)`` for each field of an app's config section."""
    hints = typing.get_type_hints(config_type)
    rows = []
    for f in dataclasses.fields(config_type):
        default = f.default if f.default is not dataclasses.MISSING else (
            f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
        rows.append((f.name, _type_text(hints[f.name]), default))
    return rows


def _type_text(hint: Any) -> str:
    if isinstance(hint, type) and not typing.get_args(hint):
        return hint.__name__
    return str(hint).replace("typing.", "")


def _coerce(hint: Any, value: Any, where: str, path: Any) -> Any:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for option in (a for a in args if a is not type(None)):
            try:
                return _coerce(option, value, where, path)
            except InputError as exc:
                errors.append(exc)
        raise errors[0] if errors else InputError(path, f"{where}: expected {_type_text(hint)}, got {value!r}")
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise InputError(path, f"{where}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(args[0], v, f"{where}[{i}]", path) for i, v in enumerate(value))
        if len(args) != len(value):
            raise InputError(path, f"{where}: expected {len(args)} values, got {len(value)}")
        return tuple(_coerce(a, v, f"{where}[{i}]", path) for i, (a, v) in enumerate(zip(args, value, strict=True)))
    if origin is dict or hint is dict:
        if not isinstance(value, dict):
            raise InputError(path, f"{where}: expected an object, got {value!r}")
        return dict(value)
    if hint is bool:
        if not isinstance(value, bool):
            raise InputError(path, f"{where}: expected true or false, got {value!r}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError(path, f"{where}: expected an integer, got {value!r}")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(path, f"{where}: expected a number, got {value!r}")
        return float(value)
    if hint is str:
        if not isinstance(value, str):
            raise InputError(path, f"{where}: expected a string, got {value!r}")
        return value
    if typing.get_origin(hint) is typing.Literal:
        if value not in args:
            raise InputError(path, f"{where}: expected one of {', '.join(map(repr, args))}, got {value!r}")
        return value
    return value


def build_config(config_type: type, section: dict | None, where: str, path: Any = None) -> Any:
    """An app's config from its pipeline section (``enabled`` is the pipeline's, not the app's). Errors name the
    field: ``<path>: stages.flow.max_pairs: expected an integer, got 'x'``."""
    section = dict(section or {})
    section.pop("enabled", None)
    hints = typing.get_type_hints(config_type)
    names = [f.name for f in dataclasses.fields(config_type)]
    unknown = sorted(set(section) - set(names))
    if unknown:
        raise InputError(path, f"{where}.{unknown[0]}: unknown field (the section has: {', '.join(names) or 'none'})")
    values = {k: _coerce(hints[k], v, f"{where}.{k}", path) for k, v in section.items()}
    try:
        return config_type(**values)
    except (TypeError, ValueError) as exc:
        raise InputError(path, f"{where}: {exc}") from exc


def describe(app: App) -> dict:
    """An app as JSON: name, description, where it comes from, what it needs and writes, its config section."""
    return {"name": app.name, "description": getattr(app, "description", ""),
            "module": type(app).__module__, "needs": list(getattr(app, "needs", ())),
            "runs_by_default": app.name in V1_APPS, "outputs": list(getattr(app, "outputs", ())),
            "config": [{"field": f, "type": t, "default": _json_default(d)} for f, t, d in config_fields(app.config_type)]}


def _json_default(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value
