"""A procedural two-link arm on a base: URDF text, STL meshes and its own kinematic tree.

Links (z up, metres, world origin at the base's bottom centre):

* ``base_link`` — box 0.14 x 0.14 x 0.06, resting on z = 0;
* ``link1`` — cylinder r = 0.04, h = 0.22 on ``joint1`` (revolute about z, 0.06 above the base);
* ``link2`` — box 0.06 x 0.06 x 0.18 on ``joint2`` (revolute about y, at the top of link1).

The kinematic tree is parsed by ``robogs.synth.scene.chain`` (the generator's own URDF reader), not by
the toolkit's kinematics, so the scene stays an independent oracle.
"""

from __future__ import annotations

import numpy as np
import trimesh

from robogs.synth.scene.chain import parse_urdf_bytes
from robogs.synth.scene.robot_source import RobotAssets

__all__ = ["two_link_robot", "TWO_LINK_JOINTS", "TWO_LINK_COLORS"]

TWO_LINK_JOINTS = ("joint1", "joint2")
#: linear RGB of each link
TWO_LINK_COLORS = {
    "base_link": (0.35, 0.38, 0.45),
    "link1": (0.85, 0.45, 0.12),
    "link2": (0.15, 0.40, 0.85),
}
_DENSITY = 1200.0  # kg/m^3, plastic-like


def _meshes() -> dict[str, trimesh.Trimesh]:
    base = trimesh.creation.box(extents=(0.14, 0.14, 0.06))
    base.apply_translation((0.0, 0.0, 0.03))
    link1 = trimesh.creation.cylinder(radius=0.04, height=0.22, sections=24)
    link1.apply_translation((0.0, 0.0, 0.11))
    link2 = trimesh.creation.box(extents=(0.06, 0.06, 0.18))
    link2.apply_translation((0.0, 0.0, 0.09))
    return {"base_link": base, "link1": link1, "link2": link2}


def _inertial(mesh: trimesh.Trimesh) -> str:
    mesh = mesh.copy()
    mesh.density = _DENSITY
    c = mesh.center_mass
    inertia = mesh.moment_inertia
    return (
        f'<inertial><origin xyz="{c[0]:.9g} {c[1]:.9g} {c[2]:.9g}" rpy="0 0 0"/>'
        f'<mass value="{mesh.mass:.9g}"/>'
        f'<inertia ixx="{inertia[0, 0]:.9g}" ixy="{inertia[0, 1]:.9g}" ixz="{inertia[0, 2]:.9g}" '
        f'iyy="{inertia[1, 1]:.9g}" iyz="{inertia[1, 2]:.9g}" izz="{inertia[2, 2]:.9g}"/></inertial>'
    )


def _link(name: str, mesh: trimesh.Trimesh) -> str:
    uri = f"meshes/{name}.stl"
    geo = f'<geometry><mesh filename="{uri}"/></geometry>'
    return (
        f'<link name="{name}">{_inertial(mesh)}'
        f'<visual><origin xyz="0 0 0" rpy="0 0 0"/>{geo}</visual>'
        f'<collision><origin xyz="0 0 0" rpy="0 0 0"/>{geo}</collision></link>'
    )


def two_link_robot() -> RobotAssets:
    """The two-link arm as :class:`robogs.synth.scene.robot_source.RobotAssets` (tool link: ``link2``)."""
    meshes = _meshes()
    joints = (
        '<joint name="joint1" type="revolute"><parent link="base_link"/><child link="link1"/>'
        '<origin xyz="0 0 0.06" rpy="0 0 0"/><axis xyz="0 0 1"/>'
        '<limit lower="-3.14" upper="3.14" effort="20" velocity="2"/></joint>'
        '<joint name="joint2" type="revolute"><parent link="link1"/><child link="link2"/>'
        '<origin xyz="0 0 0.22" rpy="0 0 0"/><axis xyz="0 1 0"/>'
        '<limit lower="-2.0" upper="2.0" effort="10" velocity="2"/></joint>'
    )
    text = (
        '<?xml version="1.0"?>\n<robot name="two_link">'
        + "".join(_link(n, m) for n, m in meshes.items())
        + joints
        + "</robot>\n"
    )
    files = {f"robot/meshes/{n}.stl": m.export(file_type="stl") for n, m in meshes.items()}
    model = parse_urdf_bytes(text.encode(), "robot/robot.urdf")
    return RobotAssets(
        text,
        files,
        model,
        meshes,
        dict(TWO_LINK_COLORS),
        tool_link="link2",
        pusher_radius=0.0,
        mdh=None,
        source="procedural two-link arm",
    )


def _check() -> None:  # pragma: no cover - developer aid
    r = two_link_robot()
    T = r.model.fk(np.zeros((1, 2)))
    print({k: v[0, :3, 3] for k, v in T.items()})
