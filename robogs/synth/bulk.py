"""Large robogs datasets for load tests, written with pyarrow and hashlib directly.

This writer follows ``spec/FORMAT.md`` by hand and imports nothing from ``robogs.format``, so
the validator under test never shares a code path with the data it checks. The robot is a
planar 3R arm (three revolute joints about +z, links 0.30, 0.25 and 0.10 m along x), whose
end-effector pose has a closed form:

    x = sum_i L_i cos(q_1 + ... + q_i),  y = sum_i L_i sin(q_1 + ... + q_i),
    z = 0.1 m,  yaw = q_1 + q_2 + q_3.

Each episode holds ``joint_states`` (positions and analytic velocities of a sum of sines) and
``ee_poses`` (the closed-form pose of ``tool0``), both at ``rate_hz`` on an int64 ns clock.
Tables are written in row groups of 65,536 rows, like the robogs writer. Large datasets use the
chunked layout of spec 1.1.0 (``chunk_size``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

__all__ = [
    "write_bulk_dataset",
    "write_bulk_bags",
    "SHARD_ABOVE",
    "DEFAULT_CHUNK_SIZE",
    "planar_urdf",
    "bulk_cli",
    "LINKS_M",
    "JOINTS",
]

LINKS_M = (0.30, 0.25, 0.10)
"""Link lengths along x [m]: joint1->joint2, joint2->joint3, joint3->tool0."""

JOINTS = ("joint1", "joint2", "joint3")
_BASE_Z = 0.1
_T0_NS = 1_700_000_000_000_000_000
_ROW_GROUP = 1 << 16
_CHUNK_ROWS = 1 << 18
#: ``robogs synth --episodes N`` shards above this many episodes (the flat manifest lists every
#: file: 2 entries per episode) ...
SHARD_ABOVE = 100
#: ... in chunks of this many episodes, as LeRobot v3's chunk folders
DEFAULT_CHUNK_SIZE = 1000


def planar_urdf() -> str:
    """URDF text of the planar 3R arm (inertials valid, no meshes)."""

    def link(name: str, mass: float) -> str:
        i = mass * 0.01
        return (
            f'<link name="{name}"><inertial><origin xyz="0 0 0"/><mass value="{mass}"/>'
            f'<inertia ixx="{i}" ixy="0" ixz="0" iyy="{i}" iyz="0" izz="{i}"/></inertial></link>'
        )

    def joint(
        name: str, parent: str, child: str, x: float, z: float, kind: str = "revolute"
    ) -> str:
        lim = '<axis xyz="0 0 1"/><limit lower="-3.1" upper="3.1" effort="50" velocity="4"/>'
        return (
            f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{x} 0 {z}" rpy="0 0 0"/>{lim if kind == "revolute" else ""}</joint>'
        )

    parts = ['<?xml version="1.0"?>', '<robot name="planar3r">', link("base_link", 2.0)]
    parts += [link("link1", 1.0), link("link2", 0.8), link("link3", 0.3), link("tool0", 0.05)]
    parts.append(joint("joint1", "base_link", "link1", 0.0, _BASE_Z))
    parts.append(joint("joint2", "link1", "link2", LINKS_M[0], 0.0))
    parts.append(joint("joint3", "link2", "link3", LINKS_M[1], 0.0))
    parts.append(joint("tool0_joint", "link3", "tool0", LINKS_M[2], 0.0, "fixed"))
    parts.append("</robot>")
    return "\n".join(parts) + "\n"


def _motion(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Amplitudes [3, 3] rad, angular frequencies [3, 3] rad/s and phases [3, 3] rad."""
    amp = rng.uniform(0.1, 0.6, (3, 3))
    omega = rng.uniform(0.5, 3.0, (3, 3))
    phase = rng.uniform(0.0, 2 * math.pi, (3, 3))
    return amp, omega, phase


