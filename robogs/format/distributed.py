"""Validate one dataset across workers (a local process, or Ray tasks) with the findings of one run.

The checks are split by what their findings depend on (:data:`EPISODE_SCOPED`,
:data:`FILE_SCOPED`; a check module may also declare ``check_scope(code) -> str``):

* **episode** checks yield, for the whole dataset, the concatenation of what they yield for
  each episode alone, in manifest order (timing, sync, stale values, finite samples, table
  schemas, names, forward kinematics, boxes, penetration);
* **file** checks yield the concatenation over contiguous slices of the sorted ``files``
  section (existence, size, sha256, rows, readable and in-budget tables);
* every other check (manifest schema, unlisted files, escaping paths, the URDF and assets, the
  binding re-render with its dataset-wide time budget, plug-ins) runs on the driver.

A worker runs its unit one *view* at a time: the manifest with ``episodes`` cut to one
episode (``files`` empty), or ``files`` cut to a slice (no episodes). Only the URDF, chain,
meshes and sidecars are kept from one view to the next, so a task holds at most one episode's
tables (each at most ``MAX_TABLE_BYTES``) besides the imported modules. For each check the
worker returns its findings (at most ``max_per_code`` per code; the rest counted, with the
files they name), and how the check ended: normally, or by an input already reported, an
unreadable input, or a crash. The driver replays these in check order through the ordinary
runner, stopping a check where it stopped in the first view that ended it, so the caps per
code, the ``X002`` de-duplication and the final sort are exactly those of
:func:`robogs.format.validate.validate` in one process.

In the sharded layout (:mod:`robogs.format.shards`) a unit names its chunk index and a range
of it instead of carrying the rows: the worker reads that one ``index.json`` (kept for the next
unit of the same chunk) and takes ``episodes[lo:hi]``, or ``sorted(files)[lo:hi]``. A task
then holds one chunk index (at most ``chunk_size`` episodes, ~1 MB on disk for 1000 episodes)
and one episode's tables. Tasks never span two chunks; the manifest's own episodes and files
(the URDF, the chunk indexes themselves) travel as rows. Chunk units are used only when every
index merged cleanly (no ``I011`` problem), so their rows are exactly the driver's merged view.

Splitting needs a schema-valid manifest in which no table is named by two episodes; otherwise
everything runs on the driver (one process), and :attr:`Plan.reason` says why.

Ray is imported only by :class:`RayExecutor`.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from .checks.context import STREAM_FILE_FIELDS, CheckContext, InputReported
from .checks.registry import Check, available_checks
from .dataset import Dataset
from .errors import RobogsError
from .findings import Finding, severity_rank
from .validate import CheckRun, Report, _Runner, select_checks, validate

__all__ = [
    "EPISODE_SCOPED",
    "FILE_SCOPED",
    "Plan",
    "Unit",
    "UnitResult",
    "Executor",
    "LocalExecutor",
    "RayExecutor",
    "check_scope",
    "plan_units",
    "run_unit",
    "ray_unit",
    "validate_distributed",
    "DEFAULT_EPISODES_PER_TASK",
    "DEFAULT_FILES_PER_TASK",
]

#: checks whose findings concatenate over single-episode views, in episode order
EPISODE_SCOPED: frozenset[str] = frozenset(
    {"S003", "S007", "I009", *(f"T{i:03d}" for i in range(1, 15)), "G007", "G008", "G009"}
    | {"G010", "G011"}
)
#: checks whose findings concatenate over contiguous slices of the sorted ``files`` section
FILE_SCOPED: frozenset[str] = frozenset({"I001", "I003", "I004", "I005", "I006", "I010"})
#: of those, the ones that also read tables named only by streams (need every stream table listed)
_STREAM_FILES = frozenset({"I006", "I010"})

#: cache entries of a view that hold dataset-wide facts, kept from one view to the next
_SHARED_CACHE = frozenset(
    {"urdf", "chain", "fitted_chain", "sidecar", "mesh", "hull", "mm", "mesh-file"}
    | {"link-geometry"}
)

DEFAULT_EPISODES_PER_TASK = 25
DEFAULT_FILES_PER_TASK = 200


def check_scope(chk: Check) -> str:
    """``episode``, ``file`` or ``dataset`` (runs on the driver) for a check.

    A check module may declare the scope of its own checks with a module-level
    ``check_scope(code) -> str``; unknown plug-ins run on the driver.
    """
    hook = getattr(sys.modules.get(getattr(chk.fn, "__module__", "") or ""), "check_scope", None)
    if callable(hook) and hook is not check_scope:
        try:
            scope = hook(chk.code)
        except Exception:  # a wrong hint must never change findings: run it on the driver
            scope = None
        if scope in ("episode", "file", "dataset"):
            return str(scope)
    if chk.code in EPISODE_SCOPED:
        return "episode"
    if chk.code in FILE_SCOPED:
        return "file"
    return "dataset"


@dataclass(frozen=True)
class Unit:
    """One task: some episodes (manifest entries) or a slice of the ``files`` section.

    With ``chunk`` (a chunk index path) the rows are not carried: the worker reads
    ``episodes[lo:hi]`` or ``sorted(files.items())[lo:hi]`` of that index itself.
    """

    index: int
    kind: str  # "episodes" or "files"
    episodes: tuple[dict[str, Any], ...] = ()
    files: tuple[tuple[str, Any], ...] = ()
    codes: tuple[str, ...] = ()
    chunk: str | None = None
    lo: int = 0
    hi: int = 0

    def size(self) -> int:
        """Episodes or files of the unit."""
        if self.chunk is not None:
            return self.hi - self.lo
        return len(self.episodes) if self.kind == "episodes" else len(self.files)


@dataclass
class _Outcome:
    """What one check yielded on a unit, and how it ended there."""

    findings: list[Finding] = field(default_factory=list)
    over: Counter = field(default_factory=Counter)  # per code, findings past the cap
    over_files: set[str] = field(default_factory=set)  # files of those (error/warning)
    end: str = "done"  # done | reported | error | crashed
    error: dict[str, Any] | None = None  # the RobogsError that ended it (path, where, ...)
    seconds: float = 0.0


@dataclass
class UnitResult:
    """A unit's outcomes per check code, and the worker's peak resident memory (bytes)."""

    index: int
    outcomes: dict[str, _Outcome]
    peak_rss: int
    seconds: float
    pid: int
    cpu_seconds: float = 0.0  # CPU time of the task's process (user + system), load-independent


@dataclass
class Plan:
    """How a validation is split: the units, the scope of each selected check, and
    why nothing was split (``reason``; None when split)."""

    units: list[Unit]
    scopes: dict[str, str]
    reason: str | None = None


def _view_manifest(
    base: dict[str, Any],
    kind: str,
    episodes: Sequence[dict[str, Any]],
    files: Sequence[tuple[str, Any]],
    k: int,
) -> dict[str, Any]:
    view = dict(base)
    if kind == "episodes":
        view["episodes"] = [episodes[k]]
        view["files"] = {}
    else:
        view["episodes"] = []
        view["files"] = dict(files)
    return view


#: chunk indexes this worker process read: (root, index) -> (stat key, episodes, sorted files)
_INDEX_CACHE: dict[tuple[str, str], tuple[tuple[int, int], list[Any], list[tuple[str, Any]]]] = {}
_INDEX_CACHE_MAX = 2  # a task reads one chunk; the next task is most often of the same chunk


def _chunk_rows(root: str, rel: str) -> tuple[list[Any], list[tuple[str, Any]]]:
    """A chunk index's episodes and its sorted files, read once per process while unchanged.

    Raises:
        FormatError: the index is unreadable or not a chunk index.
    """
    from .shards import read_chunk

    path = Path(root) / rel
    try:
        st = path.stat()
        stamp = (st.st_mtime_ns, st.st_size)
    except OSError:
        stamp = (-1, -1)
    hit = _INDEX_CACHE.get((root, rel))
    if hit is not None and hit[0] == stamp:
        return hit[1], hit[2]
    doc = read_chunk(Path(root), {"index": rel}, manifest_path=Path(root) / "manifest.json")
    rows = (stamp, list(doc["episodes"]), sorted(doc["files"].items()))
    while len(_INDEX_CACHE) >= _INDEX_CACHE_MAX:
        _INDEX_CACHE.pop(next(iter(_INDEX_CACHE)))
    _INDEX_CACHE[(root, rel)] = rows
    return rows[1], rows[2]


def _unit_rows(root: str, unit: Unit) -> tuple[Sequence[dict[str, Any]], Sequence[tuple[str, Any]]]:
    """The episodes and files a unit covers (read from its chunk index when it names one)."""
    if unit.chunk is None:
        return unit.episodes, unit.files
    episodes, files = _chunk_rows(root, unit.chunk)
    if unit.kind == "episodes":
        return episodes[unit.lo : unit.hi], ()
    return (), files[unit.lo : unit.hi]


class _ViewContext(CheckContext):
    """A :class:`CheckContext` on a part of the manifest (validated as a whole by the driver)."""

    def __init__(self, root: Path, view: dict[str, Any], shared: dict[Any, Any], **kw: Any):
        self._view = view
        super().__init__(root, **kw)
        self.manifest_problems = []  # the driver checked the whole manifest
        self._cache.update(shared)

    def _open(self) -> Dataset:
        return Dataset(self.root, self._view)


class _Recorder(_Runner):
    """Records what the checks yield on one view instead of keeping a report."""

    def __init__(self, ctx: CheckContext, max_per_code: int) -> None:
        super().__init__(ctx, max_per_code)
        self.out = _Outcome()
        self.kept: Counter = Counter()

    def add(self, f: Finding) -> None:
        if self.kept[f.code] >= self.max_per_code:
            self.out.over[f.code] += 1
            if f.location.file and severity_rank(f.severity) <= 1:
                self.out.over_files.add(f.location.file)
            return
        self.kept[f.code] += 1
        self.out.findings.append(f)

    def _input_finding(self, chk: Check, exc: RobogsError) -> Finding | None:
        self.out.end = "error"
        self.out.error = {
            "path": None if exc.path is None else str(exc.path),
            "where": exc.where,
            "message": exc.message,
            "hint": exc.hint,
        }
        return None


def _watched(chk: Check, out: list[_Outcome]) -> Check:
    """The check, noting in ``out[0]`` when it stops on an input reported elsewhere."""
    fn = chk.fn

    def watched(c: Check, ctx: CheckContext) -> Iterator[Finding]:
        try:
            yield from fn(c, ctx)
        except InputReported:
            out[0].end = "reported"
            raise

    return dataclasses.replace(chk, fn=watched)


def _peak_rss() -> int:
    try:
        import resource

        return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024  # Linux: KiB
    except (ImportError, OSError):
        return 0


def run_unit(
    root: str,
    base: dict[str, Any],
    unit: Unit,
    settings: dict[str, Any],
) -> UnitResult:
    """Run ``unit.codes`` on each view of a unit (the body of one task).

    Args:
        root: dataset folder (the same path on every node).
        base: the manifest without its ``episodes`` and ``files``.
        unit: what to check.
        settings: ``quick``, ``budgets``, ``options``, ``max_per_code``, ``label_threads``.
    """
    t0, c0 = time.perf_counter(), time.process_time()
    checks = [c for code, c in available_checks().items() if code in set(unit.codes)]
    missing = sorted(set(unit.codes) - {c.code for c in checks})
    if missing:
        raise RobogsError(
            f"checks {', '.join(missing)} are not registered in worker process {os.getpid()}",
            where="robogs.format.distributed",
            hint="install check plug-ins on every node (entry point robogs.checks), or run "
            "them on the driver with check_scope(code) -> 'dataset'",
        )
    checks.sort(key=lambda c: unit.codes.index(c.code))
    max_per_code = int(settings.get("max_per_code", 50))
    total: dict[str, _Outcome] = {c.code: _Outcome() for c in checks}
    kept: dict[str, Counter] = {c.code: Counter() for c in checks}
    shared: dict[Any, Any] = {}
    episodes, files = _unit_rows(root, unit)
    n_views = len(episodes) if unit.kind == "episodes" else 1
    for k in range(n_views):
        todo = [c for c in checks if total[c.code].end == "done"]
        if not todo:
            break
        ctx = _ViewContext(
            Path(root),
            _view_manifest(base, unit.kind, episodes, files, k),
            shared,
            quick=bool(settings.get("quick", False)),
            budgets=settings.get("budgets"),
            label_threads=int(settings.get("label_threads", 1)),
            options=settings.get("options"),
        )
        rec = _Recorder(ctx, max_per_code)
        for chk in todo:
            rec.out, rec.kept = _Outcome(), kept[chk.code]
            box = [rec.out]
            t = time.perf_counter()
            rec.run(_watched(chk, box))
            if rec.runs[-1].status == "crashed":
                rec.out.end = "crashed"
            _merge(total[chk.code], rec.out, time.perf_counter() - t)
        shared.update({key: v for key, v in ctx._cache.items() if key[0] in _SHARED_CACHE})
        del ctx, rec
    cpu = time.process_time() - c0
    return UnitResult(unit.index, total, _peak_rss(), time.perf_counter() - t0, os.getpid(), cpu)


def _merge(into: _Outcome, part: _Outcome, seconds: float) -> None:
    into.findings += part.findings
    into.over.update(part.over)
    into.over_files |= part.over_files
    into.end, into.error = part.end, part.error
    into.seconds += seconds


def plan_units(
    ctx: CheckContext,
    checks: Sequence[Check],
    *,
    episodes_per_task: int = DEFAULT_EPISODES_PER_TASK,
    files_per_task: int = DEFAULT_FILES_PER_TASK,
) -> Plan:
    """Split the selected checks of a dataset into units (see the module docstring)."""
    scopes = {c.code: check_scope(c) for c in checks}
    if ctx.version_error is not None or not ctx.manifest_valid:
        return Plan([], dict.fromkeys(scopes, "dataset"), "the manifest does not follow its schema")
    raw = ctx.manifest.get("episodes")
    entries = [
        e
        for e in (raw if isinstance(raw, list) else [])
        if isinstance(e, dict) and {"id", "start_ns", "end_ns", "streams"} <= set(e)
    ]
    owner: dict[str, int] = {}
    for i, e in enumerate(entries):
        streams = e.get("streams")
        for st in streams.values() if isinstance(streams, dict) else []:
            if not isinstance(st, dict):
                continue
            for fld in STREAM_FILE_FIELDS:
                rel = st.get(fld)
                if isinstance(rel, str) and owner.setdefault(rel, i) != i:
                    reason = f"{rel!r} is named by two episodes"
                    return Plan([], dict.fromkeys(scopes, "dataset"), reason)
    if any(s == "file" for s in scopes.values()) and not set(owner) <= set(ctx.files):
        for code in _STREAM_FILES & set(scopes):
            scopes[code] = "dataset"  # they would also read tables that are not listed
    ep_codes = tuple(c.code for c in checks if scopes[c.code] == "episode")
    file_codes = tuple(c.code for c in checks if scopes[c.code] == "file")
    ept, fpt = max(1, episodes_per_task), max(1, files_per_task)
    files = sorted(ctx.files.items())
    layout = _chunk_layout(ctx, entries, files)
    units: list[Unit] = []

    def add(kind: str, codes: tuple[str, ...], src: str | None, rows: list[Any], lo: int) -> None:
        """Units of at most ``ept`` / ``fpt`` rows for a run of rows (from chunk ``src``)."""
        step = ept if kind == "episodes" else fpt
        for a in range(0, len(rows), step):
            part, n = rows[a : a + step], len(rows[a : a + step])
            if src is not None:
                units.append(
                    Unit(len(units), kind, codes=codes, chunk=src, lo=lo + a, hi=lo + a + n)
                )
            elif kind == "episodes":
                units.append(Unit(len(units), kind, episodes=tuple(part), codes=codes))
            else:
                units.append(Unit(len(units), kind, files=tuple(part), codes=codes))

    if ep_codes:
        for src, rows, lo in layout[0] if layout else [(None, entries, 0)]:
            add("episodes", ep_codes, src, rows, lo)
    if file_codes:
        for src, rows, lo in layout[1] if layout else [(None, files, 0)]:
            add("files", file_codes, src, rows, lo)
    return Plan(units, scopes)


_Runs = list[tuple[str | None, list[Any], int]]


def _chunk_layout(
    ctx: CheckContext, entries: list[dict[str, Any]], files: list[tuple[str, Any]]
) -> tuple[_Runs, _Runs] | None:
    """The merged episodes and sorted files cut into runs ``(chunk index or None, rows, lo)``:
    a run from a chunk index holds its rows ``lo .. lo + len(rows)`` (the worker re-reads them);
    a run with None travels as rows. None when the dataset is not sharded or its merged view is
    not exactly the manifest's rows followed by each index's (then every unit carries rows)."""
    from .shards import chunk_dir, chunk_of, is_sharded

    ds = ctx.dataset
    small = ds.manifest
    if not is_sharded(small) or ds.shard_problems:
        return None
    raw = ctx.manifest.get("episodes")
    top_eps, top_files = small.get("episodes", []), small.get("files", {})
    chunks = small.get("shards", {}).get("chunks")
    if not (
        isinstance(raw, list)
        and len(raw) == len(entries)
        and isinstance(top_eps, list)
        and isinstance(top_files, dict)
        and isinstance(chunks, list)
    ):
        return None
    counts: list[tuple[str, int]] = []
    folder: dict[str, str] = {}
    for c in chunks:
        rel, n = (c.get("index"), c.get("episodes")) if isinstance(c, dict) else (None, None)
        if not isinstance(rel, str) or not isinstance(n, int) or "/" not in rel:
            return None
        counts.append((rel, n))
        if folder.setdefault(rel.rsplit("/", 1)[0] + "/", rel) != rel:
            return None  # two indexes in one folder
    if len(top_eps) + sum(n for _, n in counts) != len(entries):
        return None
    ep_runs: _Runs = [(None, entries[: len(top_eps)], 0)] if top_eps else []
    at = len(top_eps)
    for rel, n in counts:
        if n:
            ep_runs.append((rel, entries[at : at + n], 0))
        at += n
    file_runs: _Runs = []
    pos: dict[str, int] = {}
    for rel, entry in files:
        k = chunk_of(rel)
        src = None if rel in top_files else folder.get(f"{chunk_dir(k)}/" if k is not None else "")
        if src is None and rel not in top_files:
            return None  # a file from an index outside its folder
        if file_runs and file_runs[-1][0] == src:
            file_runs[-1][1].append((rel, entry))
        else:
            file_runs.append((src, [(rel, entry)], pos.get(src, 0) if src else 0))
        if src is not None:
            pos[src] = pos.get(src, 0) + 1
    return ep_runs, file_runs


class Executor(Protocol):
    """Runs units somewhere and yields their results as they finish (any order)."""

    def run(self, root: str, base: dict[str, Any], units: Sequence[Unit], settings: dict[str, Any]) -> Iterator[UnitResult]: ...  # fmt: skip


class LocalExecutor:
    """Runs the units one after another in this process (tests, and no cluster at hand)."""

    workers = 1

    def run(
        self, root: str, base: dict[str, Any], units: Sequence[Unit], settings: dict[str, Any]
    ) -> Iterator[UnitResult]:
        for u in units:
            yield run_unit(root, base, u, settings)


class RayExecutor:
    """Runs each unit as a Ray task (``ray.init(address)`` unless Ray is already up).

    A task whose worker dies is retried (``max_retries``); a task asks Ray for
    ``memory_bytes`` of memory, so the scheduler never packs more tasks on a node than fit.

    Args:
        address: a Ray cluster address, ``auto`` for the running one, or None to start a
            local cluster with ``num_cpus`` CPUs.
        num_cpus: CPUs of a local cluster (None: all).
        max_retries: retries of a task whose worker process died.
        memory_bytes: memory reserved per task (a scheduling resource).
        init_kwargs: more ``ray.init`` arguments (e.g. ``object_store_memory``).
        body: the task body (default :func:`run_unit` with one numerics thread); a wrapper
            must call it through and return its :class:`UnitResult`.
    """

    def __init__(
        self,
        address: str | None = None,
        *,
        num_cpus: int | None = None,
        max_retries: int = 3,
        memory_bytes: int | None = None,
        init_kwargs: dict[str, Any] | None = None,
        body: Callable[..., UnitResult] | None = None,
    ) -> None:
        self.address = address
        self.body = body or ray_unit
        self.num_cpus = num_cpus
        self.max_retries = max_retries
        self.memory_bytes = memory_bytes
        self.init_kwargs = dict(init_kwargs or {})
        self.started = False
        self.workers = num_cpus or 0
        #: seconds spent starting or joining the cluster (inside the first ``run``)
        self.init_seconds = 0.0

    def connect(self) -> Any:
        """Start or join the cluster (once); the ``ray`` module."""
        os.environ.setdefault("RAY_DISABLE_IMPORT_WARNING", "1")
        try:
            import ray
        except ImportError:
            raise RobogsError(
                "--ray needs the ray package",
                where="--ray",
                hint="pip install 'robogs[scale]'",
            ) from None
        if not ray.is_initialized():
            t0 = time.perf_counter()
            kw: dict[str, Any] = {
                "include_dashboard": False,
                "log_to_driver": False,
                "logging_level": "ERROR",
            }
            kw.update(self.init_kwargs)
            try:
                if self.address:
                    ray.init(address=self.address, **kw)
                else:
                    ray.init(num_cpus=self.num_cpus, **kw)
            except Exception as exc:
                raise RobogsError(
                    f"cannot start or join a Ray cluster: {str(exc).strip()[:300]}",
                    where=f"--ray {self.address or ''}".strip(),
                    hint="start one with 'ray start --head', or give --ray without ADDRESS "
                    "for a local cluster",
                ) from None
            self.started = True
            self.init_seconds = time.perf_counter() - t0
        self.workers = int(ray.cluster_resources().get("CPU", 1))
        return ray

    def run(
        self, root: str, base: dict[str, Any], units: Sequence[Unit], settings: dict[str, Any]
    ) -> Iterator[UnitResult]:
        ray = self.connect()
        opts: dict[str, Any] = {"max_retries": self.max_retries, "num_cpus": 1}
        if self.memory_bytes:
            opts["memory"] = int(self.memory_bytes)
        task = ray.remote(self.body).options(**opts)
        base_ref = ray.put(base)
        pending = [task.remote(root, base_ref, u, settings) for u in units]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            try:
                result = ray.get(done[0])
            except Exception as exc:  # a task that failed all its tries
                for ref in pending:
                    ray.cancel(ref)
                first = (str(exc).strip().splitlines() or [type(exc).__name__])[-1]
                raise RobogsError(
                    f"a Ray task failed: {first[:300]}",
                    where="--ray",
                    hint="the dataset must be at the same path on every node, with robogs "
                    "(and any check plug-in) installed there",
                ) from None
            yield result

    def shutdown(self) -> None:
        """Stop the local cluster this executor started (no-op otherwise)."""
        if self.started:
            import ray

            ray.shutdown()
            self.started = False


def ray_unit(root: str, base: dict[str, Any], unit: Unit, settings: dict[str, Any]) -> UnitResult:
    """Task body: one thread for the numerics of this worker (one task per CPU)."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)
    return run_unit(root, base, unit, settings)


