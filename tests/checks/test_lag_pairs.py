"""Inter-stream lag for the other pairs: object pose vs a camera's boxes (T015), wrench vs
contact (T016).

Both fixtures are built here with numpy, pyarrow and trimesh: the object's path, the boxes
(corners projected by the pinhole model written below, rounded outwards to pixel edges as a
mask's box is), the pushes and the force are closed forms, and the delays are applied to the
closed forms, so the expected lags come from the construction.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import trimesh

from robogs.format import Dataset
from robogs.format.cameras import CameraModel
from robogs.format.checks.lag_pairs import contact_lag
from robogs.format.validate import validate

T0 = 1_000_000_000
SIZE = 0.05  # cube edge, m
FX, CX, CY, W, H = 500.0, 320.0, 240.0, 640, 480
#: camera 1 m above (0.5, 0, 0) looking straight down (OpenCV axes: x along world x)
R_WC = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])
P_WC = np.array([0.5, 0.0, 1.0])


def _path(t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Object centre [N, 3] (m) and yaw [N] (rad) sliding on the table, up to ~0.2 m/s."""
    xyz = np.stack(
        [
            0.5 + 0.10 * np.sin(1.3 * t_s) + 0.03 * np.sin(3.1 * t_s),
            0.08 * np.sin(0.9 * t_s + 0.3) + 0.02 * np.cos(2.3 * t_s),
            np.full_like(t_s, SIZE / 2),
        ],
        axis=1,
    )
    return xyz, 0.5 * np.sin(0.7 * t_s)


def _boxes(t_s: np.ndarray) -> np.ndarray:
    """[N, 4] pixel-edge boxes (x_min, y_min, x_max exclusive, y_max exclusive) of the cube."""
    xyz, yaw = _path(t_s)
    corners = np.array(np.meshgrid(*[[-SIZE / 2, SIZE / 2]] * 3, indexing="ij")).reshape(3, -1).T
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.zeros((t_s.size, 3, 3))
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = c, -s, s, c, 1.0
    world = np.einsum("nij,vj->nvi", rot, corners) + xyz[:, None]
    cam = (world - P_WC) @ R_WC  # R_WC^T (p - c), row vectors
    u = FX * cam[..., 0] / cam[..., 2] + CX
    v = FX * cam[..., 1] / cam[..., 2] + CY
    return np.stack(
        [np.floor(u.min(1)), np.floor(v.min(1)), np.ceil(u.max(1)), np.ceil(v.max(1))], 1
    )


def _pose_rows(t_s: np.ndarray, delay_s: float, rng: np.random.Generator) -> dict:
    xyz, yaw = _path(t_s - delay_s)
    xyz = xyz + rng.normal(0, 2e-4, xyz.shape)
    return {
        "x": xyz[:, 0],
        "y": xyz[:, 1],
        "z": xyz[:, 2],
        "qw": np.cos(yaw / 2),
        "qx": np.zeros_like(yaw),
        "qy": np.zeros_like(yaw),
        "qz": np.sin(yaw / 2),
    }


def _object_camera_dataset(root: Path, delay_ms: float) -> Path:
    """Object poses at 120 Hz (delayed by ``delay_ms``), its boxes in one camera at 30 Hz."""
    rng = np.random.default_rng(1)
    t_p = T0 + 3_100_000 + np.arange(0, 6 * 120) * 8_333_333
    t_b = T0 + np.arange(0, 6 * 30) * 33_333_333
    box = _boxes((t_b - T0) * 1e-9)
    T_wc = np.eye(4)
    T_wc[:3, :3], T_wc[:3, 3] = R_WC, P_WC
    ep = "episodes/ep000"
    with Dataset.create(root) as w:
        w.set_camera(CameraModel("cam0", W, H, FX, FX, CX, CY, T_world_cam=T_wc))
        w.write_bytes(
            "assets/box/mesh.ply", trimesh.creation.box([SIZE] * 3).export(file_type="ply")
        )
        w.set_asset("box", kind="object", mesh="assets/box/mesh.ply")
        poses = {"t_ns": pa.array(t_p, pa.int64()), "object": ["box"] * t_p.size}
        poses.update(_pose_rows((t_p - T0) * 1e-9, delay_ms * 1e-3, rng))
        w.write_table(f"{ep}/object_poses.parquet", pa.table(poses), kind="object_poses")
        boxes = {
            "t_ns": pa.array(t_b, pa.int64()),
            "camera": ["cam0"] * t_b.size,
            "frame_index": pa.array(np.arange(t_b.size), pa.int64()),
            "label_id": pa.array(np.full(t_b.size, 100), pa.int32()),
            **{c: box[:, i] for i, c in enumerate(("x_min", "y_min", "x_max", "y_max"))},
        }
        w.write_table(f"{ep}/boxes2d.parquet", pa.table(boxes), kind="boxes2d")
        seg = {
            "label_id": pa.array([100], pa.int32()),
            "category": ["box"],
            "instance": pa.array([1], pa.int32()),
            "kind": ["object"],
            "target": ["box"],
        }
        w.write_table(f"{ep}/segments.parquet", pa.table(seg), kind="segments")

        def stream(kind: str, rate: float | None) -> dict:
            return {
                "kind": kind,
                "path": f"{ep}/{kind}.parquet",
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "nominal_rate_hz": rate,
            }

        streams = {
            "object_poses": stream("object_poses", 120.0),
            "boxes2d": stream("boxes2d", 30.0),
            "segments": {**stream("segments", None), "stamp_source": "none"},
        }
        streams["segments"].pop("nominal_rate_hz")
        w.add_episode("ep000", start_ns=T0, end_ns=int(t_p[-1]), streams=streams)
        w.commit()
    return root


