"""``convert_path``: detect the source format, run its converter, commit the dataset atomically.

The dataset is built in the writer's temp folder; if anything fails (a corrupt file, a bad
calibration, Ctrl-C) the temp folder is discarded and ``out`` is left as it was. An existing
``out`` is replaced only with ``force=True``, and never when it is not a robogs dataset or
when the source lies inside it.
"""

from __future__ import annotations

from pathlib import Path

from robogs.format.dataset import Dataset
from robogs.format.errors import InputError

from ..registry import Converter, detect_format, get_converter, options_of
from .context import ConvertOptions, IngestContext
from .gaps import split_episodes
from .progress import ProgressReporter
from .provenance import Provenance
from .robot import attach_robot, attach_robot_description, urdf_root_link

__all__ = ["convert_path"]


def convert_path(
    src: str | Path,
    out: str | Path,
    *,
    fmt: str | None = None,
    options: ConvertOptions | None = None,
    force: bool = False,
) -> Dataset:
    """Convert ``src`` into a new dataset at ``out``.

    Args:
        src: bag, MCAP, video, image folder, nerfstudio or COLMAP capture.
        out: dataset folder to create.
        fmt: source format name (default: detected from ``src``).
        options: conversion options: the shared core, the converter's own in ``source``
            (0.2 flat keywords are routed there); ``split_gaps`` cuts every episode where all
            its streams pause (:mod:`.gaps`), the cut table going to
            ``provenance.split_at_gaps``.
        force: replace an existing dataset at ``out``.

    Returns:
        The committed dataset, opened for reading.

    Raises:
        RobogsError: unusable input (naming file, topic and stamp where known), an existing
            output without ``force``; nothing is written in that case.
    """
    src, out = Path(src), Path(out)
    conv: Converter = get_converter(fmt) if fmt else detect_format(src)
    spec = options_of(conv)
    opts = (options or ConvertOptions()).resolve(spec.type if spec is not None else None)
    if not src.exists():
        raise InputError("source does not exist", path=src)
    prov = Provenance(conv.name, src.name)
    # --force replaces only a robogs dataset, never the source or a folder holding it
    writer = Dataset.create(
        out, overwrite=force, protect=[src, *([opts.urdf] if opts.urdf else [])]
    )
    ctx = IngestContext(writer, opts, prov, ProgressReporter(opts.progress))
    with writer:
        if opts.urdf is not None:
            ctx.robot_root_link = urdf_root_link(opts.urdf)
        conv.convert(src, ctx)
        if opts.urdf is not None:
            if "urdf" not in (writer.manifest.get("robot") or {}):  # (tabular may attach it)
                attach_robot(ctx, opts.urdf, package_roots=opts.package_roots)
        elif ctx.robot_description:
            attach_robot_description(
                ctx, ctx.robot_description, package_roots=opts.package_roots or None, source=src
            )
        else:
            prov.note("no robot: pass --urdf to add one (the source has no robot_description)")
        if ctx.streams:
            assert ctx.start_ns is not None and ctx.end_ns is not None
            writer.add_episode(
                opts.episode,
                start_ns=ctx.start_ns,
                end_ns=ctx.end_ns,
                streams=ctx.streams,
                segment=src.name,
            )
        elif not writer.manifest.get("cameras") and not writer.manifest.get("episodes"):
            raise InputError(
                "nothing was converted (every message was dropped)",
                path=src,
                where="; ".join(f"{i['topic']}: {i['problem']}" for i in prov.issues[:3]) or None,
                hint="see the roles with --topic/--map",
            )
        if ctx.clock:
            writer.manifest["conventions"]["clock"] = ctx.clock
        writer.manifest["provenance"] = prov.to_dict()
        if opts.split_gaps:
            writer.manifest["provenance"]["split_at_gaps"] = split_episodes(
                writer, opts.split_gap_s
            )
        if opts.command:
            writer.manifest["generator"] = {"command": opts.command[:2000]}
        return writer.commit()
