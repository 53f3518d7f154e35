"""Bulk datasets with a few episodes corrupted in known ways (for the split-validation oracle).

Written with pyarrow and hashlib directly; the validator is never called here.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from robogs.synth.bulk import write_bulk_dataset

__all__ = ["mutated_bulk", "EXPECTED_CODES"]

#: codes the mutations below must raise (besides the checks that then skip the broken inputs)
EXPECTED_CODES = {"T001", "I009", "T003", "I004", "I005", "I001", "I006", "G008", "I002"}


def _manifest(root: Path) -> dict:
    return json.loads((root / "manifest.json").read_text(encoding="utf-8"))


def _save(root: Path, m: dict) -> None:
    (root / "manifest.json").write_text(json.dumps(m, indent=1), encoding="utf-8")


def _rehash(root: Path, rel: str) -> None:
    m = _manifest(root)
    p = root / rel
    m["files"][rel]["sha256"] = hashlib.sha256(p.read_bytes()).hexdigest()
    m["files"][rel]["size"] = p.stat().st_size
    _save(root, m)


def _edit(root: Path, rel: str, fn) -> None:
    tab = pq.read_table(root / rel)
    pq.write_table(fn(tab), root / rel)
    _rehash(root, rel)


def _set(tab: pa.Table, name: str, values: np.ndarray) -> pa.Table:
    return tab.set_column(tab.schema.get_field_index(name), name, pa.array(values))


def mutated_bulk(root: Path, n_episodes: int, *, duration_s: float = 0.4) -> Path:
    """A bulk dataset (``n_episodes`` >= 32) with nine defects in known episodes."""
    assert n_episodes >= 32
    write_bulk_dataset(root, n_episodes=n_episodes, duration_s=duration_s, seed=3)
    w = max(3, len(str(n_episodes - 1)))

    def rel(k: int, name: str) -> str:
        return f"episodes/ep{k:0{w}d}/{name}.parquet"

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
    m = _manifest(root)
    m["files"][rel(15, "joint_states")]["sha256"] = "0" * 64  # I004
    m["files"][rel(19, "ee_poses")]["rows"] += 1  # I005
    _save(root, m)
    (root / rel(23, "ee_poses")).unlink()  # I001, and the checks reading it skip it
    p = root / rel(27, "joint_states")
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])  # I006
    _rehash(root, rel(27, "joint_states"))
    _edit(root, rel(30, "joint_states"), offset)
    (root / "notes.txt").write_text("not listed\n", encoding="utf-8")  # I002
    return root
