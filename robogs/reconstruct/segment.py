"""Assign reconstructed points (mesh vertices, Gaussian centres) to links and objects by label voting.

Each point is projected into every labelled view; where it is visible (its camera depth within
``tol_m`` of the rendered median depth at that pixel) the panoptic label there gets a vote.
Label ids map to targets through the ``segments`` table; the target with most votes wins.
Points no view sees take the target of their nearest voted neighbour (the 2DGS mesh is
watertight-ish, so hidden faces exist). A point whose winning vote is "unlabelled" (id 0 or a
segment without a target) is left unassigned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import trimesh
from scipy.spatial import cKDTree

from .views import Segment, View

__all__ = [
    "TargetMap",
    "target_map",
    "vote_targets",
    "face_targets",
    "drop_fragments",
    "split_mesh",
]


@dataclass
class TargetMap:
    """Targets of a scene: ``names[k]`` is target k+1 (0 = unassigned), ``kinds[k]`` its kind.

    Attributes:
        names: link or object names.
        kinds: ``robot_link`` or ``object`` (``background`` segments naming an asset count as
            objects that do not move).
        lut: [65536] label id -> target index (0 for unlabelled ids and segments without target).
    """

    names: list[str]
    kinds: list[str]
    lut: np.ndarray


def target_map(segments: dict[int, Segment], links: set[str]) -> TargetMap:
    """Targets named by the segments; a ``robot_link`` target must be a URDF link."""
    names: list[str] = []
    kinds: list[str] = []
    lut = np.zeros(1 << 16, np.int64)
    for lab, seg in sorted(segments.items()):
        if not seg.target or not 0 < lab < (1 << 16):
            continue
        kind = "robot_link" if seg.target in links else "object"
        if seg.kind == "robot_link" and seg.target not in links:
            continue  # names a link the URDF lacks: left unassigned
        if seg.target not in names:
            names.append(seg.target)
            kinds.append(kind)
        lut[lab] = names.index(seg.target) + 1
    return TargetMap(names, kinds, lut)


def vote_targets(
    points: np.ndarray, views: list[View], depths: list[torch.Tensor], tmap: TargetMap, tol_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Target index [N] (0 = none) and vote share [N] (0..1) of world points [N, 3]."""
    n_t = len(tmap.names) + 1
    votes = torch.zeros(len(points), n_t, dtype=torch.float32)
    P = torch.as_tensor(points, dtype=torch.float64)
    lut = torch.as_tensor(tmap.lut)
    for v, d in zip(views, depths, strict=True):
        if v.labels is None:
            continue
        T = v.camera.T_world_cam.to(torch.float64)
        pc = (P - T[:3, 3]) @ T[:3, :3]
        z = pc[:, 2]
        zs = torch.where(z > 1e-9, z, torch.ones_like(z))
        u = torch.floor(v.camera.fx * pc[:, 0] / zs + v.camera.cx).long()
        w = torch.floor(v.camera.fy * pc[:, 1] / zs + v.camera.cy).long()
        H, W = v.labels.shape
        inside = (z > 0) & (u >= 0) & (u < W) & (w >= 0) & (w < H)
        pix = w.clamp(0, H - 1) * W + u.clamp(0, W - 1)
        dd = d.detach().cpu().reshape(-1).to(torch.float64)[pix]
        seen = inside & (dd > 0) & ((dd - z).abs() < tol_m)
        lab = torch.as_tensor(v.labels.reshape(-1))[pix].clamp(0, (1 << 16) - 1)
        t = lut[lab]
        idx = torch.nonzero(seen)[:, 0]
        votes.index_put_((idx, t[idx]), torch.ones(len(idx)), accumulate=True)
    total = votes.sum(1)
    best = votes.argmax(1)
    share = torch.where(
        total > 0, votes.max(1).values / total.clamp(min=1), torch.zeros_like(total)
    )
    target = best.numpy().copy()
    seen_any = (total > 0).numpy()
    if seen_any.any() and not seen_any.all():
        _, nn = cKDTree(points[seen_any]).query(points[~seen_any], k=1)
        target[~seen_any] = target[seen_any][nn]
    elif not seen_any.any():
        target[:] = 0
    return target, share.numpy()


def face_targets(mesh: trimesh.Trimesh, vertex_target: np.ndarray) -> np.ndarray:
    """[F] target of each face: its vertices' majority, else its first vertex's."""
    t = np.asarray(vertex_target)[np.asarray(mesh.faces)]
    return np.where((t[:, 1] == t[:, 2]), t[:, 1], t[:, 0])


def drop_fragments(
    mesh: trimesh.Trimesh, vertex_target: np.ndarray, *, min_fraction: float = 0.2
) -> np.ndarray:
    """[F] bool: faces kept once every target is reduced to its main pieces.

    A link or object is one rigid body, so its faces should form one connected piece (two or
    three where another part hides its middle). Faces of target k are grouped into connected
    components (shared edges between faces of k only); a component is kept when its area is at
    least ``min_fraction`` of the largest component of k, so the threshold comes from the target
    itself. What goes are floaters between the cameras and the target (rendered depth
    in front of it, voted to it because they project onto its pixels) and bits of a neighbour's
    surface that won the vote at a boundary. Unassigned faces (target 0) are kept.
    """
    ft = face_targets(mesh, vertex_target)
    keep = np.ones(len(ft), bool)
    if len(ft) == 0:
        return keep
    adj = np.asarray(mesh.face_adjacency)
    same = ft[adj[:, 0]] == ft[adj[:, 1]]
    labels = trimesh.graph.connected_component_labels(adj[same], node_count=len(ft))
    area = np.asarray(mesh.area_faces)
    comp_area = np.bincount(labels, weights=area)
    for k in np.unique(ft):
        if k <= 0:
            continue
        comps = np.unique(labels[ft == k])
        big = comp_area[comps].max()
        small = comps[comp_area[comps] < min_fraction * big]
        keep &= ~np.isin(labels, small)
    return keep


def split_mesh(
    mesh: trimesh.Trimesh, vertex_target: np.ndarray, n_targets: int
) -> dict[int, trimesh.Trimesh]:
    """Sub-mesh per target index 1..n: the faces of :func:`face_targets` k."""
    maj = face_targets(mesh, vertex_target)
    out = {}
    for k in range(1, n_targets + 1):
        sel = maj == k
        if sel.any():
            sub = mesh.submesh([np.flatnonzero(sel)], append=True, repair=False)
            out[k] = sub
    return out
