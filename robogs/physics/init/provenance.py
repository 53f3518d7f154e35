"""Where every physics.json value came from, and editing values by dotted key.

physics.json keeps ``sources``: dotted key -> ``{source, value, sigma?, detail?, bounds?}``.
``source`` is one of ``mesh``, ``annotation``, ``user``, ``estimated``, ``prior(<material>)``,
``urdf``, ``default``. ``value`` is the value as that source gave it: when a later revision (a
fit) changed the value, :func:`rows` reports the revision's own value and says what it replaced.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from robogs.format.errors import InputError

__all__ = ["Entry", "record", "rows", "format_table", "set_value", "parse_assignment"]


@dataclass
class Entry:
    """The source of one value.

    Attributes:
        key: dotted key in physics.json (``objects.box.size_m``).
        value: the value written.
        source: ``mesh``, ``annotation``, ``user``, ``estimated``, ``prior(...)``, ``urdf``, ``default``.
        sigma: 1-sigma uncertainty of an estimated value (same shape as the value), or None.
        detail: how it was obtained.
        bounds: (low, high) for a prior, or None.
    """

    key: str
    value: Any
    source: str
    sigma: Any = None
    detail: str = ""
    bounds: Any = None

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"source": self.source, "value": self.value}
        if self.sigma is not None:
            d["sigma"] = self.sigma
        if self.detail:
            d["detail"] = self.detail
        if self.bounds is not None:
            d["bounds"] = [float(b) for b in self.bounds]
        return d


def record(physics: dict[str, Any], entries: list[Entry]) -> dict[str, Any]:
    """``physics`` with ``sources`` updated by ``entries`` (a new dict)."""
    out = dict(physics)
    src = dict(out.get("sources") or {})
    for e in entries:
        src[e.key] = e.to_dict()
    out["sources"] = src
    return out


def _leaves(node: Any, prefix: str) -> list[tuple[str, Any]]:
    if isinstance(node, dict):
        out: list[tuple[str, Any]] = []
        for k, v in node.items():
            out += _leaves(v, f"{prefix}.{k}" if prefix else str(k))
        return out
    return [(prefix, node)]


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return str(v)


def _fmt_sigma(s: Any) -> str:
    if s is None:
        return ""
    if isinstance(s, list):
        return " ± [" + ", ".join(f"{x * 1000:.1f}" for x in s) + "] mm"
    return f" ± {float(s) * 1000:.1f} mm"


def rows(physics: dict[str, Any]) -> list[tuple[str, str, str]]:
    """(key, value, source) for every value under ``objects`` and ``gravity_mps2``."""
    src = physics.get("sources") or {}
    rev = physics.get("revision")
    out = []
    for key, val in _leaves({"objects": physics.get("objects", {})}, "") + [
        ("gravity_mps2", physics.get("gravity_mps2"))
    ]:
        if val is None:
            continue
        rec = src.get(key)
        if rec is None:
            source = "(not recorded)"
        else:
            source = str(rec.get("source", "?"))
            if source == "estimated":
                source += _fmt_sigma(rec.get("sigma"))
            if "bounds" in rec:
                source += f" in [{_fmt(rec['bounds'][0])}, {_fmt(rec['bounds'][1])}]"
            if rec.get("value") != val:
                source = f"revision {rev} (replaced {_fmt(rec.get('value'))} from {source})"
            elif rec.get("detail"):
                source += f"; {rec['detail']}"
        out.append((key, _fmt(val), source))
    return out


def format_table(physics: dict[str, Any], width: int = 100) -> str:
    """The :func:`rows` as an aligned text table."""
    r = rows(physics)
    kw = max(len(k) for k, _, _ in r)
    vw = min(max(len(v) for _, v, _ in r), 44)
    head = f"physics.json revision {physics.get('revision')}"
    lines = [head, f"{'key':<{kw}}  {'value':<{vw}}  source", "-" * min(width, kw + vw + 40)]
    for k, v, s in r:
        lines.append(f"{k:<{kw}}  {v:<{vw}}  {s}")
    return "\n".join(lines)


def parse_assignment(text: str) -> tuple[str, Any]:
    """``KEY=VALUE``: VALUE parsed as JSON (numbers, lists, true/false/null), else a string."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key or any(not p for p in key.split(".")):
        raise InputError(
            f"cannot read {text!r}", hint="write KEY=VALUE, e.g. objects.box.mass_kg=0.35"
        )
    try:
        value = json.loads(raw)
    except ValueError:
        value = raw
    return key, value


def set_value(physics: dict[str, Any], key: str, value: Any) -> dict[str, Any]:
    """A copy of ``physics`` with the dotted ``key`` set (dicts created; list items by index)."""
    import copy

    doc = copy.deepcopy(physics)
    parts = key.split(".")
    node: Any = doc
    for i, p in enumerate(parts[:-1]):
        if isinstance(node, list):
            node = node[_index(node, p, key)]
        else:
            nxt = node.get(p)
            if nxt is None:
                nxt = node[p] = {}
            elif not isinstance(nxt, (dict, list)):
                raise InputError(f"{'.'.join(parts[: i + 1])} is a value, not a group", where=key)
            node = nxt
    last = parts[-1]
    if isinstance(node, list):
        node[_index(node, last, key)] = value
    else:
        node[last] = value
    return doc


def _index(node: list, p: str, key: str) -> int:
    try:
        i = int(p)
        node[i]
        return i
    except (ValueError, IndexError):
        raise InputError(f"{p!r} is not an index of a {len(node)}-item list", where=key) from None
