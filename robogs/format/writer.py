"""``DatasetWriter``: the one atomic way to create or change a dataset.

The writer builds the new version in a hidden sibling folder
(``.<name>.tmp-<id>``), writes ``manifest.json`` last with the sha256, size and
row count of every file, then swaps it into place with renames. If anything
fails or the process dies before the swap, the previous dataset is untouched;
a stale temp folder is removed by the next writer. A lock file refuses a
second concurrent writer.

The swap exchanges the two folders in one ``renameat2(RENAME_EXCHANGE)`` call
where the kernel and file system allow it, so the dataset path always holds a
complete version; elsewhere it falls back to two renames, and a crash between
them is undone by the next writer. The lock is an advisory ``flock`` on
``.<name>.lock`` holding the writer's PID, opened with ``O_NOFOLLOW``; the file is
removed when the writer commits, aborts or the process exits. The kernel releases the
lock when the process dies (even by ``kill -9``), so a stale lock file never blocks
anyone: the next writer takes it over with a note naming the dead PID. Dataset names
are matched literally, never as glob patterns.

Editing an existing dataset starts from hard links to its files (copies where
links are impossible); every write replaces a file by rename, so the original
files are never modified in place.
"""

from __future__ import annotations

import datetime as _dt
import errno
import fcntl
import functools
import hashlib
import logging
import os
import shutil
import stat
import uuid
import weakref
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import pyarrow as pa
import pyarrow.parquet as pq

from .cameras import CameraModel
from .errors import (
    ConcurrentEditError,
    DatasetExistsError,
    FormatError,
    LockError,
    output_error,
)
from .jsonio import dumps_json
from .paths import check_relpath
from .replace import check_replaceable, exchange, recover, sibling_versions
from .schemas import schema_problems
from .spec_version import SPEC_VERSION
from .splats import SplatSet, write_splat_ply
from .tables import TABLES, check_table_schema

if TYPE_CHECKING:
    from .dataset import Dataset

__all__ = ["DatasetWriter", "CONVENTIONS", "sha256_file", "sibling_versions"]

CONVENTIONS: dict[str, Any] = {
    "units": "SI",
    "world_frame": {"name": "world", "up": "+z", "handedness": "right", "origin": "robot_base"},
    "quaternion_order": "wxyz",
    "camera_axes": "opencv",
    "time_unit": "ns",
}

_CHUNK = 1 << 20


