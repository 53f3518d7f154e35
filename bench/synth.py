"""Synthetic scene generation speed, and the scanline rasteriser against a bounding-box baseline.

Prints, for each requested size, the wall time of ``robogs.synth.scene.synthesize`` (targets: small
< 10 s on 2 cores) and its frame rate; then, for one frame of the scene at the medium resolution
(robot + box over the table, the table drawn too), the time of the generator's scanline
rasteriser and of a bounding-box edge-function rasteriser written here as the baseline (the
textbook vectorised method: test every pixel centre of each triangle's bounding box), their
ratio, and whether both give the same label image.

Usage: ``PYTHONPATH=. .venv/bin/python bench/synth.py [--sizes small,medium] [--threads 2] [--append]``
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
import trimesh

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robogs.synth.scene import scene, synthesize  # noqa: E402
from robogs.synth.scene.generate import _camera  # noqa: E402
from robogs.synth.scene.raster import FrameBuffers, PinholeView, project, rasterize  # noqa: E402
from robogs.synth.scene.rigid import invert_T, make_T  # noqa: E402
from robogs.synth.scene.robot_source import generated_ur5  # noqa: E402


def _frame_geometry(
    width: int, height: int
) -> tuple[PinholeView, np.ndarray, np.ndarray, np.ndarray]:
    """World vertices, faces and labels of the scene at a typical arm pose, and the camera."""
    robot = generated_ur5()
    q = np.array([[0.68, -1.54, -1.94, -1.23, 1.57, 0.0]])
    poses = robot.model.fk(q)
    parts = [(robot.meshes[lk], poses[lk][0], i + 1) for i, lk in enumerate(robot.visible_links)]
    box = trimesh.creation.box(extents=scene.BOX_SIZE)
    table = trimesh.creation.box(extents=scene.TABLE_SIZE)
    parts.append((box, make_T(None, (0.45, 0.1, 0.03)), scene.LABEL_BOX))
    parts.append((table, make_T(None, scene.TABLE_CENTER), scene.LABEL_TABLE))
    verts, faces, labels, off = [], [], [], 0
    for mesh, T, lab in parts:
        v = np.asarray(mesh.vertices) @ T[:3, :3].T + T[:3, 3]
        verts.append(v)
        faces.append(np.asarray(mesh.faces) + off)
        labels.append(np.full(len(mesh.faces), lab, np.uint16))
        off += len(v)
    preset = scene.SizePreset(1.0, width, height, 0.01)
    cam = _camera(preset)
    view = PinholeView(width, height, cam.fx, cam.fy, cam.cx, cam.cy, invert_T(cam.T_world_cam))
    return view, np.concatenate(verts), np.concatenate(faces), np.concatenate(labels)


_STATS: dict[str, int] = {}


def _bbox_baseline(
    view: PinholeView, verts: np.ndarray, faces: np.ndarray, labels: np.ndarray
) -> np.ndarray:
    """Label image by testing every pixel centre of every triangle's bounding box."""
    W, H = view.width, view.height
    pu, pv, pz = project(view, verts)
    u, v, z = pu[faces], pv[faces], pz[faces]
    x0 = np.maximum(np.ceil(u.min(1) - 0.5), 0).astype(np.int64)
    x1 = np.minimum(np.floor(u.max(1) - 0.5), W - 1).astype(np.int64)
    y0 = np.maximum(np.ceil(v.min(1) - 0.5), 0).astype(np.int64)
    y1 = np.minimum(np.floor(v.max(1) - 0.5), H - 1).astype(np.int64)
    area = (u[:, 1] - u[:, 0]) * (v[:, 2] - v[:, 0]) - (u[:, 2] - u[:, 0]) * (v[:, 1] - v[:, 0])
    ok = (x1 >= x0) & (y1 >= y0) & (np.abs(area) > 1e-12) & (z.min(1) > 1e-3)
    idx = np.nonzero(ok)[0]
    bw = x1[idx] - x0[idx] + 1
    counts = bw * (y1[idx] - y0[idx] + 1)
    tri = np.repeat(idx, counts)
    off = np.arange(tri.size) - np.repeat(np.cumsum(counts) - counts, counts)
    wrep = np.repeat(bw, counts)
    px, py = x0[tri] + off % wrep, y0[tri] + off // wrep
    cx, cy = px + 0.5, py + 0.5
    ua, va = u[tri, 0], v[tri, 0]
    ub, vb, uc, vc = u[tri, 1] - ua, v[tri, 1] - va, u[tri, 2] - ua, v[tri, 2] - va
    du, dv = cx - ua, cy - va
    wb = (du * vc - uc * dv) / area[tri]
    wc = (ub * dv - du * vb) / area[tri]
    wa = 1 - wb - wc
    inside = (wa >= -1e-9) & (wb >= -1e-9) & (wc >= -1e-9)
    tri, wa, wb, wc = tri[inside], wa[inside], wb[inside], wc[inside]
    pix = py[inside] * W + px[inside]
    iz = 1.0 / z[tri]
    inv = wa * iz[:, 0] + wb * iz[:, 1] + wc * iz[:, 2]
    zbuf = np.zeros(W * H)
    np.maximum.at(zbuf, pix, inv)
    win = inv >= zbuf[pix]
    lab = np.zeros(W * H, np.uint16)
    lab[pix[win]] = labels[tri[win]]
    _STATS["tested"], _STATS["covered"] = int(counts.sum()), int(inside.sum())
    return lab.reshape(H, W)


