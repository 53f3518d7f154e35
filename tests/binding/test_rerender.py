"""Binding checks (B0xx) on the small synthetic scene: clean, and corrupted one way at a time.

The scene's labels are rasterised from the meshes by the generator's own renderer, so they are
an independent oracle for the splat re-render. Offsets and displacements are injected exactly
(camera stamps +20 ms, camera moved 3 mm along its x axis) and must be recovered to 1 ms / 1 mm.

Each mutation runs twice: with ``full`` (every ``stride``-th frame, 8 fit frames: the behaviour
before the time budget) and in the default budgeted mode with a fixed per-frame cost (so the
frame choice is the same on every machine): 0.2 s per frame in the default 4 s budget compares
8 of the 120 frames and fits on 2; the mutations must still be caught.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from scipy.spatial.distance import cdist

from robogs.format.checks import CheckContext, InputReported, get_check
from robogs.format.checks.binding import alignment_fit, label_summary
from robogs.format.findings import Finding
from robogs.format.images import decode_label_png, encode_label_png
from robogs.format.rerender import boundary_distance, compare_frame, void_band
from robogs.format.splats import read_splat_ply, write_splat_ply

B_CODES = [f"B{i:03d}" for i in range(1, 12)]
#: speed options of these tests: every 8th frame for the label pass, 8 frames for the fit, no budget
FAST = {"stride": 8, "fit_frames": 8, "full": True}
#: the default budgeted mode, with a fixed per-frame cost instead of a measured one
BUDGETED = {"frame_cost_s": 0.2}
MODES = {"full": FAST, "budget": BUDGETED}


@pytest.fixture(scope="module")
def synth_scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from robogs.synth.scene import synthesize

    root = tmp_path_factory.mktemp("synth") / "small"
    synthesize(root, seed=0, size="small", progress=False)
    return root


@pytest.fixture()
def scene_copy(synth_scene: Path, tmp_path: Path):
    def make(name: str) -> Path:
        dst = tmp_path / name
        shutil.copytree(synth_scene, dst)
        return dst

    return make


def _rehash(root: Path, *rels: str) -> None:
    mpath = root / "manifest.json"
    m = json.loads(mpath.read_text(encoding="utf-8"))
    for rel in rels:
        data = (root / rel).read_bytes()
        m["files"][rel] = {
            **m["files"][rel],
            "sha256": hashlib.sha256(data).hexdigest(),
            "size": len(data),
        }
    mpath.write_text(json.dumps(m, indent=2, sort_keys=True), encoding="utf-8")


def _run(
    root: Path, codes: list[str], budgets: dict[str, float] | None = None, **options: object
) -> tuple[list[Finding], CheckContext]:
    """Run checks like the validator does (inputs reported elsewhere end a check quietly)."""
    ctx = CheckContext(root, budgets=budgets)
    base = MODES[str(options.pop("mode", "full"))]
    ctx.options = {**base, **options}  # type: ignore[attr-defined]
    out: list[Finding] = []
    for code in codes:
        try:
            out.extend(get_check(code).run(ctx))
        except InputReported:
            pass
    return out, ctx


def _stream(root: Path) -> tuple[str, str]:
    m = json.loads((root / "manifest.json").read_text())
    ep = m["episodes"][0]
    return ep["id"], next(n for n, s in ep["streams"].items() if s["kind"] == "camera")


# ------------------------------------------------------------------------------ oracles


def _brute_boundary(a: np.ndarray, b: np.ndarray) -> tuple[float, int]:
    def edge(m: np.ndarray) -> np.ndarray:
        p = np.pad(m, 1, mode="edge")
        inner = p[1:-1, 1:-1] & p[:-2, 1:-1] & p[2:, 1:-1] & p[1:-1, :-2] & p[1:-1, 2:]
        return np.argwhere(m & ~inner).astype(float)

    ea, eb = edge(a), edge(b)
    d = cdist(ea, eb)
    return float(d.min(1).sum() + d.min(0).sum()), len(ea) + len(eb)


@pytest.mark.parametrize("shift", [(0, 0), (0, 3), (2, -1), (5, 4)])
def test_boundary_distance_matches_brute_force(shift: tuple[int, int]) -> None:
    a = np.zeros((40, 50), bool)
    a[8:25, 10:31] = True
    a[12:16, 28:40] = True  # an L-shape
    b = np.roll(a, shift, axis=(0, 1))
    s, n = boundary_distance(a, b)
    s0, n0 = _brute_boundary(a, b)
    assert n == n0
    assert s == pytest.approx(s0, rel=1e-4, abs=1e-3)
    if shift == (0, 3):  # a pure horizontal shift of 3 px moves vertical edges by 3 px
        assert 0.5 < s / n <= 3.0


def test_compare_frame_counts_and_void_band() -> None:
    rec = np.zeros((60, 80), np.int64)
    rec[10:40, 10:50] = 1
    rec[20:30, 55:75] = 2
    ren = rec.copy()
    ren[rec == 2] = 0  # label 2 missing from the re-render
    ren[10:40, 50] = 1  # label 1 one column wider (inside the void band)
    prob = np.eye(3, dtype=np.float32)[ren]
    m = compare_frame(prob, np.ones((60, 80)), rec, 2)
    keep = ~void_band(rec)
    for c in (1, 2):
        inter = ((rec == c) & (ren == c) & keep).sum()
        union = (((rec == c) | (ren == c)) & keep).sum()
        assert m.inter[c - 1] == inter and m.union[c - 1] == union
    assert m.inter[0] == m.union[0]  # the one-column growth hides in the void band
    assert m.inter[1] == 0 and m.union[1] > 0
    s, n = _brute_boundary(rec == 1, ren == 1)
    assert m.boundary_sum[0] == pytest.approx(s, rel=1e-4) and m.boundary_count[0] == n
    band = void_band(rec)
    assert band[9:12, 20].all() and not band[7, 20] and not band[13, 20]  # 2 px each side


# ------------------------------------------------------------------------------ the scene


def test_clean_scene_has_no_binding_finding(synth_scene: Path) -> None:
    findings, ctx = _run(synth_scene, B_CODES, stride=16)
    assert not findings, [f"{f.severity} {f.code} {f.message}" for f in findings]
    # the colour match clears its floor with room to spare: raise the floor to see the value
    ctx.budgets["binding.psnr_min_db"] = 100.0
    (psnr,) = get_check("B004").run(ctx)
    assert 24.0 < psnr.value < 40.0  # 26.4 dB measured (mp4 + splat edges); linear colour: 12
    ep, stream = _stream(synth_scene)
    summary = {s.name: s for s in label_summary(ctx, ep, stream)}
    assert summary["table"].iou > 0.99 and summary["upper_arm_link"].iou > 0.95
    assert all(s.boundary_px < 1.5 for s in summary.values() if s.pixels)
    fit = alignment_fit(ctx, ep, stream)
    assert fit is not None and fit.offset_observable
    assert abs(fit.offset_ms) < 2.0  # the small scene resolves the offset to about 1.5 ms
    assert fit.shift_2d_mm < 1.5
    assert fit.cost_after <= fit.cost_before


@pytest.mark.parametrize(("mode", "tol_ms"), [("full", 1.0), ("budget", 3.5)])
def test_camera_stamps_20ms_late_are_measured(scene_copy, mode: str, tol_ms: float) -> None:
    """8 fit frames recover the offset to 1 ms; the 2 frames of the budgeted mode to 2.5 ms."""
    from robogs.synth.mutations import MUTATIONS

    root = scene_copy("late")
    MUTATIONS["shift_camera_stamps"](root, 20.0)
    findings, _ctx = _run(root, ["B005", "B006"], mode=mode)
    off = [f for f in findings if f.code == "B005"]
    assert len(off) == 1, findings
    assert abs(off[0].value - 20.0) < tol_ms
    assert f"from {8 if mode == 'full' else 2} moving frames" in off[0].message
    assert off[0].severity == "error" and "late" in off[0].message
    assert not [f for f in findings if f.code == "B006"]


@pytest.mark.parametrize("mode", ["full", "budget"])
def test_camera_moved_3mm_is_measured(scene_copy, mode: str) -> None:
    root = scene_copy("moved")
    rel = json.loads((root / "manifest.json").read_text())["cameras"]["cam0"]
    cam = json.loads((root / rel).read_text())
    T = np.asarray(cam["T_world_cam"], float)
    T[:3, 3] += 0.003 * T[:3, 0]  # 3 mm along the camera's own x axis; the frames stay
    cam["T_world_cam"] = T.tolist()
    (root / rel).write_text(json.dumps(cam, indent=2))
    _rehash(root, rel)
    findings, _ctx = _run(root, ["B005", "B006"], mode=mode)
    ext = [f for f in findings if f.code == "B006"]
    assert len(ext) == 1, findings
    assert abs(ext[0].value - 3.0) < 1.0
    assert "x +" in ext[0].message  # displaced towards +x of the camera
    assert not [f for f in findings if f.code == "B005"]


@pytest.mark.parametrize(("mode", "stride"), [("full", 16), ("budget", 1)])
def test_relabelled_link_is_named(scene_copy, mode: str, stride: int) -> None:
    root = scene_copy("relabel")
    m = json.loads((root / "manifest.json").read_text())
    entry = m["robot"]["splats"]
    s = read_splat_ply(root / entry["path"])
    src, dst = entry["targets"].index("forearm_link"), entry["targets"].index("upper_arm_link")
    s.bind_id[s.bind_id == src] = dst
    write_splat_ply(root / entry["path"], s)
    _rehash(root, entry["path"])
    findings, _ctx = _run(root, ["B001", "B002"], stride=stride, mode=mode)
    face = [f for f in findings if f.code == "B001"]
    assert face and face[0].location.link == "upper_arm_link" and "forearm_link" in face[0].message
    assert face[0].value > 50.0  # mm: the forearm is far from the upper arm's faces
    iou = {f.location.link: f.value for f in findings if f.code == "B002"}
    assert "forearm_link" in iou and iou["forearm_link"] < 0.2


@pytest.mark.parametrize(
    ("mutation", "kwargs", "at_most_db", "mode"),
    [
        ("splats_in_linear_rgb", {}, 16.0, "full"),
        ("swap_splat_channels", {"target": "table"}, 18.0, "full"),
        ("splats_in_linear_rgb", {}, 16.0, "budget"),
    ],
)
def test_wrong_splat_colours_fall_below_the_psnr_floor(
    scene_copy, mutation: str, kwargs: dict, at_most_db: float, mode: str
) -> None:
    from robogs.synth.mutations import MUTATIONS

    root = scene_copy(mutation)
    MUTATIONS[mutation](root, **kwargs)
    # every binding check but the label-only alignment fit (B005, B006), which colour cannot move
    codes = [c for c in B_CODES if c not in ("B005", "B006")]
    stride = 16 if mode == "full" else 1
    findings, ctx = _run(root, codes, stride=stride, mode=mode)
    assert [(f.code, f.severity) for f in findings] == [("B004", "warning")], findings
    (f,) = findings
    floor = ctx.budget("binding.psnr_min_db")
    assert floor == 20.0 and f.budget == floor
    assert f.value < at_most_db  # measured: 12.2 dB (linear), 15.2 dB (table red/blue swapped)
    assert f"PSNR {f.value:.2f} dB" in f.message and "below the 20 dB floor" in f.message
    assert f.location.stream == _stream(root)[1] and f.location.frame is not None
    # the floor is a budget: lowering it below the measured value silences the check
    quiet, _ = _run(
        root, ["B004"], budgets={"binding.psnr_min_db": f.value - 0.5}, stride=stride, mode=mode
    )
    assert not quiet


def test_face_offset_error_in_mm(scene_copy) -> None:
    root = scene_copy("offset")
    rel = json.loads((root / "manifest.json").read_text())["assets"]["box"]["splats"]["path"]
    s = read_splat_ply(root / rel)
    s.bind_offset[7] = 0.005  # declared 5 mm off the face, stored on it
    write_splat_ply(root / rel, s)
    _rehash(root, rel)
    findings, _ctx = _run(root, ["B001"])
    assert len(findings) == 1 and findings[0].location.object == "box"
    assert findings[0].value == pytest.approx(5.0, abs=1e-3)
    assert "1 of" in findings[0].message and findings[0].location.where == "vertex 7"


def test_bad_inputs_are_findings_not_crashes(scene_copy) -> None:
    root = scene_copy("bad")
    m = json.loads((root / "manifest.json").read_text())
    rel = m["assets"]["box"]["splats"]["path"]
    s = read_splat_ply(root / rel)
    s.means[0] = np.nan
    s.log_scales[1] = -np.inf
    s.log_scales[2] = 5.0  # e^5 = 148 m
    s.quats[3] *= 1.01
    s.quats[4] = 0.0
    write_splat_ply(root / rel, s)
    cam_rel = m["cameras"]["cam0"]
    cam = json.loads((root / cam_rel).read_text())
    T = np.asarray(cam["T_world_cam"], float)
    T[:3, :3] *= 1.2  # not a rotation
    cam["T_world_cam"] = T.tolist()
    (root / cam_rel).write_text(json.dumps(cam, indent=2))
    labels_rel = next(s for s in m["episodes"][0]["streams"].values() if s["kind"] == "camera")[
        "labels"
    ]
    tab = pq.read_table(root / labels_rel)
    pngs = tab.column("png").to_pylist()
    img = decode_label_png(pngs[3]).copy()
    img[:5, :5] = 999
    pngs[3] = encode_label_png(img)
    pq.write_table(tab.set_column(1, "png", pa.array(pngs, pa.binary())), root / labels_rel)
    _rehash(root, rel, cam_rel, labels_rel)

    findings, _ctx = _run(root, B_CODES, stride=40)
    msgs = {f.code: [] for f in findings}
    for f in findings:
        msgs[f.code].append(f.message)
    b007 = " ".join(msgs.get("B007", []))
    for what in ("non-finite centre", "zero scale", "scale above 10 m", "zero rotation"):
        assert what in b007, b007
    assert any("1.01" in t for t in msgs.get("B008", [])), msgs
    assert any("orthonormal" in t for t in msgs.get("B009", [])), msgs
    assert any("999" in t for t in msgs.get("B010", [])), msgs
    # the degenerate camera cannot be re-rendered: the label checks stay silent instead of failing
    assert not {"B002", "B003", "B005", "B006"} & set(msgs)


def test_bad_splats_do_not_stop_the_rerender(scene_copy) -> None:
    root = scene_copy("nan")
    rel = json.loads((root / "manifest.json").read_text())["robot"]["splats"]["path"]
    s = read_splat_ply(root / rel)
    s.means[:50] = np.nan  # a few broken Gaussians among thousands
    write_splat_ply(root / rel, s)
    _rehash(root, rel)
    findings, ctx = _run(root, ["B002", "B003", "B007"], stride=40)
    assert [f.code for f in findings if f.severity != "info"] == ["B007"]
    ep, stream = _stream(root)
    assert all(math.isfinite(x.iou) for x in label_summary(ctx, ep, stream) if x.pixels)


def test_scaled_render_camera_keeps_pixel_edges() -> None:
    from robogs.format.cameras import CameraModel
    from robogs.format.errors import InputError
    from robogs.format.render.camera import camera_from_model as _render_camera
    from robogs.format.rerender import RerenderOptions

    model = CameraModel("c", 640, 480, 500.0, 510.0, 320.5, 240.25, T_world_cam=np.eye(4))
    cam = _render_camera(model, np.eye(4), 0.5)
    assert (cam.width, cam.height) == (320, 240)
    x = np.array([0.1, -0.05, 1.3])  # a point in the camera frame
    full = np.array([model.fx * x[0] / x[2] + model.cx, model.fy * x[1] / x[2] + model.cy])
    half = np.array([cam.fx * x[0] / x[2] + cam.cx, cam.fy * x[1] / x[2] + cam.cy])
    assert np.allclose(half, 0.5 * full)  # pixel-edge coordinates scale exactly
    for bad in ({"stride": 0}, {"scale": 0.0}, {"scale": -1.0}, {"fit_frames": 0}):
        with pytest.raises(InputError):
            RerenderOptions(**bad)
