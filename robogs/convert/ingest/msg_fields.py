"""Duck-typed reads of ROS message fields (rosbags, ``mcap_ros2`` and Foxglove objects alike)."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["floats"]


def floats(values: Any) -> np.ndarray:
    """A message's number sequence as a flat float64 array."""
    return np.asarray(values, dtype=np.float64).reshape(-1)
