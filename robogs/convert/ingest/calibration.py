"""Camera calibrations -> :class:`robogs.format.cameras.CameraModel`.

Sources:

* ``sensor_msgs/CameraInfo`` messages (ROS 1 upper-case ``K, D, P`` or ROS 2 lower-case),
* ROS ``camera_info`` YAML files (``camera_calibration_parsers`` layout),
* OpenCV FileStorage YAML (``%YAML:1.0`` with ``!!opencv-matrix`` nodes), read with a
  ``yaml.SafeLoader`` subclass that knows only that one tag,
* ROS INI calibration files (``[image]`` + one camera section).

Pixel convention: ROS and OpenCV put the centre of the top-left pixel at (0, 0); robogs
(like COLMAP) puts it at (0.5, 0.5). The principal point is therefore shifted by
:data:`OPENCV_PIXEL_SHIFT` = +0.5 px on import (``cx_robogs = cx_ros + 0.5``); focal lengths and
distortion coefficients are unchanged.

Distortion models and their coefficient counts follow ROS ``camera_info``:
``plumb_bob`` 5 (k1, k2, p1, p2, k3), ``rational_polynomial`` 8, ``equidistant`` 4. A count
that does not match its model is an :class:`~robogs.format.errors.InputError` naming the file
or topic and stamp — it is never padded or truncated.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from robogs.format.cameras import DISTORTION_COEFFS, CameraModel
from robogs.format.errors import InputError

from .yamlio import NoAliasSafeLoader, load_yaml_text

__all__ = [
    "OPENCV_PIXEL_SHIFT",
    "camera_from_info_msg",
    "read_calibration",
    "check_distortion",
    "camera_from_matrices",
]

OPENCV_PIXEL_SHIFT = 0.5
_MAX_BYTES = 1 << 20
_ALIASES = {"fisheye": "equidistant", "kannala_brandt": "equidistant", "": "none", "none": "none"}


def check_distortion(
    model: str,
    coeffs: Sequence[float],
    *,
    path: str | Path | None = None,
    where: str | None = None,
) -> tuple[str, tuple[float, ...]]:
    """Validate a distortion model name and its coefficients.

    An empty model name is inferred from the count (0 none, 5 plumb_bob, 8
    rational_polynomial), as in the ROS INI format, which has no model field.

    Returns:
        ``(model, coefficients)`` in robogs spelling.

    Raises:
        InputError: unknown model, wrong count, or non-finite coefficients.
    """
    m = _ALIASES.get(model.strip().lower(), model.strip().lower())
    d = tuple(float(v) for v in coeffs)
    if model.strip() == "":
        m = {0: "none", 5: "plumb_bob", 8: "rational_polynomial"}.get(len(d), "")
        if not m:
            raise InputError(
                f"{len(d)} distortion coefficients and no distortion model",
                path=path,
                where=where,
                hint="name the model (plumb_bob 5, rational_polynomial 8, equidistant 4)",
            )
    if m == "none" and len(d) == 0:
        return "none", ()
    if m == "none" and not any(d):
        return "none", ()
    if m not in DISTORTION_COEFFS:
        raise InputError(
            f"unsupported distortion model {model!r}",
            path=path,
            where=where,
            hint="supported: plumb_bob, rational_polynomial, equidistant",
        )
    want = DISTORTION_COEFFS[m]
    if len(d) not in want:
        hint = "re-run the calibration or fix the file"
        if m == "plumb_bob" and len(d) == 4:
            hint = "a 4-coefficient fisheye calibration is 'equidistant'; plumb_bob needs k1 k2 p1 p2 k3"
        raise InputError(
            f"distortion model {m} needs {want[0]} coefficients, got {len(d)}",
            path=path,
            where=where,
            hint=hint,
        )
    if not all(math.isfinite(v) for v in d):
        raise InputError("non-finite distortion coefficient", path=path, where=where)
    return m, d


def camera_from_matrices(
    name: str,
    width: int,
    height: int,
    K: Sequence[float],
    D: Sequence[float],
    model: str,
    *,
    path: str | Path | None = None,
    where: str | None = None,
    pixel_shift: float = OPENCV_PIXEL_SHIFT,
) -> CameraModel:
    """A :class:`CameraModel` from a row-major 3x3 ``K`` (OpenCV pixel convention) and ``D``.

    Raises:
        InputError: uncalibrated (``fx <= 0``), skewed or malformed ``K``, bad size or distortion.
    """
    k = np.asarray(list(K), dtype=np.float64).reshape(-1)
    if k.size != 9 or not np.all(np.isfinite(k)):
        raise InputError(
            f"camera matrix must have 9 finite values, has {k.size}", path=path, where=where
        )
    fx, skew, cx, _, fy, cy = k[0], k[1], k[2], k[3], k[4], k[5]
    if fx <= 0 or fy <= 0:
        raise InputError(
            "camera is not calibrated (fx or fy is 0)",
            path=path,
            where=where,
            hint="calibrate the camera, or pass a calibration file",
        )
    if (
        abs(skew) > 1e-9 * fx
        or abs(k[3]) > 1e-12
        or k[6] != 0
        or k[7] != 0
        or abs(k[8] - 1.0) > 1e-12
    ):
        raise InputError(
            "camera matrix is not [[fx,0,cx],[0,fy,cy],[0,0,1]] (skew is not supported)",
            path=path,
            where=where,
        )
    try:
        width, height = int(width), int(height)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"invalid image size {width}x{height}", path=path, where=where) from None
    if not (0 < width <= 65536 and 0 < height <= 65536):
        raise InputError(f"invalid image size {width}x{height}", path=path, where=where)
    m, d = check_distortion(model, D, path=path, where=where)
    return CameraModel(
        name=name,
        width=int(width),
        height=int(height),
        fx=float(fx),
        fy=float(fy),
        cx=float(cx) + pixel_shift,
        cy=float(cy) + pixel_shift,
        distortion_model=m,
        distortion=d,
    )


def _field(msg: Any, *names: str) -> Any:
    for n in names:
        if hasattr(msg, n):
            return getattr(msg, n)
    raise AttributeError(names[0])


def camera_from_info_msg(
    msg: Any, *, name: str, topic: str, t_ns: int, rectified: bool = False
) -> CameraModel:
    """A camera from a ``sensor_msgs/CameraInfo`` message (ROS 1 or ROS 2 field names).

    Region of interest and binning are applied (ROI first, then binning, as in
    ``image_geometry``). With ``rectified``, intrinsics come from ``P`` and there is no
    distortion (for ``image_rect`` topics).

    Raises:
        InputError: naming the topic and stamp, for a bad matrix or distortion.
    """
    where = f"topic {topic} stamp {t_ns}"
    K = np.asarray(_field(msg, "k", "K"), dtype=np.float64).reshape(-1)
    D = [float(v) for v in np.asarray(_field(msg, "d", "D"), dtype=np.float64).reshape(-1)]
    model = str(getattr(msg, "distortion_model", ""))
    width, height = int(msg.width), int(msg.height)
    if rectified:
        P = np.asarray(_field(msg, "p", "P"), dtype=np.float64).reshape(-1)
        if P.size == 12:
            K = np.array([P[0], P[1], P[2], P[4], P[5], P[6], P[8], P[9], P[10]])
            D, model = [], "none"
    roi = getattr(msg, "roi", None)
    if (
        roi is not None
        and int(roi.width) > 0
        and int(roi.height) > 0
        and (int(roi.width) != width or int(roi.height) != height)
    ):
        K = K.copy()
        K[2] -= int(roi.x_offset)
        K[5] -= int(roi.y_offset)
        width, height = int(roi.width), int(roi.height)
    bx, by = (
        max(int(getattr(msg, "binning_x", 0) or 1), 1),
        max(int(getattr(msg, "binning_y", 0) or 1), 1),
    )
    if bx > 1 or by > 1:
        K = K.copy()
        K[0] /= bx
        K[2] /= bx
        K[4] /= by
        K[5] /= by
        width, height = width // bx, height // by
    if model.strip() == "" and not any(D):
        model, D = "none", []
    return camera_from_matrices(name, width, height, K, D, model, where=where)


# ----------------------------------------------------------------------------- files


class _OpenCVLoader(NoAliasSafeLoader):
    """SafeLoader (no aliases) that also builds ``!!opencv-matrix`` nodes (as dicts)."""


def _opencv_matrix(loader: yaml.SafeLoader, node: yaml.Node) -> dict[str, Any]:
    return loader.construct_mapping(node, deep=True)  # type: ignore[arg-type]


_OpenCVLoader.add_constructor("tag:yaml.org,2002:opencv-matrix", _opencv_matrix)


def _matrix(doc: dict[str, Any], key: str, path: Path) -> list[float]:
    node = doc.get(key)
    if node is None:
        raise InputError(f"missing {key!r}", path=path)
    data = node.get("data") if isinstance(node, dict) else node
    if not isinstance(data, list):
        raise InputError(f"{key!r} has no data list", path=path, where=key)
    try:
        vals = [float(v) for v in data]
    except (TypeError, ValueError):
        raise InputError(f"{key!r} holds non-numbers", path=path, where=key) from None
    if isinstance(node, dict) and "rows" in node and "cols" in node:
        if int(node["rows"]) * int(node["cols"]) != len(vals):
            raise InputError(
                f"{key!r} declares {node['rows']}x{node['cols']} but holds {len(vals)} values",
                path=path,
                where=key,
            )
    return vals


def _read_text(path: Path) -> str:
    try:
        if path.stat().st_size > _MAX_BYTES:
            raise InputError("calibration file is too large", path=path)
        return path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"cannot read calibration file ({exc.strerror})", path=path) from None
    except UnicodeDecodeError:
        raise InputError("calibration file is not UTF-8 text", path=path) from None


def _read_yaml(path: Path, text: str, name: str | None) -> CameraModel:
    opencv = text.lstrip().startswith("%YAML:")
    if opencv:  # OpenCV writes '%YAML:1.0', which PyYAML rejects as a directive
        text = re.sub(r"^\s*%YAML:[0-9.]+[^\n]*\n", "", text, count=1)
    doc = load_yaml_text(text, path=path, what="calibration", loader=_OpenCVLoader)
    if not isinstance(doc, dict):
        raise InputError("calibration YAML must be a mapping", path=path)
    try:
        width, height = int(doc["image_width"]), int(doc["image_height"])
    except (KeyError, TypeError, ValueError, OverflowError):
        raise InputError("calibration has no image_width/image_height", path=path) from None
    K = _matrix(doc, "camera_matrix", path)
    D = _matrix(doc, "distortion_coefficients", path) if "distortion_coefficients" in doc else []
    model = (
        str(doc.get("distortion_model", "")) if not opencv else str(doc.get("distortion_model", ""))
    )
    cam = name or str(doc.get("camera_name") or path.stem)
    from .roles import safe_name

    return camera_from_matrices(safe_name(cam), width, height, K, D, model, path=path)


def _read_ini(path: Path, text: str, name: str | None) -> CameraModel:
    # ROS INI: '[image]' then 'width'/'height' with the value on the next line; one camera
    # section with 'camera matrix', 'distortion', 'rectification', 'projection' blocks.
    sections: dict[str, list[str]] = {}
    current = None
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith(("#", ";")):
            continue
        m = re.fullmatch(r"\[(.+)\]", line)
        if m:
            current = m.group(1).strip()
            sections[current] = []
        elif current is not None:
            sections[current].append(line)
    if "image" not in sections or len(sections) < 2:
        raise InputError("INI calibration needs an [image] section and a camera section", path=path)

    def _blocks(lines: list[str]) -> dict[str, list[float]]:
        out: dict[str, list[float]] = {}
        key = None
        for line in lines:
            try:
                vals = [float(v) for v in line.split()]
            except ValueError:
                key = line.lower()
                out[key] = []
                continue
            if key is None:
                raise InputError("number before any key in INI calibration", path=path, where=line)
            out[key].extend(vals)
        return out

    img = _blocks(sections["image"])
    cam_section = next(s for s in sections if s != "image")
    cam = _blocks(sections[cam_section])
    try:
        width, height = int(img["width"][0]), int(img["height"][0])
        K = cam["camera matrix"]
    except (KeyError, IndexError):
        raise InputError(
            "INI calibration lacks width, height or camera matrix", path=path
        ) from None
    from .roles import safe_name

    return camera_from_matrices(
        safe_name(name or cam_section), width, height, K, cam.get("distortion", []), "", path=path
    )


def read_calibration(path: str | Path, *, name: str | None = None) -> CameraModel:
    """Read a calibration file (ROS YAML, OpenCV YAML, ROS INI) into a :class:`CameraModel`.

    Args:
        path: the file.
        name: camera name (default: ``camera_name`` in the file, else the file stem).

    Raises:
        InputError: unreadable, malformed, uncalibrated, or inconsistent distortion.
    """
    p = Path(path)
    text = _read_text(p)
    try:
        if p.suffix.lower() == ".ini" or text.lstrip().startswith("["):
            return _read_ini(p, text, name)
        return _read_yaml(p, text, name)
    except (TypeError, ValueError, OverflowError, AttributeError) as exc:
        raise InputError(
            f"calibration holds a value of the wrong type ({type(exc).__name__}: {str(exc)[:120]})",
            path=p,
            hint="image_width/image_height are integers; matrices hold numbers (rows, cols, data)",
        ) from None
