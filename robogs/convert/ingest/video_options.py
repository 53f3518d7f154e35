"""Options of the video and image-folder converters and their flags."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from robogs.format.errors import InputError

from .option_flags import add_video_flag

__all__ = ["VideoOptions", "add_arguments", "options_from_args"]


@dataclass(frozen=True)
class VideoOptions:
    """User choices for a video file or an image folder (all optional).

    Attributes:
        camera_file: calibration YAML/INI of the camera.
        camera_name: camera name (default: from the calibration or the file).
        stamps_csv: sidecar ``frame_index,t_ns`` CSV.
        assume_fps: derive frame stamps as ``offset + i / fps`` (only when asked; recorded
            as ``stamp_source: derived``).
        offset_ns: offset (ns) added to container/sidecar stamps to put them on the dataset
            clock.
        joints_csv: joint log (``t_ns``, ``position.<joint>`` ...) next to the video.
        video: decode images and write ``rgb.mp4`` (False: frames tables only).
    """

    camera_file: Path | None = None
    camera_name: str | None = None
    stamps_csv: Path | None = None
    assume_fps: float | None = None
    offset_ns: int = 0
    joints_csv: Path | None = None
    video: bool = True


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the video and image-folder flags."""
    g = parser.add_argument_group("videos and image folders")
    g.add_argument(
        "--camera", type=Path, metavar="FILE", help="calibration (ROS/OpenCV YAML, ROS INI)"
    )
    g.add_argument(
        "--camera-name", metavar="NAME", help="camera name (default: from the calibration or file)"
    )
    g.add_argument(
        "--stamps", type=Path, metavar="CSV", help="frame stamps: CSV with frame_index,t_ns"
    )
    g.add_argument(
        "--assume-fps",
        type=float,
        metavar="FPS",
        help="derive frame stamps as i/FPS (recorded as stamp_source 'derived')",
    )
    g.add_argument(
        "--offset-ns", type=int, default=0, help="added to container/sidecar stamps (ns)"
    )
    g.add_argument(
        "--joints", type=Path, metavar="CSV", help="joint log: t_ns, position.<joint> ..."
    )
    add_video_flag(g)


def options_from_args(args: argparse.Namespace) -> VideoOptions:
    """The :class:`VideoOptions` of parsed arguments.

    Raises:
        InputError: ``--assume-fps`` not positive.
    """
    fps = getattr(args, "assume_fps", None)
    if fps is not None and not fps > 0:
        raise InputError("--assume-fps must be positive", where="--assume-fps")
    return VideoOptions(
        camera_file=getattr(args, "camera", None),
        camera_name=getattr(args, "camera_name", None),
        stamps_csv=getattr(args, "stamps", None),
        assume_fps=fps,
        offset_ns=int(getattr(args, "offset_ns", 0) or 0),
        joints_csv=getattr(args, "joints", None),
        video=not getattr(args, "no_video", False),
    )
