"""Camera poses from images by structure from motion (``pycolmap``, CPU; the ``sfm`` extra).

Steps: SIFT feature extraction, matching (exhaustive up to ``EXHAUSTIVE_MAX`` images, else
sequential, as for video), incremental mapping (COLMAP, Schönberger & Frahm 2016). The largest
model is kept; its frame is arbitrary (scale, origin, up). ``robogs reconstruct --align apply``
then fits the similarity to the URDF (Umeyama + ICP on the link-labelled mesh) and moves the
cameras into the robot's world, reporting the residual in mm.

Video keyframes (:func:`select_keyframes`): frames are scored by sharpness, the variance of the
Laplacian (Pech-Pacheco et al. 2000); a frame is kept when it is not blurred (score ≥
``blur_ratio`` x the median score) and has moved since the last keyframe (mean absolute
difference of the grey images ≥ ``min_change``, a cheap baseline proxy).

Failure (too few registered images: blurred or duplicate frames, no parallax) raises
:class:`SfmError` naming how many images registered.

Two basins. On an inward-looking orbit (the synthetic static capture: 60 views of a table-top
scene at 50 deg field of view) the incremental mapper has a second, wrong solution: the scene
depth-reversed (every rotation off by ~180 deg after the best similarity) with the focal length
at ~0.4x the truth (fx 146, fy 128 px for 343 true), 60 of 60 images registered and a mean
reprojection error of 1.3 px instead of 0.35 px. Which one a run reaches depends on the focal
start, the RANSAC seed and the thread timing (bench/RESULTS.md, h51), not on the images: the
true start (fx = fy = 343 px, seed 0) reached it with 1 thread, with 2 threads it did not;
one shared focal (square pixels) and mapping with the focal held at the start both still
reached it. So the mapper is run from ``FOCAL_STARTS`` (two focal starts, two RANSAC seeds) on
the same features and matches, and the model is chosen by the data: most registered images,
then lowest mean reprojection error (the depth-reversed model fits the same tracks ~4x worse).
Starts that end in different focal lengths are reported (:attr:`SfmResult.starts`, the
provenance, and a :class:`SfmBasinWarning`), never resolved silently.

Repeatable with any thread count (h74). Three things made a run with ``threads > 1`` differ
from the last on the same images: (1) multi-threaded extraction wrote the images into the
database in the order their features finished, so the image ids (and with them the pair
order and the mapper's choices) changed from run to run (14 of 60 ids moved between two runs
of the sample); (2) the two-view verification drew its RANSAC samples from COLMAP's
thread-local generators (``random_seed = -1``: 29-33 of 1184 verified pairs changed their
inliers); (3) the mapper's bundle adjustment sums in thread order (poses up to 5e-15 apart
between two runs on one database; COLMAP repeats a seeded mapper only on one thread). So the
images are imported in name order before extraction, the verification gets the run's seed, and
the mapper runs on one thread (``repeatable=False`` gives it ``threads``). The sample's
database then came out byte for byte the same from two runs with 2 threads, and its poses the
same from 2 and from 1 thread (3 runs), with extraction and matching (most of the time) still
on ``threads``; the step's CPU time did not change (34.5-36.8 s before and after).
"""

from __future__ import annotations

import shutil
import warnings
from contextlib import closing
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from robogs.format.cameras import CameraModel
from robogs.format.errors import InputError

__all__ = [
    "SfmError",
    "SfmBasinWarning",
    "SfmResult",
    "SfmStart",
    "EXHAUSTIVE_MAX",
    "FOCAL_STARTS",
    "sharpness",
    "select_keyframes",
    "run_sfm",
    "convert_sfm",
]

#: match every pair up to this many images; sequential (overlap 10) beyond
EXHAUSTIVE_MAX = 60

#: focal starts of the mapper, as factors of the first start (the given intrinsics, else
#: COLMAP's guess 1.2 x the larger image side); start i uses RANSAC seed ``seed + i``. The wrong
#: basin lies below the true focal (~0.4x), and starts below the truth reached it most often
#: (bench/RESULTS.md, h51), so the second start is above the first.
FOCAL_STARTS = (1.0, 1.6)

