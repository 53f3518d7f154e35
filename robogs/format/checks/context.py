"""``CheckContext``: a tolerant, caching view of one :class:`~robogs.format.dataset.Dataset`.

The checks read the dataset through the context, and the context reads it through the
``Dataset`` readers (``read_parquet``, ``parquet_metadata``, ``Dataset.camera``,
``Dataset.physics``, ``Dataset.urdf``, ``Dataset.mesh``). What it adds is only:

* **tolerance**: the manifest is read without raising on schema problems (they become
  findings); a path that leaves the root is never opened; a read that fails is cached as a
  failure and raised as :class:`InputReported` (or, for the robot and meshes, as the
  ``RobogsError`` that the check reading it reports), so one broken file is one finding, from
  the check that owns it, and never a crash of the others;
* **caching**: what several checks read (footers, tables, sidecars, the URDF and its chain,
  meshes, label boxes) is read once, by :meth:`CheckContext.cached`.

Layout facts (which fields name files, entity columns) live in :mod:`.layout`, facts derived
from meshes in :mod:`.assets`. Nothing here writes to the dataset.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pyarrow as pa
import pyarrow.parquet as pq

from ..budgets import DEFAULT_BUDGETS
from ..cameras import CameraModel
from ..dataset import MANIFEST_NAME, Dataset, Episode, parquet_metadata, read_parquet
from ..errors import FormatError, PathEscapeError, RobogsError, VersionError
from ..jsonio import read_json
from ..paths import check_relpath, resolve_inside
from ..schemas import schema_problems
from ..spec_version import SPEC_VERSION, parse_version
from ..tables import check_table_schema, null_problems
from .layout import (
    ENTITY_COLUMNS,
    PERIODIC_KINDS,
    STREAM_FILE_FIELDS,
    PathRef,
    path_refs,
    table_kind,
)

if TYPE_CHECKING:
    import trimesh
    import yourdfpy

    from ..kinematics import Chain
    from .label_boxes import LabelBoxes

__all__ = [
    "CheckContext",
    "InputReported",
    "PathRef",
    "STREAM_FILE_FIELDS",
    "table_kind",
    "PERIODIC_KINDS",
    "ENTITY_COLUMNS",
]

#: largest decompressed size (bytes) of a table that a check may read whole into memory; a larger
#: one is reported by I010 and skipped by those checks (the streaming checks still read it)
MAX_TABLE_BYTES = 256 * 1024 * 1024


class InputReported(Exception):
    """Raised by the context when a check's input is unusable and already reported.

    The runner skips the rest of that check quietly: the problem (an unsafe path,
    a missing or unreadable file, an invalid sidecar) has its own finding.
    """


@dataclass(frozen=True)
class _Failed:
    """A cached read failure."""

    error: RobogsError


class CheckContext:
    """Lazy view of one dataset for the checks.

    Args:
        root: dataset folder.
        quick: only the manifest and parquet footers may be read.
        budgets: budget overrides on top of the dataset's (e.g. from ``--budget``).
        label_threads: decoder threads for label images.
        progress: called with a short note when a long step starts.
        options: free-form settings for checks that take them (e.g. the binding
            re-render's ``stride``); unknown keys are ignored.

    Raises:
        FormatError: the folder or its manifest cannot be read at all (the caller
            reports this as unreadable input).
    """

    def __init__(
        self,
        root: str | Path,
        *,
        quick: bool = False,
        budgets: dict[str, float] | None = None,
        label_threads: int = 2,
        progress: Callable[[str], None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> None:
        self.root = Path(root)
        self.options: dict[str, Any] = dict(options or {})
        self.quick = quick
        self.label_threads = label_threads
        self.progress = progress or (lambda _msg: None)
        self.version_error: VersionError | None = None
        self.dataset = self._open()
        # a sharded dataset's chunk indexes merged in; their problems are reported by I011
        self.manifest: dict[str, Any] = self.dataset.full_manifest(lenient=True)
        self.manifest_problems = schema_problems("manifest", self.manifest)
        self.budget_problems: list[str] = []
        self.budgets = self._budgets(budgets or {})
        self._cache: dict[Any, Any] = {}
        self._unsafe: dict[str, PathEscapeError] | None = None

    # -- opening ----------------------------------------------------------------
    def _open(self) -> Dataset:
        try:
            return Dataset.open(self.root, check_schema=False)
        except VersionError as exc:
            # newer major (or unparseable) version: keep the raw manifest, report it as a finding
            self.version_error = exc
            raw = read_json(self.root / MANIFEST_NAME, what="manifest", root=self.root)
            return Dataset(self.root, raw)

    def _budgets(self, overrides: dict[str, float]) -> dict[str, float]:
        values = {name: b.value for name, b in DEFAULT_BUDGETS.items()}
        declared = self.manifest.get("budgets")
        if isinstance(declared, dict):
            for name, value in declared.items():
                if name not in values:
                    self.budget_problems.append(f"unknown budget {name!r}")
                elif (
                    isinstance(value, int | float)
                    and not isinstance(value, bool)
                    and math.isfinite(value)
                    and value >= 0
                ):
                    values[name] = float(value)
                else:
                    self.budget_problems.append(
                        f"budget {name!r} must be a non-negative number, got {value!r}"
                    )
        for name, value in overrides.items():
            if name not in values:
                raise FormatError(
                    f"unknown budget {name!r}",
                    where="--budget",
                    hint=f"known budgets: {', '.join(sorted(values))}",
                )
            values[name] = float(value)
        return values

    # -- manifest facts ---------------------------------------------------------------
    @property
    def manifest_valid(self) -> bool:
        """True when the manifest follows its JSON Schema (and its version is readable).

        Fields unknown to this reader do not count when the dataset declares a newer
        minor spec version (they are reported as warnings and ignored).
        """
        if self.version_error is not None:
            return False
        problems = self.manifest_problems
        if self.newer_minor:
            problems = [p for p in problems if not p.message.startswith("Additional properties")]
        return not problems

    @property
    def newer_minor(self) -> bool:
        """True when the manifest's spec version is a newer minor of this reader's major."""
        try:
            theirs = parse_version(str(self.manifest.get("spec_version", "")))
        except VersionError:
            return False
        ours = parse_version(SPEC_VERSION)
        return theirs[0] == ours[0] and theirs[1] > ours[1]

    @property
    def files(self) -> dict[str, dict[str, Any]]:
        """The manifest's ``files`` section (empty when malformed)."""
        files = self.manifest.get("files")
        return files if isinstance(files, dict) else {}

    @property
    def episodes(self) -> list[Episode]:
        """Episodes of the manifest (only well-formed entries)."""
        out = []
        for e in (
            self.manifest.get("episodes", [])
            if isinstance(self.manifest.get("episodes"), list)
            else []
        ):
            if isinstance(e, dict) and {"id", "start_ns", "end_ns", "streams"} <= set(e):
                out.append(Episode(self.dataset, e))
        return out

    def streams(
        self, kinds: tuple[str, ...] | None = None
    ) -> Iterator[tuple[Episode, str, dict[str, Any]]]:
        """``(episode, stream name, stream entry)`` for every stream (of the given kinds)."""
        for ep in self.episodes:
            for name, st in ep.streams.items():
                if isinstance(st, dict) and (kinds is None or st.get("kind") in kinds):
                    yield ep, name, st

    def budget(self, name: str) -> float:
        """A resolved budget value (defaults, then dataset, then caller overrides)."""
        return self.budgets[name]

    def rel(self, path: str | Path | None) -> str | None:
        """Dataset-relative spelling of a path when it lies inside the root."""
        if path is None:
            return None
        p = Path(path)
        try:
            return p.resolve().relative_to(self.root.resolve()).as_posix()
        except (ValueError, OSError):
            return str(path)

    # -- paths --------------------------------------------------------------------------
    def path_refs(self) -> list[PathRef]:
        """Every path the manifest names (:func:`.layout.path_refs`)."""
        return path_refs(self.manifest)

    @property
    def unsafe_paths(self) -> dict[str, PathEscapeError]:
        """Manifest paths that leave the root (``..``, absolute, URI, symlink), keyed by spelling."""
        if self._unsafe is None:
            self._unsafe = {}
            for ref in self.path_refs():
                if ref.rel in self._unsafe:
                    continue
                try:
                    self._cache[("path", ref.rel)] = self._resolve(ref.rel, ref.where)
                except PathEscapeError as exc:
                    self._unsafe[ref.rel] = exc
        return self._unsafe

    def path(self, rel: str, *, where: str | None = None) -> Path:
        """Absolute path of a manifest path (resolved once); unsafe ones raise
        :class:`InputReported`."""
        if not isinstance(rel, str) or rel in self.unsafe_paths:
            raise InputReported(rel)
        full = self._cache.get(("path", rel))
        if full is None:
            try:
                full = self._resolve(rel, where)
            except PathEscapeError:
                raise InputReported(rel) from None
            self._cache[("path", rel)] = full
        return full

    def _resolve(self, rel: str, where: str | None) -> Path:
        """:func:`resolve_inside` with each folder looked at once: a path none of whose parts
        is a symlink resolves to the resolved root joined with it (what ``realpath`` gives);
        one through a symlink is resolved in full."""
        clean = check_relpath(rel, source=MANIFEST_NAME, where=where)
        root = self._cache.get(("dir", ""))
        if root is None:
            root = self._cache[("dir", "")] = self.root.resolve()
        prefix = ""
        for part in clean.split("/"):
            prefix = f"{prefix}/{part}" if prefix else part
            linked = self._cache.get(("link", prefix))
            if linked is None:
                linked = self._cache[("link", prefix)] = os.path.islink(os.path.join(root, prefix))
            if linked:
                return resolve_inside(self.root, rel, source=MANIFEST_NAME, where=where)
        return root / clean

    def existing(self, rel: str, *, where: str | None = None) -> Path:
        """Like :meth:`path`, and the file must exist (a missing one is reported elsewhere)."""
        p = self.path(rel, where=where)
        if not p.is_file():
            raise InputReported(rel)
        return p

    # -- the one tolerant read -------------------------------------------------------------
    def cached(self, key: Any, build: Callable[[], Any], *, reported: bool = True) -> Any:
        """``build()`` once per ``key``; its failure (a ``RobogsError``) is cached as well.

        Args:
            key: cache key (a tuple naming what is read).
            build: the read, through a ``Dataset`` reader.
            reported: the failure is reported by an integrity or schema check, so it is raised
                as :class:`InputReported` (the caller skips quietly); False re-raises the
                ``RobogsError`` for the calling check to report (URDF, meshes).
        """
        if key not in self._cache:
            try:
                self._cache[key] = build()
            except RobogsError as exc:
                self._cache[key] = _Failed(exc)
        value = self._cache[key]
        if isinstance(value, _Failed):
            if reported:
                raise InputReported(str(key[-1])) from value.error
            raise value.error
        return value

    # -- tables ----------------------------------------------------------------------------
    def footer(self, rel: str) -> pq.FileMetaData:
        """Parquet footer of a manifest path (cached); broken files raise :class:`InputReported`."""
        path = self.existing(rel)
        return self.cached(("footer", rel), lambda: parquet_metadata(path))

    def table_kinds(self) -> dict[str, str]:
        """Table kind of every table a stream names, keyed by relative path."""
        key = ("table-kinds",)
        if key not in self._cache:
            kinds: dict[str, str] = {}
            for _ep, _name, st in self.streams():
                for fld in STREAM_FILE_FIELDS:
                    kind = table_kind(st, fld)
                    if kind and isinstance(st.get(fld), str):
                        kinds.setdefault(st[fld], kind)
            self._cache[key] = kinds
        return self._cache[key]

    def table(self, rel: str, *, columns: tuple[str, ...] | None = None) -> pa.Table:
        """A whole parquet table (or some of its columns), cached per file and column set.

        Tables that are unreadable or do not match their kind's columns and types raise
        :class:`InputReported` (the integrity and schema checks report them).
        """
        if self.quick:
            raise RuntimeError("a quick check tried to read a table body")
        kind = self._require_schema(rel)
        if self.table_bytes(rel) > MAX_TABLE_BYTES:
            raise InputReported(rel)  # I010 reports it
        key = ("table", rel, columns)
        full = self._cache.get(("table", rel, None))
        if key not in self._cache and columns is not None and isinstance(full, pa.Table):
            self._cache[key] = full.select(list(columns))
        path = self.existing(rel)
        cols = list(columns) if columns else None
        tab = self.cached(key, lambda: read_parquet(path, columns=cols))  # I006 reports failures
        if kind is not None and null_problems(kind, tab):
            self._cache[("table-ok", rel)] = False
            raise InputReported(rel)  # S003 reports the nulls
        return tab

    def table_bytes(self, rel: str) -> int:
        """Size of a parquet table once read into memory, bytes, from its footer alone.

        The larger of the encoded row-group totals and rows x the widths of its fixed-width
        columns (dictionary and run-length encoding make the first far smaller than the arrays).
        """
        md = self.footer(rel)
        encoded = sum(md.row_group(i).total_byte_size for i in range(md.num_row_groups))
        width = 0
        for field in md.schema.to_arrow_schema():
            try:
                width += max(field.type.bit_width // 8, 0)
            except ValueError:  # variable width: counted by the encoded total
                pass
        return int(max(encoded, md.num_rows * width))

    def _require_schema(self, rel: str) -> str | None:
        """The table kind of ``rel``; :class:`InputReported` when its footer is unreadable or off
        the kind's columns and types (the integrity and schema checks report those)."""
        md = self.footer(rel)
        kind = self.table_kinds().get(rel)
        if kind is not None:
            ok_key = ("table-ok", rel)
            if ok_key not in self._cache:
                self._cache[ok_key] = not check_table_schema(kind, md.schema.to_arrow_schema())
            if not self._cache[ok_key]:
                raise InputReported(rel)
        return kind

    def stream_table(
        self,
        ep: Episode,
        stream: str,
        *,
        field: str = "path",
        columns: tuple[str, ...] | None = None,
    ) -> pa.Table:
        """The table a stream names in ``field`` (``path``, ``frames``, ``labels``...)."""
        st = ep.streams.get(stream, {})
        rel = st.get(field)
        if not isinstance(rel, str):
            raise InputReported(f"{stream}/{field}")
        return self.table(rel, columns=columns)

    def find_stream(self, ep: Episode, kind: str) -> str | None:
        """Name of the first stream of ``kind`` in an episode that names a table."""
        for name, st in ep.streams.items():
            if isinstance(st, dict) and st.get("kind") == kind and isinstance(st.get("path"), str):
                return name
        return None

    # -- sidecars -------------------------------------------------------------------------
    def physics(self) -> dict[str, Any]:
        """``physics.json`` through :meth:`Dataset.physics` (schema-valid), or
        :class:`InputReported` (S00x reports an invalid one)."""
        rel = self.manifest.get("physics")
        if not isinstance(rel, str):
            raise InputReported("physics")
        self.existing(rel)
        return self.cached(("sidecar", "physics"), self.dataset.physics)

    def camera(self, name: str) -> CameraModel:
        """A camera model through :meth:`Dataset.camera` (schema-valid), or
        :class:`InputReported`."""
        cams = self.manifest.get("cameras")
        rel = cams.get(name) if isinstance(cams, dict) else None
        if not isinstance(rel, str):
            raise InputReported(f"cameras/{name}")
        self.existing(rel)
        return self.cached(("sidecar", "camera", name), lambda: self.dataset.camera(name))

    # -- robot and meshes ----------------------------------------------------------------

    def urdf(self) -> yourdfpy.URDF:
        """The robot URDF, kinematics only (cached); errors are raised as ``RobogsError``.

        Link meshes are loaded by the geometry checks themselves (faster than building
        yourdfpy's scene graph).
        """
        robot = self.manifest.get("robot") or {}
        rel = robot.get("urdf") if isinstance(robot, dict) else None
        if not isinstance(rel, str):
            raise InputReported("robot/urdf")
        path = self.existing(rel)
        return self.cached(("urdf",), lambda: self._load_urdf(path), reported=False)

    def _load_urdf(self, path: Path) -> yourdfpy.URDF:
        """:meth:`Dataset.urdf` without meshes, plus ``robogs_mesh_refs`` (resolved mesh paths)."""
        from ..urdf import MeshRef, mesh_refs, resolve_mesh_uri

        urdf = self.dataset.urdf(load_meshes=False)
        refs: list[MeshRef] = []
        cache: dict[str, Path] = {}
        for ref in mesh_refs(urdf):
            try:
                resolved = resolve_mesh_uri(ref.uri, path, self.root, _cache=cache)
            except RobogsError:
                continue  # reported by I007 (escapes) or G001 (unresolvable)
            if resolved.is_file():
                refs.append(MeshRef(ref.link, ref.kind, ref.uri, resolved))
        urdf.robogs_mesh_refs = refs
        return urdf

    def urdf_path(self) -> Path:
        """Absolute path of the robot URDF (unsafe or missing: :class:`InputReported`)."""
        robot = self.manifest.get("robot") or {}
        rel = robot.get("urdf") if isinstance(robot, dict) else None
        if not isinstance(rel, str):
            raise InputReported("robot/urdf")
        return self.existing(rel)

    def chain(self) -> Chain:
        """Forward kinematics of the robot (cached)."""
        from ..kinematics import Chain

        return self.cached(
            ("chain",),
            lambda: Chain.from_urdf(self.urdf(), floating_as_fixed=True),
            reported=False,
        )

    def fitted_chain(self) -> tuple[Chain, str]:
        """The robot chain with the joint offsets of the current physics revision, and a note
        on what was applied (:func:`robogs.format.kinematics.fitted_chain`); the nominal chain
        when there is no (valid) ``physics.json``."""
        from ..kinematics import fitted_chain

        def build() -> tuple[Chain, str]:
            chain = self.chain()
            try:
                physics = self.physics()
            except InputReported:
                return chain, ""  # no physics.json, or reported by S00x
            return fitted_chain(chain, physics, path=self.manifest.get("physics"))

        return self.cached(("fitted_chain",), build, reported=False)

    def has_robot(self) -> bool:
        robot = self.manifest.get("robot")
        return isinstance(robot, dict) and isinstance(robot.get("urdf"), str)

    def asset_names(self, kinds: tuple[str, ...] = ("object", "table", "background")) -> list[str]:
        assets = self.manifest.get("assets")
        if not isinstance(assets, dict):
            return []
        return sorted(
            n for n, a in assets.items() if isinstance(a, dict) and a.get("kind") in kinds
        )

    def asset_kind(self, name: str) -> str | None:
        a = (self.manifest.get("assets") or {}).get(name)
        return a.get("kind") if isinstance(a, dict) else None

    def asset_mesh(self, name: str) -> trimesh.Trimesh:
        """An asset's mesh (metres, asset frame; cached); no mesh: :class:`InputReported`."""
        a = (self.manifest.get("assets") or {}).get(name)
        rel = a.get("mesh") if isinstance(a, dict) else None
        if not isinstance(rel, str):
            raise InputReported(f"assets/{name}/mesh")
        self.existing(rel)
        return self.cached(("mesh", name), lambda: self.dataset.mesh(name), reported=False)

    # -- label images -------------------------------------------------------------------
    def label_boxes(self, ep: Episode, stream: str) -> LabelBoxes:
        """Per-frame, per-label boxes of a camera stream's label table (one pass, cached)."""
        from .label_boxes import scan_label_boxes

        rel = ep.streams.get(stream, {}).get("labels")
        if not isinstance(rel, str):
            raise InputReported(f"{stream}/labels")
        path = self.existing(rel)
        self._require_schema(rel)
        self.progress(f"label boxes {ep.id}/{stream}")
        return self.cached(
            ("labels", rel),
            lambda: scan_label_boxes(path, threads=self.label_threads),
            reported=False,
        )
