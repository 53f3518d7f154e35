"""A ``robogs`` verb that misbehaves on purpose, to check that the harness sees each breach."""

from __future__ import annotations

import argparse

from robogs.format.errors import InputError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "how", choices=["ok", "finding", "user_error", "crash", "spin", "exit3", "silent2"]
    )


def run(args: argparse.Namespace) -> int:
    if args.how == "user_error":
        raise InputError("bad input", path="x.bag", where="byte 3", hint="fix it")
    if args.how == "crash":
        return {}["missing"]
    if args.how == "spin":
        n = 0
        while True:
            n += 1
    return {"ok": 0, "finding": 1, "exit3": 3, "silent2": 2}[args.how]
