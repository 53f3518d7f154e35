"""The reference reconstructor: multi-view frames -> 2D surfels, meshes, links and the binding.

``robogs reconstruct DATASET`` trains 2D Gaussian surfels (Huang et al. 2024; 3D Gaussians on
request) with the robogs rasterizer on the static views of a dataset, fuses their median depth
into a TSDF, meshes and cleans it, assigns mesh and Gaussians to links and objects by the
panoptic labels, fits the similarity to the URDF, binds every Gaussian to a face of its target's
mesh and writes it all back through the atomic writer. ``robogs evaluate`` measures held-out
images, labels and meshes. See ``docs/reconstruct.md``.

Example:
    >>> from robogs.reconstruct import ReconstructOptions, TrainConfig, reconstruct, evaluate
    >>> rep = reconstruct("scene/", ReconstructOptions(train=TrainConfig(iterations=3000)))  # doctest: +SKIP
    >>> evaluate("scene/", reference="scan.ply", visible_only=True).mesh.fscore  # doctest: +SKIP
"""

from __future__ import annotations

from .align import AlignmentResult, Similarity, align_to_meshes, umeyama
from .bind import bind_to_mesh, bound_positions
from .densify import DensifyConfig
from .evaluate import EvaluationReport, ViewMetrics, evaluate, visible_mask
from .image_metrics import label_iou, psnr, ssim
from .init import InitConfig
from .mesh_clean import clean_mesh
from .mesh_metrics import MeshMetrics, mesh_metrics, point_metrics, robogs_compat
from .model import GaussianModel, LearningRates
from .pipeline import ReconstructionReport, ReconstructOptions, reconstruct
from .train import TrainConfig, TrainResult, train
from .tsdf import TSDFVolume, extract_mesh, fuse_tsdf
from .views import Capture, View, load_capture

__all__ = [
    "reconstruct",
    "ReconstructOptions",
    "ReconstructionReport",
    "evaluate",
    "EvaluationReport",
    "ViewMetrics",
    "TrainConfig",
    "TrainResult",
    "train",
    "InitConfig",
    "DensifyConfig",
    "LearningRates",
    "GaussianModel",
    "load_capture",
    "Capture",
    "View",
    "fuse_tsdf",
    "extract_mesh",
    "TSDFVolume",
    "clean_mesh",
    "umeyama",
    "align_to_meshes",
    "Similarity",
    "AlignmentResult",
    "bind_to_mesh",
    "bound_positions",
    "psnr",
    "ssim",
    "label_iou",
    "mesh_metrics",
    "point_metrics",
    "robogs_compat",
    "MeshMetrics",
    "visible_mask",
]