#: two starts whose focal lengths differ by more than this fraction ended in different models
BASIN_TOL = 0.05


class SfmError(InputError):
    """Structure from motion registered too few images."""


class SfmBasinWarning(UserWarning):
    """The mapper's starts ended in different models; the one that fits the data best was kept."""


@dataclass
class SfmResult:
    """Recovered cameras in the (arbitrary) SfM frame.

    Attributes:
        names: image names, in the order of ``T_world_cam``.
        T_world_cam: [N, 4, 4] camera-to-world (OpenCV axes, SfM units).
        K: [3, 3] shared intrinsics after refinement (px, pixel centres at +0.5).
        size: (width, height) px.
        registered: images registered.
        total: images given.
        points: 3D points of the model.
        reprojection_px: mean reprojection error, px.
        model_dir: the largest model, written as a COLMAP binary model.
        starts: every start of the mapper and where it ended (the chosen one has ``chosen``).
    """

    names: list[str]
    T_world_cam: np.ndarray
    K: np.ndarray
    size: tuple[int, int]
    registered: int
    total: int
    points: int
    reprojection_px: float
    model_dir: Path | None = None
    starts: list[SfmStart] = field(default_factory=list)


@dataclass
class SfmStart:
    """One run of the incremental mapper on the shared features and matches.

    Attributes:
        start_px: focal length the run started from, px.
        seed: its RANSAC seed.
        fx, fy: focal lengths it ended with, px (nan: no model).
        registered: images in its largest model.
        points: 3D points of that model.
        reprojection_px: its mean reprojection error, px (inf: no model).
        chosen: this run's model is the result.
    """

    start_px: float
    seed: int
    fx: float
    fy: float
    registered: int
    points: int
    reprojection_px: float
    chosen: bool = False

    def key(self) -> tuple[int, float]:
        """Choice order (higher is better): registered images, then lower reprojection error."""
        return (self.registered, -self.reprojection_px)


def sharpness(gray: np.ndarray) -> float:
    """Variance of the Laplacian of a grey image (higher is sharper)."""
    return float(cv2.Laplacian(np.asarray(gray, np.float64), cv2.CV_64F).var())


def select_keyframes(
    frames: list[np.ndarray], *, blur_ratio: float = 0.5, min_change: float = 2.0
) -> list[int]:
    """Indices of the keyframes of a video (RGB or grey uint8 frames).

    Args:
        frames: the decoded frames.
        blur_ratio: a frame sharper than this fraction of the median sharpness is not blurred.
        min_change: mean absolute grey difference (0-255) from the last keyframe to keep a frame.
    """
    grey = [f if f.ndim == 2 else cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for f in frames]
    if not grey:
        return []
    s = np.array([sharpness(g) for g in grey])
    floor = blur_ratio * float(np.median(s))
    keep: list[int] = []
    for i, g in enumerate(grey):
        if s[i] < floor:
            continue
        if keep:
            diff = np.abs(g.astype(np.int16) - grey[keep[-1]].astype(np.int16)).mean()
            if diff < min_change:
                continue
        keep.append(i)
    return keep


def _pycolmap():
    try:
        import pycolmap
    except ImportError:
        raise InputError(
            "structure from motion needs pycolmap",
            hint="pip install 'robogs[sfm]'",
        ) from None
    return pycolmap


