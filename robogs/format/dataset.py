"""``Dataset``: the one way to read a robogs dataset (writing goes through ``DatasetWriter``).

Everything is lazy: opening reads only ``manifest.json``; tables, images,
meshes, splats and the URDF are read when asked for, and the chunk indexes of a sharded
dataset (``robogs.format.shards``) when its episodes or files are. Nothing here writes to
the dataset folder.

Example:
    >>> ds = Dataset.open("scene/")                       # doctest: +SKIP
    >>> js = ds.episode("ep000").table("joint_states")    # pyarrow.Table  # doctest: +SKIP
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from .budgets import resolve_budgets
from .cameras import CameraModel
from .errors import FormatError
from .jsonio import read_json
from .paths import resolve_inside
from .schemas import schema_problems
from .shards import ShardProblem, expand, is_sharded, read_chunk
from .spec_version import migrate
from .splats import SplatSet, read_splat_ply

if TYPE_CHECKING:
    import trimesh
    import yourdfpy

    from .writer import DatasetWriter

__all__ = ["Dataset", "Episode", "MANIFEST_NAME"]

MANIFEST_NAME = "manifest.json"


def read_parquet(path: Path, *, columns: list[str] | None = None) -> pa.Table:
    """Read a parquet file, turning Arrow errors into a ``FormatError`` naming the file."""
    try:
        return pq.read_table(path, columns=columns)
    except FileNotFoundError:
        raise FormatError(
            "table is missing", path=path, hint="restore it or re-create the dataset"
        ) from None
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise FormatError(
            f"unreadable parquet table ({type(exc).__name__}: {str(exc).splitlines()[0][:200]})",
            path=path,
            hint="the file is truncated or not parquet; re-export it",
        ) from None


def parquet_metadata(path: Path) -> pq.FileMetaData:
    """Read only a parquet footer (row count, schema) — cheap, for quick checks."""
    try:
        # an opened file skips pyarrow's file-system resolution of a path (~15 us a file)
        with pa.OSFile(str(path)) as fh:
            return pq.ParquetFile(fh).metadata
    except FileNotFoundError:
        raise FormatError("table is missing", path=path) from None
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise FormatError(
            f"unreadable parquet footer ({str(exc).splitlines()[0][:200]})",
            path=path,
            hint="the file is truncated or not parquet; re-export it",
        ) from None


class Episode:
    """One recorded episode: its streams, read lazily."""

    def __init__(self, dataset: Dataset, entry: dict[str, Any]) -> None:
        self.dataset = dataset
        self.entry = entry
        self.id: str = entry["id"]
        self.start_ns: int = int(entry["start_ns"])
        self.end_ns: int = int(entry["end_ns"])
        self.streams: dict[str, dict[str, Any]] = dict(entry.get("streams", {}))
        self.segment: str = str(entry.get("segment", self.id))

    def __repr__(self) -> str:
        return f"Episode({self.id!r}, streams={sorted(self.streams)})"

    def has(self, stream: str) -> bool:
        return stream in self.streams

    def stream(self, name: str) -> dict[str, Any]:
        try:
            return self.streams[name]
        except KeyError:
            raise FormatError(
                f"episode {self.id!r} has no stream {name!r}",
                path=self.dataset.manifest_path,
                where=f"episodes/{self.id}/streams",
                hint=f"available: {', '.join(sorted(self.streams)) or 'none'}",
            ) from None

    def _resolve_field(self, name: str, field: str) -> Path:
        st = self.stream(name)
        if field not in st:
            raise FormatError(
                f"stream {name!r} has no {field!r}",
                path=self.dataset.manifest_path,
                where=f"episodes/{self.id}/streams/{name}",
            )
        return self.dataset.resolve(st[field], where=f"episodes/{self.id}/streams/{name}/{field}")

    def table(self, name: str, *, columns: list[str] | None = None) -> pa.Table:
        """The stream's table (``path``), e.g. ``joint_states`` or ``object_poses``."""
        return read_parquet(self._resolve_field(name, "path"), columns=columns)

    def table_path(self, name: str) -> Path:
        return self._resolve_field(name, "path")

    @property
    def camera_streams(self) -> dict[str, dict[str, Any]]:
        """Camera streams keyed by camera name."""
        return {
            s["camera"]: s
            for s in self.streams.values()
            if s.get("kind") == "camera" and "camera" in s
        }

    def _camera_stream_name(self, camera: str) -> str:
        for name, s in self.streams.items():
            if s.get("kind") == "camera" and s.get("camera") == camera:
                return name
        raise FormatError(
            f"episode {self.id!r} has no stream for camera {camera!r}",
            path=self.dataset.manifest_path,
        )

    def frames(self, camera: str) -> pa.Table:
        """``t_ns, frame_index`` for every recorded frame of ``camera``."""
        return read_parquet(self._resolve_field(self._camera_stream_name(camera), "frames"))

    def video_path(self, camera: str) -> Path:
        return self._resolve_field(self._camera_stream_name(camera), "video")

    def labels_path(self, camera: str) -> Path:
        return self._resolve_field(self._camera_stream_name(camera), "labels")

    def iter_labels(self, camera: str, *, batch_rows: int = 64) -> Iterator[tuple[int, np.ndarray]]:
        """Yield ``(frame_index, label image [H, W] uint16)`` without loading all frames."""
        from .images import decode_label_png

        path = self.labels_path(camera)
        try:
            pf = pq.ParquetFile(path)
            for batch in pf.iter_batches(batch_size=batch_rows, columns=["frame_index", "png"]):
                idx = batch.column(0).to_numpy()
                for i, blob in zip(idx, batch.column(1).to_pylist(), strict=True):
                    yield int(i), decode_label_png(blob, path=path, where=f"frame_index {int(i)}")
        except (pa.ArrowException, OSError) as exc:
            raise FormatError(
                f"unreadable label table ({str(exc)[:200]})",
                path=path,
                hint="the file is truncated or not parquet; re-export it",
            ) from None

    def iter_video(self, camera: str) -> Iterator[np.ndarray]:
        """Yield RGB frames [H, W, 3] uint8 in file order."""
        from .images import iter_video_frames

        yield from iter_video_frames(self.video_path(camera))


