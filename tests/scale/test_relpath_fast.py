"""``check_relpath``'s split fast path gives what the PurePosixPath spelling gave, path for path.

Oracle: the reference below (the function before the fast path, verbatim in its logic) on
hand-picked tricky spellings and on 20,000 random strings over an alphabet of separators,
dots, letters and odd characters; the result or the error message must be the same.
"""

from __future__ import annotations

import random
from pathlib import PurePosixPath

from robogs.format.errors import PathEscapeError
from robogs.format.paths import NAME_MAX_BYTES, PATH_MAX_BYTES, check_relpath


def _reference(rel: str) -> str:
    if not isinstance(rel, str) or not rel or "\x00" in rel:
        raise PathEscapeError(f"invalid path {rel!r}")
    if (
        "://" in rel
        or rel.startswith(("/", "\\"))
        or "\\" in rel
        or (len(rel) > 1 and rel[1] == ":")
    ):
        raise PathEscapeError(f"path {rel!r} is not relative to the dataset root")
    parts = PurePosixPath(rel).parts
    long = [p for p in parts if len(p.encode("utf-8", "surrogatepass")) > NAME_MAX_BYTES]
    if long or len(rel.encode("utf-8", "surrogatepass")) > PATH_MAX_BYTES:
        raise PathEscapeError("too long")
    if any(p == ".." for p in parts):
        raise PathEscapeError(f"path {rel!r} escapes the dataset root")
    return str(PurePosixPath(*[p for p in parts if p != "."]))


def _outcome(fn, rel: str) -> str:
    try:
        return "ok " + fn(rel)
    except PathEscapeError as exc:
        return "error " + ("too long" if "too long" in exc.message else exc.message)


TRICKY = [
    "a", "a/b", "a//b", "a/./b", "./a", "a/.", "a/", ".", "..", "a/../b", "a/..", "...", "a/...",
    ".a/b.", "a/b/", "//a", "a///b/", "./", "././a", "a/.b/./c", "é/ü", "x" * 256, "a/" + "y" * 255,
    "a/" * 600, "c:x", "a:b", "a\\b", "http://x", "", "a\x00b", " ", "a/ /b",
]  # fmt: skip


def test_tricky_spellings():
    for rel in TRICKY:
        assert _outcome(check_relpath, rel) == _outcome(_reference, rel), rel


def test_random_spellings():
    rng = random.Random(3)
    alphabet = ["/", "/", ".", ".", "a", "b", "é", " ", ":", "\\"]
    for _ in range(20000):
        rel = "".join(rng.choice(alphabet) for _ in range(rng.randint(1, 12)))
        assert _outcome(check_relpath, rel) == _outcome(_reference, rel), repr(rel)