class _Replayer(_Runner):
    """The runner of a split validation: driver checks run here, the others are replayed."""

    def __init__(
        self,
        ctx: CheckContext,
        max_per_code: int,
        *,
        plan: Plan,
        results: Callable[[], dict[str, list[tuple[int, _Outcome]]]],
    ) -> None:
        super().__init__(ctx, max_per_code)
        self.plan = plan
        self._results = results

    def run(self, chk: Check) -> None:
        if self.plan.reason is not None or self.plan.scopes.get(chk.code, "dataset") == "dataset":
            super().run(chk)
            return
        if chk.needs_valid_manifest and not self.ctx.manifest_valid:  # pragma: no cover
            super().run(chk)
            return
        parts = [o for _i, o in sorted(self._results().get(chk.code, []), key=lambda p: p[0])]
        n, status, seconds = 0, "ran", 0.0
        for part in parts:
            seconds += part.seconds
            for f in part.findings:
                self.add(f)
                n += 1
            for code, k in part.over.items():
                self.dropped[code] += k
                n += k
            self.reported_files |= part.over_files
            if part.end == "reported":
                status = "skipped" if n == 0 else "ran"
                break
            if part.end == "crashed":
                status = "crashed"
                break
            if part.end == "error":
                f = self._input_finding(chk, _Err(**(part.error or {})))  # type: ignore[arg-type]
                if f is not None:
                    self.add(f)
                    n += 1
                break
        self.runs.append(CheckRun(chk.code, chk.group, chk.title, status, seconds, n))


