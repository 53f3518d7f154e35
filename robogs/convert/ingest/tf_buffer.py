"""Transform tree over time, from ``/tf`` and ``/tf_static`` (tf2_msgs/TFMessage).

Each ``TransformStamped`` is one sample of the edge ``T_parent_child`` (``header.frame_id`` =
parent, ``child_frame_id`` = child). Static edges hold one transform; dynamic edges hold a time
series. :meth:`TfBuffer.lookup_at` composes the chain between two frames at given stamps the way
tf2 does (http://wiki.ros.org/tf2): every dynamic edge is interpolated at the stamp, translation
linearly and rotation by slerp (Shoemake 1985), and a stamp outside an edge's samples is
accepted only within ``tolerance_ns`` of its first or last sample (that sample is used).

Memory: samples are kept in RAM up to ``spill_rows`` per edge; beyond that they are appended to
a temporary file and read back through a memory map, so a long recording does not need its
whole ``/tf`` in memory. Transforms are 4x4 float64, metres; quaternions are stored (w, x, y, z).
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robogs.format.frames import matrix_to_quat_np, quat_to_matrix_np

from .tf_tree import frame_path

__all__ = ["TfBuffer", "Hop", "quats_to_matrices", "matrices_to_quats", "slerp_wxyz", "poses_of"]

_REC = np.dtype([("t", "<i8"), ("p", "<f8", (7,))])  # p = x y z qw qx qy qz
_SORT_CHUNK = 1 << 18


def quats_to_matrices(q_wxyz: np.ndarray) -> np.ndarray:
    """[N, 3, 3] rotations of quaternions [N, 4] (w, x, y, z); normalised first."""
    return quat_to_matrix_np(np.asarray(q_wxyz, dtype=np.float64).reshape(-1, 4))


def matrices_to_quats(R: np.ndarray) -> np.ndarray:
    """[N, 4] quaternions (w, x, y, z), ``w >= 0``, of rotations [N, 3, 3]."""
    return matrix_to_quat_np(np.asarray(R, dtype=np.float64).reshape(-1, 3, 3))


def slerp_wxyz(q0: np.ndarray, q1: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation of quaternion pairs [N, 4] at fractions u [N] (shortest arc)."""
    q0 = q0 / np.linalg.norm(q0, axis=1, keepdims=True)
    q1 = q1 / np.linalg.norm(q1, axis=1, keepdims=True)
    d = np.sum(q0 * q1, axis=1)
    q1 = np.where(d[:, None] < 0, -q1, q1)
    d = np.clip(np.abs(d), 0.0, 1.0)
    theta = np.arccos(d)
    s = np.sin(theta)
    small = s < 1e-9
    s_safe = np.where(small, 1.0, s)
    w0 = np.where(small, 1.0 - u, np.sin((1.0 - u) * theta) / s_safe)
    w1 = np.where(small, u, np.sin(u * theta) / s_safe)
    q = w0[:, None] * q0 + w1[:, None] * q1
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _invert(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms [..., 4, 4]."""
    R = T[..., :3, :3]
    Rt = np.swapaxes(R, -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


class _EdgeSamples:
    """Samples of one dynamic edge: RAM first, a temp file past ``spill_rows``."""

    def __init__(self, spill_rows: int, spill_dir: Callable[[], str]) -> None:
        self._buf: list[tuple[int, tuple[float, ...]]] = []
        self._spill_rows = spill_rows
        self._spill_dir = spill_dir
        self._file: Path | None = None
        self._spilled = 0
        self.t: np.ndarray = np.zeros(0, np.int64)
        self.p: np.ndarray = np.zeros((0, 7))

    def append(self, t_ns: int, vals: tuple[float, ...]) -> None:
        self._buf.append((t_ns, vals))
        if len(self._buf) >= self._spill_rows:
            self._spill()

    def _spill(self) -> None:
        if not self._buf:
            return
        if self._file is None:
            self._file = Path(tempfile.mkstemp(suffix=".tf", dir=self._spill_dir())[1])
        arr = np.array(self._buf, dtype=_REC)
        with open(self._file, "ab") as fh:
            arr.tofile(fh)
        self._spilled += len(self._buf)
        self._buf.clear()

    def finalize(self) -> int:
        """Sort by stamp, keep the last sample of equal stamps; returns how many were dropped."""
        if self._file is None:
            rec = np.array(self._buf, dtype=_REC)
            self._buf.clear()
        else:
            self._spill()
            rec = np.memmap(self._file, dtype=_REC, mode="r", shape=(self._spilled,))
        t = np.asarray(rec["t"])
        n = t.size
        if n and not np.all(t[1:] > t[:-1]):
            order = np.argsort(t, kind="stable")
            ts = t[order]
            order = order[np.r_[ts[1:] != ts[:-1], True]]
            if self._file is None:
                rec = rec[order]
            else:
                path = self._file.with_suffix(".sorted")
                out = np.memmap(path, dtype=_REC, mode="w+", shape=(order.size,))
                for i in range(0, order.size, _SORT_CHUNK):
                    out[i : i + _SORT_CHUNK] = rec[order[i : i + _SORT_CHUNK]]
                out.flush()
                rec = np.memmap(path, dtype=_REC, mode="r", shape=(order.size,))
        self.t = rec["t"]
        self.p = rec["p"]
        return n - int(self.t.size)

    def at(self, t: np.ndarray, tolerance_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """Interpolated ``[N, 4, 4]`` transforms at stamps ``t`` [N] and a validity mask [N]."""
        n = self.t.size
        out = np.tile(np.eye(4), (t.size, 1, 1))
        if n == 0:
            return out, np.zeros(t.size, bool)
        i = np.searchsorted(self.t, t, side="right") - 1
        before, after = i < 0, i >= n - 1
        ok = np.ones(t.size, bool)
        ok[before] = (self.t[0] - t[before]) <= tolerance_ns
        ok[after] = (t[after] - self.t[n - 1]) <= tolerance_ns
        i0 = np.clip(i, 0, n - 1)
        i1 = np.clip(i + 1, 0, n - 1)
        t0 = np.asarray(self.t[i0], dtype=np.int64)
        t1 = np.asarray(self.t[i1], dtype=np.int64)
        span = (t1 - t0).astype(np.float64)
        u = np.where(span > 0, (t - t0).astype(np.float64) / np.where(span > 0, span, 1.0), 0.0)
        u = np.clip(np.where(before | after, 0.0, u), 0.0, 1.0)
        p0 = np.asarray(self.p[i0], dtype=np.float64)
        p1 = np.asarray(self.p[i1], dtype=np.float64)
        xyz = p0[:, :3] + u[:, None] * (p1[:, :3] - p0[:, :3])
        q = slerp_wxyz(p0[:, 3:], p1[:, 3:], u)
        out[:, :3, :3] = quats_to_matrices(q)
        out[:, :3, 3] = xyz
        return out, ok

    def close(self) -> None:
        self.t = np.zeros(0, np.int64)
        self.p = np.zeros((0, 7))


@dataclass(frozen=True)
class Hop:
    """One step of a chain: ``T_a_b`` is edge ``(a, b)`` or the inverse of edge ``(b, a)``."""

    a: str
    b: str
    inverse: bool
    dynamic: bool

    @property
    def edge(self) -> tuple[str, str]:
        """The stored edge ``(parent, child)``."""
        return (self.b, self.a) if self.inverse else (self.a, self.b)


class TfBuffer:
    """Static and time-varying transforms between frames.

    Args:
        tolerance_ns: how far a stamp may lie outside a dynamic edge's samples (ns).
        spill_rows: samples of one edge held in RAM before spilling to a temp file.
    """

    def __init__(self, *, tolerance_ns: int = 100_000_000, spill_rows: int = 1 << 18) -> None:
        self.tolerance_ns = int(tolerance_ns)
        self._spill_rows = int(spill_rows)
        self._static: dict[tuple[str, str], np.ndarray] = {}
        self._dynamic: dict[tuple[str, str], _EdgeSamples] = {}
        self._adj: dict[str, set[str]] = {}
        self._tmp: str | None = None
        self.finalized = False
        self.duplicates = 0

    # ------------------------------------------------------------------ building
    def _spill_dir(self) -> str:
        if self._tmp is None:
            self._tmp = tempfile.mkdtemp(prefix="robogs-tf-")
        return self._tmp

    def _link(self, parent: str, child: str) -> None:
        self._adj.setdefault(parent, set()).add(child)
        self._adj.setdefault(child, set()).add(parent)

    @property
    def frames(self) -> set[str]:
        return set(self._adj)

    @property
    def dynamic_edges(self) -> list[tuple[str, str]]:
        return sorted(self._dynamic)

    @property
    def static_edges(self) -> list[tuple[str, str]]:
        return sorted(self._static)

    def add_static(self, parent: str, child: str, T_parent_child: np.ndarray) -> None:
        """Add (or replace) a static edge."""
        parent, child = parent.lstrip("/"), child.lstrip("/")
        self._static[(parent, child)] = np.asarray(T_parent_child, dtype=np.float64)
        self._link(parent, child)

    def add_sample(
        self, parent: str, child: str, t_ns: int, xyz: Iterable[float], q_wxyz: Iterable[float]
    ) -> None:
        """Add one sample of a dynamic edge (translation m, quaternion w, x, y, z)."""
        if self.finalized:
            raise RuntimeError("internal: TfBuffer sample added after finalize()")
        parent, child = parent.lstrip("/"), child.lstrip("/")
        key = (parent, child)
        edge = self._dynamic.get(key)
        if edge is None:
            edge = self._dynamic[key] = _EdgeSamples(self._spill_rows, self._spill_dir)
            self._link(parent, child)
        edge.append(int(t_ns), (*map(float, xyz), *map(float, q_wxyz)))

    def finalize(self) -> list[tuple[str, str]]:
        """Sort every edge's samples; returns edges that are both static and dynamic.

        Such an edge is treated as dynamic (its static transform is forgotten).
        """
        if self.finalized:
            return []
        both = sorted(set(self._static) & set(self._dynamic))
        for key in both:
            del self._static[key]
        for edge in self._dynamic.values():
            self.duplicates += edge.finalize()
        self.finalized = True
        return both

    def close(self) -> None:
        """Release the samples and remove the spill files."""
        for edge in self._dynamic.values():
            edge.close()
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    # ------------------------------------------------------------------ queries
    def times(self, parent: str, child: str) -> np.ndarray:
        """Sorted sample stamps (ns) of a dynamic edge."""
        return self._dynamic[(parent, child)].t

    def parent_of(self, child: str) -> str | None:
        """Parent of ``child`` through a dynamic edge, else through a static one."""
        for table in (self._dynamic, self._static):
            for p, c in table:
                if c == child:
                    return p
        return None

    def chain(self, target: str, source: str) -> list[Hop] | None:
        """Hops composing ``T_target_source`` (shortest path), or ``None`` when not connected."""
        path = frame_path(self._adj, target, source)
        if path is None:
            return None
        hops = []
        for a, b in zip(path[:-1], path[1:], strict=True):
            if (a, b) in self._dynamic or (a, b) in self._static:
                hops.append(Hop(a, b, False, (a, b) in self._dynamic))
            else:
                hops.append(Hop(a, b, True, (b, a) in self._dynamic))
        return hops

    def lookup(self, target: str, source: str) -> np.ndarray | None:
        """``T_target_source`` when the chain is all static, else ``None``."""
        hops = self.chain(target, source)
        if hops is None or any(h.dynamic for h in hops):
            return None
        T = np.eye(4)
        for h in hops:
            M = self._static[h.edge]
            T = T @ (np.linalg.inv(M) if h.inverse else M)
        return T

    def compose(self, hops: list[Hop], t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``[N, 4, 4]`` transforms of a chain at stamps ``t_ns`` [N] and a validity mask [N]."""
        if not self.finalized:
            raise RuntimeError("internal: TfBuffer queried before finalize()")
        t = np.asarray(t_ns, dtype=np.int64).reshape(-1)
        T = np.tile(np.eye(4), (t.size, 1, 1))
        ok = np.ones(t.size, bool)
        for h in hops:
            if h.dynamic:
                M, good = self._dynamic[h.edge].at(t, self.tolerance_ns)
                ok &= good
            else:
                M = self._static[h.edge][None]
            T = T @ (_invert(M) if h.inverse else M)
        return T, ok

    def driver(self, hops: list[Hop]) -> Hop | None:
        """The dynamic hop nearest the chain's source frame (its stamps drive a pose stream)."""
        for h in reversed(hops):
            if h.dynamic:
                return h
        return None


def poses_of(T: np.ndarray) -> np.ndarray:
    """Rows ``x y z qw qx qy qz`` [N, 7] of transforms [N, 4, 4]."""
    return np.concatenate([T[:, :3, 3], matrices_to_quats(T[:, :3, :3])], axis=1)
