"""The Gaussian–Mesh–Pixel binding: pose bound Gaussians at any time t.

A Gaussian bound to link L, stored at the rest state t0, moves as

    x(t) = T_world_L(t) · T_world_L(t0)⁻¹ · x(t0)

(Lou et al. 2024, Robo-GS §3.2; the Robostudio code applies P_t = T_t T_0⁻¹ P_0).
``T_world_L(t)`` is forward kinematics of the joint states linearly interpolated
at t; an object Gaussian follows its interpolated pose stream (slerp); table and
background Gaussians are static. The Gaussian's rotation is left-multiplied by
the same rotation, and its SH colour is rotated so that the colour seen from
world direction d after the motion equals the rest colour seen from Rᵀd.

Example:
    >>> g = pose_splats(Dataset.open("scene/"), t_ns=1_500_000_000)  # doctest: +SKIP
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from .dataset import Dataset, Episode
from .errors import FormatError
from .frames import matrix_to_quat, quat_multiply, quat_normalize, quat_to_matrix
from .interp import interp_linear, interp_pose
from .render.gaussians import Gaussians
from .render.sh import sh_basis, sh_degree_of

__all__ = ["Binding", "BoundTarget", "pose_splats", "rotate_sh"]


@dataclass(frozen=True)
class BoundTarget:
    """What a group of Gaussians is bound to.

    Attributes:
        kind: "robot_link", "object" or "static".
        name: link or asset name.
        owner: "robot" or the asset name (whose splat file holds the Gaussians).
    """

    kind: str
    name: str
    owner: str


def _fibonacci_dirs(n: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    i = torch.arange(n, dtype=dtype, device=device) + 0.5
    z = 1.0 - 2.0 * i / n
    r = torch.sqrt(torch.clamp(1.0 - z * z, min=0.0))
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    return torch.stack([r * torch.cos(phi), r * torch.sin(phi), z], dim=-1)


def rotate_sh(sh: torch.Tensor, R: torch.Tensor) -> torch.Tensor:
    """Rotate SH colour coefficients by rotations ``R``.

    Real SH bands are closed under rotation, so the rotated coefficients are the
    exact least-squares solution of ``Y(d)·c' = Y(Rᵀd)·c`` over 64 fixed
    directions (deterministic; exact up to float rounding).

    Args:
        sh: [N, K, 3] coefficients, K in {1, 4, 9, 16}.
        R: [N, 3, 3] rotations (world frame).

    Returns:
        [N, K, 3] rotated coefficients; degree 0 is unchanged.
    """
    k = sh.shape[1]
    degree = sh_degree_of(k)
    if degree is None:
        raise FormatError(f"SH with {k} coefficients is not degree 0..3")
    if degree == 0:
        return sh
    work = torch.float64
    d = _fibonacci_dirs(64, work, sh.device)
    Y = sh_basis(d, degree)  # [S, K]
    Y_pinv = torch.linalg.pinv(Y)  # [K, S]
    d_rot = torch.einsum("nji,sj->nsi", R.to(work), d)  # Rᵀ d, [N, S, 3]
    Y_rot = sh_basis(d_rot.reshape(-1, 3), degree).reshape(R.shape[0], d.shape[0], k)
    M = torch.einsum("ks,nsj->nkj", Y_pinv, Y_rot)  # [N, K, K]
    return torch.einsum("nkj,njc->nkc", M, sh.to(work)).to(sh.dtype)


class Binding:
    """The bound Gaussians of a dataset and the motion of their targets over time.

    Args:
        dataset: the dataset.
        episode: episode id (default: the only one).
        owners: splat owners to include ("robot" and/or asset names); default all that have splats.
        device, dtype: where and in which precision to build the Gaussians.
    """

    def __init__(
        self,
        dataset: Dataset,
        episode: str | None = None,
        *,
        owners: list[str] | None = None,
        device: str | torch.device = "cpu",
        dtype: torch.dtype = torch.float32,
    ) -> None:
        self.dataset = dataset
        self.episode: Episode = dataset.episode(episode)
        self.device = torch.device(device)
        self.dtype = dtype
        if owners is None:
            owners = (["robot"] if "splats" in (dataset.manifest.get("robot") or {}) else []) + [
                a for a, e in sorted(dataset.assets.items()) if "splats" in e
            ]
        self.targets: list[BoundTarget] = []
        parts: dict[str, list[Any]] = {
            k: [] for k in ("means", "quats", "scales", "opac", "sh", "tid", "face", "uv", "off")
        }
        self._rest_links: dict[str, np.ndarray] = {}
        self._rest_objects: dict[str, np.ndarray] = {}
        self._chain = None
        self.chain_note = ""
        kinds = set()
        for owner in owners:
            entry = dataset.splat_entry(owner)
            s = dataset.splats(owner)
            kinds.add(s.kind)
            base = len(self.targets)
            for name in entry["targets"]:
                self.targets.append(self._make_target(owner, name, entry))
            bad = (s.bind_id < -1) | (s.bind_id >= len(entry["targets"]))
            if bad.any():
                raise FormatError(
                    f"{int(bad.sum())} Gaussians of {owner!r} have bind_id outside 0..{len(entry['targets']) - 1}",
                    path=dataset.resolve(entry["path"]),
                    where="bind_id",
                )
            parts["means"].append(s.means)
            parts["quats"].append(s.quats)
            parts["scales"].append(s.log_scales)
            parts["opac"].append(s.opacity_logits)
            parts["sh"].append(s.sh)
            parts["tid"].append(np.where(s.bind_id >= 0, s.bind_id + base, -1))
            parts["face"].append(s.bind_face)
            parts["uv"].append(s.bind_uv)
            parts["off"].append(s.bind_offset)
        if len(kinds) > 1:
            raise FormatError(
                "cannot mix 3DGS and 2DGS splats in one scene", path=dataset.manifest_path
            )
        if not owners:
            raise FormatError(
                "dataset has no splats",
                path=dataset.manifest_path,
                hint="run robogs reconstruct, or add splats with the writer",
            )
        ks = {p.shape[1] for p in parts["sh"]}
        kmax = max(ks)
        sh = [
            np.concatenate([p, np.zeros((p.shape[0], kmax - p.shape[1], 3), p.dtype)], 1)
            for p in parts["sh"]
        ]

        def t(x: Any, dt: torch.dtype = dtype) -> torch.Tensor:
            return torch.as_tensor(np.concatenate(x), dtype=dt, device=self.device)

        self.rest = Gaussians(
            t(parts["means"]),
            quat_normalize(t(parts["quats"])),
            t(parts["scales"]),
            t(parts["opac"]),
            torch.as_tensor(np.concatenate(sh), dtype=dtype, device=self.device),
        )
        self.target_index = t(parts["tid"], torch.long)
        self.bind_face = t(parts["face"], torch.long)
        self.bind_uv = t(parts["uv"])
        self.bind_offset = t(parts["off"])
        self._joint_stream: tuple[torch.Tensor, torch.Tensor] | None = None
        self._object_streams: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    # -- set-up ------------------------------------------------------------------------
    def _make_target(self, owner: str, name: str, entry: dict[str, Any]) -> BoundTarget:
        rest = entry.get("rest", {})
        if owner == "robot":
            self._rest_links[name] = np.zeros(0)
            self._rest_q = rest.get("joint_positions")
            if self._rest_q is None:
                raise FormatError(
                    "robot splats have no rest joint_positions",
                    path=self.dataset.manifest_path,
                    where="robot/splats/rest",
                    hint="record the joint state the splats were captured at",
                )
            return BoundTarget("robot_link", name, owner)
        kind = self.dataset.assets[owner]["kind"]
        if kind == "object":
            pose = (rest.get("object_poses") or {}).get(name)
            if pose is None:
                raise FormatError(
                    f"object {name!r} splats have no rest pose",
                    path=self.dataset.manifest_path,
                    where=f"assets/{owner}/splats/rest/object_poses",
                )
            self._rest_objects[name] = np.asarray(pose, dtype=np.float64)
            return BoundTarget("object", name, owner)
        return BoundTarget("static", name, owner)

    @property
    def chain(self):
        """Forward kinematics of the robot with the current physics revision's fitted joint
        offsets (:func:`robogs.format.kinematics.fitted_chain`); ``chain_note`` says what was
        applied. A missing or unreadable ``physics.json`` leaves the URDF's nominal chain."""
        if self._chain is None:
            from .kinematics import Chain, dataset_fitted_chain

            nominal = Chain.from_urdf(self.dataset.urdf(load_meshes=False))
            self._chain, self.chain_note = dataset_fitted_chain(self.dataset, nominal)
        return self._chain

    def _joints(self) -> tuple[torch.Tensor, torch.Tensor]:
        if self._joint_stream is None:
            tab = self.episode.table("joint_states")
            cols = [f"position.{j}" for j in self.chain.joint_names]
            missing = [c for c in cols if c not in tab.column_names]
            if missing:
                raise FormatError(
                    f"joint_states lacks {', '.join(missing)}",
                    path=self.episode.table_path("joint_states"),
                    hint="record every actuated joint of the URDF",
                )
            t = torch.as_tensor(tab.column("t_ns").to_numpy().astype(np.int64))
            q = torch.as_tensor(
                np.stack([tab.column(c).to_numpy() for c in cols], -1), dtype=torch.float64
            )
            self._joint_stream = (t, q)
        return self._joint_stream

    def _object_stream(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if name not in self._object_streams:
            tab = self.episode.table("object_poses")
            m = np.asarray(tab.column("object").to_pylist()) == name
            if not m.any():
                raise FormatError(
                    f"no poses for object {name!r}", path=self.episode.table_path("object_poses")
                )
            cols = {
                c: tab.column(c).to_numpy()[m]
                for c in ("t_ns", "x", "y", "z", "qw", "qx", "qy", "qz")
            }
            self._object_streams[name] = (
                cols["t_ns"].astype(np.int64),
                np.stack([cols["x"], cols["y"], cols["z"]], -1),
                np.stack([cols["qw"], cols["qx"], cols["qy"], cols["qz"]], -1),
            )
        return self._object_streams[name]

    def set_object_poses(
        self, name: str, t_ns: np.ndarray, xyz: np.ndarray, qwxyz: np.ndarray
    ) -> None:
        """Make object ``name``'s Gaussians follow these poses instead of its recorded stream.

        Args:
            name: object name (a bound target of kind "object").
            t_ns: [N] increasing stamps, int64 ns.
            xyz: [N, 3] ``T_world_object`` translations, m.
            qwxyz: [N, 4] rotations (w, x, y, z).

        Used to render a model's predicted object poses (interpolated like the recorded ones).
        """
        if name not in self._rest_objects:
            raise FormatError(f"{name!r} is not a bound object", where="set_object_poses")
        self._object_streams[name] = (
            np.asarray(t_ns, np.int64),
            np.asarray(xyz, np.float64).reshape(-1, 3),
            np.asarray(qwxyz, np.float64).reshape(-1, 4),
        )

    # -- motion --------------------------------------------------------------------------
    def target_motion(self, t_ns: int) -> torch.Tensor:
        """[n_targets, 4, 4] rigid motion ``T(t) · T(t0)⁻¹`` of every target, float64."""
        out = torch.eye(4, dtype=torch.float64).repeat(len(self.targets), 1, 1)
        link_ids = [i for i, tg in enumerate(self.targets) if tg.kind == "robot_link"]
        if link_ids:
            chain = self.chain
            t, q = self._joints()
            q_t = interp_linear(torch.tensor([int(t_ns)]), t, q, outside="clamp")[0]
            try:
                q0 = torch.tensor(
                    [float(self._rest_q[j]) for j in chain.joint_names], dtype=torch.float64
                )
            except KeyError as exc:
                raise FormatError(
                    f"rest joint_positions lacks joint {exc.args[0]!r}",
                    path=self.dataset.manifest_path,
                    where="robot/splats/rest",
                ) from None
            T = chain.forward(torch.stack([q_t, q0]))  # [2, L, 4, 4]
            idx = [chain.link_index(self.targets[i].name) for i in link_ids]
            out[link_ids] = T[0, idx] @ torch.linalg.inv(T[1, idx])
        for i, tg in enumerate(self.targets):
            if tg.kind != "object":
                continue
            ts, p, qw = self._object_stream(tg.name)
            pos, quat = interp_pose(np.array([int(t_ns)], np.int64), ts, p, qw, outside="clamp")
            T_t = _pose_to_T(torch.as_tensor(pos[0]), torch.as_tensor(quat[0]))
            r = torch.as_tensor(self._rest_objects[tg.name])
            T_0 = _pose_to_T(r[:3], r[3:])
            out[i] = T_t @ torch.linalg.inv(T_0)
        return out

    def pose(self, t_ns: int, *, time_offset_ns: int = 0) -> Gaussians:
        """The Gaussians at dataset time ``t_ns + time_offset_ns`` (world frame)."""
        M = self.target_motion(int(t_ns) + int(time_offset_ns)).to(self.device)
        tid = self.target_index.clamp(min=0)
        bound = (self.target_index >= 0)[:, None]
        Mg = M[tid]  # [N, 4, 4]
        R = Mg[:, :3, :3]
        means64 = self.rest.means.double()
        moved = (R @ means64[..., None])[..., 0] + Mg[:, :3, 3]
        means = torch.where(bound, moved, means64).to(self.dtype)
        qR = matrix_to_quat(M[:, :3, :3]).to(self.dtype)[tid]  # one conversion per target
        quats = torch.where(bound, quat_multiply(qR, self.rest.quats), self.rest.quats)
        sh = self.rest.sh
        if sh.shape[1] > 1:
            # rotate per target (few distinct rotations), then gather
            Rt = M[:, :3, :3]
            eye = torch.eye(3, dtype=Rt.dtype, device=Rt.device)
            sh = sh.clone()
            for i in range(len(self.targets)):
                sel = self.target_index == i
                if sel.any() and not torch.allclose(Rt[i], eye, atol=1e-12):
                    sh[sel] = rotate_sh(sh[sel], Rt[i].expand(int(sel.sum()), 3, 3))
        return Gaussians(means, quats, self.rest.log_scales, self.rest.opacity_logits, sh)


def _pose_to_T(p: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
    T = torch.eye(4, dtype=torch.float64)
    T[:3, :3] = quat_to_matrix(q.double())
    T[:3, 3] = p.double()
    return T


def pose_splats(
    dataset: Dataset, t_ns: int, *, episode: str | None = None, device: str | torch.device = "cpu"
) -> Gaussians:
    """All bound Gaussians of ``dataset`` posed at ``t_ns`` (see :class:`Binding`)."""
    return Binding(dataset, episode, device=device).pose(t_ns)