def run_sfm(
    image_dir: str | Path,
    work: str | Path,
    *,
    intrinsics: tuple[float, float, float, float] | None = None,
    sequential: bool | None = None,
    min_registered: int = 3,
    threads: int = 1,
    seed: int = 0,
    max_features: int = 2000,
    focal_starts: tuple[float, ...] = FOCAL_STARTS,
    repeatable: bool = True,
    verbose: bool = False,
) -> SfmResult:
    """Recover the poses of the images in ``image_dir`` (one shared pinhole camera).

    Features and matches are computed once; the incremental mapper then runs once per focal
    start (``focal_starts``, with seeds ``seed``, ``seed + 1``, ...) and the model with the most
    registered images, then the lowest mean reprojection error, is kept (module docstring: the
    mapper has a depth-reversed basin at ~0.4x the focal length). Pixels are square (one focal
    length, COLMAP ``SIMPLE_PINHOLE``) unless ``intrinsics`` gives fx != fy.

    Args:
        image_dir: folder of images (one camera).
        work: scratch folder (database, models), replaced.
        intrinsics: (fx, fy, cx, cy) px with pixel centres at +0.5 if known: the first focal
            start and a prior for matching (calibrated two-view geometry); refined anyway.
            None: the first start is COLMAP's guess (EXIF focal, else 1.2 x the larger side).
        sequential: match neighbours only (video); None: when more than ``EXHAUSTIVE_MAX`` images.
        min_registered: fewer registered images raise :class:`SfmError`.
        threads: CPU threads for COLMAP's feature extraction and matching (and the mapper
            with ``repeatable=False``).
        seed: COLMAP's random seed (RANSAC of the two-view verification and of the first
            start's mapper).
        max_features: SIFT features kept per image (caps matching work: exhaustive matching
            of N images costs N(N-1)/2 pairs of ``max_features``^2 descriptor distances).
        focal_starts: focal starts as factors of the first start (each a mapper run, ~15 s on
            the 60-image sample); ``(1.0,)`` runs the mapper once.
        repeatable: run the mapper on one thread, so that the same images give the same model
            with any ``threads`` (module docstring); False: the mapper gets ``threads`` too
            and its result may differ from run to run in the last bits, or more.
        verbose: keep COLMAP's own log (glog, on stderr); else nothing but fatal errors.

    Raises:
        SfmError: fewer than ``min_registered`` images registered (or none in the largest model).
        InputError: pycolmap missing, no images, a focal start not positive.

    Warns:
        SfmBasinWarning: the starts ended in different focal lengths (by more than
            ``BASIN_TOL``); the message names them and the one kept.
    """
    pc = _pycolmap()
    if not verbose:  # COLMAP logs every step through glog; the result and errors are ours
        pc.logging.minloglevel = 3  # FATAL only: failures reach the user as SfmError
    image_dir, work = Path(image_dir), Path(work)
    names = sorted(p.name for p in image_dir.iterdir() if p.is_file())
    if not names:
        raise InputError("no images to reconstruct from", path=image_dir)
    factors = [float(f) for f in focal_starts]
    if not factors or not all(np.isfinite(f) and f > 0 for f in factors):
        raise InputError(
            f"focal_starts must be positive factors, got {tuple(focal_starts)}",
            hint="e.g. (1.0, 1.6): the first start, then 1.6 x its focal length",
        )
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    db = work / "database.db"
    pc.set_random_seed(seed)
    ro = pc.ImageReaderOptions()
    square = intrinsics is None or abs(intrinsics[0] - intrinsics[1]) <= 1e-6 * abs(intrinsics[0])
    ro.camera_model = "SIMPLE_PINHOLE" if square else "PINHOLE"
    if intrinsics is not None:
        fx, fy, cx, cy = intrinsics
        # COLMAP: pixel centres at +0.5 too; giving them marks the focal length as a prior
        ro.camera_params = f"{fx},{cx},{cy}" if square else f"{fx},{fy},{cx},{cy}"
    eo = pc.FeatureExtractionOptions()
    eo.num_threads = threads
    eo.sift.max_num_features = max_features
    eo.sift.first_octave = -1  # upsample once: small images need the finest octave
    # image ids in name order: extraction on threads writes images as their features finish
    pc.Database.open(db).close()
    pc.import_images(db, image_dir, camera_mode=pc.CameraMode.SINGLE, image_names=names, options=ro)
    pc.extract_features(
        db,
        image_dir,
        image_names=names,
        camera_mode=pc.CameraMode.SINGLE,
        reader_options=ro,
        extraction_options=eo,
        device=pc.Device.cpu,
    )
    mo = pc.FeatureMatchingOptions()
    mo.num_threads = threads
    vo = pc.TwoViewGeometryOptions()
    vo.ransac.random_seed = seed  # -1 (COLMAP's default) draws from per-thread generators
    if sequential if sequential is not None else len(names) > EXHAUSTIVE_MAX:
        pc.match_sequential(db, matching_options=mo, verification_options=vo, device=pc.Device.cpu)
    else:
        pc.match_exhaustive(db, matching_options=mo, verification_options=vo, device=pc.Device.cpu)
    with closing(pc.Database.open(db)) as d:
        cam0 = d.read_all_cameras()[0]
    base = np.array(cam0.params, np.float64)
    runs: list[tuple[SfmStart, object]] = []
    for i, factor in enumerate(factors):
        params = base.copy()
        params[cam0.focal_length_idxs()] *= factor
        cam0.params = params.tolist()  # the prior flag stays as extraction set it
        with closing(pc.Database.open(db)) as d:
            d.update_camera(cam0)
        out = work / f"start{i}"
        out.mkdir()
        opts = pc.IncrementalPipelineOptions()
        opts.num_threads = 1 if repeatable else threads
        opts.random_seed = seed + i
        pc.set_random_seed(seed + i)
        models = pc.incremental_mapping(db, image_dir, out, options=opts)
        rec = max(models.values(), key=lambda r: r.num_reg_images(), default=None)
        runs.append((_start(rec, float(params[cam0.focal_length_idxs()[0]]), seed + i), rec))
    starts = [r for r, _ in runs]
    best_i = _choose(starts)
    best = runs[best_i][1]
    n = starts[best_i].registered
    if n < min_registered:
        raise SfmError(
            f"structure from motion registered {n} of {len(names)} images "
            f"(need ≥ {min_registered})",
            path=image_dir,
            hint="the images need overlap and parallax: move the camera around the scene "
            "(not only turn it), avoid blurred and duplicate frames",
        )
    _warn_basins(starts, image_dir)
    res = _result(best, len(names))
    res.starts = starts
    res.model_dir = work / "model"
    res.model_dir.mkdir()
    best.write(res.model_dir)
    return res


