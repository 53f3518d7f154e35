"""``/tf`` and ``/tf_static`` during a bag or MCAP conversion: frames become object poses and
camera extrinsics.

The transform messages are read in the first pass (with the other static topics), into a
:class:`~robogs.convert.ingest.tf_buffer.TfBuffer`. Then:

* **Objects.** A TF frame becomes an ``object_poses`` stream ``T_world_frame``, sampled at the
  stamps of the dynamic edge nearest the frame (other dynamic edges on the chain interpolated).
  By default every child frame of a dynamic edge is an object, except the world frame, robot
  links (from ``--urdf`` or ``/robot_description``), camera frames and the frames the cameras
  hang from. ``--tf-object NAME=FRAME`` (or ``tf_objects:`` in the ``--map`` YAML) chooses the
  frames instead; ``--no-tf-objects`` turns the default off.
* **Cameras.** A camera whose frame (its images' ``header.frame_id``, or ``--tf-camera
  CAM=FRAME``) hangs from a dynamic edge gets ``extrinsics: time_varying`` and a
  ``camera_extrinsics`` table ``T_world_cam`` at each frame's stamp. The frame is taken to be
  an optical frame (REP 103: x right, y down, z forward), i.e. OpenCV axes.

Stamps: per topic, ``header.stamp`` of the transforms when the first one is plausible, else the
log time, as for every other topic.
"""

from __future__ import annotations

import heapq
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from robogs.format.errors import InputError

from .provenance import Provenance
from .roles import safe_name
from .tf_buffer import Hop, TfBuffer, poses_of
from .tf_tree import pose_to_matrix

__all__ = ["TfObject", "TfIngest", "stamp_ns"]

_CHUNK = 4096
Edge = tuple[str, str]


@dataclass
class TfObject:
    """A frame written as an object pose stream."""

    name: str
    frame: str
    hops: list[Hop]
    driver: Hop
    source: str  # sink source id, e.g. "/tf:box"


def stamp_ns(stamp: Any) -> int:
    """A ROS 1 (``secs``/``nsecs``) or ROS 2 (``sec``/``nanosec``) stamp as int64 ns."""
    sec = getattr(stamp, "sec", None)
    if sec is None:
        sec = getattr(stamp, "secs", 0)
    nsec = getattr(stamp, "nanosec", None)
    if nsec is None:
        nsec = getattr(stamp, "nsecs", 0)
    return int(sec) * 1_000_000_000 + int(nsec)


def _parts(ts: Any) -> tuple[str, str, list[float], list[float]] | None:
    tr = ts.transform
    xyz = [float(tr.translation.x), float(tr.translation.y), float(tr.translation.z)]
    q = [float(tr.rotation.w), float(tr.rotation.x), float(tr.rotation.y), float(tr.rotation.z)]
    if not all(math.isfinite(v) for v in xyz + q) or math.sqrt(sum(v * v for v in q)) < 1e-9:
        return None
    return str(ts.header.frame_id).lstrip("/"), str(ts.child_frame_id).lstrip("/"), xyz, q


@dataclass
class _Cursor:
    obj: TfObject
    times: np.ndarray
    pos: int = 0
    t: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    vals: np.ndarray = field(default_factory=lambda: np.zeros((0, 7)))
    ok: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    k: int = 0


