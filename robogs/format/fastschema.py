"""A quick "surely valid" test of a JSON document against one of our JSON Schemas.

:func:`robogs.format.schemas.schema_problems` runs ``jsonschema`` (Draft 2020-12), which spends
~0.25 ms per episode entry of a manifest: 2.6 s for the merged manifest of 10^4 episodes. Almost
every manifest is valid, so the schema is first compiled here into nested Python closures that
answer one question: is the document valid for certain? Only when the answer is not a certain
yes (a violation, or anything this compiler does not model) does ``jsonschema`` run to find and
word the problems, so the problems reported never change; this only skips the slow run when
there are none.

The compiler models the keywords our schemas use (``type``, ``properties``, ``required``,
``additionalProperties``, ``items``, ``minItems``, ``maxItems``, ``minimum``, ``maximum``,
``exclusiveMinimum``, ``minLength``, ``maxLength``, ``pattern``, ``enum``, ``const``,
``propertyNames``, local ``$ref`` to ``#/$defs/...``) with ``jsonschema``'s semantics
(``re.search`` for patterns, bool never a number), and answers "not sure" wherever it is stricter:
a float where an integer is required, NaN or infinity compared with a bound, a list or object in
``enum``/``const``. A schema with any other keyword compiles to "not sure" for its node.
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Callable
from typing import Any

__all__ = ["compile_schema", "surely_valid"]

Test = Callable[[Any], bool]

#: keywords that only annotate (no effect on validity)
_ANNOTATIONS = frozenset({"description", "title", "$schema", "$id", "$defs", "$comment"})
_BOUNDS = ("minimum", "maximum", "exclusiveMinimum")


def _never(_x: Any) -> bool:
    return False


def _always(_x: Any) -> bool:
    return True


def _is_number(x: Any) -> bool:
    """An int or a finite float, exactly (anything else: not sure)."""
    return type(x) is int or (type(x) is float and math.isfinite(x))


_TYPES: dict[str, Test] = {
    "object": lambda x: type(x) is dict,
    "array": lambda x: type(x) is list,
    "string": lambda x: type(x) is str,
    "integer": lambda x: type(x) is int,  # a float 1.0 is valid too: "not sure" here
    "number": _is_number,
    "boolean": lambda x: type(x) is bool,
    "null": lambda x: x is None,
}


def _same(a: Any, b: Any) -> bool | None:
    """``jsonschema``'s equality for scalars (True != 1); None (not sure) for containers."""
    if isinstance(a, dict | list) or isinstance(b, dict | list):
        return None
    if type(a) is bool or type(b) is bool or a is None or b is None or type(a) is str:
        return type(a) is type(b) and a == b
    if type(b) is str:
        return False
    return a == b if _is_number(a) and _is_number(b) else None


def compile_schema(schema: Any, root: dict[str, Any] | None = None) -> Test:
    """A test that is True only for instances valid against ``schema`` (False: not sure).

    Args:
        schema: a (sub)schema, a dict or a bool.
        root: the whole schema, for ``$ref`` to ``#/$defs/<name>`` (default: ``schema``).
    """
    root = schema if root is None else root
    cache: dict[str, Test] = {}
    return _compile(schema, root, cache)


def _compile(schema: Any, root: dict[str, Any], refs: dict[str, Test]) -> Test:
    if schema is True:
        return _always
    if not isinstance(schema, dict):
        return _never
    tests: list[Test] = []
    for key, value in schema.items():
        if key in _ANNOTATIONS:
            continue
        test = _keyword(key, value, schema, root, refs)
        if test is None:
            return _never  # a keyword this compiler does not model
        tests.append(test)
    if not tests:
        return _always
    if len(tests) == 1:
        return tests[0]
    return lambda x: all(t(x) for t in tests)


