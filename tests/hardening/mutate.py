"""Hypothesis strategies that turn a valid file into a hostile one.

Byte-level mutations (flips, truncation, insertion, deletion, duplication, "interesting"
integers written over length and count fields) fit every binary format; structure-aware ones
keep a file parseable by its outer layer so that the inner reader is reached: JSON and YAML
trees (deleted keys, swapped types, absurd numbers, deep nesting, hostile paths), XML trees
(deleted elements and attributes, evil attribute values, entity declarations), CSV cells and
lines, PLY headers (absurd counts, bad property types). Every strategy draws a small list of
operations and applies it to the seed deterministically, so Hypothesis can shrink a failure
to the fewest, simplest operations.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable
from typing import Any

from hypothesis import strategies as st

__all__ = [
    "INTERESTING_INTS",
    "EVIL_STRINGS",
    "evil_values",
    "bytes_mutation",
    "json_mutation",
    "yaml_mutation",
    "xml_mutation",
    "csv_mutation",
    "ply_mutation",
    "text_mutation",
]

INTERESTING_INTS = (
    0, 1, -1, 2, 7, 8, 255, 256, 2**15 - 1, 2**16 - 1, 2**16, 2**31 - 1, 2**31, 2**32 - 1,
    2**32, 2**40, 2**53 + 1, 2**62, 2**63 - 1, 2**63, 2**64 - 1, -(2**31), -(2**63),
)  # fmt: skip


class _Long(str):
    """A long string with a short repr (keeps Hypothesis reports readable)."""

    def __repr__(self) -> str:
        return f"<{len(self)} x {self[:1]!r}>"


class _LongBytes(bytes):
    """Bytes with a short repr."""

    def __repr__(self) -> str:
        return f"<{len(self)} bytes {bytes(self[:24])!r}...>"


EVIL_STRINGS = (
    "", " ", "x", "nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e-400", "0x10", "1,5",
    "-1", "0", "99999999999999999999999999", _Long("9" * 5000), "../../../../etc/passwd",
    "/etc/passwd", "file:///etc/passwd", "package://robot/../../../../etc/passwd",
    "package://nope/x.stl", "http://127.0.0.1/x", "C:\\x", "a\x00b", "\u202e\ufeff",
    "é" * 40, "\ud7ff", "1 2", "a b c", "0 0 0 0", "1e308 1e308 1e308", "-0", "true",
)  # fmt: skip

_SEP = (b"\x00", b"\xff", b"\n", b"\r\n", b",", b" ", b"\xc3", b"\xed\xa0\x80", b"%", b"<")


def evil_values() -> st.SearchStrategy[Any]:
    """JSON/YAML scalars and small containers chosen to break readers."""
    return st.one_of(
        st.sampled_from(
            [None, True, False, 0, -1, 2**31, 2**63, -(2**63) - 1, 10**400, 1e308, -1e308,
             5e-324, [], {}, [[]], {"": None}, [1e308] * 3, "", *EVIL_STRINGS]
        ),
        st.integers(),
        st.floats(allow_nan=False, allow_infinity=False),
        st.text(max_size=12),
        st.lists(st.integers(-5, 5), max_size=5),
    )  # fmt: skip


# ----------------------------------------------------------------------------- bytes


def _apply_bytes(data: bytes, ops: list[tuple]) -> bytes:
    buf = bytearray(data)
    for op in ops:
        kind, pos = op[0], op[1]
        n = len(buf)
        at = min(int(pos * n), max(n - 1, 0))
        if kind == "flip" and n:
            buf[at] ^= op[2] or 1
        elif kind == "truncate":
            del buf[at:]
        elif kind == "insert":
            buf[at:at] = op[2]
        elif kind == "delete":
            del buf[at : at + op[2]]
        elif kind == "dup":
            buf[at:at] = buf[at : at + op[2]]
        elif kind == "int":
            width, value, endian = op[2], op[3], op[4]
            raw = (value % (1 << (8 * width))).to_bytes(width, endian)
            buf[at : at + width] = raw
        elif kind == "sep":
            buf[at:at] = op[2]
    return bytes(buf)


def _byte_op() -> st.SearchStrategy[tuple]:
    pos = st.floats(0, 1, exclude_max=True)
    return st.one_of(
        st.tuples(st.just("flip"), pos, st.integers(1, 255)),
        st.tuples(st.just("truncate"), pos),
        st.tuples(st.just("insert"), pos, st.binary(min_size=1, max_size=16)),
        st.tuples(st.just("delete"), pos, st.integers(1, 64)),
        st.tuples(st.just("dup"), pos, st.integers(1, 256)),
        st.tuples(
            st.just("int"),
            pos,
            st.sampled_from([1, 2, 4, 8]),
            st.sampled_from(INTERESTING_INTS),
            st.sampled_from(["little", "big"]),
        ),
        st.tuples(st.just("sep"), pos, st.sampled_from(_SEP)),
    )


def bytes_mutation(data: bytes, *, max_ops: int = 4) -> st.SearchStrategy[bytes]:
    """``data`` with 1..max_ops byte-level operations applied."""
    return st.lists(_byte_op(), min_size=1, max_size=max_ops).map(
        lambda ops: _apply_bytes(data, ops)
    )


def text_mutation(text: str, *, max_ops: int = 4) -> st.SearchStrategy[bytes]:
    """UTF-8 of ``text`` with byte-level operations (bad UTF-8, truncation ...)."""
    return bytes_mutation(text.encode("utf-8"), max_ops=max_ops)


# ----------------------------------------------------------------------------- trees


def _walk(doc: Any, path: list[int]) -> tuple[Any, Any]:
    """Follow ``path`` (indices taken modulo the container size); return (parent, key)."""
    parent, key = None, None
    node = doc
    for i in path:
        if isinstance(node, dict) and node:
            k = sorted(node, key=str)[i % len(node)]
            parent, key, node = node, k, node[k]
        elif isinstance(node, list) and node:
            k = i % len(node)
            parent, key, node = node, k, node[k]
        else:
            break
    return parent, key


def _deep(depth: int) -> Any:
    node: Any = 1
    for _ in range(depth):
        node = [node]
    return node


def _swap_type(v: Any) -> Any:
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, int | float):
        return str(v)
    if isinstance(v, str):
        try:
            return float(v)
        except ValueError:
            return len(v)
    if isinstance(v, list):
        return {str(i): x for i, x in enumerate(v)}
    if isinstance(v, dict):
        return list(v.values())
    return 0


def _apply_tree(doc: Any, ops: list[tuple]) -> Any:
    doc = json.loads(json.dumps(doc))  # private copy
    for kind, path, value in ops:
        try:
            doc = _tree_op(doc, kind, path, value)
        except RecursionError:  # an earlier "deep" op made the tree too deep to copy
            continue
    return doc


def _tree_op(doc: Any, kind: str, path: list[int], value: Any) -> Any:
    """Apply one operation at the node ``path`` leads to; returns the (new) root."""
    if isinstance(value, str):
        value = str(value)  # a plain str: YAML dumpers refuse str subclasses
    parent, key = _walk(doc, path)
    if parent is None:
        return value if kind == "replace" else doc
    if kind == "delete":
        del parent[key]
    elif kind == "replace":
        parent[key] = value
    elif kind == "swap":
        parent[key] = _swap_type(parent[key])
    elif kind == "deep":
        parent[key] = _deep(value)
    elif kind == "dup" and isinstance(parent, list):
        parent.insert(key, json.loads(json.dumps(parent[key])))
    elif kind == "dup" and isinstance(parent, dict):
        parent[f"{key}_"] = parent[key]
    elif (
        kind == "scale"
        and isinstance(parent[key], int | float)
        and not isinstance(parent[key], bool)
    ):
        parent[key] = parent[key] * value
    return doc


def _tree_ops(max_ops: int) -> st.SearchStrategy[list[tuple]]:
    path = st.lists(st.integers(0, 2**16), min_size=1, max_size=6)
    op = st.one_of(
        st.tuples(st.just("delete"), path, st.none()),
        st.tuples(st.just("replace"), path, evil_values()),
        st.tuples(st.just("swap"), path, st.none()),
        st.tuples(st.just("deep"), path, st.sampled_from([50, 2000, 100_000])),
        st.tuples(st.just("dup"), path, st.none()),
        st.tuples(st.just("scale"), path, st.sampled_from([-1, 0, 1e6, 1e300, 2**40])),
    )
    return st.lists(op, min_size=1, max_size=max_ops)


def _json_text(doc: Any) -> str:
    try:
        return json.dumps(doc, indent=1)
    except RecursionError:  # the "deep" op is deeper than json.dumps recurses
        return "[" * 100_000 + "]" * 100_000


def json_mutation(doc: Any, *, max_ops: int = 3) -> st.SearchStrategy[bytes]:
    """JSON text of ``doc`` with tree operations; sometimes also byte-level damage."""
    tree = _tree_ops(max_ops).map(lambda ops: _json_text(_apply_tree(doc, ops)).encode())
    raw = st.tuples(tree, st.lists(_byte_op(), max_size=2)).map(lambda t: _apply_bytes(*t))
    return st.one_of(tree, tree, raw)


def yaml_mutation(
    doc: Any, *, max_ops: int = 3, dump: Callable[[Any], str] | None = None
) -> st.SearchStrategy[bytes]:
    """YAML text of ``doc`` with tree operations, or with YAML-specific hostile text."""
    import yaml

    def _dump(d: Any) -> bytes:
        try:
            return (dump or (lambda x: yaml.safe_dump(x, sort_keys=False)))(d).encode()
        except RecursionError:
            return b"[" * 100_000

    tree = _tree_ops(max_ops).map(lambda ops: _dump(_apply_tree(doc, ops)))
    base = _dump(doc)
    hostile = st.sampled_from(
        [
            # billion laughs with aliases
            b"a: &a [x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
            b"c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c]\n"
            b"e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d]\nf: &f [*e, *e, *e, *e, *e, *e, *e, *e, *e]\n"
            b"image_width: *f\nimage_height: 12\ncamera_matrix: {data: *f}\n",
            b"!!python/object/apply:os.system ['touch /tmp/robogs_pwned']\n",
            b"image_width: !!python/object/apply:os.getcwd []\n",
            b"a: !!binary AAAA\n",
            b"\t- tabs\n",
            _LongBytes(b"%YAML:1.0\n---\n" + b"[" * 5000),
            b"- &x [*x]\n",
        ]
    )
    return st.one_of(tree, tree, hostile, bytes_mutation(base, max_ops=2))


# ----------------------------------------------------------------------------- XML


_ENTITY_DOCS = (
    b'<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">'
    b'<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;"><!ENTITY d "&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;">]>\n',
    b'<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY xxe SYSTEM "file:///etc/passwd">]>\n',
    b'<?xml version="1.0"?>\n<!DOCTYPE robot SYSTEM "http://127.0.0.1/robot.dtd">\n',
    b'<?xml version="1.0" encoding="UTF-16"?>\n',
)


def _apply_xml(data: bytes, ops: list[tuple]) -> bytes:
    from lxml import etree

    root = etree.fromstring(data, etree.XMLParser(remove_blank_text=True, resolve_entities=False))
    prefix = b""
    for kind, i, value in ops:
        nodes = list(root.iter())
        node = nodes[i % len(nodes)]
        if kind == "drop" and node is not root:
            node.getparent().remove(node)
        elif kind == "attr" and node.attrib:
            names = sorted(node.attrib)
            with contextlib.suppress(ValueError):  # lxml refuses NUL and control characters
                node.set(names[i % len(names)], value)
        elif kind == "unset" and node.attrib:
            names = sorted(node.attrib)
            del node.attrib[names[i % len(names)]]
        elif kind == "dup" and node is not root:
            with contextlib.suppress(etree.XMLSyntaxError):  # too deep for lxml to re-parse
                node.addnext(etree.fromstring(etree.tostring(node)))
        elif kind == "deep":
            cur = node
            for _ in range(value):
                cur = etree.SubElement(cur, "link")
        elif kind == "rename":
            node.tag = value if value.isidentifier() else "x"
        elif kind == "entity":
            prefix = _ENTITY_DOCS[i % len(_ENTITY_DOCS)]
        elif kind == "text":
            with contextlib.suppress(ValueError):
                node.text = value
    body = etree.tostring(root)
    if prefix:
        body = (
            prefix + body.replace(b'name="', b'name="&d;', 1) if b"&a;" in prefix else prefix + body
        )
    return body


def xml_mutation(data: bytes, *, max_ops: int = 3) -> st.SearchStrategy[bytes]:
    """XML ``data`` with tree operations, or byte-level damage."""
    idx = st.integers(0, 2**16)
    op = st.one_of(
        st.tuples(st.just("drop"), idx, st.none()),
        st.tuples(st.just("attr"), idx, st.sampled_from(EVIL_STRINGS)),
        st.tuples(st.just("attr"), idx, st.text(max_size=8)),
        st.tuples(st.just("unset"), idx, st.none()),
        st.tuples(st.just("dup"), idx, st.none()),
        st.tuples(st.just("deep"), idx, st.sampled_from([10, 300, 5000])),
        st.tuples(st.just("rename"), idx, st.sampled_from(["link", "joint", "robot", "mesh", "x"])),
        st.tuples(st.just("entity"), idx, st.none()),
        st.tuples(st.just("text"), idx, st.sampled_from(EVIL_STRINGS)),
    )
    tree = st.lists(op, min_size=1, max_size=max_ops).map(lambda ops: _apply_xml(data, ops))
    return st.one_of(tree, tree, tree, bytes_mutation(data, max_ops=3))


# ----------------------------------------------------------------------------- CSV


def _apply_csv(text: str, ops: list[tuple]) -> bytes:
    lines = text.splitlines()
    for kind, i, j, value in ops:
        if not lines:
            break
        li = i % len(lines)
        cells = lines[li].split(",")
        if kind == "cell":
            cells[j % len(cells)] = value
            lines[li] = ",".join(cells)
        elif kind == "drop_line":
            del lines[li]
        elif kind == "dup_line":
            lines.insert(li, lines[li])
        elif kind == "drop_col":
            k = j % len(cells)
            lines = [",".join(c for n, c in enumerate(ln.split(",")) if n != k) for ln in lines]
        elif kind == "swap_lines":
            lk = j % len(lines)
            lines[li], lines[lk] = lines[lk], lines[li]
        elif kind == "delim":
            lines[li] = lines[li].replace(",", value[:1] or ";")
        elif kind == "many_cols":
            lines[li] = lines[li] + ("," + value) * 300
    return ("\n".join(lines) + "\n").encode("utf-8", "surrogatepass")


def csv_mutation(text: str, *, max_ops: int = 4) -> st.SearchStrategy[bytes]:
    """CSV ``text`` with cell and line operations, or byte-level damage."""
    idx = st.integers(0, 2**16)
    cell = st.one_of(st.sampled_from(EVIL_STRINGS), st.text(max_size=8))
    op = st.one_of(
        st.tuples(st.just("cell"), idx, idx, cell),
        st.tuples(st.just("drop_line"), idx, idx, st.none()),
        st.tuples(st.just("dup_line"), idx, idx, st.none()),
        st.tuples(st.just("drop_col"), idx, idx, st.none()),
        st.tuples(st.just("swap_lines"), idx, idx, st.none()),
        st.tuples(st.just("delim"), idx, idx, st.sampled_from([";", "\t", " ", "|", "\x00"])),
        st.tuples(st.just("many_cols"), idx, idx, st.sampled_from(["1", "x", ""])),
    )
    tree = st.lists(op, min_size=1, max_size=max_ops).map(lambda ops: _apply_csv(text, ops))
    return st.one_of(tree, tree, tree, text_mutation(text, max_ops=3))


# ----------------------------------------------------------------------------- PLY


_PLY_TYPES = (
    "float",
    "double",
    "int",
    "uchar",
    "char",
    "short",
    "uint",
    "float128",
    "list uchar int",
    "",
)


def _apply_ply(data: bytes, ops: list[tuple]) -> bytes:
    end = data.find(b"end_header\n")
    head = data[:end].decode("ascii").split("\n")
    body = data[end + len(b"end_header\n") :]
    for kind, i, value in ops:
        props = [k for k, ln in enumerate(head) if ln.startswith("property")]
        if kind == "count":
            head = [
                f"element vertex {value}" if ln.startswith("element vertex") else ln for ln in head
            ]
        elif kind == "type" and props:
            k = props[i % len(props)]
            head[k] = f"property {value} {head[k].split()[-1]}".replace("  ", " ")
        elif kind == "drop_prop" and props:
            del head[props[i % len(props)]]
        elif kind == "dup_prop" and props:
            k = props[i % len(props)]
            head.insert(k, head[k])
        elif kind == "element":
            head.insert(len(head), f"element face {value}")
        elif kind == "format":
            head[1] = [
                "format ascii 1.0",
                "format binary_big_endian 1.0",
                "format binary_little_endian 9",
                "format",
            ][i % 4]
        elif kind == "body":
            body = _apply_bytes(body, [value])
        elif kind == "header_noise":
            head.insert(1 + i % max(len(head) - 1, 1), value)
    return ("\n".join(head) + "\nend_header\n").encode("ascii", "replace") + body


def ply_mutation(data: bytes, *, max_ops: int = 3) -> st.SearchStrategy[bytes]:
    """A binary PLY with header operations (absurd counts, bad types) or body damage."""
    idx = st.integers(0, 2**16)
    op = st.one_of(
        st.tuples(
            st.just("count"), idx, st.sampled_from([*INTERESTING_INTS, "x", "1e9", "", "-0"])
        ),
        st.tuples(st.just("type"), idx, st.sampled_from(_PLY_TYPES)),
        st.tuples(st.just("drop_prop"), idx, st.none()),
        st.tuples(st.just("dup_prop"), idx, st.none()),
        st.tuples(st.just("element"), idx, st.sampled_from([0, 1, 2**31])),
        st.tuples(st.just("format"), idx, st.none()),
        st.tuples(st.just("body"), idx, _byte_op()),
        st.tuples(
            st.just("header_noise"),
            idx,
            st.sampled_from(["comment x", "obj_info", "property", "element", "\x00", "é"]),
        ),
    )
    tree = st.lists(op, min_size=1, max_size=max_ops).map(lambda ops: _apply_ply(data, ops))
    return st.one_of(tree, tree, tree, bytes_mutation(data, max_ops=2))