def _start(rec, start_px: float, seed: int) -> SfmStart:
    if rec is None or rec.num_reg_images() == 0:
        return SfmStart(start_px, seed, float("nan"), float("nan"), 0, 0, float("inf"))
    cam = next(iter(rec.cameras.values()))
    return SfmStart(
        start_px,
        seed,
        float(cam.focal_length_x),
        float(cam.focal_length_y),
        int(rec.num_reg_images()),
        int(rec.num_points3D()),
        float(rec.compute_mean_reprojection_error()),
    )


def _choose(starts: list[SfmStart]) -> int:
    """Mark and return the index of the kept run: most registered images, then the lowest mean
    reprojection error; a tie keeps the earlier start."""
    best = max(range(len(starts)), key=lambda i: starts[i].key())
    starts[best].chosen = True
    return best


def _warn_basins(starts: list[SfmStart], image_dir: Path) -> None:
    """Warn when the starts that registered images ended in different focal lengths."""
    done = [s for s in starts if s.registered > 0]
    f = np.array([s.fx for s in done])
    if len(done) < 2 or f.max() <= (1 + BASIN_TOL) * f.min():
        return
    kept = next(s for s in starts if s.chosen)
    ends = ", ".join(
        f"{s.start_px:.0f} px -> {s.fx:.1f} px ({s.registered} images, {s.reprojection_px:.2f} px)"
        for s in done
    )
    warnings.warn(
        f"{image_dir}: structure from motion ended in different models from its focal starts "
        f"({ends}); kept {kept.fx:.1f} px: most registered images, then lowest reprojection "
        "error. Pass the camera's intrinsics if they are known.",
        SfmBasinWarning,
        stacklevel=3,
    )


