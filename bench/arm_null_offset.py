"""False positives of the arm selection on null torque logs at two effort-noise levels.

Usage: ``OMP_NUM_THREADS=1 .venv/bin/python bench/arm_null_offset.py [SEEDS]`` (default 20).
For each seed and effort-noise scale (1x and 4x the generator's nominal 0.05-0.2 N m) it writes
a null log (:mod:`robogs.synth.armlogs`, effect ``none``, 4 segments of 4 s), imports it and
runs :func:`robogs.physics.arm.diagnose_arm`; it prints what was selected and the time offset's
figures against the null quantile, then the count of runs that selected anything.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import torch

from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.physics.arm import diagnose_arm
from robogs.synth.armlogs import ArmLogSpec, generate_armlog, ur5_urdf

NOMINAL = (0.2, 0.2, 0.15, 0.05, 0.05, 0.05)


def main(seeds: int) -> None:
    """Run the null suite and print one line per run and the totals."""
    torch.set_num_threads(1)
    root = Path(tempfile.mkdtemp(prefix="arm_null_"))
    urdf = root / "ur5.urdf"
    urdf.write_text(ur5_urdf())
    for scale in (1.0, 4.0):
        hits = 0
        for seed in range(seeds):
            d = root / f"{scale}_{seed}"
            noise = tuple(scale * x for x in NOMINAL)
            spec = ArmLogSpec(
                effect="none", seed=100 + seed, segments=4, duration_s=4.0, effort_noise=noise
            )
            generate_armlog(d / "logs", urdf, spec)
            convert_path(d / "logs", d / "ds", fmt="tabular", options=ConvertOptions(urdf=urdf))
            t = time.perf_counter()
            rep = diagnose_arm(d / "ds")
            r = {e["name"]: e for e in rep["effects"]}["effort_time_offset"]
            hits += bool(rep["selected"])
            print(
                f"noise x{scale:g} seed {seed}: selected {rep['selected']} "
                f"({time.perf_counter() - t:.1f} s); time offset dBIC {r['delta_bic']:.1f}, "
                f"held-out gain {r['heldout_gain_sigma2']:.2g} vs null {r['gate_heldout_sigma2']:.2g}"
                f" sigma^2, size {r['effect_size_sigma']:.2f} sigma",
                flush=True,
            )
        print(f"noise x{scale:g}: {hits} of {seeds} null runs selected an effect")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seeds", nargs="?", type=int, default=20, help="null seeds per noise level")
    main(ap.parse_args().seeds)