def _chunks(n: int, rate_hz: float, motion, t0_ns: int) -> Iterator[dict[str, np.ndarray]]:
    amp, omega, phase = motion
    period_ns = int(round(1e9 / rate_hz))
    for lo in range(0, n, _CHUNK_ROWS):
        idx = np.arange(lo, min(n, lo + _CHUNK_ROWS), dtype=np.int64)
        t_ns = t0_ns + idx * period_ns
        t = (idx * period_ns).astype(np.float64) * 1e-9
        arg = omega[None] * t[:, None, None] + phase[None]  # [N, joint, harmonic]
        q = (amp[None] * np.sin(arg)).sum(-1)
        qd = (amp[None] * omega[None] * np.cos(arg)).sum(-1)
        cum = np.cumsum(q, axis=1)
        x = sum(L * np.cos(cum[:, i]) for i, L in enumerate(LINKS_M))
        y = sum(L * np.sin(cum[:, i]) for i, L in enumerate(LINKS_M))
        yaw = cum[:, 2]
        yield {"t_ns": t_ns, "q": q, "qd": qd, "x": x, "y": y, "yaw": yaw}


def _write_tables(ep_dir: Path, n: int, rate_hz: float, motion, t0_ns: int) -> None:
    js_schema = pa.schema(
        [("t_ns", pa.int64())]
        + [(f"position.{j}", pa.float64()) for j in JOINTS]
        + [(f"velocity.{j}", pa.float64()) for j in JOINTS]
    )
    ee_schema = pa.schema(
        [("t_ns", pa.int64()), ("link", pa.string())]
        + [(c, pa.float64()) for c in ("x", "y", "z", "qw", "qx", "qy", "qz")]
    )
    ep_dir.mkdir(parents=True, exist_ok=True)
    with (
        pq.ParquetWriter(ep_dir / "joint_states.parquet", js_schema, compression="zstd") as js,
        pq.ParquetWriter(ep_dir / "ee_poses.parquet", ee_schema, compression="zstd") as ee,
    ):
        for c in _chunks(n, rate_hz, motion, t0_ns):
            m = len(c["t_ns"])
            cols = [pa.array(c["t_ns"], pa.int64())]
            cols += [pa.array(c["q"][:, i]) for i in range(3)]
            cols += [pa.array(c["qd"][:, i]) for i in range(3)]
            js.write_table(pa.Table.from_arrays(cols, schema=js_schema), row_group_size=_ROW_GROUP)
            half = 0.5 * c["yaw"]
            zeros = np.zeros(m)
            ecols = [
                pa.array(c["t_ns"], pa.int64()),
                pa.array(np.full(m, "tool0", dtype=object), pa.string()),
                pa.array(c["x"]),
                pa.array(c["y"]),
                pa.array(np.full(m, _BASE_Z)),
                pa.array(np.cos(half)),
                pa.array(zeros),
                pa.array(zeros),
                pa.array(np.sin(half)),
            ]
            ee.write_table(pa.Table.from_arrays(ecols, schema=ee_schema), row_group_size=_ROW_GROUP)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 20):
            h.update(chunk)
    return h.hexdigest()


def _file_entry(p: Path) -> dict[str, Any]:
    entry: dict[str, Any] = {"sha256": _sha256(p), "size": p.stat().st_size}
    if p.suffix == ".parquet":
        entry["rows"] = pq.ParquetFile(p).metadata.num_rows
    return entry


def _write_json(path: Path, doc: Any) -> None:
    """Write JSON through a temporary file renamed over ``path``."""
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(doc, indent=1), encoding="utf-8")
    os.replace(tmp, path)