def _result(rec, total: int) -> SfmResult:
    cam = next(iter(rec.cameras.values()))
    fx, fy = float(cam.focal_length_x), float(cam.focal_length_y)
    cx, cy = float(cam.principal_point_x), float(cam.principal_point_y)
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])  # same pixel convention
    names, Ts = [], []
    for im in sorted(rec.images.values(), key=lambda im: im.name):
        if not im.has_pose:
            continue
        cfw = im.cam_from_world() if callable(im.cam_from_world) else im.cam_from_world
        M = np.asarray(cfw.matrix(), np.float64)
        T = np.eye(4)
        T[:3, :3] = M[:3, :3].T
        T[:3, 3] = -M[:3, :3].T @ M[:3, 3]
        names.append(im.name)
        Ts.append(T)
    return SfmResult(
        names=names,
        T_world_cam=np.stack(Ts),
        K=K,
        size=(int(cam.width), int(cam.height)),
        registered=len(names),
        total=total,
        points=int(rec.num_points3D()),
        reprojection_px=float(rec.compute_mean_reprojection_error()),
    )


def _video_keyframes(video: Path, dst: Path) -> int:
    """Write the keyframes of ``video`` to ``dst`` as PNGs; returns how many frames were read."""
    from robogs.format.images import iter_video_frames

    frames = list(iter_video_frames(video))
    for i in select_keyframes(frames):
        cv2.imwrite(str(dst / f"{i:06d}.png"), cv2.cvtColor(frames[i], cv2.COLOR_RGB2BGR))
    return len(frames)


def _unposed_camera(ds) -> tuple[str, str, dict]:
    """(episode id, stream key, stream) of the one camera stream whose extrinsics are unknown."""
    found = [
        (ep.id, key, st)
        for ep in ds.episodes
        for key, st in ep.streams.items()
        if st.get("kind") == "camera" and ds.camera(st["camera"]).extrinsics == "unknown"
    ]
    if len(found) != 1:
        raise InputError(
            f"--sfm on a dataset needs exactly one camera stream with extrinsics unknown, "
            f"found {len(found)}",
            path=ds.root,
            hint="convert the images or the video of that camera instead",
        )
    return found[0]