class TfIngest:
    """Collects transforms, then serves object poses and camera extrinsics.

    Args:
        provenance: where problems and notes go.
        plausible: ``t_ns -> bool``, whether a header stamp lies in the recording's time range.
        tolerance_ns: how far a stamp may lie outside a dynamic edge's samples.
        spill_rows: samples per edge kept in RAM before spilling to a temp file.
    """

    def __init__(
        self,
        provenance: Provenance,
        plausible: Callable[[int], bool],
        *,
        tolerance_ns: int = 100_000_000,
        spill_rows: int = 1 << 18,
    ) -> None:
        self.prov = provenance
        self.plausible = plausible
        self.buf = TfBuffer(tolerance_ns=tolerance_ns, spill_rows=spill_rows)
        self.stamp_source: dict[str, str] = {}
        self._sigs: dict[str, Counter[frozenset[Edge]]] = {}
        self._edge_topic: dict[Edge, str] = {}
        self._heap: list[tuple[int, int]] = []
        self._cursors: list[_Cursor] = []
        self.objects: list[TfObject] = []
        self.used_edges: set[Edge] = set()

    # ------------------------------------------------------------------ reading
    def add_static(self, topic: str, msg: Any) -> int:
        """Add every transform of a ``/tf_static`` message; returns how many."""
        n = 0
        for ts in msg.transforms:
            parts = _parts(ts)
            if parts is None:
                self.prov.issue(topic, "transform with a non-finite value or zero quaternion", None)
                continue
            parent, child, xyz, q = parts
            self.buf.add_static(parent, child, pose_to_matrix(np.array(xyz), np.array(q)))
            n += 1
        return n

    def add_dynamic(self, topic: str, log_time: int, msg: Any) -> None:
        """Add every transform of a ``/tf`` message as a time sample."""
        src = self.stamp_source.get(topic)
        edges: set[Edge] = set()
        for ts in msg.transforms:
            parts = _parts(ts)
            t_hdr = stamp_ns(ts.header.stamp)
            if src is None:
                src = "sensor_header" if self.plausible(t_hdr) else "log_time"
                self.stamp_source[topic] = src
                self.prov.topic(topic).stamp_source = src
                if src == "log_time":
                    self.prov.note(
                        f"{topic}: header.stamp {t_hdr} is zero or outside the recording's time "
                        "range; log time used for this topic"
                    )
            if parts is None:
                self.prov.issue(
                    topic,
                    "transform with a non-finite value or zero quaternion (dropped)",
                    t_hdr,
                    drop=False,
                )
                continue
            if src == "sensor_header":
                if not self.plausible(t_hdr):
                    self.prov.issue(
                        topic,
                        "transform header stamp zero or outside the recording's time range "
                        "(dropped)",
                        t_hdr,
                        drop=False,
                    )
                    continue
                t = t_hdr
            else:
                t = int(log_time)
            parent, child, xyz, q = parts
            self.buf.add_sample(parent, child, t, xyz, q)
            self._edge_topic.setdefault((parent, child), topic)
            edges.add((parent, child))
        self._sigs.setdefault(topic, Counter())[frozenset(edges)] += 1

    # ------------------------------------------------------------------ planning
    def finalize(self) -> None:
        """Sort the samples (call once every transform was added)."""
        if self.buf.finalized:
            return
        for p, c in self.buf.finalize():
            self.prov.note(f"tf edge {p} -> {c} is in /tf_static and /tf; the /tf samples are used")
        if self.buf.duplicates:
            self.prov.note(
                f"{self.buf.duplicates} /tf samples repeated an edge's stamp; the last one is kept"
            )

    def _hang_frames(self, world: str, frames: set[str]) -> set[str]:
        """``frames`` and every frame on their chains to ``world``."""
        out = set(frames)
        for f in frames:
            for h in self.buf.chain(world, f) or []:
                out.update((h.a, h.b))
        return out

    def select_objects(
        self,
        world: str,
        *,
        explicit: dict[str, str],
        auto: bool,
        camera_frames: set[str],
        robot_links: set[str],
        taken: set[str],
    ) -> list[TfObject]:
        """Choose the frames written as object poses (see the module docstring).

        Raises:
            InputError: an explicit frame that is not in the transform tree.
        """
        self.finalize()
        frames = self.buf.frames
        if explicit:
            missing = sorted(f for f in explicit.values() if f.lstrip("/") not in frames)
            if missing:
                raise InputError(
                    f"--tf-object frame(s) not in /tf or /tf_static: {', '.join(missing)}",
                    where="--tf-object / tf_objects",
                    hint=f"frames: {', '.join(sorted(frames)) or 'none'}",
                )
            wanted = [(safe_name(n), f.lstrip("/")) for n, f in sorted(explicit.items())]
        elif auto:
            skip = self._hang_frames(world, camera_frames) | robot_links | {world}
            children = sorted({c for _, c in self.buf.dynamic_edges})
            wanted = []
            for c in children:
                if c in skip:
                    continue
                last = safe_name(c.rsplit("/", 1)[-1])
                if last in taken and last != safe_name(c):  # vicon/box/box and a /box pose topic
                    self.prov.note(
                        f"tf frame {c!r}: object {last!r} already has a pose topic; frame not used"
                    )
                    continue
                wanted.append((safe_name(c), c))
            left = sorted(c for c in children if c in robot_links)
            if left:
                self.prov.note(
                    f"tf frames of robot links not written as objects: {', '.join(left[:20])}"
                    + (" ..." if len(left) > 20 else "")
                )
        else:
            wanted = []
        objects: list[TfObject] = []
        for name, frame in wanted:
            if name in taken:
                self.prov.note(
                    f"tf frame {frame!r}: object {name!r} already has a pose topic; frame not used"
                )
                continue
            hops = self.buf.chain(world, frame)
            if hops is None:
                self.prov.note(
                    f"tf frame {frame!r} is not connected to the world frame {world!r}; "
                    "no object poses written"
                )
                continue
            driver = self.buf.driver(hops)
            if driver is None:
                self.prov.note(
                    f"tf frame {frame!r} is static in {world!r}; no object pose stream written"
                )
                continue
            if not explicit and self._never_moves(hops):
                self.prov.note(
                    f"tf frame {frame!r} never moves relative to {world!r} (a fixed frame such as "
                    "a mocap world, published on /tf); not an object (--tf-object NAME=FRAME "
                    "makes it one)"
                )
                continue
            topic = self._edge_topic.get(driver.edge, "/tf")
            objects.append(TfObject(name, frame, hops, driver, f"{topic}:{frame}"))
            taken.add(name)
            self.use(hops)
        if objects:
            self.prov.note(
                "tf frames written as object poses (T_world_frame): "
                + ", ".join(f"{o.frame}->{o.name}" for o in objects)
            )
        self.objects = objects
        self._cursors = [_Cursor(o, self.buf.times(*o.driver.edge)) for o in objects]
        self._heap = []
        for i, c in enumerate(self._cursors):
            if self._refill(c):
                heapq.heappush(self._heap, (int(c.t[0]), i))
        return objects

    def _never_moves(self, hops: list[Hop], tol: float = 1e-9) -> bool:
        """Whether the chain's transform is the same (within ``tol`` m and ``tol`` in each
        rotation-matrix entry) at every sample of every dynamic edge on it."""
        T0: np.ndarray | None = None
        for h in hops:
            if not h.dynamic:
                continue
            times = self.buf.times(*h.edge)
            for k in range(0, times.size, _CHUNK):
                T, ok = self.buf.compose(hops, np.asarray(times[k : k + _CHUNK], np.int64))
                T = T[ok]
                if T.shape[0] == 0:
                    continue
                if T0 is None:
                    T0 = T[0]
                if np.abs(T[:, :3, :] - T0[:3, :]).max() > tol:
                    return False
        return T0 is not None

    def use(self, hops: list[Hop]) -> None:
        """Mark a chain's dynamic edges as used (for the provenance counts)."""
        self.used_edges.update(h.edge for h in hops if h.dynamic)

    # ------------------------------------------------------------------ serving
    def _refill(self, c: _Cursor) -> bool:
        if c.pos >= c.times.size:
            return False
        t = np.asarray(c.times[c.pos : c.pos + _CHUNK], dtype=np.int64)
        c.pos += t.size
        T, ok = self.buf.compose(c.obj.hops, t)
        c.t, c.vals, c.ok, c.k = t, poses_of(T), ok, 0
        return True

    def emit_until(
        self, limit_ns: int | None, add: Callable[[TfObject, int, list[float]], None]
    ) -> None:
        """Hand every object sample with stamp ``<= limit_ns`` (all when ``None``) to ``add``,
        in stamp order across objects."""
        heap = self._heap
        while heap and (limit_ns is None or heap[0][0] <= limit_ns):
            t, i = heapq.heappop(heap)
            c = self._cursors[i]
            if c.ok[c.k]:
                add(c.obj, t, c.vals[c.k].tolist())
            else:
                self.prov.issue(
                    c.obj.source,
                    "no transform along the chain at this stamp (another edge has no sample "
                    "near it; dropped)",
                    t,
                    drop=False,
                )
            c.k += 1
            if c.k < c.t.size or self._refill(c):
                heapq.heappush(heap, (int(c.t[c.k]), i))

    def poses_at(self, hops: list[Hop], t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``[N, 4, 4]`` transforms of a chain at stamps ``t_ns`` and a validity mask."""
        return self.buf.compose(hops, t_ns)

    # ------------------------------------------------------------------ accounting
    def account(self, dynamic_topics: list[str]) -> None:
        """Written/dropped counts of the ``/tf`` topics and a note on unused frames."""
        for topic in dynamic_topics:
            rec = self.prov.topic(topic)
            unused = 0
            for sig, n in self._sigs.get(topic, Counter()).items():
                if sig & self.used_edges:
                    rec.written += n
                else:
                    unused += n
            if unused:
                self.prov.drop(
                    topic, "transforms of frames not used by any object or camera", unused
                )
        left = sorted(c for p, c in self.buf.dynamic_edges if (p, c) not in self.used_edges)
        if left:
            self.prov.note(
                f"dynamic tf frames not converted: {', '.join(left[:20])}"
                + (" ..." if len(left) > 20 else "")
            )

    def keep_static_frames(self, manifest: dict[str, Any], robot_links: set[str]) -> list[str]:
        """Keep the static frames that hang from robot links as named frames (spec 1.1.0,
        ``robot.frames``): every ``/tf_static`` edge whose parent is a robot link or an already
        kept frame and whose child is not a link. Returns the kept names (none when the robot's
        links are unknown: no ``--urdf`` and no ``robot_description``)."""
        from robogs.format.named_frames import NamedFrame, add_named_frames

        static = {(p, c): self.buf.lookup(p, c) for p, c in self.buf.static_edges}
        kept: dict[str, NamedFrame] = {}
        grew = True
        while grew:
            grew = False
            for (p, c), T in sorted(static.items()):
                if c in kept or c in robot_links or not (p in robot_links or p in kept):
                    continue
                kept[c] = NamedFrame(c, p, np.asarray(T, dtype=float), "/tf_static")
                grew = True
        if not kept:
            return []
        add_named_frames(manifest, kept)  # the robot's URDF is attached to the same entry later
        self.prov.note(
            "static tf frames kept as named frames (robot.frames): "
            + ", ".join(f"{f.parent}->{n}" for n, f in sorted(kept.items()))
        )
        return sorted(kept)

    def close(self) -> None:
        """Remove temp files."""
        self.buf.close()
