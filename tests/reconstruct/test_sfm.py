"""Structure from motion: keyframes from a video and the failure on images without parallax.

The accuracy acceptance on the 60-view 320x240 static capture: every image registers (>= 95 %)
and, after the best similarity onto the true centres (the oracle; Umeyama 1991), the camera
centres are within 1 % of the scene size and the rotations within 1 degree. It runs from the
inputs that sent the mapper's one run into its depth-reversed basin before the focal starts
(fx ~146, fy ~128 px for 343 true, every rotation ~180 deg off; bench/RESULTS.md, h51): other
views (seed 5) from COLMAP's guess, and other views with another focal length (seed 11, 40 deg)
from half the true focal; neither was used to choose the starts. (The test's own capture from
half the true focal is in the same table; it is left out here for time, ~100 s.)
"""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from robogs.convert.ingest.sfm import select_keyframes, sharpness


def _texture(seed: int, shape=(120, 160)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    small = rng.integers(0, 256, (shape[0] // 4, shape[1] // 4), dtype=np.uint8)
    return cv2.resize(small, (shape[1], shape[0]), interpolation=cv2.INTER_NEAREST)


def test_sharpness_is_the_variance_of_the_laplacian():
    g = _texture(0)
    lap = cv2.Laplacian(g.astype(np.float64), cv2.CV_64F)
    assert sharpness(g) == pytest.approx(float(lap.var()))
    assert sharpness(cv2.GaussianBlur(g, (0, 0), 3.0)) < 0.1 * sharpness(g)
    assert sharpness(np.full((8, 8), 7, np.uint8)) == 0.0


def test_keyframes_drop_blurred_and_duplicate_frames():
    a, b, c = _texture(1), _texture(2), _texture(3)
    blurred = cv2.GaussianBlur(b, (0, 0), 4.0)
    frames = [a, a.copy(), blurred, b, b.copy(), c]
    assert select_keyframes(frames) == [0, 3, 5]
    assert select_keyframes([]) == []


def test_sfm_on_identical_images_names_how_many_registered(tmp_path: Path):
    pytest.importorskip("pycolmap", reason="structure from motion needs the 'sfm' extra")
    from robogs.convert.ingest.sfm import SfmError, run_sfm

    img = tmp_path / "img"
    img.mkdir()
    g = cv2.cvtColor(_texture(4), cv2.COLOR_GRAY2BGR)
    for i in range(6):
        cv2.imwrite(str(img / f"{i:03d}.png"), g)
    with pytest.raises(SfmError, match=r"registered [0-2] of 6 images") as e:
        run_sfm(img, tmp_path / "work", intrinsics=(150.0, 150.0, 80.0, 60.0))
    assert "parallax" in e.value.hint


def _rotation_deg(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    d = np.einsum("nji,njk->nik", Ra, Rb)
    return np.degrees(np.arccos(np.clip((np.trace(d, axis1=1, axis2=2) - 1) / 2, -1, 1)))


def test_the_kept_run_has_most_images_then_lowest_reprojection_error():
    """Oracle: sorting every order of five runs by (registered desc, error asc, index asc)."""
    from itertools import permutations

    from robogs.convert.ingest.sfm import SfmStart, _choose

    rows = [  # (registered, reprojection px): the depth-reversed and the true model of h51 first
        (60, 1.325),
        (60, 0.394),
        (59, 0.20),
        (60, 0.394),
        (0, float("inf")),
    ]
    for order in permutations(range(len(rows))):
        starts = [
            SfmStart(100.0, i, 1.0, 1.0, rows[k][0], 10, rows[k][1]) for i, k in enumerate(order)
        ]
        want = sorted(
            range(len(starts)), key=lambda i: (-starts[i].registered, starts[i].reprojection_px, i)
        )[0]
        assert _choose(starts) == want
        assert [s.chosen for s in starts] == [i == want for i in range(len(starts))]
        assert rows[order[want]] == (60, 0.394)


def test_starts_in_different_basins_warn_naming_both_and_the_kept_one():
    from robogs.convert.ingest.sfm import (
        BASIN_TOL,
        SfmBasinWarning,
        SfmStart,
        _choose,
        _warn_basins,
    )

    rev = SfmStart(384.0, 0, 146.8, 146.8, 60, 3638, 1.325)
    true = SfmStart(614.4, 1, 343.3, 343.3, 60, 3129, 0.394)
    _choose([rev, true])
    with pytest.warns(
        SfmBasinWarning, match=r"384 px -> 146\.8 px.*614 px -> 343\.3 px.*kept 343\.3 px"
    ):
        _warn_basins([rev, true], Path("img"))
    near = SfmStart(614.4, 1, 146.8 * (1 + 0.9 * BASIN_TOL), 146.8, 60, 3638, 1.3)
    failed = SfmStart(614.4, 2, float("nan"), float("nan"), 0, 0, float("inf"))
    _choose([rev, near, failed])
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _warn_basins([rev, near, failed], Path("img"))  # one basin; a run with no model is no basin


def test_focal_starts_must_be_positive(tmp_path: Path):
    pytest.importorskip("pycolmap", reason="structure from motion needs the 'sfm' extra")
    from robogs.convert.ingest.sfm import run_sfm
    from robogs.format.errors import InputError

    img = tmp_path / "img"
    img.mkdir()
    cv2.imwrite(str(img / "000.png"), _texture(6))
    for bad in [(), (1.0, 0.0), (1.0, float("nan"))]:
        with pytest.raises(InputError, match="focal_starts must be positive"):
            run_sfm(img, tmp_path / "work", focal_starts=bad)


def _capture(root: Path, seed: int, hfov: float):
    """(truth, image folder) of the 60-view 320x240 static capture of ``seed`` at ``hfov`` deg."""
    from robogs.synth.multiview import synthesize_multiview

    truth = synthesize_multiview(
        root / "cap",
        robot="ur5",
        n_views=60,
        width=320,
        height=240,
        seed=seed,
        hfov_deg=hfov,
        poses=False,
    )
    img = root / "img"
    img.mkdir()
    for i, im in enumerate(truth.images):
        cv2.imwrite(str(img / f"{i:03d}.png"), cv2.cvtColor(im, cv2.COLOR_RGB2BGR))
    return truth, img


@pytest.fixture(scope="module")
def video_sfm(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """``robogs convert walk.mkv out --sfm --sfm-threads 2`` run once per module (and worker):
    the 60-view 320x240 static capture of seed 3 (the ``seed3-guess`` capture), every view twice
    in a lossless FFV1 video. Returns the truth, the exit code, the output folder, the
    :class:`SfmResult` of the convert's one ``run_sfm`` call (recorded by a pass-through wrapper)
    and whether the keyframe images it was given equal the capture's views pixel for pixel.

    ``test_sfm_recovers_the_static_capture[seed3-guess]`` and
    ``test_convert_sfm_on_a_video_keeps_one_keyframe_per_view`` both read this run: SfM on those
    keyframes is SfM on the capture's own images (same pixels, same name order, the same
    ``run_sfm`` options: COLMAP's guess, 2 threads), so it ran twice before (h77)."""
    pytest.importorskip("pycolmap", reason="structure from motion needs the 'sfm' extra")
    from robogs.cli.main import main
    from robogs.convert.ingest import sfm
    from robogs.synth.multiview import synthesize_multiview

    root = tmp_path_factory.mktemp("video_sfm")
    truth = synthesize_multiview(
        root / "cap", robot="ur5", n_views=60, width=320, height=240, seed=3, poses=False
    )
    video = root / "walk.mkv"
    vw = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"FFV1"), 10.0, (320, 240))
    for im in truth.images:
        for _ in range(2):
            vw.write(cv2.cvtColor(im, cv2.COLOR_RGB2BGR))
    vw.release()
    seen: dict = {}
    real = sfm.run_sfm

    def recorded(image_dir, work, **kw):
        files = sorted(Path(image_dir).glob("*.png"))
        got = [cv2.cvtColor(cv2.imread(str(f)), cv2.COLOR_BGR2RGB) for f in files]
        seen["same_pixels"] = len(got) == len(truth.images) and all(
            np.array_equal(a, b) for a, b in zip(got, truth.images, strict=False)
        )
        seen["kw"] = kw
        seen["res"] = real(image_dir, work, **kw)
        return seen["res"]

    argv = ["convert", str(video), str(root / "out"), "--sfm", "--sfm-threads", "2"]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sfm, "run_sfm", recorded)
        rc = main(argv)
    return {"truth": truth, "rc": rc, "out": root / "out", **seen}


@pytest.mark.slow
@pytest.mark.parametrize(
    ("seed", "hfov", "focal"),
    [
        # the test's capture from COLMAP's guess: 147.7 px on CI and on the shared machine once;
        # its SfM is the video test's run (fixture video_sfm: the same images)
        pytest.param(3, 50.0, None, id="seed3-guess"),
        # other views from COLMAP's guess: fx 144.6, fy 128.9 px before
        pytest.param(5, 50.0, None, id="seed5-guess"),
        # other views and another focal length (440 px), not used to choose the starts:
        # fx 183.1, fy 165.4 px before
        pytest.param(11, 40.0, 0.5, id="seed11-40deg-half-focal"),
    ],
)
def test_sfm_recovers_the_static_capture(tmp_path: Path, request, seed, hfov, focal):
    """38-63 s each at load 3-4 on 2 cores (2026-11-27): 60 images, 2000 SIFT features each,
    exhaustive matching, two mapper runs (one in the reversed basin costs ~50 s more). Seed 3
    from COLMAP's guess reads the video test's run (fixture ``video_sfm``), whose keyframes are
    checked here to be this capture's images pixel for pixel, given with the same options."""
    pytest.importorskip("pycolmap", reason="structure from motion needs the 'sfm' extra")
    import json
    import warnings

    from robogs.convert.ingest.sfm import FOCAL_STARTS, SfmBasinWarning, run_sfm
    from robogs.reconstruct.align import umeyama

    if (seed, hfov, focal) == (3, 50.0, None):
        run = request.getfixturevalue("video_sfm")
        assert run["same_pixels"] and run["kw"] == {"threads": 2}, run.get("kw")
        truth, res = run["truth"], run["res"]
        view = [int(Path(n).stem) // 2 for n in res.names]  # frame 2v is view v
    else:
        truth, img = _capture(tmp_path, seed, hfov)
        K = truth.K
        intr = None if focal is None else (focal * K[0, 0], focal * K[1, 1], K[0, 2], K[1, 2])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SfmBasinWarning)  # the choice is what is tested here
            res = run_sfm(img, tmp_path / "work", intrinsics=intr, threads=2)
        view = [int(n[:3]) for n in res.names]
    K = truth.K
    starts = json.dumps([vars(s) for s in res.starts])
    assert res.registered >= 57 and res.total == 60, starts
    assert res.size == (320, 240)
    assert np.allclose(res.K[[0, 1], [2, 2]], K[[0, 1], [2, 2]])
    assert abs(res.K[0, 0] / K[0, 0] - 1) < 0.01, starts  # focal length refined from a start
    assert res.K[1, 1] == res.K[0, 0]  # square pixels: one focal length
    assert sum(s.chosen for s in res.starts) == 1 and len(res.starts) == len(FOCAL_STARTS)
    Tt = truth.T_world_cam[view]
    S = umeyama(res.T_world_cam[:, :3, 3], Tt[:, :3, 3])
    size = float(np.linalg.norm(np.ptp(truth.scene_mesh.vertices, axis=0)))
    err = np.linalg.norm(S.apply(res.T_world_cam[:, :3, 3]) - Tt[:, :3, 3], axis=1)
    assert err.max() < 0.01 * size, json.dumps({"max_m": err.max(), "size_m": size})
    ang = _rotation_deg(np.einsum("ij,njk->nik", S.R, res.T_world_cam[:, :3, :3]), Tt[:, :3, :3])
    assert ang.max() < 1.0, starts


def test_convert_sfm_on_duplicate_frames_is_one_line_naming_the_count(tmp_path: Path, capsys):
    """``robogs convert DIR OUT --sfm`` on six copies of one image: exit 2, no dataset."""
    pytest.importorskip("pycolmap", reason="structure from motion needs the 'sfm' extra")
    from robogs.cli.main import main

    img = tmp_path / "img"
    img.mkdir()
    g = cv2.cvtColor(_texture(5), cv2.COLOR_GRAY2BGR)
    for i in range(6):
        cv2.imwrite(str(img / f"{i:03d}.png"), g)
    code = main(["convert", str(img), str(tmp_path / "out"), "--sfm"])
    err = capsys.readouterr().err
    assert code == 2 and re.search(r"registered [0-2] of 6 images", err), err
    assert "Traceback" not in err and not (tmp_path / "out").exists()


def test_convert_sfm_on_a_posed_dataset_is_refused(tmp_path: Path, capsys):
    """Mutation of the input kind: a dataset whose camera has poses has nothing to recover."""
    from robogs.cli.main import main
    from robogs.synth.multiview import synthesize_multiview

    synthesize_multiview(tmp_path / "d", n_views=4, width=16, height=12)
    code = main(["convert", str(tmp_path / "d"), str(tmp_path / "out"), "--sfm"])
    err = capsys.readouterr().err
    assert code == 2 and "extrinsics unknown, found 0" in err, err


@pytest.mark.slow
def test_convert_sfm_on_a_video_keeps_one_keyframe_per_view(video_sfm: dict):
    """~70 s on a loaded 2-core machine (the run is shared with the seed-3 accuracy case):
    every view of the static sample twice in a lossless video; the duplicates are dropped as
    keyframes and the 60 views become a posed COLMAP-route dataset that validates."""
    from robogs.format.dataset import Dataset
    from robogs.format.validate import validate

    assert video_sfm["rc"] == 0
    out = video_sfm["out"]
    ds = Dataset.open(out)
    sfm = ds.manifest["provenance"]["sfm"]
    assert sfm["images"] == 60 and sfm["registered"] >= 57
    assert sfm["frame"].startswith("arbitrary")
    assert [f for f in validate(out).findings if f.severity == "error"] == []


def _db_state(work: Path) -> tuple[list[str], dict[tuple[str, str], bytes]]:
    """(image names in id order, the verified inlier matches of every pair by names)."""
    from contextlib import closing

    import pycolmap

    with closing(pycolmap.Database.open(work / "database.db")) as d:
        images = sorted(d.read_all_images(), key=lambda im: im.image_id)
        name = {im.image_id: im.name for im in images}
        pairs, geoms = d.read_two_view_geometries()
        inliers = {}
        for pid, g in zip(pairs, geoms, strict=True):
            i, j = pycolmap.pair_id_to_image_pair(pid)
            inliers[(name[i], name[j])] = np.asarray(g.inlier_matches).tobytes()
    return [im.name for im in images], inliers


@pytest.mark.slow
def test_sfm_repeats_exactly_with_two_threads_and_with_one(tmp_path: Path):
    """Mutation of the thread count (h74): the same 16 images through ``run_sfm`` with 2 threads
    and with 1 give the same database (image ids in name order, the same verified
    inliers for every pair) and the same model to the bit. Before, multi-threaded extraction
    numbered the images as their features finished, the verification drew from per-thread
    generators and the mapper summed in thread order: 14 of 60 ids, 29-33 of 1184 pairs and
    the poses changed between runs of the sample. Was 20 images and three runs (51-65 s on 2
    cores at load 7-8); 16 images and two runs since 2026-11-28 (suite time, 23 s idle). The
    unseeded verification (``random_seed = -1``) is caught at this size; the multi-threaded mapper
    alone (``repeatable=False``) was not caught here, nor by the 20-image three-run version."""
    pytest.importorskip("pycolmap", reason="structure from motion needs the 'sfm' extra")
    from robogs.convert.ingest.sfm import run_sfm
    from robogs.synth.multiview import synthesize_multiview

    truth = synthesize_multiview(
        tmp_path / "cap", robot="ur5", n_views=16, width=320, height=240, seed=3, poses=False
    )
    img = tmp_path / "img"
    img.mkdir()
    for i, im in enumerate(truth.images):
        cv2.imwrite(str(img / f"{i:03d}.png"), cv2.cvtColor(im, cv2.COLOR_RGB2BGR))
    runs = [
        (run_sfm(img, tmp_path / f"w{k}", threads=t, focal_starts=(1.0,)), tmp_path / f"w{k}")
        for k, t in enumerate((2, 1))
    ]
    first, work0 = runs[0]
    names, inliers = _db_state(work0)
    assert names == sorted(names) and len(names) == 16
    assert first.registered >= 12, first.starts  # a model to compare, not a wrong one
    for res, work in runs[1:]:
        assert _db_state(work) == (names, inliers)
        assert res.names == first.names and res.starts == first.starts
        assert np.array_equal(res.T_world_cam, first.T_world_cam)
        assert np.array_equal(res.K, first.K)
