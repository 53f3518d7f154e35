"""Protobuf channels in MCAP: Foxglove schemas mapped onto dataset streams.

The ``FileDescriptorSet`` of each schema is built here with ``descriptor_pb2`` (Foxglove's
message layouts, https://docs.foxglove.dev/docs/visualization/message-schemas), and the messages
are encoded by a small wire-format encoder of this file, so nothing on the writing side goes
through the protobuf runtime that the reader uses.
"""

from __future__ import annotations

import struct
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq
import pytest

from robogs.convert.ingest import convert_path
from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.protobuf_schema import protobuf_decoder

T0 = 1_700_000_000_000_000_000

# ----------------------------------------------------------------------------- descriptors

_T = {  # descriptor_pb2.FieldDescriptorProto.Type
    "double": 1, "fixed32": 7, "string": 9, "message": 11, "bytes": 12,
}  # fmt: skip
# message -> [(field, number, type, repeated, message type)]
_MESSAGES = {
    "Vector3": [("x", 1, "double"), ("y", 2, "double"), ("z", 3, "double")],
    "Quaternion": [("x", 1, "double"), ("y", 2, "double"), ("z", 3, "double"), ("w", 4, "double")],
    "Pose": [("position", 1, ".foxglove.Vector3"), ("orientation", 2, ".foxglove.Quaternion")],
    "CompressedImage": [
        ("timestamp", 1, ".google.protobuf.Timestamp"), ("frame_id", 4, "string"),
        ("data", 2, "bytes"), ("format", 3, "string"),
    ],
    "RawImage": [
        ("timestamp", 1, ".google.protobuf.Timestamp"), ("frame_id", 7, "string"),
        ("width", 2, "fixed32"), ("height", 3, "fixed32"), ("encoding", 4, "string"),
        ("step", 5, "fixed32"), ("data", 6, "bytes"),
    ],
    "CameraCalibration": [
        ("timestamp", 1, ".google.protobuf.Timestamp"), ("frame_id", 9, "string"),
        ("width", 2, "fixed32"), ("height", 3, "fixed32"), ("distortion_model", 4, "string"),
        ("D", 5, "double*"), ("K", 6, "double*"), ("R", 7, "double*"), ("P", 8, "double*"),
    ],
    "FrameTransform": [
        ("timestamp", 1, ".google.protobuf.Timestamp"), ("parent_frame_id", 2, "string"),
        ("child_frame_id", 3, "string"), ("translation", 4, ".foxglove.Vector3"),
        ("rotation", 5, ".foxglove.Quaternion"),
    ],
    "FrameTransforms": [("transforms", 1, ".foxglove.FrameTransform*")],
    "PoseInFrame": [
        ("timestamp", 1, ".google.protobuf.Timestamp"), ("frame_id", 2, "string"),
        ("pose", 3, ".foxglove.Pose"),
    ],
    "Log": [("timestamp", 1, ".google.protobuf.Timestamp"), ("message", 3, "string")],
}  # fmt: skip
_DEPS = {
    "Pose": ["Vector3", "Quaternion"],
    "FrameTransform": ["Vector3", "Quaternion"],
    "FrameTransforms": ["FrameTransform"],
    "PoseInFrame": ["Pose"],
}


def _file(name: str) -> object:
    from google.protobuf import descriptor_pb2

    fd = descriptor_pb2.FileDescriptorProto(name=f"foxglove/{name}.proto", package="foxglove")
    fd.syntax = "proto3"
    msg = fd.message_type.add(name=name)
    uses_ts = False
    for fname, num, typ in _MESSAGES[name]:
        repeated = typ.endswith("*")
        typ = typ.rstrip("*")
        f = msg.field.add(name=fname, number=num)
        f.label = 3 if repeated else 1
        if typ.startswith("."):
            f.type = _T["message"]
            f.type_name = typ
            uses_ts |= typ == ".google.protobuf.Timestamp"
        else:
            f.type = _T[typ]
    if uses_ts:
        fd.dependency.append("google/protobuf/timestamp.proto")
    fd.dependency.extend(f"foxglove/{d}.proto" for d in _DEPS.get(name, []))
    return fd


def schema_bytes(name: str, *, with_timestamp: bool = True) -> bytes:
    """Serialized FileDescriptorSet of ``foxglove.<name>`` and its imports (deps last)."""
    from google.protobuf import descriptor_pb2

    order: list[str] = []

    def visit(n: str) -> None:
        for d in _DEPS.get(n, []):
            visit(d)
        if n not in order:
            order.append(n)

    visit(name)
    fds = descriptor_pb2.FileDescriptorSet()
    for n in reversed(order):  # the reader must sort out dependency order itself
        fds.file.append(_file(n))
    if with_timestamp:
        ts = descriptor_pb2.FileDescriptorProto(
            name="google/protobuf/timestamp.proto", package="google.protobuf", syntax="proto3"
        )
        m = ts.message_type.add(name="Timestamp")
        m.field.add(name="seconds", number=1, type=3, label=1)  # int64
        m.field.add(name="nanos", number=2, type=5, label=1)  # int32
        fds.file.append(ts)
    return fds.SerializeToString()


