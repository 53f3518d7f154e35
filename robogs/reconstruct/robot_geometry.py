"""The robot's bind target meshes: each link's first visual mesh, posed at a joint state.

Spec §6: a Gaussian bound to link L names a face of L's *first visual mesh in the link frame*
(the visual origin and mesh scale applied, faces in file order: loaded with ``process=False``
so face indices match what the validator reads).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import trimesh

from robogs.format.dataset import Dataset
from robogs.format.errors import FormatError
from robogs.format.kinematics import Chain
from robogs.format.meshes import load_mesh

__all__ = ["LinkMesh", "link_meshes", "link_poses"]


@dataclass
class LinkMesh:
    """A link's bind target.

    Attributes:
        name: link name.
        mesh: first visual mesh in the link frame, m (faces in file order).
        T_world_link: [4, 4] pose at the requested joint state.
    """

    name: str
    mesh: trimesh.Trimesh
    T_world_link: np.ndarray

    def world_mesh(self) -> trimesh.Trimesh:
        """The mesh in the world frame (same faces)."""
        m = self.mesh.copy()
        m.apply_transform(self.T_world_link)
        return m


def link_poses(
    ds: Dataset, joint_positions: dict[str, float]
) -> tuple[Chain, dict[str, np.ndarray]]:
    """Forward kinematics of the dataset's URDF: link -> ``T_world_link`` [4, 4] (float64).

    The world origin is ``robot.base_link`` (spec §4), so poses are taken relative to it when
    it is not the URDF root.
    """
    chain = Chain.from_urdf(ds.urdf(load_meshes=False))
    missing = [j for j in chain.joint_names if j not in joint_positions]
    if missing:
        raise FormatError(
            f"no recorded position for joints {', '.join(missing[:5])}",
            hint="record every actuated joint in joint_states",
        )
    q = torch.tensor([float(joint_positions[j]) for j in chain.joint_names], dtype=torch.float64)
    T = chain.forward(q)
    base = (ds.manifest.get("robot") or {}).get("base_link")
    if isinstance(base, str) and base in chain.link_names and base != chain.link_names[0]:
        T = torch.linalg.inv(T[chain.link_index(base)]) @ T
    return chain, {name: T[i].numpy() for i, name in enumerate(chain.link_names)}


def link_meshes(ds: Dataset, joint_positions: dict[str, float]) -> dict[str, LinkMesh]:
    """Every link with a readable first visual mesh, posed at ``joint_positions``."""
    urdf = ds.urdf(load_meshes=True)
    _, poses = link_poses(ds, joint_positions)
    resolved = {(r.link, r.kind, r.uri): r.path for r in getattr(urdf, "robogs_mesh_refs", [])}
    out: dict[str, LinkMesh] = {}
    for link in urdf.robot.links:
        visual = next(
            (v for v in link.visuals if v.geometry is not None and v.geometry.mesh is not None),
            None,
        )
        if visual is None or link.name not in poses:
            continue
        path = resolved.get((link.name, "visual", visual.geometry.mesh.filename))
        if path is None:
            continue
        mesh = load_mesh(path, where=f"link {link.name} visual", triangles=False)
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            continue
        v = np.asarray(mesh.vertices, np.float64)
        if visual.geometry.mesh.scale is not None:
            v = v * np.broadcast_to(np.asarray(visual.geometry.mesh.scale, np.float64), (3,))
        M = np.asarray(visual.origin if visual.origin is not None else np.eye(4), np.float64)
        v = v @ M[:3, :3].T + M[:3, 3]
        out[link.name] = LinkMesh(
            link.name, trimesh.Trimesh(v, np.asarray(mesh.faces), process=False), poses[link.name]
        )
    return out