def _ref(ref: Any, root: dict[str, Any], refs: dict[str, Test]) -> Test | None:
    if not isinstance(ref, str) or not ref.startswith("#/$defs/"):
        return None
    name = ref[len("#/$defs/") :]
    target = root.get("$defs", {}).get(name)
    if target is None or "/" in name or "~" in name:
        return None
    if name not in refs:
        refs[name] = _never  # placeholder while compiling; looked up at call time below
        refs[name] = _compile(target, root, refs)
    return lambda x: refs[name](x)  # so a recursive reference reaches the compiled test


def _keyword(
    key: str, value: Any, schema: dict[str, Any], root: dict[str, Any], refs: dict[str, Test]
) -> Test | None:
    """The test of one keyword (None: not modelled)."""
    if key == "$ref":
        return _ref(value, root, refs)
    if key == "type":
        names = value if isinstance(value, list) else [value]
        if not all(isinstance(n, str) and n in _TYPES for n in names):
            return None
        checks = [_TYPES[n] for n in names]
        return checks[0] if len(checks) == 1 else (lambda x: any(c(x) for c in checks))
    if key in _BOUNDS:
        if not _is_number(value):
            return None
        if key == "minimum":
            return lambda x: not _number_like(x) or (_is_number(x) and x >= value)
        if key == "maximum":
            return lambda x: not _number_like(x) or (_is_number(x) and x <= value)
        return lambda x: not _number_like(x) or (_is_number(x) and x > value)
    if key in ("minLength", "maxLength", "minItems", "maxItems"):
        if type(value) is not int:
            return None
        kind = str if key.endswith("Length") else list
        if key.startswith("min"):
            return lambda x: not isinstance(x, kind) or len(x) >= value
        return lambda x: not isinstance(x, kind) or len(x) <= value
    if key == "pattern":
        if not isinstance(value, str):
            return None
        try:
            rx = re.compile(value)
        except re.error:
            return None
        return lambda x: not isinstance(x, str) or rx.search(x) is not None
    if key == "enum":
        if not isinstance(value, list):
            return None
        return lambda x: any(_same(x, v) for v in value)
    if key == "const":
        return lambda x: bool(_same(x, value))
    if key == "required":
        if not isinstance(value, list) or not all(isinstance(k, str) for k in value):
            return None
        need = tuple(value)
        return lambda x: not isinstance(x, dict) or all(k in x for k in need)
    if key == "properties":
        if not isinstance(value, dict):
            return None
        props = {k: _compile(v, root, refs) for k, v in value.items()}
        return lambda x: not isinstance(x, dict) or all(t(x[k]) for k, t in props.items() if k in x)
    if key == "additionalProperties":
        if "patternProperties" in schema:
            return None
        known = frozenset(schema.get("properties", {}) or {})
        extra = _compile(value, root, refs) if value is not False else None
        if extra is None:
            return lambda x: not isinstance(x, dict) or all(k in known for k in x)
        return lambda x: (
            not isinstance(x, dict) or all(extra(v) for k, v in x.items() if k not in known)
        )
    if key == "items":
        if not isinstance(value, dict | bool):
            return None
        each = _compile(value, root, refs)
        return lambda x: not isinstance(x, list) or all(each(v) for v in x)
    if key == "propertyNames":
        names = _compile(value, root, refs)
        return lambda x: not isinstance(x, dict) or all(names(k) for k in x)
    return None


def _number_like(x: Any) -> bool:
    """What ``jsonschema`` compares with a bound: any number but a bool."""
    return isinstance(x, numbers.Number) and not isinstance(x, bool)


_COMPILED: dict[int, tuple[Any, Test]] = {}


def surely_valid(schema: dict[str, Any], document: Any) -> bool:
    """True when ``document`` is valid against ``schema`` for certain (compiled once per schema
    object); False when it is not, or this compiler cannot tell."""
    hit = _COMPILED.get(id(schema))
    if hit is None or hit[0] is not schema:
        hit = (schema, compile_schema(schema))
        _COMPILED[id(schema)] = hit
    try:
        return bool(hit[1](document))
    except (TypeError, ValueError, RecursionError):
        return False