def _best(fn, repeats: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="small,medium", help="comma-separated sizes to generate")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--append", action="store_true", help="append the output to bench/RESULTS.md")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    lines = [
        f"machine: {platform.machine()} {platform.processor() or ''}, cpu_count={os.cpu_count()}, "
        f"torch threads={torch.get_num_threads()} (the generator itself uses numpy only)"
    ]
    with tempfile.TemporaryDirectory() as tmp:
        for size in args.sizes.split(","):
            preset = scene.SIZES[size]
            t = time.perf_counter()
            synthesize(Path(tmp) / size, size=size, progress=False)
            wall = time.perf_counter() - t
            frames = int(np.floor(preset.duration_s * 30))
            lines.append(
                f"synthesize {size}: {wall:.2f} s for {preset.duration_s:.0f} s of data, "
                f"{preset.width}x{preset.height}, ~{frames} frames ({frames / wall:.0f} frames/s overall)"
            )
    view, verts, faces, labels = _frame_geometry(320, 240)
    lines.append(
        f"rasteriser workload: one 320x240 frame, {len(faces):,} triangles (robot, box, table)"
    )

    def scan() -> np.ndarray:
        buf = FrameBuffers.empty(320, 240, np.zeros((240, 320, 3), np.uint8))
        rasterize(view, verts, faces, labels, np.zeros((len(faces), 3), np.uint8), buf)
        return buf.label_image(320, 240)

    t_scan, lab_scan = _best(scan, 20)
    t_base, lab_base = _best(lambda: _bbox_baseline(view, verts, faces, labels), 5)
    same = np.array_equal(lab_scan, lab_base)
    lines.append(f"scanline rasteriser: {t_scan * 1e3:.2f} ms/frame")
    lines.append(f"baseline bounding-box rasteriser: {t_base * 1e3:.2f} ms/frame")
    lines.append(
        f"  (baseline tests {_STATS['tested']:,} pixel centres; {_STATS['covered']:,} are covered)"
    )
    lines.append(f"speed-up: {t_base / t_scan:.1f}x ; identical label images: {same}")
    text = "\n".join(lines)
    print(text)
    if args.append:
        cmd = "PYTHONPATH=. .venv/bin/python bench/synth.py " + " ".join(sys.argv[1:])
        with open(Path(__file__).with_name("RESULTS.md"), "a") as fh:
            fh.write(
                f"\n\n## synth — synthetic scene generation (2026-11-22)\n\nCommand: `{cmd.strip()}`\n\n"
                f"```\n{text}\n```\n"
            )


if __name__ == "__main__":
    main()
