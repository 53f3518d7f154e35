"""A URDF kinematic tree parsed from XML, with batched numpy forward kinematics.

This is the generator's own reading of a URDF (defusedxml, no yourdfpy, no
``robogs.format.kinematics``) so that the ground truth it produces is an
independent oracle for the toolkit's kinematics. Conventions follow the URDF
specification (http://wiki.ros.org/urdf/XML/joint): a joint's ``origin`` is
``T_parent_joint``; the child link frame is the joint frame moved by the joint
(rotation about ``axis`` for revolute/continuous, translation along it for
prismatic); ``rpy`` is R = Rz(y) Ry(p) Rx(r).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from defusedxml import ElementTree as DET

from robogs.format.errors import InputError

from .rigid import axis_angle_matrix, make_T, rpy_to_matrix

__all__ = ["Joint", "Visual", "Inertial", "RobotModel", "parse_urdf", "parse_urdf_bytes"]

_MOVING = ("revolute", "continuous", "prismatic")


@dataclass
class Joint:
    """One URDF joint.

    Attributes:
        T_parent_joint: [4, 4] the joint origin in the parent link frame.
        axis: [3] unit axis in the joint frame.
        lower, upper: limits (rad or m); +-inf for continuous joints.
        mimic: (driver joint, multiplier, offset) or None.
    """

    name: str
    type: str
    parent: str
    child: str
    T_parent_joint: np.ndarray
    axis: np.ndarray
    lower: float = -np.inf
    upper: float = np.inf
    velocity: float = np.inf
    effort: float = np.inf
    damping: float = 0.0
    friction: float = 0.0
    mimic: tuple[str, float, float] | None = None

    @property
    def actuated(self) -> bool:
        """True for moving joints that are not mimics of another joint."""
        return self.type in _MOVING and self.mimic is None


@dataclass
class Visual:
    """One visual geometry of a link: a mesh URI or a primitive, in the link frame."""

    link: str
    T_link_visual: np.ndarray
    mesh_uri: str | None = None
    scale: np.ndarray = field(default_factory=lambda: np.ones(3))
    primitive: str | None = None  # box | cylinder | sphere
    params: tuple[float, ...] = ()


@dataclass
class Inertial:
    """A link's inertial: mass (kg), CoM origin in the link frame, inertia (kg m^2) about the CoM."""

    mass: float
    T_link_com: np.ndarray
    inertia: np.ndarray


