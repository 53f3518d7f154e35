"""Integrity checks (I0xx): the folder holds exactly the files the manifest lists, unchanged.

Paths that leave the dataset root are reported by ``I007`` and never opened by
any check (the context refuses them).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from ..dataset import MANIFEST_NAME
from ..errors import FormatError, PathEscapeError, RobogsError
from ..findings import Finding
from ..paths import resolve_inside
from ..writer import sha256_file
from . import context as _context
from .context import CheckContext, InputReported
from .registry import Check, check

__all__: list[str] = []

_REWRITE = "re-create the dataset with the writer, or restore the file from a backup"


def _inside(p: Path, root: Path) -> bool:
    target, base = p.resolve(), root.resolve()
    return target == base or base in target.parents


def _listed(ctx: CheckContext) -> Iterator[tuple[str, dict, Path]]:
    """(rel, manifest entry, absolute path) for every safe listed file."""
    for rel, entry in sorted(ctx.files.items()):
        if not isinstance(entry, dict):
            continue
        try:
            yield rel, entry, ctx.path(rel)
        except InputReported:
            continue


def _differs(chk: Check, rel: str, text: str, actual: int, listed: int) -> Iterator[Finding]:
    """A finding when a file's measured count (``text`` formats it) is not the listed one."""
    if actual != listed:
        yield chk.finding(
            f"{text.format(actual)}, the manifest says {listed}",
            file=rel,
            value=actual - listed,
            budget=0,
        )


