"""The one mesh loader: a good mesh loads, each bad file is a RobogsError with place and hint."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from robogs.format.errors import FormatError, InputError
from robogs.format.meshes import MESH_FORMATS_HINT, load_mesh


def test_box_loads_with_its_geometry(tmp_path: Path) -> None:
    box = trimesh.creation.box(extents=(0.1, 0.2, 0.3))
    box.export(tmp_path / "b.stl")
    m = load_mesh(tmp_path / "b.stl")
    assert len(m.faces) == 12
    np.testing.assert_allclose(m.extents, (0.1, 0.2, 0.3), atol=1e-7)


def test_missing_unreadable_and_empty(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="mesh file not found") as e:
        load_mesh(tmp_path / "nope.stl", error=InputError, where="--object a=mesh:")
    assert e.value.where == "--object a=mesh:"
    (tmp_path / "bad.glb").write_bytes(b"glTF\x02\x00\x00\x00garbage")
    with pytest.raises(FormatError, match="unreadable mesh") as e:
        load_mesh(tmp_path / "bad.glb")
    assert e.value.hint == MESH_FORMATS_HINT and e.value.path == str(tmp_path / "bad.glb")
    (tmp_path / "empty.obj").write_text("# nothing\n")
    with pytest.raises(FormatError, match="no triangles"):
        load_mesh(tmp_path / "empty.obj")
    load_mesh(tmp_path / "empty.obj", triangles=False)  # vertex-only callers check themselves


def test_a_zip_bomb_mesh_is_refused_before_unpacking(tmp_path: Path) -> None:
    """Issue 19: vertices and decompressed bytes are budgeted. A 3MF/ZAE is a zip; a 300 MB
    member compressed to a few hundred kB is refused from the archive's directory alone."""
    import zipfile

    from robogs.format.meshes import MAX_MESH_BYTES

    bomb = tmp_path / "bomb.3mf"
    with zipfile.ZipFile(bomb, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        with zf.open("3D/3dmodel.model", "w", force_zip64=True) as fh:
            chunk = b"\0" * (1 << 20)
            for _ in range(MAX_MESH_BYTES // len(chunk) + 8):
                fh.write(chunk)
    assert bomb.stat().st_size < 2_000_000
    with pytest.raises(FormatError, match="unpacked from .*over the 268435456-byte budget"):
        load_mesh(bomb)


def test_the_vertex_budget(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import robogs.format.meshes as meshes

    p = tmp_path / "box.stl"
    trimesh.creation.box((0.1, 0.1, 0.1)).export(p)
    n = len(load_mesh(p).vertices)  # STL repeats vertices per triangle (process=False): 36
    assert n == 36
    monkeypatch.setattr(meshes, "MAX_MESH_VERTICES", n - 1)
    with pytest.raises(FormatError, match="36 vertices, over the 35 budget"):
        load_mesh(p)
