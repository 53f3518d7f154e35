"""``robogs roles DATASET`` lists every stream with its role and the reason recorded at
conversion; ``robogs roles set DATASET TOPIC_OR_STREAM ROLE`` re-roles a decoded ``generic``
stream (``ee_pose:<link>``, ``object_pose:<name>``, ``wrench:<frame>`` or ``ignore``) and
writes a new version of the dataset (:func:`robogs.format.roles.set_role`). Poses are moved
into the world through the static frame they are recorded in (``header.frame_id``, or
``--frame``): the base link, a link fixed to it, or a named frame of ``robot.frames``; an
``ee_pose`` entity may be a named frame fixed to a link.

Exit codes: 0 listed or changed, 2 usage error, unknown stream, or a role the stream's
columns do not fit (nothing is written then).
"""

from __future__ import annotations

import argparse
import json

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``robogs roles [set] DATASET [TOPIC_OR_STREAM ROLE]``."""
    parser.add_argument(
        "words",
        nargs="+",
        metavar="ARG",
        help="DATASET (list the roles), or: set DATASET TOPIC_OR_STREAM ROLE",
    )
    parser.add_argument("--episode", help="only this episode (set: default every episode)")
    parser.add_argument(
        "--frame",
        help="set, pose roles: the frame the values are in (default: the table's "
        "header.frame_id): the world, the base link, a link or a named frame fixed to it",
    )
    parser.add_argument("--json", action="store_true", help="machine-readable output")


def run(args: argparse.Namespace) -> int:
    from robogs.format.errors import RobogsError

    words = list(args.words)
    if words[0] != "set" and args.frame is not None:
        raise RobogsError(
            "--frame applies to 'roles set' only", hint="robogs roles set ... --frame F"
        )
    if words[0] == "set":
        if len(words) != 4:
            raise RobogsError(
                "usage: robogs roles set DATASET TOPIC_OR_STREAM ROLE",
                hint="ROLE is ee_pose:<link>, object_pose:<name>, wrench:<frame> or ignore",
            )
        return _set(words[1], words[2], words[3], args)
    if len(words) != 1:
        raise RobogsError(
            f"unexpected arguments {' '.join(words[1:])!r}",
            hint="robogs roles DATASET, or robogs roles set DATASET TOPIC_OR_STREAM ROLE",
        )
    return _list(words[0], args)


def _list(root: str, args: argparse.Namespace) -> int:
    from robogs.format.dataset import Dataset
    from robogs.format.roles import list_roles

    rows = [r for r in list_roles(Dataset.open(root)) if args.episode in (None, r.episode)]
    if args.json:
        print(json.dumps([r.__dict__ for r in rows], indent=2))
        return 0
    for r in rows:
        src = f" <- {r.source}" if r.source else ""
        why = f"  ({r.reason})" if r.reason else ""
        print(f"{r.episode}  {r.stream:<28} {r.role:<24}{src}{why}")
    return 0


def _set(root: str, target: str, role: str, args: argparse.Namespace) -> int:
    from robogs.format.roles import set_role

    changes = set_role(root, target, role, episode=args.episode, frame=args.frame)
    if args.json:
        print(json.dumps([{**c.__dict__, "lines": list(c.lines)} for c in changes], indent=2))
        return 0
    for c in changes:
        for line in c.lines:
            print(line)
    print(f"{root}: new version written ({len(changes)} episode(s) changed)")
    return 0
