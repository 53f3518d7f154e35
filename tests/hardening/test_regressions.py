"""One test per crash the fuzzers found: the minimal input that crashed, now one clear error
(or a finding), naming the file and the place."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from robogs.convert.ingest.calibration import read_calibration
from robogs.convert.ingest.roles import load_role_map
from robogs.convert.ingest.rosbag_source import ros2_storage_paths
from robogs.convert.ingest.tabular import _to_ns, read_mapping
from robogs.convert.ingest.video import read_stamps_csv
from robogs.format import Dataset
from robogs.format.errors import FormatError, InputError
from robogs.format.splats import read_splat_ply

from .craft import craft_mcap, one_message_records
from .harness import run_inprocess
from .seeds import Seeds
from .targets import link_copy, put


def _findings(ds: Path, select: str) -> list[dict]:
    v = run_inprocess(["validate", ds, "--json", "--select", select])
    assert v.ok and v.rc in (0, 1), v.describe()
    return json.loads(v.stdout)["findings"]


def _replace_table(seeds: Seeds, tmp_path: Path, rel: str, fn) -> Path:
    ds = link_copy(seeds.dataset, tmp_path / "ds")
    table = fn(pq.read_table(seeds.dataset / rel))
    (ds / rel).unlink()
    pq.write_table(table, ds / rel)
    return ds


# ----------------------------------------------------------------------------- dataset readers


def test_splat_property_declared_twice(seeds: Seeds, tmp_path: Path) -> None:
    data = (seeds.dataset / "assets/box/splats.ply").read_bytes()
    head, body = data.split(b"end_header\n", 1)
    path = tmp_path / "s.ply"
    path.write_bytes(head.replace(b"property float y\n", b"property float y\nproperty float y\n", 1)
                     + b"end_header\n" + body)  # fmt: skip
    with pytest.raises(FormatError, match=r"property 'y' is declared twice") as err:
        read_splat_ply(path)
    assert "s.ply" in str(err.value) and "header line" in str(err.value)


@pytest.mark.parametrize(
    ("rel", "column"),
    [
        ("episodes/ep000/joint_states.parquet", "t_ns"),
        ("episodes/ep000/boxes2d.parquet", "label_id"),
        ("episodes/ep000/cameras/cam0/labels.parquet", "frame_index"),
        ("episodes/ep000/segments.parquet", "label_id"),
    ],
)
def test_nulls_in_integer_columns_are_a_schema_finding(
    seeds: Seeds, tmp_path: Path, rel: str, column: str
) -> None:
    def nulls(t: pa.Table) -> pa.Table:
        k = t.schema.get_field_index(column)
        return t.set_column(k, t.schema.field(k), pa.nulls(t.num_rows, t.schema.field(k).type))

    ds = _replace_table(seeds, tmp_path, rel, nulls)
    found = _findings(ds, "S003,T001,T007,T010,T011,G009,B010,S007")
    assert not [f for f in found if f["code"] == "X001"], found
    s003 = [f for f in found if f["code"] == "S003" and f["location"]["file"] == rel]
    assert s003 and f"column '{column}' holds" in s003[0]["message"], found


def test_duplicate_column_names_are_a_schema_finding(seeds: Seeds, tmp_path: Path) -> None:
    rel = "episodes/ep000/ee_poses.parquet"
    ds = _replace_table(seeds, tmp_path, rel, lambda t: t.rename_columns(["t_ns"] * t.num_columns))
    found = _findings(ds, "S003,T001,T007,T008,G008")
    assert not [f for f in found if f["code"] == "X001"], found
    assert any(f["code"] == "S003" and "duplicate column names" in f["message"] for f in found)


def test_label_table_with_swapped_columns(seeds: Seeds, tmp_path: Path) -> None:
    rel = "episodes/ep000/cameras/cam0/labels.parquet"
    ds = _replace_table(seeds, tmp_path, rel, lambda t: t.rename_columns(["png", "frame_index"]))
    found = _findings(ds, "S003,G009,T010")
    assert not [f for f in found if f["code"] == "X001"], found
    assert any(f["code"] == "S003" for f in found)


def test_empty_joint_states_do_not_crash_the_limit_check(seeds: Seeds, tmp_path: Path) -> None:
    ds = _replace_table(
        seeds, tmp_path, "episodes/ep000/joint_states.parquet", lambda t: t.slice(0, 0)
    )
    found = _findings(ds, "G007,I005")
    assert not [f for f in found if f["code"] == "X001"], found
    assert any(f["code"] == "I005" and "0 rows" in f["message"] for f in found), found


def test_mesh_with_2d_vertices(seeds: Seeds, tmp_path: Path) -> None:
    ds = link_copy(seeds.dataset, tmp_path / "ds")
    obj = (
        "".join(f"v {x} {y}\n" for x, y in [(0, 0), (1, 0), (0, 1), (1, 1)]) + "f 1 2 3\nf 2 4 3\n"
    )
    put(ds / "assets/box/mesh.ply", b"")  # the manifest now points elsewhere
    put(ds / "assets/box/mesh.obj", obj.encode())
    m = json.loads((ds / "manifest.json").read_text())
    m["assets"]["box"]["mesh"] = "assets/box/mesh.obj"
    put(ds / "manifest.json", json.dumps(m).encode())
    with pytest.raises(FormatError, match="vertices|triangles") as err:
        Dataset.open(ds).mesh("box")
    assert "mesh.obj" in str(err.value)
    found = _findings(ds, "G006,G010,G011")
    assert not [f for f in found if f["code"] == "X001"], found


# ----------------------------------------------------------------------------- converter inputs


def test_stamps_csv_not_utf8_and_out_of_range(tmp_path: Path) -> None:
    p = tmp_path / "stamps.csv"
    p.write_bytes(b"frame_index,t_ns\n0,100\n1,2\xff00\n")
    with pytest.raises(InputError, match="not UTF-8") as err:
        read_stamps_csv(p)
    assert "stamps.csv" in str(err.value)
    p.write_text("frame_index,t_ns\n0,100\n1," + "9" * 30 + "\n")
    with pytest.raises(InputError, match="int64") as err:
        read_stamps_csv(p)
    assert "line 3" in str(err.value)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (
            "image_width: 16\nimage_height: 12\ncamera_matrix: " + "[" * 3000 + "]" * 3000,
            "nested too deeply",
        ),
        ("image_width: .inf\nimage_height: 12\n", "image_width"),
        (
            "image_width: 16\nimage_height: 12\ncamera_matrix: {rows: [3], cols: 3, data: [1,0,0,0,1,0,0,0,1]}\n",
            "wrong type",
        ),
        ("a: &x [1]\nimage_width: *x\n", "alias"),
    ],
    ids=["deep", "inf_width", "rows_list", "alias"],
)
def test_calibration_yaml(tmp_path: Path, text: str, match: str) -> None:
    p = tmp_path / "cam.yaml"
    p.write_text(text)
    with pytest.raises(InputError, match=match) as err:
        read_calibration(p)
    assert "cam.yaml" in str(err.value)


def test_calibration_ini_with_nan_size(tmp_path: Path, seeds: Seeds) -> None:
    text = seeds.calibrations[2].read_text().replace("width\n16", "width\nnan")
    p = tmp_path / "cam.ini"
    p.write_text(text)
    with pytest.raises(InputError, match="wrong type.*NaN") as err:
        read_calibration(p)
    assert "cam.ini" in str(err.value)


def test_ros2_metadata_nested_too_deeply(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: " + "[" * 5000)
    with pytest.raises(InputError, match="nested too deeply") as err:
        ros2_storage_paths(bag)
    assert "metadata.yaml" in str(err.value)


def test_role_map_not_utf8(tmp_path: Path) -> None:
    p = tmp_path / "roles.yaml"
    p.write_bytes(b"/joint_states: joint_states\n/x: \xff\n")
    with pytest.raises(InputError, match="not UTF-8") as err:
        load_role_map(p)
    assert "roles.yaml" in str(err.value) and "byte 32" in str(err.value)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (
            "time: {column: t_ns, unit: ns}\ngap_s: 5.0e+299\njoints: {j1: position.j1, j2: position.j2}\n",
            "gap_s",
        ),
        (
            "time: {column: t_ns, unit: ns}\ngap_s: [1]\njoints: {j1: position.j1, j2: position.j2}\n",
            "wrong type",
        ),
        (
            "time: {column: t_ns, unit: ns, epoch_ns: "
            + "9" * 30
            + "}\njoints: {j1: position.j1, j2: position.j2}\n",
            "epoch_ns",
        ),
        ("time: {column: t_ns, unit: ns}\njoints: {j1: [1, 2], j2: position.j2}\n", "wrong type"),
    ],
    ids=["huge_gap", "gap_list", "huge_epoch", "joint_list"],
)
def test_column_map(tmp_path: Path, text: str, match: str) -> None:
    p = tmp_path / "map.yaml"
    p.write_text(text)
    with pytest.raises(InputError, match=match) as err:
        read_mapping(p, ["j1", "j2"])
    assert "map.yaml" in str(err.value)


def test_column_map_not_utf8(tmp_path: Path) -> None:
    p = tmp_path / "map.yaml"
    p.write_bytes(b"time: {column: t\xff}\n")
    with pytest.raises(InputError, match="not UTF-8"):
        read_mapping(p, ["j1", "j2"])


def test_time_column_out_of_int64_is_a_dropped_row_not_a_crash() -> None:
    t, bad = _to_ns(np.array(["1.5", "9" * 5000, "1e30", "-3", "9223372037"]), "s")
    assert bad.tolist() == [False, True, True, False, True]
    assert t[[0, 3]].tolist() == [1_500_000_000, -3_000_000_000]
    t, bad = _to_ns(np.array([1, 2**62], dtype=np.int64), "ms")
    assert bad.tolist() == [False, True] and t[0] == 1_000_000
    t, bad = _to_ns(np.array([0.5, 1e19, np.nan]), "s")
    assert bad.tolist() == [False, True, True] and t[0] == 500_000_000


def test_tabular_csv_with_huge_stamps_converts_the_rest(seeds: Seeds, tmp_path: Path) -> None:
    lines = seeds.logs[0].read_text().splitlines()
    lines[3] = "9" * 5000 + lines[3][lines[3].index(",") :]
    log = tmp_path / "log.csv"
    log.write_text("\n".join(lines) + "\n")
    v = run_inprocess(["convert", log, tmp_path / "out", "--urdf", seeds.urdf, "--json"])
    assert v.ok and v.rc == 0, v.describe()
    prov = Dataset.open(tmp_path / "out").manifest["provenance"]
    assert "4" in json.dumps(prov)  # the dropped row is reported by its line number
    js = Dataset.open(tmp_path / "out").episode().table("joint_states")
    assert js.num_rows == len(lines) - 2


def test_mcap_schema_that_does_not_fit_its_type(seeds: Seeds, tmp_path: Path) -> None:
    """Found by atheris: a stored schema whose field names differ from the ROS type decodes into
    a message the handlers cannot use (AttributeError inside the TF ingest)."""
    seed = next(p for p in seeds.mcaps if p.name == "nocrc_none.mcap").read_bytes()
    assert b"Quaternion rotation" in seed
    path = tmp_path / "misfit.mcap"
    path.write_bytes(seed.replace(b"Quaternion rotation", b"Quaternion rotatiom"))
    v = run_inprocess(["convert", path, tmp_path / "out"])
    assert v.ok and v.rc == 2, v.describe()
    assert "misfit.mcap" in v.stderr and "topic /tf_static" in v.stderr
    assert "does not fit its type" in v.stderr


def test_mcap_record_length_beyond_an_index(tmp_path: Path) -> None:
    """Found by atheris: a record length of 2**64-1 inside a chunk (BytesIO.read OverflowError)."""
    records = bytearray(one_message_records())
    records[1:9] = (2**64 - 1).to_bytes(8, "little")  # opcode, then the record length
    path = tmp_path / "overflow.mcap"
    path.write_bytes(craft_mcap(bytes(records), "", len(records), len(records)))
    v = run_inprocess(["convert", path, tmp_path / "out"])
    assert v.ok and v.rc == 2, v.describe()
    assert "overflow.mcap" in v.stderr and "corrupt" in v.stderr