def manifest_stamp(path: Path) -> tuple[int, int, int, int] | None:
    """(device, inode, size, mtime ns) of a manifest file; None when it cannot be stat'ed.

    Every commit writes the manifest into a new folder that is swapped into place, so a new
    version always has a new inode; an edit in place changes size or mtime.
    """
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


class Dataset:
    """A robogs dataset folder, opened for reading."""

    def __init__(self, root: Path, manifest: dict[str, Any]) -> None:
        self.root = root
        self.manifest = manifest
        #: identity of the manifest file as read (device, inode, size, mtime ns); an edit
        #: refuses to commit over a dataset whose manifest is no longer this one
        self.manifest_stamp: tuple[int, int, int, int] | None = None
        #: problems with chunk indexes met by ``full_manifest(lenient=True)``
        self.shard_problems: list[ShardProblem] = []
        self._merged: dict[str, Any] | None = None

    # -- opening and creating -------------------------------------------------
    @classmethod
    def open(cls, path: str | Path, *, check_schema: bool = True) -> Dataset:
        """Open a dataset folder, reading and checking only its manifest.

        Args:
            path: the dataset root folder.
            check_schema: raise on schema violations (the validator passes False
                and reports them as findings instead).

        Raises:
            FormatError: missing/malformed manifest; VersionError: newer major spec.
        """
        root = Path(path)
        if not root.is_dir():
            from .writer import sibling_versions  # the name is literal, never a glob

            olds = sibling_versions(root, "old") if not root.exists() else []
            raise FormatError(
                "not a dataset folder" if root.exists() else "dataset folder does not exist",
                path=root,
                hint=f"an interrupted write left the previous version in {olds[-1].name}; "
                "the next robogs write restores it (or rename it back)"
                if olds
                else "pass the folder that holds manifest.json",
            )
        mpath = root / MANIFEST_NAME
        for _ in range(3):  # a commit may swap the folder while we read: read until stable
            before = manifest_stamp(mpath)
            manifest = read_json(mpath, what="manifest", root=root)
            stamp = manifest_stamp(mpath)
            if stamp == before:
                break
        if not isinstance(manifest, dict):
            raise FormatError("manifest must be a JSON object", path=mpath, where="/")
        if manifest.get("format") != "robogs" and check_schema:
            raise FormatError(
                "not a robogs manifest (format != 'robogs')", path=mpath, where="/format"
            )
        if "spec_version" in manifest or check_schema:
            manifest = migrate(manifest, path=mpath)
        if check_schema:
            problems = schema_problems("manifest", manifest)
            if problems:
                p = problems[0]
                more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
                raise FormatError(
                    p.message + more,
                    path=mpath,
                    where=p.pointer,
                    hint="run robogs-validate for the full list",
                )
        ds = cls(root, manifest)
        ds.manifest_stamp = stamp
        return ds

    @classmethod
    def create(
        cls,
        path: str | Path,
        *,
        name: str | None = None,
        overwrite: bool = False,
        protect: Sequence[str | Path] = (),
    ) -> DatasetWriter:
        """Start writing a new dataset at ``path`` (atomically; see ``DatasetWriter``).

        With ``overwrite`` an existing *robogs dataset* at ``path`` is replaced on commit; any
        other folder, or one that is, holds or lies inside a path of ``protect`` (the command's
        inputs), is refused before any work (:func:`robogs.format.replace.check_replaceable`).
        """
        from .writer import DatasetWriter

        return DatasetWriter(Path(path), base=None, overwrite=overwrite, name=name, protect=protect)

    def edit(self) -> DatasetWriter:
        """Start an atomic edit of this dataset: a new version replaces it on commit."""
        from .writer import DatasetWriter

        return DatasetWriter(self.root, base=self, overwrite=True, name=self.name)

    # -- basic facts -----------------------------------------------------------
    @property
    def manifest_path(self) -> Path:
        return self.root / MANIFEST_NAME

    @property
    def name(self) -> str:
        return str(self.manifest.get("name", self.root.name))

    @property
    def spec_version(self) -> str:
        return str(self.manifest.get("spec_version", ""))

    @property
    def files(self) -> dict[str, dict[str, Any]]:
        """Every listed file (a sharded dataset's chunk indexes are read for it)."""
        return dict(self.full_manifest().get("files", {}))

    @property
    def sharded(self) -> bool:
        """True for the chunked layout of spec 1.1.0 (episodes listed in chunk indexes)."""
        return is_sharded(self.manifest)

    def full_manifest(self, *, lenient: bool = False) -> dict[str, Any]:
        """The manifest with every chunk index merged in (the manifest itself when flat).

        Read once and kept, and checked against the manifest schema (as a flat manifest is
        when opened). With ``lenient`` (the validator, which reports problems as findings)
        an unreadable or malformed index is left out and noted in :attr:`shard_problems`, and
        nothing is schema-checked.

        Raises:
            FormatError: a chunk index cannot be read, or the merged manifest breaks the
                schema (not ``lenient``).
        """
        if not self.sharded:
            return self.manifest
        if self._merged is None:
            problems: list[ShardProblem] | None = [] if lenient else None
            merged = expand(
                self.root, self.manifest, problems=problems, manifest_path=self.manifest_path
            )
            if not lenient:
                self._schema_checked(merged)
            self._merged, self.shard_problems = merged, problems or []
        return self._merged

    def _schema_checked(self, manifest: dict[str, Any], *, index: str | None = None) -> None:
        """Raise the first schema problem of a merged manifest (or of one chunk's entry)."""
        problems = schema_problems("manifest", {k: v for k, v in manifest.items() if k != "shards"})
        if problems:
            p = problems[0]
            raise FormatError(
                p.message,
                path=self.root / index if index else self.manifest_path,
                where=p.pointer if index is None else f"an episode entry: {p.pointer}",
                hint="run robogs-validate for the full list",
            )

    @property
    def num_episodes(self) -> int:
        """Number of episodes, from the manifest alone (no chunk index is read)."""
        shards = self.manifest.get("shards")
        if isinstance(shards, dict) and isinstance(shards.get("episodes"), int):
            return int(shards["episodes"])
        return len(self.full_manifest().get("episodes", []))

    @cached_property
    def budgets(self) -> dict[str, float]:
        """Default budgets merged with the dataset's overrides."""
        return resolve_budgets(self.manifest.get("budgets"), source=str(self.manifest_path))

    def resolve(self, rel: str, *, where: str | None = None) -> Path:
        """Absolute path of a dataset-relative path; refuses escapes from the root."""
        return resolve_inside(self.root, rel, source=self.manifest_path, where=where)

    # -- episodes ---------------------------------------------------------------
    @property
    def episodes(self) -> list[Episode]:
        return [Episode(self, e) for e in self.full_manifest().get("episodes", [])]

    def episode(self, episode_id: str | None = None) -> Episode:
        """One episode by id (the only one if ``episode_id`` is None).

        A sharded dataset reads its chunk indexes one at a time until the episode is found.
        """
        if self.sharded and self._merged is None and episode_id is not None:
            for e in self.manifest.get("episodes", []):
                if e.get("id") == episode_id:
                    return Episode(self, e)
            for entry in self.manifest["shards"].get("chunks", []):
                doc = read_chunk(self.root, entry, manifest_path=self.manifest_path)
                for e in doc["episodes"]:
                    if isinstance(e, dict) and e.get("id") == episode_id:
                        one = {**self.manifest, "episodes": [e], "files": {}}
                        self._schema_checked(one, index=entry["index"])
                        return Episode(self, e)
        eps = self.episodes
        if episode_id is None and len(eps) == 1:
            return eps[0]
        for e in eps:
            if e.id == episode_id:
                return e
        raise FormatError(
            f"no episode {episode_id!r}",
            path=self.manifest_path,
            where="episodes",
            hint=f"available: {', '.join(e.id for e in eps[:20]) or 'none'}"
            + (f", ... ({len(eps)} in all)" if len(eps) > 20 else ""),
        )

    # -- cameras, physics, robot, assets ---------------------------------------
    @property
    def camera_names(self) -> list[str]:
        return sorted(self.manifest.get("cameras", {}))

    def camera(self, name: str) -> CameraModel:
        """Intrinsics and static extrinsics of one camera."""
        rel = self.manifest.get("cameras", {}).get(name)
        if rel is None:
            raise FormatError(
                f"no camera {name!r}",
                path=self.manifest_path,
                where="cameras",
                hint=f"available: {', '.join(self.camera_names) or 'none'}",
            )
        path = self.resolve(rel, where=f"cameras/{name}")
        doc = read_json(path, what="camera file")
        problems = schema_problems("camera", doc)
        if problems:
            raise FormatError(problems[0].message, path=path, where=problems[0].pointer)
        return CameraModel.from_dict(doc)

    def physics(self) -> dict[str, Any]:
        """The current physics parameters (``physics.json``), schema-checked."""
        rel = self.manifest.get("physics")
        if rel is None:
            raise FormatError(
                "dataset has no physics.json",
                path=self.manifest_path,
                where="physics",
                hint="add physics with DatasetWriter.set_physics",
            )
        path = self.resolve(rel, where="physics")
        doc = read_json(path, what="physics file")
        problems = schema_problems("physics", doc)
        if problems:
            raise FormatError(problems[0].message, path=path, where=problems[0].pointer)
        return doc

    def physics_history(self) -> list[int]:
        """Revision numbers kept under ``physics/history/``."""
        revs = []
        for rel in self.files:
            if rel.startswith("physics/history/rev-") and rel.endswith(".json"):
                revs.append(int(rel[len("physics/history/rev-") : -len(".json")]))
        return sorted(revs)

    @property
    def urdf_path(self) -> Path:
        robot = self.manifest.get("robot")
        if not robot:
            raise FormatError("dataset has no robot", path=self.manifest_path, where="robot")
        return self.resolve(robot["urdf"], where="robot/urdf")

    @property
    def named_frames(self) -> dict[str, Any]:
        """Named frames fixed to robot links (``robot.frames``, spec 1.1.0; empty without):
        name -> :class:`robogs.format.named_frames.NamedFrame`, checked rigid."""
        from .named_frames import read_named_frames

        return read_named_frames(self.manifest, self.manifest_path)

    def urdf(self, *, load_meshes: bool = True) -> yourdfpy.URDF:
        """The robot as a ``yourdfpy.URDF``; mesh URIs resolve inside the dataset."""
        from .urdf import load_urdf

        return load_urdf(self.urdf_path, root=self.root, load_meshes=load_meshes)

    def mdh(self) -> dict[str, Any] | None:
        """The optional modified-DH table (``robot/mdh.json``) as a dict, schema-checked."""
        rel = (self.manifest.get("robot") or {}).get("mdh")
        if rel is None:
            return None
        path = self.resolve(rel, where="robot/mdh")
        doc = read_json(path, what="MDH table")
        problems = schema_problems("mdh", doc)
        if problems:
            raise FormatError(problems[0].message, path=path, where=problems[0].pointer)
        return doc

    @property
    def assets(self) -> dict[str, dict[str, Any]]:
        return dict(self.manifest.get("assets", {}))

    def mesh(self, asset: str) -> trimesh.Trimesh:
        """An asset's mesh (metres, asset frame) via trimesh."""

        entry = self.assets.get(asset)
        if not entry or "mesh" not in entry:
            raise FormatError(
                f"asset {asset!r} has no mesh", path=self.manifest_path, where=f"assets/{asset}"
            )
        from .meshes import load_mesh

        path = self.resolve(entry["mesh"], where=f"assets/{asset}/mesh")
        mesh = load_mesh(path)
        v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
            raise FormatError(
                f"mesh has vertices {v.shape} and faces {f.shape}, expected [N, 3]",
                path=path,
                hint="re-export the mesh with 3D vertices and triangles",
            )
        if not np.all(np.isfinite(v)) or f.min() < 0 or f.max() >= len(v):
            raise FormatError(
                "mesh has non-finite vertices or faces that index no vertex",
                path=path,
                hint="re-export the mesh",
            )
        return mesh

    def splat_entry(self, owner: str) -> dict[str, Any]:
        """The manifest entry of the splats of ``owner`` ('robot' or an asset name)."""
        entry = (
            (self.manifest.get("robot") or {}) if owner == "robot" else self.assets.get(owner, {})
        )
        if "splats" not in entry:
            raise FormatError(f"{owner!r} has no splats", path=self.manifest_path)
        return entry["splats"]

    def splats(self, owner: str) -> SplatSet:
        """Gaussians of ``owner`` ('robot' or an asset name) at their rest state."""
        entry = self.splat_entry(owner)
        return read_splat_ply(self.resolve(entry["path"], where=f"{owner}/splats/path"))
