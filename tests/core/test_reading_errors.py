"""Hostile or malformed input gives one clear RobogsError naming file, place and fix."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robogs.format import Dataset, FormatError, PathEscapeError, VersionError
from robogs.format.paths import resolve_inside
from robogs.format.spec_version import SPEC_VERSION, check_readable, migrate, register_migration
from robogs.format.splats import SplatSet, read_splat_ply, write_splat_ply


def _minimal(path: Path) -> Path:
    with Dataset.create(path) as w:
        w.commit()
    return path


def test_malformed_manifest_names_line_and_column(tmp_path: Path) -> None:
    root = _minimal(tmp_path / "ds")
    (root / "manifest.json").write_text('{"format": "robogs",\n "spec_version": }')
    with pytest.raises(FormatError) as err:
        Dataset.open(root)
    assert "manifest.json" in str(err.value) and "line 2 column" in str(err.value)


def test_nan_in_json_is_rejected(tmp_path: Path) -> None:
    root = _minimal(tmp_path / "ds")
    doc = json.loads((root / "manifest.json").read_text())
    (root / "manifest.json").write_text(
        json.dumps(doc).replace('"episodes": []', '"episodes": [], "x": NaN')
    )
    with pytest.raises(FormatError, match="non-finite"):
        Dataset.open(root)


def test_newer_major_version_refused_naming_both() -> None:
    with pytest.raises(VersionError) as err:
        check_readable("2.0.0")
    msg = str(err.value)
    assert "2.0.0" in msg and SPEC_VERSION in msg and "upgrade robogs" in msg


def test_migration_hook_upgrades_old_major() -> None:
    register_migration(0, lambda m: {**m, "spec_version": "1.0.0", "migrated": True})
    assert migrate({"spec_version": "0.9.0"})["migrated"] is True


@pytest.mark.parametrize(
    "rel", ["../../etc/passwd", "/etc/passwd", "file:///etc/passwd", "a/../../b", "C:\\x"]
)
def test_escaping_paths_refused(tmp_path: Path, rel: str) -> None:
    with pytest.raises(PathEscapeError):
        resolve_inside(tmp_path, rel)


def test_symlink_escape_refused(tmp_path: Path) -> None:
    (tmp_path / "root").mkdir()
    (tmp_path / "root" / "link").symlink_to("/etc")
    with pytest.raises(PathEscapeError, match="symlink"):
        resolve_inside(tmp_path / "root", "link/passwd")


def _splats(n: int, k: int = 4, scales: int = 3) -> SplatSet:
    rng = np.random.default_rng(0)
    return SplatSet(
        means=rng.normal(size=(n, 3)).astype("f4"),
        quats=rng.normal(size=(n, 4)).astype("f4"),
        log_scales=rng.normal(size=(n, scales)).astype("f4"),
        opacity_logits=rng.normal(size=n).astype("f4"),
        sh=rng.normal(size=(n, k, 3)).astype("f4"),
        bind_id=rng.integers(0, 5, n).astype("i4"),
        bind_face=rng.integers(0, 100, n).astype("i4"),
        bind_uv=rng.random((n, 2)).astype("f4"),
        bind_offset=rng.normal(size=n).astype("f4"),
    )


@pytest.mark.parametrize("k,scales", [(1, 3), (4, 3), (9, 2), (16, 3)])
def test_splat_ply_round_trip(tmp_path: Path, k: int, scales: int) -> None:
    s = _splats(57, k, scales)
    write_splat_ply(tmp_path / "s.ply", s)
    back = read_splat_ply(tmp_path / "s.ply")
    for name in (
        "means",
        "quats",
        "log_scales",
        "opacity_logits",
        "sh",
        "bind_id",
        "bind_face",
        "bind_uv",
        "bind_offset",
    ):
        assert np.array_equal(getattr(back, name), getattr(s, name)), name
    assert back.kind == ("2dgs" if scales == 2 else "3dgs") and back.sh_degree == int(k**0.5) - 1


def test_splat_ply_channel_major_rest_order(tmp_path: Path) -> None:
    """f_rest_i is channel-major: all red coefficients first (3DGS layout)."""
    s = _splats(1, 4)
    write_splat_ply(tmp_path / "s.ply", s)
    from plyfile import PlyData

    v = PlyData.read(str(tmp_path / "s.ply"))["vertex"]
    assert v["f_rest_0"][0] == s.sh[0, 1, 0] and v["f_rest_3"][0] == s.sh[0, 1, 1]


def test_truncated_splat_ply(tmp_path: Path) -> None:
    write_splat_ply(tmp_path / "s.ply", _splats(10))
    data = (tmp_path / "s.ply").read_bytes()
    (tmp_path / "s.ply").write_bytes(data[:-7])
    with pytest.raises(FormatError, match="truncated"):
        read_splat_ply(tmp_path / "s.ply")


def test_absurd_splat_header_rejected_before_allocation(tmp_path: Path) -> None:
    (tmp_path / "s.ply").write_bytes(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 99999999999\n"
        b"property float x\nend_header\n"
    )
    with pytest.raises(FormatError, match="over the limit"):
        read_splat_ply(tmp_path / "s.ply")


def test_not_a_dataset(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match="does not exist"):
        Dataset.open(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FormatError, match="manifest is missing"):
        Dataset.open(tmp_path / "empty")


def test_truncated_parquet_is_a_format_error(tmp_path: Path) -> None:
    import pyarrow as pa

    with Dataset.create(tmp_path / "ds") as w:
        w.write_table(
            "e/js.parquet",
            pa.table({"t_ns": pa.array([1, 2], pa.int64()), "position.a": [0.0, 1.0]}),
            kind="joint_states",
        )
        w.add_episode(
            "ep0",
            start_ns=1,
            end_ns=2,
            streams={
                "joint_states": {
                    "kind": "joint_states",
                    "path": "e/js.parquet",
                    "stamp_source": "synthetic",
                    "offset_ns": 0,
                }
            },
        )
        ds = w.commit()
    p = ds.root / "e/js.parquet"
    p.write_bytes(p.read_bytes()[:-20])
    with pytest.raises(FormatError, match="truncated or not parquet"):
        ds.episode("ep0").table("joint_states")
