"""Backlash play operator: the prefix-scan form against the sequential loop it replaced.

Input: 10 minutes of 6 joints at 1 kHz (600 000 samples, a random walk), 13 parameter sets at
once (a forward-difference Jacobian of 12 backlash widths plus the base point), float64.

    .venv/bin/python bench/play.py
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _loop(x0: torch.Tensor, q: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    out = torch.empty_like(q)
    x = x0
    for k in range(q.shape[-2]):
        qk = q[..., k, :]
        x = torch.minimum(torch.maximum(x, qk - w[..., 0, :]), qk + w[..., 0, :])
        out[..., k, :] = x
    return out


def main(argv: list[str] | None = None) -> None:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    torch.set_num_threads(1)
    from robogs.physics.arm.kinematic_model import play_scan

    gen = torch.Generator().manual_seed(0)
    m, n, j = 13, 600_000, 6
    q = torch.cumsum(torch.randn(1, n, j, generator=gen, dtype=torch.float64) * 1e-3, dim=-2)
    q = q.expand(m, -1, -1)
    w = torch.rand(m, 1, j, generator=gen, dtype=torch.float64) * 0.01
    x0 = q[:, 0] - w[:, 0]
    t0 = time.perf_counter()
    fast = play_scan(x0, q, w)
    t_scan = time.perf_counter() - t0
    t0 = time.perf_counter()
    slow = _loop(x0, q, w)
    t_loop = time.perf_counter() - t0
    err = float((fast - slow).abs().max())
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, torch threads 1"
    )
    print(
        f"play operator, {m} sets x {n} samples x {j} joints: scan {t_scan:.2f} s, loop {t_loop:.2f} s"
    )
    print(f"speed-up (loop / scan): {t_loop / t_scan:.1f}x; max difference {err:.1e} rad")


if __name__ == "__main__":
    main()
