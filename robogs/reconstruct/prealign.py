"""Cameras from structure from motion into the robot's world, before training.

``robogs convert DATASET OUT --sfm`` poses the views in the SfM frame: arbitrary scale, origin
and up (``provenance.sfm.frame`` says so). Seeding from the URDF and every length in metres
(spacings, carving, TSDF) need the robot's world, so :func:`prealign_sfm` fits the similarity
first, from the labels alone: the labelled visual hull (``init._hull_grid``, frame-agnostic)
gives boundary voxels; each takes the label most of the views where it is frontmost see there;
the voxels of each link are fitted to that link's URDF mesh at the recorded joint state
(``align.align_to_meshes``: Umeyama on the per-link centroids, then ICP). The cameras are moved
by it in one atomic edit, the residual is reported in mm, and ``reconstruct --align apply``
refines the transform on the trained mesh afterwards.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from robogs.format.dataset import Dataset
from robogs.format.errors import InputError

from .align import AlignmentResult, align_to_meshes
from .init import _frontmost, _hull_grid, _project, workspace_bounds
from .robot_geometry import link_meshes
from .views import Capture

__all__ = ["needs_prealign", "prealign_sfm", "prealign_json", "PREALIGN_RES"]

#: voxels along the longest workspace edge of the labelled hull
PREALIGN_RES = 160


def needs_prealign(ds: Dataset) -> bool:
    """True when the cameras are still in an SfM frame (``provenance.sfm.frame`` arbitrary)."""
    sfm = ds.manifest.get("provenance", {}).get("sfm")
    return isinstance(sfm, dict) and str(sfm.get("frame", "")).startswith("arbitrary")


def _labelled_boundary(capture: Capture, res: int) -> tuple[np.ndarray, np.ndarray]:
    """Boundary voxel centres [N, 3] of the labelled visual hull and their majority label [N]."""
    views = [v for v in capture.views if v.labels is not None]
    lo, hi = workspace_bounds(capture, None, views)
    occ, vox = _hull_grid(views, lo, hi, res, None, min_seen=max(2, math.ceil(0.2 * len(views))))
    if occ is None or not occ.any():
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    pad = np.pad(occ, 1)
    inner = np.ones_like(occ)
    for ax in range(3):
        for s in (0, 2):
            sl = [slice(1, -1)] * 3
            sl[ax] = slice(s, s + occ.shape[ax])
            inner &= pad[tuple(sl)]
    idx = np.argwhere(occ & ~inner)
    pts = lo + (idx + 0.5) * vox
    pts = pts[_frontmost(pts, views, vox)]
    P = torch.as_tensor(pts, dtype=torch.float64)
    votes: dict[int, torch.Tensor] = {}
    for v in views:
        u, w, z = _project(P, v)
        H, W = v.labels.shape
        inside = (z > 0) & (u >= 0) & (u < W) & (w >= 0) & (w < H)
        pix = w.clamp(0, H - 1).long() * W + u.clamp(0, W - 1).long()
        zbuf = torch.full((H * W,), float("inf"), dtype=torch.float64)
        zbuf.scatter_reduce_(0, pix[inside], z[inside], reduce="amin")
        front = inside & (z <= zbuf[pix] + 1.5 * vox)
        lab = torch.from_numpy(np.asarray(v.labels)).reshape(-1)[pix]
        for k in torch.unique(lab[front]).tolist():
            if k > 0:
                votes.setdefault(k, torch.zeros(len(P), dtype=torch.int32))
                votes[k] += (front & (lab == k)).to(torch.int32)
    if not votes:
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    keys = sorted(votes)
    tally = torch.stack([votes[k] for k in keys], 1)
    best = tally.argmax(1)
    label = torch.as_tensor(keys)[best]
    label[tally.max(1).values == 0] = 0
    return pts, label.numpy()


def prealign_sfm(ds: Dataset, capture: Capture, *, res: int = PREALIGN_RES) -> AlignmentResult:
    """Fit the similarity taking the SfM frame to the robot's world (see the module docstring).

    Raises:
        InputError: no robot, no joint state, or no labelled link voxels to fit.
    """
    if not ds.manifest.get("robot") or not capture.joint_positions:
        raise InputError(
            "cameras from structure from motion need the robot (URDF and joint state) to be "
            "placed in its world",
            path=ds.root,
            hint="convert with --urdf and a joint state, or pose the cameras yourself",
        )
    lmeshes = link_meshes(ds, capture.joint_positions)
    pts, label = _labelled_boundary(capture, res)
    by_label = {s.label_id: s.target for s in capture.segments.values()}
    points = {
        n: pts[label == k] for k, n in by_label.items() if n in lmeshes and (label == k).sum() >= 3
    }
    return align_to_meshes(points, {n: lm.world_mesh() for n, lm in lmeshes.items()})


def prealign_json(a: AlignmentResult) -> dict[str, Any]:
    """The figures of a pre-alignment, for the manifest and the report (mm, degrees)."""
    return {
        "scale": a.transform.scale,
        "rotation_deg": a.transform.rotation_deg,
        "rms_mm": a.rms_mm,
        "median_mm": a.median_mm,
        "p90_mm": a.p90_mm,
        "pairs": a.pairs,
    }
