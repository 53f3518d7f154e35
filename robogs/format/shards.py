"""The chunked (sharded) layout of spec 1.1.0: episodes in ``episodes/chunk-NNN/``, one index each.

A dataset with many episodes keeps ``manifest.json`` small: its ``shards`` block names one
index per chunk (``episodes/chunk-NNN/index.json``) with the chunk's episode, file and row
counts, and its ``files`` section lists the indexes (sha256, size) but not the episode files.
Each index holds the chunk's episode entries and the ``files`` entries (sha256, size, rows) of
every file under its chunk folder. The layout follows LeRobot v3's ``chunk-000`` folders of at
most ``chunk_size`` (default 1000) episodes (https://huggingface.co/docs/lerobot/lerobot-dataset-v3).

Readers merge the indexes lazily (:func:`expand`): the merged manifest is the manifest with
``episodes`` = its own episodes followed by each chunk's, in chunk order, and ``files`` = its
own files and each chunk's. A flat (1.0-style) dataset has no ``shards`` block and is its own
merged manifest.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import FormatError, RobogsError
from .jsonio import dumps_json, read_json
from .paths import resolve_inside

__all__ = [
    "CHUNK_FORMAT",
    "DEFAULT_CHUNK_SIZE",
    "INDEX_NAME",
    "LAYOUT",
    "Migration",
    "ShardProblem",
    "chunk_dir",
    "chunk_of",
    "expand",
    "is_sharded",
    "migrate_layout",
    "plan_moves",
    "rename_refs",
    "read_chunk",
    "shard_manifest",
]

LAYOUT = "chunked"
CHUNK_FORMAT = "robogs-chunk"
INDEX_NAME = "index.json"
DEFAULT_CHUNK_SIZE = 1000

_CHUNK_RE = re.compile(r"^episodes/chunk-(\d{3,})/")


def chunk_dir(k: int) -> str:
    """Dataset-relative folder of chunk ``k``: ``episodes/chunk-000``."""
    return f"episodes/chunk-{k:03d}"


def chunk_of(rel: str) -> int | None:
    """The chunk number of a path under ``episodes/chunk-NNN/``; None elsewhere."""
    m = _CHUNK_RE.match(rel)
    return int(m.group(1)) if m else None


def is_sharded(manifest: Any) -> bool:
    """True when a manifest declares the chunked layout (a ``shards`` block)."""
    return isinstance(manifest, dict) and "shards" in manifest


@dataclass(frozen=True)
class ShardProblem:
    """Something wrong with a chunk index: the file it concerns, where, and what."""

    file: str
    where: str
    message: str


def _chunk_entries(manifest: dict[str, Any]) -> list[Any]:
    shards = manifest.get("shards")
    chunks = shards.get("chunks") if isinstance(shards, dict) else None
    return chunks if isinstance(chunks, list) else []


def read_chunk(root: Path, entry: dict[str, Any], *, manifest_path: Path) -> dict[str, Any]:
    """Read and shape-check one chunk index named by a ``shards.chunks`` entry.

    Raises:
        FormatError: the index is missing, not JSON, escapes the root or is not a chunk index.
    """
    rel = entry.get("index")
    if not isinstance(rel, str):
        raise FormatError("chunk entry has no index path", path=manifest_path, where="shards")
    path = resolve_inside(root, rel, source=manifest_path, where="shards/chunks/index")
    doc = read_json(path, what="chunk index", root=root)

    def bad(msg: str, where: str = "/") -> FormatError:
        return FormatError(msg, path=path, where=where, hint="rewrite it with robogs migrate")

    if not isinstance(doc, dict) or doc.get("format") != CHUNK_FORMAT:
        raise bad(f"not a chunk index (format != {CHUNK_FORMAT!r})", "/format")
    if not isinstance(doc.get("episodes"), list):
        raise bad("'episodes' must be a list", "/episodes")
    files = doc.get("files")
    if not isinstance(files, dict) or not all(isinstance(v, dict) for v in files.values()):
        raise bad("'files' must map paths to entries", "/files")
    return doc


def expand(
    root: Path,
    manifest: dict[str, Any],
    *,
    problems: list[ShardProblem] | None = None,
    manifest_path: Path | None = None,
) -> dict[str, Any]:
    """The merged manifest: the manifest's episodes and files followed by every chunk's.

    Args:
        root: dataset folder.
        manifest: the manifest as read (returned unchanged when it is not sharded).
        problems: collects index problems and leaves the chunk out; None raises them instead.
        manifest_path: for error messages (default ``root/manifest.json``).

    Raises:
        FormatError: a chunk index is unreadable or malformed (only when ``problems`` is None).
    """
    if not is_sharded(manifest):
        return manifest
    mpath = manifest_path or root / "manifest.json"
    raw_eps, raw_files = manifest.get("episodes", []), manifest.get("files", {})
    episodes = list(raw_eps) if isinstance(raw_eps, list) else []
    files = dict(raw_files) if isinstance(raw_files, dict) else {}
    for i, entry in enumerate(_chunk_entries(manifest)):
        try:
            if not isinstance(entry, dict):
                raise FormatError("chunk entry must be an object", path=mpath)
            doc = read_chunk(root, entry, manifest_path=mpath)
        except RobogsError as exc:
            if problems is None:
                raise
            rel = entry.get("index") if isinstance(entry, dict) else None
            problems.append(
                ShardProblem(
                    rel if isinstance(rel, str) else "manifest.json",
                    exc.where or f"/shards/chunks/{i}",
                    exc.message,
                )
            )
            continue
        episodes.extend(doc["episodes"])
        for rel, fentry in doc["files"].items():
            if rel in files:
                if problems is None:
                    raise FormatError(
                        f"{rel!r} is listed twice", path=mpath, where=f"/shards/chunks/{i}"
                    )
                problems.append(ShardProblem(entry["index"], f"/files/{rel}", "listed twice"))
                continue
            files[rel] = fentry
        if problems is not None:
            problems.extend(_disagreements(entry, doc))
    merged = dict(manifest)
    merged["episodes"], merged["files"] = episodes, files
    return merged


def _disagreements(entry: dict[str, Any], doc: dict[str, Any]) -> list[ShardProblem]:
    """Counts in the manifest's chunk entry that the index does not bear out, and index files
    outside the chunk's folder."""
    rel = entry["index"]
    folder = rel.rsplit("/", 1)[0] + "/" if "/" in rel else ""
    out = []
    rows = sum(
        int(v.get("rows", 0)) for v in doc["files"].values() if isinstance(v.get("rows"), int)
    )
    for key, actual in (
        ("episodes", len(doc["episodes"])),
        ("files", len(doc["files"])),
        ("rows", rows),
    ):
        listed = entry.get(key)
        if isinstance(listed, int) and listed != actual:
            out.append(
                ShardProblem(
                    rel, f"/{key}", f"index holds {actual} {key}, the manifest says {listed}"
                )
            )
    for f in sorted(doc["files"]):
        if not f.startswith(folder) or f == rel:
            out.append(
                ShardProblem(rel, f"/files/{f}", f"{f!r} lies outside the chunk folder {folder!r}")
            )
    return out