def _findings(root: Path, code: str) -> list:
    return [f for f in validate(root, select=[code]).findings if f.code == code]


@pytest.mark.parametrize("delay_ms", [12.0, -9.0])
def test_delayed_object_poses_are_caught_against_the_boxes(tmp_path: Path, delay_ms: float) -> None:
    (f,) = _findings(_object_camera_dataset(tmp_path / "ds", delay_ms), "T015")
    assert f.value == pytest.approx(delay_ms, abs=1.0)
    assert f.severity == "error" and f.location.stream == "object_poses"


def test_object_poses_on_time_give_no_t015(tmp_path: Path) -> None:
    assert _findings(_object_camera_dataset(tmp_path / "ds", 0.0), "T015") == []


def test_small_object_motion_in_the_synthetic_scene_gives_no_t015(clean_root: Path) -> None:
    assert _findings(clean_root, "T015") == []


# --------------------------------------------------------------------------- T016

#: pushes (start s, end s, speed m/s) of the object along x
PUSHES = ((1.0, 1.8, 0.10), (3.0, 3.6, 0.15), (4.5, 5.2, 0.08))
FORCE_N, RISE_S = 2.0, 0.002


def _object_x(t_s: np.ndarray) -> np.ndarray:
    """x (m) of an object pushed quasi-statically: it moves at the pusher's speed in a push."""
    x = np.zeros_like(t_s)
    for a, b, v in PUSHES:
        x += v * np.clip(t_s - a, 0.0, b - a)
    return x


def _force(t_s: np.ndarray) -> np.ndarray:
    """Contact force magnitude (N): a 2 ms linear rise at contact, a fall at release."""
    f = np.zeros_like(t_s)
    for a, b, _v in PUSHES:
        f += FORCE_N * np.clip((t_s - a) / RISE_S, 0, 1) * np.clip((b - t_s) / RISE_S, 0, 1)
    return f


