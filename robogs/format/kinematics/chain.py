"""Batched forward kinematics of a URDF tree in torch.

A :class:`Chain` is built once from a ``yourdfpy.URDF`` (fixed joint origins, axes, types,
mimic couplings, parent order) and then evaluates ``T_base_link`` for every link for any batch
of joint vectors. The per-joint motion uses Rodrigues' formula folded into precomputed matrices,
so one call costs a handful of batched tensor operations plus one 3x3 product per link.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch
import yourdfpy

from robogs.format.errors import FormatError, InputError
from robogs.format.kinematics.joint_values import as_joint_tensor

__all__ = ["Chain", "JOINT_TYPES"]

JOINT_TYPES: tuple[str, ...] = ("fixed", "revolute", "continuous", "prismatic")
"""Joint types :class:`Chain` evaluates; ``floating``/``planar`` need ``floating_as_fixed``."""


def _skew_np(v: np.ndarray) -> np.ndarray:
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


@dataclass
class Chain:
    """Forward kinematics of a kinematic tree.

    Links are stored in topological order (``link_names[0]`` is the root, every parent comes
    before its children). Link ``k >= 1`` hangs from ``parents[k]`` through joint
    ``tree_joint_names[k - 1]`` whose transform is ``T_parent_child = origin @ motion(q)``,
    with ``motion`` a rotation of ``q`` rad about ``axis`` (revolute, continuous) or a
    translation of ``q`` m along ``axis`` (prismatic), ``axis`` a unit vector in the joint
    frame (URDF semantics).

    A joint's value is ``multiplier * q[source] + offset``: ``source`` indexes the actuated
    joints (``joint_names``); for an actuated joint multiplier is 1 and offset 0, for a mimic
    joint they come from ``<mimic>``; for fixed joints both are 0.

    Attributes:
        link_names: [L] link names, topological order.
        parents: [L] index of each link's parent (-1 for the root).
        tree_joint_names: [L-1] name of the joint above link k (k = 1..L-1).
        joint_names: [J] actuated joints (not fixed, not mimic), in URDF order.
        joint_types: [L-1] type of the joint above each link.
        origins: [L-1, 4, 4] fixed ``T_parent_jointframe`` of each joint, float64.
        axes: [L-1, 3] unit joint axes in the joint frame.
        source: [L-1] index into ``q`` (0 for fixed joints).
        multiplier: [L-1] mimic multiplier (1 actuated, 0 fixed).
        offset: [L-1] mimic offset in rad or m (0 otherwise).
        joint_lower: [J] lower limits (rad or m; -inf when unlimited).
        joint_upper: [J] upper limits (rad or m; +inf when unlimited).
    """

    link_names: list[str]
    parents: list[int]
    tree_joint_names: list[str]
    joint_names: list[str]
    joint_types: list[str]
    origins: np.ndarray
    axes: np.ndarray
    source: np.ndarray
    multiplier: np.ndarray
    offset: np.ndarray
    joint_lower: np.ndarray
    joint_upper: np.ndarray
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_urdf(cls, urdf: yourdfpy.URDF, *, floating_as_fixed: bool = False) -> Chain:
        """Build the chain of a URDF model.

        Args:
            urdf: a ``yourdfpy.URDF`` (e.g. from :func:`robogs.format.urdf.load_urdf`; meshes
                need not be loaded).
            floating_as_fixed: treat ``floating`` and ``planar`` joints as fixed at their origin
                (they then take no entry in ``q``). When False they raise.

        Returns:
            The chain.

        Raises:
            FormatError: unsupported joint types, bad mimic references, zero axes, a link graph
                that is not a tree.
        """
        robot = urdf.robot
        joints = list(robot.joints)
        by_child = {j.child: j for j in joints}
        children: dict[str, list[yourdfpy.Joint]] = {}
        for j in joints:
            children.setdefault(j.parent, []).append(j)
        roots = [lk.name for lk in robot.links if lk.name not in by_child]
        if len(roots) != 1:
            raise FormatError(
                f"a kinematic tree needs exactly one root link, found {roots[:5]}",
                where=f"robot '{robot.name}'",
            )

        def eff_type(j: yourdfpy.Joint) -> str:
            if j.type in ("floating", "planar"):
                if floating_as_fixed:
                    return "fixed"
                raise FormatError(
                    f"joint type '{j.type}' is not supported by Chain",
                    where=f"joint '{j.name}'",
                    hint="pass floating_as_fixed=True to freeze it at its origin",
                )
            if j.type not in JOINT_TYPES:
                raise FormatError(f"unknown joint type '{j.type}'", where=f"joint '{j.name}'")
            return j.type

        actuated = [j for j in joints if eff_type(j) != "fixed" and j.mimic is None]
        joint_names = [j.name for j in actuated]
        index = {n: i for i, n in enumerate(joint_names)}

        link_names = [roots[0]]
        parents = [-1]
        order: list[yourdfpy.Joint] = []
        pos = {roots[0]: 0}
        frontier = [roots[0]]
        while frontier:
            nxt = []
            for name in frontier:
                for j in children.get(name, []):
                    if j.child in pos:
                        raise FormatError("link graph has a cycle", where=f"joint '{j.name}'")
                    pos[j.child] = len(link_names)
                    link_names.append(j.child)
                    parents.append(pos[name])
                    order.append(j)
                    nxt.append(j.child)
            frontier = nxt
        if len(link_names) != len(robot.links):
            missing = sorted({lk.name for lk in robot.links} - set(pos))[:5]
            raise FormatError(f"links not connected to the root: {missing}")

        m = len(order)
        origins = np.zeros((m, 4, 4))
        axes = np.zeros((m, 3))
        source = np.zeros(m, dtype=np.int64)
        multiplier = np.zeros(m)
        offset = np.zeros(m)
        types: list[str] = []
        for k, j in enumerate(order):
            t = eff_type(j)
            types.append(t)
            origins[k] = np.eye(4) if j.origin is None else np.asarray(j.origin, dtype=np.float64)
            if t == "fixed":
                axes[k] = (0.0, 0.0, 1.0)
                continue
            axis = np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=float)
            norm = float(np.linalg.norm(axis))
            if not np.isfinite(norm) or norm < 1e-9:
                raise FormatError("joint axis is zero or not finite", where=f"joint '{j.name}'")
            axes[k] = axis / norm
            if j.mimic is None:
                source[k] = index[j.name]
                multiplier[k] = 1.0
            else:
                if j.mimic.joint not in index:
                    raise FormatError(
                        f"mimic joint '{j.mimic.joint}' is not an actuated joint",
                        where=f"joint '{j.name}'",
                        hint="a mimic must follow a revolute/continuous/prismatic joint",
                    )
                source[k] = index[j.mimic.joint]
                multiplier[k] = 1.0 if j.mimic.multiplier is None else float(j.mimic.multiplier)
                offset[k] = 0.0 if j.mimic.offset is None else float(j.mimic.offset)

        lower = np.full(len(actuated), -np.inf)
        upper = np.full(len(actuated), np.inf)
        for i, j in enumerate(actuated):
            if j.type != "continuous" and j.limit is not None:
                if j.limit.lower is not None:
                    lower[i] = float(j.limit.lower)
                if j.limit.upper is not None:
                    upper[i] = float(j.limit.upper)
        return cls(
            link_names=link_names,
            parents=parents,
            tree_joint_names=[j.name for j in order],
            joint_names=joint_names,
            joint_types=types,
            origins=origins,
            axes=axes,
            source=source,
            multiplier=multiplier,
            offset=offset,
            joint_lower=lower,
            joint_upper=upper,
        )

    # ------------------------------------------------------------------ queries

    @property
    def num_joints(self) -> int:
        """J, the length of ``q``."""
        return len(self.joint_names)

    @property
    def num_links(self) -> int:
        """L, the number of links (frames returned by :meth:`forward`)."""
        return len(self.link_names)

    def link_index(self, name: str) -> int:
        """Index of a link in ``link_names`` (and in the output of :meth:`forward`)."""
        try:
            return self.link_names.index(name)
        except ValueError:
            raise InputError(
                f"unknown link '{name}'", hint=f"links are {self.link_names}"
            ) from None

    def _consts(self, dtype: torch.dtype, device: torch.device) -> dict[str, torch.Tensor]:
        key = (dtype, str(device))
        c = self._cache.get(key)
        if c is None:
            R_o = self.origins[:, :3, :3]
            K = (
                np.stack([_skew_np(a) for a in self.axes])
                if len(self.axes)
                else np.zeros((0, 3, 3))
            )
            is_rev = np.array([t in ("revolute", "continuous") for t in self.joint_types])
            is_pri = np.array([t == "prismatic" for t in self.joint_types])

            def tt(x: np.ndarray) -> torch.Tensor:
                return torch.as_tensor(np.asarray(x, dtype=np.float64), dtype=dtype, device=device)

            c = {
                "R_o": tt(R_o),
                "A": tt(R_o @ K),  # coefficient of sin(q)
                "B": tt(R_o @ K @ K),  # coefficient of 1 - cos(q)
                "t_o": tt(self.origins[:, :3, 3]),
                "u": tt(np.einsum("kij,kj->ki", R_o, self.axes)),  # axis in the parent frame
                "src": torch.as_tensor(self.source, dtype=torch.long, device=device),
                "mul_rev": tt(self.multiplier * is_rev),
                "off_rev": tt(self.offset * is_rev),
                "mul_pri": tt(self.multiplier * is_pri),
                "off_pri": tt(self.offset * is_pri),
            }
            self._cache[key] = c
        return c

    def joint_values(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Angles and displacements of every tree joint (mimic couplings applied).

        Args:
            q: [..., J] actuated joint values (rad, m).

        Returns:
            ([..., L-1] angle in rad (0 unless revolute/continuous),
             [..., L-1] displacement in m (0 unless prismatic)).
        """
        q = self._check_q(q)
        c = self._consts(q.dtype, q.device)
        if self.num_joints == 0:
            src = torch.zeros(*q.shape[:-1], len(self.joint_types), dtype=q.dtype, device=q.device)
        else:
            src = q[..., c["src"]]
        return src * c["mul_rev"] + c["off_rev"], src * c["mul_pri"] + c["off_pri"]

    def _check_q(self, q: torch.Tensor) -> torch.Tensor:
        return as_joint_tensor(q, self.joint_names)

    # ------------------------------------------------------------------ kinematics

    def forward(self, q: torch.Tensor) -> torch.Tensor:
        """Pose of every link in the root link's frame.

        Args:
            q: [..., J] actuated joint values in ``joint_names`` order (rad for revolute and
                continuous, m for prismatic). Any leading batch shape; float32/float64; CPU
                or CUDA. A numpy array or list is accepted and treated as float64.

        Returns:
            [..., L, 4, 4] ``T_root_link`` for each link in ``link_names`` order, with the
            dtype and device of ``q``; differentiable with respect to ``q``.
        """
        q = self._check_q(q)
        c = self._consts(q.dtype, q.device)
        batch = q.shape[:-1]
        qf = q.reshape(-1, self.num_joints)
        angle, disp = self.joint_values(qf)  # [B, M]
        s = torch.sin(angle)[..., None, None]
        one_minus_c = (1.0 - torch.cos(angle))[..., None, None]
        R_loc = c["R_o"] + s * c["A"] + one_minus_c * c["B"]  # [B, M, 3, 3]
        t_loc = c["t_o"] + disp[..., None] * c["u"]  # [B, M, 3]

        n = qf.shape[0]
        eye = torch.eye(3, dtype=q.dtype, device=q.device).expand(n, 3, 3)
        Rs: list[torch.Tensor] = [eye]
        ts: list[torch.Tensor] = [torch.zeros(n, 3, dtype=q.dtype, device=q.device)]
        for k in range(1, self.num_links):
            p = self.parents[k]
            Rl, tl = R_loc[:, k - 1], t_loc[:, k - 1]
            Rp, tp = Rs[p], ts[p]
            Rs.append(Rp @ Rl)
            ts.append((Rp @ tl[..., None])[..., 0] + tp)
        R = torch.stack(Rs, dim=1)  # [B, L, 3, 3]
        t = torch.stack(ts, dim=1)  # [B, L, 3]
        top = torch.cat((R, t[..., None]), dim=-1)
        bottom = torch.zeros(n, self.num_links, 1, 4, dtype=q.dtype, device=q.device)
        bottom[..., 3] = 1.0
        T = torch.cat((top, bottom), dim=-2)
        return T.reshape(*batch, self.num_links, 4, 4)

    def forward_links(self, q: torch.Tensor, links: Sequence[str]) -> torch.Tensor:
        """Poses of selected links.

        Args:
            q: [..., J] joint values.
            links: link names.

        Returns:
            [..., len(links), 4, 4] ``T_root_link``.
        """
        idx = [self.link_index(n) for n in links]
        return self.forward(q)[..., idx, :, :]
