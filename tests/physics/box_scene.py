"""The box-on-a-table scene shared by the engine tests: a 0.4 kg box (80 x 60 x 50 mm) on the
plane z = 0, pushed by a 1 cm capsule pusher 40 mm long; SI units, gravity -z."""

from __future__ import annotations

G = 9.81  # [m/s^2]


def box_on_table(mu: float) -> dict:
    """A physics document (``physics.json`` shape) with the box's friction ``mu`` (static =
    dynamic)."""
    return {
        "gravity_mps2": [0.0, 0.0, -G],
        "objects": {
            "box": {
                "equation": "rigid",
                "mass_kg": 0.4,
                "size_m": [0.08, 0.06, 0.05],
                "friction_dynamic": mu,
                "friction_static": mu,
            },
            "table": {"equation": "static", "plane_z_m": 0.0},
            "pusher": {
                "equation": "kinematic",
                "shape": "capsule",
                "radius_m": 0.01,
                "length_m": 0.04,
            },
        },
    }