def _episode_chunk(ep: dict[str, Any], fields: tuple[str, ...]) -> int | None:
    """The one chunk all of an episode's stream files lie in (None: no stream files)."""
    found: set[int | None] = set()
    for st in (ep.get("streams") or {}).values():
        for fld in fields:
            rel = st.get(fld) if isinstance(st, dict) else None
            if isinstance(rel, str):
                found.add(chunk_of(rel))
    if not found:
        return None
    if len(found) > 1 or None in found:
        raise FormatError(
            f"episode {ep.get('id')!r} has stream files outside one chunk folder: "
            f"{sorted(str(c) for c in found)}",
            where=f"episodes/{ep.get('id')}",
            hint="write an episode's files under one episodes/chunk-NNN/ folder",
        )
    return found.pop()


def shard_manifest(
    root: Path,
    manifest: dict[str, Any],
    *,
    stream_fields: tuple[str, ...],
    hasher: Callable[[Path], str],
) -> dict[str, Any]:
    """Write a chunk index for every ``episodes/chunk-NNN/`` folder of a merged manifest; return
    the small manifest (writers call this on their temporary folder before the swap).

    Every file under a chunk folder goes to its index; an episode goes to the chunk holding its
    stream files (all in one chunk), an episode without stream files stays in the manifest.

    Args:
        root: the folder being written.
        manifest: merged manifest with ``shards`` (``chunk_size``), ``episodes`` and ``files``;
            old index files it lists are replaced (unlinked first: they may be hard links to
            the previous version).
        stream_fields: the stream fields that name files.
        hasher: sha256 of a file.
    """
    shards = dict(manifest["shards"])
    by_chunk: dict[int, dict[str, Any]] = {}
    top_files: dict[str, Any] = {}
    for rel, entry in manifest["files"].items():
        k = chunk_of(rel)
        if _is_index(rel):
            (root / rel).unlink(missing_ok=True)
            continue
        if k is None:
            top_files[rel] = entry
        else:
            by_chunk.setdefault(k, {"episodes": [], "files": {}})["files"][rel] = entry
    top_eps = []
    for ep in manifest["episodes"]:
        k = _episode_chunk(ep, stream_fields)
        if k is None:
            top_eps.append(ep)
        else:
            by_chunk.setdefault(k, {"episodes": [], "files": {}})["episodes"].append(ep)
    chunks = []
    for k in sorted(by_chunk):
        part = by_chunk[k]
        rel = f"{chunk_dir(k)}/{INDEX_NAME}"
        doc = {
            "format": CHUNK_FORMAT,
            "chunk": k,
            "episodes": part["episodes"],
            "files": part["files"],
        }
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.unlink(missing_ok=True)
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(dumps_json(doc))
            fh.flush()
            os.fsync(fh.fileno())
        top_files[rel] = {"sha256": hasher(path), "size": path.stat().st_size}
        rows = sum(int(v.get("rows", 0)) for v in part["files"].values())
        chunks.append(
            {
                "index": rel,
                "episodes": len(part["episodes"]),
                "files": len(part["files"]),
                "rows": rows,
            }
        )
    shards.update(
        layout=LAYOUT,
        chunk_size=int(shards.get("chunk_size", DEFAULT_CHUNK_SIZE)),
        episodes=len(manifest["episodes"]),
        chunks=chunks,
    )
    small = dict(manifest)
    small["shards"], small["episodes"] = shards, top_eps
    small["files"] = dict(sorted(top_files.items()))
    return small


