"""The MuJoCo engine against closed-form contact cases (tolerances in mm), the engine registry,
and mesh substitution.

Oracles:

* sliding to rest: Coulomb friction decelerates a block at mu g, so it stops after
  ``v0^2 / (2 mu g)``; semi-implicit Euler at dt stops it ``v0 dt / 2`` early (0.3 mm at
  0.6 m/s), inside the 1 mm tolerance;
* incline: below the friction angle the block sticks; above it slides with
  ``a = g (sin(theta) - mu cos(theta))``, distance ``a t^2 / 2``;
* off-centre point push, quasi-static, frictionless pusher, ellipsoidal limit surface
  (Lynch, Maekawa & Tanie 1992): the wrench (F, 0, -e F) gives the twist
  ``(vx, vy, w) ~ (F, 0, -e F / c^2)``; the pusher point moves at ``vx (1 + e^2 / c^2)``, so the
  block turns by ``-e / (c^2 + e^2)`` rad per metre of push. ``c`` (torque over force limit)
  lies between the mean footprint radius (uniform pressure) and the corner radius (MuJoCo's
  box-plane contact puts the pressure at the four corners), which bounds the turn;
* two blocks, one sliding into the other: momentum is conserved through the short impact, so
  the post-impact speeds sum to the pre-impact speed whatever the restitution; each then
  slides to rest, so ``sqrt(2 mu g dA) + sqrt(2 mu g dB) = v1``.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from robogs.format.errors import InputError
from robogs.format.mjcf import MAX_HULL_VERTICES, collision_hull, scene_mjcf
from robogs.physics.engines import ObjectState, choose_engine, get_engine, make_drive

G = 9.81
SIZE = (0.08, 0.06, 0.05)
HZ = 0.5 * SIZE[2]


def _physics(mu: float = 0.4, *, pusher: dict | None = None, table: dict | None = None) -> dict:
    objects = {
        "box": {"equation": "rigid", "mass_kg": 0.4, "size_m": list(SIZE), "friction_dynamic": mu},
        "table": {"equation": "static", "plane_z_m": 0.0, **(table or {})},
    }
    if pusher is not None:
        objects["pusher"] = {"equation": "kinematic", **pusher}
    return {"gravity_mps2": [0.0, 0.0, -G], "objects": objects}


def _still_drive(n_t: int, seconds: float, dt: float = 1e-3):
    """A drive without a pusher: S grid steps, poses wanted at 0 and at the end."""
    s = int(round(seconds / dt)) + 1
    obs = np.tile([[0.0, (s - 1) * dt]], (n_t, 1))
    return make_drive(
        dt, np.zeros((n_t, s, 3)), np.zeros((n_t, s)), obs, np.zeros((n_t, 3)), np.zeros(n_t)
    )


def _at(pos, vel=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0)) -> ObjectState:
    return ObjectState(
        pos=np.array([pos], float), quat=np.array([quat], float), vel=np.array([vel], float)
    )


# --------------------------------------------------------------------------- (a) slide to rest
@pytest.mark.parametrize(("v0", "mu"), [(0.3, 0.2), (0.6, 0.5), (0.6, 0.2)])
def test_block_slides_to_rest_after_v0_squared_over_2_mu_g(v0: float, mu: float) -> None:
    eng = get_engine("mujoco")(_physics(mu))
    d_true = v0**2 / (2 * mu * G)
    out = eng.rollout(
        _still_drive(1, 2 * v0 / (mu * G) + 0.2), {"box": _at((0, 0, HZ), (v0, 0, 0))}
    )
    p = out.pos["box"][0, 0, -1]
    assert abs(p[0] - d_true) * 1e3 < 1.0, (p[0], d_true)
    assert abs(p[1]) * 1e3 < 0.1
    assert abs(out.yaw("box")[0, 0, -1]) < math.radians(0.1)


def test_slide_distance_follows_the_friction_parameter() -> None:
    """Parameter sets change the object-table pair friction: d scales as 1/mu."""
    eng = get_engine("mujoco")(_physics(0.3))
    mus = [0.2, 0.3, 0.6]
    out = eng.rollout(
        _still_drive(1, 0.6), {"box": _at((0, 0, HZ), (0.5, 0, 0))},
        params={"objects.box.friction_dynamic": mus},
    )  # fmt: skip
    for i, mu in enumerate(mus):
        assert abs(out.pos["box"][i, 0, -1, 0] - 0.25 / (2 * mu * G)) * 1e3 < 1.0


# --------------------------------------------------------------------------- (b) incline
def _incline(theta: float, mu: float, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """The block released at rest on a plane tilted by ``theta`` about y; returns the start
    and end positions and the downhill unit vector."""
    n = np.array([math.sin(theta), 0.0, math.cos(theta)])
    eng = get_engine("mujoco")(_physics(mu, table={"normal": n.tolist(), "point_m": [0, 0, 0]}))
    q = (math.cos(theta / 2), 0.0, math.sin(theta / 2), 0.0)
    out = eng.rollout(_still_drive(1, seconds), {"box": _at(n * HZ, quat=q)})
    downhill = np.array([math.cos(theta), 0.0, -math.sin(theta)])
    return out.pos["box"][0, 0, -1] - out.pos["box"][0, 0, 0], downhill


def test_block_below_the_friction_angle_stays_put() -> None:
    mu = 0.5  # friction angle 26.6 deg
    move, downhill = _incline(math.radians(20.0), mu, 1.0)
    assert abs(move @ downhill) * 1e3 < 0.5
    assert abs(move[1]) * 1e3 < 0.5


@pytest.mark.parametrize("deg", [30.0, 35.0])
def test_block_above_the_friction_angle_accelerates_at_g_sin_minus_mu_cos(deg: float) -> None:
    mu, t = 0.5, 0.5
    th = math.radians(deg)
    move, downhill = _incline(th, mu, t)
    expected = 0.5 * G * (math.sin(th) - mu * math.cos(th)) * t**2
    assert abs(move @ downhill - expected) * 1e3 < 3.0, (move @ downhill, expected)


# --------------------------------------------------------------------------- (c) off-centre push
def _push_drive(start: np.ndarray, heading: np.ndarray, speed: float, dist: float, dt=1e-3):
    """Constant-speed pusher from ``start`` along ``heading`` for ``dist`` m, then 0.3 s still."""
    n_move = int(round(dist / speed / dt))
    s = np.concatenate([np.arange(n_move + 1) * speed * dt, np.full(300, n_move * speed * dt)])
    p = start[None] + s[:, None] * heading[None]
    obs = (np.arange(0, len(s), 10) * dt)[None]
    return make_drive(dt, p[None], np.zeros((1, len(s))), obs, np.array([[0, 0, HZ]]), np.zeros(1))


def test_off_centre_push_turns_the_block_by_the_quasi_static_rate() -> None:
    mu, r, e = 0.4, 0.005, 0.015  # pusher radius, contact offset from the centre line
    eng = get_engine("mujoco")(_physics(mu, pusher={"shape": "sphere", "radius_m": r}))
    gap, push = 0.005, 0.03  # travel before contact, travel in contact
    start = np.array([-SIZE[0] / 2 - r - gap, e, HZ])
    out = eng.rollout(_push_drive(start, np.array([1.0, 0, 0]), 0.05, gap + push))
    turn = float(out.yaw("box")[0, 0, -1])
    hx, hy = SIZE[0] / 2, SIZE[1] / 2
    u = (np.arange(200) + 0.5) / 200 - 0.5
    c_uniform = float(np.hypot(*np.meshgrid(u * SIZE[0], u * SIZE[1])).mean())
    c_corner = math.hypot(hx, hy)
    lo, hi = (push * e / (c**2 + e**2) for c in (c_corner, c_uniform))
    assert turn < 0, "a push above the centre line turns the block clockwise"
    assert 0.8 * lo <= -turn <= 1.2 * hi, (math.degrees(turn), math.degrees(lo), math.degrees(hi))
    # the block moved forward about as far as the pusher travelled in contact, less the turn
    assert 0.5 * push < out.pos["box"][0, 0, -1, 0] < push + 1e-3
    # in mm: the quasi-static push integrated (the planar joint set's limit surface is the
    # ellipsoid with c = the face's mean radius; the corner-loaded one, c = half diagonal, is
    # the counterfactual and must miss)
    pos, yaw = out.pos["box"][0, 0, -1, :2], turn
    for c, hits in ((c_uniform, True), (c_corner, False)):
        q_pos, q_yaw = _quasi_static_push(start[:2], r, 0.05, gap + push, c)
        pos_mm = float(np.linalg.norm(pos - q_pos)) * 1e3
        corner_mm = abs(yaw - q_yaw) * c_corner * 1e3  # a corner's displacement from the turn
        assert (pos_mm < 1.0 and corner_mm < 1.0) == hits, (c, pos_mm, corner_mm)


def _quasi_static_push(
    start: np.ndarray, r: float, v: float, travel: float, c: float, n: int = 20000
) -> tuple[np.ndarray, float]:
    """Final (x, y) [m] and yaw [rad] of the block under a frictionless sphere pusher moving
    along +x from ``start`` (its centre, world frame) at ``v`` for ``travel`` m, quasi-static on
    an ellipsoidal limit surface of characteristic length ``c`` [m] (Lynch, Maekawa & Tanie
    1992; Howe & Cutkosky 1996): the body twist is proportional to ``(F_x, F_y, M / c^2)``,
    with the contact force along the face normal (+x body) at the pusher's body-frame ``y``,
    scaled so the face keeps up with the pusher. Explicit Euler over ``n`` steps."""
    hx = SIZE[0] / 2
    dt = travel / v / n
    xb, th = np.zeros(2), 0.0
    for i in range(n):
        d = start + np.array([v * i * dt, 0.0]) - xb
        ct, st = math.cos(th), math.sin(th)
        px, py = ct * d[0] + st * d[1], -st * d[0] + ct * d[1]
        if px < -hx - r:  # not yet touching the face
            continue
        k = v * ct / (1.0 + py * py / c**2)  # body-x speed: the face moves with the pusher
        xb = xb + dt * k * np.array([ct, st])
        th -= dt * k * py / c**2
    return xb, th


def test_pusher_friction_drags_the_block_sideways() -> None:
    """A pusher pushing a face while also sliding along it (+y) drags the block along +y only
    with friction (a mocap pusher, zero velocity in the solver, could not do this). Without
    friction the block moves along the face normal; as the contact point crosses the centre
    line it turns by about 1 deg, and the limit surface couples that turn into a sideways drift
    of either sign, below 1 mm over the 15 mm push."""
    dt, r, n = 1e-3, 0.005, 500
    t = np.arange(n) * dt
    x = -SIZE[0] / 2 - r + 0.03 * t  # in contact from the start, pushing at 3 cm/s
    y = -0.01 + 0.04 * t  # sliding along the face at 4 cm/s
    p = np.stack([x, y, np.full(n, HZ)], -1)[None]
    obs = np.array([[0.0, (n - 1) * dt]])
    drive = make_drive(dt, p, np.zeros((1, n)), obs, np.array([[0, 0, HZ]]), np.zeros(1))
    eng = get_engine("mujoco")(_physics(0.3, pusher={"shape": "sphere", "radius_m": r}))
    out = eng.rollout(drive, params={"objects.pusher.friction_dynamic": [0.0, 1.0]})
    side = out.pos["box"][:, 0, -1, 1]
    assert abs(side[0]) * 1e3 < 1.0
    assert (side[1] - side[0]) * 1e3 > 2.0, side


def _follow(eng, drive) -> tuple[float, int]:
    """Stepping ``drive``: (the pusher's largest distance from its path [m], the number of
    steps with a contact on the pusher's geom)."""
    path = drive.pusher[0].numpy()
    qa = eng.model.joint("pusher_x").qposadr[0]
    worst, touched, pid = 0.0, 0, eng.model.geom("pusher").id
    for k, _, d in eng.step_states(drive):
        worst = max(worst, float(np.linalg.norm(d.qpos[qa : qa + 3] - path[k + 1])))
        touched += bool(np.any(d.contact.geom[: d.ncon] == pid))
    return worst, touched


def test_the_pusher_follows_the_measured_path() -> None:
    """The servo-driven pusher is where the drive says, also while pushing (0.05 mm)."""
    eng = get_engine("mujoco")(
        _physics(0.4, pusher={"shape": "capsule", "radius_m": 0.01, "length_m": 0.04})
    )
    start = np.array([-SIZE[0] / 2 - 0.01 - 0.01, 0.0, HZ])
    worst, touched = _follow(eng, _push_drive(start, np.array([1.0, 0, 0]), 0.1, 0.06))
    assert touched > 50  # the pusher was in contact with the box for a while
    assert worst * 1e3 < 0.05


def test_stepping_is_the_rollout() -> None:
    """``step_states`` starts where ``rollout`` does and applies its servo targets: the second
    trajectory of a two-push drive (a 10 cm/s push at y = 0 and y = 15 mm, the box started
    with 0.1 / 0.2 m/s along y) gives the rollout's poses at every step, to 1e-12 m / rad (the
    first trajectory's are millimetres away)."""
    eng = get_engine("mujoco")(_physics(0.4, pusher={"shape": "sphere", "radius_m": 0.005}))
    one = [
        _push_drive(np.array([-0.05, y, HZ]), np.array([1.0, 0, 0]), 0.1, 0.03) for y in (0, 0.015)
    ]
    n = one[0].n_steps
    obs = np.tile(np.arange(n) * 1e-3, (2, 1))
    pusher = np.stack([d.pusher[0].numpy() for d in one])
    drive = make_drive(
        1e-3, pusher, np.zeros((2, n)), obs, np.tile([0, 0, HZ], (2, 1)), np.zeros(2)
    )
    start = ObjectState(
        pos=np.tile([0.0, 0, HZ], (2, 1)), quat=np.tile([1.0, 0, 0, 0], (2, 1)),
        vel=np.array([[0.0, 0.1, 0], [0.0, 0.2, 0]]),
    )  # fmt: skip
    out = eng.rollout(drive, {"box": start})
    lay = eng.layout["box"]
    steps = [
        (k, d.qpos[lay.qpos : lay.qpos + 4].copy())
        for k, _, d in eng.step_states(drive, {"box": start}, traj=1)
    ]
    assert [k for k, _ in steps] == list(range(n - 1))
    q = np.array([x for _, x in steps])
    assert np.abs(q[:, :3] - out.pos["box"][0, 1, 1:]).max() < 1e-12
    assert np.abs(q[:, 3] - out.yaw("box")[0, 1, 1:]).max() < 1e-12
    assert np.abs(q[:, :3] - out.pos["box"][0, 0, 1:]).max() > 1e-3  # not the first trajectory


# --------------------------------------------------------------------------- (d) two objects
def _two_boxes(mu: float, pusher: dict | None = None) -> dict:
    doc = _physics(mu, pusher=pusher)
    doc["objects"]["box2"] = dict(doc["objects"]["box"])
    return doc


def test_block_sliding_into_another_conserves_momentum() -> None:
    mu, v0, gap = 0.3, 0.6, 0.02
    eng = get_engine("mujoco")(_two_boxes(mu))
    b_start = SIZE[0] + gap
    init = {"box": _at((0, 0, HZ), (v0, 0, 0)), "box2": _at((b_start, 0, HZ))}
    out = eng.rollout(_still_drive(1, 0.6), init)
    da = out.pos["box"][0, 0, -1, 0] - gap
    db = out.pos["box2"][0, 0, -1, 0] - b_start
    v1 = math.sqrt(v0**2 - 2 * mu * G * gap)
    assert db > 0.005  # the struck block moved
    speeds = math.sqrt(2 * mu * G * max(da, 0.0)) + math.sqrt(2 * mu * G * db)
    assert abs(speeds - v1) / v1 < 0.05, (speeds, v1)
    # inelastic bound (both at v1/2) <= struck distance <= elastic bound (v1)
    assert (v1 / 2) ** 2 / (2 * mu * G) - 1e-3 <= db <= v1**2 / (2 * mu * G) + 1e-3
    assert (
        out.pos["box2"][0, 0, -1, 0] - out.pos["box"][0, 0, -1, 0] >= SIZE[0] - 1e-4
    )  # no overlap


def test_block_pushed_into_another_moves_it_by_the_remaining_travel() -> None:
    r, gap_p, gap_b, travel = 0.005, 0.005, 0.01, 0.06
    eng = get_engine("mujoco")(_two_boxes(0.4, pusher={"shape": "sphere", "radius_m": r}))
    start = np.array([-SIZE[0] / 2 - r - gap_p, 0.0, HZ])
    b_start = SIZE[0] + gap_b
    init = {"box2": _at((b_start, 0, HZ))}
    out = eng.rollout(_push_drive(start, np.array([1.0, 0, 0]), 0.05, travel), init)
    moved = out.pos["box2"][0, 0, -1, 0] - b_start
    assert abs(moved - (travel - gap_p - gap_b)) * 1e3 < 2.0, moved
    assert abs(out.pos["box2"][0, 0, -1, 1]) * 1e3 < 1.0


# --------------------------------------------------------------------------- the registry
def test_auto_picks_mujoco_where_planar_cannot_represent_the_scene() -> None:
    planar = get_engine("planar")
    assert planar.can_represent(_physics())[0]
    assert choose_engine(_physics())[0] == "planar"
    for doc, why in [
        (_two_boxes(0.4), "2 rigid objects"),
        (_physics(table={"normal": [0.1, 0.0, 1.0]}), "tilted"),
        (
            _physics(pusher={"shape": "sphere", "radius_m": 0.01, "friction_dynamic": 0.5}),
            "friction",
        ),
    ]:
        ok, reason = planar.can_represent(doc)
        assert not ok and why in reason
        assert choose_engine(doc)[0] == "mujoco"
    assert not get_engine("mujoco").can_represent(
        {"objects": {"door": {"equation": "articulated"}}}
    )[0]


def test_mujoco_and_planar_agree_on_centred_pushes() -> None:
    """Both engines on the 9 noiseless pushes of the scenario generator, true friction: the
    same answers within 2.5 mm RMS (MuJoCo's soft pusher impacts are not fully plastic)."""
    from robogs.physics.prepare import prepare
    from robogs.synth.scenarios import make_scenario

    rec = make_scenario("none", seed=0, kinds=("push",), noise="zero")
    rec.physics["objects"]["box"]["friction_dynamic"] = rec.meta["true_friction_dynamic"]
    prep = prepare(rec)
    a = get_engine("mujoco")(rec.physics).rollout(prep.drive).pos["box"][0]
    b = get_engine("planar")(rec.physics).rollout(prep.drive).pos["box"][0]
    mask = prep.mask.numpy()
    rms = np.sqrt(np.mean(np.sum((a - b)[mask] ** 2, -1))) * 1e3
    assert rms < 2.5, rms


def test_bad_parameters_and_grasps_are_refused() -> None:
    eng = get_engine("mujoco")(_physics())
    with pytest.raises(InputError, match="cannot be set"):
        eng.model_for({"objects.box.colour": 1.0})
    drive = _still_drive(1, 0.01)
    drive.grasp[:] = True
    with pytest.raises(InputError, match="grasp"):
        eng.rollout(drive)
    with pytest.raises(InputError, match="grasp"):
        eng.step_states(drive)
    with pytest.raises(InputError, match="trajectory 1"):
        eng.step_states(_still_drive(1, 0.01), traj=1)


# --------------------------------------------------------------------------- meshes
def test_a_box_mesh_slides_like_the_box() -> None:
    import trimesh

    mesh = trimesh.creation.box(extents=SIZE)
    eng = get_engine("mujoco")(_physics(0.3), meshes={"box": mesh})
    assert eng.scene.notes == []  # a closed convex mesh of 8 vertices is used as is
    out = eng.rollout(_still_drive(1, 0.5), {"box": _at((0, 0, HZ), (0.5, 0, 0))})
    assert abs(out.pos["box"][0, 0, -1, 0] - 0.25 / (2 * 0.3 * G)) * 1e3 < 1.0


def test_a_detailed_non_convex_mesh_is_hulled_decimated_and_reported() -> None:
    import trimesh

    ring = trimesh.creation.annulus(r_min=0.02, r_max=0.03, height=0.02, sections=2000)
    hull, note = collision_hull(ring, "ring")
    assert len(hull.vertices) <= MAX_HULL_VERTICES
    assert "convex hull" in note and "non-convex" in note and "decimated to 256" in note
    # the decimated hull keeps the outer radius (farthest-point samples lie on the rim)
    assert np.hypot(*hull.vertices[:, :2].T).max() == pytest.approx(0.03, rel=1e-6)
    open_box = trimesh.creation.box(extents=SIZE)
    open_box.update_faces(np.arange(len(open_box.faces)) > 1)  # one face removed
    assert "not watertight" in collision_hull(open_box, "open")[1]
    doc = _physics()
    doc["objects"]["ring"] = {
        "equation": "rigid", "mass_kg": 0.2, "inertia_kgm2": (np.eye(3) * 7.2e-5).tolist()
    }  # fmt: skip
    scene = scene_mjcf(doc, meshes={"ring": ring})
    assert any("ring" in n for n in scene.notes)
    model = mujoco.MjModel.from_xml_string(scene.xml, assets=scene.assets)
    assert model.nmesh == 1 and model.body("ring").mass[0] == pytest.approx(0.2)


def test_a_flat_mesh_is_refused_with_the_object_named() -> None:
    import trimesh

    from robogs.format.errors import FormatError

    flat = trimesh.Trimesh(
        vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], faces=[[0, 1, 2], [1, 3, 2]]
    )
    with pytest.raises(FormatError, match="sheet"):
        collision_hull(flat, "sheet")