# Checks share one shape by design: a @check(...) registration over a finding loop.
@check(
    "I001",
    group="integrity",
    severity="error",
    title="listed files exist",
    needs_full=False,
    needs_valid_manifest=False,
    quantity="missing files",
    hint=_REWRITE,
)
def _missing(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for rel, _entry, path in _listed(ctx):
        if not path.is_file():
            what = "is not a regular file" if path.exists() else "is missing"
            yield chk.finding(f"file listed in the manifest {what}", file=rel)


@check(
    "I002",
    group="integrity",
    severity="error",
    title="no files besides those listed",
    needs_full=False,
    needs_valid_manifest=False,
    quantity="unlisted files",
    hint="remove the file, or add it through the writer so the manifest lists it",
)
def _extra(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    listed = set(ctx.files)
    root = ctx.root
    for dirpath, dirnames, filenames in os.walk(root, followlinks=False):
        here = Path(dirpath)
        dirnames.sort()
        for name in [*sorted(filenames), *[d for d in dirnames if (here / d).is_symlink()]]:
            p = here / name
            rel = p.relative_to(root).as_posix()
            if rel == MANIFEST_NAME or rel in listed:
                continue
            if p.is_symlink() and not _inside(p, root):
                continue  # reported by I007, never opened
            elif (here / name).is_dir() and not p.is_symlink():
                continue
            yield chk.finding("file is in the dataset folder but not in the manifest", file=rel)


@check(
    "I003",
    group="integrity",
    severity="error",
    title="file sizes match the manifest",
    needs_full=False,
    quantity="size difference",
    unit="bytes",
    hint=_REWRITE,
)
def _size(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for rel, entry, path in _listed(ctx):
        if path.is_file() and isinstance(entry.get("size"), int):
            yield from _differs(chk, rel, "file is {} bytes", path.stat().st_size, entry["size"])


@check(
    "I004",
    group="integrity",
    severity="error",
    title="file contents match their sha256",
    quantity="hash mismatch",
    hint="the file was edited after the manifest was written; " + _REWRITE,
)
def _sha(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    todo = [
        (rel, entry, path)
        for rel, entry, path in _listed(ctx)
        if path.is_file()
        and isinstance(entry.get("sha256"), str)
        and entry.get("size") == path.stat().st_size
    ]
    ctx.progress(f"hashing {len(todo)} files")
    with ThreadPoolExecutor(max_workers=max(1, ctx.label_threads)) as pool:
        digests = pool.map(lambda item: sha256_file(item[2]), todo)
        for (rel, entry, _path), digest in zip(todo, digests, strict=True):
            if digest != entry["sha256"]:
                yield chk.finding(
                    f"sha256 is {digest[:12]}..., the manifest says {entry['sha256'][:12]}...",
                    file=rel,
                )


def _parquet_rels(ctx: CheckContext) -> list[str]:
    rels = {rel for rel in ctx.files if rel.endswith(".parquet")}
    for _ep, _name, st in ctx.streams():
        for fld in ("path", "frames", "labels", "extrinsics"):
            if isinstance(st.get(fld), str):
                rels.add(st[fld])
    return sorted(rels)


@check(
    "I005",
    group="integrity",
    severity="error",
    title="table row counts match the manifest",
    needs_full=False,
    quantity="row difference",
    unit="rows",
    hint=_REWRITE,
)
def _rows(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for rel, entry, _path in _listed(ctx):
        if not rel.endswith(".parquet") or not isinstance(entry.get("rows"), int):
            continue
        try:
            rows = ctx.footer(rel).num_rows
        except InputReported:
            continue
        yield from _differs(chk, rel, "table has {} rows", rows, entry["rows"])


@check(
    "I006",
    group="integrity",
    severity="error",
    title="parquet tables are readable",
    needs_full=False,
    quantity="unreadable tables",
    hint="the file is truncated or not parquet; re-export it",
)
def _readable(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for rel in _parquet_rels(ctx):
        try:
            path = ctx.existing(rel)
        except InputReported:
            continue
        try:
            ctx.footer(rel)
        except InputReported as exc:
            cause = exc.__cause__
            msg = cause.message if isinstance(cause, RobogsError) else "unreadable parquet footer"
            yield chk.finding(msg, file=rel)
            continue
        if ctx.quick:
            continue
        try:  # stream the body without keeping it, so corruption past the footer shows up here
            pf = pq.ParquetFile(path, pre_buffer=False)  # one row group in memory at a time
            for _batch in pf.iter_batches(batch_size=1 << 16, use_threads=False):
                pass
        except (pa.ArrowException, OSError, ValueError) as exc:
            yield chk.finding(
                f"table body is unreadable ({str(exc).splitlines()[0][:200]})", file=rel
            )


@check(
    "I007",
    group="integrity",
    severity="error",
    title="paths stay inside the dataset root",
    needs_full=False,
    needs_valid_manifest=False,
    quantity="escaping paths",
    hint="paths are relative to the dataset root, with '/' separators, no '..', no URI, no symlink out",
)
def _escapes(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    seen: set[str] = set()
    for ref in ctx.path_refs():
        exc = ctx.unsafe_paths.get(ref.rel)
        if exc is None or (ref.rel, ref.where) in seen:
            continue
        seen.add((ref.rel, ref.where))
        yield chk.finding(
            f"{exc.message}; it was not opened",
            file=MANIFEST_NAME,
            where=ref.where,
            hint=exc.hint or chk.hint,
        )
    root = ctx.root.resolve()
    for dirpath, dirnames, filenames in os.walk(ctx.root, followlinks=False):
        here = Path(dirpath)
        for name in sorted([*filenames, *dirnames]):
            p = here / name
            if not p.is_symlink():
                continue
            if not _inside(p, root):
                yield chk.finding(
                    "symbolic link leads outside the dataset root; it was not opened",
                    file=p.relative_to(ctx.root).as_posix(),
                    hint="replace the link with the file itself",
                )
    if not ctx.quick:
        yield from _urdf_mesh_escapes(chk, ctx)


def _urdf_mesh_escapes(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    from ..urdf import mesh_refs, parse_urdf_robot, resolve_mesh_uri

    robot = ctx.manifest.get("robot")
    rel = robot.get("urdf") if isinstance(robot, dict) else None
    if not isinstance(rel, str):
        return
    try:
        path = ctx.existing(rel)
        refs = mesh_refs(parse_urdf_robot(path))
    except (InputReported, RobogsError):
        return  # a broken URDF is reported by the geometry checks
    cache: dict[str, Path] = {}
    for ref in refs:
        try:
            resolve_mesh_uri(ref.uri, path, ctx.root, _cache=cache)
        except PathEscapeError as exc:
            yield chk.finding(
                f"{exc.message}; it was not opened",
                file=rel,
                where=f"link '{ref.link}' {ref.kind} mesh '{ref.uri}'",
                link=ref.link,
                hint=exc.hint or chk.hint,
            )
        except FormatError:
            continue  # unknown package etc.: reported when the URDF is loaded


@check(
    "I008",
    group="integrity",
    severity="error",
    title="files named by the manifest are listed in files",
    needs_full=False,
    needs_valid_manifest=False,
    quantity="unlisted references",
    hint="add the file through the writer so it is hashed and listed",
)
def _unlisted(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    listed = set(ctx.files)
    seen: set[str] = set()
    for ref in ctx.path_refs():
        if (
            ref.role == "file"
            or ref.rel in listed
            or ref.rel in ctx.unsafe_paths
            or ref.rel in seen
        ):
            continue
        seen.add(ref.rel)
        try:
            exists = resolve_inside(ctx.root, ref.rel).is_file()
        except PathEscapeError:
            continue
        state = "exists but is not listed" if exists else "is neither listed nor present"
        yield chk.finding(
            f"{ref.rel!r} {state} in the manifest's files", file=MANIFEST_NAME, where=ref.where
        )


def _nonfinite_rows(col: pa.Array | pa.ChunkedArray) -> np.ndarray:
    """Row indices (within the batch) holding a NaN or ±inf, nulls excluded.

    A list column (e.g. a 4x4 transform) counts a row once if any element is non-finite.
    """
    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    if pa.types.is_floating(col.type):
        vals = col.to_numpy(zero_copy_only=False)
        valid = ~np.asarray(col.is_null(), dtype=bool)
        return np.flatnonzero(~np.isfinite(vals) & valid)
    if (
        pa.types.is_list(col.type)
        or pa.types.is_large_list(col.type)
        or pa.types.is_fixed_size_list(col.type)
    ) and pa.types.is_floating(col.type.value_type):
        flat = pc.list_flatten(col)
        parents = np.asarray(pc.list_parent_indices(col))
        vals = flat.to_numpy(zero_copy_only=False)
        valid = ~np.asarray(flat.is_null(), dtype=bool)
        return np.unique(parents[~np.isfinite(vals) & valid])
    return np.empty(0, dtype=np.int64)


def _float_columns(schema: pa.Schema) -> list[str]:
    out = []
    for f in schema:
        t = f.type
        if pa.types.is_floating(t) or (
            (pa.types.is_list(t) or pa.types.is_large_list(t) or pa.types.is_fixed_size_list(t))
            and pa.types.is_floating(t.value_type)
        ):
            out.append(f.name)
    return out


@check(
    "I009",
    group="integrity",
    severity="error",
    title="numeric samples are finite",
    quantity="non-finite values",
    unit="rows",
    hint="the source holds NaN or inf samples; drop or repair those rows before using the data "
    "(a NaN joint angle or pose makes forward kinematics, rendering and fitting meaningless)",
)
def _finite(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    """Every floating column of every stream table, streamed one row group at a time."""
    from .streaming import batches  # streaming imports context, as this module does

    for ep, name, st in ctx.streams():
        rel = st.get("path")
        if not isinstance(rel, str) or not rel.endswith(".parquet"):
            continue
        try:
            schema = ctx.footer(rel).schema.to_arrow_schema()
        except InputReported:
            continue
        cols = _float_columns(schema)
        if not cols:
            continue
        read = cols + (["t_ns"] if "t_ns" in schema.names and "t_ns" not in cols else [])
        count = dict.fromkeys(cols, 0)
        first: dict[str, tuple[int, int | None]] = {}
        offset = 0
        try:
            for batch in batches(ctx, rel, read):
                t_ns = batch.column("t_ns").to_numpy() if "t_ns" in read else None
                for c in cols:
                    rows = _nonfinite_rows(batch.column(c))
                    if rows.size:
                        count[c] += int(rows.size)
                        if c not in first:
                            r = int(rows[0])
                            first[c] = (offset + r, int(t_ns[r]) if t_ns is not None else None)
                offset += batch.num_rows
        except InputReported:
            continue
        for c in cols:
            if not count[c]:
                continue
            row, t = first[c]
            yield chk.finding(
                f"{count[c]} of {offset} rows of column {c!r} hold NaN or inf (first at row {row})",
                value=float(count[c]),
                budget=0.0,
                file=rel,
                where=f"column {c}, row {row}",
                episode=ep.id,
                stream=name,
                t_ns=t,
            )


@check(
    "I010",
    group="integrity",
    severity="warning",
    title="tables fit the in-memory budget of the checks",
    needs_full=False,
    quantity="decompressed size",
    unit="MiB",
    hint="a table far larger than its file is a decompression bomb or a corrupt footer; a "
    "genuine one should be split into shorter episodes",
)
def _table_budget(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    """Footer totals only: nothing is decompressed to find out."""
    for rel in _parquet_rels(ctx):
        try:
            size = ctx.table_bytes(rel)
            disk = ctx.existing(rel).stat().st_size
        except (InputReported, OSError):
            continue
        if size <= _context.MAX_TABLE_BYTES:
            continue
        rows = ctx.footer(rel).num_rows
        yield chk.finding(
            f"table takes {size / 2**20:.0f} MiB in memory ({rows} rows, {size / max(disk, 1):.0f}x "
            f"its {disk} bytes on disk); checks that read whole tables skip it",
            value=round(size / 2**20, 1),
            budget=_context.MAX_TABLE_BYTES / 2**20,
            file=rel,
        )


@check(
    "I011",
    group="integrity",
    severity="error",
    title="chunk indexes are readable and agree with the manifest",
    needs_full=False,
    needs_valid_manifest=False,
    quantity="index problems",
    hint="rewrite the indexes with the writer (robogs migrate DATASET --to sharded)",
)
def _chunk_indexes(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    """Sharded layout (spec 1.1.0): every chunk index is listed in the manifest's own ``files``
    (so I001/I003/I004 verify its size and sha256), reads as a chunk index, holds the episode,
    file and row counts the manifest states, and lists only files under its chunk folder."""
    shards = ctx.manifest.get("shards")
    if shards is None:
        return
    own = ctx.dataset.manifest.get("files")
    own = own if isinstance(own, dict) else {}
    chunks = shards.get("chunks") if isinstance(shards, dict) else None
    for i, entry in enumerate(chunks if isinstance(chunks, list) else []):
        rel = entry.get("index") if isinstance(entry, dict) else None
        if isinstance(rel, str) and rel not in own:
            yield chk.finding(
                "chunk index is not listed in the manifest's files (its hash is not checked)",
                file=rel,
                where=f"/shards/chunks/{i}",
            )
    for p in ctx.dataset.shard_problems:
        yield chk.finding(p.message, file=p.file, where=p.where)