@dataclass
class Migration:
    """What :func:`migrate_layout` did: the layout written, episodes, files moved, chunks."""

    layout: str
    episodes: int
    moved: int
    chunks: int
    verified: int


def plan_moves(
    episodes: list[dict[str, Any]], files: dict[str, Any], chunk_size: int, fields: tuple[str, ...]
) -> dict[str, str]:
    """Old path -> new path of every file of the ``k``-th episode, into chunk ``k // chunk_size``.

    Files under the episode's folder (``episodes/<id>/`` or ``episodes/chunk-NNN/<id>/``) keep
    their path below it; a stream file elsewhere goes to ``episodes/chunk-CCC/<id>/<old path>``.
    """
    moves: dict[str, str] = {}

    def home(rel: str) -> str:  # the path with any chunk folder taken out
        k = chunk_of(rel)
        return rel if k is None else "episodes/" + rel[len(chunk_dir(k)) + 1 :]

    by_folder: dict[str, list[str]] = {}
    for rel in files:
        parts = home(rel).split("/")
        if len(parts) > 2 and parts[0] == "episodes":
            by_folder.setdefault(parts[1], []).append(rel)
    for k, ep in enumerate(episodes):
        eid, dest = str(ep.get("id")), chunk_dir(k // chunk_size)
        named = [rel for st in (ep.get("streams") or {}).values() for f in fields
                 if isinstance(rel := st.get(f), str)]  # fmt: skip
        for rel in [*by_folder.get(eid, []), *named]:
            h = home(rel)
            new = (
                f"{dest}/{h[len('episodes/') :]}"
                if h.startswith(f"episodes/{eid}/")
                else f"{dest}/{eid}/{rel}"
            )
            if moves.setdefault(rel, new) != new:
                raise FormatError(
                    f"{rel!r} belongs to two episodes; it cannot move into one chunk",
                    where=f"episodes/{eid}",
                    hint="give every episode its own files",
                )
    return {old: new for old, new in moves.items() if old != new}


def rename_refs(obj: Any, moves: dict[str, str]) -> Any:
    """``obj`` with every string that is a moved path replaced by its new path."""
    if isinstance(obj, str):
        return moves.get(obj, obj)
    if isinstance(obj, dict):
        return {k: rename_refs(v, moves) for k, v in obj.items()}
    if isinstance(obj, list):
        return [rename_refs(v, moves) for v in obj]
    return obj


def migrate_layout(
    path: str | Path,
    *,
    to: str = "sharded",
    chunk_size: int = DEFAULT_CHUNK_SIZE,
    progress: Callable[[str], None] | None = None,
) -> Migration:
    """Rewrite a dataset into the chunked (``sharded``) or the ``flat`` layout, atomically.

    Every file is first checked against the sha256 the manifest records (a damaged dataset is
    refused: migrating would bless the damage). The new version is built by the writer in a
    temporary folder (files hard-linked where possible, episode files renamed into
    ``episodes/chunk-NNN/``, one index per chunk) and swapped into place in one step
    (:func:`robogs.format.replace.exchange`); the hashes it records are then compared with the
    old ones, file for file.

    Raises:
        RobogsError: unknown layout, bad chunk size, a file that fails its hash, or a file
            named by two episodes.
    """
    from .checks.context import STREAM_FILE_FIELDS
    from .dataset import Dataset
    from .writer import sha256_file

    note = progress or (lambda _msg: None)
    if to not in ("sharded", "flat"):
        raise RobogsError(f"unknown layout {to!r}", where="--to", hint="use sharded or flat")
    if chunk_size < 1:
        raise RobogsError("chunk size must be >= 1", where="--chunk-size")
    ds = Dataset.open(path)
    merged = ds.full_manifest()
    files: dict[str, Any] = merged.get("files", {})
    note(f"verifying {len(files)} files")
    bad = [
        rel for rel, e in sorted(files.items()) if sha256_file(ds.resolve(rel)) != e.get("sha256")
    ]
    if bad:
        raise FormatError(
            f"{len(bad)} file(s) do not match their sha256 (first: {bad[0]}); nothing was changed",
            path=ds.root / bad[0],
            hint="run robogs validate DATASET and repair the dataset first",
        )
    fields = tuple(STREAM_FILE_FIELDS)
    episodes = list(merged.get("episodes", []))
    moves = plan_moves(episodes, files, chunk_size, fields) if to == "sharded" else {}
    note(f"moving {len(moves)} files")
    with ds.edit() as w:
        for old, new in moves.items():
            dst = w.tmp / new
            dst.parent.mkdir(parents=True, exist_ok=True)
            os.replace(w.tmp / old, dst)
        for old in moves:  # folders left empty by the moves
            parent = (w.tmp / old).parent
            while parent != w.tmp and parent.is_dir() and not any(parent.iterdir()):
                parent.rmdir()
                parent = parent.parent
        w.manifest = rename_refs(w.manifest, moves)
        if to == "sharded":
            w.manifest["shards"] = {"layout": LAYOUT, "chunk_size": chunk_size}
        else:
            w.manifest.pop("shards", None)
            for rel in files:
                if _is_index(rel):
                    (w.tmp / rel).unlink()
        note("writing the new version")
        new_ds = w.commit()
    new_files = new_ds.files
    verified = 0
    for rel, e in files.items():
        if _is_index(rel):
            continue
        got = new_files.get(moves.get(rel, rel), {}).get("sha256")
        if got != e.get("sha256"):
            raise FormatError(
                f"after the migration {moves.get(rel, rel)!r} has sha256 {got}, "
                f"the source had {e.get('sha256')}",
                path=new_ds.root,
                hint="restore the dataset from a backup and report this as a bug",
            )
        verified += 1
    chunks = len(new_ds.manifest.get("shards", {}).get("chunks", []))
    return Migration(to, len(episodes), len(moves), chunks, verified)


def _is_index(rel: str) -> bool:
    k = chunk_of(rel)
    return k is not None and rel == f"{chunk_dir(k)}/{INDEX_NAME}"
