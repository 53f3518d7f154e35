"""``robogs physics init|show|set DATASET``: the physics model from the data, shown and edited."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare ``init``, ``show`` and ``set``."""
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    p = sub.add_parser(
        "init",
        help="write physics.json from what the dataset holds, with the source of every value",
    )
    p.add_argument("dataset", type=Path)
    p.add_argument(
        "--object",
        action="append",
        default=[],
        metavar="NAME=SPEC",
        help="box=box:LxWxH | box=mesh:FILE | box=material:NAME | pusher=sphere:R | "
        "pusher=capsule:R,L | table=plane:Z (repeatable)",
    )
    p.add_argument("--pusher", metavar="LINK", help="the pusher link (default: the closest one)")
    p.add_argument("--force", action="store_true", help="replace an existing physics.json")
    p.add_argument("--dry-run", action="store_true", help="print the table, write nothing")
    p.add_argument("--json", action="store_true", help="print the document as JSON")
    p = sub.add_parser("show", help="print physics.json as a table with the source of every value")
    p.add_argument("dataset", type=Path)
    p.add_argument("--json", action="store_true", help="print the document as JSON")
    p = sub.add_parser("set", help="set KEY=VALUE (dotted keys, JSON values) as a new revision")
    p.add_argument("dataset", type=Path)
    p.add_argument("assign", nargs="+", metavar="KEY=VALUE")
    p.add_argument("--json", action="store_true", help="print the document as JSON")


def run(args: argparse.Namespace) -> int:
    from robogs.physics.init import format_table, init_physics, set_physics_values, show_physics

    if args.action == "init":
        res = init_physics(
            args.dataset,
            objects=list(args.object),
            pusher_link=args.pusher,
            force=args.force,
            write=not args.dry_run,
        )
        if args.json:
            print(json.dumps(res.physics, indent=1))
        else:
            print(format_table(res.physics))
            for n in res.notes:
                print(f"note: {n}")
            if not args.dry_run:
                print(
                    f"wrote physics.json revision {res.physics.get('revision')} to {args.dataset}"
                )
        return 0
    if args.action == "show":
        if args.json:
            from robogs.format.dataset import Dataset

            print(json.dumps(Dataset.open(args.dataset).physics(), indent=1))
        else:
            print(show_physics(args.dataset))
        return 0
    doc = set_physics_values(args.dataset, list(args.assign))
    print(json.dumps(doc, indent=1) if args.json else format_table(doc))
    return 0
