"""nerfstudio ``transforms.json`` captures -> cameras + one static episode.

Conventions (nerfstudio ``docs/quickstart/data_conventions.md``): ``transform_matrix`` is the
camera-to-world pose with OpenGL/Blender camera axes (x right, y up, z back). robogs cameras use
OpenCV axes, so ``T_world_cam = c2w @ diag(1, -1, -1, 1)`` (flip the camera's y and z). The
intrinsics (``fl_x, fl_y, cx, cy`` in px, pixel centres at +0.5, as in COLMAP) are taken as
they are. ``camera_angle_x`` (instant-ngp) gives ``fl_x = w / (2 tan(angle / 2))``.

nerfstudio's world frame is whatever the capture pipeline produced (often COLMAP's, re-oriented
and re-scaled by ``ns-process-data``). It is kept as given and recorded in the provenance, or
rotated so that ``--world-up`` becomes +z.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from robogs.format.cameras import CameraModel
from robogs.format.errors import InputError

from ..registry import register_converter
from .calibration import check_distortion
from .capture import View, orient_world, write_static_capture
from .context import IngestContext

__all__ = ["convert_nerfstudio", "detect_nerfstudio", "read_transforms", "T_GL_TO_CV"]

#: right-multiply an OpenGL-axes camera pose to get the OpenCV-axes pose
T_GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])
_MAX_BYTES = 256 << 20
_INTR = (
    "fl_x",
    "fl_y",
    "cx",
    "cy",
    "w",
    "h",
    "k1",
    "k2",
    "k3",
    "k4",
    "p1",
    "p2",
    "camera_angle_x",
    "camera_angle_y",
)


def _transforms_file(path: Path) -> Path | None:
    if path.is_file() and path.suffix.lower() == ".json" and path.name.startswith("transforms"):
        return path
    if path.is_dir() and (path / "transforms.json").is_file():
        return path / "transforms.json"
    return None


def detect_nerfstudio(path: Path) -> bool:
    """A ``transforms*.json`` file or a folder holding ``transforms.json``."""
    return _transforms_file(path) is not None


def _num(d: dict[str, Any], key: str, path: Path, where: str) -> float:
    v = d.get(key)
    if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(float(v)):
        raise InputError(f"{key!r} must be a finite number", path=path, where=where)
    return float(v)


def _camera(d: dict[str, Any], model: str, path: Path, where: str, name: str) -> CameraModel:
    try:
        w, h = int(d["w"]), int(d["h"])
    except (KeyError, TypeError, ValueError):
        raise InputError(
            "intrinsics need 'w' and 'h' (image size in px)", path=path, where=where
        ) from None
    if "fl_x" in d:
        fx = _num(d, "fl_x", path, where)
    elif "camera_angle_x" in d:
        fx = 0.5 * w / math.tan(0.5 * _num(d, "camera_angle_x", path, where))
    else:
        raise InputError("intrinsics need 'fl_x' or 'camera_angle_x'", path=path, where=where)
    if "fl_y" in d:
        fy = _num(d, "fl_y", path, where)
    elif "camera_angle_y" in d:
        fy = 0.5 * h / math.tan(0.5 * _num(d, "camera_angle_y", path, where))
    else:
        fy = fx
    cx = _num(d, "cx", path, where) if "cx" in d else w / 2.0
    cy = _num(d, "cy", path, where) if "cy" in d else h / 2.0
    k = {n: float(d.get(n, 0.0) or 0.0) for n in ("k1", "k2", "k3", "k4", "p1", "p2")}
    m = model.upper()
    if m == "OPENCV_FISHEYE":
        dm, dist = check_distortion(
            "equidistant", [k["k1"], k["k2"], k["k3"], k["k4"]], path=path, where=where
        )
    elif m in ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE", ""):
        coeffs = [k["k1"], k["k2"], k["p1"], k["p2"], k["k3"]]
        if k["k4"]:
            raise InputError("k4 is set for a non-fisheye camera", path=path, where=where)
        dm, dist = ("plumb_bob", tuple(coeffs)) if any(coeffs) else ("none", ())
    else:
        raise InputError(
            f"unsupported camera_model {model!r}",
            path=path,
            where=where,
            hint="supported: OPENCV, OPENCV_FISHEYE, PINHOLE",
        )
    if fx <= 0 or fy <= 0 or w <= 0 or h <= 0:
        raise InputError("focal lengths and image size must be positive", path=path, where=where)
    return CameraModel(
        name=name,
        width=w,
        height=h,
        fx=fx,
        fy=fy,
        cx=cx,
        cy=cy,
        distortion_model=dm,
        distortion=dist,
    )


def _image_path(rel: str, base: Path, images: Path | None, path: Path, where: str) -> Path:
    if not isinstance(rel, str) or not rel:
        raise InputError("frame has no file_path", path=path, where=where)
    p = (images / Path(rel).name) if images is not None else (base / rel)
    if not p.suffix and not p.exists():
        for ext in (".png", ".jpg", ".jpeg"):
            if p.with_suffix(ext).exists():
                return p.with_suffix(ext)
    return p


def read_transforms(path: Path, *, images: Path | None = None) -> tuple[list[View], dict[str, Any]]:
    """Parse ``transforms.json`` into views (OpenCV ``T_world_cam``, source world kept).

    Returns:
        ``(views, extra)``: ``extra`` holds ``applied_transform`` and other world facts.

    Raises:
        InputError: malformed JSON, missing intrinsics, bad matrices.
    """
    try:
        if path.stat().st_size > _MAX_BYTES:
            raise InputError("transforms.json is too large", path=path)
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"cannot read transforms.json ({exc.strerror})", path=path) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"transforms.json is not valid JSON ({exc})", path=path) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("frames"), list):
        raise InputError("transforms.json needs a 'frames' list", path=path)
    model = str(doc.get("camera_model", "OPENCV"))
    base = path.parent
    cams: dict[tuple, str] = {}
    views: list[View] = []
    for i, fr in enumerate(doc["frames"]):
        where = f"frames[{i}]"
        if not isinstance(fr, dict):
            raise InputError("frame is not an object", path=path, where=where)
        intr = {k: doc[k] for k in _INTR if k in doc}
        intr.update({k: fr[k] for k in _INTR if k in fr})
        cam = _camera(intr, model, path, where, "cam0")
        key = (
            cam.width,
            cam.height,
            cam.fx,
            cam.fy,
            cam.cx,
            cam.cy,
            cam.distortion_model,
            cam.distortion,
        )
        name = cams.setdefault(key, f"cam{len(cams)}")
        cam = replace(cam, name=name)
        try:
            M = np.asarray(fr["transform_matrix"], dtype=np.float64)
        except (KeyError, TypeError, ValueError):
            raise InputError(
                "frame has no numeric transform_matrix", path=path, where=where
            ) from None
        if M.shape == (3, 4):
            M = np.vstack([M, [0.0, 0.0, 0.0, 1.0]])
        if M.shape != (4, 4) or not np.all(np.isfinite(M)):
            raise InputError(
                f"transform_matrix must be 4x4 (or 3x4), is {M.shape}", path=path, where=where
            )
        R = M[:3, :3]
        if abs(np.linalg.det(R) - 1.0) > 1e-3 or np.abs(R.T @ R - np.eye(3)).max() > 1e-3:
            raise InputError(
                "transform_matrix rotation is not orthonormal (scaled poses are not supported)",
                path=path,
                where=where,
            )
        rel = fr.get("file_path")
        views.append(
            View(str(rel), _image_path(rel, base, images, path, where), cam, M @ T_GL_TO_CV)
        )
    extra: dict[str, Any] = {}
    if "applied_transform" in doc:
        extra["applied_transform"] = doc["applied_transform"]
    return views, extra


def convert_nerfstudio(src: Path, ctx: IngestContext) -> None:
    """Convert a nerfstudio capture (``transforms.json`` + images)."""
    path = _transforms_file(src)
    if path is None:
        raise InputError("no transforms.json here", path=src)
    views, extra = read_transforms(path, images=ctx.options.images)
    prov = ctx.provenance
    prov.extra.update({"capture": "nerfstudio", **extra})
    orient_world(
        ctx,
        views,
        "world frame kept as in transforms.json (nerfstudio worlds are arbitrary: origin and scale "
        "come from the capture pipeline, not the robot base)",
    )
    prov.note("camera poses converted from OpenGL (x right, y up, z back) to OpenCV axes")
    write_static_capture(ctx, views, source=path.name)


register_converter(
    "nerfstudio",
    detect_nerfstudio,
    convert_nerfstudio,
    description="nerfstudio transforms.json capture",
    priority=90,
)
