"""Static multi-view captures of an arm and a box, with independent ground truth.

``synthesize_multiview(out, robot="two_link"|"ur5", n_views=..., width=..., height=...)``
writes a robogs dataset whose only camera orbits a static scene (a ``camera_extrinsics``
table), with panoptic labels, the URDF and the object poses, but no splats: the input of the
reference reconstructor. The returned :class:`MultiviewTruth` holds the true meshes and the
visible-surface samples for mesh metrics. Pixels come from ``robogs.synth.scene.raster`` and
kinematics from ``robogs.synth.scene.chain``; nothing is shared with what the scene tests.
"""

from .generate import (
    BACKGROUND_RGB,
    CAMERA_NAME,
    EPISODE_ID,
    LABEL_BOX,
    MultiviewTruth,
    read_truth_poses,
    synthesize_multiview,
    truth_path,
    write_truth,
)

__all__ = [
    "synthesize_multiview",
    "MultiviewTruth",
    "truth_path",
    "write_truth",
    "read_truth_poses",
    "EPISODE_ID",
    "CAMERA_NAME",
    "LABEL_BOX",
    "BACKGROUND_RGB",
]
