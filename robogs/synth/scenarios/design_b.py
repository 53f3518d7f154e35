"""Design B: a second hidden-effect scenario design that differs from the first in every variable.

=========================  ======================================  ===============================
variable                   design A (:mod:`.generate`)             design B (this module)
=========================  ======================================  ===============================
trajectories               20 (9 pushes, 4 off-centre, 4 slides,   9 (6 pushes in 3 opposite
                           3 drops)                                pairs, 2 slides, 1 drop)
free slide after contact   up to ~130 mm                           <= 60 mm (:data:`MAX_SLIDE_M`)
pusher                     capsule r 10 mm, 40 mm long             sphere r 12 mm
object                     80 x 60 x 50 mm, 0.40 kg, mu_d 0.35     50 x 50 x 40 mm, 0.25 kg,
                                                                   mu_d 0.30, mu_s 0.40
camera                     30 fps, 1 mm, 0.5 deg, jitter 2 ms,     60 fps, 2 mm, 1 deg, jitter
                           no drops                                4 ms, 8 % dropped samples
encoders                   500 Hz, 1e-4 rad                        250 Hz, 2e-4 rad
gaps between trajectories  10 s                                    2-6 s, random
=========================  ======================================  ===============================

Detectability is decided here, from the expected ΔBIC of adding the true effect: the noiseless
observations with the effect against the best plain model (the dynamic friction refitted
without the effect, parabolic search as in :func:`.generate.detectability`) give
``chi2_0 = sum ((obs_e - obs_0) / sigma)^2`` over the samples kept (times the kept fraction);
the expected fall of chi^2 when the effect's ``k`` parameters are added is ``chi2_0 + k`` (a
non-central chi^2), so ``E[ΔBIC] ~= -(chi2_0 + k) + k ln n`` (Schwarz 1978, noise variance
known, ``n`` the samples kept). A case is detectable when ``E[ΔBIC] <= -10`` ("strong" evidence, Kass & Raftery
1995, J. Am. Stat. Assoc. 90). The generator shares no code with ``robogs.physics``.

``quasi_static=True`` replaces the motions by six slow pushes (0.04-0.06 m/s) whose objects
stop within a sample of losing contact: the data of item 6 of issue 17.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from robogs.synth.scenarios.generate import (
    FAMILY,
    FINE_DT,
    TRUE_PARAMS,
    ScenarioRecording,
    ScenarioTrajectory,
    _observe,
    _path,
    _quat_mul,
    _quat_yaw,
    _sample,
    _small_rot,
    observed_with_sigma,
)
from robogs.synth.scenarios.motions import Motion, grasp_place, push, release_slide
from robogs.synth.scenarios.sim import TruthBox, TruthEffect, simulate_truth

__all__ = [
    "BOX_B",
    "NOISE_B",
    "CAMERA_HZ_B",
    "ENCODER_HZ_B",
    "MAX_SLIDE_M",
    "N_PARAMS",
    "make_design_b",
    "expected_delta_bic",
    "detectable_b",
]

BOX_B = TruthBox(
    size=(0.05, 0.05, 0.04),
    mass=0.25,
    mu_s=0.40,
    mu_d=0.30,
    pusher_radius=0.012,
    pusher_length=0.0,
)
"""Object, friction and a sphere pusher of design B."""
CAMERA_HZ_B = 60.0
ENCODER_HZ_B = 250.0
NOISE_B: dict[str, float] = {
    "pos": 2e-3,
    "rot": float(np.radians(1.0)),
    "jitter": 4e-3,
    "encoder": 2e-4,
    "drop": 0.08,
}
"""Camera position [m] and orientation [rad] noise, stamp jitter [s], encoder noise [rad],
fraction of camera samples dropped."""
PUSH_SPEEDS = (0.30, 0.42, 0.36, 0.45, 0.33, 0.39)
"""Release speeds of the six pushes [m/s]: free slides v^2 / (2 mu_d g) of 15-34 mm."""
SLIDE_SPEEDS_B = (0.35, 0.52)
"""Release speeds of the two release-and-slide motions [m/s] (slides of 21-46 mm)."""
MAX_SLIDE_M = 0.06
N_PARAMS = {k: len(v) for k, v in TRUE_PARAMS.items()}
"""Parameters of each effect (the ``k`` of the expected ΔBIC)."""
DBIC_DETECTABLE = -10.0


def _motions(box: TruthBox, quasi_static: bool) -> list[Motion]:
    out: list[Motion] = []
    speeds = (0.04, 0.05, 0.06, 0.04, 0.05, 0.06) if quasi_static else PUSH_SPEEDS
    for j, v in enumerate(speeds):
        heading = 0.4 + np.pi * (j % 2) + (j // 2) * 2 * np.pi / 3  # three opposite pairs
        out.append(push(box, FINE_DT, heading, float(v), 0.0, f"bpush_{j}", contact=0.03))
    if not quasi_static:
        for j, v in enumerate(SLIDE_SPEEDS_B):
            out.append(release_slide(box, FINE_DT, 2.5 + 2.2 * j, v, f"bslide_{j}"))
        out.append(grasp_place(box, FINE_DT, -0.8, 0.03, "bplace_0"))
    return out


@functools.lru_cache(maxsize=32)
def _truth(effect: str, quasi_static: bool, mu_d: float | None):
    motions = _motions(BOX_B, quasi_static)
    path = _path(motions)
    eff = TruthEffect(effect, TRUE_PARAMS[effect]) if effect != "none" else TruthEffect()
    dyn = eff if FAMILY[effect] == "contact" else TruthEffect()
    pos, yaw = simulate_truth(
        BOX_B,
        dyn,
        path,
        np.stack([m.box_xy for m in motions]),
        np.array([m.box_yaw for m in motions]),
        mu_d=mu_d,
    )
    return motions, path, pos, yaw


@functools.lru_cache(maxsize=32)
def expected_delta_bic(effect: str, quasi_static: bool = False) -> float:
    """Expected ΔBIC of adding ``effect`` to the plain model on design B (module docstring)."""
    if effect == "none":
        return 0.0
    _, _, pos, yaw = _truth(effect, quasi_static, None)
    n_fine = pos.shape[1]
    t = np.arange(0.0, (n_fine - 1) * FINE_DT - 0.05, 1 / CAMERA_HZ_B)
    shift = TRUE_PARAMS[effect].get("delta", 0.0) if effect == "time_offset" else 0.0
    keep = 1.0 - NOISE_B["drop"]

    obs, pe, ye, sig, sig_y = observed_with_sigma(pos, yaw, t, shift, effect, NOISE_B, CAMERA_HZ_B)

    def chi2(mu: float) -> float:
        _, _, p0, y0 = _truth("none", quasi_static, round(mu, 6))
        a, b = obs(p0, y0, 0.0, "none")
        return keep * float(np.sum(((pe - a) / sig) ** 2) + np.sum(((ye - b) / sig_y) ** 2))

    mus = BOX_B.mu_d * np.array([0.9, 0.95, 1.0, 1.05, 1.1])
    if FAMILY[effect] == "sensor":
        best = chi2(BOX_B.mu_d)
    else:
        vals = np.array([chi2(m) for m in mus])
        c = np.polyfit(mus, vals, 2)  # chi2(mu) is near a parabola around its minimum
        m_star = float(np.clip(-c[1] / (2 * c[0]), mus[0], mus[-1])) if c[0] > 0 else mus[2]
        best = min(float(vals.min()), chi2(m_star))
    n = keep * 4 * pos.shape[0] * len(t)
    k = N_PARAMS[effect]
    return float(-(best + k) + k * np.log(n))


def detectable_b(effect: str, quasi_static: bool = False) -> bool:
    """Whether the generator deems ``effect`` detectable on design B (E[ΔBIC] <= -10)."""
    return effect != "none" and expected_delta_bic(effect, quasi_static) <= DBIC_DETECTABLE


def make_design_b(
    effect: str = "none", *, seed: int = 0, quasi_static: bool = False
) -> ScenarioRecording:
    """One design-B scenario with ``effect`` hidden (``"none"``: null data).

    ``meta`` carries the truth, ``expected_delta_bic`` and ``detectable``.
    """
    if effect not in TRUE_PARAMS:
        raise ValueError(f"unknown effect {effect!r}; known: {sorted(TRUE_PARAMS)}")
    rng = np.random.default_rng(10_000 + seed)
    motions, path, pos, yaw = _truth(effect, quasi_static, None)
    n_t, n_fine = pos.shape[:2]
    dur = (n_fine - 1) * FINE_DT
    delta = TRUE_PARAMS[effect]["delta"] if effect == "time_offset" else 0.0
    enc_t = np.arange(0.0, dur, 1 / ENCODER_HZ_B)
    t0 = 1_750_000_000_000_000_000
    trajs = []
    for i, m in enumerate(motions):
        tc = np.arange(rng.uniform(0, 1 / CAMERA_HZ_B), dur - 0.05, 1 / CAMERA_HZ_B)
        tc = tc[rng.uniform(size=len(tc)) >= NOISE_B["drop"]]  # dropped samples
        p_obs, y_obs = _observe(effect, _sample(pos[i], tc), _sample(yaw[i], tc))
        p_obs = p_obs + rng.normal(0.0, NOISE_B["pos"], p_obs.shape)
        q = _quat_mul(_quat_yaw(y_obs), _small_rot(rng.normal(0.0, NOISE_B["rot"], (len(tc), 3))))
        stamps = tc + delta + rng.normal(0.0, NOISE_B["jitter"], len(tc))
        order = np.argsort(stamps)
        ee_p = _sample(path.pos[i], enc_t) + rng.normal(
            0.0, 0.6 * NOISE_B["encoder"], (len(enc_t), 3)
        )
        grasp = path.grasp[i][np.clip(np.round(enc_t / FINE_DT).astype(int), 0, n_fine - 1)]
        trajs.append(
            ScenarioTrajectory(
                name=m.name,
                t_ns=t0 + np.round(stamps[order] * 1e9).astype(np.int64),
                object_pos=p_obs[order],
                object_quat=q[order],
                ee_t_ns=t0 + np.round(enc_t * 1e9).astype(np.int64),
                ee_pos=ee_p,
                ee_quat=_quat_yaw(_sample(path.yaw[i], enc_t)),
                grasp=grasp,
                kind=m.kind,
            )
        )
        t0 += int((dur + rng.uniform(2.0, 6.0)) * 1e9)  # gap before the next trajectory
    box = BOX_B
    sx, sy, sz = box.size
    physics: dict[str, Any] = {
        "revision": 1,
        "gravity_mps2": [0.0, 0.0, -box.gravity],
        "objects": {
            "box": {
                "equation": "rigid",
                "mass_kg": box.mass,
                "com_m": [0.0, 0.0, 0.0],
                "inertia_kgm2": [
                    [box.mass * (sy**2 + sz**2) / 12.0, 0.0, 0.0],
                    [0.0, box.mass * (sx**2 + sz**2) / 12.0, 0.0],
                    [0.0, 0.0, box.inertia_z],
                ],
                "size_m": list(box.size),
                "friction_static": box.mu_s,
                "friction_dynamic": round(float(box.mu_d * rng.uniform(0.85, 1.15)), 4),
                "restitution": box.restitution,
                "damping_linear": 0.0,
                "damping_angular": 0.0,
            },
            "table": {"equation": "static", "plane_z_m": box.table_z},
            "pusher": {
                "equation": "kinematic",
                "link": "ee",
                "shape": "sphere",
                "radius_m": box.pusher_radius,
                "length_m": 0.0,
                "grasp_joint": "grasp",
                "grasp_threshold": 0.5,
            },
        },
        "effects": [],
        "sensors": {"camera": {"time_offset_ns": 0}},
    }
    edbic = expected_delta_bic(effect, quasi_static)
    meta = {
        "design": "B-quasi-static" if quasi_static else "B",
        "effect": effect,
        "family": FAMILY[effect],
        "true_params": dict(TRUE_PARAMS[effect]),
        "true_friction_dynamic": box.mu_d,
        "noise_levels": dict(NOISE_B),
        "seed": seed,
        "expected_delta_bic": edbic,
        "detectable": detectable_b(effect, quasi_static),
    }
    return ScenarioRecording(trajectories=trajs, physics=physics, object_name="box", meta=meta)
