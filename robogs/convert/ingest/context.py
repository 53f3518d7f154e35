"""What a converter gets to work with: options, the dataset writer, provenance, progress.

A converter's job is ``convert(src, ctx)``: read ``src`` and write tables, videos and
cameras through ``ctx.writer``, declare streams with :meth:`IngestContext.add_stream`, and
record everything it skipped in ``ctx.provenance``. Creating the writer, attaching the
robot, writing the provenance block and committing are done by
:func:`robogs.convert.ingest.convert.convert_path` around it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from robogs.format.writer import DatasetWriter

from .progress import ProgressReporter
from .provenance import Provenance

__all__ = ["ConvertOptions", "IngestContext"]


@dataclass(frozen=True)
class ConvertOptions:
    """User choices for a conversion (all optional).

    Attributes:
        roles: topic -> role overrides (``joint_states``, ``camera_image``, ``camera_info``,
            ``camera_labels``, ``object_pose:<name>``, ``ee_pose:<link>``, ``wrench:<frame>``,
            ``tf_static``, ``robot_description``, ``ignore``).
        urdf: robot URDF to copy into ``robot/`` (with its meshes).
        package_roots: ``package://NAME`` -> folder, for the URDF's mesh URIs.
        episode: id of the episode written.
        world_frame: TF frame that is the dataset world (default: ``world``, then the
            URDF root link, ``base_link``, ``base``, ``map``).
        camera_file: calibration YAML/INI for a video or image-folder source.
        camera_name: camera name for a video or image-folder source.
        stamps_csv: sidecar ``frame_index,t_ns`` CSV for a video or image folder.
        assume_fps: derive frame stamps as ``offset + i / fps`` (only when asked; recorded
            as ``stamp_source: derived``).
        offset_ns: offset added to video/container stamps to put them on the dataset clock.
        joints_csv: joint log (``t_ns``, ``position.<joint>`` ...) next to a video.
        images: image folder of a static capture (COLMAP/nerfstudio) when not the default.
        world_up: world up axis of a static capture (``+y`` rotates a y-up world to z-up);
            ``None`` keeps the source world as it is.
        video: decode images and write ``rgb.mp4`` (False: frames tables only).
        progress: show a progress bar on stderr.
        stamp_tolerance_ns: header stamps further than this outside the bag's time range are
            not plausible.
        jump_back_ns: a stamp going back by more than this is a clock jump (sample dropped).
        jump_forward_ns: a stamp jumping forward by more than this is reported.
        command: the command line, for the provenance record.
        mapping: column mapping YAML of a tabular joint log (``--map`` for that format).
        gap_s: a jump in time longer than this splits a tabular log into segments.
        tf_objects: object name -> TF frame written as its ``object_poses`` (``--tf-object``);
            when given, only these frames become objects.
        tf_auto_objects: without ``tf_objects``, write every moving TF frame that is not a
            robot link or camera frame as an object (``--no-tf-objects`` turns it off).
        tf_cameras: camera name -> TF frame of the camera (OpenCV axes), instead of the
            images' ``header.frame_id`` (``--tf-camera``).
        tf_tolerance_ns: a stamp may lie this far outside a moving TF edge's samples (its first
            or last sample is used); further out there is no transform.
        tf_spill_rows: ``/tf`` samples per edge kept in RAM before spilling to a temp file.
    """

    roles: dict[str, str] = field(default_factory=dict)
    urdf: Path | None = None
    package_roots: dict[str, Path] = field(default_factory=dict)
    episode: str = "ep000"
    world_frame: str | None = None
    camera_file: Path | None = None
    camera_name: str | None = None
    stamps_csv: Path | None = None
    assume_fps: float | None = None
    offset_ns: int = 0
    joints_csv: Path | None = None
    images: Path | None = None
    world_up: str | None = None
    video: bool = True
    progress: bool = False
    stamp_tolerance_ns: int = 10_000_000_000
    jump_back_ns: int = 1_000_000_000
    jump_forward_ns: int = 3600 * 1_000_000_000
    command: str | None = None
    mapping: Path | None = None
    gap_s: float | None = None
    tf_objects: dict[str, str] = field(default_factory=dict)
    tf_auto_objects: bool = True
    tf_cameras: dict[str, str] = field(default_factory=dict)
    tf_tolerance_ns: int = 100_000_000
    tf_spill_rows: int = 1 << 18


@dataclass
class IngestContext:
    """The state shared by a converter and the driver around it."""

    writer: DatasetWriter
    options: ConvertOptions
    provenance: Provenance
    progress: ProgressReporter
    streams: dict[str, dict[str, Any]] = field(default_factory=dict)
    start_ns: int | None = None
    end_ns: int | None = None
    clock: str | None = None
    robot_description: str | None = None
    robot_root_link: str | None = None

    def add_stream(
        self,
        name: str,
        entry: dict[str, Any],
        *,
        start_ns: int | None = None,
        end_ns: int | None = None,
    ) -> None:
        """Declare one stream of the episode and widen the episode's time span."""
        self.streams[name] = entry
        for t in (start_ns, end_ns):
            if t is None:
                continue
            self.start_ns = t if self.start_ns is None else min(self.start_ns, t)
            self.end_ns = t if self.end_ns is None else max(self.end_ns, t)

    def episode_dir(self) -> str:
        """``episodes/<id>``, the folder of the episode being written."""
        return f"episodes/{self.options.episode}"
