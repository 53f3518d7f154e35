"""Options of the message converters (ROS 1 and ROS 2 bags, MCAP) and their flags."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path

from robogs.format.errors import InputError

from ..registry import ConverterOptions
from .option_flags import add_video_flag
from .roles import load_frame_map, load_role_map, parse_frame_flags

__all__ = ["BAG_OPTIONS", "BagOptions", "add_arguments", "options_from_args"]


@dataclass(frozen=True)
class BagOptions:
    """User choices for a bag or MCAP (all optional).

    Attributes:
        role_map: topic -> role from the ``--map`` YAML (``--topic`` flags, the core
            ``roles``, win over it).
        world_frame: TF frame that is the dataset world (default: ``world``, then the URDF
            root link, ``base_link``, ``base``, ``map``).
        video: decode images and write ``rgb.mp4`` (False: frames tables only).
        stamp_tolerance_ns: header stamps further than this outside the bag's time range are
            not plausible.
        jump_back_ns: a stamp going back by more than this is a clock jump (sample dropped).
        jump_forward_ns: a stamp jumping forward by more than this is reported.
        tf_objects: object name -> TF frame written as its ``object_poses``; when given, only
            these frames become objects.
        tf_auto_objects: without ``tf_objects``, write every moving TF frame that is not a
            robot link or camera frame as an object.
        tf_cameras: camera name -> TF frame of the camera (OpenCV axes), instead of the
            images' ``header.frame_id``.
        tf_tolerance_ns: a stamp may lie this far outside a moving TF edge's samples (its
            first or last sample is used); further out there is no transform.
        tf_spill_rows: ``/tf`` samples per edge kept in RAM before spilling to a temp file.
    """

    role_map: dict[str, str] = field(default_factory=dict)
    world_frame: str | None = None
    video: bool = True
    stamp_tolerance_ns: int = 10_000_000_000
    jump_back_ns: int = 1_000_000_000
    jump_forward_ns: int = 3600 * 1_000_000_000
    tf_objects: dict[str, str] = field(default_factory=dict)
    tf_auto_objects: bool = True
    tf_cameras: dict[str, str] = field(default_factory=dict)
    tf_tolerance_ns: int = 100_000_000
    tf_spill_rows: int = 1 << 18


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the bag/MCAP flags (``--map`` and ``--topic`` are the CLI's shared ones)."""
    g = parser.add_argument_group("bags and MCAP")
    g.add_argument("--world-frame", metavar="FRAME", help="TF frame that is the dataset world")
    g.add_argument(
        "--tf-object",
        action="append",
        default=[],
        metavar="NAME=FRAME",
        help="write TF frame FRAME as object NAME's poses (repeatable; replaces the default "
        "choice of every moving frame that is not a robot link or camera)",
    )
    g.add_argument(
        "--no-tf-objects", action="store_true", help="do not write moving TF frames as objects"
    )
    g.add_argument(
        "--tf-camera",
        action="append",
        default=[],
        metavar="CAM=FRAME",
        help="TF frame (OpenCV axes) of camera CAM, instead of its images' frame_id",
    )
    g.add_argument(
        "--tf-tolerance-ms",
        type=float,
        default=100.0,
        metavar="MS",
        help="how far a stamp may lie outside a moving TF frame's samples (default 100 ms)",
    )
    add_video_flag(g)


def options_from_args(args: argparse.Namespace) -> BagOptions:
    """The :class:`BagOptions` of parsed arguments (``--map`` read as a role and frame map).

    Raises:
        InputError: a malformed map or flag, a negative ``--tf-tolerance-ms``.
    """
    role_map: dict[str, str] = {}
    tf_objects: dict[str, str] = {}
    tf_cameras: dict[str, str] = {}
    mapping = getattr(args, "map", None)
    if mapping is not None:
        role_map = {t: str(r) for t, r in load_role_map(Path(mapping)).items()}
        tf_objects, tf_cameras = load_frame_map(Path(mapping))
    tf_objects.update(parse_frame_flags(getattr(args, "tf_object", []), "--tf-object"))
    tf_cameras.update(parse_frame_flags(getattr(args, "tf_camera", []), "--tf-camera"))
    tol_ms = getattr(args, "tf_tolerance_ms", 100.0)
    if not tol_ms >= 0:
        raise InputError("--tf-tolerance-ms must be >= 0", where="--tf-tolerance-ms")
    return BagOptions(
        role_map=role_map,
        world_frame=getattr(args, "world_frame", None),
        video=not getattr(args, "no_video", False),
        tf_objects=tf_objects,
        tf_auto_objects=not getattr(args, "no_tf_objects", False),
        tf_cameras=tf_cameras,
        tf_tolerance_ns=int(round(tol_ms * 1e6)),
    )


#: the options of the ros1, ros2 and mcap converters (their registry entries' ``options``)
BAG_OPTIONS = ConverterOptions(BagOptions, add_arguments, options_from_args)
