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
