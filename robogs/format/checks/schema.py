"""Schema checks (S0xx): the manifest, the JSON sidecars and the table columns follow the spec."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from ..dataset import MANIFEST_NAME, read_parquet
from ..errors import FormatError, RobogsError, VersionError
from ..findings import Finding
from ..jsonio import read_json
from ..schemas import schema_problems
from ..spec_version import SPEC_VERSION, parse_version
from ..tables import check_table_schema, family_columns, non_null_columns
from .context import STREAM_FILE_FIELDS, CheckContext, InputReported, table_kind
from .registry import Check, check
from .streaming import batches

__all__: list[str] = []


def _theirs(ctx: CheckContext) -> tuple[int, int, int] | None:
    try:
        return parse_version(str(ctx.manifest.get("spec_version", "")))
    except VersionError:
        return None


def _newer_minor(ctx: CheckContext) -> bool:
    return ctx.newer_minor


# Checks share one shape by design: a @check(...) registration over a finding loop.
@check(
    "S001",
    group="schema",
    severity="error",
    title="manifest follows the JSON Schema",
    needs_full=False,
    needs_valid_manifest=False,
    quantity="schema violations",
    hint="fix the field named by the JSON pointer; the writer never produces this",
)
def _manifest_schema(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    lenient = _newer_minor(ctx)
    for p in ctx.manifest_problems:
        unknown_field = "Additional properties are not allowed" in p.message
        if lenient and unknown_field:
            yield chk.finding(
                f"{p.message} (field of a newer minor spec version)",
                severity="warning",
                file=MANIFEST_NAME,
                where=p.pointer,
                hint=f"this robogs reads spec {SPEC_VERSION}; upgrade robogs to use the field",
            )
        else:
            yield chk.finding(p.message, file=MANIFEST_NAME, where=p.pointer)


def _sidecars(ctx: CheckContext) -> list[tuple[str, str, str]]:
    """(relative path, schema name, manifest pointer) of every JSON sidecar."""
    out: list[tuple[str, str, str]] = []
    cams = ctx.manifest.get("cameras")
    if isinstance(cams, dict):
        out += [
            (rel, "camera", f"/cameras/{name}")
            for name, rel in sorted(cams.items())
            if isinstance(rel, str)
        ]
    phys = ctx.manifest.get("physics")
    if isinstance(phys, str):
        out.append((phys, "physics", "/physics"))
    robot = ctx.manifest.get("robot")
    if isinstance(robot, dict) and isinstance(robot.get("mdh"), str):
        out.append((robot["mdh"], "mdh", "/robot/mdh"))
    for rel in sorted(ctx.files):
        if rel.startswith("physics/history/rev-") and rel.endswith(".json"):
            out.append((rel, "physics", f"/files/{rel}"))
    return out


@check(
    "S002",
    group="schema",
    severity="error",
    title="JSON sidecars follow their schemas",
    needs_valid_manifest=False,
    quantity="schema violations",
    hint="fix the field named by the JSON pointer (cameras/*.json, physics.json, robot/mdh.json)",
)
def _sidecar_schema(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for rel, schema, _ptr in _sidecars(ctx):
        try:
            path = ctx.existing(rel)
        except InputReported:
            continue  # missing or unsafe: reported by the integrity checks
        try:
            doc = read_json(path, what=f"{schema} file")
        except FormatError as exc:
            yield chk.finding(exc.message, file=rel, where=exc.where, hint=exc.hint or chk.hint)
            continue
        if not isinstance(doc, dict):
            yield chk.finding(f"{schema} file must hold a JSON object", file=rel, where="/")
            continue
        for p in schema_problems(schema, doc):
            yield chk.finding(p.message, file=rel, where=p.pointer)


@check(
    "S003",
    group="schema",
    severity="error",
    title="table columns and types match the table kind",
    needs_full=False,
    quantity="column problems",
    hint="re-export the table with the columns and types of spec/FORMAT.md",
)
def _table_schema(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    done: set[str] = set()
    for ep, name, st in ctx.streams():
        for fld in STREAM_FILE_FIELDS:
            rel = st.get(fld)
            kind = table_kind(st, fld)
            if not isinstance(rel, str) or not kind or rel in done:
                continue
            done.add(rel)
            try:
                md = ctx.footer(rel)
            except InputReported:
                continue
            schema = md.schema.to_arrow_schema()
            problems = check_table_schema(kind, schema) or _null_problems(ctx, rel, kind, md)
            for problem in problems:
                yield chk.finding(f"{kind} table: {problem}", file=rel, episode=ep.id, stream=name)


def _null_problems(ctx: CheckContext, rel: str, kind: str, md: Any) -> list[str]:
    """Nulls in columns that must not hold them, from the footer statistics.

    When a column chunk has no statistics, full mode reads the column; quick mode trusts it.
    """
    names = md.schema.to_arrow_schema().names
    cols = non_null_columns(kind, names)
    counts: dict[str, int] = {}
    unknown: list[str] = []
    for name in cols:
        j = names.index(name)
        n = 0
        for g in range(md.num_row_groups):
            stats = md.row_group(g).column(j).statistics
            if stats is None or not stats.has_null_count:
                unknown.append(name)
                break
            n += stats.null_count
        counts[name] = n
    if unknown and not ctx.quick:
        try:
            tab = read_parquet(ctx.existing(rel), columns=unknown)
        except (FormatError, InputReported):
            return []  # unreadable bodies are reported by I006
        counts.update({c: tab.column(c).null_count for c in unknown})
    return [f"column {c!r} holds {n} nulls" for c, n in counts.items() if n]


@check(
    "S004",
    group="schema",
    severity="warning",
    title="spec version is not a newer minor version",
    needs_full=False,
    needs_valid_manifest=False,
    quantity="spec version",
    hint="upgrade robogs to read every field of this dataset",
)
def _newer_minor_version(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    if _newer_minor(ctx):
        yield chk.finding(
            f"dataset uses spec {ctx.manifest.get('spec_version')}, newer than the spec {SPEC_VERSION} "
            "this robogs reads; fields it does not know are reported but ignored",
            file=MANIFEST_NAME,
            where="/spec_version",
        )


@check(
    "S005",
    group="schema",
    severity="error",
    title="spec major version is readable",
    needs_full=False,
    needs_valid_manifest=False,
    quantity="spec version",
    hint="upgrade robogs (pip install -U robogs) to read this dataset",
)
def _major_version(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    err = ctx.version_error
    if err is not None and _theirs(ctx) is not None:
        yield chk.finding(
            err.message, file=MANIFEST_NAME, where="/spec_version", hint=err.hint or chk.hint
        )


@check(
    "S006",
    group="schema",
    severity="error",
    title="budget overrides in the manifest are known",
    needs_full=False,
    needs_valid_manifest=False,
    quantity="unknown budgets",
    hint="use the budget names listed in spec/FORMAT.md (robogs-validate --list-checks shows them)",
)
def _budget_names(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for problem in ctx.budget_problems:
        yield chk.finding(problem, file=MANIFEST_NAME, where="/budgets")


def _strings(ctx: CheckContext, rel: str, column: str) -> set[str | None]:
    """Distinct values of a name column, read batch by batch; nulls appear as ``None``."""
    out: set[str | None] = set()
    for b in batches(ctx, rel, (column,)):
        out |= {None if v is None else str(v) for v in b.column(0).unique().to_pylist()}
    return out


@check(
    "S007",
    group="schema",
    severity="error",
    title="tables name known joints, links, objects, cameras and labels",
    quantity="unknown names",
    hint="rename the entries to the URDF joint/link, asset, camera or segment names",
)
def _names(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    joints: set[str] | None = None
    links: set[str] | None = None
    actuated: list[str] = []
    if ctx.has_robot():
        try:
            chain = ctx.chain()
            actuated = list(chain.joint_names)
            joints = set(actuated)
            links = set(chain.link_names)
        except (InputReported, RobogsError):
            pass  # the URDF is reported by the geometry checks
    assets = set(ctx.asset_names())
    cameras = set(ctx.manifest.get("cameras") or {})

    def unknown(found: set[str | None], known: set[str] | None) -> list[str]:
        """Names not in ``known`` (all of them count when ``known`` is None), and nulls."""
        bad = {v for v in found if v is None or (known is not None and v not in known)}
        return sorted("<null>" if v is None else v for v in bad)

    for ep, name, st in ctx.streams():
        kind = st.get("kind")
        rel = st.get("path")
        loc = {"episode": ep.id, "stream": name}
        if kind == "camera":
            cam = st.get("camera")
            if not isinstance(cam, str) or cam not in cameras:
                yield chk.finding(
                    f"camera stream names camera {cam!r}, which the manifest does not declare",
                    file=MANIFEST_NAME,
                    where=f"/episodes/{ep.id}/streams/{name}/camera",
                    **loc,
                )
            continue
        if not isinstance(rel, str):
            continue
        try:
            names = ctx.footer(rel).schema.to_arrow_schema().names
        except InputReported:
            continue
        checks: list[tuple[str, list[str]]] = []
        if kind == "joint_states":
            cols = family_columns(names, "position.")
            checks.append(("joint", unknown(set(cols), joints)))
            for fam in ("velocity.", "effort."):
                checks.append(("joint", unknown(set(family_columns(names, fam)), joints)))
            missing = [j for j in actuated if j not in cols]
            if joints is not None and missing:
                yield chk.finding(
                    f"joint_states has no position column for actuated joints {missing}",
                    severity="warning",
                    file=rel,
                    **loc,
                    hint="record every actuated joint; forward-kinematics checks need them",
                )
        elif kind == "actions":
            checks.append(("joint", unknown(set(family_columns(names, "command.")), joints)))
        elif kind == "ee_poses" and "link" in names:
            checks.append(("link", unknown(_strings(ctx, rel, "link"), links)))
        elif kind in ("object_poses", "boxes3d") and "object" in names:
            checks.append(("object", unknown(_strings(ctx, rel, "object"), assets)))
        elif kind == "boxes2d" and "camera" in names:
            checks.append(
                (
                    "camera",
                    unknown(_strings(ctx, rel, "camera"), cameras),
                )
            )
            yield from _box_labels(chk, ctx, ep, rel, loc)
        elif kind == "segments" and {"kind", "target"} <= set(names):
            seg = ctx.table(rel, columns=("kind", "target"))
            kinds = np.asarray(seg.column("kind").to_pylist(), dtype=object)
            targets = np.asarray(seg.column("target").to_pylist(), dtype=object)
            checks.append(
                ("link", unknown({str(t) for t in targets[kinds == "robot_link"]}, links))
            )
            checks.append(("object", unknown({str(t) for t in targets[kinds == "object"]}, assets)))
            bad_kinds = sorted({str(k) for k in kinds} - {"robot_link", "object", "background"})
            if bad_kinds:
                yield chk.finding(
                    f"segments use unknown kinds {bad_kinds}",
                    file=rel,
                    **loc,
                    hint="kind is one of robot_link, object, background",
                )
        for what, bad in checks:
            if bad:
                yield chk.finding(f"{kind} names unknown {what}s {bad[:10]}", file=rel, **loc)


def _box_labels(
    chk: Check, ctx: CheckContext, ep: Any, rel: str, loc: dict[str, Any]
) -> Iterator[Finding]:
    seg_name = ctx.find_stream(ep, "segments")
    if seg_name is None or "label_id" not in ctx.footer(rel).schema.to_arrow_schema().names:
        return
    try:
        known = set(
            ctx.stream_table(ep, seg_name, columns=("label_id",)).column("label_id").to_pylist()
        )
    except InputReported:
        return
    used = set(ctx.table(rel, columns=("label_id",)).column("label_id").unique().to_pylist())
    bad = sorted(int(v) for v in used - known if v is not None)
    if bad:
        yield chk.finding(
            f"boxes2d use label ids {bad[:10]} that the segments table does not define",
            file=rel,
            **loc,
        )
