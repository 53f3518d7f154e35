"""Convert many bags into one dataset, one task per bag (in this process, or as Ray tasks).

Each bag ``k`` (in sorted order) is converted by :func:`robogs.convert.ingest.convert.convert_path`
into its own dataset under ``OUT.partial/.parts/k`` with episode id ``ep{k:04d}`` (with
``--split-at-gaps``, the task also cuts it, at its own derived or given gap, into
``ep{k:04d}_000``, ...; the cut table is kept in ``provenance.bags``). The driver
then moves each episode's files into ``OUT.partial/episodes/``, takes the files outside the
episodes (robot, cameras) from the first bag that converted and requires the same bytes from
the others, and writes the manifest once, at the end (a temporary file renamed over it), before
renaming ``OUT.partial`` to ``OUT``. With ``chunk_size`` (by default when more than 100 bags
converted) the dataset has the sharded layout of spec 1.1.0: the ``k``-th converted episode in
``episodes/chunk-{k // chunk_size:03d}/``, one index per chunk. A bag that fails (unreadable, or with a robot unlike the
first's) is left out and named, with its one-line error, in ``provenance.failed``; the others
land. A Ray task whose worker dies is retried (``max_retries``).
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from robogs.format.errors import InputError, RobogsError
from robogs.format.jsonio import dumps_json, read_json

__all__ = ["BagResult", "ManyResult", "convert_many", "convert_bag", "MERGED_KEYS", "SHARD_ABOVE"]

#: more converted episodes than this give the sharded layout (unless ``chunk_size`` says)
SHARD_ABOVE = 100

#: manifest sections that every bag's dataset must share (besides episodes, files, provenance)
MERGED_KEYS = ("format", "spec_version", "conventions", "robot", "cameras", "assets", "physics")


@dataclass
class BagResult:
    """One bag: its episode id, and its manifest (converted) or its one-line error."""

    index: int
    source: str
    episode: str
    manifest: dict[str, Any] | None = None
    error: str | None = None
    seconds: float = 0.0
    peak_rss: int = 0
    pid: int = 0


@dataclass
class ManyResult:
    """The merged dataset: episodes written, bags that failed (source, error), timings."""

    out: Path
    episodes: list[str] = field(default_factory=list)
    bags: int = 0  # bags converted (each gives one episode, or several with --split-at-gaps)
    failed: list[dict[str, str]] = field(default_factory=list)
    peak_rss: dict[int, int] = field(default_factory=dict)
    task_seconds: float = 0.0
    wall_seconds: float = 0.0


def _peak_rss() -> int:
    import resource

    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


def convert_bag(index: int, src: str, part: str, options: Any, fmt: str | None) -> BagResult:
    """Task body: convert one bag into the dataset folder ``part`` (episode ``ep{index:04d}``)."""
    from dataclasses import replace

    from .ingest.convert import convert_path

    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    t0 = time.perf_counter()
    eid = f"ep{index:04d}"
    res = BagResult(index, src, eid, pid=os.getpid())
    try:
        opts = replace(options, episode=eid, progress=False)
        convert_path(Path(src), Path(part), fmt=fmt, options=opts, force=True)
        res.manifest = read_json(Path(part) / "manifest.json", what="manifest")
    except RobogsError as exc:
        res.error = exc.one_line()
    except Exception as exc:  # a converter bug must not sink the other bags
        res.error = f"{src}: {type(exc).__name__}: {str(exc)[:300]}"
    res.seconds, res.peak_rss = time.perf_counter() - t0, _peak_rss()
    return res


def _local(jobs: Sequence[tuple]) -> Iterator[BagResult]:
    for job in jobs:
        yield convert_bag(*job)


def _ray(jobs: Sequence[tuple], executor: Any) -> Iterator[BagResult]:
    ray = executor.connect()
    task = ray.remote(convert_bag).options(num_cpus=1, max_retries=executor.max_retries)
    pending = [task.remote(*job) for job in jobs]
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        try:
            yield ray.get(done[0])
        except Exception as exc:  # a task that failed all its tries (e.g. its node died)
            for ref in pending:
                ray.cancel(ref)
            raise RobogsError(
                f"a Ray task failed: {(str(exc).strip().splitlines() or ['?'])[-1][:300]}",
                where="--ray",
                hint="the bags and OUT must be at the same path on every node",
            ) from None


def convert_many(
    sources: Sequence[str | Path],
    out: str | Path,
    options: Any,
    *,
    fmt: str | None = None,
    executor: Any = None,
    force: bool = False,
    progress: Callable[[int, int], None] | None = None,
    chunk_size: int | None = None,
) -> ManyResult:
    """Convert ``sources`` (one episode each) into one dataset at ``out``.

    Args:
        sources: bag or MCAP paths, in episode order.
        out: the dataset folder to create.
        options: a :class:`robogs.convert.ingest.context.ConvertOptions` (its episode id is
            replaced per bag).
        fmt: source format (default: detected per bag).
        executor: a :class:`robogs.format.distributed.RayExecutor`, or None for this process.
        force: replace an existing ``out``.
        progress: called as ``progress(bags_done, n_bags)``.
        chunk_size: episodes per chunk of the sharded layout; None: sharded in chunks of
            :data:`~robogs.format.shards.DEFAULT_CHUNK_SIZE` when more than
            :data:`SHARD_ABOVE` episodes converted, flat otherwise; 0: flat.

    Raises:
        InputError: no sources, ``out`` exists (without ``force``), or no bag converted.
    """
    t0 = time.perf_counter()
    out = Path(out)
    srcs = [str(Path(s)) for s in sources]
    if not srcs:
        raise InputError(
            "no source matches", where="SRC_GLOB", hint="quote the glob: 'bags/*.mcap'"
        )
    if out.exists() and not force:
        raise InputError(f"{out} exists", where="OUT", hint="--force replaces it")
    stage = out.with_name(out.name + ".partial")
    if stage.exists():
        shutil.rmtree(stage)
    parts = stage / ".parts"
    parts.mkdir(parents=True)
    jobs = [(k, s, str(parts / f"{k:04d}"), options, fmt) for k, s in enumerate(srcs)]
    stream = _local(jobs) if executor is None else _ray(jobs, executor)
    result = ManyResult(out)
    bags: dict[int, BagResult] = {}
    for done, res in enumerate(stream, 1):
        bags[res.index] = res
        result.peak_rss[res.pid] = max(result.peak_rss.get(res.pid, 0), res.peak_rss)
        result.task_seconds += res.seconds
        if progress is not None:
            progress(done, len(jobs))
    manifest = _merge(stage, [bags[k] for k in sorted(bags)], result)
    if manifest is None:
        shutil.rmtree(stage, ignore_errors=True)
        first = result.failed[0]["error"] if result.failed else "?"
        raise InputError(
            f"none of the {len(srcs)} sources converted (first: {first})",
            where="SRC_GLOB",
            hint="convert one bag alone to see why",
        )
    shutil.rmtree(parts)
    manifest = _shard(stage, manifest, chunk_size)
    tmp = stage / ".manifest.json.tmp"
    tmp.write_text(dumps_json(manifest), encoding="utf-8")
    os.replace(tmp, stage / "manifest.json")  # the manifest is written last, once
    if out.exists():
        shutil.rmtree(out)
    os.replace(stage, out)
    result.wall_seconds = time.perf_counter() - t0
    return result


def _shard(stage: Path, manifest: dict[str, Any], chunk_size: int | None) -> dict[str, Any]:
    """The merged manifest in the sharded layout (files moved in ``stage``), or as it is."""
    from robogs.format.checks.context import STREAM_FILE_FIELDS
    from robogs.format.shards import DEFAULT_CHUNK_SIZE, plan_moves, rename_refs, shard_manifest
    from robogs.format.writer import sha256_file

    n = len(manifest["episodes"])
    if chunk_size is None:
        chunk_size = DEFAULT_CHUNK_SIZE if n > SHARD_ABOVE else 0
    if not chunk_size:
        return manifest
    fields = tuple(STREAM_FILE_FIELDS)
    moves = plan_moves(manifest["episodes"], manifest["files"], chunk_size, fields)
    for old, new in moves.items():
        (stage / new).parent.mkdir(parents=True, exist_ok=True)
        os.replace(stage / old, stage / new)
    for old in moves:  # the episode folders left empty
        parent = (stage / old).parent
        while parent != stage and parent.is_dir() and not any(parent.iterdir()):
            parent.rmdir()
            parent = parent.parent
    merged = rename_refs({k: v for k, v in manifest.items() if k != "files"}, moves)
    merged["files"] = {moves.get(r, r): e for r, e in manifest["files"].items()}
    merged["shards"] = {"layout": "chunked", "chunk_size": chunk_size}
    return shard_manifest(stage, merged, stream_fields=fields, hasher=sha256_file)


def _merge(stage: Path, bags: list[BagResult], result: ManyResult) -> dict[str, Any] | None:
    """Move the converted episodes into ``stage``; the merged manifest (None if none converted)."""
    base: dict[str, Any] | None = None
    shared: dict[str, dict[str, Any]] = {}
    episodes: list[dict[str, Any]] = []
    files: dict[str, dict[str, Any]] = {}
    per_bag: dict[str, Any] = {}
    for bag in bags:
        m = bag.manifest
        if m is None:
            result.failed.append({"source": bag.source, "error": bag.error or "not converted"})
            continue
        part = stage / ".parts" / f"{bag.index:04d}"
        ids = [str(e.get("id")) for e in m.get("episodes", []) if isinstance(e, dict)]
        # the bag's episode, or the pieces --split-at-gaps cut it into (epKKKK_000, ...)
        prefix = tuple(f"episodes/{eid}/" for eid in dict.fromkeys([bag.episode, *ids]))
        own = {r: e for r, e in m.get("files", {}).items() if r.startswith(prefix)}
        common = {r: e for r, e in m.get("files", {}).items() if not r.startswith(prefix)}
        if base is None:
            base, shared = m, common
        else:
            differs = [k for k in MERGED_KEYS if m.get(k) != base.get(k)]
            differs += [
                r
                for r in sorted(set(common) | set(shared))
                if common.get(r, {}).get("sha256") != shared.get(r, {}).get("sha256")
            ]
            if differs:
                result.failed.append(
                    {
                        "source": bag.source,
                        "error": f"differs from the first converted bag in {differs[:5]}",
                    }
                )
                continue
        for rel in sorted(own):
            (stage / rel).parent.mkdir(parents=True, exist_ok=True)
            os.replace(part / rel, stage / rel)
        if base is m:
            for rel in sorted(common):
                (stage / rel).parent.mkdir(parents=True, exist_ok=True)
                os.replace(part / rel, stage / rel)
        files.update(own)
        episodes += m.get("episodes", [])
        per_bag[bag.episode] = m.get("provenance", {})
        result.episodes += ids
        result.bags += 1
    if base is None:
        return None
    files.update(shared)
    manifest = {k: v for k, v in base.items() if k not in ("episodes", "files", "provenance")}
    manifest["name"] = result.out.name
    manifest["episodes"] = episodes
    manifest["files"] = dict(sorted(files.items()))
    manifest["provenance"] = {
        "converter": "robogs convert --ray" if per_bag else "robogs convert",
        "sources": len(bags),
        "bags": per_bag,
        "failed": list(result.failed),
    }
    return manifest


def run_many(args: Any, options: Any) -> int:
    """``robogs convert 'SRC_GLOB' OUT [--ray [ADDRESS|auto]]``: exit 0 when every bag landed,
    1 when some failed (named on stderr and in ``provenance.failed``), 2 when none did."""
    import glob
    import sys

    srcs = sorted(glob.glob(str(args.src)))
    executor = None
    if args.ray is not None:
        from robogs.format.distributed import RayExecutor

        executor = (
            RayExecutor(None, init_kwargs={"object_store_memory": 200 * 1024**2})
            if args.ray == "local"
            else RayExecutor(args.ray)
        )
    show = None
    if options.progress:

        def show(done: int, total: int) -> None:
            print(f"\r{done}/{total} bags", end="\n" if done == total else "", file=sys.stderr)

    try:
        res = convert_many(
            srcs,
            args.out,
            options,
            fmt=args.fmt,
            executor=executor,
            force=args.force,
            progress=show,
        )
    finally:
        if executor is not None:
            executor.shutdown()
    peak = max(res.peak_rss.values(), default=0)
    each = "one episode each" if len(res.episodes) == res.bags else f"{len(res.episodes)} episodes"
    print(
        f"wrote {res.out} ({res.bags} of {len(srcs)} bags, {each}; "
        f"{len(res.peak_rss)} worker processes, peak RSS {peak / 2**20:.0f} MiB, "
        f"{res.task_seconds:.1f} task-s in {res.wall_seconds:.1f} s)"
    )
    if options.split_gaps:
        bags = read_json(res.out / "manifest.json", what="manifest")["provenance"]["bags"]
        for prov in bags.values():
            for rec in prov.get("split_at_gaps") or []:
                print(
                    f"  split {rec['episode']} at pauses > {rec['gap_s']:.3g} s "
                    f"({'derived' if rec['derived'] else 'given'}): "
                    f"{', '.join(e['id'] for e in rec['episodes'])}"
                )
    for f in res.failed:
        print(f"  not converted: {f['error']}", file=sys.stderr)
    return 1 if res.failed else 0
