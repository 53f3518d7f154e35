"""COLMAP sparse models (text or binary) -> cameras + one static episode.

Formats as in COLMAP ``doc/format.rst`` and ``scripts/python/read_write_model.py``:
``cameras.{txt,bin}`` (model, size, parameters) and ``images.{txt,bin}`` (per image a
world-to-camera pose: Hamilton quaternion ``(qw, qx, qy, qz)`` and translation, OpenCV camera
axes, plus 2D points that are skipped). The binary files are preferred when both exist. COLMAP
puts the centre of the top-left pixel at (0.5, 0.5), as robogs does, so intrinsics are copied.

``T_world_cam = inverse([R(q) | t])``: ``R_wc = R^T``, camera centre ``-R^T t``.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import BinaryIO

import numpy as np

from robogs.format.cameras import CameraModel
from robogs.format.errors import InputError

from ..registry import register_converter
from .calibration import check_distortion
from .capture import View, orient_world, write_static_capture
from .context import IngestContext
from .tf_tree import quat_to_matrix_np

__all__ = ["convert_colmap", "detect_colmap", "read_colmap_model", "model_folder", "COLMAP_MODELS"]

#: model id -> (name, number of parameters)
COLMAP_MODELS: dict[int, tuple[str, int]] = {
    0: ("SIMPLE_PINHOLE", 3),
    1: ("PINHOLE", 4),
    2: ("SIMPLE_RADIAL", 4),
    3: ("RADIAL", 5),
    4: ("OPENCV", 8),
    5: ("OPENCV_FISHEYE", 8),
    6: ("FULL_OPENCV", 12),
    7: ("FOV", 5),
    8: ("SIMPLE_RADIAL_FISHEYE", 4),
    9: ("RADIAL_FISHEYE", 5),
    10: ("THIN_PRISM_FISHEYE", 12),
}
_BY_NAME = {name: (mid, n) for mid, (name, n) in COLMAP_MODELS.items()}
_MAX_COUNT = 10_000_000


def _has_model(p: Path) -> bool:
    return any((p / f"cameras{e}").is_file() for e in (".bin", ".txt")) and any(
        (p / f"images{e}").is_file() for e in (".bin", ".txt")
    )


def model_folder(path: Path) -> Path | None:
    """The folder holding ``cameras``/``images``: ``path``, ``path/sparse/0`` or ``path/sparse``."""
    for p in (path, path / "sparse" / "0", path / "sparse"):
        if p.is_dir() and _has_model(p):
            return p
    return None


def detect_colmap(path: Path) -> bool:
    """A COLMAP project or model folder (``sparse/0`` text or binary)."""
    return path.is_dir() and model_folder(path) is not None


def _camera_from_params(
    cid: int, model: str, w: int, h: int, params: list[float], path: Path
) -> CameraModel:
    where = f"camera {cid}"
    p = [float(v) for v in params]
    n = _BY_NAME.get(model, (None, None))[1]
    if n is None:
        raise InputError(f"unknown COLMAP camera model {model!r}", path=path, where=where)
    if len(p) != n:
        raise InputError(f"{model} needs {n} parameters, got {len(p)}", path=path, where=where)
    if model == "SIMPLE_PINHOLE":
        fx = fy = p[0]
        cx, cy, dm, d = p[1], p[2], "none", []
    elif model == "PINHOLE":
        fx, fy, cx, cy, dm, d = p[0], p[1], p[2], p[3], "none", []
    elif model == "SIMPLE_RADIAL":
        fx = fy = p[0]
        cx, cy, dm, d = p[1], p[2], "plumb_bob", [p[3], 0.0, 0.0, 0.0, 0.0]
    elif model == "RADIAL":
        fx = fy = p[0]
        cx, cy, dm, d = p[1], p[2], "plumb_bob", [p[3], p[4], 0.0, 0.0, 0.0]
    elif model == "OPENCV":
        fx, fy, cx, cy = p[:4]
        dm, d = "plumb_bob", [p[4], p[5], p[6], p[7], 0.0]
    elif model == "FULL_OPENCV":
        fx, fy, cx, cy = p[:4]
        dm, d = "rational_polynomial", p[4:12]
    elif model == "OPENCV_FISHEYE":
        fx, fy, cx, cy = p[:4]
        dm, d = "equidistant", p[4:8]
    else:
        raise InputError(
            f"COLMAP camera model {model} has no robogs equivalent",
            path=path,
            where=where,
            hint="undistort the images with COLMAP (image_undistorter) and convert that model",
        )
    if not any(d):
        dm, d = "none", []
    dm, dd = check_distortion(dm, d, path=path, where=where)
    if fx <= 0 or fy <= 0 or w <= 0 or h <= 0:
        raise InputError("non-positive focal length or image size", path=path, where=where)
    return CameraModel(
        name=f"cam{cid}",
        width=int(w),
        height=int(h),
        fx=fx,
        fy=fy,
        cx=cx,
        cy=cy,
        distortion_model=dm,
        distortion=dd,
    )


def _lines(path: Path) -> list[str]:
    try:
        return path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read COLMAP text file ({exc})", path=path) from None


def _cameras_txt(path: Path) -> dict[int, CameraModel]:
    out: dict[int, CameraModel] = {}
    for n, line in enumerate(_lines(path), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        try:
            cid, model, w, h = int(parts[0]), parts[1], int(parts[2]), int(parts[3])
            params = [float(v) for v in parts[4:]]
        except (IndexError, ValueError):
            raise InputError("malformed camera line", path=path, where=f"line {n}") from None
        out[cid] = _camera_from_params(cid, model, w, h, params, path)
    return out


def _images_txt(path: Path) -> list[tuple[str, int, np.ndarray, np.ndarray]]:
    out = []
    lines = _lines(path)
    i = 0
    while i < len(lines):
        s = lines[i].strip()
        i += 1
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        try:
            q = np.array([float(v) for v in parts[1:5]])
            t = np.array([float(v) for v in parts[5:8]])
            cid = int(parts[8])
            name = " ".join(parts[9:])
        except (IndexError, ValueError):
            raise InputError("malformed image line", path=path, where=f"line {i}") from None
        if not name:
            raise InputError("image line without a name", path=path, where=f"line {i}")
        out.append((name, cid, q, t))
        i += 1  # the POINTS2D line that follows (possibly empty)
    return out


class _Bin:
    def __init__(self, fh: BinaryIO, path: Path, size: int) -> None:
        self.fh, self.path, self.size = fh, path, size

    def read(self, fmt: str) -> tuple:
        n = struct.calcsize(fmt)
        data = self.fh.read(n)
        if len(data) != n:
            raise InputError(
                "COLMAP binary file is truncated", path=self.path, where=f"byte {self.fh.tell()}"
            )
        return struct.unpack(fmt, data)

    def count(self) -> int:
        (n,) = self.read("<Q")
        if n > _MAX_COUNT:
            raise InputError(
                f"implausible count {n}", path=self.path, where=f"byte {self.fh.tell() - 8}"
            )
        return n

    def cstring(self) -> str:
        buf = bytearray()
        while True:
            c = self.fh.read(1)
            if not c:
                raise InputError("COLMAP binary file is truncated (image name)", path=self.path)
            if c == b"\x00":
                break
            buf += c
            if len(buf) > 4096:
                raise InputError("image name too long", path=self.path)
        return buf.decode("utf-8", errors="replace")

    def skip(self, n: int) -> None:
        if self.fh.tell() + n > self.size:
            raise InputError("COLMAP binary file is truncated (points2D)", path=self.path)
        self.fh.seek(n, 1)


def _open_bin(path: Path) -> tuple[BinaryIO, _Bin]:
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise InputError(f"cannot open ({exc.strerror})", path=path) from None
    return fh, _Bin(fh, path, path.stat().st_size)


def _cameras_bin(path: Path) -> dict[int, CameraModel]:
    fh, b = _open_bin(path)
    with fh:
        out: dict[int, CameraModel] = {}
        for _ in range(b.count()):
            cid, mid, w, h = b.read("<iiQQ")
            if mid not in COLMAP_MODELS:
                raise InputError(
                    f"unknown COLMAP camera model id {mid}", path=path, where=f"camera {cid}"
                )
            name, n = COLMAP_MODELS[mid]
            out[cid] = _camera_from_params(cid, name, int(w), int(h), list(b.read(f"<{n}d")), path)
        return out


def _images_bin(path: Path) -> list[tuple[str, int, np.ndarray, np.ndarray]]:
    fh, b = _open_bin(path)
    with fh:
        out = []
        for _ in range(b.count()):
            vals = b.read("<I7di")
            name = b.cstring()
            npts = b.count()
            b.skip(24 * npts)
            out.append((name, int(vals[8]), np.array(vals[1:5]), np.array(vals[5:8])))
        return out


def _points_count(folder: Path) -> int | None:
    if (folder / "points3D.bin").is_file():
        with open(folder / "points3D.bin", "rb") as fh:
            data = fh.read(8)
        return struct.unpack("<Q", data)[0] if len(data) == 8 else None
    if (folder / "points3D.txt").is_file():
        return sum(
            1 for ln in _lines(folder / "points3D.txt") if ln.strip() and not ln.startswith("#")
        )
    return None


def read_colmap_model(folder: Path, images: Path) -> list[View]:
    """Views of a COLMAP model (binary preferred), poses as OpenCV ``T_world_cam``.

    Raises:
        InputError: malformed or truncated files, unknown cameras or models.
    """
    cams = (
        _cameras_bin(folder / "cameras.bin")
        if (folder / "cameras.bin").is_file()
        else _cameras_txt(folder / "cameras.txt")
    )
    ipath = folder / "images.bin" if (folder / "images.bin").is_file() else folder / "images.txt"
    imgs = _images_bin(ipath) if ipath.suffix == ".bin" else _images_txt(ipath)
    views = []
    for name, cid, q, t in imgs:
        if cid not in cams:
            raise InputError(
                f"image {name!r} uses camera {cid}, which is not in the cameras file", path=ipath
            )
        if not np.all(np.isfinite(q)) or not np.all(np.isfinite(t)) or np.linalg.norm(q) < 1e-12:
            raise InputError(f"image {name!r} has a non-finite or zero pose", path=ipath)
        R = quat_to_matrix_np(q)  # world -> camera
        T = np.eye(4)
        T[:3, :3] = R.T
        T[:3, 3] = -R.T @ t
        views.append(View(name, images / name, cams[cid], T))
    return views


def convert_colmap(src: Path, ctx: IngestContext) -> None:
    """Convert a COLMAP capture (model folder + images)."""
    folder = model_folder(src)
    if folder is None:
        raise InputError("no COLMAP model (cameras + images) here", path=src)
    if ctx.options.images is not None:
        images = ctx.options.images
    else:
        project = (
            src
            if folder != src
            else (folder.parent.parent if folder.parent.name == "sparse" else folder.parent)
        )
        images = project / "images"
    views = read_colmap_model(folder, images)
    prov = ctx.provenance
    prov.extra.update(
        {"capture": "colmap", "model": "binary" if (folder / "images.bin").is_file() else "text"}
    )
    pts = _points_count(folder)
    if pts is not None:
        prov.note(f"points3D ({pts} points) not converted: the format has no sparse point cloud")
    if (folder / "rigs.txt").is_file() or (folder / "frames.txt").is_file():
        prov.note("rigs/frames (COLMAP rig model) not converted; per-image poses are used")
    orient_world(
        ctx,
        views,
        "world frame kept as in the COLMAP model (arbitrary origin, orientation and scale)",
    )
    write_static_capture(ctx, views, source=_images_name(folder))


def _images_name(folder: Path) -> str:
    return "images.bin" if (folder / "images.bin").is_file() else "images.txt"


register_converter(
    "colmap",
    detect_colmap,
    convert_colmap,
    description="COLMAP sparse model (text or binary)",
    priority=80,
)
