"""Security: paths never leave the dataset root, XML entities and YAML aliases are refused,
absurd sizes are refused before anything is allocated, MCAP and bag chunk decompression is
capped, and nothing in a dataset is unpickled or evaluated.

"Never opened" is tested with named pipes (FIFOs) outside the root: opening a FIFO for reading
blocks until a writer appears, so any reader — Python, pyarrow, OpenCV or trimesh — that
follows a hostile path hangs and the subprocess harness reports a hang.
"""

from __future__ import annotations

import ast
import io
import json
import os
import pickle
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from robogs.convert.ingest.decompress import (
    MAX_CHUNK_BYTES,
    DecompressionLimitError,
    bounded_decompress,
    capped_decompression,
)
from robogs.format import Dataset
from robogs.format.errors import FormatError, InputError, PathEscapeError
from robogs.format.splats import read_splat_ply
from robogs.format.urdf import load_urdf, parse_urdf_robot

from .craft import craft_mcap, one_message_records
from .harness import run_inprocess, run_subprocess
from .seeds import TINY_URDF, Seeds
from .targets import link_copy, put

REPO = Path(__file__).resolve().parents[2]
MiB = 1 << 20


def _peak(fn) -> tuple[object, int]:
    """(result or exception, peak bytes traced by tracemalloc while ``fn`` ran)."""
    tracemalloc.start()
    try:
        try:
            out: object = fn()
        except Exception as exc:  # noqa: BLE001 - the caller inspects it
            out = exc
        return out, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.fixture
def outside(tmp_path: Path) -> Path:
    """A folder beside the dataset holding FIFOs that must never be opened."""
    out = tmp_path / "outside"
    out.mkdir()
    for name in ("secret.parquet", "secret.json", "secret.stl", "secret.ply", "secret.urdf"):
        os.mkfifo(out / name)
    return out


def _edit_manifest(ds: Path, fn) -> None:
    m = json.loads((ds / "manifest.json").read_text())
    fn(m)
    put(ds / "manifest.json", json.dumps(m).encode())


# ----------------------------------------------------------------------------- paths

