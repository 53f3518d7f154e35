"""Each converter owns its options and flags (issue 14): the registry carries them, the convert
CLI adds every converter's group and hands the running converter its own options.

The oracle for the plug-in case is a converter registered here that writes what it received.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa
import pytest

from robogs.cli.main import main
from robogs.convert import registry
from robogs.convert.ingest import convert_path
from robogs.convert.ingest.bag_options import BagOptions
from robogs.convert.ingest.capture_options import CaptureOptions
from robogs.convert.ingest.context import ConvertOptions, IngestContext
from robogs.convert.ingest.video_options import VideoOptions


def test_builtin_converters_own_their_options() -> None:
    from robogs.convert.ingest.tabular.options import TabularOptions

    want = {
        "ros1": BagOptions,
        "ros2": BagOptions,
        "mcap": BagOptions,
        "video": VideoOptions,
        "images": VideoOptions,
        "nerfstudio": CaptureOptions,
        "colmap": CaptureOptions,
        "tabular": TabularOptions,
        "lerobot": None,
    }
    got = {}
    for name in want:
        spec = registry.options_of(registry.get_converter(name))
        got[name] = spec.type if spec is not None else None
    assert got == want


def test_each_group_parses_its_flags() -> None:
    parser = argparse.ArgumentParser()
    from robogs.cli.convert_cmd import add_arguments

    add_arguments(parser)
    args = parser.parse_args(
        ["src", "out", "--tf-object", "box=box_link", "--tf-tolerance-ms", "5", "--no-video"]
    )
    bag = registry.options_of(registry.get_converter("mcap")).options_from_args(args)
    assert bag == BagOptions(tf_objects={"box": "box_link"}, tf_tolerance_ns=5_000_000, video=False)
    args = parser.parse_args(["src", "out", "--assume-fps", "12.5", "--camera-name", "c"])
    vid = registry.options_of(registry.get_converter("video")).options_from_args(args)
    assert vid == VideoOptions(assume_fps=12.5, camera_name="c")
    args = parser.parse_args(["src", "out", "--world-up", "+y"])
    cap = registry.options_of(registry.get_converter("colmap")).options_from_args(args)
    assert cap == CaptureOptions(world_up="+y")


def test_legacy_flat_keywords_go_to_the_running_converter() -> None:
    opts = ConvertOptions(video=False, tf_objects={"b": "f"}, camera_name="c", episode="e1")
    bag = opts.resolve(BagOptions)
    assert bag.source == BagOptions(video=False, tf_objects={"b": "f"})
    assert bag.legacy == {"camera_name": "c"} and bag.episode == "e1"
    assert bag.video is False and bag.tf_auto_objects is True  # read through to the source
    vid = opts.resolve(VideoOptions)
    assert vid.source == VideoOptions(video=False, camera_name="c")
    # replace() of a resolved options object folds the keyword into its source
    assert dataclasses.replace(bag, world_frame="map").source.world_frame == "map"
    with pytest.raises(TypeError, match="unexpected keyword"):
        ConvertOptions(not_an_option=1)
    with pytest.raises(AttributeError, match="assume_fps"):
        _ = bag.assume_fps  # not a bag option


@dataclass(frozen=True)
class _EchoOptions:
    greeting: str = "hello"
    times: int = 1


def _add(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("echo")
    g.add_argument("--greeting", default="hello")
    g.add_argument("--times", type=int, default=1)


def _from_args(args: argparse.Namespace) -> _EchoOptions:
    return _EchoOptions(args.greeting, args.times)


def _convert(src: Path, ctx: IngestContext) -> None:
    opts = ctx.options.source_as(_EchoOptions)
    ctx.provenance.note(json.dumps({"greeting": opts.greeting, "times": opts.times}))
    rel = f"{ctx.episode_dir()}/streams/echo.parquet"
    ctx.writer.write_table(rel, pa.table({"t_ns": pa.array([1, 2], pa.int64())}), kind="generic")
    entry = {"kind": "generic", "path": rel, "stamp_source": "log_time", "offset_ns": 0}
    ctx.add_stream("streams/echo", entry, start_ns=1, end_ns=2)


def test_plugin_converter_adds_its_flags_and_gets_its_options(tmp_path: Path, capsys) -> None:
    src = tmp_path / "a.echo"
    src.write_text("x")
    spec = registry.ConverterOptions(_EchoOptions, _add, _from_args)
    with registry.REGISTRY.sandbox():
        registry.register_converter(
            "echo", lambda p: p.suffix == ".echo", _convert, options=spec, priority=1000
        )
        assert main(["convert", "--help"]) == 0
        assert "--greeting" in capsys.readouterr().out
        out = tmp_path / "ds"
        rc = main(["convert", str(src), str(out), "--greeting", "hi", "--times", "3", "--json"])
        assert rc == 0
        notes = json.loads(capsys.readouterr().out)["notes"]
        assert json.dumps({"greeting": "hi", "times": 3}) in notes
        # the library path: options given as the converter's dataclass, or its defaults
        ds = convert_path(src, tmp_path / "ds2", options=ConvertOptions())
        assert json.dumps({"greeting": "hello", "times": 1}) in ds.manifest["provenance"]["notes"]
