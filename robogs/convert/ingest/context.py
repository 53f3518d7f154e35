"""What a converter gets to work with: options, the dataset writer, provenance, progress.

A converter's job is ``convert(src, ctx)``: read ``src`` and write tables, videos and
cameras through ``ctx.writer``, declare streams with :meth:`IngestContext.add_stream`, and
record everything it skipped in ``ctx.provenance``. Creating the writer, attaching the
robot, writing the provenance block, cutting at gaps and committing are done by
:func:`robogs.convert.ingest.convert.convert_path` around it.

Options come in two parts (``robogs/convert/design.md``): the shared core in
:class:`ConvertOptions`, and the options dataclass of the converter that runs (``source``:
:class:`~.bag_options.BagOptions`, :class:`~.video_options.VideoOptions`,
:class:`~.capture_options.CaptureOptions`, ``tabular.options.TabularOptions``, or a plug-in's).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from robogs.format.writer import DatasetWriter

from .progress import ProgressReporter
from .provenance import Provenance

__all__ = ["ConvertOptions", "IngestContext", "LEGACY_FIELDS"]

#: the per-converter fields of the 0.2 flat ``ConvertOptions``; still accepted as keywords
#: (routed to the options of the converter that runs, see :meth:`ConvertOptions.resolve`)
LEGACY_FIELDS = frozenset(
    {
        "world_frame",
        "camera_file",
        "camera_name",
        "stamps_csv",
        "assume_fps",
        "offset_ns",
        "joints_csv",
        "images",
        "world_up",
        "video",
        "stamp_tolerance_ns",
        "jump_back_ns",
        "jump_forward_ns",
        "mapping",
        "gap_s",
        "tf_objects",
        "tf_auto_objects",
        "tf_cameras",
        "tf_tolerance_ns",
        "tf_spill_rows",
    }
)


@dataclass(frozen=True, init=False)
class ConvertOptions:
    """The shared core of a conversion's options, plus the running converter's own.

    Attributes:
        roles: topic -> role overrides (``joint_states``, ``camera_image``, ``camera_info``,
            ``camera_labels``, ``object_pose:<name>``, ``ee_pose:<link>``, ``wrench:<frame>``,
            ``tf_static``, ``robot_description``, ``ignore``), from ``--topic``.
        urdf: robot URDF to copy into ``robot/`` (with its meshes).
        package_roots: ``package://NAME`` -> folder, for the URDF's mesh URIs.
        episode: id of the episode written (the base name when cut at gaps).
        progress: show a progress bar on stderr.
        command: the command line, for the provenance record.
        split_gaps: cut every episode where all its streams pause (``--split-at-gaps``).
        split_gap_s: the pause (s) that cuts; None derives it from the data (10x the median
            period of the densest stream).
        source: the options dataclass of the converter that runs (None: its defaults).
        legacy: 0.2 flat keywords (:data:`LEGACY_FIELDS`) not yet routed to ``source``.

    Reading a per-converter field on the options (``ctx.options.video``) reads it from
    ``source``, then ``legacy``: converters written against the flat 0.2 options keep working.
    """

    roles: dict[str, str] = field(default_factory=dict)
    urdf: Path | None = None
    package_roots: dict[str, Path] = field(default_factory=dict)
    episode: str = "ep000"
    progress: bool = False
    command: str | None = None
    split_gaps: bool = False
    split_gap_s: float | None = None
    source: Any = None
    legacy: Mapping[str, Any] = field(default_factory=dict)

    def __init__(
        self,
        *,
        roles: Mapping[str, str] | None = None,
        urdf: Path | None = None,
        package_roots: Mapping[str, Path] | None = None,
        episode: str = "ep000",
        progress: bool = False,
        command: str | None = None,
        split_gaps: bool = False,
        split_gap_s: float | None = None,
        source: Any = None,
        legacy: Mapping[str, Any] | None = None,
        **flat: Any,
    ) -> None:
        unknown = sorted(set(flat) - LEGACY_FIELDS)
        if unknown:
            raise TypeError(f"ConvertOptions got unexpected keyword(s) {', '.join(unknown)}")
        merged = {**(legacy or {}), **flat}
        if source is not None and dataclasses.is_dataclass(source):
            names = {f.name for f in dataclasses.fields(source)}
            own = {k: v for k, v in merged.items() if k in names}
            if own:
                source = dataclasses.replace(source, **own)
                merged = {k: v for k, v in merged.items() if k not in names}
        for name, value in (
            ("roles", dict(roles or {})),
            ("urdf", urdf),
            ("package_roots", dict(package_roots or {})),
            ("episode", episode),
            ("progress", progress),
            ("command", command),
            ("split_gaps", split_gaps),
            ("split_gap_s", split_gap_s),
            ("source", source),
            ("legacy", merged),
        ):
            object.__setattr__(self, name, value)

    def __getattr__(self, name: str) -> Any:
        """A per-converter field: from ``source``, then from the legacy keywords."""
        if name.startswith("__") or name in ("source", "legacy"):
            raise AttributeError(name)
        d = self.__dict__
        src = d.get("source")
        if src is not None and hasattr(src, name):
            return getattr(src, name)
        legacy = d.get("legacy") or {}
        if name in legacy:
            return legacy[name]
        raise AttributeError(
            f"ConvertOptions has no {name!r} (neither a core option nor one of "
            f"{type(src).__name__ if src is not None else 'the converter'}'s options)"
        )

    def resolve(self, options_type: type | None) -> ConvertOptions:
        """These options with ``source`` an instance of ``options_type`` (the running
        converter's class): the given one, else one built from the legacy keywords it has."""
        if options_type is None or isinstance(self.source, options_type):
            return self
        names = {f.name for f in dataclasses.fields(options_type)}
        own = {k: v for k, v in self.legacy.items() if k in names}
        rest = {k: v for k, v in self.legacy.items() if k not in names}
        return dataclasses.replace(self, source=options_type(**own), legacy=rest)

    def source_as(self, options_type: type) -> Any:
        """The running converter's options as ``options_type`` (its defaults when absent)."""
        return self.resolve(options_type).source


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
