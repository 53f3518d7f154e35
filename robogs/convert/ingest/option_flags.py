"""Helpers shared by the converters' ``add_arguments`` functions.

Several converters take the same flag (``--no-video`` is read by bags, videos and captures);
each declares it with :func:`add_flag`, which adds it once, so the convert CLI can add every
converter's group to one parser.
"""

from __future__ import annotations

import argparse
from typing import Any

__all__ = ["add_flag", "add_video_flag"]


def add_flag(group: Any, *flags: str, **kwargs: Any) -> None:
    """``group.add_argument(*flags, **kwargs)`` unless the parser already has one of ``flags``
    (argparse groups share their parser's option table)."""
    table: dict[str, argparse.Action] = group._option_string_actions
    if any(f in table for f in flags):
        return
    group.add_argument(*flags, **kwargs)


def add_video_flag(group: Any) -> None:
    """``--no-video``: write the frames tables only, no ``rgb.mp4`` (``args.no_video``)."""
    add_flag(group, "--no-video", action="store_true", help="write frames tables only (no rgb.mp4)")
