"""A label PNG that claims far more pixels than it stores is refused from its header, before
inflation (issue 19, item 4: a 57 kB 5000x5000 PNG took ``validate --select G009`` to 4.2 GB)."""

from __future__ import annotations

import hashlib
import json
import resource
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from robogs.format.errors import FormatError
from robogs.format.images import MAX_LABEL_PIXELS, decode_label_png


def _plant(root: Path, png: bytes) -> str:
    m = json.loads((root / "manifest.json").read_text())
    rel = next(
        st["labels"]
        for ep in m["episodes"]
        for st in ep["streams"].values()
        if isinstance(st.get("labels"), str)
    )
    t = pq.read_table(root / rel)
    pngs = t.column("png").to_pylist()
    pngs[0] = png
    i = t.schema.get_field_index("png")
    t = t.set_column(i, t.schema.field(i), pa.array(pngs, t.schema.field(i).type))
    pq.write_table(t, root / rel)
    data = (root / rel).read_bytes()
    m["files"][rel].update(sha256=hashlib.sha256(data).hexdigest(), size=len(data))
    (root / "manifest.json").write_text(json.dumps(m))
    return rel


def _png(h: int, w: int) -> bytes:
    ok, buf = cv2.imencode(".png", np.zeros((h, w), np.uint16))
    assert ok
    return buf.tobytes()


def test_budget_boundary_is_exact() -> None:
    side = int(np.sqrt(MAX_LABEL_PIXELS))
    assert decode_label_png(_png(side, side)).shape == (side, side)
    with pytest.raises(FormatError, match="over the 16777216-pixel budget"):
        decode_label_png(_png(side, side + 1))


def test_bomb_is_a_finding_with_bounded_memory(clean_copy: Path) -> None:
    bomb = _png(5000, 5000)
    assert len(bomb) < 100_000  # tiny on disk, 50 MB decoded
    _plant(clean_copy, bomb)
    exe = Path(sys.executable).with_name("robogs-validate")
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    run = subprocess.run(
        [str(exe), str(clean_copy), "--select", "G009", "--json"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    peak_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    assert run.returncode == 1, run.stderr
    report = json.loads(run.stdout)
    msgs = [f["message"] for f in report["findings"]]
    assert any("5000x5000 pixels, over the 16777216-pixel budget" in m for m in msgs), msgs
    # RUSAGE_CHILDREN is the largest child so far; earlier children of this worker are smaller
    assert max(before, peak_kb) < 1_000_000, f"peak RSS {peak_kb} kB"
