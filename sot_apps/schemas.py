"""JSON Schema validation of the project's data contracts (data_schema/<name>.schema.json).

``validate(name, data, path)`` raises :class:`~sot_apps.errors.InputError` naming the file and the
offending field (``frames[3].world_from_ego[0][1]: ...``). Non-finite numbers (JSON's NaN/Infinity,
which Python's json module accepts) are rejected everywhere, before the schema is applied. A document first goes
through the schema's compiled check (:mod:`sot_apps.schema_subset`, no jsonschema import); jsonschema checks
(and words the error of) whatever that check does not pass.
"""

from __future__ import annotations

import functools
import json
import math
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterator

from .errors import InputError
from .schema_subset import compile_schema

if TYPE_CHECKING:   # jsonschema (~0.1 s to import) is imported when a document fails the compiled check
    from jsonschema import Draft202012Validator
    from jsonschema.exceptions import ValidationError

__all__ = ["load_schema", "validate", "load_json", "load_json_validated", "schema_names", "json_path"]

_REPO_SCHEMA_DIR = Path(__file__).resolve().parents[1] / "data_schema"


def _schema_text(name: str) -> str:
    filename = f"{name}.schema.json"
    try:
        resource = resources.files("data_schema").joinpath(filename)
        if resource.is_file():
            return resource.read_text(encoding="utf-8")
    except (ModuleNotFoundError, FileNotFoundError):
        pass
    fallback = _REPO_SCHEMA_DIR / filename
    if fallback.is_file():
        return fallback.read_text(encoding="utf-8")
    raise KeyError(f"no schema named {name!r} (looked for {filename} in the data_schema package and {_REPO_SCHEMA_DIR})")


def schema_names() -> list[str]:
    """Names of all schemas shipped in data_schema/."""
    names: set[str] = set()
    try:
        names |= {p.name[: -len(".schema.json")] for p in resources.files("data_schema").iterdir()
                  if p.name.endswith(".schema.json")}
    except ModuleNotFoundError:
        pass
    if _REPO_SCHEMA_DIR.is_dir():
        names |= {p.name[: -len(".schema.json")] for p in _REPO_SCHEMA_DIR.glob("*.schema.json")}
    return sorted(names)


@functools.lru_cache(maxsize=None)
def load_schema(name: str) -> dict[str, Any]:
    """The parsed schema ``data_schema/<name>.schema.json``. The shipped schemas are checked against the 2020-12
    meta-schema by the tests (tests/io/test_schemas.py), not on every load: that check took ~30 ms per schema,
    paid by every command that reads or writes a document."""
    return json.loads(_schema_text(name))


@functools.lru_cache(maxsize=None)
def _validator(name: str) -> Draft202012Validator:
    from jsonschema import Draft202012Validator

    return Draft202012Validator(load_schema(name))


@functools.lru_cache(maxsize=None)
def _compiled(name: str) -> Callable[[Any], bool] | None:
    return compile_schema(load_schema(name))


def json_path(parts: Any) -> str:
    """``["frames", 3, "state", "x"]`` -> ``frames[3].state.x`` (``(root)`` for the document itself)."""
    out = ""
    for part in parts:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out or "(root)"


def _non_finite(data: Any, prefix: tuple = ()) -> Iterator[tuple]:
    if isinstance(data, float):
        if not math.isfinite(data):
            yield prefix
    elif isinstance(data, dict):
        for key, value in data.items():
            yield from _non_finite(value, prefix + (key,))
    elif isinstance(data, (list, tuple)):
        for i, value in enumerate(data):
            yield from _non_finite(value, prefix + (i,))
    else:  # numpy scalars and arrays handed in by writers
        try:
            import numpy as np

            if isinstance(data, (np.floating, np.ndarray)) and not np.all(np.isfinite(data)):
                yield prefix
        except TypeError:
            pass


def _describe(error: ValidationError) -> str:
    parts = list(error.absolute_path)
    if error.validator == "required":
        missing = [name for name in error.validator_value if isinstance(error.instance, dict) and name not in error.instance]
        if missing:
            return f"{json_path(parts + [missing[0]])}: required field is missing"
    if error.validator == "additionalProperties" and isinstance(error.instance, dict):
        allowed = set(error.schema.get("properties", {}))
        patterns = error.schema.get("patternProperties", {})
        extra = [k for k in error.instance if k not in allowed and not patterns]
        if extra:
            return f"{json_path(parts + [extra[0]])}: unknown field (not allowed by the schema)"
    if error.validator == "type":
        expected = error.validator_value
        expected = " or ".join(expected) if isinstance(expected, list) else expected
        return f"{json_path(parts)}: wrong type, expected {expected}, got {_short(error.instance)}"
    return f"{json_path(parts)}: {error.message if len(error.message) < 200 else error.message[:200] + '...'}"


def _short(value: Any) -> str:
    text = json.dumps(value, default=str)
    return text if len(text) <= 40 else text[:37] + "..."


def validate(schema_name: str, data: Any, path: str | Path | None) -> None:
    """Check ``data`` against ``data_schema/<schema_name>.schema.json``.

    Raises InputError(path, "<field>: <problem>") on the first (most relevant) violation.
    """
    for where in _non_finite(data):
        raise InputError(path, f"{json_path(where)}: non-finite number (NaN or Infinity) is not allowed")
    compiled = _compiled(schema_name)
    if compiled is not None and compiled(data):   # valid as jsonschema decides (sot_apps.schema_subset)
        return
    from jsonschema.exceptions import best_match

    error = best_match(_validator(schema_name).iter_errors(data))
    if error is not None:
        raise InputError(path, f"{_describe(error)} ({schema_name} schema)")


def load_json(path: str | Path) -> Any:
    """Read a JSON file; a missing file or invalid JSON is an InputError naming the file."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file is missing" if not path.exists() else "not a regular file")
    try:
        with open(path, encoding="utf-8") as handle:
            return json.load(handle)
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from exc
    except UnicodeDecodeError as exc:
        raise InputError(path, f"not valid UTF-8 text ({exc.reason})") from exc
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror})") from exc


def load_json_validated(path: str | Path, schema_name: str) -> Any:
    """Read a JSON file and validate it against ``schema_name``."""
    data = load_json(path)
    validate(schema_name, data, path)
    return data
