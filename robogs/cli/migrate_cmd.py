"""``robogs migrate DATASET [--to sharded|flat] [--chunk-size K]``: rewrite a dataset's layout.

``--to sharded`` (the default) moves the episodes of a flat dataset into
``episodes/chunk-NNN/`` folders of K episodes (default 1000) with one index per chunk (spec
1.1.0, FORMAT.md 9.1); ``--to flat`` lists every file in the manifest again. Every file is
checked against its sha256 first, the new version is swapped in atomically, and its hashes are
compared with the old ones (:func:`robogs.format.shards.migrate_layout`).
"""

from __future__ import annotations

import argparse
import sys
import time

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from robogs.format.shards import DEFAULT_CHUNK_SIZE

    parser.add_argument("dataset", help="dataset folder (rewritten in place, atomically)")
    parser.add_argument(
        "--to",
        choices=("sharded", "flat"),
        default="sharded",
        help="layout to write (default sharded: episodes/chunk-NNN/ with one index per chunk)",
    )
    parser.add_argument(
        "--chunk-size",
        type=int,
        default=DEFAULT_CHUNK_SIZE,
        metavar="K",
        help=f"episodes per chunk with --to sharded (default {DEFAULT_CHUNK_SIZE})",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress notes")


def run(args: argparse.Namespace) -> int:
    """Migrate; print one summary line. Errors are ``RobogsError`` (one line from ``main``)."""
    from robogs.format.dataset import Dataset
    from robogs.format.shards import DEFAULT_CHUNK_SIZE, migrate_layout

    ds = Dataset.open(args.dataset)
    shards = ds.manifest.get("shards") or {}
    same = (args.to == "flat" and not ds.sharded) or (
        args.to == "sharded"
        and ds.sharded
        and shards.get("chunk_size", DEFAULT_CHUNK_SIZE) == args.chunk_size
    )
    if same:
        print(f"{args.dataset} already has the {args.to} layout; nothing to do")
        return 0

    def note(msg: str) -> None:
        if not args.quiet:
            print(f"robogs migrate: {msg}", file=sys.stderr)

    t = time.perf_counter()
    m = migrate_layout(args.dataset, to=args.to, chunk_size=args.chunk_size, progress=note)
    how = (
        f"sharded layout ({m.chunks} chunk(s) of <= {args.chunk_size} episodes)"
        if m.layout == "sharded"
        else "flat layout"
    )
    print(
        f"migrated {args.dataset} to the {how}: {m.episodes} episodes, {m.moved} files moved, "
        f"{m.verified} hashes verified, in {time.perf_counter() - t:.1f} s"
    )
    return 0
