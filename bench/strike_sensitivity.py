"""How a flush strike's outcome depends on the box's start tilt: generator, planar, MuJoCo.

A horizontal capsule (radius 10 mm, length 40 mm: design A's pusher) strikes the 80 x 60 mm
face of design A's box flush, 2 mm off the face's centre line, at ``v`` m/s for 48 mm, then
stops; the box's centre of mass sits (12, -8) mm off its centre (design A's hidden
``com_offset``) or at the centre. The box starts turned by a tilt in [-0.8, 0.8] deg (17
values) against the capsule; the figure is its yaw 0.4 s after the pusher stops, relative to the
capsule's heading: 0 for every tilt when the face ends flush against the capsule.

Printed per source (the ground-truth simulator of the synthetic scenarios, the planar engine,
the MuJoCo engine, and MuJoCo with the object-pusher pair of stops 49-52, 2.5 steps x damping
ratio 1.7, which stop 53 replaced by 5 steps x 1.2) and speed: the range of the final yaw over the tilts [deg], the largest jump
between neighbouring tilts (0.1 deg apart) [deg], and the range as a ratio to the tilts' own
range, 1.6 deg (the in-run baseline: a box that keeps its start tilt has ratio 1; one that ends
flush whatever its tilt, 0; above 1 the strike amplifies the start pose's uncertainty). The design A pushes run at 0.30 / 0.425 / 0.55 m/s;
the start yaw the fitter sees is known to about 0.1-0.2 deg (0.4 deg yaw noise per sample).

    .venv/bin/python bench/strike_sensitivity.py [--speeds 0.25,0.35,0.425,0.55]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

SIZE, R, L = (0.08, 0.06, 0.05), 0.01, 0.04
"""Box size [m], capsule radius and length [m] (design A)."""
COM = (0.012, -0.008)
TILTS = np.radians(np.linspace(-0.8, 0.8, 17))
GAP, LATERAL, CONTACT, DT, FINE_DT = 0.003, 0.002, 0.045, 1e-3, 2.5e-4
OLD_PAIR = None
"""MuJoCo's object-pusher pair of stops 49-52 (2.5 steps x damping ratio 1.7), set in main."""


def _old_pair():
    import dataclasses

    from robogs.format.mjcf import PLANAR_SETTINGS

    return dataclasses.replace(PLANAR_SETTINGS, pusher_timeconst_steps=2.5, pusher_dampratio=1.7)


def _physics(com: tuple[float, float]) -> dict:
    box = {
        "equation": "rigid",
        "mass_kg": 0.4,
        "size_m": list(SIZE),
        "friction_dynamic": 0.35,
        "com_m": [com[0], com[1], 0.0],
    }
    return {
        "gravity_mps2": [0.0, 0.0, -9.81],
        "objects": {
            "box": box,
            "table": {"equation": "static", "plane_z_m": 0.0},
            "pusher": {"equation": "kinematic", "shape": "capsule", "radius_m": R, "length_m": L},
        },
    }


def _path(v: float, dt: float, n: int) -> np.ndarray:
    """[n, 3] capsule centre: along +x at ``v`` for GAP + CONTACT, then still."""
    start = np.array([-SIZE[0] / 2 - R - GAP, LATERAL, SIZE[2] / 2])
    s = np.minimum(np.arange(n) * v * dt, GAP + CONTACT)
    return start[None] + s[:, None] * np.array([1.0, 0.0, 0.0])[None]


def _engine_yaw(name: str, v: float, com: tuple[float, float], settings=None) -> np.ndarray:
    from robogs.physics.engines import get_engine, make_drive
    from robogs.physics.engines.mujoco_engine import MujocoEngine

    n = int(round((GAP + CONTACT) / v / DT)) + 400
    t = len(TILTS)
    pos = np.repeat(_path(v, DT, n)[None], t, 0)
    obs = np.repeat((np.arange(0, n, 10) * DT)[None], t, 0)
    init = np.repeat(np.array([[0.0, 0.0, SIZE[2] / 2]]), t, 0)
    drive = make_drive(DT, pos, np.zeros((t, n)), obs, init, TILTS)
    if name == "mujoco":
        eng = MujocoEngine(_physics(com), settings=settings, pusher_speed=v)
    else:
        eng = get_engine(name)(_physics(com))
    yaw = eng.rollout(drive).yaw("box")[0]
    return np.degrees(yaw[:, -1])


def _generator_yaw(v: float, com: tuple[float, float]) -> np.ndarray:
    from robogs.synth.scenarios.sim import EEPath, TruthBox, TruthEffect, simulate_truth

    n = int(round(((GAP + CONTACT) / v + 0.4) / FINE_DT))
    t = len(TILTS)
    path = EEPath(
        FINE_DT,
        np.repeat(_path(v, FINE_DT, n)[None], t, 0),
        np.zeros((t, n)),
        np.zeros((t, n), bool),
    )
    box = TruthBox(
        size=SIZE, mass=0.4, mu_s=0.45, mu_d=0.35, restitution=0.0, com=(0.0, 0.0),
        table_z=0.0, pusher_radius=R, pusher_length=L, gravity=9.81,
    )  # fmt: skip
    eff = TruthEffect("com_offset", {"dx": com[0], "dy": com[1]}) if any(com) else TruthEffect()
    _, yaw = simulate_truth(box, eff, path, np.zeros((t, 2)), TILTS)
    return np.degrees(yaw[:, -1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speeds", default="0.25,0.35,0.425,0.55", help="strike speeds [m/s]")
    args = ap.parse_args()
    torch.set_num_threads(1)
    global OLD_PAIR
    OLD_PAIR = _old_pair()
    speeds = [float(s) for s in args.speeds.split(",")]
    print(
        f"machine: {platform.machine()} {os.cpu_count()} cores, torch {torch.__version__} "
        f"threads {torch.get_num_threads()}, OMP {os.environ['OMP_NUM_THREADS']}"
    )
    print("tilts [deg]:", " ".join(f"{x:5.1f}" for x in np.degrees(TILTS)))
    sources = {
        "generator": _generator_yaw,
        "planar": lambda v, c: _engine_yaw("planar", v, c),
        "mujoco": lambda v, c: _engine_yaw("mujoco", v, c),
        "mujoco, pair of stops 49-52": lambda v, c: _engine_yaw("mujoco", v, c, OLD_PAIR),
    }
    for com in (COM, (0.0, 0.0)):
        print(f"\nCoM offset {1e3 * com[0]:.0f}, {1e3 * com[1]:.0f} mm")
        print(
            "| source | speed m/s | final yaw range deg | largest jump deg | range / tilts' | s |"
        )
        print("|---|---|---|---|---|---|")
        for name, fn in sources.items():
            base = float(np.ptp(np.degrees(TILTS)))
            for v in speeds:
                t0 = time.perf_counter()
                y = fn(v, com)
                rng, jump = float(np.ptp(y)), float(np.max(np.abs(np.diff(y))))
                ratio = rng / base
                print(
                    f"| {name} | {v:.3g} | {rng:.2f} | {jump:.2f} | {ratio:.2f} | "
                    f"{time.perf_counter() - t0:.1f} |",
                    flush=True,
                )
                print("    final yaw:", " ".join(f"{x:5.2f}" for x in y))


if __name__ == "__main__":
    main()