HOSTILE = {
    "dotdot": "../outside/secret.parquet",
    "deep_dotdot": "episodes/../../outside/secret.parquet",
    "absolute": "{outside}/secret.parquet",
    "file_uri": "file://{outside}/secret.parquet",
    "package_uri": "package://robot/../../outside/secret.parquet",
    "backslash": "..\\outside\\secret.parquet",
    "windows": "C:\\outside\\secret.parquet",
    "nul": "episodes/ep000/joint_states.parquet\x00../x",
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_manifest_path_refused_by_the_reader(
    seeds: Seeds, tmp_path: Path, outside: Path, name: str
) -> None:
    ds = link_copy(seeds.dataset, tmp_path / "ds")
    rel = HOSTILE[name].format(outside=outside)
    _edit_manifest(
        ds, lambda m: m["episodes"][0]["streams"]["joint_states"].__setitem__("path", rel)
    )
    with pytest.raises(PathEscapeError) as err:
        Dataset.open(ds, check_schema=False).episode("ep000").table("joint_states")
    assert "manifest.json" in str(err.value) and "joint_states/path" in str(err.value)


def test_symlinked_file_out_of_root_refused(seeds: Seeds, tmp_path: Path, outside: Path) -> None:
    ds = link_copy(seeds.dataset, tmp_path / "ds")
    link = ds / "episodes/ep000/joint_states.parquet"
    link.unlink()
    link.symlink_to(outside / "secret.parquet")
    with pytest.raises(PathEscapeError, match="symlink"):
        Dataset.open(ds).episode("ep000").table("joint_states")


def test_validate_reports_every_escape_and_opens_none(
    seeds: Seeds, tmp_path: Path, outside: Path
) -> None:
    """One manifest with a hostile path in every kind of field, plus symlinks out of the root:
    validate (in a subprocess, FIFOs as targets) finishes, reports each, and opens none."""
    ds = link_copy(seeds.dataset, tmp_path / "ds")
    o = str(outside)

    def poison(m: dict) -> None:
        streams = m["episodes"][0]["streams"]
        streams["joint_states"]["path"] = "../outside/secret.parquet"
        streams["object_poses"]["path"] = f"{o}/secret.parquet"
        streams["camera/cam0"]["frames"] = f"file://{o}/secret.parquet"
        m["cameras"]["cam0"] = "cameras/../../outside/secret.json"
        m["physics"] = f"{o}/secret.json"
        m["robot"]["mdh"] = "package://robot/../../outside/secret.json"
        m["assets"]["box"]["mesh"] = "assets/box/out.ply"  # a symlink, below
        m["robot"]["urdf"] = "robot/out.urdf"  # a symlink, below

    _edit_manifest(ds, poison)
    (ds / "assets/box/out.ply").symlink_to(outside / "secret.ply")
    (ds / "robot/out.urdf").symlink_to(outside / "secret.urdf")
    ee = ds / "episodes/ep000/ee_poses.parquet"
    ee.unlink()
    ee.symlink_to(outside / "secret.parquet")
    v = run_subprocess(
        ["validate", ds, "--json", "--ignore", "B002,B003,B004,B005,B006,B009,P004,T012"],
        cpu_limit_s=60,
        wall_limit_s=240,
    )
    assert v.ok and v.rc == 1, v.describe()
    found = json.loads(v.stdout)["findings"]
    escapes = [f for f in found if f["code"] == "I007"]
    wheres = {f["location"].get("where") for f in escapes}
    files = {f["location"].get("file") for f in escapes}
    assert wheres >= {
        "/episodes/0/streams/joint_states/path",
        "/episodes/0/streams/object_poses/path",
        "/episodes/0/streams/camera/cam0/frames",
        "/cameras/cam0",
        "/physics",
        "/robot/mdh",
        "/assets/box/mesh",
        "/robot/urdf",
    }, wheres
    assert "episodes/ep000/ee_poses.parquet" in files, files


URDF_ESCAPES = {
    "dotdot": "../../outside/secret.stl",
    "absolute": "{outside}/secret.stl",
    "file_uri": "file://{outside}/secret.stl",
    "package_dotdot": "package://robot/../../outside/secret.stl",
    "http": "http://127.0.0.1/secret.stl",
    "symlinked_package": "package://evil/secret.stl",
    "symlinked_file": "meshes/out.stl",
}


def _hostile_robot(tmp_path: Path, outside: Path, uri: str) -> Path:
    root = tmp_path / "ws" / "robot"
    (root / "meshes").mkdir(parents=True)
    (root / "meshes" / "out.stl").symlink_to(outside / "secret.stl")
    (root / "evil").symlink_to(outside, target_is_directory=True)
    (root / "package.xml").write_text("<package><name>robot</name></package>")
    urdf = root / "robot.urdf"
    urdf.write_text(TINY_URDF.replace("meshes/base.stl", uri.format(outside=outside)))
    return urdf


@pytest.mark.parametrize("name", sorted(URDF_ESCAPES))
def test_urdf_mesh_escape_refused(tmp_path: Path, outside: Path, name: str) -> None:
    urdf = _hostile_robot(tmp_path, outside, URDF_ESCAPES[name])
    with pytest.raises(PathEscapeError) as err:
        load_urdf(urdf, root=urdf.parent)
    assert "robot.urdf" in str(err.value) and "link 'base'" in str(err.value)


def test_convert_with_escaping_urdf_exits_2_and_opens_nothing(
    seeds: Seeds, tmp_path: Path, outside: Path
) -> None:
    urdf = _hostile_robot(tmp_path, outside, URDF_ESCAPES["symlinked_package"])
    v = run_subprocess(
        ["convert", seeds.mcaps[2], tmp_path / "out", "--urdf", urdf], wall_limit_s=120
    )
    assert v.ok and v.rc == 2, v.describe()
    assert "outside" in v.stderr and "secret.stl" in v.stderr
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- XML and YAML

BILLION_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE robot [
 <!ENTITY a "aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa">
 <!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;"> <!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">
 <!ENTITY d "&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;"> <!ENTITY e "&d;&d;&d;&d;&d;&d;&d;&d;&d;&d;">
 <!ENTITY f "&e;&e;&e;&e;&e;&e;&e;&e;&e;&e;"> <!ENTITY g "&f;&f;&f;&f;&f;&f;&f;&f;&f;&f;">
 <!ENTITY h "&g;&g;&g;&g;&g;&g;&g;&g;&g;&g;"> <!ENTITY i "&h;&h;&h;&h;&h;&h;&h;&h;&h;&h;">
]>
<robot name="&i;"><link name="base"/></robot>
"""

XXE = """<?xml version="1.0"?>
<!DOCTYPE robot [<!ENTITY xxe SYSTEM "file://{outside}/secret.urdf">]>
<robot name="r"><link name="&xxe;"/></robot>
"""

PARAMETER_ENTITY = """<?xml version="1.0"?>
<!DOCTYPE robot [<!ENTITY % ext SYSTEM "file://{outside}/secret.urdf"> %ext;]>
<robot name="r"><link name="base"/></robot>
"""

EXTERNAL_DTD = """<?xml version="1.0"?>
<!DOCTYPE robot SYSTEM "file://{outside}/secret.urdf">
<robot name="r"><link name="base"/></robot>
"""


@pytest.mark.parametrize("doc", ["billion_laughs", "xxe", "parameter_entity", "external_dtd"])
def test_hostile_xml_rejected_without_expansion(tmp_path: Path, outside: Path, doc: str) -> None:
    text = {"billion_laughs": BILLION_LAUGHS, "xxe": XXE, "parameter_entity": PARAMETER_ENTITY,
            "external_dtd": EXTERNAL_DTD}[doc]  # fmt: skip
    path = tmp_path / "r.urdf"
    path.write_text(text.format(outside=outside))
    out, peak = _peak(lambda: parse_urdf_robot(path))
    assert isinstance(out, FormatError), out
    assert "entities" in str(out) and "r.urdf" in str(out)
    assert peak < 4 * MiB  # 10**9 characters were never expanded


def test_billion_laughs_via_cli_is_one_clear_error(
    seeds: Seeds, tmp_path: Path, outside: Path
) -> None:
    urdf = tmp_path / "bl.urdf"
    urdf.write_text(BILLION_LAUGHS)
    v = run_subprocess(
        ["convert", seeds.mcaps[2], tmp_path / "out", "--urdf", urdf], wall_limit_s=120
    )
    assert v.ok and v.rc == 2, v.describe()
    assert v.stderr.count("\n") == 1 and "entities" in v.stderr
    assert v.peak_rss < 1024 * MiB


def test_collada_mesh_with_xxe_refused(tmp_path: Path, outside: Path, seeds: Seeds) -> None:
    root = tmp_path / "robot"
    (root / "meshes").mkdir(parents=True)
    dae = next(p for p in seeds.meshes if p.suffix == ".dae").read_text()
    head = f'<?xml version="1.0"?>\n<!DOCTYPE COLLADA [<!ENTITY xxe SYSTEM "file://{outside}/secret.urdf">]>\n'
    body = dae.split("?>", 1)[1] if dae.startswith("<?xml") else dae
    (root / "meshes" / "base.dae").write_text(
        head + body.replace("<asset>", "<asset><title>&xxe;</title>", 1)
    )
    urdf = root / "robot.urdf"
    urdf.write_text(TINY_URDF.replace("meshes/base.stl", "meshes/base.dae"))
    with pytest.raises(FormatError, match="entities"):
        load_urdf(urdf, root=root)


@pytest.mark.parametrize(
    "text",
    [
        "a: &a [x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
        "image_width: *b\nimage_height: 12\n",
        "image_width: !!python/object/apply:os.mkdir ['{marker}']\nimage_height: 12\n",
        "image_width: 16\nimage_height: 12\n"
        + "camera_matrix: "
        + "[" * 20000
        + "]" * 20000
        + "\n",
    ],
    ids=["alias_bomb", "python_tag", "deep_nesting"],
)
def test_hostile_calibration_yaml_refused(tmp_path: Path, text: str) -> None:
    from robogs.convert.ingest.calibration import read_calibration

    marker = tmp_path / "pwned"
    path = tmp_path / "cam.yaml"
    path.write_text(text.format(marker=marker))
    with pytest.raises(InputError) as err:
        read_calibration(path)
    assert "cam.yaml" in str(err.value)
    assert not marker.exists()


# ----------------------------------------------------------------------------- sizes


def _splat_ply(count: str, body: bytes) -> bytes:
    props = "".join(f"property float {p}\n" for p in
                    ("x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
                     "rot_0", "rot_1", "rot_2", "rot_3"))  # fmt: skip
    return (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {count}\n{props}end_header\n".encode()
        + body
    )


@pytest.mark.parametrize("count", [str(2**40), str(2**64 - 1), "49999999"])
def test_splat_header_claiming_absurd_count_refused_before_allocation(
    tmp_path: Path, count: str
) -> None:
    path = tmp_path / "s.ply"
    path.write_bytes(_splat_ply(count, bytes(56 * 3)))
    out, peak = _peak(lambda: read_splat_ply(path))
    assert isinstance(out, FormatError), out
    assert "s.ply" in str(out) and ("limit" in str(out) or "implies" in str(out))
    assert peak < 1 * MiB


def test_splat_reader_reads_a_valid_file_of_the_same_layout(tmp_path: Path) -> None:
    """Control for the test above: the same header with a matching body is read."""
    path = tmp_path / "s.ply"
    path.write_bytes(_splat_ply("3", np.arange(42, dtype="<f4").tobytes()))
    s = read_splat_ply(path)
    assert len(s) == 3 and s.means[2].tolist() == [28.0, 29.0, 30.0]


def test_mesh_ply_header_claiming_absurd_count_refused(seeds: Seeds, tmp_path: Path) -> None:
    ds = link_copy(seeds.dataset, tmp_path / "ds")
    data = (seeds.dataset / "assets/box/mesh.ply").read_bytes()
    assert b"element vertex 8\n" in data
    put(
        ds / "assets/box/mesh.ply",
        data.replace(b"element vertex 8\n", b"element vertex 4000000000\n"),
    )
    out, peak = _peak(lambda: Dataset.open(ds).mesh("box"))
    assert isinstance(out, FormatError) and "mesh.ply" in str(out), out
    assert peak < 4 * MiB


def test_label_png_claiming_huge_size_refused_before_decode() -> None:
    import zlib

    from robogs.format.images import decode_label_png

    ihdr = (60000).to_bytes(4, "big") * 2 + bytes([16, 0, 0, 0, 0])
    chunk = lambda t, b: len(b).to_bytes(4, "big") + t + b + zlib.crc32(t + b).to_bytes(4, "big")  # noqa: E731
    png = (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b""))
        + chunk(b"IEND", b"")
    )
    out, peak = _peak(lambda: decode_label_png(png, path="labels.parquet", where="frame_index 3"))
    assert isinstance(out, FormatError) and "60000x60000" in str(out), out
    assert peak < 1 * MiB


def test_json_over_the_limit_refused_without_reading(tmp_path: Path, seeds: Seeds) -> None:
    ds = link_copy(seeds.dataset, tmp_path / "ds")
    big = ds / "manifest.json"
    big.unlink()
    with open(big, "wb") as fh:  # sparse: 65 MiB claimed, nothing written
        fh.truncate(65 * MiB)
    out, peak = _peak(lambda: Dataset.open(ds))
    assert isinstance(out, FormatError) and "limit" in str(out), out
    assert peak < 1 * MiB


# ----------------------------------------------------------------------------- decompression


def _zeros_bomb(kind: str, size: int) -> bytes:
    if kind == "zstd":
        import zstandard

        return zstandard.ZstdCompressor(level=3, write_content_size=True).compress(bytes(size))
    if kind == "lz4":
        import lz4.frame

        return lz4.frame.compress(bytes(size), store_size=True)
    import bz2

    return bz2.compress(bytes(size), 9)


@pytest.mark.parametrize("kind", ["zstd", "lz4", "bz2"])
def test_bounded_decompress_stops_at_the_limit(kind: str) -> None:
    bomb = _zeros_bomb(kind, 64 * MiB)
    assert len(bomb) < MiB
    out, peak = _peak(lambda: bounded_decompress(bomb, kind, 4 * MiB))
    assert isinstance(out, DecompressionLimitError), out
    assert peak < 12 * MiB
    assert bounded_decompress(bomb, kind, 64 * MiB) == bytes(64 * MiB)


def test_crafted_mcap_is_readable_when_honest(tmp_path: Path) -> None:
    """Control: the hand-written MCAP is valid for the mcap library and for robogs."""
    import zstandard
    from mcap.reader import make_reader

    records = one_message_records()
    data = craft_mcap(zstandard.compress(records), "zstd", len(records), len(records))
    msgs = list(make_reader(io.BytesIO(data)).iter_messages())
    assert [c.topic for _, c, _ in msgs] == ["/joint_states"]
    path = tmp_path / "ok.mcap"
    path.write_bytes(data)
    v = run_inprocess(["convert", path, tmp_path / "out"])
    assert v.ok and v.rc == 0, v.describe()
    table = Dataset.open(tmp_path / "out").episode().table("joint_states")
    assert table.column("position.j1").to_pylist() == [0.25]
    assert table.column("position.j2").to_pylist() == [-0.5]


@pytest.mark.parametrize(
    "case",
    ["zstd_small_claims", "lz4_small_claims", "index_claims_huge", "chunk_claims_huge"],
)
def test_mcap_chunk_decompression_is_capped(tmp_path: Path, case: str) -> None:
    kind = case.split("_")[0] if case.startswith(("zstd", "lz4")) else "zstd"
    bomb = _zeros_bomb(kind, 64 * MiB)
    claims = {
        "zstd_small_claims": (1000, 1000),
        "lz4_small_claims": (1000, 1000),
        "index_claims_huge": (1000, 2**40),
        "chunk_claims_huge": (2**40, 1000),
    }[case]
    path = tmp_path / "bomb.mcap"
    path.write_bytes(craft_mcap(bomb, kind, *claims))
    v, peak = _peak(lambda: run_inprocess(["convert", path, tmp_path / "out"]))
    assert v.ok and v.rc == 2, v.describe()
    assert "bomb.mcap" in v.stderr and ("limit" in v.stderr or "declared" in v.stderr), v.stderr
    assert peak < 16 * MiB, peak  # the 64 MiB the chunk expands to were never allocated


def test_uncapped_library_would_allocate_the_bomb() -> None:
    """Why the cap matters: zstd's one-shot decompressor trusts the frame's content size."""
    import zstandard

    bomb = _zeros_bomb("zstd", 64 * MiB)
    out, peak = _peak(lambda: zstandard.decompress(bomb, 1000))
    assert len(out) == 64 * MiB and peak >= 64 * MiB


def test_mcap_record_claiming_2_62_bytes_is_a_short_read(tmp_path: Path) -> None:
    records = one_message_records()
    data = bytearray(craft_mcap(records, "", len(records), len(records)))
    at = data.index(records) - 8  # the chunk's data-length field
    data[at : at + 8] = (2**62).to_bytes(8, "little")
    path = tmp_path / "long.mcap"
    path.write_bytes(bytes(data))
    v, peak = _peak(lambda: run_inprocess(["convert", path, tmp_path / "out"]))
    assert v.ok and v.rc == 2 and "long.mcap" in v.stderr, v.describe()
    assert peak < 16 * MiB


def test_bag_decompressors_capped_only_inside_the_block() -> None:
    from rosbags.rosbag1 import reader as r1
    from rosbags.rosbag2 import storage_mcap as r2

    bomb = _zeros_bomb("bz2", 8 * MiB)
    before = (r1.decompressors["bz2"], r2.DECOMPRESSORS["zstd"])
    with capped_decompression(limit=MiB):
        with pytest.raises(DecompressionLimitError):
            r1.decompressors["bz2"](bomb)
        with pytest.raises(DecompressionLimitError):
            r2.DECOMPRESSORS["zstd"](_zeros_bomb("zstd", 8 * MiB), 8 * MiB)
    assert (r1.decompressors["bz2"], r2.DECOMPRESSORS["zstd"]) == before
    assert len(r1.decompressors["bz2"](bomb)) == 8 * MiB
    assert MAX_CHUNK_BYTES <= 512 * MiB


# ----------------------------------------------------------------------------- code execution


class _Plant:
    """Unpickling this creates the marker folder."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.mkdir, (str(self.marker),))


def test_pickled_checkpoint_is_refused_not_run(tmp_path: Path) -> None:
    import torch

    from robogs.reconstruct.checkpoint import load_checkpoint

    marker = tmp_path / "pwned"
    ckpt = tmp_path / "ckpt.pt"
    torch.save({"format": "robogs-reconstruct-checkpoint-1", "x": _Plant(marker)}, ckpt)
    with pytest.raises(InputError, match="checkpoint"):
        load_checkpoint(ckpt, "fp")
    assert not marker.exists()


def test_pickles_and_extension_types_in_a_dataset_are_never_loaded(
    seeds: Seeds, tmp_path: Path
) -> None:
    """An object-dtype .npy listed in the manifest, a parquet table whose column claims the
    pickle-based ``arrow.py_extension_type``, and a pickle named like a mesh: validate and the
    reader API report or refuse them, and nothing is unpickled."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    marker = tmp_path / "pwned"
    ds = link_copy(seeds.dataset, tmp_path / "ds")
    payload = pickle.dumps(_Plant(marker))
    np.save(ds / "extra.npy", np.array([_Plant(marker)], dtype=object), allow_pickle=True)
    put(ds / "assets/box/mesh.ply", payload)
    js = pq.read_table(seeds.dataset / "episodes/ep000/joint_states.parquet")
    meta = {
        b"ARROW:extension:name": b"arrow.py_extension_type",
        b"ARROW:extension:metadata": payload,
    }
    field = pa.field("extra", pa.binary(), metadata=meta)
    js = js.append_column(field, pa.array([b"x"] * js.num_rows, pa.binary()))
    ep = ds / "episodes/ep000/joint_states.parquet"
    ep.unlink()
    pq.write_table(js, ep)

    def listed(m: dict) -> None:
        m["files"]["extra.npy"] = {"sha256": "0" * 64, "size": (ds / "extra.npy").stat().st_size}

    _edit_manifest(ds, listed)
    v = run_inprocess(
        ["validate", ds, "--json", "--ignore", "B002,B003,B004,B005,B006,B009,P004,T012"]
    )
    assert v.ok and v.rc == 1, v.describe()
    found = {(f["code"], f["location"].get("file")) for f in json.loads(v.stdout)["findings"]}
    assert ("I004", "extra.npy") in found, found  # hashed as bytes, never loaded
    assert any(c == "G006" and f == "assets/box/mesh.ply" for c, f in found), found
    d = Dataset.open(ds)
    d.episode("ep000").table("joint_states")
    with pytest.raises(FormatError):
        d.mesh("box")
    assert not marker.exists()


_FORBIDDEN_CALLS = {
    ("pickle", "load"), ("pickle", "loads"), ("pickle", "Unpickler"), ("marshal", "loads"),
    ("marshal", "load"), ("yaml", "unsafe_load"), ("yaml", "full_load"), ("shelve", "open"),
    ("dill", "load"), ("dill", "loads"), ("pd", "read_pickle"), ("pandas", "read_pickle"),
}  # fmt: skip


def _violations(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
        owner = f.value.id if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) else ""
        kw = {k.arg: k.value for k in node.keywords}
        where = (
            f"{path.relative_to(REPO) if path.is_relative_to(REPO) else path.name}:{node.lineno}"
        )
        if isinstance(f, ast.Name) and name in ("eval", "exec"):
            out.append(f"{where}: {name}()")
        elif (owner, name) in _FORBIDDEN_CALLS:
            out.append(f"{where}: {owner}.{name}()")
        elif owner == "torch" and name == "load":
            wo = kw.get("weights_only")
            if not (isinstance(wo, ast.Constant) and wo.value is True):
                out.append(f"{where}: torch.load without weights_only=True")
        elif owner in ("np", "numpy") and name == "load":
            ap = kw.get("allow_pickle")
            if (
                isinstance(ap, ast.Constant)
                and ap.value is not False
                or (ap is not None and not isinstance(ap, ast.Constant))
            ):
                out.append(f"{where}: np.load with allow_pickle")
        elif owner == "yaml" and name == "load":
            loader = kw.get("Loader")
            text = ast.unparse(loader) if loader is not None else ""
            # yamlio.load_yaml_text takes the loader as an argument and checks it is a SafeLoader
            exempt = path.name == "yamlio.py" and text == "loader"
            if not exempt and not any(k in text for k in ("Safe", "NoAlias", "_OpenCVLoader")):
                out.append(f"{where}: yaml.load with {text or 'the default loader'}")
    return out


def test_no_code_path_unpickles_or_evaluates() -> None:
    files = sorted((REPO / "robogs").rglob("*.py"))
    assert len(files) > 150
    bad = [v for p in files for v in _violations(p)]
    assert not bad, bad


def test_the_static_scan_catches_each_pattern(tmp_path: Path) -> None:
    """Control for the scan above: each forbidden call in a scratch file is reported."""
    src = tmp_path / "probe.py"
    src.write_text(
        "import pickle, torch, numpy as np, yaml\n"
        "pickle.loads(b'')\ntorch.load('x')\ntorch.load('x', weights_only=False)\n"
        "np.load('x', allow_pickle=True)\nyaml.load('a')\neval('1')\nyaml.unsafe_load('a')\n"
        "torch.load('x', weights_only=True)\nnp.load('x')\nyaml.load('a', Loader=yaml.SafeLoader)\n"
    )
    found = _violations(src)
    assert len(found) == 7, found
