"""Bulk datasets with a few episodes corrupted in known ways (for the split-validation oracle).

Written with pyarrow and hashlib directly; the validator is never called here.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from robogs.synth.bulk import write_bulk_dataset

__all__ = ["mutated_bulk", "EXPECTED_CODES", "to_flat_path"]

#: codes the mutations below must raise (besides the checks that then skip the broken inputs)
EXPECTED_CODES = {"T001", "I009", "T003", "I004", "I005", "I001", "I006", "G008", "I002"}


def _manifest(root: Path) -> dict:
    return json.loads((root / "manifest.json").read_text(encoding="utf-8"))


def _save(root: Path, m: dict) -> None:
    (root / "manifest.json").write_text(json.dumps(m, indent=1), encoding="utf-8")


def _lister(root: Path, rel: str) -> Path:
    """The JSON file whose ``files`` lists ``rel``: the manifest, or its chunk's index."""
    parts = rel.split("/")
    if parts[1].startswith("chunk-") and len(parts) > 3:
        return root / "episodes" / parts[1] / "index.json"
    return root / "manifest.json"


def _set_entry(root: Path, rel: str, **values) -> None:
    """Change ``rel``'s files entry where it is listed (a chunk index is then rehashed)."""
    doc_path = _lister(root, rel)
    doc = json.loads(doc_path.read_text(encoding="utf-8"))
    for key, v in values.items():
        doc["files"][rel][key] = v(doc["files"][rel][key]) if callable(v) else v
    doc_path.write_text(json.dumps(doc, indent=1), encoding="utf-8")
    if doc_path.name == "index.json":  # the manifest's chunk entry keeps the row total
        index_rel = doc_path.relative_to(root).as_posix()
        m = _manifest(root)
        for c in m["shards"]["chunks"]:
            if c["index"] == index_rel:
                c["rows"] = sum(f.get("rows", 0) for f in doc["files"].values())
        _save(root, m)
        _rehash(root, index_rel)


def _rehash(root: Path, rel: str) -> None:
    p = root / rel
    digest, size = hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_size
    if _lister(root, rel).name == "index.json":
        _set_entry(root, rel, sha256=digest, size=size)
        return
    m = _manifest(root)
    m["files"][rel]["sha256"], m["files"][rel]["size"] = digest, size
    _save(root, m)


def _edit(root: Path, rel: str, fn) -> None:
    tab = pq.read_table(root / rel)
    pq.write_table(fn(tab), root / rel)
    _rehash(root, rel)


def _set(tab: pa.Table, name: str, values: np.ndarray) -> pa.Table:
    return tab.set_column(tab.schema.get_field_index(name), name, pa.array(values))


def mutated_bulk(
    root: Path, n_episodes: int, *, duration_s: float = 0.4, chunk_size: int | None = None
) -> Path:
    """A bulk dataset (``n_episodes`` >= 32) with nine defects in known episodes; with
    ``chunk_size`` in the sharded layout, the defects the same (entries edited in the chunk
    indexes, whose own hashes are then brought up to date)."""
    assert n_episodes >= 32
    write_bulk_dataset(
        root, n_episodes=n_episodes, duration_s=duration_s, seed=3, chunk_size=chunk_size
    )
    w = max(3, len(str(n_episodes - 1)))

    def rel(k: int, name: str) -> str:
        folder = "episodes" if chunk_size is None else f"episodes/chunk-{k // chunk_size:03d}"
        return f"{folder}/ep{k:0{w}d}/{name}.parquet"

    def swap(tab: pa.Table) -> pa.Table:  # two stamps out of order (T001)
        t = tab.column("t_ns").to_numpy().copy()
        t[50], t[51] = t[51], t[50]
        return _set(tab, "t_ns", t)

    def nan_x(tab: pa.Table) -> pa.Table:  # non-finite samples (I009)
        x = tab.column("x").to_numpy().copy()
        x[10:20] = np.nan
        return _set(tab, "x", x)

    def offset(tab: pa.Table) -> pa.Table:  # joint 2 reads 0.05 rad off (G008)
        return _set(tab, "position.joint2", tab.column("position.joint2").to_numpy() + 0.05)

    _edit(root, rel(3, "joint_states"), swap)
    _edit(root, rel(7, "ee_poses"), nan_x)
    _edit(root, rel(8, "ee_poses"), nan_x)
    _edit(root, rel(11, "joint_states"), lambda t: pa.concat_tables([t[:100], t[110:]]))
    _set_entry(root, rel(15, "joint_states"), sha256="0" * 64)  # I004
    _set_entry(root, rel(19, "ee_poses"), rows=lambda r: r + 1)  # I005
    (root / rel(23, "ee_poses")).unlink()  # I001, and the checks reading it skip it
    p = root / rel(27, "joint_states")
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])  # I006
    _rehash(root, rel(27, "joint_states"))
    _edit(root, rel(30, "joint_states"), offset)
    (root / "notes.txt").write_text("not listed\n", encoding="utf-8")  # I002
    return root


def to_flat_path(text: str) -> str:
    """``episodes/chunk-NNN/<ep>/...`` -> ``episodes/<ep>/...`` (to compare the two layouts)."""
    return re.sub(r"episodes/chunk-\d{3,}/", "episodes/", text)
