"""Write a hidden-effect scenario as a robogs dataset (through the robogs Dataset writer).

One episode per trajectory (``segment`` = the trajectory name, so held-out splits are by
trajectory), with ``object_poses``, ``ee_poses`` and ``joint_states`` (a ``grasp`` pseudo-joint,
1 while the gripper holds the object), and physics.json with the nominal values the tool
starts from. The truth (hidden effect, its values, noise levels) is written *beside* the dataset,
to ``<OUT>.truth.json`` (:func:`truth_path`), so that it never travels with the data and the tool
cannot read it by accident. :func:`read_truth` loads it back for benches and tests.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pyarrow as pa

from robogs.synth.scenarios.generate import ScenarioRecording

__all__ = ["write_scenario", "truth_path", "read_truth"]


def _pose_table(t: np.ndarray, key: str, name: str, pos: np.ndarray, quat: np.ndarray) -> pa.Table:
    return pa.table(
        {
            "t_ns": pa.array(t, pa.int64()),
            key: pa.array([name] * len(t), pa.string()),
            "x": pos[:, 0],
            "y": pos[:, 1],
            "z": pos[:, 2],
            "qw": quat[:, 0],
            "qx": quat[:, 1],
            "qy": quat[:, 2],
            "qz": quat[:, 3],
        }
    )


def truth_path(out_path: str | Path) -> Path:
    """Where :func:`write_scenario` puts the truth of the dataset at ``out_path``: beside it,
    ``<parent>/<name>.truth.json`` (outside the dataset folder)."""
    out = Path(out_path)
    return out.with_name(out.name + ".truth.json")


def read_truth(out_path: str | Path) -> dict:
    """The truth written beside the scenario dataset at ``out_path`` (see :func:`truth_path`)."""
    from robogs.format.errors import InputError

    path = truth_path(out_path)
    if not path.is_file():
        raise InputError(
            "no scenario truth beside the dataset",
            path=path,
            hint="write the scenario with robogs.synth.scenarios.write_scenario (robogs synth --effect)",
        )
    return json.loads(path.read_text())


def write_scenario(
    recording: ScenarioRecording,
    out_path: str | Path,
    *,
    overwrite: bool = False,
    wrenches: bool = False,
):
    """Write ``recording`` to ``out_path`` and its truth to :func:`truth_path` (beside it, never
    inside); return the opened ``Dataset``. ``wrenches``: also write the trajectories' pusher
    force (``wrench_t_ns``, ``wrench_force`` [N], world axes) as a ``wrenches`` stream in frame
    ``world`` (torques 0)."""
    from robogs.format.dataset import Dataset

    link = recording.physics["objects"]["pusher"].get("link", "ee")
    grasp_joint = recording.physics["objects"]["pusher"].get("grasp_joint", "grasp")
    w = Dataset.create(out_path, name="scenario", overwrite=overwrite)  # no hint of the truth
    w.set_asset(recording.object_name, kind="object")  # object_poses name a declared asset (S007)
    others = sorted({n for tr in recording.trajectories for n in getattr(tr, "others", {})})
    for name in others:  # more tracked objects (``others``: name -> (t_ns, pos, quat))
        w.set_asset(name, kind="object")
    sigma_ms = 1e3 * float(recording.meta.get("noise_levels", {}).get("jitter", 0.0))
    if sigma_ms > 0:
        # The camera stamps carry a designed Gaussian jitter of sigma_ms; the dataset declares
        # that timing quality so the validator judges it against it (the p99 of |N(0, s)| is
        # 2.58 s, the largest of a few thousand samples about 4 s).
        w.manifest["budgets"] = {
            "time.jitter_p99_ms": round(max(5.0, 3.0 * sigma_ms), 3),
            "time.jitter_max_ms": round(max(20.0, 4.5 * sigma_ms), 3),
        }
    for tr in recording.trajectories:
        ep = tr.name
        poses = [
            _pose_table(tr.t_ns, "object", recording.object_name, tr.object_pos, tr.object_quat)
        ]
        for n, (t_o, p_o, q_o) in getattr(tr, "others", {}).items():
            poses.append(_pose_table(t_o, "object", n, p_o, q_o))
        table = poses[0] if len(poses) == 1 else pa.concat_tables(poses).sort_by("t_ns")
        w.write_table(f"episodes/{ep}/object_poses.parquet", table, kind="object_poses")
        w.write_table(
            f"episodes/{ep}/ee_poses.parquet",
            _pose_table(tr.ee_t_ns, "link", link, tr.ee_pos, tr.ee_quat),
            kind="ee_poses",
        )
        w.write_table(
            f"episodes/{ep}/joint_states.parquet",
            pa.table(
                {
                    "t_ns": pa.array(tr.ee_t_ns, pa.int64()),
                    f"position.{grasp_joint}": np.asarray(tr.grasp, dtype=float),
                }
            ),
            kind="joint_states",
        )
        streams = {
            "object_poses": {
                "kind": "object_poses",
                "path": f"episodes/{ep}/object_poses.parquet",
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "nominal_rate_hz": 30.0,
            },
            "ee_poses": {
                "kind": "ee_poses",
                "path": f"episodes/{ep}/ee_poses.parquet",
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "nominal_rate_hz": 500.0,
                "derived": ["x", "y", "z", "qw", "qx", "qy", "qz"],
            },
            "joint_states": {
                "kind": "joint_states",
                "path": f"episodes/{ep}/joint_states.parquet",
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "nominal_rate_hz": 500.0,
            },
        }
        wt = getattr(tr, "wrench_t_ns", None)
        if wrenches and wt is not None and len(wt):
            f = np.asarray(tr.wrench_force, dtype=float)
            cols = {"t_ns": pa.array(wt, pa.int64()), "frame": ["world"] * len(wt)}
            cols.update({c: f[:, i] for i, c in enumerate(("fx", "fy", "fz"))})
            cols.update({c: np.zeros(len(wt)) for c in ("tx", "ty", "tz")})
            w.write_table(f"episodes/{ep}/wrenches.parquet", pa.table(cols), kind="wrenches")
            streams["wrenches"] = {
                "kind": "wrenches",
                "path": f"episodes/{ep}/wrenches.parquet",
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "nominal_rate_hz": round(1e9 / float(np.median(np.diff(wt))), 3),
            }
        stamps = [tr.t_ns, tr.ee_t_ns] + ([wt] if "wrenches" in streams else [])
        start, end = int(min(t[0] for t in stamps)), int(max(t[-1] for t in stamps))
        w.add_episode(ep, start_ns=start, end_ns=end, streams=streams, segment=tr.name)
    physics = {k: v for k, v in recording.physics.items() if k != "revision"}
    w.set_physics(physics, note="nominal values of the scenario")
    ds = w.commit()
    meta = {k: (float(v) if isinstance(v, np.floating) else v) for k, v in recording.meta.items()}
    _write_atomic(truth_path(out_path), json.dumps(meta, default=float, indent=1) + "\n")
    return ds


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.part")
    tmp.write_text(text)
    os.replace(tmp, path)
