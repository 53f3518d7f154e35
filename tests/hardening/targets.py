"""Fuzz targets: one per reader, each a seed, a mutation strategy and a ``robogs`` command.

A target's ``strategy(seeds)`` draws a :class:`Case` (which seed file, the hostile bytes) and
``prepare(seeds, case, work)`` lays the case out in an empty folder and returns the argument
list of the ``robogs`` command that reads it. Dataset files are hard-linked from the seed
dataset and the mutated file replaces its link, so the seed itself never changes. The
``validate`` commands select the checks that read the mutated file, to keep a case fast.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hypothesis import strategies as st

from .harness import Verdict
from .mutate import (
    _apply_bytes,
    _byte_op,
    bytes_mutation,
    csv_mutation,
    json_mutation,
    ply_mutation,
    text_mutation,
    xml_mutation,
    yaml_mutation,
)
from .seeds import JOINTS, T0, Seeds

__all__ = ["Case", "Target", "TARGETS", "target", "run_case", "link_copy", "put"]


@dataclass(frozen=True)
class Case:
    """One hostile input: ``variant`` picks the seed file, ``data`` is its new content."""

    variant: str
    data: Any


@dataclass(frozen=True)
class Target:
    """A reader under fuzzing.

    Attributes:
        name: short id (test names, campaign report).
        family: reader family in the report table.
        inputs: what is tried, in words.
        strategy: ``seeds -> SearchStrategy[Case]``.
        prepare: ``(seeds, case, work folder) -> argv`` of ``robogs``.
    """

    name: str
    family: str
    inputs: str
    strategy: Callable[[Seeds], st.SearchStrategy[Case]]
    prepare: Callable[[Seeds, Case, Path], list[str]]


# ----------------------------------------------------------------------------- helpers


def link_copy(src: Path, dst: Path) -> Path:
    """Copy a folder tree by hard links (cheap; replace a file with :func:`put`, never edit it)."""
    shutil.copytree(src, dst, copy_function=os.link)
    return dst


def put(path: Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` after removing what is there (breaks a hard link)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.exists() or path.is_symlink():
        path.unlink()
    path.write_bytes(data)
    return path


def _variants(files: dict[str, Path], mutate: Callable[[bytes, str], st.SearchStrategy[Any]]):
    return st.sampled_from(sorted(files)).flatmap(
        lambda k: mutate(files[k].read_bytes(), k).map(lambda d: Case(k, d))
    )


def _manifest(ds: Path) -> dict[str, Any]:
    return json.loads((ds / "manifest.json").read_text())


def _dataset(seeds: Seeds, work: Path, rel: str, data: bytes) -> Path:
    ds = link_copy(seeds.dataset, work / "ds")
    put(ds / rel, data)
    return ds


def _validate(ds: Path, select: str | None = None, *extra: str) -> list[str]:
    argv = ["validate", str(ds), "--json", "--no-progress", *extra]
    return argv + (["--select", select] if select else [])


# ----------------------------------------------------------------------------- dataset files

#: sidecar -> the checks that read it (B009 and P004 render or voxelise: too slow per case)
_SIDECARS = {
    "cameras/cam0.json": "S002,T012",
    "physics.json": "S002,P001,P002,P003",
    "robot/mdh.json": "S002,G008",
}
_TABLES = (
    "episodes/ep000/joint_states.parquet",
    "episodes/ep000/object_poses.parquet",
    "episodes/ep000/ee_poses.parquet",
    "episodes/ep000/boxes2d.parquet",
    "episodes/ep000/segments.parquet",
    "episodes/ep000/cameras/cam0/frames.parquet",
    "episodes/ep000/cameras/cam0/labels.parquet",
)
_TABLE_CHECKS = (
    "S003,S007,I005,I006,T001,T002,T003,T004,T005,T006,T007,T008,T009,T010,T011,G007,G009,B010"
)


def _manifest_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    return json_mutation(_manifest(seeds.dataset)).map(lambda d: Case("manifest.json", d))


def _manifest_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    return _validate(_dataset(seeds, work, "manifest.json", case.data), None, "--quick")


def _manifest_full_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    ds = _dataset(seeds, work, "manifest.json", case.data)
    return _validate(ds, "S,I,T001,T007,T008,T009,G001,G002,G003,G005,G006,G007,P,B009,B010")


def _sidecar_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    files = {rel: seeds.dataset / rel for rel in _SIDECARS}
    return _variants(files, lambda b, k: json_mutation(json.loads(b)))


def _sidecar_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    ds = _dataset(seeds, work, case.variant, case.data)
    return _validate(ds, _SIDECARS[case.variant])


def _table_op() -> st.SearchStrategy[tuple]:
    idx = st.integers(0, 2**16)
    return st.one_of(
        st.tuples(st.just("drop"), idx, st.none()),
        st.tuples(st.just("cast"), idx, st.sampled_from(["string", "int32", "float32", "int64", "float64", "binary", "bool"])),
        st.tuples(st.just("nulls"), idx, st.none()),
        st.tuples(st.just("value"), idx, st.sampled_from([float("nan"), float("inf"), -1e308, 2**63 - 1, -(2**63), 0, -1])),
        st.tuples(st.just("rows"), idx, st.sampled_from([0, 1, 2, -1])),
        st.tuples(st.just("reverse"), idx, st.none()),
        st.tuples(st.just("rename"), idx, st.sampled_from(["t_ns", "position.", "x", "", "frame_index", "png"])),
        st.tuples(st.just("bytes"), idx, _byte_op()),
    )  # fmt: skip


def _apply_table(data: bytes, ops: list[tuple]) -> bytes:
    """Apply table operations with pyarrow, then any byte operations on the written file."""
    import io

    import numpy as np
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    table = pq.read_table(io.BytesIO(data))
    byte_ops = []
    for kind, i, value in ops:
        if kind == "bytes":
            byte_ops.append(value)
            continue
        if table.num_columns == 0:
            break
        k = i % table.num_columns
        col = table.column(k)
        name = table.schema.names[k]
        try:
            if kind == "drop":
                table = table.remove_column(k)
            elif kind == "cast":
                table = table.set_column(k, name, pc.cast(col, value, safe=False))
            elif kind == "nulls":
                table = table.set_column(k, name, pa.nulls(table.num_rows, col.type))
            elif kind == "value":
                arr = np.full(
                    table.num_rows,
                    value,
                    dtype=np.float64 if isinstance(value, float) else np.int64,
                )
                table = table.set_column(k, name, pc.cast(pa.array(arr), col.type, safe=False))
            elif kind == "rows":
                n = table.num_rows if value < 0 else value
                table = table.slice(0, n) if value >= 0 else table.take(list(range(n)) * 2)
            elif kind == "reverse":
                table = table.take(list(range(table.num_rows - 1, -1, -1)))
            elif kind == "rename":
                names = list(table.schema.names)
                names[k] = value
                table = table.rename_columns(names)
        except (pa.ArrowException, ValueError, TypeError, OverflowError):
            continue  # this operation does not apply to this column type
    sink = io.BytesIO()
    pq.write_table(table, sink)
    return _apply_bytes(sink.getvalue(), byte_ops)


def _table_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    rels = st.sampled_from(_TABLES)
    ops = st.lists(_table_op(), min_size=1, max_size=3)
    return st.tuples(rels, ops).map(lambda t: Case(t[0], t[1]))


def _table_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    data = _apply_table((seeds.dataset / case.variant).read_bytes(), case.data)
    return _validate(_dataset(seeds, work, case.variant, data), _TABLE_CHECKS)


def _splat_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    seed = (seeds.dataset / "assets/box/splats.ply").read_bytes()
    return ply_mutation(seed).map(lambda d: Case("assets/box/splats.ply", d))


def _splat_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    ds = _dataset(seeds, work, case.variant, case.data)
    m = _manifest(ds)  # only the box keeps splats: the case stays small and fast
    m["robot"].pop("splats", None)
    m["assets"]["table"].pop("splats", None)
    put(ds / "manifest.json", json.dumps(m).encode())
    return _validate(ds, "B001,B007,B008,B011")


def _urdf_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    seed = (seeds.dataset / "robot/robot.urdf").read_bytes()
    return xml_mutation(seed).map(lambda d: Case("robot/robot.urdf", d))


def _urdf_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    ds = _dataset(seeds, work, case.variant, case.data)
    return _validate(ds, "G001,G002,G003,G004,G005,G007,S007")


_MESH_FILES = {
    "assets/box/mesh.ply": None,  # the dataset's own binary PLY
    "robot/meshes/base_link.stl": None,  # a URDF mesh
}


def _mesh_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    files = {rel: seeds.dataset / rel for rel in _MESH_FILES}
    files.update({f"assets/box/{p.name}": p for p in seeds.meshes})

    def mutate(data: bytes, key: str) -> st.SearchStrategy[bytes]:
        if key.endswith((".obj", ".dae")) or key.endswith("box.ply"):
            text = data.decode("utf-8")
            return st.one_of(
                text_mutation(text),
                xml_mutation(data)
                if key.endswith(".dae")
                else csv_mutation(text.replace(" ", ",")).map(lambda b: b.replace(b",", b" ")),
            )
        if key.endswith("mesh.ply"):
            return st.one_of(ply_mutation(data), bytes_mutation(data))
        return bytes_mutation(data)

    return _variants(files, mutate)


def _mesh_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    ds = _dataset(seeds, work, case.variant, case.data)
    if case.variant.startswith("assets/box/") and case.variant != "assets/box/mesh.ply":
        m = _manifest(ds)
        m["assets"]["box"]["mesh"] = case.variant
        put(ds / "manifest.json", json.dumps(m).encode())
    return _validate(ds, "G001,G004,G005,G006,G010,G011")


# ----------------------------------------------------------------------------- converters


def _convert(src: Path, work: Path, *extra: str) -> list[str]:
    return ["convert", str(src), str(work / "out"), "--json", "--no-progress", *extra]


def _file_strategy(files: dict[str, Path], mutate=None) -> st.SearchStrategy[Case]:
    return _variants(files, mutate or (lambda b, k: bytes_mutation(b)))


def _mcap_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    return _file_strategy({p.name: p for p in seeds.mcaps})


def _mcap_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    return _convert(put(work / case.variant, case.data), work)


_IMAGE_FIELDS = {
    "height": st.sampled_from([0, 1, 12, 2**31 - 1, 2**32 - 1]),
    "width": st.sampled_from([0, 1, 16, 2**31 - 1, 2**32 - 1]),
    "step": st.sampled_from([0, 3, 48, 2**32 - 1]),
    "encoding": st.sampled_from(["rgb8", "bgr8", "mono8", "mono16", "16UC1", "32FC1", "bayer_rggb8", "yuv422", "", "x" * 300]),
    "data_len": st.sampled_from([0, 1, 576, 575, 577, 100_000]),
}  # fmt: skip


def _message_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    """Structure-aware MCAP: valid container, hostile message contents."""
    floats = st.one_of(st.floats(), st.sampled_from([1e308, -1e308, 0.0]))
    joint = st.fixed_dictionaries(
        {
            "names": st.lists(st.sampled_from([*JOINTS, "", "j1", "x" * 200]), max_size=4),
            "position": st.lists(floats, max_size=4),
            "velocity": st.lists(floats, max_size=4),
            "sec": st.sampled_from([0, 1, 2**31 - 1, -(2**31), T0 // 10**9]),
            "nanosec": st.sampled_from([0, 999_999_999, 2**32 - 1]),
        }
    )
    image = st.one_of(st.none(), st.fixed_dictionaries(_IMAGE_FIELDS))
    info = st.fixed_dictionaries(
        {
            "model": st.sampled_from(["plumb_bob", "rational_polynomial", "equidistant", "", "x"]),
            "d": st.lists(floats, max_size=9),
            "k": st.lists(floats, min_size=9, max_size=9),
            "w": st.sampled_from([0, 16, 2**32 - 1]),
        }
    )
    compressed = st.tuples(st.sampled_from(["png", "jpeg", "", "x"]), st.binary(max_size=64))
    return st.fixed_dictionaries(
        {
            "joints": st.lists(joint, max_size=4),
            "image": image,
            "info": info,
            "compressed": compressed,
        }
    ).map(lambda d: Case("messages.mcap", d))


def _message_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    from mcap_ros2.writer import Writer

    from .seeds import _msgdef

    d = case.data
    path = work / "m.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh)
        types = [
            "sensor_msgs/msg/JointState",
            "sensor_msgs/msg/Image",
            "sensor_msgs/msg/CameraInfo",
            "sensor_msgs/msg/CompressedImage",
        ]
        sch = {t: w.register_msgdef(t, _msgdef(t)) for t in types}
        t = T0
        for k, j in enumerate(d["joints"]):
            msg = {
                "header": {"stamp": {"sec": j["sec"], "nanosec": j["nanosec"]}, "frame_id": ""},
                "name": j["names"],
                "position": j["position"],
                "velocity": j["velocity"],
                "effort": [],
            }
            w.write_message("/joint_states", sch[types[0]], msg, log_time=t + k, publish_time=t + k)
        img = d["image"] or {
            "height": 12,
            "width": 16,
            "encoding": "rgb8",
            "step": 48,
            "data_len": 576,
        }
        hdr = {"stamp": {"sec": T0 // 10**9, "nanosec": 5}, "frame_id": "cam"}
        msg = {
            "header": hdr,
            "height": img["height"],
            "width": img["width"],
            "encoding": img["encoding"],
            "is_bigendian": 0,
            "step": img["step"],
            "data": bytes(img["data_len"]),
        }
        w.write_message("/cam/image_raw", sch[types[1]], msg, log_time=t + 10, publish_time=t + 10)
        inf = d["info"]
        info = {
            "header": hdr,
            "height": 12,
            "width": inf["w"],
            "distortion_model": inf["model"],
            "d": inf["d"],
            "k": inf["k"],
            "r": [1.0, 0, 0, 0, 1, 0, 0, 0, 1],
            "p": [0.0] * 12,
            "binning_x": 0,
            "binning_y": 0,
            "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
        }
        w.write_message(
            "/cam/camera_info", sch[types[2]], info, log_time=t + 11, publish_time=t + 11
        )
        fmt, blob = d["compressed"]
        comp = {"header": hdr, "format": fmt, "data": blob}
        w.write_message(
            "/cam2/image_raw/compressed", sch[types[3]], comp, log_time=t + 12, publish_time=t + 12
        )
        w.finish()
    return _convert(path, work)


def _ros1_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    return _file_strategy({p.name: p for p in seeds.bags})


def _ros1_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    return _convert(put(work / case.variant, case.data), work)


def _ros2_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    import yaml

    meta = seeds.ros2_bag / "metadata.yaml"
    db = seeds.ros2_bag / "r2.db3"
    return st.one_of(
        yaml_mutation(yaml.safe_load(meta.read_text())).map(lambda d: Case("metadata.yaml", d)),
        bytes_mutation(db.read_bytes()).map(lambda d: Case("r2.db3", d)),
    )


def _ros2_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    bag = link_copy(seeds.ros2_bag, work / "r2")
    put(bag / case.variant, case.data)
    return _convert(bag, work)


def _video_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    return _file_strategy({p.name: p for p in seeds.videos})


def _video_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    src = put(work / case.variant, case.data)
    return _convert(src, work, "--camera", str(seeds.calibrations[0]))


def _calib_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    import yaml

    def mutate(data: bytes, key: str) -> st.SearchStrategy[bytes]:
        text = data.decode()
        if key.endswith(".ini"):
            return st.one_of(
                csv_mutation(text.replace(" ", ",")).map(lambda b: b.replace(b",", b" ")),
                text_mutation(text),
            )
        if "opencv" in key:
            body = text.split("---\n", 1)[1].replace("!!opencv-matrix", "")
            doc = yaml.safe_load(body)

            def dump(d: Any) -> str:
                text = yaml.safe_dump(d)
                return "%YAML:1.0\n---\n" + text.replace(
                    "camera_matrix:\n", "camera_matrix: !!opencv-matrix\n"
                )

            return st.one_of(yaml_mutation(doc, dump=dump), text_mutation(text))
        return yaml_mutation(yaml.safe_load(text))

    return _variants({p.name: p for p in seeds.calibrations}, mutate)


def _calib_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    cal = put(work / case.variant, case.data)
    return _convert(seeds.videos[1], work, "--camera", str(cal))


def _stamps_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    return csv_mutation(seeds.stamps.read_text()).map(lambda d: Case("stamps.csv", d))


def _stamps_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    stamps = put(work / "stamps.csv", case.data)
    return _convert(
        seeds.videos[1], work, "--stamps", str(stamps), "--camera", str(seeds.calibrations[2])
    )


def _tab_csv_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    return csv_mutation(seeds.logs[0].read_text()).map(lambda d: Case("log.csv", d))


def _tab_csv_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    return _convert(put(work / "log.csv", case.data), work, "--urdf", str(seeds.urdf))


def _tab_pq_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    return st.lists(_table_op(), min_size=1, max_size=3).map(lambda ops: Case("log.parquet", ops))


def _tab_pq_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    data = _apply_table(seeds.logs[1].read_bytes(), case.data)
    return _convert(put(work / "log.parquet", data), work, "--urdf", str(seeds.urdf))


_MAPPING = {
    "time": {"column": "t_ns", "unit": "ns"},
    "gap_s": 0.5,
    "joints": {
        "j1": {"position": {"column": "position.j1", "unit": "rad"}, "velocity": "velocity.j1"},
        "j2": {"position": "position.j2", "effort": {"column": "velocity.j2", "unit": "A", "torque_constant": 0.1, "gear_ratio": 100}},
    },
    "effort_kind": "current",
    "hold": {},
}  # fmt: skip


def _mapping_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    return yaml_mutation(_MAPPING).map(lambda d: Case("map.yaml", d))


def _mapping_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    m = put(work / "map.yaml", case.data)
    return _convert(seeds.logs[0], work, "--urdf", str(seeds.urdf), "--map", str(m))


_ROLES = {
    "topics": {
        "/joint_states": "joint_states",
        "/box/pose": "object_pose:box",
        "/cam/image_raw/compressed": "camera_image:cam",
    },
    "tf_objects": {"box": "box"},
}


def _roles_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    return yaml_mutation(_ROLES).map(lambda d: Case("roles.yaml", d))


def _roles_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    m = put(work / "roles.yaml", case.data)
    return _convert(seeds.mcaps[2], work, "--map", str(m))


def _robot_strategy(seeds: Seeds) -> st.SearchStrategy[Case]:
    return xml_mutation(seeds.urdf.read_bytes()).map(lambda d: Case("robot.urdf", d))


def _robot_prepare(seeds: Seeds, case: Case, work: Path) -> list[str]:
    robot = link_copy(seeds.urdf.parent, work / "robot")
    urdf = put(robot / "robot.urdf", case.data)
    return _convert(seeds.mcaps[2], work, "--urdf", str(urdf))


TARGETS: tuple[Target, ...] = (
    Target("manifest", "manifest JSON", "manifest.json tree edits (deleted keys, type swaps, absurd numbers, deep nesting, hostile paths) and byte damage; validate --quick", _manifest_strategy, _manifest_prepare),
    Target("manifest_full", "manifest JSON", "the same manifest edits; schema, integrity, time and geometry checks that open the files it names", _manifest_strategy, _manifest_full_prepare),
    Target("sidecar", "sidecar JSON", "cameras/cam0.json, physics.json, robot/mdh.json tree edits and byte damage", _sidecar_strategy, _sidecar_prepare),
    Target("tables", "parquet tables", "7 episode tables: dropped/renamed/cast columns, nulls, NaN/inf/int64 extremes, 0/1/duplicated rows, footer and page byte damage", _table_strategy, _table_prepare),
    Target("splats", "splat PLY", "header edits (vertex counts up to 2**64-1, bad/duplicate/missing properties, extra elements, wrong format) and body damage", _splat_strategy, _splat_prepare),
    Target("urdf", "URDF XML", "dataset URDF: dropped elements/attributes, evil attribute values (nan, 1e308, escaping mesh paths), duplicates, 5000-deep nesting, entity/DOCTYPE declarations, byte damage", _urdf_strategy, _urdf_prepare),
    Target("robot_urdf", "URDF XML", "URDF given to convert --urdf (mesh copy, package:// resolution) with the same edits", _robot_strategy, _robot_prepare),
    Target("meshes", "meshes", "binary PLY and STL of the dataset, OBJ, ASCII PLY, STL, COLLADA, GLB assets: header edits, text and byte damage", _mesh_strategy, _mesh_prepare),
    Target("mcap", "bags and MCAP", "ROS 2 MCAP (zstd, lz4, uncompressed chunks): byte damage and interesting integers over length/count fields", _mcap_strategy, _mcap_prepare),
    Target("mcap_messages", "bags and MCAP", "valid MCAP container with hostile messages: JointState length mismatches and extreme stamps, Image with absurd width/height/step/encoding, CameraInfo with wrong distortion, garbage CompressedImage", _message_strategy, _message_prepare),
    Target("ros1", "bags and MCAP", "ROS 1 bags (uncompressed, bz2, lz4): byte damage", _ros1_strategy, _ros1_prepare),
    Target("ros2", "bags and MCAP", "ROS 2 bag folder: metadata.yaml tree edits, sqlite3 byte damage", _ros2_strategy, _ros2_prepare),
    Target("video", "video containers", "MP4 (mp4v) and AVI (MJPG): byte damage", _video_strategy, _video_prepare),
    Target("calibration", "calibration YAML", "ROS camera_info YAML, OpenCV FileStorage YAML, ROS INI: tree edits, alias bombs, python tags, byte damage", _calib_strategy, _calib_prepare),
    Target("stamps", "video containers", "frame stamps CSV (--stamps): cell, line and byte edits", _stamps_strategy, _stamps_prepare),
    Target("tabular_csv", "CSV/Parquet joint logs", "CSV joint log: cells (nan, 1e308, 5000-digit numbers, text), dropped/duplicated lines and columns, delimiters, byte damage", _tab_csv_strategy, _tab_csv_prepare),
    Target("tabular_parquet", "CSV/Parquet joint logs", "Parquet joint log: column and value edits, byte damage", _tab_pq_strategy, _tab_pq_prepare),
    Target("tabular_map", "YAML maps", "column map YAML (--map) of a joint log: tree edits and hostile YAML", _mapping_strategy, _mapping_prepare),
    Target("role_map", "YAML maps", "topic role map YAML (--map) of an MCAP: tree edits and hostile YAML", _roles_strategy, _roles_prepare),
)  # fmt: skip


def target(name: str) -> Target:
    """The target called ``name``."""
    for t in TARGETS:
        if t.name == name:
            return t
    raise KeyError(name)


def run_case(seeds: Seeds, tgt: Target, case: Case, *, subprocess: bool = False) -> Verdict:
    """Lay ``case`` out in a temporary folder, run its command, judge it, clean up."""
    import tempfile

    from .harness import run_inprocess, run_subprocess

    with tempfile.TemporaryDirectory(prefix=f"robogs-fuzz-{tgt.name}-") as tmp:
        argv = tgt.prepare(seeds, case, Path(tmp))
        return (run_subprocess if subprocess else run_inprocess)(argv)
