"""Options of the static-capture converters (nerfstudio, COLMAP) and their flags."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from .option_flags import add_video_flag

__all__ = ["CaptureOptions", "UP_AXES", "add_arguments", "options_from_args"]

UP_AXES = ("+x", "-x", "+y", "-y", "+z", "-z")


@dataclass(frozen=True)
class CaptureOptions:
    """User choices for a static capture (all optional).

    Attributes:
        images: image folder when not the default one next to the model.
        world_up: the source world's up axis (``+y`` rotates a y-up world to z-up); None
            keeps the source world as it is.
        video: decode images and write ``rgb.mp4`` (False: frames tables only).
    """

    images: Path | None = None
    world_up: str | None = None
    video: bool = True


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the nerfstudio/COLMAP flags."""
    g = parser.add_argument_group("static captures (nerfstudio, COLMAP)")
    g.add_argument(
        "--images", type=Path, metavar="DIR", help="image folder (default: next to the model)"
    )
    g.add_argument("--world-up", choices=UP_AXES, help="source world's up axis, rotated to +z")
    add_video_flag(g)


def options_from_args(args: argparse.Namespace) -> CaptureOptions:
    """The :class:`CaptureOptions` of parsed arguments."""
    return CaptureOptions(
        images=getattr(args, "images", None),
        world_up=getattr(args, "world_up", None),
        video=not getattr(args, "no_video", False),
    )
