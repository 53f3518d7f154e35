"""Turn decoded ROS messages into dataset streams (shared by the bag and MCAP readers).

A reader (``rosbag_source``, ``mcap_source``) lists its topics, asks :meth:`MessageIngest.plan`
which to read, feeds the first-pass topics (``/tf_static``, ``/tf``, ``/robot_description``, and
``camera_info`` when there is a ``/tf``) first through :meth:`MessageIngest.handle`, then the
probe topics through :meth:`MessageIngest.probe`, then every other wanted message in log-time
order, and finally calls :meth:`MessageIngest.finish`. Messages are duck-typed: rosbags and
``mcap_ros2`` objects both work, with ROS 1 (``K``, ``D``) or ROS 2 (``k``, ``d``) field names.

:class:`MessageIngest` only routes; the jobs live in their own modules:

- :mod:`.topic_plan`: which topic becomes which stream (roles and reasons);
- :mod:`.stamps`: header stamp or log time, plausibility, jump thresholds;
- :mod:`.pose_probe`: pose topics compared with forward kinematics (object or end effector);
- handlers per kind: :mod:`.joint_handler`, :mod:`.camera_handler` (camera info, images,
  labels, extrinsics), :mod:`.pose_handler` (poses, wrenches), :mod:`.generic_handler`, and
  :mod:`.tf_ingest` (TF tree, moving frames as objects).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from .bag_options import BagOptions
from .camera_handler import CameraHandler
from .context import IngestContext
from .generic_handler import GenericHandler
from .joint_handler import JointStateHandler
from .pose_handler import PoseHandler, WrenchHandler
from .pose_probe import PoseProbe
from .roles import Role, safe_name
from .stamps import StampClock
from .tf_ingest import TfIngest
from .topic_plan import PRODUCTIVE_ROLES, STATIC_ROLES, TopicInfo, TopicPlan, plan_topics

__all__ = ["TopicInfo", "MessageIngest", "PRODUCTIVE_ROLES", "STATIC_ROLES"]

_WORLD_CANDIDATES = ("world", "base_link", "base", "map", "odom")


class MessageIngest:
    """Routes decoded messages to the handler of their topic's role.

    Args:
        ctx: the conversion context (its ``options.source`` is a :class:`BagOptions`).
        time_range: ``(start_ns, end_ns)`` of the recording's log times, for plausibility of
            header stamps (``None``: any non-zero stamp is plausible).
    """

    def __init__(self, ctx: IngestContext, *, time_range: tuple[int, int] | None) -> None:
        self.ctx = ctx
        self.opts = ctx.options
        self.bag: BagOptions = ctx.options.source_as(BagOptions)
        self.prov = ctx.provenance
        self.clock = StampClock(self.prov, time_range, self.bag)
        self.topic_plan = TopicPlan()
        self.read: dict[str, int] = {}
        self.tf = TfIngest(
            self.prov,
            self.clock.plausible,
            tolerance_ns=self.bag.tf_tolerance_ns,
            spill_rows=self.bag.tf_spill_rows,
        )
        self._static_topics: set[str] = set()
        self._main_started = False
        self._world: str | None = None
        self._probe = PoseProbe(self.topic_plan, self.clock, self.prov)
        self._joints = JointStateHandler(ctx, self.clock, None)
        self._cameras = CameraHandler(
            ctx, self.topic_plan, self.clock, self.bag, self.tf, self.world_frame
        )
        self._poses = PoseHandler(ctx, self.clock, self.tf, self.world_frame)
        self._wrenches = WrenchHandler(ctx, self.clock, {})
        self._generic = GenericHandler(ctx, self.clock)
        ctx.clock = ctx.clock or "ros_time"

    # ------------------------------------------------------------------ planning
    @property
    def roles(self) -> dict[str, Role]:
        """topic -> role."""
        return self.topic_plan.roles

    @property
    def types(self) -> dict[str, str]:
        """topic -> normalised message type."""
        return self.topic_plan.types

    @property
    def counts(self) -> dict[str, int]:
        """topic -> indexed message count."""
        return self.topic_plan.counts

    @property
    def reasons(self) -> dict[str, str]:
        """topic -> why it got its role."""
        return self.topic_plan.reasons

    @property
    def probe_topics(self) -> list[str]:
        """Topics of the probe pass (read after the static ones, before the main pass)."""
        return self._probe.topics

    def passes(
        self, static: list[str], main: list[str], name: str
    ) -> Iterator[tuple[list[str], str, bool]]:
        """The reading passes of :meth:`plan`'s topics, in order, an empty one skipped when its
        turn comes: ``(topics, label, probing)`` for the static topics, the probe of pose topics
        against the robot (:meth:`probe`), then the main pass (label ``name``, :meth:`handle`)."""
        every = (
            (static, "static topics", False),
            (self.probe_topics, "pose topics against the robot", True),
            (main, name, False),
        )
        return (p for p in every if p[0])

    def plan(self, topics: list[TopicInfo]) -> tuple[list[str], list[str]]:
        """Give every topic a role (:func:`~.topic_plan.plan_topics`).

        Returns:
            ``(static_topics, main_topics)``: read the first list completely before the second.

        Raises:
            InputError: a role that does not fit the topic's type, a role naming an absent
                topic, or no topic that puts data into the dataset.
        """
        plan = plan_topics(
            topics,
            {**self.bag.role_map, **self.opts.roles},
            self.prov,
            has_urdf=self.opts.urdf is not None,
        )
        self.topic_plan = plan
        self._static_topics = set(plan.static)
        self._probe = PoseProbe(plan, self.clock, self.prov)
        self._joints.topic = plan.joint_topic
        self._cameras.plan = plan
        self._wrenches.streams = plan.wrench_streams
        return plan.static, plan.main

    def probe(self, topic: str, log_time: int, msg: Any) -> None:
        """Keep a subsample of a probed pose topic and the joint states around it."""
        self._probe.add(topic, log_time, msg)

    # ------------------------------------------------------------------ dispatch
    def handle(self, topic: str, log_time: int, msg: Any) -> None:
        """Process one decoded message of a planned topic."""
        self.read[topic] = self.read.get(topic, 0) + 1
        role = self.topic_plan.roles.get(topic)
        if role is None or role.kind == "ignore":
            return
        if topic not in self._static_topics:
            self._begin_main()
            self.tf.emit_until(int(log_time), self._poses.add_tf_object)
        kind = role.kind
        if kind == "tf_static":
            self.tf.add_static(topic, msg)
            self.prov.topic(topic).written += 1
            return
        if kind == "tf":
            self.tf.add_dynamic(topic, log_time, msg)
            return
        if kind == "robot_description":
            if self.ctx.robot_description is None:
                self.ctx.robot_description = str(msg.data)
                self.prov.topic(topic).written += 1
            else:
                self.prov.drop(topic, "only the first robot_description is used")
            return
        if kind == "camera_info":
            self._cameras.info(topic, role, log_time, msg)
            return
        if kind == "generic" and not hasattr(getattr(msg, "header", None), "stamp"):
            t: int | None = self.clock.log_stamp(topic, log_time)
        else:
            t = self.clock.stamp(topic, msg, log_time)
        if t is None:
            return
        if kind == "joint_states":
            self._joints.add(topic, t, msg)
        elif kind == "camera_image":
            self._cameras.image(topic, role, t, msg)
        elif kind == "camera_labels":
            self._cameras.labels(topic, role, t, msg)
        elif kind in ("object_pose", "ee_pose"):
            self._poses.add(topic, role, t, msg)
        elif kind == "wrench":
            self._wrenches.add(topic, role, t, msg)
        elif kind == "generic":
            self._generic.add(topic, t, msg)

    def note_undecodable(self, topic: str, log_time: int, error: str) -> None:
        """Record a message that the reader could not decode."""
        self.read[topic] = self.read.get(topic, 0) + 1
        self.prov.issue(topic, f"message could not be decoded ({error[:120]})", log_time)

    # ------------------------------------------------------------------ frames
    def world_frame(self) -> str:
        """The TF frame taken as the dataset world."""
        if self._world is None:
            frames = self.tf.buf.frames
            cands = [self.bag.world_frame] if self.bag.world_frame else []
            cands += [self.ctx.robot_root_link] if self.ctx.robot_root_link else []
            cands += list(_WORLD_CANDIDATES)
            self._world = next(
                (c for c in cands if c in frames), cands[0] if self.bag.world_frame else "world"
            )
        return self._world

    def _robot_links(self) -> set[str]:
        """Link names of the robot (``--urdf`` or ``/robot_description``); empty if unknown."""
        from xml.etree.ElementTree import ParseError

        import defusedxml.ElementTree as ET

        try:
            if self.opts.urdf is not None:
                root = ET.parse(str(self.opts.urdf)).getroot()
            elif self.ctx.robot_description:
                root = ET.fromstring(self.ctx.robot_description)
            else:
                return set()
        except (OSError, ParseError, ValueError) as exc:
            self.prov.note(f"robot links unknown for the tf frames ({type(exc).__name__})")
            return set()
        return {str(link.get("name")) for link in root.iter("link") if link.get("name")}

    def _begin_main(self) -> None:
        """Once, after the first pass: decide the probed roles, sort the transforms and choose
        the tf objects."""
        if self._main_started:
            return
        self._main_started = True
        self._probe.decide(self.opts.urdf, self.ctx.robot_description)
        if not self.tf.buf.dynamic_edges:
            self.tf.finalize()
            return
        taken = {r.name or safe_name(t) for t, r in self.roles.items() if r.kind == "object_pose"}
        self.tf.select_objects(
            self.world_frame(),
            explicit=dict(self.bag.tf_objects),
            auto=self.bag.tf_auto_objects,
            camera_frames=self._cameras.frame_ids(),
            robot_links=self._robot_links(),
            taken=taken,
        )
        for obj in self.tf.objects:
            topic = obj.source.rsplit(":", 1)[0]
            self.clock.source[obj.source] = self.tf.stamp_source.get(topic, "log_time")

    # ------------------------------------------------------------------ finishing
    def finish(self) -> None:
        """Close every handler, write cameras, declare streams, account for unread messages."""
        self._begin_main()
        self.tf.emit_until(None, self._poses.add_tf_object)
        self._joints.close()
        self._poses.close()
        self._wrenches.close()
        self._generic.close()
        self.prov.extra["decoded"] = self._decode_summary()
        self._cameras.close_labels()
        self._cameras.close()
        self.tf.account([t for t, r in self.roles.items() if r.kind == "tf"])
        self.tf.keep_static_frames(self.ctx.writer.manifest, self._robot_links())
        self.tf.close()
        for topic, n_index in self.counts.items():
            role = self.topic_plan.roles.get(topic)
            if role is None or role.kind == "ignore":
                continue
            got = self.read.get(topic, 0)
            if got < n_index:
                self.prov.drop(
                    topic, "listed in the index but not delivered by the reader", n_index - got
                )
                self.prov.note(
                    f"{topic}: {n_index - got} of {n_index} indexed messages were not delivered"
                )
            elif got > n_index:
                self.prov.topic(topic).messages = got
        self._cameras.report_pending()

    def _decode_summary(self) -> dict[str, Any]:
        """Messages decoded and not decoded over every topic not mapped to ``ignore``, and the
        message types outside the standard ROS type stores (custom types)."""
        from rosbags.typesys import Stores, get_typestore

        std = set(get_typestore(Stores.ROS2_HUMBLE).types) | set(
            get_typestore(Stores.ROS1_NOETIC).types
        )
        undecodable = 0
        for i in self.prov.issues:
            if i["problem"].startswith("message could not be decoded"):
                undecodable += int(i["count"])
        undecodable += sum(int(u.get("messages") or 0) for u in self.prov.undecodable)
        listed = [t for t, r in self.roles.items() if r.kind != "ignore"]
        custom = sorted(
            {self.types[t] for t in listed if self.types[t] not in std and "/msg/" in self.types[t]}
        )
        return {
            "topics": len(listed) + len(self.prov.undecodable),
            "messages": sum(self.read.get(t, 0) for t in listed) - undecodable,
            "undecodable": undecodable,
            "ignored_topics": sorted(t for t, r in self.roles.items() if r.kind == "ignore"),
            "custom_types": custom,
        }

    def abort(self) -> None:
        """Close open files after a failure (the writer discards them)."""
        self._joints.abort()
        self._wrenches.abort()
        self._poses.abort()
        self._cameras.abort()
        self.tf.close()