def sha256_file(path: Path) -> str:
    """Hex sha256 of a file, read in 1 MiB chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


def _robogs_version() -> str:
    try:
        from importlib.metadata import version

        return version("robogs")
    except Exception:  # not installed as a distribution (e.g. source tree)
        return "0+unknown"


_LOG = logging.getLogger(__name__)
_F = TypeVar("_F", bound=Callable[..., Any])
_LOCK_FLAGS = os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC


def _pid_alive(pid: int) -> bool:
    """Whether a process with this PID exists (it may belong to another user)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class _DatasetLock:
    """Exclusive advisory ``flock`` on ``.<name>.lock`` beside a dataset, holding the PID.

    The file is opened with ``O_NOFOLLOW|O_CREAT`` and must be a regular file with one link,
    so a planted symlink or hard link is refused and never written. The holder unlinks the file
    before unlocking it; an acquirer re-checks after locking that the path still names the
    file it locked (else it retries), so two writers never hold two different files. A file
    left by a killed holder is taken over with a note naming its PID.
    """

    def __init__(self, path: Path, target: Path) -> None:
        self.path = path
        self.pid = os.getpid()
        self.fd: int | None = None
        for _ in range(50):
            fd = self._open(target)
            st = os.fstat(fd)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _pid_in(os.pread(fd, 32, 0))
                os.close(fd)
                raise LockError(
                    f"another robogs process (PID {holder or 'unknown'}) is writing this "
                    f"dataset; lock file {path}",
                    path=target,
                    hint="wait for it to finish; the lock is released when that process exits, "
                    "even if it is killed",
                ) from None
            try:
                now = os.lstat(path)
            except FileNotFoundError:
                now = None
            if now is not None and (now.st_dev, now.st_ino) == (st.st_dev, st.st_ino):
                break
            os.close(fd)  # the previous holder unlinked it in between: lock the new file
        else:  # pragma: no cover - 50 lost races in a row
            raise LockError(f"could not take the lock file {path}", path=target)
        self.fd = fd
        dead = _pid_in(os.pread(fd, 32, 0))
        if dead is not None and dead != self.pid:
            state = "no longer running" if not _pid_alive(dead) else "no longer holding it"
            _LOG.warning(
                "robogs: note: took over the stale lock %s left by PID %d (%s)", path, dead, state
            )
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{self.pid}\n".encode("ascii"), 0)

    def _open(self, target: Path) -> int:
        try:
            fd = os.open(self.path, _LOCK_FLAGS, 0o644)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise FormatError(
                    f"the lock file {self.path} is a symbolic link; refusing to follow it",
                    path=target,
                    hint="remove the link (robogs creates its own lock file)",
                ) from None
            if exc.errno == errno.EISDIR:
                hint = "it is a folder; remove it (robogs creates its own lock file)"
            else:
                hint = "the folder that holds the dataset must be writable"
            raise FormatError(
                f"cannot create the lock file {self.path}: {exc.strerror}", path=target, hint=hint
            ) from None
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_nlink != 1:
            os.close(fd)
            raise FormatError(
                f"the lock file {self.path} is not a plain file of its own "
                f"({'hard-linked' if stat.S_ISREG(st.st_mode) else 'not a regular file'}); "
                "refusing to use it",
                path=target,
                hint="remove it (robogs creates its own lock file)",
            )
        return fd

    def release(self) -> None:
        """Unlink the lock file (if it is still ours), then unlock; idempotent, owner only."""
        fd, self.fd = self.fd, None
        if fd is None or os.getpid() != self.pid:
            return
        try:
            now, st = os.lstat(self.path), os.fstat(fd)
            if (now.st_dev, now.st_ino) == (st.st_dev, st.st_ino):
                os.unlink(self.path)
        except OSError:
            pass
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)


def _pid_in(data: bytes) -> int | None:
    """The PID a lock file holds, or None if empty or not a number."""
    text = data.decode("ascii", errors="replace").strip()
    return int(text) if text.isdigit() else None


def _abandon(lock: _DatasetLock, tmp: Path) -> None:
    """Discard an uncommitted temp folder and release the lock (GC, exit or abort)."""
    if os.getpid() == lock.pid:
        shutil.rmtree(tmp, ignore_errors=True)
    lock.release()


def _writes(action: str) -> Callable[[_F], _F]:
    """Turn an ``OSError`` of a writer method into an :class:`OutputError` naming the cause.

    Disk full, read-only file system, name too long or busy is then one clear line, and a
    converter never mistakes it for a broken input (it re-raises robogs errors as they are).
    """

    def wrap(fn: _F) -> _F:
        @functools.wraps(fn)
        def inner(self: DatasetWriter, *args: Any, **kwargs: Any) -> Any:
            try:
                return fn(self, *args, **kwargs)
            except OSError as exc:
                raise output_error(exc, path=self.target, action=action) from None

        return inner  # type: ignore[return-value]

    return wrap