def _pose_dataset(src: Path, out: Path, work: Path, *, force: bool, threads: int):
    """Copy the dataset ``src`` to ``out`` with the SfM poses and intrinsics of its unposed camera."""
    import os

    import pyarrow as pa

    from robogs.format.dataset import Dataset, read_parquet
    from robogs.format.errors import DatasetExistsError
    from robogs.format.frames import matrix_to_quat_np
    from robogs.format.images import iter_video_frames
    from robogs.format.replace import check_replaceable

    ds = Dataset.open(src)
    ep_id, key, st = _unposed_camera(ds)
    cam = ds.camera(st["camera"])
    frames = read_parquet(ds.resolve(st["frames"]))
    index = frames.column("frame_index").to_numpy()
    img = work / "images"
    img.mkdir(parents=True)
    want = {int(i) for i in index}
    for i, rgb in enumerate(iter_video_frames(ds.resolve(st["video"]))):
        if i in want:
            cv2.imwrite(str(img / f"{i:06d}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    res = run_sfm(img, work / "sfm", threads=threads)  # intrinsics from SfM (see run_sfm)
    if res.registered < len(index):
        raise SfmError(
            f"structure from motion registered {res.registered} of {len(index)} images; "
            "every view of a dataset needs a pose",
            path=src,
            hint="drop the blurred or duplicate views, or recapture with more overlap",
        )
    pos = {int(n[:6]): T for n, T in zip(res.names, res.T_world_cam, strict=True)}
    T = np.stack([pos[int(i)] for i in index])
    q = matrix_to_quat_np(T[:, :3, :3])
    cols = {"t_ns": frames.column("t_ns")}
    cols.update({c: pa.array(T[:, i, 3]) for i, c in enumerate("xyz")})
    cols.update({c: pa.array(q[:, i]) for i, c in enumerate(("qw", "qx", "qy", "qz"))})
    if out.exists() and not force:
        raise DatasetExistsError(
            "output exists", path=out, hint="pass --force to replace it, or choose another path"
        )
    check_replaceable(out, folder=True, sources=[src])
    tmp = out.with_name(out.name + ".sfm-tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    shutil.copytree(src, tmp)
    tds = Dataset.open(tmp)
    rel = f"{Path(st['frames']).parent.as_posix()}/extrinsics.parquet"
    fx, fy, cx, cy = res.K[0, 0], res.K[1, 1], res.K[0, 2], res.K[1, 2]
    with tds.edit() as w:
        w.write_table(rel, pa.table(cols), kind="camera_extrinsics")
        w.set_camera(
            CameraModel(
                cam.name,
                cam.width,
                cam.height,
                float(fx),
                float(fy),
                float(cx),
                float(cy),
                extrinsics="time_varying",
            )
        )
        eps = [dict(e) for e in w.manifest["episodes"]]
        for e in eps:
            if e["id"] == ep_id:
                e["streams"] = {**e["streams"], key: {**e["streams"][key], "extrinsics": rel}}
        w.manifest["episodes"] = eps
        prov = dict(w.manifest.get("provenance", {}))
        prov["sfm"] = _sfm_json(res, "arbitrary (SfM): run reconstruct --align apply")
        w.manifest["provenance"] = prov
        w.commit()
    if out.exists():
        shutil.rmtree(out)
    os.replace(tmp, out)
    return Dataset.open(out), res


def _sfm_json(res: SfmResult, frame: str) -> dict:
    return {
        "registered": res.registered,
        "images": res.total,
        "points": res.points,
        "reprojection_px": round(res.reprojection_px, 4),
        "starts": [
            {
                "start_px": round(s.start_px, 2),
                "seed": s.seed,
                "focal_px": [_finite(s.fx, 2), _finite(s.fy, 2)],
                "registered": s.registered,
                "reprojection_px": _finite(s.reprojection_px, 4),
                "chosen": s.chosen,
            }
            for s in res.starts
        ],
        "frame": frame,
        "tool": "pycolmap",
    }


def _finite(x: float, digits: int) -> float | None:
    """``x`` rounded, or None (JSON null) for a run that made no model (nan or inf)."""
    return round(x, digits) if np.isfinite(x) else None


def convert_sfm(
    src: str | Path, out: str | Path, *, options, force: bool = False, threads: int = 1
):
    """``robogs convert SRC OUT --sfm``: poses by structure from motion, then a dataset.

    ``SRC`` is a folder of images, a video (keyframes by sharpness and change) or a robogs
    dataset whose one camera declares ``extrinsics: unknown`` (its frames are posed in place of
    the unknown, labels and robot kept). Images and videos become a COLMAP model that the COLMAP
    converter writes as cameras and static views. The frame is SfM's (arbitrary scale, origin and
    up); ``robogs reconstruct --align apply`` moves it onto the URDF.

    Returns:
        (the written Dataset, the :class:`SfmResult`).
    """
    import tempfile

    from .convert import convert_path

    src, out = Path(src), Path(out)
    if not src.exists():
        raise InputError("no such file or folder", path=src)
    with tempfile.TemporaryDirectory(prefix="robogs-sfm-") as tmp:
        work = Path(tmp)
        if (src / "manifest.json").is_file():
            return _pose_dataset(src, out, work, force=force, threads=threads)
        if src.is_dir():
            images = src
        else:
            images = work / "keyframes"
            images.mkdir()
            n = _video_keyframes(src, images)
            if not any(images.iterdir()):
                raise SfmError(f"no usable keyframe in {n} video frames", path=src)
        res = run_sfm(images, work / "sfm", threads=threads)
        opts = replace(options, images=images)
        ds = convert_path(res.model_dir, out, fmt="colmap", options=opts, force=force)
        with ds.edit() as w:
            prov = dict(w.manifest.get("provenance", {}))
            prov["sfm"] = _sfm_json(res, "arbitrary (SfM): run reconstruct --align apply")
            w.manifest["provenance"] = prov
            ds = w.commit()
        return ds, res
