"""Camera messages -> cameras and ``camera`` streams: ``CameraInfo``, colour images, labels.

One camera per name (from the role, else the topic). The first calibrated ``CameraInfo`` gives
the intrinsics; colour images go to a :class:`~.sinks.CameraSink` (frames table and video);
16-bit label images wait for the colour frame of the same stamp and go to ``labels.parquet``.
At the end each camera's ``T_world_cam`` comes from the TF tree: static, or one row per frame
in ``extrinsics.parquet`` when the camera frame moves.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from robogs.format.cameras import CameraModel
from robogs.format.errors import InputError
from robogs.format.images import encode_label_png

from .bag_options import BagOptions
from .calibration import camera_from_info_msg
from .context import IngestContext
from .msg_fields import floats
from .pose_handler import POSE_COLUMNS
from .roles import Role, camera_name_from_topic
from .ros_images import decode_compressed_image, decode_raw_image
from .sinks import CameraSink
from .stamps import StampClock
from .tf_buffer import poses_of
from .tf_ingest import TfIngest, stamp_ns
from .topic_plan import TopicPlan

__all__ = ["CameraHandler"]

_MAX_PENDING_LABELS = 256
_LABEL_SUFFIXES = (
    "compressed",
    "image_raw",
    "image",
    "labels",
    "label",
    "panoptic",
    "segmentation",
)


@dataclass
class _Camera:
    name: str
    image_topic: str | None = None
    info_topic: str | None = None
    model: CameraModel | None = None
    info_key: tuple | None = None
    frame_id: str = ""
    sink: CameraSink | None = None
    stamp_source: str | None = None
    frame_of: dict[int, int] | None = None
    labels_topic: str | None = None


class CameraHandler:
    """The cameras of a recording.

    Args:
        ctx: the conversion context.
        plan: the topic plan (message types and counts).
        clock: stamp sources.
        options: ``video`` and ``tf_cameras``.
        tf: the TF tree (camera extrinsics).
        world: ``world()`` -> the TF frame that is the dataset world.
    """

    def __init__(
        self,
        ctx: IngestContext,
        plan: TopicPlan,
        clock: StampClock,
        options: BagOptions,
        tf: TfIngest,
        world: Callable[[], str],
    ) -> None:
        self.ctx = ctx
        self.prov = ctx.provenance
        self.plan = plan
        self.clock = clock
        self.opts = options
        self.tf = tf
        self.world = world
        self.cameras: dict[str, _Camera] = {}
        self._pending_labels: dict[str, list[tuple[int, np.ndarray]]] = {}
        self._labels_writers: dict[str, tuple[pq.ParquetWriter, int]] = {}

    def frame_ids(self) -> set[str]:
        """TF frames of the cameras (known so far and given by ``--tf-camera``)."""
        ids = {c.frame_id for c in self.cameras.values() if c.frame_id}
        return ids | {f.lstrip("/") for f in self.opts.tf_cameras.values()}

    def _camera(self, name: str) -> _Camera:
        cam = self.cameras.get(name)
        if cam is None:
            cam = self.cameras[name] = _Camera(name)
        return cam

    # ------------------------------------------------------------------ messages
    def info(self, topic: str, role: Role, log_time: int, msg: Any) -> None:
        """A ``CameraInfo``: the first calibrated one is the camera's intrinsics."""
        name = role.name or camera_name_from_topic(topic)
        cam = self._camera(name)
        if cam.info_topic is not None and cam.info_topic != topic:
            self.prov.drop(topic, f"camera {name} already has camera_info from {cam.info_topic}")
            return
        cam.info_topic = topic
        header = getattr(msg, "header", None)
        t = stamp_ns(header.stamp) if header is not None else int(log_time)
        K = floats(getattr(msg, "k", getattr(msg, "K", ())))
        key = (
            int(msg.width),
            int(msg.height),
            tuple(K.tolist()),
            tuple(floats(getattr(msg, "d", getattr(msg, "D", ()))).tolist()),
            str(msg.distortion_model),
        )
        if cam.info_key is None:
            cam.info_key = key
            if K.size != 9 or K[0] == 0.0:
                self.prov.issue(
                    topic, "camera is not calibrated (K[0] == 0); no intrinsics written", t
                )
                return
            cam.model = camera_from_info_msg(msg, name=name, topic=topic, t_ns=t)
            cam.frame_id = str(header.frame_id).lstrip("/") if header is not None else ""
            self.prov.topic(topic).stamp_source = (
                "sensor_header" if header is not None else "log_time"
            )
        elif key != cam.info_key:
            self.prov.issue(
                topic, "calibration differs from the first camera_info (first one kept)", t
            )
            return
        if cam.model is None:
            self.prov.drop(topic, "camera is not calibrated (K[0] == 0)")
            return
        self.prov.topic(topic).written += 1

    def _fps_hint(self, topic: str) -> float:
        n = self.plan.counts.get(topic, 0)
        tr = self.clock.time_range
        if tr and n > 1 and tr[1] > tr[0]:
            return max(1.0, min(1000.0, (n - 1) / ((tr[1] - tr[0]) / 1e9)))
        return 30.0

    def _decode(self, topic: str, t: int, msg: Any) -> tuple[str, np.ndarray] | None:
        if self.plan.types.get(topic) == "sensor_msgs/msg/CompressedImage":
            out = decode_compressed_image(msg, topic=topic, t_ns=t)
            if out is None:
                fmt = str(getattr(msg, "format", ""))[:40]
                self.prov.issue(
                    topic, f"compressed image not decodable as a still image (format {fmt!r})", t
                )
            return out
        return decode_raw_image(msg, topic=topic, t_ns=t)

    def image(self, topic: str, role: Role, t: int, msg: Any) -> None:
        """A colour image at stamp ``t`` (ns)."""
        name = role.name or camera_name_from_topic(topic)
        cam = self._camera(name)
        if cam.image_topic is not None and cam.image_topic != topic:
            self.prov.drop(topic, f"camera {name} already has images from {cam.image_topic}")
            return
        if cam.sink is None:
            ep = self.ctx.episode_dir()
            w = self.ctx.writer
            cam.image_topic = topic
            cam.stamp_source = self.clock.source.get(topic)
            cam.sink = CameraSink(
                w.path(f"{ep}/cameras/{name}/frames.parquet"),
                w.path(f"{ep}/cameras/{name}/rgb.mp4"),
                topic=topic,
                provenance=self.prov,
                video=self.opts.video,
                fps_hint=self._fps_hint(topic),
            )
            header = getattr(msg, "header", None)
            if header is not None and not cam.frame_id:
                cam.frame_id = str(header.frame_id).lstrip("/")
            cam.frame_of = {}
        if not cam.sink.accepts(t):
            return
        rgb = None
        if self.opts.video:
            out = self._decode(topic, t, msg)
            if out is None:
                return
            kind, rgb = out
            if kind != "rgb":
                self.prov.issue(
                    topic,
                    "16-bit single-channel image on a colour camera topic (map it as "
                    "camera_labels)",
                    t,
                )
                return
        elif self.plan.types.get(topic) == "sensor_msgs/msg/Image":
            decode_raw_image(msg, topic=topic, t_ns=t)  # size checks even without video
        cam.sink.add(t, rgb)
        assert cam.frame_of is not None
        cam.frame_of[t] = cam.sink.count - 1
        self.prov.topic(topic).written += 1
        self._match_labels(cam)

    def labels(self, topic: str, role: Role, t: int, msg: Any) -> None:
        """A 16-bit label image at stamp ``t`` (ns), kept until its colour frame arrives."""
        if role.name:
            name = role.name
        else:  # /camera/<cam>/labels/compressed -> <cam>
            parts = [p for p in topic.split("/") if p]
            while parts and parts[-1] in _LABEL_SUFFIXES:
                parts = parts[:-1]
            name = camera_name_from_topic("/" + "/".join(parts) + "/image_raw")
        out = self._decode(topic, t, msg)
        if out is None:
            return
        kind, img = out
        if kind != "mono16":
            if img.ndim == 3 and np.array_equal(img[..., 0], img[..., 1]):
                img = img[..., 0].astype(np.uint16)
            else:
                self.prov.issue(topic, "label image is not single-channel (dropped)", t)
                return
        cam = self._camera(name)
        cam.labels_topic = cam.labels_topic or topic
        pend = self._pending_labels.setdefault(name, [])
        pend.append((t, img))
        self._match_labels(cam)
        if len(pend) > _MAX_PENDING_LABELS:
            t_old, _ = pend.pop(0)
            self.prov.issue(
                topic, "label image without a colour frame of the same stamp (dropped)", t_old
            )

    def _match_labels(self, cam: _Camera) -> None:
        pend = self._pending_labels.get(cam.name)
        if not pend or cam.frame_of is None:
            return
        keep = []
        for t, img in pend:
            idx = cam.frame_of.get(t)
            if idx is None:
                keep.append((t, img))
                continue
            self._write_label(cam, idx, img)
        self._pending_labels[cam.name] = keep

    def _write_label(self, cam: _Camera, frame_index: int, img: np.ndarray) -> None:
        schema = pa.schema([pa.field("frame_index", pa.int64()), pa.field("png", pa.binary())])
        entry = self._labels_writers.get(cam.name)
        if entry is None:
            path = self.ctx.writer.path(
                f"{self.ctx.episode_dir()}/cameras/{cam.name}/labels.parquet"
            )
            entry = (pq.ParquetWriter(path, schema, compression="none"), 0)
        writer, n = entry
        writer.write_table(
            pa.Table.from_arrays(
                [
                    pa.array([frame_index], pa.int64()),
                    pa.array([encode_label_png(img)], pa.binary()),
                ],
                schema=schema,
            )
        )
        self._labels_writers[cam.name] = (writer, n + 1)
        assert cam.labels_topic is not None
        self.prov.topic(cam.labels_topic).written += 1

    # ------------------------------------------------------------------ finishing
    def close_labels(self) -> None:
        """Close the label tables (before the cameras are declared)."""
        for writer, _ in self._labels_writers.values():
            writer.close()

    def report_pending(self) -> None:
        """Record the label images whose colour frame never arrived."""
        for name, pend in self._pending_labels.items():
            for t, _ in pend:
                self.prov.issue(
                    self.cameras[name].labels_topic or name,
                    "label image without a colour frame of the same stamp (dropped)",
                    t,
                )

    def _extrinsics(
        self, name: str, cam: _Camera, frame: str
    ) -> tuple[np.ndarray | None, str | None]:
        """``(T_world_cam, extrinsics_rel)`` of a camera: a static transform, or ``None`` and the
        path of a ``camera_extrinsics`` table written at the frame stamps (moving frame)."""
        world = self.world()
        hops = self.tf.buf.chain(world, frame) if frame else None
        if hops is None:
            self.prov.note(
                f"camera {name}: no /tf or /tf_static chain from {world!r} to "
                f"{frame or '(no frame_id)'!r}; T_world_cam set to identity"
            )
            return np.eye(4), None
        if frame and "optical" not in frame and frame not in self.opts.tf_cameras.values():
            self.prov.note(
                f"camera {name}: frame {frame!r} is taken as an optical frame (x right, y down, "
                "z forward); pass --tf-camera CAM=FRAME to choose another"
            )
        if not any(h.dynamic for h in hops):
            return self.tf.buf.lookup(world, frame), None
        self.tf.use(hops)
        stamps = np.array(sorted(cam.frame_of or {}), dtype=np.int64)
        T, ok = self.tf.poses_at(hops, stamps)
        for t in stamps[~ok]:
            self.prov.issue(
                cam.image_topic or name,
                "no /tf transform of the camera frame near this frame stamp (no extrinsics row)",
                int(t),
                drop=False,
            )
        if not ok.any():
            t0 = self.tf.buf.times(*self.tf.buf.driver(hops).edge)[:1]  # type: ignore[union-attr]
            T0, _ = self.tf.poses_at(hops, np.asarray(t0, np.int64))
            self.prov.note(
                f"camera {name}: frame {frame!r} moves in /tf but no frame stamp is covered; "
                "static T_world_cam taken from the first transform"
            )
            return T0[0], None
        vals = poses_of(T[ok])
        cols = [pa.array(stamps[ok], pa.int64())] + [pa.array(vals[:, j]) for j in range(7)]
        rel = f"{self.ctx.episode_dir()}/cameras/{name}/extrinsics.parquet"
        table = pa.Table.from_arrays(cols, names=["t_ns", *POSE_COLUMNS])
        self.ctx.writer.write_table(rel, table, kind="camera_extrinsics")
        self.prov.note(
            f"camera {name}: frame {frame!r} moves in /tf; T_world_cam written per frame "
            f"({int(ok.sum())} rows, extrinsics time_varying)"
        )
        return None, rel

    def close(self) -> None:
        """Close every camera, write its model and declare its ``camera/<name>`` stream.

        Raises:
            InputError: ``--tf-camera`` names a camera the source does not have.
        """
        ctx, ep = self.ctx, self.ctx.episode_dir()
        unknown = sorted(set(self.opts.tf_cameras) - set(self.cameras))
        if unknown:
            raise InputError(
                f"--tf-camera names camera(s) not in the source: {', '.join(unknown)}",
                where="--tf-camera / tf_cameras",
                hint=f"cameras: {', '.join(sorted(self.cameras)) or 'none'}",
            )
        for name, cam in sorted(self.cameras.items()):
            stats = cam.sink.close() if cam.sink is not None else None
            model = cam.model
            extrinsics_rel = None
            if model is not None:
                frame = self.opts.tf_cameras.get(name, cam.frame_id).lstrip("/")
                T, extrinsics_rel = self._extrinsics(name, cam, frame)
                if stats is not None and cam.sink is not None and cam.sink.size is not None:
                    if cam.sink.size != (model.width, model.height):
                        self.prov.issue(
                            cam.image_topic or name,
                            f"image size {cam.sink.size} differs from camera_info "
                            f"{(model.width, model.height)}",
                            None,
                            drop=False,
                        )
                ext = "time_varying" if extrinsics_rel else "static"
                ctx.writer.set_camera(replace(model, T_world_cam=T, extrinsics=ext))
            elif cam.image_topic is not None:
                self.prov.note(
                    f"camera {name}: images without a usable camera_info; no intrinsics written "
                    "(pass the calibration with --map or record camera_info)"
                )
            if stats is not None and stats.rows:
                entry: dict[str, Any] = {
                    "kind": "camera",
                    "camera": name,
                    "frames": f"{ep}/cameras/{name}/frames.parquet",
                    "stamp_source": cam.stamp_source or "log_time",
                    "offset_ns": 0,
                    "nominal_rate_hz": stats.rate_hz,
                    "source": cam.image_topic or "",
                }
                if self.opts.video:
                    entry["video"] = f"{ep}/cameras/{name}/rgb.mp4"
                if name in self._labels_writers:
                    entry["labels"] = f"{ep}/cameras/{name}/labels.parquet"
                if extrinsics_rel:
                    entry["extrinsics"] = extrinsics_rel
                ctx.add_stream(
                    f"camera/{name}", entry, start_ns=stats.start_ns, end_ns=stats.end_ns
                )

    def abort(self) -> None:
        """Close open files after a failure (the writer discards them)."""
        for cam in self.cameras.values():
            if cam.sink is not None:
                cam.sink.abort()
        self.close_labels()
