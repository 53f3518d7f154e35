"""The camera a frame is rendered from (OpenCV axes, pixel centres at +0.5)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import torch

if TYPE_CHECKING:
    from ..cameras import CameraModel

__all__ = ["Camera", "DISTORTION_MODELS", "camera_from_model"]

#: distortion model name -> number of coefficients (OpenCV / ROS order)
DISTORTION_MODELS: dict[str, int] = {"none": 0, "plumb_bob": 5, "equidistant": 4}


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera with optional lens distortion.

    Axes follow OpenCV (x right, y down, z forward). Pixel (0, 0) covers [0, 1) x [0, 1), so
    its centre is (0.5, 0.5).

    Attributes:
        width: image width, px.
        height: image height, px.
        fx: focal length along x, px.
        fy: focal length along y, px.
        cx: principal point x, px.
        cy: principal point y, px.
        T_world_cam: [4, 4] rigid transform mapping camera-frame points to the world frame.
        distortion_model: "none", "plumb_bob" (k1, k2, p1, p2, k3) or "equidistant" (k1..k4,
            the OpenCV fisheye model).
        distortion: the coefficients of ``distortion_model``.
        near: Gaussians with camera-frame z <= near are culled, m.
        far: Gaussians with camera-frame z >= far are culled, m.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    T_world_cam: torch.Tensor
    distortion_model: str = "none"
    distortion: tuple[float, ...] = ()
    near: float = 0.01
    far: float = 100.0

    @property
    def is_distorted(self) -> bool:
        """True when the lens model bends rays (non-zero coefficients)."""
        return self.distortion_model != "none" and any(float(c) != 0.0 for c in self.distortion)

    def pinhole(self) -> Camera:
        """The same camera without distortion."""
        return replace(self, distortion_model="none", distortion=())

    def world_to_cam(
        self, dtype: torch.dtype, device: torch.device
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Rotation and translation mapping world points into the camera frame.

        Returns:
            R_cam_world [3, 3], t_cam_world [3] (m) and the camera centre [3] in the world
            frame (m), in the requested dtype and device. Differentiable w.r.t. T_world_cam.
        """
        T = self.T_world_cam.to(dtype=dtype, device=device)
        R_wc = T[:3, :3]
        t_wc = T[:3, 3]
        R_cw = R_wc.transpose(0, 1)
        t_cw = -(R_cw @ t_wc)
        return R_cw, t_cw, t_wc


def camera_from_model(model: CameraModel, T_world_cam: np.ndarray, scale: float = 1.0) -> Camera:
    """The renderer's camera for a stored camera model, resized by ``scale``.

    Pixel-edge coordinates scale exactly: the size rounds to whole pixels (at least 1) and
    ``fx, cx`` (``fy, cy``) scale by the realised width (height) ratio.

    Args:
        model: the stored intrinsics and lens model.
        T_world_cam: [4, 4] camera pose (OpenCV axes), m.
        scale: render resolution as a fraction of the model's.
    """
    w = max(1, int(round(model.width * scale)))
    h = max(1, int(round(model.height * scale)))
    sx, sy = w / model.width, h / model.height
    return Camera(
        width=w,
        height=h,
        fx=model.fx * sx,
        fy=model.fy * sy,
        cx=model.cx * sx,
        cy=model.cy * sy,
        T_world_cam=torch.as_tensor(np.asarray(T_world_cam, np.float64)),
        distortion_model=model.distortion_model,
        distortion=tuple(model.distortion),
    )
