"""Ingest safety: no clobbering, no half-written output, clear errors for hostile inputs."""

from __future__ import annotations

from pathlib import Path

import pytest

from robogs.convert.ingest import ConvertOptions, convert_path
from robogs.format.errors import DatasetExistsError, InputError, RobogsError


def _leftovers(parent: Path, name: str = "out") -> list[str]:
    return sorted(
        p.name
        for p in parent.iterdir()
        if p.name == name
        or p.name.startswith(f".{name}.tmp-")
        or p.name.startswith(f".{name}.old-")
    )


@pytest.fixture
def small(tmp_path: Path, synth) -> Path:
    synth.write_ros2_mcap(tmp_path / "a.mcap", duration_s=0.1)
    return tmp_path / "a.mcap"


def test_existing_output_needs_force(small: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    first = convert_path(small, out)
    sha = first.manifest["files"]
    with pytest.raises(DatasetExistsError):
        convert_path(small, out)
    assert convert_path(small, out, force=True).manifest["files"] == sha
    assert _leftovers(tmp_path) == ["out"]


def test_force_never_replaces_a_folder_that_is_not_a_dataset(small: Path, tmp_path: Path) -> None:
    precious = tmp_path / "precious"
    precious.mkdir()
    (precious / "thesis.tex").write_text("keep me")
    with pytest.raises(DatasetExistsError, match="robogs did not write"):
        convert_path(small, precious, force=True)
    assert (precious / "thesis.tex").read_text() == "keep me"
    with pytest.raises(DatasetExistsError, match="source"):
        convert_path(small, tmp_path, force=True)


def test_failure_midway_leaves_nothing(tmp_path: Path, synth) -> None:
    # frame 5 of 9 has one row of pixel data missing: the conversion fails after writing
    # joint states and four video frames
    synth.write_ros2_mcap(
        tmp_path / "bad.mcap", image_kind="raw", duration_s=0.3, hostile={"bad_image_at": 5}
    )
    with pytest.raises(InputError) as ei:
        convert_path(tmp_path / "bad.mcap", tmp_path / "out")
    msg = str(ei.value)
    t5 = synth.T0 + 12_000_000 + round(5 * 1e9 / 30) - synth.LATENCY
    assert "topic /camera/cam0/image_raw" in msg and f"stamp {t5}" in msg and "bytes" in msg
    assert _leftovers(tmp_path) == []


def test_existing_dataset_survives_a_failed_forced_conversion(
    small: Path, tmp_path: Path, synth
) -> None:
    out = tmp_path / "out"
    before = convert_path(small, out).manifest["files"]
    synth.write_ros2_mcap(
        tmp_path / "bad.mcap", image_kind="raw", duration_s=0.3, hostile={"bad_image_at": 2}
    )
    with pytest.raises(InputError):
        convert_path(tmp_path / "bad.mcap", out, force=True)
    from robogs.format.dataset import Dataset

    assert Dataset.open(out).manifest["files"] == before
    assert _leftovers(tmp_path) == ["out"]


def test_truncated_mcap(small: Path, tmp_path: Path) -> None:
    data = small.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="mcap recover|truncated"):
        convert_path(cut, tmp_path / "out")
    assert _leftovers(tmp_path) == []


def test_corrupt_chunk_names_topic_and_time(tmp_path: Path, synth) -> None:
    src = tmp_path / "a.mcap"
    synth.write_ros2_mcap(src, duration_s=0.3, chunk_size=4096)
    data = bytearray(src.read_bytes())
    i = len(data) // 2
    data[i : i + 64] = bytes(64)  # zero 64 bytes in the middle of the data section
    bad = tmp_path / "corrupt.mcap"
    bad.write_bytes(bytes(data))
    with pytest.raises(RobogsError) as ei:
        convert_path(bad, tmp_path / "out")
    assert "corrupt" in str(ei.value) and "log time" in str(ei.value)
    assert _leftovers(tmp_path) == []


def test_unknown_chunk_compression(small: Path, tmp_path: Path) -> None:
    data = small.read_bytes()
    assert b"zstd" in data
    bad = tmp_path / "weird.mcap"
    bad.write_bytes(data.replace(b"zstd", b"brot"))
    with pytest.raises(InputError, match="unknown chunk compression 'brot'"):
        convert_path(bad, tmp_path / "out")
    assert _leftovers(tmp_path) == []


def test_four_coefficient_plumb_bob_is_an_error(tmp_path: Path, synth) -> None:
    synth.write_ros2_mcap(tmp_path / "a.mcap", duration_s=0.1, distortion=(0.1, 0.01, 0.0, 0.0))
    with pytest.raises(InputError) as ei:
        convert_path(tmp_path / "a.mcap", tmp_path / "out")
    msg = str(ei.value)
    assert (
        "plumb_bob needs 5 coefficients, got 4" in msg
        and "topic /camera/cam0/camera_info stamp" in msg
    )
    assert "equidistant" in msg  # the hint names the likely intent
    assert _leftovers(tmp_path) == []


def test_truncated_ros1_bag(tmp_path: Path, synth) -> None:
    synth.write_ros1_bag(tmp_path / "a.bag", duration_s=0.2)
    data = (tmp_path / "a.bag").read_bytes()
    (tmp_path / "cut.bag").write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(InputError, match="cannot open bag .*index looks damaged"):
        convert_path(tmp_path / "cut.bag", tmp_path / "out")
    assert _leftovers(tmp_path) == []


def test_interrupt_leaves_nothing(small: Path, tmp_path: Path, monkeypatch) -> None:
    from robogs.convert.ingest import messages

    calls = {"n": 0}
    real = messages.MessageIngest.handle

    def interrupted(self, topic, log_time, msg):
        calls["n"] += 1
        if calls["n"] == 30:
            raise KeyboardInterrupt
        return real(self, topic, log_time, msg)

    monkeypatch.setattr(messages.MessageIngest, "handle", interrupted)
    with pytest.raises(KeyboardInterrupt):
        convert_path(small, tmp_path / "out", options=ConvertOptions())
    assert _leftovers(tmp_path) == []