@dataclass
class _Err:
    """The parts of a ``RobogsError`` the runner reads (the error itself stays in the worker)."""

    path: str | None = None
    where: str | None = None
    message: str = ""
    hint: str | None = None


@dataclass
class Stats:
    """How a split validation went: units, workers seen, peak RSS per worker (bytes), task CPU."""

    units: int = 0
    #: of those, units that read their rows from a chunk index (the sharded layout)
    chunk_units: int = 0
    reason: str | None = None
    peak_rss: dict[int, int] = field(default_factory=dict)
    task_seconds: float = 0.0
    #: CPU seconds of the tasks, per worker process (does not depend on the machine's load)
    cpu_seconds: dict[int, float] = field(default_factory=dict)
    wall_seconds: float = 0.0


def validate_distributed(
    path: str | Path,
    *,
    executor: Executor | None = None,
    episodes_per_task: int = DEFAULT_EPISODES_PER_TASK,
    files_per_task: int = DEFAULT_FILES_PER_TASK,
    select: Iterable[str] | None = None,
    ignore: Iterable[str] | None = None,
    quick: bool = False,
    budgets: dict[str, float] | None = None,
    progress: bool | Callable[[str, float, float], None] = False,
    max_per_code: int = 50,
    label_threads: int = 1,
    options: dict[str, Any] | None = None,
    stats: Stats | None = None,
) -> Report:
    """:func:`robogs.format.validate.validate`, with per-episode and per-file checks in tasks.

    The report's findings, their order, the per-code caps and notes are those of the
    single-process run; ``Report.runs`` add up the workers' seconds. ``stats`` (if given)
    is filled with the units and the peak resident memory of each worker process.

    Raises:
        FormatError: as :func:`~robogs.format.validate.validate`.
    """
    t0 = time.perf_counter()
    executor = executor or LocalExecutor()
    stats = stats if stats is not None else Stats()
    select_l, ignore_l = list(select or []), list(ignore or [])
    settings = {
        "quick": quick,
        "budgets": dict(budgets or {}),
        "options": dict(options or {}),
        "max_per_code": max_per_code,
        "label_threads": 1,
    }
    state: dict[str, Any] = {}

    def make_runner(ctx: CheckContext, cap: int) -> _Replayer:
        checks = select_checks(
            list(available_checks().values()), select=select_l, ignore=ignore_l, quick=quick
        )
        plan = plan_units(
            ctx, checks, episodes_per_task=episodes_per_task, files_per_task=files_per_task
        )
        stats.units, stats.reason = len(plan.units), plan.reason
        stats.chunk_units = sum(u.chunk is not None for u in plan.units)
        # the workers get episodes and files through their units, or read their chunk's index
        base = {k: v for k, v in ctx.manifest.items() if k not in ("episodes", "files", "shards")}
        stream = executor.run(str(ctx.root), base, plan.units, settings) if plan.units else iter(())
        state["stream"], state["left"] = stream, len(plan.units)

        def results() -> dict[str, list[tuple[int, _Outcome]]]:
            if "by_code" not in state:
                by_code: dict[str, list[tuple[int, _Outcome]]] = {}
                total = state["left"]
                for done, res in enumerate(state["stream"], 1):
                    stats.peak_rss[res.pid] = max(stats.peak_rss.get(res.pid, 0), res.peak_rss)
                    stats.task_seconds += res.seconds
                    stats.cpu_seconds[res.pid] = (
                        stats.cpu_seconds.get(res.pid, 0.0) + res.cpu_seconds
                    )
                    for code, out in res.outcomes.items():
                        by_code.setdefault(code, []).append((res.index, out))
                    note = getattr(ctx.progress, "fraction", None)
                    if callable(note):
                        ctx.progress(f"{done}/{total} tasks")
                        note(done / max(total, 1))
                state["by_code"] = by_code
            return state["by_code"]

        return _Replayer(ctx, cap, plan=plan, results=results)

    report = validate(
        path,
        select=select_l,
        ignore=ignore_l,
        quick=quick,
        budgets=budgets,
        progress=progress,
        max_per_code=max_per_code,
        label_threads=label_threads,
        options=options,
        runner=make_runner,
    )
    _INDEX_CACHE.clear()  # the indexes a LocalExecutor read in this process
    stats.wall_seconds = time.perf_counter() - t0
    report.seconds = stats.wall_seconds
    return report
