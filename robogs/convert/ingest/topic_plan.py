"""Which topic becomes which stream: the role of every topic of a bag or MCAP.

:func:`plan_topics` gives each topic a role (an override from ``--topic``/``--map``, else the
default for its name and type), keeps one ``joint_states`` topic, names the wrench streams,
picks the pose topics to compare with the robot's forward kinematics, and records every role
and its reason in the provenance. It reads no message.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from robogs.format.errors import InputError

from .provenance import Provenance
from .roles import Role, default_role, normalize_type, parse_role, safe_name

__all__ = [
    "PRODUCTIVE_ROLES",
    "ROLE_TYPES",
    "STATIC_ROLES",
    "TopicInfo",
    "TopicPlan",
    "plan_topics",
    "wrench_streams",
]

#: roles that put data into the dataset
PRODUCTIVE_ROLES = frozenset(
    {
        "joint_states",
        "camera_image",
        "camera_info",
        "camera_labels",
        "object_pose",
        "ee_pose",
        "wrench",
    }
)
#: roles read before everything else (``/tf`` too: the whole tree is known before the main pass)
STATIC_ROLES = frozenset({"tf_static", "tf", "robot_description"})

_POSES = {
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "geometry_msgs/msg/TransformStamped",
}
_IMAGES = {"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"}
_TF = {"tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"}
#: role kind -> the message types it accepts
ROLE_TYPES: dict[str, set[str]] = {
    "joint_states": {"sensor_msgs/msg/JointState"},
    "camera_image": _IMAGES,
    "camera_labels": _IMAGES,
    "camera_info": {"sensor_msgs/msg/CameraInfo"},
    "object_pose": _POSES,
    "ee_pose": _POSES,
    "wrench": {"geometry_msgs/msg/WrenchStamped"},
    "tf_static": _TF,
    "tf": _TF,
    "robot_description": {"std_msgs/msg/String"},
}


@dataclass(frozen=True)
class TopicInfo:
    """A topic as listed by a reader: name, message type, indexed message count."""

    topic: str
    msgtype: str
    count: int


@dataclass
class TopicPlan:
    """The roles of a source's topics and the reading order.

    Attributes:
        roles: topic -> role (may change once probing decides a pose topic is an end effector).
        types: topic -> normalised message type.
        counts: topic -> indexed message count.
        reasons: topic -> why it got its role (printed in the roles table).
        overrides: topic -> role given by the user.
        joint_topic: the one topic written as ``joint_states`` (None: none).
        static: topics read completely before the others (TF, robot description, and camera
            info when there is a ``/tf``).
        main: the other wanted topics, read in log-time order.
        wrench_streams: wrench topic -> (stream name, file stem).
        probe: pose topics whose role is a guess from their type alone, to compare with FK.
    """

    roles: dict[str, Role] = field(default_factory=dict)
    types: dict[str, str] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    reasons: dict[str, str] = field(default_factory=dict)
    overrides: dict[str, Role] = field(default_factory=dict)
    joint_topic: str | None = None
    static: list[str] = field(default_factory=list)
    main: list[str] = field(default_factory=list)
    wrench_streams: dict[str, tuple[str, str]] = field(default_factory=dict)
    probe: list[str] = field(default_factory=list)


def wrench_streams(topics: list[str]) -> dict[str, tuple[str, str]]:
    """Stream name and file stem of each wrench topic: ``wrenches`` for one topic, else one
    stream per topic named after it (``wrenches/netft_data``)."""
    if len(topics) == 1:
        return {topics[0]: ("wrenches", "wrenches")}
    out: dict[str, tuple[str, str]] = {}
    used: set[str] = set()
    for t in sorted(topics):
        base = safe_name(t)
        name = base
        k = 1
        while name in used:
            k += 1
            name = f"{base}_{k}"
        used.add(name)
        out[t] = (f"wrenches/{name}", f"wrenches_{name}")
    return out


def plan_topics(
    topics: list[TopicInfo],
    overrides: dict[str, str | Role],
    prov: Provenance,
    *,
    has_urdf: bool,
) -> TopicPlan:
    """Give every topic a role and record the roles (and the ignored topics) in ``prov``.

    Args:
        topics: the source's topics.
        overrides: topic -> role given by the user (a string is parsed).
        prov: the provenance record.
        has_urdf: a URDF is given (pose topics can be probed against FK).

    Raises:
        InputError: a role that does not fit the topic's type, a role naming an absent topic,
            several topics forced to ``joint_states``, or no topic that puts data into the
            dataset.
    """
    plan = TopicPlan()
    plan.overrides = {
        t: parse_role(r, where=f"role of {t}") if isinstance(r, str) else r
        for t, r in overrides.items()
    }
    known = {t.topic for t in topics}
    missing = sorted(set(plan.overrides) - known)
    if missing:
        raise InputError(
            f"role given for topics not in the source: {', '.join(missing)}",
            where="--topic/--map",
            hint=f"topics: {', '.join(sorted(known)) or 'none'}",
        )
    for info in topics:
        t = normalize_type(info.msgtype)
        plan.types[info.topic] = t
        plan.counts[info.topic] = info.count
        if info.topic in plan.overrides:
            role = plan.overrides[info.topic]
            if role.kind not in ("ignore", "generic") and t not in ROLE_TYPES.get(role.kind, set()):
                raise InputError(
                    f"topic {info.topic} has type {t}, which cannot be {role}",
                    where="--topic/--map",
                    hint=f"{role.kind} takes {', '.join(sorted(ROLE_TYPES[role.kind]))}",
                )
            reason = "mapped to ignore" if role.kind == "ignore" else "given by --topic/--map"
        else:
            role, reason = default_role(info.topic, t)
        plan.roles[info.topic] = role
        plan.reasons[info.topic] = reason
    _choose_joint_topic(plan)
    for info in topics:
        role = plan.roles[info.topic]
        rec = prov.topic(info.topic, plan.types[info.topic], str(role))
        rec.messages = info.count
        rec.reason = plan.reasons.get(info.topic)
        if role.kind == "ignore" and info.count:
            prov.drop(info.topic, plan.reasons.get(info.topic, "ignored"), info.count)
    live = {t: r for t, r in plan.roles.items() if plan.counts[t] > 0}
    productive = [t for t, r in live.items() if r.kind in PRODUCTIVE_ROLES]
    has_tf = any(r.kind == "tf" for r in live.values())
    if not productive and not has_tf:
        listing = (
            "; ".join(f"{t.topic} {normalize_type(t.msgtype)} x{t.count}" for t in topics) or "none"
        )
        raise InputError(
            "nothing to convert: no joint states, images, camera info, poses or wrenches",
            where=f"topics: {listing}",
            hint="map topics to roles with --topic ROLE=TOPIC or --map roles.yaml",
        )
    static = [t for t, r in live.items() if r.kind in STATIC_ROLES]
    if has_tf:  # camera frames must be known before tf frames are chosen as objects
        static += [t for t in productive if plan.roles[t].kind == "camera_info"]
        productive = [t for t in productive if plan.roles[t].kind != "camera_info"]
    generic = [t for t, r in live.items() if r.kind == "generic"]
    plan.probe = _probe_candidates(plan, has_urdf=has_urdf)
    plan.wrench_streams = wrench_streams([t for t in productive if plan.roles[t].kind == "wrench"])
    plan.static, plan.main = sorted(static), sorted(productive + generic)
    return plan


def _probe_candidates(plan: TopicPlan, *, has_urdf: bool) -> list[str]:
    """Pose topics whose role is a guess from the type alone (probed against FK), when there
    is a robot and a joint topic to drive it."""
    robot = has_urdf or any(
        r.kind == "robot_description" and plan.counts[t] for t, r in plan.roles.items()
    )
    cands = [
        t
        for t, r in plan.roles.items()
        if r.kind == "object_pose"
        and t not in plan.overrides
        and plan.counts[t] > 0
        and [p for p in t.split("/") if p][:1] != ["objects"]
    ]
    return cands if cands and robot and plan.joint_topic is not None else []


def _choose_joint_topic(plan: TopicPlan) -> None:
    """One ``joint_states`` topic: the forced one, ``/joint_states``, else the busiest; the
    others become generic tables."""
    cands = [t for t, r in plan.roles.items() if r.kind == "joint_states"]
    if len(cands) <= 1:
        plan.joint_topic = cands[0] if cands else None
        return
    forced = [t for t in cands if t in plan.overrides]
    if len(forced) > 1:
        raise InputError(
            f"several topics mapped to joint_states: {', '.join(forced)}",
            where="--topic/--map",
            hint="map one; ignore the others",
        )
    if forced:
        chosen = forced[0]
    elif "/joint_states" in cands:
        chosen = "/joint_states"
    else:
        chosen = max(cands, key=lambda t: (plan.counts[t], t))
    for t in cands:
        if t != chosen:
            plan.roles[t] = Role("generic")
            plan.reasons[t] = (
                f"another topic provides joint_states ({chosen}); decoded into a generic table"
            )
    plan.joint_topic = chosen