# ----------------------------------------------------------------------------- wire format


def _varint(n: int) -> bytes:
    out = bytearray()
    n &= (1 << 64) - 1
    while True:
        b = n & 0x7F
        n >>= 7
        out.append(b | (0x80 if n else 0))
        if not n:
            return bytes(out)


def enc(name: str, **values: object) -> bytes:
    """Encode a message of ``_MESSAGES[name]`` (dict values for sub-messages)."""
    out = bytearray()
    for fname, num, typ in _MESSAGES[name]:
        if fname not in values:
            continue
        v = values[fname]
        repeated = typ.endswith("*")
        typ = typ.rstrip("*")
        items = v if repeated else [v]
        if typ == "double" and repeated:  # packed
            body = b"".join(struct.pack("<d", float(x)) for x in items)
            out += _varint(num << 3 | 2) + _varint(len(body)) + body
            continue
        for x in items:
            if typ == "double":
                out += _varint(num << 3 | 1) + struct.pack("<d", float(x))
            elif typ == "fixed32":
                out += _varint(num << 3 | 5) + struct.pack("<I", int(x))
            elif typ in ("string", "bytes"):
                b = x.encode() if isinstance(x, str) else bytes(x)
                out += _varint(num << 3 | 2) + _varint(len(b)) + b
            elif typ == ".google.protobuf.Timestamp":
                b = _varint(1 << 3) + _varint(x // 10**9) + _varint(2 << 3) + _varint(x % 10**9)
                out += _varint(num << 3 | 2) + _varint(len(b)) + b
            else:
                b = enc(typ.rsplit(".", 1)[1], **x)
                out += _varint(num << 3 | 2) + _varint(len(b)) + b
    return bytes(out)


def _xyz(v: np.ndarray) -> dict[str, float]:
    return dict(zip("xyz", map(float, v), strict=True))


def _q(yaw: float) -> dict[str, float]:
    return {"x": 0.0, "y": 0.0, "z": float(np.sin(yaw / 2)), "w": float(np.cos(yaw / 2))}


# ----------------------------------------------------------------------------- the file


def _write(path: Path) -> dict[str, object]:
    from mcap.writer import Writer

    n, dt = 6, 50_000_000
    stamps = [T0 + 10_000_000 + k * dt for k in range(n)]
    box = {t: (np.array([0.3 + 0.01 * k, -0.1, 0.02]), 0.2 * k) for k, t in enumerate(stamps)}
    mug = {t: (np.array([0.5, 0.2 + 0.02 * k, 0.0]), -0.1 * k) for k, t in enumerate(stamps)}
    rig = {t: 0.05 * k for k, t in enumerate(stamps)}
    images = {t: np.full((16, 24, 3), 40 + 30 * k, np.uint8) for k, t in enumerate(stamps)}
    raw = {t: np.random.default_rng(k).integers(0, 255, (8, 10, 3), np.uint8) for k, t in enumerate(stamps)}  # fmt: skip
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="", library="test")
        ch = {}
        for topic, name in (
            ("/cam0/image", "CompressedImage"),
            ("/cam0/camera_info", "CameraCalibration"),
            ("/cam1/image", "RawImage"),
            ("/tf", "FrameTransforms"),
            ("/tf_static", "FrameTransform"),
            ("/mug/pose", "PoseInFrame"),
            ("/log", "Log"),
        ):
            sid = w.register_schema(f"foxglove.{name}", "protobuf", schema_bytes(name))
            ch[topic] = w.register_channel(topic, "protobuf", sid)
        static = enc(
            "FrameTransform", timestamp=T0, parent_frame_id="rig", child_frame_id="cam0_optical",
            translation=_xyz(np.array([1.0, 0.0, 0.5])), rotation=_q(0.3),
        )  # fmt: skip
        w.add_message(ch["/tf_static"], log_time=T0, publish_time=T0, data=static)
        for k, t in enumerate(stamps):
            tfs = [
                {"timestamp": t, "parent_frame_id": "world", "child_frame_id": "box",
                 "translation": _xyz(box[t][0]), "rotation": _q(box[t][1])},
                {"timestamp": t, "parent_frame_id": "world", "child_frame_id": "rig",
                 "translation": _xyz(np.zeros(3)), "rotation": _q(rig[t])},
            ]  # fmt: skip
            ok, png = cv2.imencode(".png", cv2.cvtColor(images[t], cv2.COLOR_RGB2BGR))
            assert ok
            msgs = [
                ("/tf", enc("FrameTransforms", transforms=tfs)),
                ("/cam0/image", enc("CompressedImage", timestamp=t, frame_id="cam0_optical",
                                    data=png.tobytes(), format="png")),
                ("/cam0/camera_info", enc(
                    "CameraCalibration", timestamp=t, frame_id="cam0_optical", width=24,
                    height=16, distortion_model="plumb_bob", D=[0.0] * 5,
                    K=[20.0, 0.0, 11.5, 0.0, 21.0, 7.5, 0.0, 0.0, 1.0],
                    R=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], P=[0.0] * 12)),
                ("/cam1/image", enc("RawImage", timestamp=t, frame_id="cam1", width=10, height=8,
                                    encoding="rgb8", step=30, data=raw[t].tobytes())),
                ("/mug/pose", enc("PoseInFrame", timestamp=t, frame_id="world",
                                  pose={"position": _xyz(mug[t][0]), "orientation": _q(mug[t][1])})),
                ("/log", enc("Log", timestamp=t, message=f"step {k}")),
            ]  # fmt: skip
            for j, (topic, data) in enumerate(msgs):
                log = t + 1_000_000 + j
                w.add_message(ch[topic], log_time=log, publish_time=log, data=data)
        w.finish()
    return {"stamps": stamps, "box": box, "mug": mug, "rig": rig, "images": images, "raw": raw}


