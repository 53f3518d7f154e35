"""Camera models as stored in ``cameras/<name>.json``.

Axes follow OpenCV (x right, y down, z forward). Intrinsics are in pixels with
pixel centres at +0.5. ``T_world_cam`` maps camera-frame points to the world.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["CameraModel", "DISTORTION_COEFFS"]

#: number of coefficients each distortion model takes (OpenCV / ROS order)
DISTORTION_COEFFS = {
    "none": (0,),
    "plumb_bob": (5,),
    "rational_polynomial": (8,),
    "equidistant": (4,),
}


@dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics (px), distortion, and static extrinsics."""

    name: str
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion_model: str = "none"
    distortion: tuple[float, ...] = ()
    T_world_cam: np.ndarray | None = field(default=None, compare=False)
    extrinsics: str = "static"

    @property
    def K(self) -> np.ndarray:
        """[3, 3] intrinsic matrix in px."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CameraModel:
        T = d.get("T_world_cam")
        return cls(
            name=str(d["name"]),
            width=int(d["width"]),
            height=int(d["height"]),
            fx=float(d["fx"]),
            fy=float(d["fy"]),
            cx=float(d["cx"]),
            cy=float(d["cy"]),
            distortion_model=str(d.get("distortion_model", "none")),
            distortion=tuple(float(v) for v in d.get("distortion", ())),
            T_world_cam=None if T is None else np.asarray(T, dtype=np.float64),
            extrinsics=str(d.get("extrinsics", "static")),
        )

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "name": self.name,
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "distortion_model": self.distortion_model,
            "distortion": list(self.distortion),
            "extrinsics": self.extrinsics,
        }
        if self.T_world_cam is not None:
            out["T_world_cam"] = np.asarray(self.T_world_cam, dtype=float).tolist()
        return out
