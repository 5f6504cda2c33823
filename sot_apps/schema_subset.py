"""A compiled check of a JSON Schema (Draft 2020-12) written with the keywords the project's schemas use.

:func:`compile_schema` turns a schema into a function ``document -> bool``: True when the document is valid, as
jsonschema's ``Draft202012Validator`` decides. Importing jsonschema costs ~0.1 s, paid by every command that reads
or writes a document; this check needs none of it. It says False for an invalid document and also whenever it is
not sure (a value of a type a JSON parser does not make, such as a tuple or a numpy scalar; ``uniqueItems`` over
anything but strings): :func:`sot_apps.schemas.validate` then asks jsonschema, which also words the error. A schema
with a keyword outside :data:`KEYWORDS` (or a boolean subschema, a ``$ref`` outside ``#/$defs/``, a ``const`` or
``enum`` value that is not a plain scalar) is not compiled: None, jsonschema checks every document.
tests/io/test_schema_subset.py compares both on every shipped schema with valid and broken documents.
"""

from __future__ import annotations

import re
from typing import Any, Callable

__all__ = ["compile_schema", "KEYWORDS"]

Check = Callable[[Any], bool]

ANNOTATIONS = frozenset({"$schema", "$id", "$comment", "title", "description", "version", "examples", "default",
                         "$defs"})
KEYWORDS = frozenset({"type", "const", "enum", "minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum",
                      "minLength", "maxLength", "pattern", "items", "prefixItems", "minItems", "maxItems",
                      "uniqueItems", "properties", "required", "additionalProperties", "anyOf", "$ref"})
_SCALARS = (str, int, float, bool, type(None))
# exact Python type -> JSON Schema types it is (bool is not an integer; a float with an integral value is one)
_KINDS: dict[type, tuple[str, ...]] = {dict: ("object",), list: ("array",), str: ("string",), bool: ("boolean",),
                                       int: ("integer", "number"), float: ("number",), type(None): ("null",)}


class Unsure(Exception):
    """The document holds a value the compiled check does not judge (jsonschema does)."""


class _Declined(Exception):
    """The schema uses something outside the subset: no compiled check."""


def _kinds(value: Any) -> tuple[str, ...]:
    kinds = _KINDS.get(type(value))
    if kinds is None:
        raise Unsure
    if kinds == ("number",) and value.is_integer():
        return ("integer", "number")
    return kinds


def _equal(value: Any, expected: Any) -> bool:
    """jsonschema's equality for a plain scalar ``expected``: True is not 1, 1 is 1.0."""
    if type(value) not in _KINDS:
        raise Unsure
    if isinstance(value, (dict, list)):
        return False
    if isinstance(value, str) or isinstance(expected, str):
        return value == expected
    if isinstance(value, bool) or isinstance(expected, bool):
        return type(value) is type(expected) and value == expected
    return value == expected


def compile_schema(schema: dict) -> Check | None:
    """The check of ``schema`` (see the module doc), or None when it uses anything outside the subset."""
    defs: dict[str, Check] = {}
    try:
        check = _compile(schema, schema, defs)
    except _Declined:
        return None

    def valid(document: Any) -> bool:
        try:
            return check(document)
        except (Unsure, RecursionError):
            return False

    return valid


def _compile(schema: Any, root: dict, defs: dict[str, Check]) -> Check:
    if not isinstance(schema, dict) or not set(schema) <= KEYWORDS | ANNOTATIONS:
        raise _Declined
    checks: list[Check] = []
    kind_checks: dict[str, list[Check]] = {"object": [], "array": [], "string": [], "number": []}
    if "type" in schema:
        wanted = schema["type"] if isinstance(schema["type"], list) else [schema["type"]]
        checks.append(lambda v, wanted=frozenset(wanted): not wanted.isdisjoint(_kinds(v)))
    for key in ("const", "enum"):
        if key in schema:
            options = [schema[key]] if key == "const" else schema[key]
            if not isinstance(options, list) or not all(isinstance(o, _SCALARS) for o in options):
                raise _Declined
            checks.append(lambda v, options=options: any(_equal(v, o) for o in options))
    number = kind_checks["number"]
    for key, test in (("minimum", lambda v, m: v >= m), ("maximum", lambda v, m: v <= m),
                      ("exclusiveMinimum", lambda v, m: v > m), ("exclusiveMaximum", lambda v, m: v < m)):
        if key in schema:
            number.append(lambda v, m=schema[key], test=test: test(v, m))
    string = kind_checks["string"]
    if "minLength" in schema:
        string.append(lambda v, n=schema["minLength"]: len(v) >= n)
    if "maxLength" in schema:
        string.append(lambda v, n=schema["maxLength"]: len(v) <= n)
    if "pattern" in schema:
        string.append(lambda v, p=re.compile(schema["pattern"]): p.search(v) is not None)
    array = kind_checks["array"]
    prefix = [_compile(s, root, defs) for s in schema.get("prefixItems", [])]
    if prefix:
        array.append(lambda v: all(c(item) for c, item in zip(prefix, v, strict=False)))   # fewer items: fine
    if "items" in schema:
        item_check, start = _compile(schema["items"], root, defs), len(prefix)
        array.append(lambda v: all(item_check(item) for item in v[start:]))
    if "minItems" in schema:
        array.append(lambda v, n=schema["minItems"]: len(v) >= n)
    if "maxItems" in schema:
        array.append(lambda v, n=schema["maxItems"]: len(v) <= n)
    if schema.get("uniqueItems") is True:
        array.append(_unique_strings)
    obj = kind_checks["object"]
    obj.append(_string_keys)
    properties = {k: _compile(s, root, defs) for k, s in schema.get("properties", {}).items()}
    if properties:
        obj.append(lambda v: all(check(v[k]) for k, check in properties.items() if k in v))
    if "required" in schema:
        obj.append(lambda v, names=tuple(schema["required"]): all(name in v for name in names))
    if "additionalProperties" in schema:
        extra = schema["additionalProperties"]
        if extra is False:
            obj.append(lambda v: all(k in properties for k in v))
        elif extra is not True:   # true: anything goes
            extra_check = _compile(extra, root, defs)
            obj.append(lambda v: all(extra_check(x) for k, x in v.items() if k not in properties))
    if "anyOf" in schema:
        options = [_compile(s, root, defs) for s in schema["anyOf"]]
        checks.append(lambda v: any(c(v) for c in options))
    if "$ref" in schema:
        checks.append(_reference(schema["$ref"], root, defs))
    for kind, kind_list in kind_checks.items():
        if kind_list:
            checks.append(lambda v, kind=kind, kind_list=kind_list: kind not in _kinds(v) or all(c(v) for c in kind_list))
    return lambda v: all(c(v) for c in checks)


def _reference(ref: Any, root: dict, defs: dict[str, Check]) -> Check:
    name = ref[len("#/$defs/"):] if isinstance(ref, str) and ref.startswith("#/$defs/") else None
    if name is None or "/" in name or "~" in name or name not in root.get("$defs", {}):
        raise _Declined
    if name not in defs:
        defs[name] = lambda v: defs[name](v)   # a recursive reference finds the compiled check once it is made
        defs[name] = _compile(root["$defs"][name], root, defs)
    return lambda v: defs[name](v)


def _string_keys(value: dict) -> bool:
    if not all(type(key) is str for key in value):
        raise Unsure
    return True


def _unique_strings(items: list) -> bool:
    if not all(type(item) is str for item in items):
        raise Unsure
    return len(set(items)) == len(items)
