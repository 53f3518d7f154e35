"""Static captures: a known 3D point must land on its known pixel in every converted view.

Each synthetic view is built backwards from the pixel: choose the pixel (u, v), a depth and a
random camera rotation, then place the camera so that the world point X is seen there. The
COLMAP files store world-to-camera poses, the nerfstudio file camera-to-world poses with OpenGL
axes; the converted dataset must reproduce (u, v) to 1e-6 px with robogs' conventions.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq
import pytest

from robogs.convert.ingest import ConvertOptions, convert_path
from robogs.convert.registry import detect_format
from robogs.format.errors import InputError
from robogs.format.validate import validate

X = np.array([0.3, -0.2, 0.5])
W, H = 80, 60
INTR = [(70.0, 72.0, 40.3, 29.8), (55.0, 55.0, 39.0, 31.0)]


def _rot(rng: np.random.Generator) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def _views(n: int = 5, seed: int = 0) -> list[dict]:
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        fx, fy, cx, cy = INTR[i % 2]
        u, v, d = rng.uniform(5, W - 5), rng.uniform(5, H - 5), rng.uniform(0.5, 3.0)
        R_wc = _rot(rng)  # camera (OpenCV axes) to world
        ray = np.array([(u - cx) / fx, (v - cy) / fy, 1.0]) * d
        C = X - R_wc @ ray
        out.append(
            {
                "name": f"img_{i:03d}.png",
                "cam": i % 2 + 1,
                "u": u,
                "v": v,
                "R_wc": R_wc,
                "C": C,
                "K": (fx, fy, cx, cy),
            }
        )
    return out


def _images(folder: Path, views: list[dict]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for i, v in enumerate(views):
        img = np.full((H, W, 3), 40 * i % 255, np.uint8)
        cv2.imwrite(str(folder / v["name"]), img)


def _qvec(R: np.ndarray) -> np.ndarray:
    w = np.sqrt(max(0.0, 1 + np.trace(R))) / 2
    if w > 1e-3:
        return np.array(
            [
                w,
                (R[2, 1] - R[1, 2]) / (4 * w),
                (R[0, 2] - R[2, 0]) / (4 * w),
                (R[1, 0] - R[0, 1]) / (4 * w),
            ]
        )
    raise AssertionError("test rotation too close to a half turn; change the seed")


def _colmap_text(model: Path, views: list[dict]) -> None:
    model.mkdir(parents=True)
    cams = [
        "# Camera list",
        *(
            f"{k + 1} PINHOLE {W} {H} {fx!r} {fy!r} {cx!r} {cy!r}"
            for k, (fx, fy, cx, cy) in enumerate(INTR)
        ),
    ]
    (model / "cameras.txt").write_text("\n".join(cams) + "\n")
    lines = ["# Image list with two lines of data per image:"]
    for i, v in enumerate(views):
        R_cw = v["R_wc"].T
        t = -R_cw @ v["C"]
        q = _qvec(R_cw)
        lines.append(
            " ".join(repr(float(x)) for x in [*q, *t]).join(
                [f"{i + 1} ", f" {v['cam']} {v['name']}"]
            )
        )
        lines.append("" if i % 2 else "12.5 7.25 -1")  # POINTS2D lines, some empty
    (model / "images.txt").write_text("\n".join(lines) + "\n")
    (model / "points3D.txt").write_text("# 3D point list\n1 0.3 -0.2 0.5 255 0 0 0.1 1 0\n")


def _colmap_binary(model: Path, views: list[dict]) -> None:
    model.mkdir(parents=True)
    with open(model / "cameras.bin", "wb") as fh:
        fh.write(struct.pack("<Q", len(INTR)))
        for k, intr in enumerate(INTR):
            fh.write(struct.pack("<iiQQ", k + 1, 1, W, H) + struct.pack("<4d", *intr))
    with open(model / "images.bin", "wb") as fh:
        fh.write(struct.pack("<Q", len(views)))
        for i, v in enumerate(views):
            R_cw = v["R_wc"].T
            t = -R_cw @ v["C"]
            fh.write(
                struct.pack("<I7di", i + 1, *_qvec(R_cw), *t, v["cam"])
                + v["name"].encode()
                + b"\x00"
            )
            fh.write(struct.pack("<Q", 2) + struct.pack("<ddq", 1.0, 2.0, -1) * 2)


def _projections(ds, world: np.ndarray) -> dict[str, tuple[float, float]]:
    """Pixel of X (re-expressed by ``world``) in every view, read back through the dataset."""
    ep = ds.episode()
    out = {}
    for cam_name, st in ep.camera_streams.items():
        cam = ds.camera(cam_name)
        ext = pq.read_table(ds.resolve(st["extrinsics"])).to_pydict()
        frames = ep.frames(cam_name).to_pydict()
        assert frames["t_ns"] == ext["t_ns"]
        for k, t in enumerate(ext["t_ns"]):
            from robogs.convert.ingest.tf_tree import pose_to_matrix

            T = pose_to_matrix(
                np.array([ext[c][k] for c in "xyz"]),
                np.array([ext[c][k] for c in ("qw", "qx", "qy", "qz")]),
            )
            Xw = world @ np.append(X, 1.0)
            p = np.linalg.inv(T) @ Xw
            out[t] = (cam.fx * p[0] / p[2] + cam.cx, cam.fy * p[1] / p[2] + cam.cy)
    return out


def _check(ds, views: list[dict], world: np.ndarray | None = None) -> None:
    proj = _projections(ds, np.eye(4) if world is None else world)
    assert sorted(proj) == list(range(len(views)))  # t_ns = view ordinal
    for i, v in enumerate(views):
        u, w = proj[i]
        assert abs(u - v["u"]) < 1e-6 and abs(w - v["v"]) < 1e-6, (i, u, v["u"], w, v["v"])


@pytest.mark.parametrize("kind", ["text", "binary"])
def test_colmap_reprojects_known_point(tmp_path: Path, kind: str) -> None:
    views = _views()
    (_colmap_text if kind == "text" else _colmap_binary)(tmp_path / "proj" / "sparse" / "0", views)
    _images(tmp_path / "proj" / "images", views)
    assert detect_format(tmp_path / "proj").name == "colmap"
    ds = convert_path(tmp_path / "proj", tmp_path / "out")
    assert ds.camera_names == ["cam1", "cam2"]
    c1 = ds.camera("cam1")
    assert (c1.fx, c1.fy, c1.cx, c1.cy, c1.distortion_model) == (*INTR[0], "none")
    assert c1.extrinsics == "time_varying" and c1.T_world_cam is None
    _check(ds, views)
    assert len(list(ds.episode().iter_video("cam1"))) == 3
    assert [f for f in validate(tmp_path / "out").findings if f.severity == "error"] == []


def _nerfstudio(folder: Path, views: list[dict], per_frame: bool) -> None:
    frames = []
    for v in views:
        M = np.eye(4)
        M[:3, :3] = v["R_wc"] @ np.diag([1.0, -1.0, -1.0])  # OpenGL camera axes
        M[:3, 3] = v["C"]
        fr = {"file_path": f"images/{v['name']}", "transform_matrix": M.tolist()}
        if per_frame:
            fx, fy, cx, cy = v["K"]
            fr.update(fl_x=fx, fl_y=fy, cx=cx, cy=cy, w=W, h=H)
        frames.append(fr)
    doc: dict = {"camera_model": "OPENCV", "frames": frames}
    if not per_frame:
        fx, fy, cx, cy = INTR[0]
        doc.update(fl_x=fx, fl_y=fy, cx=cx, cy=cy, w=W, h=H, k1=0.0, k2=0.0, p1=0.0, p2=0.0)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "transforms.json").write_text(json.dumps(doc))
    _images(folder / "images", views)


def test_nerfstudio_reprojects_known_point(tmp_path: Path) -> None:
    views = _views(seed=1)
    _nerfstudio(tmp_path / "ns", views, per_frame=True)
    assert detect_format(tmp_path / "ns").name == "nerfstudio"
    ds = convert_path(tmp_path / "ns", tmp_path / "out")
    assert ds.camera_names == ["cam0", "cam1"]
    _check(ds, views)
    assert any("world frame kept" in n for n in ds.manifest["provenance"]["notes"])
    assert [f for f in validate(tmp_path / "out").findings if f.severity == "error"] == []


def test_nerfstudio_world_up(tmp_path: Path) -> None:
    views = [dict(v, K=INTR[0]) for v in _views(seed=2)]
    for v in views:  # one intrinsics for all views: rebuild the poses for INTR[0]
        fx, fy, cx, cy = INTR[0]
        v["C"] = X - v["R_wc"] @ (np.array([(v["u"] - cx) / fx, (v["v"] - cy) / fy, 1.0]) * 1.5)
    _nerfstudio(tmp_path / "ns", views, per_frame=False)
    ds = convert_path(
        tmp_path / "ns" / "transforms.json", tmp_path / "out", options=ConvertOptions(world_up="+y")
    )
    T_up = np.eye(4)
    T_up[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # y-up -> z-up: (x, y, z) -> (x, -z, y)
    _check(ds, views, world=T_up)


def test_capture_errors(tmp_path: Path) -> None:
    views = _views(n=2)
    _colmap_text(tmp_path / "p" / "sparse" / "0", views)
    with pytest.raises(InputError, match="image file not found"):
        convert_path(tmp_path / "p", tmp_path / "out")  # no images folder
    _images(tmp_path / "p" / "images", views)
    (tmp_path / "p" / "sparse" / "0" / "cameras.txt").write_text("1 PINHOLE 80 60 70 72 40\n")
    with pytest.raises(InputError, match="PINHOLE needs 4 parameters, got 3"):
        convert_path(tmp_path / "p", tmp_path / "out")
    _colmap_binary(tmp_path / "b" / "sparse" / "0", views)
    data = (tmp_path / "b" / "sparse" / "0" / "images.bin").read_bytes()
    (tmp_path / "b" / "sparse" / "0" / "images.bin").write_bytes(data[:100])
    with pytest.raises(InputError, match="truncated"):
        convert_path(tmp_path / "b", tmp_path / "out")
    assert not (tmp_path / "out").exists()
