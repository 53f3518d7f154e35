"""Camera-intrinsics diagnosis from mask boundaries: null calibration, recovery, mask-stream cost.

For each seed a synthetic scene is generated (``robogs.synth.scene``: labels rasterised from the
meshes with the true intrinsics), then

* null: the intrinsics fit on the scene as generated (nothing may be reported);
* perturbed: the dataset declares ``fx * 1.03`` and ``cx + 4 px`` (``robogs.synth.mutations.
  perturb_intrinsics``), the fit must find ``dfx = 0.03``, ``dcx = 4 px``;
* small: ``fx * 1.01`` and ``cx + 1 px``, to show the detection limit.

Prints per scene the held-out gain, effect size [sigma], ΔBIC (with the effective number of
independent boundary pixels it uses) and the fitted values with their 95 % half-widths, then per
case the median and largest relative error of dfx and dcx, how often each interval holds the
truth, the ΔBIC range, the largest null gain and effect size (the gate's thresholds must sit
above them), and the wall time of the mask stream of ``compare`` (30 frames) on the scene.

Run: ``.venv/bin/python bench/mask_intrinsics.py [--seeds 0-7] [--size small]``
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import torch


def _seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b or a) + 1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-7")
    ap.add_argument("--size", default="small", choices=("small", "medium"))
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    from robogs.format.dataset import Dataset
    from robogs.physics.intrinsics import (
        EFFECT_SIZE_MIN,
        HELDOUT_MIN_GAIN,
        fit_intrinsics,
    )
    from robogs.physics.masks import mask_boundary
    from robogs.synth.mutations import perturb_intrinsics
    from robogs.synth.scene import synthesize

    print(
        f"machine: {platform.machine()} {platform.processor() or ''} cpus={os.cpu_count()} "
        f"torch threads={torch.get_num_threads()} size={args.size}"
    )
    cases = {"null": None, "3%/4px": (0.03, 4.0), "1%/1px": (0.01, 1.0)}
    res: dict[str, list[tuple[np.ndarray, np.ndarray, object]]] = {c: [] for c in cases}
    stream_s = []
    tmp = Path(tempfile.mkdtemp(prefix="robogs-intr-"))
    try:
        for seed in _seeds(args.seeds):
            root = tmp / f"s{seed}"
            synthesize(root, seed=seed, size=args.size, progress=False)
            t0 = time.perf_counter()
            ms = mask_boundary(Dataset.open(root))
            stream_s.append(time.perf_counter() - t0)
            for case, kw in cases.items():
                ds_root = root
                if kw is not None:
                    ds_root = tmp / f"s{seed}_{case.replace('/', '_').replace('%', '')}"
                    shutil.copytree(root, ds_root)
                    perturb_intrinsics(ds_root, fx_rel=kw[0], cx_px=kw[1])
                f = fit_intrinsics(Dataset.open(ds_root))[0]
                r = f.row
                v = f.values
                half = np.array([(p.high - p.low) / 2 for p in r.params])
                res[case].append((v, half, f))
                print(
                    f"seed {seed} {case:7s} gain {r.heldout_gain:6.3f} size {r.effect_size:5.2f} "
                    f"dBIC {r.delta_bic:7.0f} (n_eff {f.extra['n_effective']:5.0f} of "
                    f"{f.extra['n_points']}) dfx {v[0]:+.4f}±{half[0]:.4f} dfy {v[1]:+.4f}±"
                    f"{half[1]:.4f} dcx {v[2]:+.2f}±{half[2]:.2f} dcy {v[3]:+.2f}±{half[3]:.2f} "
                    f"reported {r.reported} rivals {r.rivals} "
                    f"boundary {f.boundary_px_before:.3f}->{f.boundary_px_after:.3f} px"
                )
            print(
                f"seed {seed} mask stream: {ms.frames} frames {ms.boundary_px:.3f} px, "
                f"{stream_s[-1]:.2f} s"
            )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    for case, kw in cases.items():
        v = np.array([x[0] for x in res[case]])
        half = np.array([x[1] for x in res[case]])
        truth = np.array([kw[0], 0.0, kw[1], 0.0]) if kw else np.zeros(4)
        cover = (np.abs(v - truth) <= half).mean(0)
        rows = [x[2].row for x in res[case]]
        dbic = [r.delta_bic for r in rows]
        line = (
            f"{case:7s} reported {sum(r.reported for r in rows)}/{len(rows)}; interval holds the "
            f"truth (dfx dfy dcx dcy) {' '.join(f'{c:.2f}' for c in cover)}; median half-width "
            f"{' '.join(f'{h:.4g}' for h in np.median(half, 0))}; dBIC {min(dbic):.0f} .. "
            f"{max(dbic):.0f}; max |dfy| {np.abs(v[:, 1]).max():.4f}, max |dcy| "
            f"{np.abs(v[:, 3]).max():.2f} px"
        )
        if kw:
            e_f = np.abs(v[:, 0] / kw[0] - 1) * 100
            e_c = np.abs(v[:, 2] / kw[1] - 1) * 100
            line += (
                f"; relative error dfx median {np.median(e_f):.1f} % (max {e_f.max():.1f} %), "
                f"dcx median {np.median(e_c):.1f} % (max {e_c.max():.1f} %)"
            )
        else:
            line += f"; dfx {v[:, 0].min():+.4f} .. {v[:, 0].max():+.4f}"
        print(line)
    null_gain = [x[2].row.heldout_gain for x in res["null"]]
    null_size = [x[2].row.effect_size for x in res["null"]]
    print(
        f"null max gain {max(null_gain):.3f} (gate {HELDOUT_MIN_GAIN}, ratio "
        f"{HELDOUT_MIN_GAIN / max(max(null_gain), 1e-9):.1f}), max effect size "
        f"{max(null_size):.2f} (gate {EFFECT_SIZE_MIN}, ratio "
        f"{EFFECT_SIZE_MIN / max(max(null_size), 1e-9):.1f}); "
        f"mask stream median {np.median(stream_s):.2f} s for 30 frames"
    )


if __name__ == "__main__":
    main()