class DatasetWriter:
    """Builds a dataset version in a temp folder and swaps it in on ``commit``.

    Use as a context manager: leaving the block without ``commit()`` (or with an
    exception) discards the temp folder and leaves the target as it was.
    """

    def __init__(
        self,
        target: Path,
        *,
        base: Dataset | None,
        overwrite: bool,
        name: str | None,
        protect: Sequence[str | Path] = (),
    ) -> None:
        # an edit of a dataset reached through a symlink swaps the real folder, keeping the link
        self.target = Path(target).resolve() if base is not None else Path(target).absolute()
        self.base = base
        parent = self.target.parent
        if not parent.is_dir():
            raise FormatError(
                "parent folder of the output does not exist", path=parent, hint="create it first"
            )
        self.committed = False
        self._lock: _DatasetLock | None = self._acquire_lock()
        try:
            self._recover()
            self._check_unchanged(base)
            if base is None and self.target.exists() and not overwrite:
                raise DatasetExistsError(
                    "output already exists",
                    path=self.target,
                    hint="choose another path or pass --force to replace it",
                )
            if base is None:  # --force replaces only a robogs dataset that is not an input
                check_replaceable(self.target, folder=True, sources=protect, what="output")
            self.tmp = parent / f".{self.target.name}.tmp-{uuid.uuid4().hex[:8]}"
            try:  # writability is known before any work: a read-only parent fails here
                self.tmp.mkdir()
            except OSError as exc:
                raise output_error(exc, path=self.target, action="creating the dataset") from None
        except BaseException:
            self._release_lock()
            raise
        # on abort, garbage collection or interpreter exit: temp folder and lock file go
        self._finalizer = weakref.finalize(self, _abandon, self._lock, self.tmp)
        if base is not None:
            merged = base.full_manifest()  # a sharded base: its chunk indexes merged in
            self.manifest: dict[str, Any] = {k: v for k, v in merged.items() if k != "files"}
            self._link_base(base)
        else:
            self.manifest = {
                "format": "robogs",
                "spec_version": SPEC_VERSION,
                "name": name or self.target.name,
                "conventions": dict(CONVENTIONS),
                "episodes": [],
            }

    # -- locking and recovery ----------------------------------------------------
    @property
    def lock_path(self) -> Path:
        """The lock file beside the dataset, ``.<name>.lock``."""
        return self.target.parent / f".{self.target.name}.lock"

    def _acquire_lock(self) -> _DatasetLock:
        return _DatasetLock(self.lock_path, self.target)

    def _release_lock(self) -> None:
        lock, self._lock = getattr(self, "_lock", None), None
        if lock is not None:
            lock.release()

    def _recover(self) -> None:
        """Finish or undo a swap interrupted by a crash, and remove temp folders: the lock is
        held, so every temp folder of this dataset belongs to a dead writer (with a note)."""
        recover(self.target, stale_tmp_s=-1.0)

    def _check_unchanged(self, base: Dataset | None) -> None:
        """Optimistic concurrency: under the lock, the dataset must still be the version read.

        Two commands that read the same revision and both commit would otherwise lose the
        first one's work (e.g. two ``robogs fit`` runs writing the same physics revision).
        """
        if base is None or base.manifest_stamp is None:
            return
        from .dataset import MANIFEST_NAME, manifest_stamp

        now = manifest_stamp(self.target / MANIFEST_NAME)
        if now != base.manifest_stamp:
            raise ConcurrentEditError(
                "dataset changed on disk since this command read it; nothing was written",
                path=self.target,
                hint="another robogs command committed a new version meanwhile; run this one "
                "again on the new version",
            )

    @_writes("linking the previous version")
    def _link_base(self, base: Dataset) -> None:
        for rel in base.files:
            src = base.resolve(rel)
            dst = self.tmp / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            try:
                os.link(src, dst)
            except OSError:
                shutil.copy2(src, dst)

    # -- low-level file operations -----------------------------------------------
    def path(self, rel: str) -> Path:
        """Absolute path inside the temp folder for ``rel`` (parents created).

        A file still hard-linked to the previous version is first replaced by a private
        copy, so writing through this path can never change the previous version.
        """
        rel = check_relpath(rel, where="writer")
        if rel == "manifest.json":
            raise FormatError(
                "manifest.json is written by commit()", hint="set fields on writer.manifest"
            )
        p = self.tmp / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        if p.is_file() and p.stat().st_nlink > 1:
            part = p.with_name(p.name + ".part")
            shutil.copy2(p, part)
            os.replace(part, p)
        return p

    def _part(self, rel: str) -> tuple[Path, Path]:
        final = self.path(rel)
        return final, final.with_name(final.name + ".part")

    @_writes("writing the dataset")
    def write_bytes(self, rel: str, data: bytes) -> Path:
        final, part = self._part(rel)
        part.write_bytes(data)
        os.replace(part, final)
        return final

    @_writes("writing the dataset")
    def write_text(self, rel: str, text: str) -> Path:
        return self.write_bytes(rel, text.encode("utf-8"))

    @_writes("writing the dataset")
    def write_json(self, rel: str, obj: Any, *, schema: str | None = None) -> Path:
        """Write a JSON sidecar, checking it against ``spec/schemas/<schema>`` first."""
        if schema is not None:
            problems = schema_problems(schema, obj)
            if problems:
                raise FormatError(
                    f"refusing to write invalid {schema}: {problems[0].message}",
                    path=rel,
                    where=problems[0].pointer,
                )
        return self.write_text(rel, dumps_json(obj))

    @_writes("writing the dataset")
    def copy_file(self, rel: str, src: str | Path) -> Path:
        final, part = self._part(rel)
        shutil.copyfile(src, part)
        os.replace(part, final)
        return final

    @_writes("writing the dataset")
    def remove(self, rel: str) -> None:
        p = self.tmp / check_relpath(rel)
        if p.is_dir():
            shutil.rmtree(p)
        elif p.exists():
            p.unlink()

    @_writes("writing a table")
    def write_table(self, rel: str, table: pa.Table, *, kind: str) -> Path:
        """Write a parquet table of a kind from ``robogs.format.tables``, checking its columns.

        Stamped tables must have non-null int64 ``t_ns``.
        """
        problems = check_table_schema(kind, table.schema)
        if problems:
            raise FormatError(
                f"table does not match kind {kind!r}: {'; '.join(problems)}", path=rel
            )
        if TABLES[kind].stamped and table.column("t_ns").null_count:
            raise FormatError("t_ns has nulls", path=rel, where="t_ns")
        final, part = self._part(rel)
        pq.write_table(table, part, compression="zstd", row_group_size=1 << 16)
        os.replace(part, final)
        return final

    @_writes("writing splats")
    def write_splats(self, rel: str, splats: SplatSet) -> Path:
        final, part = self._part(rel)
        write_splat_ply(part, splats)
        os.replace(part, final)
        return final

    # -- manifest-level helpers ---------------------------------------------------
    def set_robot(
        self,
        urdf_rel: str,
        *,
        base_link: str | None = None,
        ee_link: str | None = None,
        mdh_rel: str | None = None,
    ) -> None:
        robot = dict(self.manifest.get("robot", {}))
        robot["urdf"] = urdf_rel
        for k, v in (("base_link", base_link), ("ee_link", ee_link), ("mdh", mdh_rel)):
            if v is not None:
                robot[k] = v
        self.manifest["robot"] = robot

    def set_asset(self, name: str, **entry: Any) -> None:
        """Declare an asset: ``kind`` ('object'|'table'|'background'), ``mesh``, ``splats``."""
        assets = dict(self.manifest.get("assets", {}))
        assets[name] = {**assets.get(name, {}), **entry}
        self.manifest["assets"] = assets

    def set_camera(self, camera: CameraModel) -> None:
        rel = f"cameras/{camera.name}.json"
        self.write_json(rel, camera.to_dict(), schema="camera")
        self.manifest.setdefault("cameras", {})[camera.name] = rel

    def set_physics(self, physics: dict[str, Any], *, note: str | None = None) -> int:
        """Write ``physics.json`` as a new revision; the previous one goes to ``physics/history``.

        Returns:
            the new revision number.
        """
        old_rel = self.manifest.get("physics")
        prev = None
        if old_rel is not None and (self.tmp / old_rel).exists():
            import json

            prev = json.loads((self.tmp / old_rel).read_text())
            self.write_text(
                f"physics/history/rev-{int(prev['revision']):04d}.json", dumps_json(prev)
            )
        doc = dict(physics)
        doc["revision"] = 1 if prev is None else int(prev["revision"]) + 1
        doc["parent_revision"] = None if prev is None else int(prev["revision"])
        if note is not None:
            doc["note"] = note
        self.write_json("physics.json", doc, schema="physics")
        self.manifest["physics"] = "physics.json"
        return doc["revision"]

    def add_episode(
        self,
        episode_id: str,
        *,
        start_ns: int,
        end_ns: int,
        streams: dict[str, dict[str, Any]],
        segment: str | None = None,
    ) -> None:
        """Declare an episode and its streams (replacing one with the same id)."""
        entry: dict[str, Any] = {
            "id": episode_id,
            "start_ns": int(start_ns),
            "end_ns": int(end_ns),
            "streams": streams,
        }
        if segment is not None:
            entry["segment"] = segment
        eps = [e for e in self.manifest.get("episodes", []) if e["id"] != episode_id]
        eps.append(entry)
        self.manifest["episodes"] = sorted(eps, key=lambda e: e["id"])

    # -- commit ---------------------------------------------------------------------
    def _file_entries(self) -> dict[str, dict[str, Any]]:
        files: dict[str, dict[str, Any]] = {}
        for p in sorted(self.tmp.rglob("*")):
            if not p.is_file() or p.name == "manifest.json" and p.parent == self.tmp:
                continue
            if p.name.endswith(".part"):
                p.unlink()
                continue
            rel = p.relative_to(self.tmp).as_posix()
            entry: dict[str, Any] = {"sha256": sha256_file(p), "size": p.stat().st_size}
            if p.suffix == ".parquet":
                entry["rows"] = pq.ParquetFile(p).metadata.num_rows
            files[rel] = entry
        return files

    @_writes("committing the dataset")
    def commit(self) -> Dataset:
        """Write the manifest last, swap the new version into place, release the lock."""
        from .dataset import Dataset

        if self.committed:
            raise FormatError("writer already committed", path=self.target)
        self.manifest.setdefault(
            "created_utc", _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
        )
        self.manifest["generator"] = {
            **self.manifest.get("generator", {}),
            "name": "robogs",
            "version": _robogs_version(),
        }
        self.manifest["spec_version"] = SPEC_VERSION
        self.manifest["files"] = self._file_entries()
        sharded = "shards" in self.manifest  # the chunked layout (checked merged, then split)
        merged = {k: v for k, v in self.manifest.items() if k != "shards"}
        problems = schema_problems("manifest", merged if sharded else self.manifest)
        if sharded and not problems:  # one index per episodes/chunk-NNN/
            from .checks.context import STREAM_FILE_FIELDS
            from .shards import shard_manifest

            self.manifest = shard_manifest(
                self.tmp, self.manifest, stream_fields=tuple(STREAM_FILE_FIELDS), hasher=sha256_file
            )
            problems = schema_problems("manifest", self.manifest)
        if problems:
            raise FormatError(
                f"refusing to commit an invalid manifest: {problems[0].message}",
                path=self.target,
                where=problems[0].pointer,
            )
        mpath = self.tmp / "manifest.json"
        with open(mpath, "w", encoding="utf-8") as fh:
            fh.write(dumps_json(self.manifest))
            fh.flush()
            os.fsync(fh.fileno())
        self._swap()
        self.committed = True
        self._finalizer.detach()
        self._release_lock()
        return Dataset.open(self.target)

    def _swap(self) -> None:
        parent = self.target.parent
        old = None
        if self.target.exists():
            if exchange(self.tmp, self.target):
                old = self.tmp  # now holds the previous version
            else:
                old = parent / f".{self.target.name}.old-{uuid.uuid4().hex[:8]}"
                os.rename(self.target, old)
                os.rename(self.tmp, self.target)
        else:
            os.rename(self.tmp, self.target)
        dir_fd = os.open(parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

    def abort(self) -> None:
        """Discard the temp folder and remove the lock file; the target is left as it was."""
        finalizer = getattr(self, "_finalizer", None)
        if finalizer is not None and not self.committed:
            finalizer()
        self._release_lock()

    def __enter__(self) -> DatasetWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if not self.committed:
            self.abort()