@dataclass
class RobotModel:
    """A URDF tree: links, joints (parent before child), visuals, inertials."""

    name: str
    root: str
    links: list[str]
    joints: list[Joint]
    visuals: dict[str, list[Visual]]
    inertials: dict[str, Inertial]

    @property
    def actuated_joints(self) -> list[Joint]:
        return [j for j in self.joints if j.actuated]

    @property
    def joint_names(self) -> list[str]:
        """Names of the actuated joints: the order of ``q``."""
        return [j.name for j in self.actuated_joints]

    def joint(self, name: str) -> Joint:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)

    def parent_joint(self, link: str) -> Joint | None:
        for j in self.joints:
            if j.child == link:
                return j
        return None

    def path_to(self, link: str) -> list[Joint]:
        """Joints from the root to ``link``, root first."""
        out: list[Joint] = []
        cur = link
        while (j := self.parent_joint(cur)) is not None:
            out.append(j)
            cur = j.parent
        return out[::-1]

    def joint_values(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """Values [B] of every moving joint (mimics included) from actuated ``q`` [B, n]."""
        q = np.atleast_2d(np.asarray(q, dtype=np.float64))
        vals = {n: q[:, i] for i, n in enumerate(self.joint_names)}
        for j in self.joints:
            if j.mimic is not None and j.type in _MOVING:
                drv, mult, off = j.mimic
                vals[j.name] = mult * vals[drv] + off
        return vals

    def fk(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """``T_root_link`` [B, 4, 4] of every link for actuated joint values ``q`` [B, n] (rad|m)."""
        q = np.atleast_2d(np.asarray(q, dtype=np.float64))
        B = q.shape[0]
        vals = self.joint_values(q)
        poses: dict[str, np.ndarray] = {self.root: np.broadcast_to(np.eye(4), (B, 4, 4)).copy()}
        for j in self.joints:  # parent before child
            T = poses[j.parent] @ j.T_parent_joint
            if j.type in ("revolute", "continuous"):
                M = np.zeros((B, 4, 4))
                M[:, :3, :3] = axis_angle_matrix(j.axis, vals[j.name])
                M[:, 3, 3] = 1.0
                T = T @ M
            elif j.type == "prismatic":
                M = np.broadcast_to(np.eye(4), (B, 4, 4)).copy()
                M[:, :3, 3] = vals[j.name][:, None] * j.axis
                T = T @ M
            poses[j.child] = T
        return poses


def _floats(text: str | None, n: int, default: float, where: str, path: Path) -> np.ndarray:
    if text is None:
        return np.full(n, default, dtype=np.float64)
    try:
        vals = [float(v) for v in text.split()]
    except ValueError:
        raise InputError(f"non-numeric values {text!r}", path=path, where=where) from None
    if len(vals) == 1 and n == 3:
        vals = vals * 3
    if len(vals) != n or not np.all(np.isfinite(vals)):
        raise InputError(f"expected {n} finite numbers, got {text!r}", path=path, where=where)
    return np.asarray(vals, dtype=np.float64)


def _origin(el, where: str, path: Path) -> np.ndarray:
    if el is None:
        return np.eye(4)
    xyz = _floats(el.get("xyz"), 3, 0.0, where, path)
    rpy = _floats(el.get("rpy"), 3, 0.0, where, path)
    return make_T(rpy_to_matrix(rpy), xyz)


def parse_urdf(path: str | Path) -> RobotModel:
    """Parse a URDF file into a :class:`RobotModel` (joints sorted parent before child).

    Raises:
        InputError: unreadable XML, missing tags, not a tree.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputError("URDF file does not exist", path=path) from None
    return parse_urdf_bytes(data, path)


def parse_urdf_bytes(data: bytes, path: str | Path = "<urdf>") -> RobotModel:
    """Parse URDF text (``path`` only names it in errors); see :func:`parse_urdf`."""
    path = Path(path)
    try:
        root = DET.fromstring(data, forbid_dtd=True)
    except Exception as exc:  # defusedxml raises several types on hostile or broken XML
        raise InputError(
            f"URDF is not readable XML ({type(exc).__name__}: {exc})", path=path
        ) from None
    if root.tag != "robot":
        raise InputError("root element is not <robot>", path=path)
    links: list[str] = []
    visuals: dict[str, list[Visual]] = {}
    inertials: dict[str, Inertial] = {}
    for lk in root.findall("link"):
        name = lk.get("name")
        if not name:
            raise InputError("<link> without a name", path=path)
        links.append(name)
        vis_list: list[Visual] = []
        for k, v in enumerate(lk.findall("visual")):
            where = f"link '{name}' visual {k}"
            T = _origin(v.find("origin"), where, path)
            g = v.find("geometry")
            if g is None or len(g) == 0:
                continue
            shape = g[0]
            if shape.tag == "mesh":
                vis_list.append(
                    Visual(
                        name,
                        T,
                        mesh_uri=shape.get("filename"),
                        scale=_floats(shape.get("scale"), 3, 1.0, where, path),
                    )
                )
            elif shape.tag == "box":
                vis_list.append(
                    Visual(
                        name,
                        T,
                        primitive="box",
                        params=tuple(_floats(shape.get("size"), 3, 0.0, where, path)),
                    )
                )
            elif shape.tag == "cylinder":
                r = _floats(shape.get("radius"), 1, 0.0, where, path)[0]
                h = _floats(shape.get("length"), 1, 0.0, where, path)[0]
                vis_list.append(Visual(name, T, primitive="cylinder", params=(r, h)))
            elif shape.tag == "sphere":
                r = _floats(shape.get("radius"), 1, 0.0, where, path)[0]
                vis_list.append(Visual(name, T, primitive="sphere", params=(r,)))
        visuals[name] = vis_list
        inert = lk.find("inertial")
        if inert is not None:
            where = f"link '{name}' inertial"
            m_el, i_el = inert.find("mass"), inert.find("inertia")
            mass = float(m_el.get("value", "0")) if m_el is not None else 0.0
            inertia = np.zeros((3, 3))
            if i_el is not None:
                g = {k: float(i_el.get(k, "0")) for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
                inertia = np.array(
                    [
                        [g["ixx"], g["ixy"], g["ixz"]],
                        [g["ixy"], g["iyy"], g["iyz"]],
                        [g["ixz"], g["iyz"], g["izz"]],
                    ]
                )
            inertials[name] = Inertial(mass, _origin(inert.find("origin"), where, path), inertia)
    joints: list[Joint] = []
    for el in root.findall("joint"):
        name = el.get("name") or ""
        where = f"joint '{name}'"
        par, chi = el.find("parent"), el.find("child")
        if par is None or chi is None or not name:
            raise InputError("joint without name, parent or child", path=path, where=where)
        jtype = el.get("type", "")
        axis = _floats(
            el.find("axis").get("xyz") if el.find("axis") is not None else None, 3, 0.0, where, path
        )
        if el.find("axis") is None:
            axis = np.array([1.0, 0.0, 0.0])
        if jtype in _MOVING:
            n = np.linalg.norm(axis)
            if n < 1e-12:
                raise InputError("joint axis is zero", path=path, where=where)
            axis = axis / n
        lim = el.find("limit")
        lower, upper, vel, eff = -np.inf, np.inf, np.inf, np.inf
        if lim is not None and jtype in ("revolute", "prismatic"):
            lower = float(lim.get("lower", "0"))
            upper = float(lim.get("upper", "0"))
        if lim is not None:
            vel = float(lim.get("velocity", "inf"))
            eff = float(lim.get("effort", "inf"))
        dyn = el.find("dynamics")
        mim = el.find("mimic")
        mimic = None
        if mim is not None:
            mimic = (
                mim.get("joint", ""),
                float(mim.get("multiplier", "1")),
                float(mim.get("offset", "0")),
            )
        joints.append(
            Joint(
                name=name,
                type=jtype,
                parent=par.get("link", ""),
                child=chi.get("link", ""),
                T_parent_joint=_origin(el.find("origin"), where, path),
                axis=axis,
                lower=lower,
                upper=upper,
                velocity=vel,
                effort=eff,
                damping=float(dyn.get("damping", "0")) if dyn is not None else 0.0,
                friction=float(dyn.get("friction", "0")) if dyn is not None else 0.0,
                mimic=mimic,
            )
        )
    children = {j.child for j in joints}
    roots = [lk for lk in links if lk not in children]
    if len(roots) != 1:
        raise InputError(f"URDF must have one root link, found {roots}", path=path)
    # order joints parent before child (breadth-first from the root)
    ordered: list[Joint] = []
    frontier = [roots[0]]
    by_parent: dict[str, list[Joint]] = {}
    for j in joints:
        by_parent.setdefault(j.parent, []).append(j)
    while frontier:
        nxt = []
        for lk in frontier:
            for j in by_parent.get(lk, []):
                ordered.append(j)
                nxt.append(j.child)
        frontier = nxt
    if len(ordered) != len(joints):
        raise InputError("URDF joints do not form a tree", path=path)
    return RobotModel(root.get("name", "robot"), roots[0], links, ordered, visuals, inertials)