def _contact_series(delay_ms: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    t_o = T0 + 2_700_000 + np.arange(0, 6 * 120) * 8_333_333
    t_w = T0 + 900_000 + np.arange(0, 6 * 500) * 2_000_000
    x = _object_x((t_o - T0) * 1e-9)
    p_o = np.stack([0.4 + x, 0.1 + 0 * x, 0.025 + 0 * x], 1) + rng.normal(0, 1e-4, (t_o.size, 3))
    mag = _force((t_w - T0) * 1e-9 - delay_ms * 1e-3)
    f = np.stack([-mag, 0.2 * mag, 0 * mag], 1) + [0.3, -0.2, -2.5]  # sensor offset
    f += rng.normal(0, 0.03, f.shape)
    return t_w, f, t_o, p_o


@pytest.mark.parametrize("delay_ms", [0.0, 12.0, -20.0])
def test_contact_lag_recovers_a_known_delay(delay_ms: float) -> None:
    est = contact_lag(*_contact_series(delay_ms))
    assert est is not None and est.pushes == len(PUSHES)
    assert est.lag_ms == pytest.approx(delay_ms, abs=1.5)
    assert est.lo_ms <= delay_ms + 1.5 and est.hi_ms >= delay_ms - 1.5


def test_contact_lag_needs_a_force_that_rises() -> None:
    t_w, f, t_o, p_o = _contact_series(0.0)
    flat = np.zeros_like(f) + [0.3, -0.2, -2.5] + np.random.default_rng(2).normal(0, 0.03, f.shape)
    assert contact_lag(t_w, flat, t_o, p_o) is None


def _contact_dataset(
    root: Path, t_w, f, t_o, p_o, rates=(120.0, 500.0), command_kind: str | None = None
) -> Path:
    """One episode: object poses ``p_o`` at ``t_o`` (no rotation), forces ``f`` at ``t_w``; with
    ``command_kind``, also a joint command stream (``actions``) that declares it."""
    ep = "episodes/ep000"
    with Dataset.create(root) as w:
        w.set_asset("box", kind="object")
        q = np.zeros(t_o.size)
        poses = {"t_ns": pa.array(t_o, pa.int64()), "object": ["box"] * t_o.size}
        poses.update({"x": p_o[:, 0], "y": p_o[:, 1], "z": p_o[:, 2], "qw": q + 1, "qx": q})
        poses.update({"qy": q, "qz": q})
        w.write_table(f"{ep}/object_poses.parquet", pa.table(poses), kind="object_poses")
        wr = {"t_ns": pa.array(t_w, pa.int64()), "frame": ["tool0"] * t_w.size}
        wr.update({c: f[:, i] for i, c in enumerate(("fx", "fy", "fz"))})
        wr.update({c: np.zeros(t_w.size) for c in ("tx", "ty", "tz")})
        w.write_table(f"{ep}/wrenches.parquet", pa.table(wr), kind="wrenches")
        streams = {
            k: {
                "kind": k,
                "path": f"{ep}/{k}.parquet",
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "nominal_rate_hz": hz,
            }
            for k, hz in zip(("object_poses", "wrenches"), rates, strict=True)
        }
        if command_kind is not None:
            act = {"t_ns": pa.array(t_o, pa.int64()), "command.j1": np.zeros(t_o.size)}
            w.write_table(f"{ep}/actions.parquet", pa.table(act), kind="actions")
            streams["actions"] = {
                "kind": "actions",
                "path": f"{ep}/actions.parquet",
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "command_kind": command_kind,
            }
        start, end = int(min(t_w[0], t_o[0])), int(max(t_w[-1], t_o[-1]))
        w.add_episode("ep000", start_ns=start, end_ns=end, streams=streams)
        w.commit()
    return root


def _wrench_dataset(root: Path, delay_ms: float) -> Path:
    return _contact_dataset(root, *_contact_series(delay_ms))


def test_delayed_wrench_is_caught_against_the_contacts(tmp_path: Path) -> None:
    (f,) = _findings(_wrench_dataset(tmp_path / "ds", 20.0), "T016")
    assert f.value == pytest.approx(20.0, abs=1.5)
    assert f.location.stream == "wrenches" and "over 3 pushes" in f.message
    assert f.severity == "error"


def test_wrench_on_time_gives_no_t016(tmp_path: Path) -> None:
    assert _findings(_wrench_dataset(tmp_path / "ds", 0.0), "T016") == []


def test_wrench_ahead_of_the_motion_is_a_note(tmp_path: Path) -> None:
    """A force before the motion can be physical (a build-up to breakaway): info, not error."""
    (f,) = _findings(_wrench_dataset(tmp_path / "ds", -20.0), "T016")
    assert f.severity == "info" and f.value == pytest.approx(-20.0, abs=1.5)


def test_force_controlled_pushes_give_no_t016_error(tmp_path: Path) -> None:
    """The force-controlled pushes of ``robogs.synth.scenarios.force_push`` (the force ramps up
    to break the box away, so it leads the motion on clean stamps) are at most a note."""
    from robogs.synth.scenarios.force_push import make_force_push

    trajs = make_force_push(seed=0).trajectories
    t_o = np.concatenate([tr.t_ns for tr in trajs])
    p_o = np.concatenate([tr.object_pos for tr in trajs])
    t_w = np.concatenate([tr.wrench_t_ns for tr in trajs])
    f = np.concatenate([tr.wrench_tool for tr in trajs])
    _contact_dataset(tmp_path / "ds", t_w, f, t_o, p_o, rates=(None, None))
    found = _findings(tmp_path / "ds", "T016")
    assert all(x.severity == "info" and x.value < 0 for x in found), [x.to_dict() for x in found]


def test_boxes_from_masks_time_like_the_boxes2d_rows(
    clean_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The synthetic scene's boxes2d rows are the boxes of its label masks: without the rows,
    T015 reads the masks and must use the same frames, stamps and centres (same fit). The
    scene's box moves at ~3 px/s, below T015's speed gate: the gate is lifted here."""
    import json
    import shutil

    from robogs.format.checks import lag_pairs
    from robogs.format.checks.context import CheckContext
    from robogs.format.checks.lag_pairs import _poses, box_lag

    monkeypatch.setattr(lag_pairs, "_MIN_PX_SPEED", 0.0)

    def fit(root: Path):
        ctx = CheckContext(root)
        ep = ctx.episodes[0]
        t_p, v_p = _poses(ctx, ep.streams["object_poses"]["path"])["box"]
        return box_lag(ctx, ep, "box", "cam0", t_p, v_p)

    rows = fit(clean_root)
    masks_root = tmp_path / "ds"
    shutil.copytree(clean_root, masks_root)
    m = json.loads((masks_root / "manifest.json").read_text())
    m["episodes"][0]["streams"].pop("boxes2d")
    (masks_root / "manifest.json").write_text(json.dumps(m))
    masks = fit(masks_root)
    assert rows is not None and masks is not None
    assert rows[1].endswith("boxes2d.parquet") and masks[1].endswith("labels.parquet")
    assert masks[0].samples == rows[0].samples
    assert masks[0].pose_lag_ms == pytest.approx(rows[0].pose_lag_ms, abs=1e-6)