def _yaw_pose(row: dict[str, float]) -> tuple[np.ndarray, float]:
    assert abs(row["qx"]) < 1e-12 and abs(row["qy"]) < 1e-12
    return np.array([row["x"], row["y"], row["z"]]), 2 * np.arctan2(row["qz"], row["qw"])


def test_foxglove_protobuf_channels_become_streams(tmp_path: Path) -> None:
    src = tmp_path / "fox.mcap"
    sc = _write(src)
    stamps = sc["stamps"]
    ds = convert_path(src, tmp_path / "out", options=ConvertOptions())
    ep = ds.episode()
    assert sorted(ep.streams) == ["camera/cam0", "camera/cam1", "object_poses", "streams/log"]
    # CompressedImage + CameraCalibration
    assert ep.frames("cam0").column("t_ns").to_pylist() == stamps
    frames = list(ep.iter_video("cam0"))
    for k, t in enumerate(stamps):
        assert np.abs(frames[k].astype(float) - sc["images"][t]).mean() < 6.0  # video codec
    cam = ds.camera("cam0")
    assert (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy) == (
        24,
        16,
        20.0,
        21.0,
        12.0,
        8.0,
    )
    # FrameTransforms on /tf: the camera hangs from the turning rig (time-varying extrinsics)
    ext = pq.read_table(ds.resolve(ep.streams["camera/cam0"]["extrinsics"])).to_pylist()
    assert [r["t_ns"] for r in ext] == stamps
    for r in ext:
        p, yaw = _yaw_pose(r)
        a = sc["rig"][r["t_ns"]]
        np.testing.assert_allclose(p, [np.cos(a), np.sin(a), 0.5], atol=1e-12)
        assert yaw == pytest.approx(a + 0.3, abs=1e-12)
    # RawImage
    assert ep.frames("cam1").column("t_ns").to_pylist() == stamps
    # PoseInFrame and the moving tf frame "box" as objects
    poses = pq.read_table(ds.resolve(ep.streams["object_poses"]["path"])).to_pylist()
    assert sorted({r["object"] for r in poses}) == ["box", "mug"]
    for name in ("box", "mug"):
        rows = [r for r in poses if r["object"] == name]
        assert [r["t_ns"] for r in rows] == stamps
        for r in rows:
            p, yaw = _yaw_pose(r)
            want_p, want_yaw = sc[name][r["t_ns"]]
            np.testing.assert_allclose(p, want_p, atol=1e-12)
            assert yaw == pytest.approx(want_yaw, abs=1e-12)
    prov = ds.manifest["provenance"]
    assert prov["topics"]["/log"]["role"] == "generic"  # no role: decoded into a generic table
    assert prov["topics"]["/log"]["written"] == 6 and "dropped" not in prov["topics"]["/log"]
    log = pq.read_table(ds.resolve(ep.streams["streams/log"]["path"]))
    assert log.column("message").to_pylist() == [f"step {k}" for k in range(6)]
    assert prov["topics"]["/cam0/image"]["stamp_source"] == "sensor_header"
    assert "undecodable" not in prov


def test_decoder_errors_are_named() -> None:
    with pytest.raises(ValueError, match="not a FileDescriptorSet"):
        protobuf_decoder("foxglove.Log", b"\xff\xff\xff")
    with pytest.raises(ValueError, match="has no message 'foxglove.Nope'"):
        protobuf_decoder("foxglove.Nope", schema_bytes("Log"))
    # a writer that left out the well-known Timestamp file: taken from the runtime
    dec = protobuf_decoder("foxglove.Log", schema_bytes("Log", with_timestamp=False))
    msg = dec(enc("Log", timestamp=T0 + 5, message="hi"))
    assert (msg.timestamp.seconds, msg.timestamp.nanos, msg.message) == (T0 // 10**9, 5, "hi")
    from google.protobuf import descriptor_pb2

    fds = descriptor_pb2.FileDescriptorSet.FromString(schema_bytes("Pose", with_timestamp=False))
    assert fds.file[-1].name == "foxglove/Vector3.proto"
    del fds.file[-1]
    with pytest.raises(ValueError, match="lacks the imported file"):
        protobuf_decoder("foxglove.Pose", fds.SerializeToString())
