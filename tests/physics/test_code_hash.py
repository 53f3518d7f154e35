"""The cache key's code hash (``gate.code_hash``, used by the gate's calibrations and the
memoised baselines) changes with the MuJoCo scene builder in ``robogs.format``, not only with
``robogs.physics``: h72 found a change to ``format/mjcf.py`` alone could reuse stale fits."""

from __future__ import annotations

from pathlib import Path

from robogs.physics import gate


def _hash_with_edit(monkeypatch, suffix: str) -> str:
    real = Path.read_bytes

    def edited(self: Path) -> bytes:
        data = real(self)
        return data + b"\n# edited\n" if self.as_posix().endswith(suffix) else data

    monkeypatch.setattr(Path, "read_bytes", edited)
    gate.code_hash.cache_clear()  # cached per process
    try:
        return gate.code_hash()
    finally:
        monkeypatch.setattr(Path, "read_bytes", real)
        gate.code_hash.cache_clear()


def test_code_hash_follows_the_physics_and_format_sources(monkeypatch):
    gate.code_hash.cache_clear()
    base = gate.code_hash()
    assert _hash_with_edit(monkeypatch, "no/such/file.py") == base  # deterministic
    assert _hash_with_edit(monkeypatch, "robogs/format/mjcf.py") != base
    assert _hash_with_edit(monkeypatch, "robogs/format/shapes.py") != base
    assert _hash_with_edit(monkeypatch, "robogs/physics/fit.py") != base
    # the engines' subfolder too: the servo smoothing (mujoco_engine) moves MuJoCo's fits (h75)
    assert _hash_with_edit(monkeypatch, "robogs/physics/engines/mujoco_engine.py") != base
    assert _hash_with_edit(monkeypatch, "robogs/cli/main.py") == base  # not model code