def write_bulk_dataset(
    root: str | Path,
    *,
    n_episodes: int,
    duration_s: float,
    rate_hz: float = 500.0,
    seed: int = 0,
    chunk_size: int | None = None,
    progress: Any = None,
) -> dict[str, Any]:
    """Write a dataset of ``n_episodes`` episodes of ``duration_s`` seconds each; return its manifest.

    With ``chunk_size`` the dataset has the chunked layout of spec 1.1.0 (FORMAT.md 9.1):
    episode ``k`` in ``episodes/chunk-{k // chunk_size:03d}/<id>/``, one ``index.json`` per
    chunk with its episodes and files, and a manifest that lists only the robot and the
    indexes. Without it, the flat 1.0 layout (``episodes/<id>/``, every file in the manifest).
    The manifest is written last, atomically (a temporary file renamed over it).

    Args:
        root: folder to create (must not exist).
        n_episodes: number of episodes.
        duration_s: length of each episode, s.
        rate_hz: joint and end-effector sample rate, Hz.
        seed: motion seed.
        chunk_size: episodes per chunk (None: flat layout).
        progress: called as ``progress(episodes_written, n_episodes)`` (optional).
    """
    root = Path(root)
    root.mkdir(parents=True)
    rng = np.random.default_rng(seed)
    (root / "robot").mkdir()
    (root / "robot" / "robot.urdf").write_text(planar_urdf(), encoding="utf-8")
    n = int(round(duration_s * rate_hz))
    period_ns = int(round(1e9 / rate_hz))
    width = max(3, len(str(n_episodes - 1)))
    episodes: list[dict[str, Any]] = []
    chunks: dict[int, dict[str, Any]] = {}
    for k in range(n_episodes):
        eid = f"ep{k:0{width}d}"
        folder = (
            f"episodes/{eid}"
            if chunk_size is None
            else f"episodes/chunk-{k // chunk_size:03d}/{eid}"
        )
        t0 = _T0_NS + k * (n * period_ns + 10_000_000_000)
        _write_tables(root / folder, n, rate_hz, _motion(rng), t0)
        streams = {
            name: {
                "kind": name,
                "path": f"{folder}/{name}.parquet",
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "nominal_rate_hz": rate_hz,
            }
            for name in ("joint_states", "ee_poses")
        }
        entry = {"id": eid, "start_ns": t0, "end_ns": t0 + (n - 1) * period_ns, "streams": streams}
        if chunk_size is None:
            episodes.append(entry)
        else:
            part = chunks.setdefault(k // chunk_size, {"episodes": [], "files": {}})
            part["episodes"].append(entry)
            for name in ("joint_states", "ee_poses"):
                rel = f"{folder}/{name}.parquet"
                part["files"][rel] = _file_entry(root / rel)
        if progress is not None:
            progress(k + 1, n_episodes)
    files: dict[str, dict[str, Any]] = {}
    if chunk_size is None:
        for p in sorted(root.rglob("*")):
            if p.is_file():
                files[p.relative_to(root).as_posix()] = _file_entry(p)
    else:
        files["robot/robot.urdf"] = _file_entry(root / "robot" / "robot.urdf")
    manifest: dict[str, Any] = {
        "format": "robogs",
        "spec_version": "1.0.0" if chunk_size is None else "1.1.0",
        "name": root.name,
        "created_utc": "2026-01-01T00:00:00+00:00",
        "generator": {"name": "robogs.synth.bulk"},
        "conventions": {
            "units": "SI",
            "world_frame": {
                "name": "world",
                "up": "+z",
                "handedness": "right",
                "origin": "robot_base",
            },
            "quaternion_order": "wxyz",
            "camera_axes": "opencv",
            "time_unit": "ns",
        },
        "robot": {"urdf": "robot/robot.urdf", "base_link": "base_link", "ee_link": "tool0"},
        "episodes": episodes,
        "files": files,
    }
    if chunk_size is not None:
        index = []
        for c, part in sorted(chunks.items()):
            rel = f"episodes/chunk-{c:03d}/index.json"
            doc = {"format": "robogs-chunk", "chunk": c, **part}
            _write_json(root / rel, doc)
            files[rel] = _file_entry(root / rel)
            rows = sum(f["rows"] for f in part["files"].values())
            index.append(
                {
                    "index": rel,
                    "episodes": len(part["episodes"]),
                    "files": len(part["files"]),
                    "rows": rows,
                }
            )
        manifest["shards"] = {
            "layout": "chunked",
            "chunk_size": chunk_size,
            "episodes": n_episodes,
            "chunks": index,
        }
        manifest["files"] = dict(sorted(files.items()))
    _write_json(root / "manifest.json", manifest)
    return manifest


def bulk_cli(args: argparse.Namespace) -> int:
    """``robogs synth OUT --episodes N [--episode-seconds S] [--seed K] [--force]``."""
    n, secs, out = int(args.episodes), float(args.episode_seconds), Path(args.out)
    if n < 1 or not (0.01 <= secs <= 3600.0):
        print(
            "robogs synth: error: --episodes must be >= 1 and --episode-seconds in [0.01, 3600]",
            file=sys.stderr,
        )
        return 2
    if out.exists():
        if not args.force:
            print(f"robogs synth: error: {out} exists (hint: --force replaces it)", file=sys.stderr)
            return 2
        shutil.rmtree(out)

    def show(done: int, total: int) -> None:
        if not args.quiet and (done == total or done % max(1, total // 20) == 0):
            print(f"\r{done}/{total} episodes", end="\n" if done == total else "", file=sys.stderr)

    chunk = getattr(args, "chunk_size", None)
    if chunk is None:
        chunk = DEFAULT_CHUNK_SIZE if n > SHARD_ABOVE else 0
    if chunk < 0:
        print("robogs synth: error: --chunk-size must be >= 0", file=sys.stderr)
        return 2
    write_bulk_dataset(
        out,
        n_episodes=n,
        duration_s=secs,
        seed=int(args.seed),
        chunk_size=chunk or None,
        progress=show,
    )
    layout = f"sharded, {chunk} episodes per chunk" if chunk else "flat"
    print(f"wrote {out} ({n} episodes of {secs:g} s, planar 3R arm at 500 Hz; {layout})")
    return 0


def write_bulk_bags(
    folder: str | Path,
    *,
    n_bags: int,
    duration_s: float,
    rate_hz: float = 200.0,
    seed: int = 0,
    corrupt: tuple[int, ...] = (),
    pause_s: float = 0.0,
) -> list[Path]:
    """Write ``n_bags`` ROS 2 MCAP files ``bag_KKKK.mcap``, each one ``/joint_states`` episode of
    the planar 3R arm (header stamps on a 1 ms grid; log time 2 ms later).

    Args:
        folder: where to write (created).
        n_bags: number of bags.
        duration_s: length of each, s.
        rate_hz: JointState rate, Hz.
        seed: motion seed.
        corrupt: indices of bags cut to their first 40 % (no footer, no summary: unreadable).
        pause_s: a pause (s) added before sample ``round(duration_s * rate_hz) // 2`` of each
            bag (stamps after it shifted), for ``--split-at-gaps``.
    """
    from mcap_ros2.writer import Writer
    from rosbags.typesys import Stores, get_typestore

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    store = get_typestore(Stores.ROS2_HUMBLE)
    msgdef = store.generate_msgdef("sensor_msgs/msg/JointState", ros_version=2)[0]
    rng = np.random.default_rng(seed)
    n = int(round(duration_s * rate_hz))
    period_ns = int(round(1e9 / rate_hz))
    out = []
    for k in range(n_bags):
        motion = _motion(rng)
        t0 = _T0_NS + k * (n * period_ns + 10_000_000_000)
        path = folder / f"bag_{k:04d}.mcap"
        with open(path, "wb") as fh:
            w = Writer(fh)
            schema = w.register_msgdef("sensor_msgs/msg/JointState", msgdef)
            for c in _chunks(n, rate_hz, motion, t0):
                for i, t in enumerate(c["t_ns"].tolist()):
                    if t >= t0 + (n // 2) * period_ns:
                        t += int(round(pause_s * 1e9))
                    msg = {
                        "header": {
                            "stamp": {"sec": t // 1_000_000_000, "nanosec": t % 1_000_000_000},
                            "frame_id": "",
                        },
                        "name": list(JOINTS),
                        "position": c["q"][i].tolist(),
                        "velocity": c["qd"][i].tolist(),
                        "effort": [],
                    }
                    log = t + 2_000_000
                    w.write_message("/joint_states", schema, msg, log_time=log, publish_time=log)
            w.finish()
        if k in corrupt:
            data = path.read_bytes()
            path.write_bytes(data[: int(len(data) * 0.4)])
        out.append(path)
    return out
