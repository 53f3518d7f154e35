"""Rerun export with ``--rerender``: labels re-rendered from the bound splats, read back with rerun.

The small synthetic scene's labels are rasterised from the meshes by the generator's own
renderer, so the re-rendered labels must mostly agree with them; the logged re-render must be
exactly what :class:`robogs.format.rerender.SceneRerenderer` gives for that frame, and the
difference image must follow its colour code pixel for pixel.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader

from robogs.cli.main import main
from robogs.convert.export import export
from robogs.format import Dataset
from robogs.format.images import decode_label_png

STRIDE = 60
SCALE = 0.5


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    from robogs.synth.scene import synthesize

    root = tmp_path_factory.mktemp("rerender") / "small"
    synthesize(root, seed=0, size="small", progress=False)
    return Dataset.open(root)


def _image(table: pa.Table, prefix: str, row: int) -> np.ndarray:
    """Row ``row`` of an ``Image``/``SegmentationImage`` column pair, as a numpy image."""
    fmt = table.column(f"{prefix}:format").to_pylist()[row][0]
    buf = np.asarray(table.column(f"{prefix}:buffer").to_pylist()[row][0], np.uint8)
    dtype = {6: np.uint8, 8: np.uint16}[fmt["channel_datatype"]]
    chans = 3 if fmt["color_model"] == 2 else 1
    img = buf.view(dtype).reshape(fmt["height"], fmt["width"], chans)
    return img[..., 0] if chans == 1 else img


@pytest.mark.slow
def test_rerender_layer_logs_labels_recorded_and_difference(scene: Dataset, tmp_path: Path) -> None:
    import cv2
    import pyarrow.parquet as pq

    from robogs.format.binding import Binding
    from robogs.format.rerender import SceneRerenderer, label_channels

    out = tmp_path / "r.rrd"
    report = export(
        "rerun", scene, out, layers=["cameras"], rerender=True, rerender_stride=STRIDE,
        rerender_scale=SCALE,
    )  # fmt: skip
    assert any("2 frames of cam0 re-rendered" in n for n in report.notes)
    batches: dict[str, list[pa.RecordBatch]] = {}
    for chunk in RrdReader(out).stream().collect().stream():
        batches.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    for e in ("labels", "recorded", "diff"):
        assert f"/rerender/cam0/{e}" in batches
    assert "/rerender" in batches  # its annotation context
    ep = scene.episode()
    frames = ep.frames("cam0")
    t_all = frames.column("t_ns").to_numpy()
    fi_all = frames.column("frame_index").to_numpy()

    def rows(entity: str, comp: str) -> pa.Table:
        return pa.Table.from_batches([b for b in batches[entity] if comp in b.schema.names])

    lab_t = rows("/rerender/cam0/labels", "SegmentationImage:buffer")
    assert lab_t.column("time").cast(pa.int64()).to_pylist() == t_all[::STRIDE].tolist()
    rec_t = rows("/rerender/cam0/recorded", "SegmentationImage:buffer")
    diff_t = rows("/rerender/cam0/diff", "Image:buffer")
    pct = rows("/plots/rerender/cam0/disagree_pct", "Scalars:scalars")
    tab = pq.read_table(ep.labels_path("cam0"))
    labels = {
        int(i): decode_label_png(b)
        for i, b in zip(
            tab.column("frame_index").to_pylist(), tab.column("png").to_pylist(), strict=True
        )
    }
    binding = Binding(scene, ep.id)
    channels = label_channels(binding, ep.table("segments"))
    rr_ = SceneRerenderer(binding, scene.camera("cam0"), channels, scale=SCALE)
    lut = np.concatenate([[0], channels.label_ids]).astype(np.uint16)
    colors = {0: (0, 0, 0), 1: (255, 0, 0), 2: (0, 255, 0), 3: (255, 255, 0)}
    for k, idx in enumerate(fi_all[::STRIDE]):
        rec = _image(rec_t, "SegmentationImage", k)
        ren = _image(lab_t, "SegmentationImage", k)
        diff = _image(diff_t, "Image", k)
        np.testing.assert_array_equal(rec, labels[int(idx)])
        if k == 0:  # the logged re-render is exactly SceneRerenderer's for this frame
            p = rr_.probabilities(rr_.render(int(t_all[idx])))
            up = cv2.resize(p, (rec.shape[1], rec.shape[0]), interpolation=cv2.INTER_LINEAR)
            np.testing.assert_array_equal(ren, lut[up.argmax(-1)])
        # difference colours, pixel by pixel
        want = np.zeros(rec.shape + (3,), np.uint8)
        for y, x in zip(*np.nonzero((rec > 0) | (ren > 0)), strict=True):
            a, b = int(rec[y, x]), int(ren[y, x])
            want[y, x] = colors[1 if b == 0 else 2 if a == 0 else 0 if a == b else 3]
        np.testing.assert_array_equal(diff, want)
        disagree = 100.0 * float(np.mean(rec != ren))
        assert pct.column("Scalars:scalars").to_pylist()[k][0] == pytest.approx(disagree, abs=1e-9)
        # the splats land where the independently rasterised labels are
        fg = (rec > 0) | (ren > 0)
        assert np.mean(rec[fg] == ren[fg]) > 0.8


def test_rerender_flags(scene: Dataset, tmp_path: Path, capsys) -> None:
    rc = main(["export", "ply", str(scene.root), str(tmp_path / "a.ply"), "--rerender"])
    assert rc == 2 and "--rerender does not apply to the ply export" in capsys.readouterr().err
    rc = main(
        ["export", "rerun", str(scene.root), str(tmp_path / "a.rrd"), "--rerender-stride", "0"]
    )
    err = capsys.readouterr().err
    assert rc == 2 and "--rerender-stride must be an integer >= 1" in err
    assert not (tmp_path / "a.rrd").exists()
